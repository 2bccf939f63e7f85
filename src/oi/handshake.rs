//! The byte sequences the server speaks at start-up and shut-down.
//!
//! Start-up: Start (→ Passive), then Safe or Full, then the Stream request, after checking that the stream's
//! frame fits the baud's 15 ms budget [C1 p14; C2 p22]. Shut-down: stop both wheels, pause the stream and
//! return the robot to Passive with Start, so it can charge and nothing moves [C1 p7; C2 p8; libcreate `serial.cpp` and pycreate2 shut down the same way].

use super::command::Command;
use super::frame::check_stream_budget;
use super::mode::DriveMode;
use super::model::{BAUD_RATES, baud_code};
use super::{Model, OiError};

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
/// trip is never overridden without the operator), then Stream again [libcreate `serial.cpp` re-sends Start and Stream on a timeout].
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

/// Rates one baud rescue tries: each costs ~110 ms with the port unread, so a rescue never keeps the port
/// from being read for much longer than 200 ms, and frames that return meanwhile are seen soon after.
pub const BAUD_RESCUE_BATCH: usize = 2;

/// Every rate a baud rescue may try, most likely first: 300 and 600 baud (a flipped bit turns Drive
/// Direct, Drive, Safe or Start into Baud (129), and the next byte, a small speed's high byte, is code 0
/// or 1 [C1 p7; C2 p9]), then the documented fallback 19200 [C1 p5; C2 p4], then the others from the
/// fastest down; never `model`'s default.
pub fn baud_rescue_rates(model: Model) -> Vec<u32> {
    let likely = [300, 600, 19_200];
    likely
        .into_iter()
        .chain(BAUD_RATES.into_iter().rev().filter(|r| !likely.contains(r)))
        .filter(|&r| r != model.baud())
        .collect()
}

/// The rates of rescue number `index` since the last frame: the next [`BAUD_RESCUE_BATCH`] of
/// [`baud_rescue_rates`], starting over after the last.
pub fn baud_rescue_batch(model: Model, index: u32) -> Vec<u32> {
    let rates = baud_rescue_rates(model);
    let batches = rates.len().div_ceil(BAUD_RESCUE_BATCH).max(1);
    let k = index as usize % batches;
    rates
        .iter()
        .skip(k * BAUD_RESCUE_BATCH)
        .take(BAUD_RESCUE_BATCH)
        .copied()
        .collect()
}

/// The Baud command that returns `model` to its default rate (sent at each rescue rate).
pub fn baud_back_bytes(model: Model) -> Vec<u8> {
    let code = baud_code(model.baud()).unwrap_or(10);
    Command::Baud(code).encode(model).unwrap_or_default()
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

    #[test]
    fn baud_rescues_try_the_likely_rates_first_two_at_a_time_and_cycle() {
        let all = baud_rescue_rates(Model::Create1);
        assert_eq!(all.len(), 11);
        assert!(!all.contains(&57_600));
        assert_eq!(&all[..3], &[300, 600, 19_200]);
        assert_eq!(baud_rescue_batch(Model::Create1, 0), vec![300, 600]);
        assert_eq!(baud_rescue_batch(Model::Create1, 1), vec![19_200, 115_200]);
        let mut seen: Vec<u32> = (0..6)
            .flat_map(|i| baud_rescue_batch(Model::Create1, i))
            .collect();
        seen.sort_unstable();
        let mut sorted = all.clone();
        sorted.sort_unstable();
        assert_eq!(seen, sorted, "six rescues cover every rate once");
        assert_eq!(baud_rescue_batch(Model::Create1, 6), vec![300, 600]);
        assert!(!baud_rescue_rates(Model::Create2).contains(&115_200));
    }
}
