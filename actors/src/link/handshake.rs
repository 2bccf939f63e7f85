//! The byte sequences the server speaks at start-up and shut-down.
//!
//! Start-up: Start (→ Passive), then Safe or Full, then the Stream request, after checking that the stream's
//! frame fits the baud's 15 ms budget [C1 p14; C2 p22]. Shut-down: stop both wheels, pause the stream and
//! return the robot to Passive with Start, so it can charge and nothing moves [create_oi.md §1.3, §4.3 (5)].

pub use pavlov::config::DriveMode;
use pavlov::oi::command::Command;
use pavlov::oi::frame::check_stream_budget;
use pavlov::oi::{Model, OiError};

/// The start-up bytes: Start, Safe/Full, Stream(ids). Fails when the stream does not fit the baud.
pub fn startup_bytes(model: Model, mode: DriveMode, stream: &[u8]) -> Result<Vec<u8>, OiError> {
    check_stream_budget(stream, model.baud())?;
    let mut out = Command::Start.encode(model)?;
    out.extend(
        match mode {
            DriveMode::Safe => Command::Safe,
            DriveMode::Full => Command::Full,
        }
        .encode(model)?,
    );
    out.extend(Command::Stream(stream.to_vec()).encode(model)?);
    Ok(out)
}

/// The bytes of a re-sync after a stale stream: Start, then Safe/Full unless the robot has tripped (a
/// trip is never overridden without the operator), then Stream again [create_oi.md §4.3 (4), §1.3 libcreate].
pub fn resync_bytes(
    model: Model,
    mode: Option<DriveMode>,
    stream: &[u8],
) -> Result<Vec<u8>, OiError> {
    match mode {
        Some(mode) => startup_bytes(model, mode, stream),
        None => {
            check_stream_budget(stream, model.baud())?;
            let mut out = Command::Start.encode(model)?;
            out.extend(Command::Stream(stream.to_vec()).encode(model)?);
            Ok(out)
        }
    }
}

/// The mode command alone (Safe or Full), sent when the operator re-arms after a trip.
pub fn mode_bytes(model: Model, mode: DriveMode) -> Result<Vec<u8>, OiError> {
    match mode {
        DriveMode::Safe => Command::Safe,
        DriveMode::Full => Command::Full,
    }
    .encode(model)
}

/// The OI mode code (packet 35) of a drive mode.
pub fn mode_code(mode: DriveMode) -> u8 {
    match mode {
        DriveMode::Safe => pavlov::supervision::mode::code::SAFE,
        DriveMode::Full => pavlov::supervision::mode::code::FULL,
    }
}

/// The shut-down bytes: Drive Direct 0 0, Pause Stream, Start (→ Passive).
pub fn shutdown_bytes(model: Model) -> Result<Vec<u8>, OiError> {
    let mut out = Command::DriveDirect { right: 0, left: 0 }.encode(model)?;
    out.extend(Command::PauseStream.encode(model)?);
    out.extend(Command::Start.encode(model)?);
    Ok(out)
}

/// The bytes that stop both wheels.
pub fn stop_bytes(model: Model) -> Result<Vec<u8>, OiError> {
    Command::DriveDirect { right: 0, left: 0 }.encode(model)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn startup_and_shutdown_bytes() {
        let b = startup_bytes(Model::Create1, DriveMode::Safe, &[6]).unwrap();
        assert_eq!(b, vec![128, 131, 148, 1, 6]);
        let b = startup_bytes(Model::Create2, DriveMode::Full, &[100]).unwrap();
        assert_eq!(b, vec![128, 132, 148, 1, 100]);
        assert_eq!(
            shutdown_bytes(Model::Create1).unwrap(),
            vec![145, 0, 0, 0, 0, 150, 0, 128]
        );
    }

    #[test]
    fn resync_sends_the_mode_only_when_not_tripped() {
        assert_eq!(
            resync_bytes(Model::Create1, Some(DriveMode::Safe), &[6]).unwrap(),
            vec![128, 131, 148, 1, 6]
        );
        assert_eq!(
            resync_bytes(Model::Create1, None, &[6]).unwrap(),
            vec![128, 148, 1, 6]
        );
        assert_eq!(
            mode_bytes(Model::Create2, DriveMode::Full).unwrap(),
            vec![132]
        );
    }

    #[test]
    fn group_100_does_not_fit_a_create_1_budget() {
        // 3 + 1 + 80 = 84 bytes fits 86 at 57600, but group 100 is not a Create 1 packet at all; and two
        // copies of group 6 (2 × 53 + 2 = 108 bytes) exceed the 86-byte budget.
        assert!(startup_bytes(Model::Create1, DriveMode::Safe, &[6, 6]).is_err());
    }
}
