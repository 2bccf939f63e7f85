//! Pure decoding of skeleton OSC packets into joint updates and user events.
//!
//! Rules (see also `config/README.md`, `[skeleton]`):
//! - Bundles are walked depth-first in order, nested up to [`MAX_BUNDLE_DEPTH`] levels; their time tags are
//!   ignored (OSCeleton sends "immediately").
//! - OSCeleton (`osceleton_mm`, `osceleton_normalized`): `/joint ,sifff name user x y z` (extra trailing
//!   arguments are ignored; `d` is accepted for `f`); `/new_user`, `/new_skel`, `/lost_user ,i user` (without an
//!   argument, as in hand mode, they are ignored); `/orient` and `/user/<n>` are known and ignored. Joints are in
//!   raw millimetres, or normalized and transformed back with `osceleton_normalized_to_mm`. Confidence is 1
//!   (OSCeleton leaves out joints below 0.5).
//! - KinectV2-OSC (`kinect_v2`): `/bodies/<id>/joints/<JointType> ,fffs x y z state` in metres (× 1000 → mm);
//!   `Tracked` gives confidence 1, `Inferred` 0.5, `NotTracked` leaves the joint out; `/bodies/<id>/hands/…`
//!   is known and ignored. The body id is the 64-bit tracking id from the address.
//! - Joint names without a counterpart in [`Joint`] (`SpineBase`, `l_collar`, …) are skipped, not errors.
//! - A message of the other family than the configured one is counted as [`Malformed::OtherFormat`]; a known
//!   address with the wrong argument types as [`Malformed::WrongTypes`]; a non-finite coordinate as
//!   [`Malformed::NonFinite`] (the joint is left out, so its previous sample ages out); anything else as
//!   [`Malformed::UnknownAddress`]. Nothing here panics.
//! - With `swap_lr`, every joint is replaced by its mirror image (`l_elbow` ↔ `r_elbow`, …).

use pavlov::config::SkeletonFormat;
use pavlov::skeleton::{Joint, osceleton_normalized_to_mm};
use rosc::{OscMessage, OscPacket, OscType};

/// Deepest bundle nesting that is decoded; deeper content is counted as malformed.
pub(crate) const MAX_BUNDLE_DEPTH: usize = 8;

/// Whether the raw datagram's bundles nest at most `max_depth` deep (the outermost bundle is at depth 0).
///
/// Check this *before* `rosc::decoder::decode_udp`: rosc decodes nested bundles recursively, and a 16 KB
/// datagram of 800 nested empty bundles overflows a 2 MiB thread stack (rosc 0.11.4, debug build), which aborts
/// the whole process. This walk only follows the element sizes and recurses at most `max_depth` levels;
/// anything else wrong with the bytes is left for rosc to report.
pub(crate) fn nesting_within(bytes: &[u8], max_depth: usize) -> bool {
    nesting_from(bytes, 0, max_depth)
}

fn nesting_from(bytes: &[u8], depth: usize, max_depth: usize) -> bool {
    const BUNDLE_TAG: &[u8] = b"#bundle\0";
    if !bytes.starts_with(BUNDLE_TAG) {
        return true;
    }
    if depth >= max_depth {
        return false;
    }
    // Tag (8 bytes) and time tag (8 bytes), then (size, element) pairs.
    let mut rest = bytes.get(16..).unwrap_or_default();
    while let Some((size, after)) = rest.split_first_chunk::<4>() {
        let size = usize::try_from(u32::from_be_bytes(*size)).unwrap_or(usize::MAX);
        let Some(element) = after.get(..size) else {
            return true;
        };
        if !nesting_from(element, depth + 1, max_depth) {
            return false;
        }
        rest = after.get(size..).unwrap_or_default();
    }
    true
}

/// A tracked person, as the streamer identifies them (OSCeleton's small integer, Kinect v2's 64-bit id).
pub(crate) type UserId = u64;

/// One thing a packet said.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum SkeletonEvent {
    /// A joint position of `user`, in millimetres.
    Joint {
        /// Whose joint.
        user: UserId,
        /// Which joint (after `swap_lr`).
        joint: Joint,
        /// Position, mm.
        pos_mm: [f64; 3],
        /// Tracker confidence in `[0, 1]`.
        confidence: f32,
    },
    /// OSCeleton `/new_user`: a person entered the view.
    NewUser(UserId),
    /// OSCeleton `/new_skel`: calibration done, a (new) skeleton starts.
    NewSkeleton(UserId),
    /// OSCeleton `/lost_user`: the person left; the id may be reused.
    LostUser(UserId),
}

/// Kinds of malformed input, each counted separately.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Malformed {
    /// The datagram is not OSC (garbage, truncated, bad padding, bad UTF-8, ...).
    Undecodable,
    /// The datagram filled the whole receive buffer, so it may have been cut off.
    Oversized,
    /// Bytes left over after the packet: a bundle cut short (rosc stops at the first incomplete element).
    Truncated,
    /// A known address with arguments of the wrong number or types.
    WrongTypes,
    /// An address this ingest does not know.
    UnknownAddress,
    /// A message of a skeleton format other than the configured one.
    OtherFormat,
    /// A NaN or infinite coordinate.
    NonFinite,
    /// Bundles nested deeper than [`MAX_BUNDLE_DEPTH`].
    TooDeep,
}

/// Counters of everything decoded.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DecodeCounts {
    /// Datagrams received.
    pub datagrams: u64,
    /// Messages seen (inside bundles or alone).
    pub(crate) messages: u64,
    /// Joint updates produced.
    pub joints: u64,
    /// Joints skipped on purpose (unknown joint name, `NotTracked`).
    pub(crate) skipped_joints: u64,
    /// Messages known and ignored (`/orient`, `/user/<n>`, hands, argument-less user events).
    pub(crate) ignored: u64,
    /// [`Malformed::Undecodable`].
    pub undecodable: u64,
    /// [`Malformed::Oversized`].
    pub oversized: u64,
    /// [`Malformed::Truncated`].
    pub truncated: u64,
    /// [`Malformed::WrongTypes`].
    pub wrong_types: u64,
    /// [`Malformed::UnknownAddress`].
    pub unknown_address: u64,
    /// [`Malformed::OtherFormat`].
    pub other_format: u64,
    /// [`Malformed::NonFinite`].
    pub non_finite: u64,
    /// [`Malformed::TooDeep`].
    pub too_deep: u64,
}

impl DecodeCounts {
    /// Count one malformed item.
    pub(crate) fn count(&mut self, kind: Malformed) {
        let slot = match kind {
            Malformed::Undecodable => &mut self.undecodable,
            Malformed::Oversized => &mut self.oversized,
            Malformed::Truncated => &mut self.truncated,
            Malformed::WrongTypes => &mut self.wrong_types,
            Malformed::UnknownAddress => &mut self.unknown_address,
            Malformed::OtherFormat => &mut self.other_format,
            Malformed::NonFinite => &mut self.non_finite,
            Malformed::TooDeep => &mut self.too_deep,
        };
        *slot = slot.saturating_add(1);
    }

    /// All malformed items together.
    pub fn malformed(&self) -> u64 {
        self.undecodable
            + self.oversized
            + self.truncated
            + self.wrong_types
            + self.unknown_address
            + self.other_format
            + self.non_finite
            + self.too_deep
    }
}

/// Turns packets into [`SkeletonEvent`]s for one configured format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Decoder {
    format: SkeletonFormat,
    swap_lr: bool,
}

impl Decoder {
    /// A decoder for `format`, mirroring left and right when `swap_lr`.
    pub(crate) fn new(format: SkeletonFormat, swap_lr: bool) -> Self {
        Decoder { format, swap_lr }
    }

    /// Decode one packet: events are appended to `events` in packet order, and every message is counted in
    /// `counts`; the returned list holds the malformed items met (for logging).
    pub(crate) fn decode(
        &self,
        packet: &OscPacket,
        events: &mut Vec<SkeletonEvent>,
        counts: &mut DecodeCounts,
    ) -> Vec<Malformed> {
        let mut bad = Vec::new();
        self.walk(packet, 0, events, counts, &mut bad);
        for &kind in &bad {
            counts.count(kind);
        }
        bad
    }

    fn walk(
        &self,
        packet: &OscPacket,
        depth: usize,
        events: &mut Vec<SkeletonEvent>,
        counts: &mut DecodeCounts,
        bad: &mut Vec<Malformed>,
    ) {
        match packet {
            OscPacket::Bundle(b) => {
                if depth >= MAX_BUNDLE_DEPTH {
                    bad.push(Malformed::TooDeep);
                    return;
                }
                for p in &b.content {
                    self.walk(p, depth + 1, events, counts, bad);
                }
            }
            OscPacket::Message(m) => {
                counts.messages += 1;
                match self.message(m) {
                    Ok(Some(event)) => {
                        if matches!(event, SkeletonEvent::Joint { .. }) {
                            counts.joints += 1;
                        }
                        events.push(event);
                    }
                    Ok(None) => {}
                    Err(Outcome::Skipped) => counts.skipped_joints += 1,
                    Err(Outcome::Ignored) => counts.ignored += 1,
                    Err(Outcome::Bad(kind)) => bad.push(kind),
                }
            }
        }
    }

    fn message(&self, m: &OscMessage) -> Result<Option<SkeletonEvent>, Outcome> {
        let addr = m.addr.as_str();
        let kinect = addr.starts_with("/bodies/");
        let osceleton = matches!(
            addr,
            "/joint" | "/new_user" | "/new_skel" | "/lost_user" | "/orient"
        ) || addr.starts_with("/user/");
        match (self.format, kinect, osceleton) {
            (SkeletonFormat::KinectV2, true, _) => self.kinect_message(addr, &m.args).map(Some),
            (SkeletonFormat::OsceletonMm | SkeletonFormat::OsceletonNormalized, _, true) => {
                self.osceleton_message(addr, &m.args)
            }
            (_, true, _) | (_, _, true) => Err(Outcome::Bad(Malformed::OtherFormat)),
            _ => Err(Outcome::Bad(Malformed::UnknownAddress)),
        }
    }

    fn osceleton_message(
        &self,
        addr: &str,
        args: &[OscType],
    ) -> Result<Option<SkeletonEvent>, Outcome> {
        let user_event = |make: fn(UserId) -> SkeletonEvent| match args {
            [] => Err(Outcome::Ignored),
            [OscType::Int(id), ..] => user_id(*id).map(|u| Some(make(u))),
            _ => Err(Outcome::Bad(Malformed::WrongTypes)),
        };
        match addr {
            "/joint" => {
                let [OscType::String(name), OscType::Int(id), x, y, z, ..] = args else {
                    return Err(Outcome::Bad(Malformed::WrongTypes));
                };
                let user = user_id(*id)?;
                let [x, y, z] = [number(x)?, number(y)?, number(z)?];
                let joint = Joint::from_osceleton(name).ok_or(Outcome::Skipped)?;
                let pos_mm = match self.format {
                    SkeletonFormat::OsceletonNormalized => osceleton_normalized_to_mm(x, y, z),
                    _ => [x, y, z],
                };
                Ok(Some(self.joint(user, joint, pos_mm, 1.0)?))
            }
            "/new_user" => user_event(SkeletonEvent::NewUser),
            "/new_skel" => user_event(SkeletonEvent::NewSkeleton),
            "/lost_user" => user_event(SkeletonEvent::LostUser),
            _ => Err(Outcome::Ignored),
        }
    }

    fn kinect_message(&self, addr: &str, args: &[OscType]) -> Result<SkeletonEvent, Outcome> {
        let mut parts = addr.split('/').skip(2);
        let (Some(id), Some(kind), Some(name), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(Outcome::Bad(Malformed::UnknownAddress));
        };
        let user: UserId = id
            .parse()
            .map_err(|_| Outcome::Bad(Malformed::UnknownAddress))?;
        match kind {
            "joints" => {}
            "hands" => return Err(Outcome::Ignored),
            _ => return Err(Outcome::Bad(Malformed::UnknownAddress)),
        }
        let [x, y, z, OscType::String(state), ..] = args else {
            return Err(Outcome::Bad(Malformed::WrongTypes));
        };
        let [x, y, z] = [number(x)?, number(y)?, number(z)?];
        let confidence = match state.as_str() {
            "Tracked" => 1.0,
            "Inferred" => 0.5,
            "NotTracked" => return Err(Outcome::Skipped),
            _ => return Err(Outcome::Bad(Malformed::WrongTypes)),
        };
        let joint = Joint::from_kinect_v2(name).ok_or(Outcome::Skipped)?;
        self.joint(
            user,
            joint,
            [x * 1000.0, y * 1000.0, z * 1000.0],
            confidence,
        )
    }

    fn joint(
        &self,
        user: UserId,
        joint: Joint,
        pos_mm: [f64; 3],
        confidence: f32,
    ) -> Result<SkeletonEvent, Outcome> {
        if !pos_mm.iter().all(|c| c.is_finite()) {
            return Err(Outcome::Bad(Malformed::NonFinite));
        }
        Ok(SkeletonEvent::Joint {
            user,
            joint: if self.swap_lr {
                joint.mirrored()
            } else {
                joint
            },
            pos_mm,
            confidence,
        })
    }
}

/// Why a message produced no event.
enum Outcome {
    Skipped,
    Ignored,
    Bad(Malformed),
}

fn user_id(id: i32) -> Result<UserId, Outcome> {
    UserId::try_from(id).map_err(|_| Outcome::Bad(Malformed::WrongTypes))
}

fn number(arg: &OscType) -> Result<f64, Outcome> {
    match arg {
        OscType::Float(v) => Ok(f64::from(*v)),
        OscType::Double(v) => Ok(*v),
        _ => Err(Outcome::Bad(Malformed::WrongTypes)),
    }
}

#[cfg(test)]
mod tests;
