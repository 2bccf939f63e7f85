//! The exponentially weighted moving average the paper feeds to the tile coder alongside each elbow angle
//! (`μ_{t+1} = 0.8 μ_t + 0.2 LeftElbow_t`). [`Ewma::update`] folds an input in and returns the new average;
//! the feature tracker ([`super::features`]) reads μ_t before folding in the tick's angle, as the paper's
//! recurrence has it.
//!
//! Policy for missing input, which the paper leaves open:
//! - The first valid sample initialises μ to that sample (no ramp up from an arbitrary 0).
//! - An invalid input (`None`, NaN or ±∞) leaves μ unchanged and the held μ is returned: a dropped joint must
//!   not drag the average towards 0 or poison it with NaN.
//! - [`Ewma::reset`] forgets μ, so the next valid sample initialises it again; the feature tracker does this
//!   after a long run of invalid input (the person left, or was lost).

/// An exponentially weighted moving average `μ ← keep·μ + (1 − keep)·x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ewma {
    keep: f64,
    mean: Option<f64>,
}

impl Ewma {
    /// An average that keeps `keep` of the old value each step (the paper uses 0.8). `keep` is clamped into
    /// `[0, 1]`; a NaN `keep` is taken as 0 (the average is then just the latest valid input).
    pub fn new(keep: f64) -> Self {
        let keep = if keep.is_nan() {
            0.0
        } else {
            keep.clamp(0.0, 1.0)
        };
        Ewma { keep, mean: None }
    }

    /// The weight kept from the old average.
    pub fn keep(&self) -> f64 {
        self.keep
    }

    /// Fold in one input and return the average (see the module docs for invalid input).
    pub fn update(&mut self, x: Option<f64>) -> Option<f64> {
        if let Some(x) = x.filter(|v| v.is_finite()) {
            self.mean = Some(match self.mean {
                Some(mu) => self.keep * mu + (1.0 - self.keep) * x,
                None => x,
            });
        }
        self.mean
    }

    /// The current average, `None` before the first valid input.
    pub fn value(&self) -> Option<f64> {
        self.mean
    }

    /// Forget the average.
    pub fn reset(&mut self) {
        self.mean = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_valid_sample_initialises_then_blends() {
        let mut e = Ewma::new(0.8);
        assert_eq!(e.update(None), None);
        assert_eq!(e.update(Some(100.0)), Some(100.0));
        let v = e.update(Some(50.0)).unwrap();
        assert!((v - 90.0).abs() < 1e-12, "{v}");
        let v = e.update(Some(50.0)).unwrap();
        assert!((v - 82.0).abs() < 1e-12, "{v}");
    }

    #[test]
    fn invalid_input_holds_the_average() {
        let mut e = Ewma::new(0.8);
        e.update(Some(120.0));
        e.update(Some(60.0));
        let held = e.value().unwrap();
        for bad in [
            None,
            Some(f64::NAN),
            Some(f64::INFINITY),
            Some(f64::NEG_INFINITY),
        ] {
            assert_eq!(e.update(bad), Some(held));
        }
        e.reset();
        assert_eq!(e.value(), None);
        assert_eq!(e.update(Some(30.0)), Some(30.0));
    }

    #[test]
    fn converges_to_a_constant_input() {
        let mut e = Ewma::new(0.8);
        e.update(Some(170.0));
        for _ in 0..100 {
            e.update(Some(60.0));
        }
        assert!((e.value().unwrap() - 60.0).abs() < 1e-6);
    }

    #[test]
    fn keep_is_clamped() {
        assert_eq!(Ewma::new(1.5).keep(), 1.0);
        assert_eq!(Ewma::new(-0.5).keep(), 0.0);
        assert_eq!(Ewma::new(f64::NAN).keep(), 0.0);
        let mut e = Ewma::new(0.0);
        e.update(Some(1.0));
        assert_eq!(e.update(Some(7.0)), Some(7.0));
    }
}
