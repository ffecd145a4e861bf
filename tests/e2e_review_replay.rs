//! End to end: one SITL flight (spatial model, noisy positions), then
//! * its `.tlog` read by the mavlink crate's own file connection and frame
//!   by frame: the same messages (the crate's scanning reader may stop a
//!   few frames before the end), every record a whole frame;
//! * `dflat review`: the HTML page has every chart and series, and its
//!   summary numbers are the ones computed here from the CSV;
//! * `dflat replay` with the flight's own configuration reproduces the
//!   logged commands; with another τ it commands something else.

#[path = "support/mod.rs"]
mod common;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use common::*;
use dflat_link::MavMessage;
use dflat_link::mavlink::MavConnection as _;
use dflat_link::tlog::TlogReader;
use dflat_tuning::flightlog::FlightCsv;

const CONFIG: &str = r#"
[logging]
dir = "@DIR@"
tlog = true
[vehicle]
model = "spatial"
thrust_mode = "normalized"
# Pose-locked ticks (the default): each tick runs on its pose's arrival,
# and the CSV's `events` column tells the replay which frames it had seen.
[controller]
tick = "pose"
[mission]
start = "path"
path = [[0.0, 0.0, -10.0], [8.0, 0.0, -10.0], [8.0, 6.0, -10.0]]
speed = 4.0
[sitl]
plant = "spatial"
start = [0.0, 0.0, -10.0]
noise_sigma = 0.01
"#;

fn newest(dir: &Path, ext: &str) -> PathBuf {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == ext) && p.to_string_lossy().contains("flight-")
        })
        .collect();
    v.sort();
    v.pop()
        .unwrap_or_else(|| panic!("no .{ext} in {}", dir.display()))
}

fn dflat(args: &[&str]) -> String {
    String::from_utf8_lossy(&common::dflat_ok(args).stdout).into_owned()
}

/// The value of `key` in the summary table (`data-key="…" data-value="…"`).
fn summary_value(html: &str, key: &str) -> f64 {
    let at = html
        .find(&format!("data-key=\"{key}\""))
        .unwrap_or_else(|| panic!("no summary key {key}"));
    let rest = &html[at..];
    let v = rest
        .split("data-value=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap();
    v.parse().unwrap_or(f64::NAN)
}

fn quantile_of(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((q * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)]
}

#[test]
fn a_flight_reviewed_replayed_and_its_tlog_read_by_the_mavlink_crate() {
    let name = "review-replay";
    let _flight = fly_in_process(name, CONFIG, Duration::from_secs(8));
    let dir = scratch_dir(name);
    let csv_path = newest(&dir, "csv");
    let tlog_path = newest(&dir, "tlog");
    let config = dir.join(format!("{name}.toml"));

    // 1. The tlog: frame by frame (our reader), and the mavlink crate's own
    // file connection, which scans for frames: the same message counts.
    let mut ours: HashMap<u32, usize> = HashMap::new();
    let mut last_ts = 0;
    for r in TlogReader::new(std::io::BufReader::new(
        std::fs::File::open(&tlog_path).unwrap(),
    )) {
        let r = r.expect("whole records");
        assert!(
            r.timestamp_us >= 1_700_000_000_000_000,
            "timestamp {} is not UNIX µs",
            r.timestamp_us
        );
        assert!(r.timestamp_us + 1_000_000 >= last_ts, "time runs backwards");
        last_ts = r.timestamp_us;
        let f = r.parse().expect("every record one valid frame");
        *ours
            .entry(dflat_link::mavlink::Message::message_id(&f.message))
            .or_default() += 1;
    }
    let conn = dflat_link::mavlink::connect::<MavMessage>(&format!("file:{}", tlog_path.display()))
        .expect("mavlink file connection");
    let mut theirs: HashMap<u32, usize> = HashMap::new();
    while let Ok((_, msg)) = conn.recv() {
        *theirs
            .entry(dflat_link::mavlink::Message::message_id(&msg))
            .or_default() += 1;
    }
    for id in [0u32, 30, 32, 82] {
        assert!(
            ours.get(&id).copied().unwrap_or(0) > 10,
            "message {id}: {ours:?}"
        );
    }
    // The crate's file connection scans for a magic byte between frames:
    // a timestamp byte 0xFD or 0xFE within the file's last ~270 bytes
    // makes it read a frame past the end, and it stops there (seen: the
    // last 6 of 1523 frames). It never reads a frame we did not.
    let missing: usize = ours
        .iter()
        .map(|(id, n)| {
            let t = theirs.get(id).copied().unwrap_or(0);
            assert!(t <= *n, "message {id}: the crate read {t}, we {n}");
            n - t
        })
        .sum();
    assert!(
        theirs.keys().all(|id| ours.contains_key(id)) && missing <= 8,
        "frame-by-frame {ours:?} vs the mavlink crate's reader {theirs:?}"
    );

    // 2. The review page.
    let html_path = dir.join("review.html");
    dflat(&[
        "review",
        csv_path.to_str().unwrap(),
        "--out",
        html_path.to_str().unwrap(),
    ]);
    let html = std::fs::read_to_string(&html_path).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
    assert!(
        !html.contains("<script") && !html.contains("http://")
            || html.contains("xmlns=\"http://www.w3.org/2000/svg\"")
    );
    for id in [
        "path",
        "tracking-error",
        "attitude",
        "thrust",
        "timing",
        "pose-age",
    ] {
        assert!(
            html.contains(&format!("<svg id=\"{id}\"")),
            "chart {id} missing"
        );
    }
    for series in [
        "measured",
        "reference",
        "tracking error",
        "roll command",
        "pitch command",
        "roll measured",
        "pitch measured",
        "thrust command",
        "solve time",
        "tick jitter",
        "pose age",
    ] {
        let tag = format!("data-name=\"{series}\" data-points=\"");
        let at = html
            .find(&tag)
            .unwrap_or_else(|| panic!("series {series} missing"));
        let n: usize = html[at + tag.len()..]
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert!(n > 100, "series {series}: {n} points");
    }
    assert!(html.contains("class=\"marker\""), "no state-change markers");
    // Summary numbers against the CSV, computed independently here.
    let csv = FlightCsv::read(&csv_path).unwrap();
    let num = |c: &str| csv.numbers(c);
    let (x, y, z, rx, ry, rz) = (
        num("x"),
        num("y"),
        num("z"),
        num("ref_x"),
        num("ref_y"),
        num("ref_z"),
    );
    let err: Vec<f64> = (0..csv.rows.len())
        .filter_map(|i| {
            Some(
                ((x[i]? - rx[i]?).powi(2) + (y[i]? - ry[i]?).powi(2) + (z[i]? - rz[i]?).powi(2))
                    .sqrt(),
            )
        })
        .collect();
    let solves: Vec<f64> = num("solve_us").into_iter().flatten().collect();
    assert_eq!(summary_value(&html, "ticks"), csv.rows.len() as f64);
    assert_eq!(
        summary_value(&html, "commands"),
        num("roll").iter().flatten().count() as f64
    );
    assert!(
        (summary_value(&html, "tracking_error_p95_m") - quantile_of(err.clone(), 0.95)).abs()
            < 1e-12
    );
    assert!((summary_value(&html, "tracking_error_max_m") - quantile_of(err, 1.0)).abs() < 1e-12);
    assert_eq!(
        summary_value(&html, "solve_us_max"),
        quantile_of(solves, 1.0)
    );

    // 3. Replay with the flight's own configuration: every command, to the
    // CSV's resolution (1 µrad). The tlog stamps each received frame at
    // the daemon's own arrival (whole µs past its epoch), the `events`
    // column cuts the batches, `t_wake` is the exact tick time and
    // `solve_us` the stopwatch. (Before the stamps were shared,
    // 2026-11-26: 232 to 401 of 401, and one flight in five off by up to
    // 0.6 mrad from a pose sample at the edge of the multi-rate window.)
    let compared = assert_replays_exactly(&csv_path, &config, &dir.join("replay.html"));
    let replay_html = std::fs::read_to_string(dir.join("replay.html")).unwrap();
    assert!(
        replay_html.contains("data-name=\"roll, replay with"),
        "no replay series in the review"
    );

    // Another τ commands something else (the replay is not a copy of the log).
    let other = dir.join("other.toml");
    let text = std::fs::read_to_string(&config)
        .unwrap()
        .replace("model = \"spatial\"", "model = \"spatial\"\ntau = 0.35");
    std::fs::write(&other, text).unwrap();
    let out = dflat(&[
        "replay",
        csv_path.to_str().unwrap(),
        "--config",
        other.to_str().unwrap(),
    ]);
    let identical_other = replay_field(&out, " identical at");
    assert!(
        identical_other < 0.2 * compared,
        "τ 0.35: {identical_other} identical\n{out}"
    );
}

/// The number just before `key` in `dflat replay`'s report line.
fn replay_field(out: &str, key: &str) -> f64 {
    out.split(key)
        .next()
        .unwrap()
        .split_whitespace()
        .last()
        .unwrap()
        .trim_end_matches(',')
        .parse()
        .unwrap()
}

/// `dflat replay` of `csv` with `config` reproduces every logged command
/// to the CSV's resolution; returns the commands compared.
fn assert_replays_exactly(csv: &Path, config: &Path, out_html: &Path) -> f64 {
    let out = dflat(&[
        "replay",
        csv.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--out",
        out_html.to_str().unwrap(),
    ]);
    eprintln!("{out}");
    let field = |key: &str| replay_field(&out, key);
    let compared = field(" commands compared");
    let identical = field(" identical at");
    assert!(compared > 200.0, "{out}");
    assert!(
        identical == compared && field(" ticks where only one side streamed") == 0.0,
        "own config: {identical} of {compared} identical\n{out}"
    );
    let largest: f64 = out
        .split("largest attitude difference ")
        .nth(1)
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        largest <= 0.5e-6 + 1e-12,
        "own config: largest difference {largest:e} rad\n{out}"
    );
    compared
}

/// A clock-ticked flight (ticks on the deadline, poses whenever they
/// arrive, the pose clock mapping every capture time) replays exactly too.
#[test]
fn a_clock_ticked_flight_replays_exactly() {
    let name = "review-replay-clock";
    let config = CONFIG.replace("tick = \"pose\"", "tick = \"clock\"");
    assert_ne!(config, CONFIG);
    let _flight = fly_in_process(name, &config, Duration::from_secs(8));
    let dir = scratch_dir(name);
    assert_replays_exactly(
        &newest(&dir, "csv"),
        &dir.join(format!("{name}.toml")),
        &dir.join("replay.html"),
    );
}
