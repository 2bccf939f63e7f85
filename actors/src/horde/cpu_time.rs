//! The CPU time of the calling thread (`CLOCK_THREAD_CPUTIME_ID`): what a Horde step costs, apart from
//! the time the thread waited for a core (under `SCHED_IDLE` on a busy machine, most of its wall time).

use std::time::Duration;

/// The CPU time the calling thread has used so far (`None` where the clock is not available).
#[cfg(target_os = "linux")]
pub(crate) fn thread_cpu_time() -> Option<Duration> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `clock_gettime` writes one `timespec` into `ts`, a valid, initialised struct that outlives
    // the call; the clock id is a constant the kernel knows.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return None;
    }
    let secs = u64::try_from(ts.tv_sec).ok()?;
    let nanos = u32::try_from(ts.tv_nsec).ok()?;
    Some(Duration::new(secs, nanos))
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn thread_cpu_time() -> Option<Duration> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_that_works_uses_cpu_time_and_one_that_sleeps_uses_little() {
        let Some(start) = thread_cpu_time() else {
            return;
        };
        let mut x = 0u64;
        let wall = std::time::Instant::now();
        while wall.elapsed() < Duration::from_millis(20) {
            x = std::hint::black_box(x.wrapping_add(1));
        }
        let worked = thread_cpu_time().unwrap_or(start) - start;
        assert!(worked > Duration::ZERO, "{worked:?}");
        let before_sleep = thread_cpu_time().unwrap_or(start);
        std::thread::sleep(Duration::from_millis(50));
        let slept = thread_cpu_time().unwrap_or(before_sleep) - before_sleep;
        // Sleeping costs a few µs of CPU; the 50 ms asleep are not counted.
        assert!(slept < Duration::from_millis(25), "{slept:?}");
    }
}
