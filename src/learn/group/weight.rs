//! [`Weight`]: the element type of a [`super::TraceGroup`]'s weight rows (`f32` for a Horde of thousands
//! of predictions, `f64` where a prediction must match the reference learner), and the row kernels
//! the group's tick is made of. Each kernel is a plain loop over two slices of equal length that the
//! compiler vectorises; a row holds one weight per prediction of the group (feature-major layout), so a
//! kernel streams one contiguous row per active feature.

use std::fmt::Debug;
use std::ops::{Add, Mul};

/// A floating-point weight.
pub trait Weight:
    Copy + Debug + Default + PartialEq + Send + Sync + 'static + Add<Output = Self> + Mul<Output = Self>
{
    /// `"f32"` or `"f64"`, for messages and checkpoints.
    const NAME: &'static str;
    /// The smallest product of trace decays an epoch runs down to before a new one starts (see
    /// `super::epochs`). Within an epoch a row's deferred base holds `w − c·A`, where `c` grows to
    /// about `1/FLOOR` times the trace; `1/FLOOR` is how many times larger than the weight the
    /// cancelling terms can get, so the floor costs `log10(1/FLOOR)` decimal digits of the weight's
    /// precision: 4 of f64's 16, 2 of f32's 7.
    const EPOCH_FLOOR: f64;
    /// Magnitudes below this are far from overflowing in every operation of a tick (a sum of two or a
    /// product by a trace coefficient): the divergence guard of [`super::TraceGroup`] checks against it.
    const SAFE: f64;
    /// The value nearest to `x`.
    fn from_f64(x: f64) -> Self;
    /// As an `f64` (exact).
    fn to_f64(self) -> f64;
    /// Whether the value is neither infinite nor NaN.
    fn finite(self) -> bool;
    /// Bytes of one value.
    const BYTES: usize;
    /// Appends the value's little-endian bytes.
    fn put_le(self, out: &mut Vec<u8>);
    /// The value of `BYTES` little-endian bytes.
    fn get_le(bytes: &[u8]) -> Self;
}

impl Weight for f32 {
    const NAME: &'static str = "f32";
    const EPOCH_FLOOR: f64 = 1e-2;
    const SAFE: f64 = 1e34;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
    const BYTES: usize = 4;
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn get_le(bytes: &[u8]) -> Self {
        let mut b = [0; 4];
        b.copy_from_slice(&bytes[..4]);
        f32::from_le_bytes(b)
    }
}

impl Weight for f64 {
    const NAME: &'static str = "f64";
    const EPOCH_FLOOR: f64 = 1e-4;
    const SAFE: f64 = 1e300;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }
    const BYTES: usize = 8;
    fn put_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn get_le(bytes: &[u8]) -> Self {
        let mut b = [0; 8];
        b.copy_from_slice(&bytes[..8]);
        f64::from_le_bytes(b)
    }
}

/// `row[i] += k · v[i]` for every `i` (the slices have the same length).
#[inline]
pub(crate) fn add_scaled<W: Weight>(row: &mut [W], k: W, v: &[W]) {
    for (r, &x) in row.iter_mut().zip(v) {
        *r = *r + k * x;
    }
}

/// `acc[i] += row[i]` for every `i`.
#[inline]
pub(crate) fn accumulate<W: Weight>(acc: &mut [W], row: &[W]) {
    for (a, &r) in acc.iter_mut().zip(row) {
        *a = *a + r;
    }
}

/// Rows at least this long are worth the check for wider vectors ([`add_scaled_wide`]).
const WIDE: usize = 64;

/// [`add_scaled`] with AVX2 instructions where the CPU has them and the row is long: the same
/// operations element by element (Rust never fuses a multiply and an add on its own), so the same bits.
pub(crate) fn add_scaled_wide<W: Weight>(row: &mut [W], k: W, v: &[W]) {
    #[cfg(target_arch = "x86_64")]
    if row.len() >= WIDE && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked), the only requirement of a `target_feature`
        // function.
        unsafe { add_scaled_avx2(row, k, v) };
        return;
    }
    add_scaled(row, k, v);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_scaled_avx2<W: Weight>(row: &mut [W], k: W, v: &[W]) {
    add_scaled(row, k, v);
}

/// [`accumulate`] with AVX2 instructions where the CPU has them and the row is long (as
/// [`add_scaled_wide`]).
pub(crate) fn accumulate_wide<W: Weight>(acc: &mut [W], row: &[W]) {
    #[cfg(target_arch = "x86_64")]
    if row.len() >= WIDE && std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: as in `add_scaled_wide`.
        unsafe { accumulate_avx2(acc, row) };
        return;
    }
    accumulate(acc, row);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn accumulate_avx2<W: Weight>(acc: &mut [W], row: &[W]) {
    accumulate(acc, row);
}

/// `acc[i] += row[i]`, then `row[i] += k · v[i]`, for every `i`: [`accumulate`] and [`add_scaled`] of
/// the same row, reading it once.
#[inline]
pub(crate) fn accumulate_and_add_scaled<W: Weight>(acc: &mut [W], row: &mut [W], k: W, v: &[W]) {
    for ((a, r), &x) in acc.iter_mut().zip(row.iter_mut()).zip(v) {
        let w = *r;
        *a = *a + w;
        *r = w + k * x;
    }
}

/// `acc[i] += row[i]`, then `row[i] += k · e[i]`, then `row[i] += m · v[i]`, for every `i`: a row read,
/// brought forward into a new epoch and touched, in one loop.
#[inline]
pub(crate) fn accumulate_forward_and_add_scaled<W: Weight>(
    acc: &mut [W],
    row: &mut [W],
    k: W,
    e: &[W],
    m: W,
    v: &[W],
) {
    for (((a, r), &x), &y) in acc.iter_mut().zip(row.iter_mut()).zip(e).zip(v) {
        let w = *r;
        *a = *a + w;
        let w = w + k * x;
        *r = w + m * y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_compute_what_they_say() {
        let mut row = [1.0f32, 2.0, 3.0];
        add_scaled(&mut row, 0.5, &[2.0, -4.0, 0.0]);
        assert_eq!(row, [2.0, 0.0, 3.0]);
        let mut acc = [0.0f64; 3];
        accumulate(&mut acc, &[1.0, 2.0, 3.0]);
        accumulate(&mut acc, &[0.5, 0.5, 0.5]);
        assert_eq!(acc, [1.5, 2.5, 3.5]);
        let long: Vec<f32> = (0..100).map(|i| i as f32 * 0.37).collect();
        let (mut narrow, mut wide) = (long.clone(), long.clone());
        add_scaled(&mut narrow, -0.3, &long);
        add_scaled_wide(&mut wide, -0.3, &long);
        assert_eq!(narrow, wide);
        accumulate(&mut narrow, &long);
        accumulate_wide(&mut wide, &long);
        assert_eq!(narrow, wide);
        let mut row = [1.0f32, 2.0, 3.0];
        let mut acc = [0.5f32; 3];
        accumulate_and_add_scaled(&mut acc, &mut row, -2.0, &[1.0, 0.5, 0.0]);
        assert_eq!((acc, row), ([1.5, 2.5, 3.5], [-1.0, 1.0, 3.0]));
        let mut acc = [0.0f32; 3];
        accumulate_forward_and_add_scaled(
            &mut acc,
            &mut row,
            2.0,
            &[1.0, 1.0, 1.0],
            1.0,
            &[0.0, 1.0, 2.0],
        );
        assert_eq!((acc, row), ([-1.0, 1.0, 3.0], [1.0, 4.0, 7.0]));
    }

    #[test]
    fn conversions_round_to_nearest() {
        assert_eq!(f32::from_f64(0.1), 0.1f32);
        assert_eq!(0.1f32.to_f64(), f64::from(0.1f32));
        assert!(!f32::from_f64(1e300).finite());
        assert!(f64::from_f64(1e300).finite());
    }
}
