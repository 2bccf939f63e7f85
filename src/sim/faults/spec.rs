//! [`FaultSpec`]: what to inject into the simulated robot's link, with its presets and its canonical
//! text form (the grammar is parsed in `parse`).
//!
//! Rates are probabilities in [0, 1]: per byte for the byte faults, per 15 ms step for the events.
//! At 66.7 steps/s a per-step rate `p` fires on average every `15 ms / p` (p = 1e-3: every 15 s).

use serde::{Deserialize, Serialize};

/// A duration drawn uniformly from `min_ms..=max_ms`, ms (rounded up to whole 15 ms steps).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MsRange {
    /// Shortest duration, ms.
    pub min_ms: u32,
    /// Longest duration, ms (≥ `min_ms`).
    pub max_ms: u32,
}

impl MsRange {
    /// `min_ms..=max_ms`.
    pub const fn new(min_ms: u32, max_ms: u32) -> Self {
        MsRange { min_ms, max_ms }
    }
}

impl std::fmt::Display for MsRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.min_ms == self.max_ms {
            write!(f, "{}", self.min_ms)
        } else {
            write!(f, "{}..{}", self.min_ms, self.max_ms)
        }
    }
}

/// Default hang duration: long enough for a 100–200 ms watchdog to fire, short enough to recover.
pub const DEFAULT_HANG: MsRange = MsRange::new(200, 3000);
/// Default trip duration: a bump over a threshold up to a second's lift.
pub const DEFAULT_TRIP: MsRange = MsRange::new(100, 1000);
/// Default longest burst, 15 ms steps (300 ms, a sluggish USB-serial adapter or Bluetooth link).
pub const DEFAULT_BURST_STEPS: u32 = 20;

/// What to inject; every rate is a probability in [0, 1], per byte or per 15 ms step as documented
/// on each field. The default injects nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FaultSpec {
    /// Per robot→host byte: the byte is lost.
    pub drop: f64,
    /// Per robot→host byte (not dropped): one random bit of it is inverted.
    pub flip: f64,
    /// Per robot→host byte (not dropped): it is sent twice.
    pub duplicate: f64,
    /// Per step: an ASCII line (a `bat:` charging line or a banner line, CR LF ended) is sent
    /// before the step's bytes, i.e. between frames.
    pub text: f64,
    /// Per step: an ASCII line is spliced at a random place strictly inside the step's bytes, i.e.
    /// inside a frame.
    pub text_inside: f64,
    /// Per step: output is held for a random 2..=`burst_steps` steps (this one included) and then
    /// released all at once (a late, bursty delivery; nothing is lost).
    pub burst: f64,
    /// Longest burst, 15 ms steps (≥ 2).
    pub burst_steps: u32,
    /// A steady latency, ms (rounded up to whole 15 ms steps): every byte reaches the wire this long
    /// after the robot sent it, evenly paced (a USB adapter's latency timer, a Bluetooth bridge).
    pub delay_ms: u32,
    /// Per step: the link hangs silently both ways for a duration drawn from `hang_ms`; the robot keeps
    /// running, its output and the host's bytes are lost meanwhile.
    pub hang: f64,
    /// How long a hang lasts, ms.
    pub hang_ms: MsRange,
    /// Per step: the link closes (end of file); the robot keeps running.
    pub eof: f64,
    /// Per step: the robot is lifted (both wheel drops) or a cliff appears under one of its four cliff
    /// sensors, for a duration drawn from `trip_ms`; in Safe mode that trips the robot to Passive.
    pub trip: f64,
    /// How long a trip event lasts, ms.
    pub trip_ms: MsRange,
    /// Per host→robot byte: the byte is lost.
    pub host_drop: f64,
    /// Per host→robot byte (not dropped): one random bit of it is inverted.
    pub host_flip: f64,
    /// The firmware reports packet 35 as mode + 1.
    pub mode_quirk: bool,
    /// The line really runs at this many bits/s (e.g. 19200, a robot that fell back to its
    /// fallback baud): a stream over this budget overflows the robot's transmit buffer and corrupts.
    pub line_baud: Option<u32>,
    /// The Create 2's boot banner is sent before the first step's bytes.
    pub banner: bool,
}

impl Default for FaultSpec {
    fn default() -> Self {
        FaultSpec {
            drop: 0.0,
            flip: 0.0,
            duplicate: 0.0,
            text: 0.0,
            text_inside: 0.0,
            burst: 0.0,
            burst_steps: DEFAULT_BURST_STEPS,
            delay_ms: 0,
            hang: 0.0,
            hang_ms: DEFAULT_HANG,
            eof: 0.0,
            trip: 0.0,
            trip_ms: DEFAULT_TRIP,
            host_drop: 0.0,
            host_flip: 0.0,
            mode_quirk: false,
            line_baud: None,
            banner: false,
        }
    }
}

/// The named presets accepted by the spec grammar.
pub const PRESETS: [&str; 3] = ["none", "soak", "all"];

impl FaultSpec {
    /// Injects nothing.
    pub fn none() -> Self {
        FaultSpec::default()
    }

    /// A mix for runs of hours that exercises every fault: at 66.7 steps/s and a 84-byte frame,
    /// about 200 dropped, 200 flipped and 200 duplicated bytes an hour, a text line between frames
    /// every ~10 s and one inside a frame every ~75 s, a burst of up to 300 ms every ~15 s, a steady
    /// 30 ms latency, and about
    /// once an hour each a hang (0.2–3 s), an end of file and a trip (0.1–1 s); the mode+1 quirk and
    /// the boot banner are on. The line runs at the configured baud.
    pub fn soak() -> Self {
        FaultSpec {
            drop: 1e-5,
            flip: 1e-5,
            duplicate: 1e-5,
            text: 1.5e-3,
            text_inside: 2e-4,
            burst: 1e-3,
            delay_ms: 30,
            hang: 4e-6,
            eof: 4e-6,
            trip: 4e-6,
            mode_quirk: true,
            banner: true,
            ..FaultSpec::default()
        }
    }

    /// Every fault at a high rate, for short tests: ~7 % of 84-byte frames damaged by byte faults,
    /// a text line between frames every 1.5 s and inside one every 3 s, a burst every 1.5 s, a steady
    /// 30 ms latency, a hang and a trip every ~15 s, an end of file every ~30 s, host bytes dropped or
    /// flipped at 1e-3, the quirk and the banner. The line baud is left alone (a slow line breaks every
    /// frame; ask for it with `baud=`).
    pub fn all() -> Self {
        FaultSpec {
            drop: 3e-4,
            flip: 3e-4,
            duplicate: 3e-4,
            text: 0.01,
            text_inside: 0.005,
            burst: 0.01,
            delay_ms: 30,
            hang: 1e-3,
            eof: 5e-4,
            trip: 1e-3,
            host_drop: 1e-3,
            host_flip: 1e-3,
            mode_quirk: true,
            banner: true,
            ..FaultSpec::default()
        }
    }

    /// The preset called `name` (`none`, `soak`, `all`).
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "none" => Some(FaultSpec::none()),
            "soak" => Some(FaultSpec::soak()),
            "all" => Some(FaultSpec::all()),
            _ => None,
        }
    }

    /// True when nothing would be injected (the durations may differ from the defaults).
    pub fn is_none(&self) -> bool {
        let rates = [
            self.drop,
            self.flip,
            self.duplicate,
            self.text,
            self.text_inside,
            self.burst,
            self.hang,
            self.eof,
            self.trip,
            self.host_drop,
            self.host_flip,
        ];
        rates.iter().all(|&r| r <= 0.0)
            && self.delay_ms == 0
            && !self.mode_quirk
            && self.line_baud.is_none()
            && !self.banner
    }

    /// One line for logs: `none`, or the canonical spec string (which parses back to this spec).
    pub fn describe(&self) -> String {
        self.to_string()
    }
}

/// The canonical spec string: every setting that differs from the default, in a fixed order, or
/// `none`. It parses back to the same spec.
impl std::fmt::Display for FaultSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let d = FaultSpec::default();
        let mut items: Vec<String> = Vec::new();
        let rates = [
            ("drop", self.drop),
            ("flip", self.flip),
            ("dup", self.duplicate),
            ("text", self.text),
            ("inside", self.text_inside),
            ("burst", self.burst),
            ("hang", self.hang),
            ("eof", self.eof),
            ("trip", self.trip),
            ("host_drop", self.host_drop),
            ("host_flip", self.host_flip),
        ];
        items.extend(
            rates
                .iter()
                .filter(|(_, r)| *r != 0.0)
                .map(|(k, r)| format!("{k}={r:e}")),
        );
        if self.burst_steps != d.burst_steps {
            items.push(format!("burst_steps={}", self.burst_steps));
        }
        if self.delay_ms != d.delay_ms {
            items.push(format!("delay_ms={}", self.delay_ms));
        }
        if self.hang_ms != d.hang_ms {
            items.push(format!("hang_ms={}", self.hang_ms));
        }
        if self.trip_ms != d.trip_ms {
            items.push(format!("trip_ms={}", self.trip_ms));
        }
        if self.mode_quirk {
            items.push("quirk".into());
        }
        if let Some(baud) = self.line_baud {
            items.push(format!("baud={baud}"));
        }
        if self.banner {
            items.push("banner".into());
        }
        if items.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&items.join(","))
        }
    }
}
