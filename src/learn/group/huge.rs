//! Weight matrices on transparent huge pages, where the kernel offers them.
//!
//! A tick reads a few hundred rows scattered over a matrix of hundreds of megabytes: with 4 KiB pages
//! nearly every row (or block of a row, [`super::fused`]) is a miss in the TLB, the cache of address
//! translations, and a walk of the page tables. On 2 MiB pages the whole matrix needs a few hundred
//! translations. Linux backs a region with huge pages when asked to (`madvise(MADV_HUGEPAGE)`, honoured
//! when `/sys/kernel/mm/transparent_hugepage/enabled` is `always` or `madvise`); elsewhere, or when the
//! kernel declines, the memory is ordinary memory and nothing else changes.

/// Huge pages are 2 MiB on x86-64 and (by default) aarch64; asking for a range of other alignment is
/// harmless.
const HUGE_PAGE: usize = 2 << 20;

/// Below this, a matrix is left on ordinary pages (a huge page would be mostly empty).
const WORTH_IT: usize = 4 * HUGE_PAGE;

/// An empty vector with room for `len` weights, its memory (not yet written, so not yet backed by any
/// page) advised to be backed by huge pages when it is large enough.
pub(crate) fn weight_vec<W>(len: usize) -> Vec<W> {
    let v: Vec<W> = Vec::with_capacity(len);
    let bytes = len.saturating_mul(std::mem::size_of::<W>());
    if bytes >= WORTH_IT {
        advise_huge(v.as_ptr().cast::<u8>(), bytes);
    }
    v
}

/// Asks the kernel to back the whole huge pages within `[start, start + bytes)` with huge pages.
#[cfg(target_os = "linux")]
fn advise_huge(start: *const u8, bytes: usize) {
    let from = (start as usize).next_multiple_of(HUGE_PAGE);
    let to = (start as usize).saturating_add(bytes) / HUGE_PAGE * HUGE_PAGE;
    if to <= from {
        return;
    }
    // SAFETY: `[from, to)` lies inside the allocation of `bytes` bytes at `start` that the caller's
    // vector owns, and is page-aligned; MADV_HUGEPAGE changes only how the kernel backs those pages,
    // never their contents, their validity or who may use them. A refusal (an old kernel, huge pages
    // turned off) is an error code and leaves the memory as it was.
    let rc = unsafe { libc::madvise(from as *mut libc::c_void, to - from, libc::MADV_HUGEPAGE) };
    let _ = rc;
}

#[cfg(not(target_os = "linux"))]
fn advise_huge(_start: *const u8, _bytes: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_weight_vector_has_room_and_holds_what_is_put_in_it() {
        let mut big: Vec<f32> = weight_vec(3 << 20);
        assert!(big.capacity() >= 3 << 20 && big.is_empty());
        big.resize(3 << 20, 1.5);
        assert!(big.iter().all(|&w| w == 1.5));
        let small: Vec<f64> = weight_vec(10);
        assert!(small.capacity() >= 10);
    }
}
