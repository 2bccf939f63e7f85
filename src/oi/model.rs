//! The robot models the server drives: their names, and the way to each one's [`ModelSpec`].

use serde::{Deserialize, Serialize};

use super::spec::{self, ModelSpec};

/// Baud rates of the Baud command's codes 0–11 [C1 p7; C2 p9].
pub const BAUD_RATES: [u32; 12] = [
    300, 600, 1200, 2400, 4800, 9600, 14_400, 19_200, 28_800, 38_400, 57_600, 115_200,
];

/// The Baud command's code for `rate`, if it is one of [`BAUD_RATES`].
pub fn baud_code(rate: u32) -> Option<u8> {
    BAUD_RATES
        .iter()
        .position(|&r| r == rate)
        .and_then(|i| u8::try_from(i).ok())
}

/// An iRobot Create model. What differs between the models is in its [`ModelSpec`] ([`Model::spec`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// The original Create (OI spec v2, 2006): 57600 baud, packets 7–42, group 6.
    Create1,
    /// The Create 2 (Roomba 600 OI): 115200 baud, packets 7–58, group 100.
    Create2,
}

impl Model {
    /// Every model, in declaration order.
    pub const ALL: [Model; 2] = [Model::Create1, Model::Create2];

    /// The model's entry in the per-model table.
    pub const fn spec(self) -> &'static ModelSpec {
        match self {
            Model::Create1 => &spec::CREATE1,
            Model::Create2 => &spec::CREATE2,
        }
    }

    /// Default serial rate [C1 p5; C2 p4].
    pub fn baud(self) -> u32 {
        self.spec().baud
    }

    /// The group packet that holds every sensor packet from 7 up: 6 on the Create 1 (packets 7–42),
    /// 100 on the Create 2 (packets 7–58).
    pub fn all_sensors_group(self) -> u8 {
        self.spec().all_sensors_group
    }

    /// The highest single sensor packet id the model answers.
    pub fn last_packet(self) -> u8 {
        self.spec().last_packet
    }

    /// Bytes the robot can send in one 15 ms stream slot at its default baud (10 bits a byte on the wire):
    /// 86 at 57600, 172 at 115200 [C1 p14; C2 p22].
    pub fn stream_budget_bytes(self) -> usize {
        self.spec().stream_budget_bytes()
    }

    /// A short lowercase name, as used in the configuration and on the command line.
    pub fn name(self) -> &'static str {
        self.spec().name
    }
}

/// Bytes that fit in one 15 ms stream slot (the period of both models) at `baud` (10 bits per byte on
/// the wire).
pub fn stream_budget_bytes(baud: u32) -> usize {
    (baud as usize * 15) / 10_000
}

impl std::fmt::Display for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Model {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Model::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("unknown model `{s}` (expected {})", name_list()))
    }
}

/// "create1 or create2": every model's name, for messages.
fn name_list() -> String {
    let names: Vec<&str> = Model::ALL.iter().map(|m| m.name()).collect();
    match names.split_last() {
        Some((last, [])) => (*last).to_string(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stream_budgets_match_the_spec() {
        assert_eq!(Model::Create1.stream_budget_bytes(), 86);
        assert_eq!(Model::Create2.stream_budget_bytes(), 172);
        assert_eq!(stream_budget_bytes(19_200), 28);
    }

    #[test]
    fn names_round_trip() {
        for m in [Model::Create1, Model::Create2] {
            assert_eq!(m.name().parse::<Model>(), Ok(m));
        }
        assert!("roomba".parse::<Model>().is_err());
    }
}
