//! The flight files' names: `flight-YYYYmmdd-HHMMSS` (UTC) and its
//! `.csv` / `.tlog`, as the daemon writes them and the tools find them.

use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// `YYYYmmdd-HHMMSS` (UTC) of `t`, e.g. `20261102-134501`.
pub fn utc_stamp(t: SystemTime) -> String {
    let secs = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        (rem / 60) % 60,
        rem % 60
    )
}

/// Proleptic Gregorian date (year, month 1–12, day 1–31) of a day count
/// since 1970-01-01 (H. Hinnant's algorithm).
pub fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

/// `dir/flight-YYYYmmdd-HHMMSS` (UTC, no extension) for a flight starting
/// at `t`; adds `-2`, `-3`, … if a `.csv` or `.tlog` of that name exists.
pub fn flight_stem(dir: &Path, t: SystemTime) -> PathBuf {
    let base = format!("flight-{}", utc_stamp(t));
    let taken = |stem: &str| {
        dir.join(format!("{stem}.csv")).exists() || dir.join(format!("{stem}.tlog")).exists()
    };
    if !taken(&base) {
        return dir.join(base);
    }
    (2..)
        .map(|i| format!("{base}-{i}"))
        .find(|s| !taken(s))
        .map(|s| dir.join(s))
        .unwrap_or_else(|| dir.join(base))
}

/// The `.tlog` of a flight given as its `.tlog` or its `.csv` (the two
/// share a stem); `None` for any other extension.
pub fn tlog_beside(flight: &Path) -> Option<PathBuf> {
    match flight.extension().and_then(|e| e.to_str()) {
        Some("tlog") => Some(flight.to_owned()),
        Some("csv") => Some(flight.with_extension("tlog")),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn stamps_are_utc_calendar_times() {
        assert_eq!(utc_stamp(UNIX_EPOCH), "19700101-000000");
        // 2026-11-02 13:45:01 UTC.
        let t = UNIX_EPOCH + Duration::from_secs(1_793_627_101);
        assert_eq!(utc_stamp(t), "20261102-134501");
        // A leap day.
        let t = UNIX_EPOCH + Duration::from_secs(951_782_400);
        assert_eq!(utc_stamp(t), "20000229-000000");
    }

    #[test]
    fn a_flight_s_tlog_is_beside_its_csv() {
        let csv = Path::new("flights/flight-20261102-134501.csv");
        assert_eq!(
            tlog_beside(csv),
            Some(PathBuf::from("flights/flight-20261102-134501.tlog"))
        );
        assert_eq!(
            tlog_beside(Path::new("x.tlog")),
            Some(PathBuf::from("x.tlog"))
        );
        assert_eq!(tlog_beside(Path::new("x.json")), None);
    }
}
