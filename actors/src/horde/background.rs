//! The Horde's threads give way to the tick: they run under Linux's `SCHED_IDLE` policy.
//!
//! On a machine with two cores the Horde's step (several ms every tick) shares the cores with the tick
//! path's threads (the timer thread, tokio's workers, the link). Under the normal policy a tick-path
//! thread woken on the Horde's core can wait for the scheduler's slice (about 3 ms) before it runs; under
//! `SCHED_IDLE` any normal thread that wakes preempts the Horde at once. An unprivileged process may
//! always lower a thread to `SCHED_IDLE`. The cost is that the Horde gets almost no CPU while the
//! machine is busy with other work: it then skips ticks, counted and shown, and control is untouched.

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

#[cfg(target_os = "linux")]
fn set_policy(policy: i32) -> std::io::Result<()> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: `sched_setscheduler` reads `param` (a valid, initialised struct that outlives the call);
    // pid 0 names the calling thread.
    let rc = unsafe { libc::sched_setscheduler(0, policy, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

#[cfg(not(target_os = "linux"))]
fn set_policy(_policy: i32) -> std::io::Result<()> {
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
}
