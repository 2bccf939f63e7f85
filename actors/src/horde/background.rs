//! The Horde's threads give way to the tick: they run under Linux's `SCHED_IDLE` policy.
//!
//! On a machine with two cores the Horde's step (several ms every tick) shares the cores with the tick
//! path's threads (the timer thread, tokio's workers, the link). Under the normal policy a tick-path
//! thread woken on the Horde's core can wait for the scheduler's slice (about 3 ms) before it runs; under
//! `SCHED_IDLE` any normal thread that wakes preempts the Horde at once. An unprivileged process may
//! always lower a thread to `SCHED_IDLE`. The cost is that the Horde gets almost no CPU while the
//! machine is busy with other work: it then skips ticks, counted and shown, and control is untouched.

use std::sync::atomic::{AtomicI32, Ordering};

/// Lowers the calling thread to `SCHED_IDLE` (`[horde] scheduling = "idle"`); a failure is logged and
/// the thread runs on under the normal policy.
pub(crate) fn give_way_to_the_tick() {
    match set_idle_policy() {
        Ok(()) => tracing::debug!("the Horde's thread runs under SCHED_IDLE"),
        Err(e) => tracing::warn!(
            "could not lower the Horde's thread to SCHED_IDLE ({e}); it competes with the tick for the CPU"
        ),
    }
}

/// Puts the calling thread back under the normal policy (when the Horde finishes: its last checkpoint
/// no longer competes with a tick). Lowering a thread's policy is always allowed; raising it back from
/// `SCHED_IDLE` may need privileges an unprivileged process lacks (`RLIMIT_NICE`): a refusal is logged
/// and the thread finishes under `SCHED_IDLE`.
pub(crate) fn back_to_normal_policy() {
    if let Err(e) = set_policy(POLICY_NORMAL) {
        tracing::debug!("the Horde's thread stays under SCHED_IDLE to finish ({e})");
    }
}

/// The Horde's threads that may be under `SCHED_IDLE` (Linux thread ids, 0 for none), so that another
/// thread can put them back under the normal policy when the Horde finishes: a thread under
/// `SCHED_IDLE` on a machine busy with other work may wait minutes for a core, and the last checkpoint
/// waits for both the learner's thread (which must first see the command to finish) and a writer
/// already under way.
#[derive(Debug, Default)]
pub(crate) struct IdleThreads {
    learner: AtomicI32,
    writer: AtomicI32,
}

impl IdleThreads {
    /// The calling thread, the learner's, gives way to the tick and is registered.
    pub(crate) fn learner_gives_way(&self) {
        give_way_to_the_tick();
        self.learner.store(thread_id(), Ordering::Release);
    }

    /// The calling thread, a checkpoint writer, gives way to the tick and is registered until
    /// [`IdleThreads::writer_done`].
    pub(crate) fn writer_gives_way(&self) {
        give_way_to_the_tick();
        self.writer.store(thread_id(), Ordering::Release);
    }

    /// The calling writer is about to end: forgotten (its id may be reused).
    pub(crate) fn writer_done(&self) {
        let me = thread_id();
        let _ = self
            .writer
            .compare_exchange(me, 0, Ordering::AcqRel, Ordering::Acquire);
    }

    /// Every registered thread back under the normal policy (refusals are logged, see
    /// [`back_to_normal_policy`]).
    pub(crate) fn all_back_to_normal(&self) {
        for tid in [&self.learner, &self.writer].map(|t| t.load(Ordering::Acquire)) {
            if tid != 0
                && let Err(e) = set_policy_of(tid, POLICY_NORMAL)
            {
                tracing::debug!("a Horde thread stays under SCHED_IDLE to finish ({e})");
            }
        }
    }
}

/// The calling thread's id (Linux's `gettid`; 0 elsewhere, which names no other thread).
fn thread_id() -> i32 {
    #[cfg(target_os = "linux")]
    // SAFETY: `gettid` takes no arguments and cannot fail.
    return unsafe { libc::gettid() };
    #[cfg(not(target_os = "linux"))]
    0
}

#[cfg(target_os = "linux")]
const POLICY_NORMAL: i32 = libc::SCHED_OTHER;
#[cfg(not(target_os = "linux"))]
const POLICY_NORMAL: i32 = 0;

fn set_idle_policy() -> std::io::Result<()> {
    #[cfg(target_os = "linux")]
    return set_policy(libc::SCHED_IDLE);
    #[cfg(not(target_os = "linux"))]
    Err(std::io::Error::other("SCHED_IDLE is Linux's"))
}

fn set_policy(policy: i32) -> std::io::Result<()> {
    set_policy_of(0, policy)
}

/// Sets the policy of thread `tid` (0: the calling thread).
#[cfg(target_os = "linux")]
fn set_policy_of(tid: i32, policy: i32) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `sched_setscheduler` reads `param` (a valid, initialised struct that outlives the call);
    // `tid` names a thread (0: the calling one); a thread that no longer exists is an error code.
    let rc = unsafe { libc::sched_setscheduler(tid, policy, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn set_policy_of(_tid: i32, _policy: i32) -> std::io::Result<()> {
    Err(std::io::Error::other("scheduling policies are Linux's"))
}

/// The calling thread's scheduling policy (`SCHED_OTHER` = 0, `SCHED_IDLE` = 5).
#[cfg(all(test, target_os = "linux"))]
pub(crate) fn current_policy() -> i32 {
    // SAFETY: no arguments but the pid; 0 names the calling thread.
    unsafe { libc::sched_getscheduler(0) }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn a_thread_that_gives_way_runs_under_sched_idle_and_others_do_not() {
        let before = current_policy();
        let inside = std::thread::spawn(|| {
            give_way_to_the_tick();
            current_policy()
        })
        .join()
        .expect("the thread runs");
        assert_eq!(inside, libc::SCHED_IDLE);
        let back = std::thread::spawn(|| {
            give_way_to_the_tick();
            back_to_normal_policy();
            current_policy()
        })
        .join()
        .expect("the thread runs");
        // Root (or a raised RLIMIT_NICE) may return to SCHED_OTHER; anyone else stays idle.
        assert!(
            back == libc::SCHED_OTHER || back == libc::SCHED_IDLE,
            "{back}"
        );
        assert_eq!(before, libc::SCHED_OTHER);
        assert_eq!(
            current_policy(),
            libc::SCHED_OTHER,
            "only the thread itself"
        );
    }

    #[test]
    fn registered_threads_are_put_back_by_another_thread() {
        let threads = std::sync::Arc::new(IdleThreads::default());
        let (asked_tx, asked_rx) = std::sync::mpsc::channel::<()>();
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
        let t = threads.clone();
        let learner = std::thread::spawn(move || {
            t.learner_gives_way();
            let idle = current_policy();
            ready_tx.send(()).expect("the test waits");
            asked_rx.recv().expect("the test asks");
            (idle, current_policy())
        });
        ready_rx.recv().expect("the thread registers");
        threads.all_back_to_normal();
        asked_tx.send(()).expect("the thread waits");
        let (idle, after) = learner.join().expect("the thread runs");
        assert_eq!(idle, libc::SCHED_IDLE);
        // Root (or a raised RLIMIT_NICE) may put it back; anyone else leaves it idle (and logs why).
        assert!(
            after == libc::SCHED_OTHER || after == libc::SCHED_IDLE,
            "{after}"
        );
        // No writer registered, and a writer that is done is forgotten.
        assert_eq!(threads.writer.load(Ordering::Acquire), 0);
        let t = threads.clone();
        std::thread::spawn(move || {
            t.writer_gives_way();
            assert_ne!(t.writer.load(Ordering::Acquire), 0);
            t.writer_done();
        })
        .join()
        .expect("the thread runs");
        assert_eq!(threads.writer.load(Ordering::Acquire), 0);
        assert_eq!(current_policy(), libc::SCHED_OTHER, "only those threads");
    }
}
