//! UTC time stamps for names on disk (`20261124T013000Z`): fixed width, so they sort by time, and
//! readable without a calendar library. The server's run ids and default recording and save names use
//! them.

use std::time::{SystemTime, UNIX_EPOCH};

/// `time` as `YYYYMMDDTHHMMSSZ` (UTC, whole seconds; before 1970 reads as 1970).
pub(crate) fn stamp(time: SystemTime) -> String {
    let secs = time.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rest) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rest / 3600,
        rest % 3600 / 60,
        rest % 60
    )
}

/// Year, month and day of the `days`-th day after 1970-01-01 (Howard Hinnant's `civil_from_days`).
fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + u64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(secs: u64) -> String {
        stamp(UNIX_EPOCH + Duration::from_secs(secs))
    }

    #[test]
    fn known_instants() {
        assert_eq!(at(0), "19700101T000000Z");
        // `date -u -d @951782400`: Tue Feb 29 00:00:00 UTC 2000 (a leap day of a century leap year).
        assert_eq!(at(951_782_400), "20000229T000000Z");
        // `date -u -d @1795483800`: Tue Nov 24 01:30:00 UTC 2026.
        assert_eq!(at(1_795_483_800), "20261124T013000Z");
        assert_eq!(at(4_102_444_799), "20991231T235959Z");
    }

    #[test]
    fn stamps_sort_like_times() {
        let mut last = at(0);
        for secs in (0..4_102_444_800u64).step_by(9_999_991) {
            let s = at(secs);
            assert!(s >= last, "{s} < {last}");
            last = s;
        }
    }
}
