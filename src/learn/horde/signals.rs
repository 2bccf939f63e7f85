//! What a general prediction (GVF) can be about: a cumulant named by a *selector*, a short path that
//! names one signal of the tick, or every signal of a kind:
//!
//! | selector | the cumulant `R_t` |
//! |---|---|
//! | `obs/<dim>` | observation dimension `<dim>` scaled to `[0, 1]` (the value the features tile) |
//! | `raw/<dim>` | the same dimension unscaled, in the sensor's units (mA, mV, mm, …; a bit is 0 or 1) |
//! | `input/<name>` | an extra input, e.g. `input/left_elbow` (an angle / 180°) |
//! | `stimulus/<name>` | 1 while stimulus `<name>` is on, else 0 (without ending the prediction there) |
//! | `feature/<k>` | 1 while feature `k` of the prediction's own feature construction is active |
//! | `bias` | 1 on every tick: the prediction learns `Σ γᵏ`, a check of τ |
//!
//! In a family, `obs/*`, `raw/*`, `input/*`, `stimulus/*` and `features/*` stand for every signal of
//! the kind: `features/*` makes one prediction per feature, as nexting did with its feature cumulants
//! \[nexting\]. A signal missing on a tick (a packet absent from the snapshot, no skeleton) is NaN: that
//! tick's update is skipped for the predictions about it.

use super::super::LearnError;
use super::super::inputs::SignalNames;

/// One signal of the tick, resolved to where its value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Source {
    /// Scaled observation dimension `i`.
    Obs(usize),
    /// Unscaled observation dimension `i`.
    Raw(usize),
    /// Extra input `i`.
    Input(usize),
    /// Stimulus `i`, as 0 or 1.
    Stimulus(usize),
    /// Feature `k` of the prediction's feature construction, as 0 or 1.
    Feature(usize),
    /// The constant 1.
    Bias,
}

/// The values of one tick that cumulants are read from.
#[derive(Debug, Clone, Copy, Default)]
pub struct TickSignals<'a> {
    /// Scaled observation, [`SignalNames::obs`] order.
    pub obs: &'a [f64],
    /// Unscaled observation, the same order.
    pub raw: &'a [f64],
    /// Extra inputs, [`SignalNames::extra`] order.
    pub extra: &'a [f64],
    /// Stimuli, [`SignalNames::stimuli`] order.
    pub stimuli: &'a [bool],
}

impl TickSignals<'_> {
    /// The value of `source` (NaN when not provided); `active` tells whether a feature is on.
    #[inline]
    pub fn value(&self, source: Source, active: impl Fn(usize) -> bool) -> f64 {
        let at = |v: &[f64], i: usize| v.get(i).copied().unwrap_or(f64::NAN);
        match source {
            Source::Obs(i) => at(self.obs, i),
            Source::Raw(i) => at(self.raw, i),
            Source::Input(i) => at(self.extra, i),
            Source::Stimulus(i) => self
                .stimuli
                .get(i)
                .map_or(f64::NAN, |&s| f64::from(u8::from(s))),
            Source::Feature(k) => f64::from(u8::from(active(k))),
            Source::Bias => 1.0,
        }
    }
}

/// The signals `selector` names (one, or every one of a kind for a `*`), each with its canonical
/// selector; `features` is the size of the prediction's feature construction.
pub fn expand(
    family: &str,
    selector: &str,
    names: &SignalNames,
    features: usize,
) -> Result<Vec<(String, Source)>, LearnError> {
    let unknown = |known: String| LearnError::UnknownSignal {
        family: family.to_string(),
        selector: selector.to_string(),
        known,
    };
    if selector == "bias" {
        return Ok(vec![("bias".into(), Source::Bias)]);
    }
    let Some((kind, name)) = selector.split_once('/') else {
        return Err(unknown(KINDS.into()));
    };
    let named = |list: &[String], make: fn(usize) -> Source| -> Result<Vec<_>, LearnError> {
        if name == "*" {
            return Ok(list
                .iter()
                .enumerate()
                .map(|(i, n)| (format!("{kind}/{n}"), make(i)))
                .collect());
        }
        match list.iter().position(|n| n == name) {
            Some(i) => Ok(vec![(format!("{kind}/{name}"), make(i))]),
            None => Err(unknown(list.join(", "))),
        }
    };
    match kind {
        "obs" => named(&names.obs, Source::Obs),
        "raw" => named(&names.obs, Source::Raw),
        "input" => named(&names.extra, Source::Input),
        "stimulus" => named(&names.stimuli, Source::Stimulus),
        "features" if name == "*" => Ok((0..features)
            .map(|k| (format!("feature/{k}"), Source::Feature(k)))
            .collect()),
        "feature" => match name.parse::<usize>() {
            Ok(k) if k < features => Ok(vec![(format!("feature/{k}"), Source::Feature(k))]),
            _ => Err(unknown(format!(
                "feature/0 … feature/{}",
                features.saturating_sub(1)
            ))),
        },
        _ => Err(unknown(KINDS.into())),
    }
}

const KINDS: &str = "obs/<dim>, raw/<dim>, input/<name>, stimulus/<name>, feature/<k>, bias, or a kind \
                     with /* (features/* for every feature)";

#[cfg(test)]
mod tests {
    use super::*;

    fn names() -> SignalNames {
        SignalNames {
            obs: vec!["current".into(), "voltage".into()],
            extra: vec!["left_elbow".into()],
            stimuli: vec!["stall".into()],
        }
    }

    #[test]
    fn selectors_name_one_signal_or_every_one_of_a_kind() {
        let n = names();
        assert_eq!(
            expand("f", "raw/voltage", &n, 10).unwrap(),
            vec![("raw/voltage".to_string(), Source::Raw(1))]
        );
        let all: Vec<Source> = expand("f", "obs/*", &n, 10)
            .unwrap()
            .into_iter()
            .map(|(_, s)| s)
            .collect();
        assert_eq!(all, vec![Source::Obs(0), Source::Obs(1)]);
        assert_eq!(expand("f", "features/*", &n, 3).unwrap().len(), 3);
        assert_eq!(
            expand("f", "feature/2", &n, 3).unwrap()[0].1,
            Source::Feature(2)
        );
        assert_eq!(expand("f", "bias", &n, 3).unwrap()[0].1, Source::Bias);
        assert_eq!(
            expand("f", "stimulus/stall", &n, 3).unwrap()[0].1,
            Source::Stimulus(0)
        );
    }

    #[test]
    fn an_unknown_selector_says_what_is_known() {
        let n = names();
        for bad in ["obs/nose", "feature/3", "sonar/1", "current", "input/*x"] {
            let e = expand("nexting", bad, &n, 3).unwrap_err().to_string();
            assert!(e.contains("nexting") && e.contains(bad), "{e}");
        }
        let e = expand("f", "obs/nose", &n, 3).unwrap_err().to_string();
        assert!(e.contains("current, voltage"), "{e}");
    }

    #[test]
    fn values_come_from_their_slice_and_missing_ones_are_nan() {
        let s = TickSignals {
            obs: &[0.5],
            raw: &[1200.0, 16_000.0],
            extra: &[],
            stimuli: &[true],
        };
        let off = |_| false;
        assert_eq!(s.value(Source::Raw(1), off), 16_000.0);
        assert!(s.value(Source::Obs(1), off).is_nan());
        assert!(s.value(Source::Input(0), off).is_nan());
        assert_eq!(s.value(Source::Stimulus(0), off), 1.0);
        assert_eq!(s.value(Source::Feature(4), |k| k == 4), 1.0);
        assert_eq!(s.value(Source::Bias, off), 1.0);
    }
}
