//! Heap allocations per simulated tick on the stepped virtual-time path
//! (`actors/src/experiment/stepped.rs`), counted by a counting global allocator over steady-state ticks
//! of the stall study's configuration. The bound is what the path guarantees once warm: every buffer on
//! it is reused, and what is still allocated per tick is listed in the book (performance.md, "Virtual
//! time"). This binary holds one test so that no other test allocates while it counts.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};

use pavlov::config::Config;
use pavlov_actors::experiment::stepped_bench_support::SteppedRun;

/// Counts every allocation and reallocation, then hands it to the system allocator.
struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: every call is forwarded unchanged to `System`, which upholds `GlobalAlloc`'s contract; the
// counter is an atomic and allocates nothing.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded with the caller's layout.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged; `ptr` came from this allocator, i.e. from `System`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged; `ptr` came from this allocator, i.e. from `System`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Ticks run before counting (buffers grow to their working size).
const WARM_UP: u64 = 500;
/// Ticks counted.
const COUNTED: u64 = 2000;
/// Allocations allowed per tick (see the module doc): the tick's record (`Arc<TickRecord>`), its
/// observation vector, its predictions' vector and each prediction's name (one prediction in the stall
/// configuration), the gate's inputs handed to gating, and on a tick whose gate engages the rule's name.
const PER_TICK: u64 = 6;

#[test]
fn a_steady_state_stepped_tick_allocates_at_most_its_bound() {
    let config = Config::from_toml(include_str!("../config/stall.toml")).expect("stall config");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
        .expect("runtime");
    let counted = rt.block_on(async {
        let mut run = SteppedRun::start(&config).await.expect("a stepped run");
        for _ in 0..WARM_UP {
            run.tick().expect("tick");
        }
        let before = ALLOCATIONS.load(Ordering::Relaxed);
        for _ in 0..COUNTED {
            drop(run.tick().expect("tick"));
        }
        ALLOCATIONS.load(Ordering::Relaxed) - before
    });
    println!(
        "{counted} allocations over {COUNTED} ticks ({:.2} per tick)",
        counted as f64 / COUNTED as f64
    );
    assert!(
        counted <= PER_TICK * COUNTED,
        "{counted} allocations over {COUNTED} ticks: more than {PER_TICK} per tick"
    );
}
