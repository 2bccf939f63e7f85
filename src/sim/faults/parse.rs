//! The fault spec grammar, as given to `pavlov sim --faults` and to tests:
//!
//! ```text
//! spec  := ""  |  item ("," item)*
//! item  := preset | flag | key "=" value
//! preset:= none | soak | all                       (replaces everything to its left)
//! flag  := quirk | banner                          (or quirk=true|false, banner=true|false)
//! key   := drop | flip | dup | text | inside | burst | hang | eof | trip | host_drop | host_flip
//!                                                  (probabilities in [0, 1], e.g. 1e-4)
//!        | burst_steps (integer ≥ 2) | delay_ms (integer ms)
//!        | hang_ms | trip_ms (ms: "300" or "200..3000")
//!        | baud (line bits/s, > 0, or "none")
//! ```
//!
//! Items apply left to right, so `soak,eof=0` is the soak preset without end-of-file events. Spaces
//! around items are ignored. Long names are accepted too: `duplicate`, `text_inside`, `mode_quirk`,
//! `line_baud`.

use super::spec::{FaultSpec, MsRange, PRESETS};

/// Why a fault spec string was rejected; every variant names the offending key or item.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FaultSpecError {
    /// The key is not part of the grammar.
    #[error(
        "unknown fault `{key}` (expected one of {PRESETS:?}, drop, flip, dup, text, inside, burst, burst_steps, delay_ms, hang, hang_ms, eof, trip, trip_ms, host_drop, host_flip, quirk, baud, banner)"
    )]
    UnknownKey { key: String },
    /// A key that needs `=value` had none.
    #[error("fault `{key}` needs a value (`{key}=…`)")]
    MissingValue { key: String },
    /// The value is not a number of the kind the key takes.
    #[error("fault `{key}`: `{value}` is not {expected}")]
    NotANumber {
        key: String,
        value: String,
        expected: &'static str,
    },
    /// A probability outside [0, 1] (or not finite).
    #[error("fault `{key}`: {value} is not a probability in [0, 1]")]
    NotAProbability { key: String, value: String },
    /// A number of the right kind but outside what the key allows.
    #[error("fault `{key}`: {value} is out of range ({allowed})")]
    OutOfRange {
        key: String,
        value: String,
        allowed: &'static str,
    },
    /// A flag given a value other than true/false.
    #[error("fault `{key}` is a flag: `{value}` is not true or false")]
    NotAFlag { key: String, value: String },
    /// A preset given a value.
    #[error("preset `{key}` takes no value (got `{value}`)")]
    PresetWithValue { key: String, value: String },
}

impl std::str::FromStr for FaultSpec {
    type Err = FaultSpecError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let mut spec = FaultSpec::none();
        for item in text.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (key, value) = match item.split_once('=') {
                Some((k, v)) => (k.trim(), Some(v.trim())),
                None => (item, None),
            };
            apply(&mut spec, key, value)?;
        }
        Ok(spec)
    }
}

/// Applies one `key[=value]` item to `spec`.
fn apply(spec: &mut FaultSpec, key: &str, value: Option<&str>) -> Result<(), FaultSpecError> {
    if let Some(preset) = FaultSpec::preset(key) {
        return match value {
            None => {
                *spec = preset;
                Ok(())
            }
            Some(v) => Err(FaultSpecError::PresetWithValue {
                key: key.into(),
                value: v.into(),
            }),
        };
    }
    match key {
        "quirk" | "mode_quirk" => spec.mode_quirk = flag(key, value)?,
        "banner" => spec.banner = flag(key, value)?,
        _ => {
            let value = value.ok_or_else(|| FaultSpecError::MissingValue { key: key.into() })?;
            apply_valued(spec, key, value)?;
        }
    }
    Ok(())
}

fn apply_valued(spec: &mut FaultSpec, key: &str, value: &str) -> Result<(), FaultSpecError> {
    let rate = || probability(key, value);
    match key {
        "drop" => spec.drop = rate()?,
        "flip" => spec.flip = rate()?,
        "dup" | "duplicate" => spec.duplicate = rate()?,
        "text" => spec.text = rate()?,
        "inside" | "text_inside" => spec.text_inside = rate()?,
        "burst" => spec.burst = rate()?,
        "hang" => spec.hang = rate()?,
        "eof" => spec.eof = rate()?,
        "trip" => spec.trip = rate()?,
        "host_drop" => spec.host_drop = rate()?,
        "host_flip" => spec.host_flip = rate()?,
        "burst_steps" => {
            let steps = integer(key, value)?;
            if steps < 2 {
                return Err(out_of_range(key, value, "at least 2 steps"));
            }
            spec.burst_steps = steps;
        }
        "delay_ms" => spec.delay_ms = integer(key, value)?,
        "hang_ms" => spec.hang_ms = ms_range(key, value)?,
        "trip_ms" => spec.trip_ms = ms_range(key, value)?,
        "baud" | "line_baud" => {
            spec.line_baud = match value {
                "none" => None,
                _ => match integer(key, value)? {
                    0 => return Err(out_of_range(key, value, "bits/s > 0")),
                    baud => Some(baud),
                },
            }
        }
        _ => return Err(FaultSpecError::UnknownKey { key: key.into() }),
    }
    Ok(())
}

fn flag(key: &str, value: Option<&str>) -> Result<bool, FaultSpecError> {
    match value {
        None | Some("true") | Some("1") | Some("on") => Ok(true),
        Some("false") | Some("0") | Some("off") => Ok(false),
        Some(v) => Err(FaultSpecError::NotAFlag {
            key: key.into(),
            value: v.into(),
        }),
    }
}

fn probability(key: &str, value: &str) -> Result<f64, FaultSpecError> {
    let p: f64 = value.parse().map_err(|_| FaultSpecError::NotANumber {
        key: key.into(),
        value: value.into(),
        expected: "a number",
    })?;
    if p.is_finite() && (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(FaultSpecError::NotAProbability {
            key: key.into(),
            value: value.into(),
        })
    }
}

fn integer(key: &str, value: &str) -> Result<u32, FaultSpecError> {
    value.parse().map_err(|_| FaultSpecError::NotANumber {
        key: key.into(),
        value: value.into(),
        expected: "a whole number",
    })
}

fn out_of_range(key: &str, value: &str, allowed: &'static str) -> FaultSpecError {
    FaultSpecError::OutOfRange {
        key: key.into(),
        value: value.into(),
        allowed,
    }
}

/// `"300"` (exactly) or `"200..3000"` (inclusive), ms.
fn ms_range(key: &str, value: &str) -> Result<MsRange, FaultSpecError> {
    let (min, max) = match value.split_once("..") {
        Some((lo, hi)) => (integer(key, lo.trim())?, integer(key, hi.trim())?),
        None => {
            let ms = integer(key, value)?;
            (ms, ms)
        }
    };
    if min > max {
        return Err(out_of_range(key, value, "min ≤ max"));
    }
    Ok(MsRange::new(min, max))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<FaultSpec, FaultSpecError> {
        s.parse()
    }

    #[test]
    fn a_full_spec_sets_every_field() {
        let s = parse(
            "drop=1e-4, flip=2e-4,dup=3e-4,text=0.002,inside=0.001,burst=0.002,burst_steps=8,delay_ms=45,\
             hang=2e-5,hang_ms=100..400,eof=1e-5,trip=1e-5,trip_ms=50,host_drop=0.5,host_flip=0.25,\
             quirk,baud=19200,banner",
        )
        .unwrap();
        assert_eq!(s.drop, 1e-4);
        assert_eq!(s.flip, 2e-4);
        assert_eq!(s.duplicate, 3e-4);
        assert_eq!(s.text, 0.002);
        assert_eq!(s.text_inside, 0.001);
        assert_eq!(s.burst, 0.002);
        assert_eq!(s.burst_steps, 8);
        assert_eq!(s.delay_ms, 45);
        assert_eq!(s.hang, 2e-5);
        assert_eq!(s.hang_ms, MsRange::new(100, 400));
        assert_eq!(s.eof, 1e-5);
        assert_eq!(s.trip, 1e-5);
        assert_eq!(s.trip_ms, MsRange::new(50, 50));
        assert_eq!(s.host_drop, 0.5);
        assert_eq!(s.host_flip, 0.25);
        assert!(s.mode_quirk && s.banner);
        assert_eq!(s.line_baud, Some(19_200));
        assert!(!s.is_none());
    }

    #[test]
    fn empty_and_none_inject_nothing() {
        for text in ["", "none", " none ", ",,", "quirk,none"] {
            let s = parse(text).unwrap();
            assert!(s.is_none(), "{text:?}");
            assert_eq!(s, FaultSpec::none());
        }
        assert!(!parse("quirk").unwrap().is_none());
        assert!(!parse("baud=19200").unwrap().is_none());
        assert!(!parse("delay_ms=15").unwrap().is_none());
        assert!(parse("quirk=false,drop=0").unwrap().is_none());
    }

    #[test]
    fn presets_parse_and_later_items_override_them() {
        assert_eq!(parse("soak").unwrap(), FaultSpec::soak());
        assert_eq!(parse("all").unwrap(), FaultSpec::all());
        let s = parse("soak,eof=0,quirk=false").unwrap();
        assert_eq!(s.eof, 0.0);
        assert!(!s.mode_quirk);
        assert_eq!(s.drop, FaultSpec::soak().drop);
        // A preset replaces what came before it.
        assert_eq!(parse("drop=0.5,soak").unwrap(), FaultSpec::soak());
    }

    #[test]
    fn every_preset_exercises_every_fault_it_promises() {
        for s in [FaultSpec::soak(), FaultSpec::all()] {
            let rates = [
                s.drop,
                s.flip,
                s.duplicate,
                s.text,
                s.text_inside,
                s.burst,
                s.hang,
                s.eof,
                s.trip,
            ];
            assert!(rates.iter().all(|&r| r > 0.0 && r < 0.1), "{s:?}");
            assert!(s.mode_quirk && s.banner && s.line_baud.is_none() && s.delay_ms > 0);
        }
    }

    #[test]
    fn describe_parses_back_to_the_same_spec() {
        let odd =
            parse("flip=0.123456789,hang_ms=15..30,trip_ms=7,burst_steps=3,baud=9600").unwrap();
        for s in [FaultSpec::none(), FaultSpec::soak(), FaultSpec::all(), odd] {
            let text = s.describe();
            assert_eq!(parse(&text).unwrap(), s, "{text}");
        }
        assert_eq!(FaultSpec::none().describe(), "none");
    }

    #[test]
    fn the_spec_round_trips_through_toml_and_partial_tables_default() {
        let s = FaultSpec::all();
        let text = toml::to_string(&s).unwrap();
        assert_eq!(toml::from_str::<FaultSpec>(&text).unwrap(), s);
        let partial: FaultSpec = toml::from_str("drop = 0.01\nline_baud = 19200").unwrap();
        assert_eq!(partial, parse("drop=0.01,baud=19200").unwrap());
    }

    #[test]
    fn each_error_names_the_key_and_value() {
        let cases: [(&str, FaultSpecError); 11] = [
            (
                "jitter=0.1",
                FaultSpecError::UnknownKey {
                    key: "jitter".into(),
                },
            ),
            ("drop", FaultSpecError::MissingValue { key: "drop".into() }),
            (
                "flip=often",
                FaultSpecError::NotANumber {
                    key: "flip".into(),
                    value: "often".into(),
                    expected: "a number",
                },
            ),
            (
                "text=1.5",
                FaultSpecError::NotAProbability {
                    key: "text".into(),
                    value: "1.5".into(),
                },
            ),
            (
                "eof=-0.1",
                FaultSpecError::NotAProbability {
                    key: "eof".into(),
                    value: "-0.1".into(),
                },
            ),
            (
                "hang=NaN",
                FaultSpecError::NotAProbability {
                    key: "hang".into(),
                    value: "NaN".into(),
                },
            ),
            (
                "burst_steps=1",
                FaultSpecError::OutOfRange {
                    key: "burst_steps".into(),
                    value: "1".into(),
                    allowed: "at least 2 steps",
                },
            ),
            (
                "hang_ms=500..100",
                FaultSpecError::OutOfRange {
                    key: "hang_ms".into(),
                    value: "500..100".into(),
                    allowed: "min ≤ max",
                },
            ),
            (
                "baud=0",
                FaultSpecError::OutOfRange {
                    key: "baud".into(),
                    value: "0".into(),
                    allowed: "bits/s > 0",
                },
            ),
            (
                "quirk=maybe",
                FaultSpecError::NotAFlag {
                    key: "quirk".into(),
                    value: "maybe".into(),
                },
            ),
            (
                "soak=1",
                FaultSpecError::PresetWithValue {
                    key: "soak".into(),
                    value: "1".into(),
                },
            ),
        ];
        for (text, expected) in cases {
            let err = parse(&format!("drop=0.1,{text}")).unwrap_err();
            assert_eq!(err, expected, "{text}");
            let key = text.split('=').next().unwrap();
            assert!(err.to_string().contains(key), "{err} should name {key}");
        }
        assert!(matches!(
            parse("trip_ms=1..x"),
            Err(FaultSpecError::NotANumber { key, value, .. }) if key == "trip_ms" && value == "x"
        ));
    }
}
