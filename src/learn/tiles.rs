//! Tile coding: continuous inputs in `[0, 1]` to sparse binary features (Sutton & Barto 1998, §8.3.2).
//!
//! A *tiling* partitions its input domain into equal tiles; exactly one tile of each tiling is active
//! for a valid input, so a coder with T tilings activates at most T of its features. Feature indices are
//! laid out tiling by tiling: tiling `k` owns the block `[k·B, (k+1)·B)` where B is its tile count.
//!
//! Two layouts, as in Modayil & Sutton:
//! - [`TileSpec::OneDimTilings`]: T tilings of N tiles per input dimension, tiling k shifted by k/T of a
//!   tile (stall experiment: T = 1, 44 dimensions × 10 tiles = 440 features, 44 active; a nexting-style
//!   Horde uses several, e.g. 44 × 11 tilings × 12 tiles = 5,808 features, 484 active, as in \[tiles3\]'s
//!   offsets for one dimension). Feature of dimension d, tiling k: `(d·T + k)·N + bin(x_d, k/T)`.
//! - [`TileSpec::PairTilings`]: 2-D tilings of N × N tiles over pairs of inputs, each with its own
//!   offset (interaction experiment: 5 tilings × 100 = 500 features, 5 active). Feature of pair k over
//!   inputs (i, j): `k·N² + bin(x_i)·N + bin(x_j)`.
//!
//! Binning, with N tiles and offset o (a fraction of one tile width, `0 ≤ o < 1`; 0 for one-dimensional
//! tilings): `bin(x) = min(floor(clamp(x, 0, 1)·N + o), N − 1)`.
//! - A finite input outside `[0, 1]` is clamped first, so it lands in the first or last tile.
//! - The value 1.0 falls in the last tile (`floor(N + o) = N` is clamped to `N − 1`).
//! - An offset shifts every tile boundary down by o tile widths: the first tile is `(1 − o)/N` wide,
//!   the last `(1 + o)/N`, and two tilings over the same pair with offsets 0 and 0.5 split each other's
//!   tiles in half (the count stays N per dimension, as in the paper's 10 × 10 = 100 tiles).
//! - A non-finite input (NaN, ±∞, or an input position beyond the given slice) activates **no feature
//!   in that tiling**: the other tilings are unaffected, and the caller sees fewer active features.

use serde::{Deserialize, Serialize};

use super::LearnError;

/// What a tile coder looks like, before validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum TileSpec {
    /// `tilings` tilings of `tiles` tiles for each of the inputs `0..dims`, tiling k offset by
    /// k/`tilings` of a tile.
    OneDimTilings {
        dims: usize,
        tiles: usize,
        tilings: usize,
    },
    /// One 2-D tiling of `tiles × tiles` per pair `(input i, input j, offset as a fraction of a tile)`.
    PairTilings {
        pairs: Vec<(usize, usize, f64)>,
        tiles: usize,
    },
}

/// A validated tile coder (see the module documentation for the exact binning rule).
#[derive(Debug, Clone, PartialEq)]
pub struct TileCoder {
    spec: TileSpec,
    num_features: usize,
    num_inputs: usize,
}

impl TileCoder {
    /// Validates `spec`: at least one tile and one tiling, offsets in `[0, 1)`, at most
    /// [`super::bounds::MAX_FEATURES`] features.
    pub fn new(spec: TileSpec) -> Result<Self, LearnError> {
        let (tilings, tiles_per_tiling, num_inputs) = match &spec {
            TileSpec::OneDimTilings {
                dims,
                tiles,
                tilings,
            } => (dims.saturating_mul(*tilings), Some(*tiles), *dims),
            TileSpec::PairTilings { pairs, tiles } => {
                let squared = tiles.checked_mul(*tiles);
                let mut inputs = 0;
                for &(i, j, offset) in pairs {
                    if !(0.0..1.0).contains(&offset) {
                        return Err(LearnError::InvalidOffset(offset));
                    }
                    inputs = inputs.max(i.saturating_add(1)).max(j.saturating_add(1));
                }
                (pairs.len(), squared, inputs)
            }
        };
        let tiles = match &spec {
            TileSpec::OneDimTilings { tiles, .. } | TileSpec::PairTilings { tiles, .. } => *tiles,
        };
        if tiles == 0 {
            return Err(LearnError::NoTiles(tiles));
        }
        if tilings == 0 {
            return Err(LearnError::NoTilings);
        }
        let num_features = tiles_per_tiling
            .and_then(|b| b.checked_mul(tilings))
            .filter(|&n| n <= super::bounds::MAX_FEATURES)
            .ok_or(LearnError::TooManyFeatures(tilings, tiles))?;
        Ok(TileCoder {
            spec,
            num_features,
            num_inputs,
        })
    }

    /// One tiling of `tiles` tiles per input dimension `0..dims`.
    pub fn one_dim(dims: usize, tiles: usize) -> Result<Self, LearnError> {
        TileCoder::one_dim_offset(dims, tiles, 1)
    }

    /// `tilings` tilings of `tiles` tiles per input dimension `0..dims`, evenly offset.
    pub fn one_dim_offset(dims: usize, tiles: usize, tilings: usize) -> Result<Self, LearnError> {
        TileCoder::new(TileSpec::OneDimTilings {
            dims,
            tiles,
            tilings,
        })
    }

    /// One `tiles × tiles` tiling per `(i, j, offset)` pair.
    pub fn pairs(pairs: Vec<(usize, usize, f64)>, tiles: usize) -> Result<Self, LearnError> {
        TileCoder::new(TileSpec::PairTilings { pairs, tiles })
    }

    /// The spec this coder was built from.
    pub fn spec(&self) -> &TileSpec {
        &self.spec
    }

    /// The length of the binary feature vector.
    pub fn num_features(&self) -> usize {
        self.num_features
    }

    /// The number of tilings, which is the number of active features for a fully valid input.
    pub fn num_tilings(&self) -> usize {
        match &self.spec {
            TileSpec::OneDimTilings { dims, tilings, .. } => dims * tilings,
            TileSpec::PairTilings { pairs, .. } => pairs.len(),
        }
    }

    /// The input length the coder reads (inputs beyond the slice count as invalid).
    pub fn num_inputs(&self) -> usize {
        self.num_inputs
    }

    /// Writes the indices of the active features for `input` into `out` (cleared first), in increasing
    /// order, at most one per tiling. Does not allocate once `out` has `num_tilings()` capacity.
    pub fn active(&self, input: &[f64], out: &mut Vec<usize>) {
        out.clear();
        match &self.spec {
            TileSpec::OneDimTilings {
                dims,
                tiles,
                tilings: 1,
            } => {
                // `bin(x, tiles, 0.0)` inlined for the paper's coder, one bin per input: the same
                // arithmetic with a 32-bit cast (the bin is at most `tiles`, far below 2³²), which took
                // the stall step's tile coding from 120 to 85 ns (`cargo bench --bench learn`).
                if *tiles == 0 {
                    return;
                }
                let input = input.get(..*dims).unwrap_or(input);
                // Every input's feature is written at the next free place and the place advances
                // only for a finite input (a non-finite one computes a bin that is then overwritten
                // or cut off): no branch and no capacity check per input, the same features.
                out.resize(input.len(), 0);
                let mut count = 0;
                for (d, &x) in input.iter().enumerate() {
                    if let Some(slot) = out.get_mut(count) {
                        *slot = d * tiles + one_tiling_bin(x, *tiles);
                    }
                    count += usize::from(x.is_finite());
                }
                out.truncate(count);
            }
            TileSpec::OneDimTilings {
                dims,
                tiles,
                tilings,
            } => {
                let step = 1.0 / *tilings as f64;
                for (d, &x) in input.iter().take(*dims).enumerate() {
                    for k in 0..*tilings {
                        if let Some(b) = bin(x, *tiles, k as f64 * step) {
                            out.push((d * tilings + k) * tiles + b);
                        }
                    }
                }
            }
            TileSpec::PairTilings { pairs, tiles } => {
                let block = tiles * tiles;
                for (k, &(i, j, offset)) in pairs.iter().enumerate() {
                    let x = input.get(i).copied().unwrap_or(f64::NAN);
                    let y = input.get(j).copied().unwrap_or(f64::NAN);
                    if let (Some(bx), Some(by)) = (bin(x, *tiles, offset), bin(y, *tiles, offset)) {
                        out.push(k * block + bx * tiles + by);
                    }
                }
            }
        }
    }
}

impl TileCoder {
    /// [`TileCoder::active`] of `input`, given that `out` holds `active` of `previous`: for the paper's
    /// coder (one tiling per dimension) when every input of both ticks is finite, only the dimensions
    /// whose input changed (bit for bit) are binned again, as a feature is a function of its own
    /// input alone; otherwise `active`. The same features either way.
    pub fn active_since(&self, input: &[f64], previous: &[f64], out: &mut Vec<usize>) {
        let TileSpec::OneDimTilings {
            dims,
            tiles,
            tilings: 1,
        } = &self.spec
        else {
            self.active(input, out);
            return;
        };
        let input = input.get(..*dims).unwrap_or(input);
        let previous = previous.get(..*dims).unwrap_or(previous);
        // `out` has a feature for every previous input only when all of them were finite.
        if *tiles == 0 || previous.len() != input.len() || out.len() != input.len() {
            self.active(input, out);
            return;
        }
        for (d, ((&x, &was), slot)) in input.iter().zip(previous).zip(out.iter_mut()).enumerate() {
            if x.to_bits() == was.to_bits() {
                continue;
            }
            if !x.is_finite() {
                self.active(input, out);
                return;
            }
            *slot = d * tiles + one_tiling_bin(x, *tiles);
        }
    }
}

/// `bin(x, tiles, 0.0)` for a finite `x` (and 0 for NaN), inlined for the paper's coder: the same
/// arithmetic with a 32-bit cast (the bin is at most `tiles`, far below 2³²), which took the stall
/// step's tile coding from 120 to 85 ns (`cargo bench --bench learn`). `tiles` is not 0.
#[inline(always)]
fn one_tiling_bin(x: f64, tiles: usize) -> usize {
    ((x.clamp(0.0, 1.0) * tiles as f64) as u32 as usize).min(tiles - 1)
}

/// The tile of `x` among `tiles` tiles shifted by `offset` tile widths; `None` for a non-finite `x`.
#[inline]
fn bin(x: f64, tiles: usize, offset: f64) -> Option<usize> {
    if !x.is_finite() || tiles == 0 {
        return None;
    }
    let scaled = x.clamp(0.0, 1.0) * tiles as f64 + offset;
    // `scaled` is finite and >= 0 here, where truncation is `floor` (without its library call, which
    // was a sixth of a learning step); the float-to-int cast saturates, so it cannot overflow.
    Some((scaled as usize).min(tiles - 1))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn interaction_pairs() -> Vec<(usize, usize, f64)> {
        // left elbow 0, its average 1, right elbow 2, its average 3.
        vec![
            (0, 1, 0.0),
            (0, 1, 0.5),
            (2, 3, 0.0),
            (2, 3, 0.5),
            (0, 2, 0.0),
        ]
    }

    #[test]
    fn bins_follow_the_documented_rule() {
        assert_eq!(bin(0.0, 10, 0.0), Some(0));
        assert_eq!(bin(0.0999, 10, 0.0), Some(0));
        assert_eq!(bin(0.1, 10, 0.0), Some(1));
        assert_eq!(bin(0.95, 10, 0.0), Some(9));
        assert_eq!(bin(1.0, 10, 0.0), Some(9));
        assert_eq!(bin(-3.0, 10, 0.0), Some(0));
        assert_eq!(bin(7.0, 10, 0.0), Some(9));
        assert_eq!(bin(0.05, 10, 0.5), Some(1));
        assert_eq!(bin(0.04, 10, 0.5), Some(0));
        assert_eq!(bin(0.96, 10, 0.5), Some(9));
        assert_eq!(bin(f64::NAN, 10, 0.0), None);
        assert_eq!(bin(f64::INFINITY, 10, 0.0), None);
        assert_eq!(bin(f64::NEG_INFINITY, 10, 0.0), None);
    }

    #[test]
    fn offset_tilings_split_each_tile() {
        // 2 dimensions, 3 tilings of 4 tiles: offsets 0, 1/3 and 2/3 of a tile.
        let c = TileCoder::one_dim_offset(2, 4, 3).unwrap();
        assert_eq!((c.num_features(), c.num_tilings()), (24, 6));
        let mut out = Vec::new();
        // x = 0.2: 0.8 + {0, 1/3, 2/3} → tiles 0, 1, 1; y = 0.9: 3.6 + … → 3, 3, 3 (clamped).
        c.active(&[0.2, 0.9], &mut out);
        assert_eq!(out, vec![0, 5, 9, 15, 19, 23]);
        // A missing dimension drops all of its tilings.
        c.active(&[f64::NAN, 0.0], &mut out);
        assert_eq!(out, vec![12, 16, 20]);
        // One tiling is exactly the paper's layout.
        let one = TileCoder::one_dim_offset(44, 10, 1).unwrap();
        assert_eq!(one, TileCoder::one_dim(44, 10).unwrap());
    }

    #[test]
    fn sizes_match_the_paper() {
        let stall = TileCoder::one_dim(44, 10).unwrap();
        assert_eq!((stall.num_features(), stall.num_tilings()), (440, 44));
        let command = TileCoder::pairs(interaction_pairs(), 10).unwrap();
        assert_eq!((command.num_features(), command.num_tilings()), (500, 5));
        assert_eq!(command.num_inputs(), 4);
    }

    #[test]
    fn invalid_specs_are_rejected() {
        assert_eq!(TileCoder::one_dim(44, 0), Err(LearnError::NoTiles(0)));
        assert_eq!(TileCoder::one_dim(0, 10), Err(LearnError::NoTilings));
        assert_eq!(TileCoder::pairs(vec![], 10), Err(LearnError::NoTilings));
        assert_eq!(
            TileCoder::pairs(vec![(0, 1, 1.0)], 10),
            Err(LearnError::InvalidOffset(1.0))
        );
        assert!(TileCoder::pairs(vec![(0, 1, f64::NAN)], 10).is_err());
        assert!(TileCoder::pairs(vec![(0, 1, -0.1)], 10).is_err());
        assert!(matches!(
            TileCoder::one_dim(usize::MAX, 2),
            Err(LearnError::TooManyFeatures(..))
        ));
        assert!(matches!(
            TileCoder::pairs(vec![(0, 1, 0.0)], usize::MAX),
            Err(LearnError::TooManyFeatures(..))
        ));
    }

    #[test]
    fn a_pair_tiling_indexes_row_major_within_its_block() {
        let coder = TileCoder::pairs(interaction_pairs(), 10).unwrap();
        let mut out = Vec::new();
        coder.active(&[0.25, 0.71, 0.0, 1.0], &mut out);
        // pair 0 (0.25, 0.71), o = 0: (2, 7) -> 27; pair 1, o = .5: (3, 7) -> 100 + 37;
        // pair 2 (0.0, 1.0), o = 0: (0, 9) -> 200 + 9; pair 3, o = .5: (0, 9) -> 300 + 9;
        // pair 4 (0.25, 0.0), o = 0: (2, 0) -> 400 + 20.
        assert_eq!(out, vec![27, 137, 209, 309, 420]);
    }

    #[test]
    fn invalid_inputs_drop_only_their_tilings() {
        let one = TileCoder::one_dim(4, 10).unwrap();
        let mut out = Vec::new();
        one.active(&[0.5, f64::NAN, 2.0, f64::INFINITY], &mut out);
        assert_eq!(out, vec![5, 29]);
        one.active(&[0.5], &mut out);
        assert_eq!(out, vec![5]);
        let pairs = TileCoder::pairs(interaction_pairs(), 10).unwrap();
        pairs.active(&[0.5, 0.5, f64::NAN, 0.5], &mut out);
        assert_eq!(out.len(), 2);
        assert!(out.iter().all(|&i| i < 200));
    }

    fn unit() -> impl Strategy<Value = f64> {
        prop_oneof![0.0..=1.0f64, Just(0.0), Just(1.0), Just(0.1), Just(0.9)]
    }

    proptest! {
        /// Re-binning only the inputs that changed gives the features `active` gives, for the paper's coder
        /// and a multi-tiling one, with inputs that repeat, change, leave `[0, 1]` or are not finite.
        #[test]
        fn coding_only_what_changed_matches_coding_everything(
            ticks in proptest::collection::vec(
                proptest::collection::vec(
                    prop_oneof![
                        4 => prop::sample::select(vec![0.0, 0.25, 0.5, 0.999, 1.0]),
                        2 => -0.5..1.5f64,
                        1 => prop::sample::select(vec![f64::NAN, f64::INFINITY, -0.0]),
                    ],
                    6,
                ),
                1..12,
            ),
            tilings in 1usize..3,
        ) {
            let coder = TileCoder::one_dim_offset(6, 10, tilings).unwrap();
            let (mut previous, mut out): (Vec<f64>, Vec<usize>) = (Vec::new(), Vec::new());
            for input in ticks {
                coder.active_since(&input, &previous, &mut out);
                let mut full = Vec::new();
                coder.active(&input, &mut full);
                prop_assert_eq!(&out, &full);
                previous = input;
            }
        }
    }

    proptest! {
        #[test]
        fn one_dim_activates_one_feature_per_dimension(input in prop::collection::vec(unit(), 44)) {
            let coder = TileCoder::one_dim(44, 10).unwrap();
            let mut out = Vec::new();
            coder.active(&input, &mut out);
            prop_assert_eq!(out.len(), 44);
            for (d, &i) in out.iter().enumerate() {
                prop_assert!(i >= d * 10 && i < (d + 1) * 10, "feature {} of tiling {}", i, d);
            }
            prop_assert!(out.windows(2).all(|w| w[0] < w[1]));
        }

        #[test]
        fn pairs_activate_one_feature_per_tiling(input in prop::collection::vec(unit(), 4)) {
            let coder = TileCoder::pairs(interaction_pairs(), 10).unwrap();
            let mut out = Vec::new();
            coder.active(&input, &mut out);
            prop_assert_eq!(out.len(), 5);
            for (k, &i) in out.iter().enumerate() {
                prop_assert!(i >= k * 100 && i < (k + 1) * 100, "feature {} of tiling {}", i, k);
            }
            prop_assert!(out.windows(2).all(|w| w[0] < w[1]));
        }

        #[test]
        fn the_paper_coders_fast_path_is_the_documented_rule(
            input in prop::collection::vec(prop::num::f64::ANY, 44),
            tiles in 1usize..=1000,
        ) {
            let coder = TileCoder::one_dim(44, tiles).unwrap();
            let mut out = Vec::new();
            coder.active(&input, &mut out);
            let expected: Vec<usize> = input
                .iter()
                .enumerate()
                .filter_map(|(d, &x)| bin(x, tiles, 0.0).map(|b| d * tiles + b))
                .collect();
            prop_assert_eq!(out, expected);
        }

        #[test]
        fn any_finite_input_is_clamped_into_a_tile(x in prop::num::f64::ANY, o in 0.0..1.0f64) {
            let b = bin(x, 10, o);
            prop_assert_eq!(b.is_some(), x.is_finite());
            if let Some(b) = b {
                prop_assert!(b < 10);
            }
        }
    }
}
