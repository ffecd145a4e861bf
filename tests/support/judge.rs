//! Judging a flight: distances to a path and their quantiles, the
//! daemon's flight CSV read back and its commands checked, tilts.

use std::path::{Path, PathBuf};

/// Distance from `p` to the polyline through `w` (3-D) \[m\].
pub fn path_distance(w: &[[f64; 3]], p: [f64; 3]) -> f64 {
    w.windows(2)
        .map(|seg| {
            let (a, b) = (seg[0], seg[1]);
            let ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]];
            let len2 = ab.iter().map(|x| x * x).sum::<f64>();
            let s = if len2 > 0.0 {
                (ap.iter().zip(&ab).map(|(x, y)| x * y).sum::<f64>() / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            dist(p, [a[0] + s * ab[0], a[1] + s * ab[1], a[2] + s * ab[2]])
        })
        .fold(f64::INFINITY, f64::min)
}

/// The true distances to `path` (NED \[m\]) of the `trace`'s samples
/// while commanded, from the first commanded one until the vehicle is
/// within `arrival` \[m\] of the path's end; and whether it got there.
pub fn path_errors(
    trace: &[dflat_sitl::TruthSample],
    path: &[[f64; 3]],
    arrival: f64,
) -> (Vec<f64>, bool) {
    let end_point = *path.last().expect("a path");
    let first = trace
        .iter()
        .position(|s| s.command.is_some())
        .unwrap_or(trace.len());
    let end = trace[first..]
        .iter()
        .position(|s| dist(s.position, end_point) < arrival)
        .map(|i| first + i);
    let errors = trace[first..end.unwrap_or(trace.len())]
        .iter()
        .map(|s| path_distance(path, s.position))
        .collect();
    (errors, end.is_some())
}

/// Euclidean distance \[m\].
pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The `q`-quantile of `v` (sorted copy, nearest rank).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)]
}

/// The largest step from one attitude target to the next of roll or
/// pitch \[deg\].
pub fn largest_tilt_step_deg<'a>(
    targets: impl Iterator<Item = &'a dflat_link::dialect::SET_ATTITUDE_TARGET_DATA>,
) -> f64 {
    let tilts: Vec<[f64; 3]> = targets
        .map(|d| dflat_link::euler_from_quaternion(d.q.map(f64::from)))
        .collect();
    tilts
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).abs().max((w[1][1] - w[0][1]).abs()))
        .fold(0.0, f64::max)
        .to_degrees()
}

/// The daemon's per-flight CSV in `dir` (the newest `*.csv`) as rows of
/// column name → field.
pub fn read_flight_csv(dir: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let mut csvs: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "csv")
                && !p
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("truth"))
        })
        .collect();
    csvs.sort();
    let path = csvs.pop().expect("no flight CSV");
    let text = std::fs::read_to_string(&path).expect("read CSV");
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .expect("header")
        .split(',')
        .map(str::to_owned)
        .collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(str::to_owned))
                .collect()
        })
        .collect()
}

/// A numeric CSV field (`None` when empty).
pub fn field(row: &std::collections::HashMap<String, String>, name: &str) -> Option<f64> {
    row.get(name)
        .filter(|v| !v.is_empty())
        .map(|v| v.parse().unwrap_or(f64::NAN))
}

/// The capture time of the newest pose a CSV row's tick had, on the
/// daemon's clock: the tick's `t_wake` less the pose's age \[s\].
pub fn pose_capture(row: &std::collections::HashMap<String, String>) -> Option<f64> {
    Some(field(row, "t_wake")? - field(row, "pose_age_ms")? / 1e3)
}

/// Checks every command in the CSV rows: finite, tilt ≤ `max_tilt_deg`,
/// thrust in [0, 1]. Returns the number of commands and the largest tilt \[deg\].
pub fn check_csv_commands(
    rows: &[std::collections::HashMap<String, String>],
    max_tilt_deg: f64,
) -> (usize, f64) {
    let mut n = 0;
    let mut worst: f64 = 0.0;
    for r in rows {
        let (Some(roll), Some(pitch), Some(yaw), Some(thrust)) = (
            field(r, "roll"),
            field(r, "pitch"),
            field(r, "yaw"),
            field(r, "thrust"),
        ) else {
            continue;
        };
        n += 1;
        assert!(
            [roll, pitch, yaw, thrust].iter().all(|v| v.is_finite()),
            "non-finite command at tick {:?}",
            r.get("tick")
        );
        let tilt = (roll.cos() * pitch.cos())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        worst = worst.max(tilt);
        assert!(
            tilt <= max_tilt_deg + 1e-3,
            "tilt {tilt:.2}° at tick {:?}",
            r.get("tick")
        );
        assert!((0.0..=1.0).contains(&thrust), "thrust {thrust}");
    }
    (n, worst)
}

/// Tilt of a SET_ATTITUDE_TARGET quaternion [w, x, y, z] \[deg\], or NaN if
/// it is not finite.
pub fn quaternion_tilt_deg(q: [f32; 4]) -> f64 {
    let [w, x, y, z] = q.map(f64::from);
    let n = (w * w + x * x + y * y + z * z).sqrt();
    if !n.is_finite() || n == 0.0 {
        return f64::NAN;
    }
    let (x, y) = (x / n, y / n);
    (1.0 - 2.0 * (x * x + y * y))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}
