//! [`OiError`]: everything that can be wrong with an Open Interface request, packet or frame.
//!
//! Every variant carries the numbers needed to say precisely what was wrong, so a driver or a
//! websocket client can be told "packet 52 is not available on the create1" rather than "bad request".

use super::Model;

/// An invalid Open Interface packet id, value, command or stream request.
#[derive(Debug, Clone, thiserror::Error, PartialEq, Eq)]
pub enum OiError {
    /// The id is neither a single sensor packet (7–58) nor a defined group (0–6, 100, 101, 106, 107).
    #[error(
        "unknown sensor packet id {0} (single packets are 7-58, groups 0-6, 100, 101, 106, 107)"
    )]
    UnknownPacket(u8),

    /// The packet or group exists, but not on this model (e.g. 43–58 and 100–107 are Create 2 only).
    #[error("sensor packet {id} is not available on the {model}")]
    NotOnModel { id: u8, model: Model },

    /// A byte slice has the wrong length for the packet or group it is supposed to hold.
    #[error("packet {id} needs {expected} data bytes, got {got}")]
    BadLength { id: u8, expected: usize, got: usize },

    /// A stream frame would not fit in one 15 ms slot at this baud rate [C1 p14; C2 p22].
    #[error(
        "a stream frame of {frame_bytes} bytes does not fit the {budget}-byte budget of one 15 ms slot at {baud} baud"
    )]
    OverBudget {
        frame_bytes: usize,
        budget: usize,
        baud: u32,
    },

    /// A Stream or Query List request with no packet ids.
    #[error("the packet list is empty (Stream and Query List need at least one packet id)")]
    EmptyStreamList,

    /// More packet ids than the model accepts in one Stream or Query List request.
    #[error("{count} packet ids requested, but the {model} accepts at most {limit}")]
    TooManyPackets {
        count: usize,
        limit: usize,
        model: Model,
    },

    /// A stream frame whose id/data bytes would not fit in its one-byte length field.
    #[error(
        "a stream frame needs {data_bytes} id and data bytes, more than the 255 its length byte can say"
    )]
    FrameTooLong { data_bytes: usize },

    /// A command that the model does not have (e.g. Stop on a Create 1, Demo on a Create 2).
    #[error("command {command} is not available on the {model}")]
    CommandNotOnModel { command: &'static str, model: Model },

    /// A command argument outside the range the specification allows.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_the_numbers() {
        let e = OiError::OverBudget {
            frame_bytes: 90,
            budget: 86,
            baud: 57_600,
        };
        let text = e.to_string();
        assert!(text.contains("90") && text.contains("86") && text.contains("57600"));
        let e = OiError::NotOnModel {
            id: 52,
            model: Model::Create1,
        };
        assert_eq!(
            e.to_string(),
            "sensor packet 52 is not available on the create1"
        );
    }
}
