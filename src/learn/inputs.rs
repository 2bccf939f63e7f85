//! The signals predictions read: named inputs (observation dimensions, then extra signals such as elbow
//! angles) and named stimuli; and the resolution of a [`FeatureSpec`] against them into a tile coder
//! plus the list of input positions it reads.
//!
//! Names are resolved once, when a [`super::PredictionSet`] is built; per tick the inputs are plain
//! slices in the declared order, so nothing is looked up by name on the hot path.

use super::LearnError;
use super::spec::FeatureSpec;
use super::tiles::TileCoder;
use crate::obs::ObsLayout;

/// The names of every signal a prediction set may read, in the order the per-tick slices use.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SignalNames {
    /// Observation dimensions ([`FeatureInputs::obs`] order).
    pub obs: Vec<String>,
    /// Extra continuous inputs ([`FeatureInputs::extra`] order), e.g. `left_elbow`, `left_elbow_avg`.
    pub extra: Vec<String>,
    /// Stimulus events (the order of the `stimuli` slice given to `learn`), e.g. `stall`.
    pub stimuli: Vec<String>,
}

impl SignalNames {
    /// The observation dimensions of `layout`, then `extra` inputs, and `stimuli`.
    pub fn for_layout(layout: &ObsLayout, extra: &[&str], stimuli: &[&str]) -> Self {
        SignalNames {
            obs: layout.names().map(str::to_string).collect(),
            extra: extra.iter().map(|s| s.to_string()).collect(),
            stimuli: stimuli.iter().map(|s| s.to_string()).collect(),
        }
    }

    /// Fails on a name used twice among the inputs, or twice among the stimuli.
    pub fn check_unique(&self) -> Result<(), LearnError> {
        let inputs = self.obs.iter().chain(&self.extra);
        for list in [inputs.collect::<Vec<_>>(), self.stimuli.iter().collect()] {
            let mut seen = std::collections::HashSet::new();
            for name in list {
                if !seen.insert(name.as_str()) {
                    return Err(LearnError::DuplicateSignal(name.clone()));
                }
            }
        }
        Ok(())
    }

    /// The position of input `name` in the concatenated input space (obs, then extra).
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.obs.iter().chain(&self.extra).position(|n| n == name)
    }

    /// The position of stimulus `name`.
    pub fn stimulus_index(&self, name: &str) -> Option<usize> {
        self.stimuli.iter().position(|n| n == name)
    }

    fn known_inputs(&self) -> String {
        let all: Vec<&str> = self
            .obs
            .iter()
            .chain(&self.extra)
            .map(String::as_str)
            .collect();
        all.join(", ")
    }

    pub(crate) fn resolve_stimulus(
        &self,
        prediction: &str,
        name: &str,
    ) -> Result<usize, LearnError> {
        self.stimulus_index(name)
            .ok_or_else(|| LearnError::UnknownStimulus {
                prediction: prediction.to_string(),
                stimulus: name.to_string(),
                known: self.stimuli.join(", "),
            })
    }

    fn resolve_input(&self, prediction: &str, name: &str) -> Result<usize, LearnError> {
        self.input_index(name)
            .ok_or_else(|| LearnError::UnknownInput {
                prediction: prediction.to_string(),
                input: name.to_string(),
                known: self.known_inputs(),
            })
    }
}

/// One tick's input values: `obs` in [`SignalNames::obs`] order (e.g. from
/// [`ObsLayout::scale`]), `extra` in [`SignalNames::extra`] order. Each value should be in `[0, 1]`;
/// a missing or non-finite value activates no feature in the tilings that read it.
#[derive(Debug, Clone, Copy, Default)]
pub struct FeatureInputs<'a> {
    pub obs: &'a [f64],
    pub extra: &'a [f64],
}

impl FeatureInputs<'_> {
    /// The value at `index` of the concatenated input space, NaN when not provided.
    #[inline]
    pub fn get(&self, index: usize) -> f64 {
        match index.checked_sub(self.obs.len()) {
            None => self.obs.get(index).copied().unwrap_or(f64::NAN),
            Some(i) => self.extra.get(i).copied().unwrap_or(f64::NAN),
        }
    }
}

/// A feature spec resolved against the signal names: the coder reads `gather[k]` as its input `k`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ResolvedFeatures {
    pub gather: Vec<usize>,
    pub coder: TileCoder,
}

pub(crate) fn resolve(
    prediction: &str,
    spec: &FeatureSpec,
    names: &SignalNames,
) -> Result<ResolvedFeatures, LearnError> {
    match spec {
        FeatureSpec::OneDim {
            all_obs,
            inputs,
            tiles,
            tilings,
        } => {
            let mut gather: Vec<usize> = if *all_obs {
                (0..names.obs.len()).collect()
            } else {
                Vec::new()
            };
            for name in inputs {
                gather.push(names.resolve_input(prediction, name)?);
            }
            let coder = TileCoder::one_dim_offset(gather.len(), *tiles, *tilings)?;
            Ok(ResolvedFeatures { gather, coder })
        }
        FeatureSpec::Pairs { pairs, tiles } => {
            let mut gather: Vec<usize> = Vec::new();
            let mut position = |name: &str| -> Result<usize, LearnError> {
                let index = names.resolve_input(prediction, name)?;
                Ok(match gather.iter().position(|&g| g == index) {
                    Some(p) => p,
                    None => {
                        gather.push(index);
                        gather.len() - 1
                    }
                })
            };
            let mut coder_pairs = Vec::with_capacity(pairs.len());
            for pair in pairs {
                coder_pairs.push((position(&pair.x)?, position(&pair.y)?, pair.offset));
            }
            let coder = TileCoder::pairs(coder_pairs, *tiles)?;
            Ok(ResolvedFeatures { gather, coder })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::spec::PairSpec;
    use crate::oi::Model;

    fn names() -> SignalNames {
        SignalNames::for_layout(
            &ObsLayout::for_model(Model::Create1),
            &[
                "left_elbow",
                "left_elbow_avg",
                "right_elbow",
                "right_elbow_avg",
            ],
            &["stall", "left_elbow_command"],
        )
    }

    #[test]
    fn inputs_concatenate_obs_then_extra() {
        let n = names();
        n.check_unique().unwrap();
        assert_eq!(n.input_index("bump_right"), Some(0));
        assert_eq!(n.input_index("left_elbow"), Some(44));
        assert_eq!(n.stimulus_index("left_elbow_command"), Some(1));
        let obs = [0.5; 44];
        let extra = [0.25, 0.75];
        let inputs = FeatureInputs {
            obs: &obs,
            extra: &extra,
        };
        assert_eq!(inputs.get(3), 0.5);
        assert_eq!(inputs.get(45), 0.75);
        assert!(inputs.get(46).is_nan());
    }

    #[test]
    fn duplicates_are_rejected() {
        let mut n = names();
        n.extra.push("current".into());
        assert_eq!(
            n.check_unique(),
            Err(LearnError::DuplicateSignal("current".into()))
        );
        let mut n = names();
        n.stimuli.push("stall".into());
        assert_eq!(
            n.check_unique(),
            Err(LearnError::DuplicateSignal("stall".into()))
        );
    }

    #[test]
    fn pairs_resolve_to_distinct_gathered_inputs() {
        let pair = |x: &str, y: &str, offset| PairSpec {
            x: x.into(),
            y: y.into(),
            offset,
        };
        let spec = FeatureSpec::Pairs {
            pairs: vec![
                pair("left_elbow", "left_elbow_avg", 0.0),
                pair("left_elbow", "left_elbow_avg", 0.5),
                pair("left_elbow", "right_elbow", 0.0),
            ],
            tiles: 10,
        };
        let r = resolve("command", &spec, &names()).unwrap();
        assert_eq!(r.gather, vec![44, 45, 46]);
        assert_eq!(r.coder.num_features(), 300);
        let bad = FeatureSpec::Pairs {
            pairs: vec![pair("left_elbow", "nose", 0.0)],
            tiles: 10,
        };
        let err = resolve("command", &bad, &names()).unwrap_err();
        assert!(
            matches!(&err, LearnError::UnknownInput { input, .. } if input == "nose"),
            "{err}"
        );
    }

    #[test]
    fn one_dim_takes_all_obs_then_named_inputs() {
        let spec = FeatureSpec::OneDim {
            all_obs: true,
            inputs: vec!["right_elbow".into()],
            tiles: 10,
            tilings: 1,
        };
        let r = resolve("p", &spec, &names()).unwrap();
        assert_eq!(r.gather.len(), 45);
        assert_eq!(r.gather[44], 46);
        assert_eq!(r.coder.num_features(), 450);
        let empty = FeatureSpec::OneDim {
            all_obs: false,
            inputs: vec![],
            tiles: 10,
            tilings: 1,
        };
        assert_eq!(
            resolve("p", &empty, &names()).unwrap_err(),
            LearnError::NoTilings
        );
    }
}
