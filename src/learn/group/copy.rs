//! [`RowCopy`]: a copy of a group's weights taken a few rows at a time while the group keeps learning.
//!
//! A Horde's weights are hundreds of megabytes; copying them at once would take a whole tick or more.
//! Instead a copy starts with the small parts of the state (traces, epochs, the previous tick) and an
//! empty weight matrix; between ticks the learner copies a budget of rows, and *before it writes a row
//! that is not copied yet, it copies that row first* (copy-on-write, a row at a time). When every row is
//! copied, the copy is the state at the moment it started, exactly.

use super::Weight;

/// A buffer for the weights of `len` copies whose memory is written, and so mapped, now: a copy into it
/// later faults no page in (a fresh allocation of hundreds of megabytes would fault in every page while
/// it is copied, and the kernel's page-table lock those faults take is one the tick's threads need).
/// Every weight is NaN until a copy overwrites it.
pub fn snapshot_buffer<W: Weight>(len: usize) -> Vec<W> {
    vec![W::from_f64(f64::NAN); len]
}

/// A copy in progress (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RowCopy<W> {
    cols: usize,
    copied: Vec<bool>,
    w0: Vec<W>,
    /// Rows below this are copied or were copied on write.
    cursor: usize,
    left: usize,
}

impl<W: Weight> RowCopy<W> {
    /// An empty copy of `features` rows of `cols` weights, into `buffer` when it has the size (a buffer
    /// of an earlier copy, whose memory is mapped already), else into newly allocated memory.
    pub fn new(features: usize, cols: usize, buffer: Option<Vec<W>>) -> Self {
        let w0 = match buffer {
            Some(b) if b.len() == features * cols => b,
            _ => vec![W::default(); features * cols],
        };
        RowCopy {
            cols,
            copied: vec![false; features],
            w0,
            cursor: 0,
            left: features,
        }
    }

    /// Copies row `f` of `live` unless it is copied already: call before writing the row.
    #[inline]
    pub fn preserve(&mut self, f: usize, live: &[W]) {
        if !self.copied[f] {
            self.copy_row(f, live);
        }
    }

    fn copy_row(&mut self, f: usize, live: &[W]) {
        let (a, b) = (f * self.cols, (f + 1) * self.cols);
        self.w0[a..b].copy_from_slice(&live[a..b]);
        self.copied[f] = true;
        self.left -= 1;
    }

    /// Copies up to `rows` more rows of `live`; returns whether the copy is complete.
    pub fn copy_some(&mut self, live: &[W], rows: usize) -> bool {
        let mut budget = rows;
        while budget > 0 && self.cursor < self.copied.len() {
            if !self.copied[self.cursor] {
                self.copy_row(self.cursor, live);
                budget -= 1;
            }
            self.cursor += 1;
        }
        self.is_complete()
    }

    /// Whether every row is copied.
    pub fn is_complete(&self) -> bool {
        self.left == 0
    }

    /// Rows still to copy.
    pub fn left(&self) -> usize {
        self.left
    }

    /// The copied weights (complete or not).
    pub fn into_weights(self) -> Vec<W> {
        self.w0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_written_during_the_copy_keep_their_old_values() {
        let mut live: Vec<f32> = (0..12).map(|v| v as f32).collect(); // 4 rows of 3
        let mut copy = RowCopy::new(4, 3, None);
        assert!(!copy.copy_some(&live, 1));
        // Row 2 is about to be written: preserved first.
        copy.preserve(2, &live);
        live[6..9].fill(-1.0);
        // Row 0 was copied already: writing it changes nothing in the copy.
        copy.preserve(0, &live);
        live[0] = 99.0;
        assert_eq!(copy.left(), 2);
        assert!(copy.copy_some(&live, 10));
        let w = copy.into_weights();
        assert_eq!(w, (0..12).map(|v| v as f32).collect::<Vec<_>>());
    }

    #[test]
    fn a_buffer_of_the_right_size_is_reused_and_every_row_overwritten() {
        let live: Vec<f32> = (0..6).map(|v| v as f32).collect(); // 2 rows of 3
        let old = vec![f32::NAN; 6];
        let at = old.as_ptr();
        let mut copy = RowCopy::new(2, 3, Some(old));
        assert!(copy.copy_some(&live, 2));
        let w = copy.into_weights();
        assert_eq!(w.as_ptr(), at, "the same memory");
        assert_eq!(w, live);
        // A buffer of another size is not used.
        let copy = RowCopy::<f32>::new(2, 3, Some(vec![1.0; 5]));
        assert_eq!(copy.into_weights(), vec![0.0; 6]);
    }
}
