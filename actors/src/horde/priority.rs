//! The Horde's threads run at a lower priority than the tick path's.
//!
//! The tick never waits for the Horde, but on a machine with few cores they compete for the CPU: a Horde
//! step of 4–9 ms every tick delayed the tick path's threads (tick → command p99 up to 2.7× that of the
//! same server without a Horde, `pavlov bench --horde`). A niced Horde thread yields a core to them; when
//! that leaves the Horde too little time it skips ticks, which it counts, as it must.

/// The nice value of the Horde's thread and of the checkpoint writers it starts (they inherit it).
pub(crate) const HORDE_NICE: i32 = 10;

/// Lowers the calling thread's priority to [`HORDE_NICE`] (or leaves a lower one) (Linux: a thread has its own nice value).
/// A failure is logged and otherwise ignored: the Horde runs at the normal priority then.
pub(crate) fn lower_this_thread() {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: gettid, getpriority and setpriority take plain integers and touch no memory of ours.
        let result = unsafe {
            let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
            // Only ever lower it (a server started with `nice` keeps its own, lower priority).
            let current = libc::getpriority(libc::PRIO_PROCESS, tid);
            libc::setpriority(libc::PRIO_PROCESS, tid, current.max(HORDE_NICE))
        };
        if result != 0 {
            tracing::debug!(
                "could not lower the Horde thread's priority: {}",
                std::io::Error::last_os_error()
            );
        }
    }
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    #[test]
    fn the_calling_thread_and_only_it_is_niced() {
        let before = std::thread::spawn(|| unsafe {
            libc::getpriority(
                libc::PRIO_PROCESS,
                libc::syscall(libc::SYS_gettid) as libc::id_t,
            )
        })
        .join()
        .unwrap();
        let niced = std::thread::spawn(|| {
            super::lower_this_thread();
            unsafe {
                libc::getpriority(
                    libc::PRIO_PROCESS,
                    libc::syscall(libc::SYS_gettid) as libc::id_t,
                )
            }
        })
        .join()
        .unwrap();
        assert_eq!(niced, before.max(super::HORDE_NICE));
        let after = std::thread::spawn(|| unsafe {
            libc::getpriority(
                libc::PRIO_PROCESS,
                libc::syscall(libc::SYS_gettid) as libc::id_t,
            )
        })
        .join()
        .unwrap();
        assert_eq!(after, before, "other threads keep their priority");
    }
}
