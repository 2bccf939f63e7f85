//! [`GatingStage`]: the paper's mixing function, plus manual teleop and the e-stop.
//!
//! In reactive mode the fixed response ϱ replaces the default policy π while the stimulus E is present,
//! `b = I{E}ϱ + (1 − I{E})π`; in Pavlovian mode also while the gating prediction exceeds its threshold,
//! `f(v) = I{E ∨ v > θ}`; in manual mode the wheels follow teleop commands, which expire after
//! [`TELEOP_HOLD_TICKS`] so that an operator who goes away cannot leave the robot driving.

use crate::control::{Action, Mode, Policy, gate, mix};

/// How many ticks a teleop command drives the wheels without being refreshed (0.5 s at 50 Hz).
pub const TELEOP_HOLD_TICKS: u64 = 25;

/// What gating decided on one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateOutput {
    /// Mode in force.
    pub mode: Mode,
    /// Whether the fixed response was selected.
    pub gate: bool,
    /// The default policy's action π.
    pub default_action: Action,
    /// The action to take (actuation may still override it for safety).
    pub action: Action,
}

/// Gating's state.
#[derive(Debug, Clone)]
pub struct GatingStage {
    mode: Mode,
    default_policy: Policy,
    response: Policy,
    estop: bool,
    teleop: Option<(Action, u64)>,
}

/// Why a command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GateError {
    /// Teleop outside manual mode.
    #[error("teleop needs manual mode; the server is in {0} mode")]
    NotManual(&'static str),
    /// Teleop while the e-stop is latched.
    #[error("the e-stop is latched; release it first")]
    EStopLatched,
}

fn mode_name(m: Mode) -> &'static str {
    match m {
        Mode::Reactive => "reactive",
        Mode::Pavlovian => "pavlovian",
        Mode::Manual => "manual",
    }
}

impl GatingStage {
    /// A gate in `mode` between `default_policy` (π) and `response` (ϱ).
    pub fn new(mode: Mode, default_policy: Policy, response: Policy) -> Self {
        GatingStage {
            mode,
            default_policy,
            response,
            estop: false,
            teleop: None,
        }
    }

    /// The mode in force.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Switches mode (and drops any teleop command).
    pub fn set_mode(&mut self, mode: Mode) {
        self.mode = mode;
        self.teleop = None;
    }

    /// Latches or releases the e-stop.
    pub fn set_estop(&mut self, on: bool) {
        self.estop = on;
        self.teleop = None;
    }

    /// Accepts a teleop command on tick `seq` (manual mode only).
    pub fn teleop(&mut self, action: Action, seq: u64) -> Result<(), GateError> {
        if self.mode != Mode::Manual {
            return Err(GateError::NotManual(mode_name(self.mode)));
        }
        if self.estop {
            return Err(GateError::EStopLatched);
        }
        self.teleop = Some((action, seq));
        Ok(())
    }

    /// Decides tick `seq`'s action from the stimulus and the gating prediction (`None` = invalid input:
    /// the gate then falls back to the stimulus alone).
    pub fn decide(
        &mut self,
        seq: u64,
        stimulus: bool,
        prediction: Option<f64>,
        threshold: f64,
    ) -> GateOutput {
        let default_action = self.default_policy.action(seq);
        let (engaged, action) = match self.mode {
            Mode::Manual => {
                let a = match self.teleop {
                    Some((a, at)) if seq.saturating_sub(at) <= TELEOP_HOLD_TICKS => a,
                    _ => Action::STOP,
                };
                (false, a)
            }
            mode => {
                let engaged = gate(mode, stimulus, prediction, threshold);
                let response = self.response.action(seq);
                (engaged, mix(response, default_action, engaged))
            }
        };
        GateOutput {
            mode: self.mode,
            gate: engaged,
            default_action,
            action: if self.estop { Action::STOP } else { action },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stage(mode: Mode) -> GatingStage {
        GatingStage::new(
            mode,
            Policy::Constant {
                left_mm_s: 200,
                right_mm_s: 200,
            },
            Policy::Stop {},
        )
    }

    #[test]
    fn reactive_responds_only_to_the_stimulus_pavlovian_also_to_the_prediction() {
        let mut r = stage(Mode::Reactive);
        assert_eq!(
            r.decide(0, false, Some(0.9), 0.5).action,
            Action::new(200, 200)
        );
        assert_eq!(r.decide(1, true, Some(0.0), 0.5).action, Action::STOP);
        let mut p = stage(Mode::Pavlovian);
        let out = p.decide(0, false, Some(0.9), 0.5);
        assert!(out.gate);
        assert_eq!(out.action, Action::STOP);
        assert_eq!(out.default_action, Action::new(200, 200));
        // An invalid prediction falls back to the stimulus alone.
        assert!(!p.decide(1, false, None, 0.5).gate);
    }

    #[test]
    fn estop_overrides_everything_and_teleop_expires() {
        let mut g = stage(Mode::Manual);
        assert_eq!(g.decide(0, false, None, 0.5).action, Action::STOP);
        g.teleop(Action::new(100, -100), 10).unwrap();
        assert_eq!(
            g.decide(10 + TELEOP_HOLD_TICKS, false, None, 0.5).action,
            Action::new(100, -100)
        );
        assert_eq!(
            g.decide(11 + TELEOP_HOLD_TICKS, false, None, 0.5).action,
            Action::STOP
        );
        g.set_estop(true);
        assert_eq!(
            g.teleop(Action::new(1, 1), 50),
            Err(GateError::EStopLatched)
        );
        let mut p = stage(Mode::Pavlovian);
        p.set_estop(true);
        assert_eq!(p.decide(0, false, Some(0.0), 0.5).action, Action::STOP);
        assert_eq!(
            stage(Mode::Reactive).teleop(Action::STOP, 0),
            Err(GateError::NotManual("reactive"))
        );
    }
}
