//! End to end, learned maps: the SITL's aerodynamic plant (parasitic drag
//! 0.03 |v|v and rotor drag 0.2 /s in the body plane, which no parametric
//! term of the daemon's planar model has: `vehicle.drag_rotor` is the
//! spatial model's, and the planar model leaves the altitude, where its
//! lift acts, to the autopilot) flown three times from a planner's
//! stream — stock, identified (`dflat identify` on the stock flight's
//! .tlog), learned (`dflat learn` on the first two flights' CSVs over the
//! identified `[vehicle]` table) — against the same airframe without the
//! aerodynamics (the matched plant) flown in the same run.
//!
//! Judged from the SITL's truth against the planner's trajectory at the
//! same SITL time, from the stream's ramp plus 2 s to its end (p95
//! horizontal, and p95 per axis): what an independent judge of the stream
//! sees. The daemon's own CSV (the measured position against the
//! reference at the tick) is printed beside it; without pose noise the two
//! agree within half a millimetre.
//!
//! The flights fly on vision poses (50 Hz, 60 ms latency told to the
//! daemon, 2 cm noise: the lab's sensing, what a companion computer
//! sees). Asserted: the learned flight within 1.1× the matched one (the
//! budget; 2026-11-29: 1.01–1.02× in three runs, one beside two busy loops — learned
//! 0.0552 m against 0.0543 m matched, identified 0.191 m, stock 1.56 m);
//! learned better than identified; after identify or learn no axis worse
//! than before; `dflat learn` learns (a refusal fails the test); the
//! learned model's status said in the daemon's log. The held-out
//! input-to-output prediction (0.48–0.49× the parametric model's in those
//! runs) is printed; the unit tests of `learn` assert it. A flight the
//! machine starved (a tick over 5 ms late in the daemon's own records) is
//! flown again (`fly`).
//!
//! `E2E_EXACT=1` flies exact poses (LOCAL_POSITION_NED at 50 Hz, no
//! noise) instead and asserts the same orderings and the held-out
//! prediction at most half the parametric model's; the 1.1× is printed,
//! not asserted: there the matched flight is 1.5 mm and 1.1× asks the
//! residual for the drag to 0.1 % (2026-11-29: learned 0.0040 m, 2.75×;
//! with the plant's own aerodynamics as the model file's weights 1.19×;
//! docs/results.md).

#[path = "support/mod.rs"]
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::*;
use dflat_tuning::flightlog::FlightLog;
use dflat_tuning::identify;

/// The stream: a racing line (accelerate along the sides, brake and turn
/// at the ends) at 7 m/s, 20 Hz p/v/a, as the lab's `experiment learned`.
const SPEED: f64 = 7.0;
const SIZE: f64 = 24.0 * (SPEED / 4.0) * (SPEED / 4.0);
const RAMP_S: f64 = 3.0;
const STREAM_S: f64 = 16.0;
/// Where the vehicle and the planner's trajectory start, NED \[m\].
const START: [f64; 3] = [0.0, 0.0, -10.0];

/// Whether the flights fly on vision poses: 50 Hz, 60 ms latency (told to
/// the daemon, `link.pose_min_latency_ms`), 2 cm noise — the lab's
/// sensing; unless `E2E_EXACT=1` (exact poses, module docs).
fn vision() -> bool {
    std::env::var_os("E2E_EXACT").is_none_or(|v| v != "1")
}

/// One flight's config: `vehicle` (a `[vehicle]` table or empty),
/// `extra` daemon lines, the aerodynamics on or off.
fn config(vehicle: &str, extra: &str, aero: bool) -> String {
    let drag = if aero {
        "quadratic_drag = 0.03\nrotor_drag = 0.2\n"
    } else {
        ""
    };
    let (link, sensing) = if vision() {
        (
            "[link]\npose_source = \"vision_position_estimate\"\npose_min_latency_ms = 60.0\n",
            "vision_rate_hz = 50.0\nvision_latency_ms = 60.0\nvision_noise_sigma = 0.02\n",
        )
    } else {
        ("", "")
    };
    format!(
        r#"
{realtime}
{vehicle}
{link}
{extra}
[logging]
dir = "@DIR@"
tlog = true
csv = true
[mission]
start = "hold"
[sitl]
start = {START:?}
{drag}
{sensing}
[sitl.planner]
shape = "racing_line"
size = {SIZE}
speed = {SPEED}
ramp_s = {RAMP_S}
rate_hz = 20.0
fields = "pva"
start_after_s = 1.0
duration_s = {STREAM_S}
"#,
        realtime = realtime_if_granted(),
    )
}

/// What one flight gives, from its CSV.
#[derive(Debug, Clone, Copy)]
struct Judged {
    /// Horizontal error to the reference, p95 \[m\].
    p95: f64,
    /// p95 of |x − ref_x|, |y − ref_y| \[m\].
    axes: [f64; 2],
    /// The daemon's STATUSTEXTs that speak of the learned residual.
    said: usize,
    /// The same judged from the SITL's truth against the planner's
    /// trajectory at the same SITL time: p95 horizontal, and per axis \[m\].
    truth: f64,
    truth_axes: [f64; 2],
}

/// The daemon's CSV in `dir`.
fn csv_in(dir: &Path) -> PathBuf {
    let mut csvs: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read dir")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "csv")
                && p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("flight"))
        })
        .collect();
    csvs.sort();
    csvs.pop().expect("no flight CSV")
}

fn tlog_in(dir: &Path) -> PathBuf {
    csv_in(dir).with_extension("tlog")
}

/// Flies `config` (real daemon, in-process SITL) and judges it from the
/// daemon's CSV: TRACKING ticks from the first one + ramp + 2 s to the
/// stream's end. A flight the machine starved is flown again, and when
/// every one was, the least late is judged ([`fly_unstarved`]); the judged
/// flight's records are in `name`'s scratch directory (identify and learn
/// read them). (The loaded suite once flew the learned flight at 1.34×
/// matched, 0.0725 against 0.0543 m, where it flies 1.00–1.02× on time,
/// beside two busy loops too.)
fn fly(name: &str, config: &str) -> Judged {
    let flight = fly_unstarved(name, config, Duration::from_secs_f64(STREAM_S + 2.5));
    assert!(flight.clean_exit, "{name}: the daemon did not exit cleanly");
    let said = flight
        .frames
        .iter()
        .filter(|f| match &f.message {
            dflat_link::MavMessage::STATUSTEXT(d) => {
                String::from_utf8_lossy(&d.text.to_vec()).contains("learned residual")
            }
            _ => false,
        })
        .count();
    let rows = read_flight_csv(&scratch_dir(name));
    let num = |r: &std::collections::HashMap<String, String>, k: &str| {
        r.get(k).and_then(|v| v.parse::<f64>().ok())
    };
    let tracking: Vec<_> = rows
        .iter()
        .filter(|r| r.get("state").is_some_and(|s| s.starts_with("TRACKING")))
        .collect();
    let t0 = tracking
        .first()
        .and_then(|r| num(r, "t"))
        .unwrap_or_else(|| panic!("{name}: never tracked"));
    let mut e = Vec::new();
    let mut ex = Vec::new();
    let mut ey = Vec::new();
    for r in tracking {
        let (Some(t), Some(x), Some(y), Some(rx), Some(ry)) = (
            num(r, "t"),
            num(r, "x"),
            num(r, "y"),
            num(r, "ref_x"),
            num(r, "ref_y"),
        ) else {
            continue;
        };
        if t < t0 + RAMP_S + 2.0 || t > t0 + STREAM_S {
            continue;
        }
        e.push(((x - rx).powi(2) + (y - ry).powi(2)).sqrt());
        ex.push((x - rx).abs());
        ey.push((y - ry).abs());
    }
    assert!(e.len() > 300, "{name}: {} ticks judged", e.len());
    let (truth, truth_axes) = judge_truth(name, &flight.report);
    Judged {
        p95: quantile(&e, 0.95),
        axes: [quantile(&ex, 0.95), quantile(&ey, 0.95)],
        said,
        truth,
        truth_axes,
    }
}

/// The SITL's true position against the planner's trajectory at the same
/// SITL time, over the judged span: p95 horizontal and per axis \[m\].
fn judge_truth(name: &str, report: &dflat_sitl::SitlReport) -> (f64, [f64; 2]) {
    let t0 = report.planner_start.expect("the planner never streamed");
    let trajectory = dflat_sim::trajectory::Trajectory {
        shape: dflat_sim::trajectory::Shape::RacingLine,
        size: SIZE,
        speed: SPEED,
        ramp_s: RAMP_S,
        start: nalgebra::Vector3::from(START),
    };
    let (mut e, mut ex, mut ey) = (Vec::new(), Vec::new(), Vec::new());
    for sample in &report.trace {
        if sample.t < t0 + RAMP_S + 2.0 || sample.t > t0 + STREAM_S {
            continue;
        }
        let want = trajectory.at(sample.t - t0).position;
        let (dx, dy) = (sample.position[0] - want.x, sample.position[1] - want.y);
        e.push(dx.hypot(dy));
        ex.push(dx.abs());
        ey.push(dy.abs());
    }
    assert!(e.len() > 300, "{name}: {} truth samples judged", e.len());
    (
        quantile(&e, 0.95),
        [quantile(&ex, 0.95), quantile(&ey, 0.95)],
    )
}

/// The identified `[vehicle]` snippet of a flight's .tlog.
fn identified(name: &str) -> String {
    let log = FlightLog::read_tlog(&tlog_in(&scratch_dir(name))).expect("tlog");
    let found = identify::identify(&log).expect("identify");
    let snippet = found.vehicle_snippet(name, None);
    eprintln!("{}\n{snippet}", found.report(name, None));
    snippet
}

/// `dflat learn` on `flights` over `config`'s `[vehicle]`: the model file
/// and the config snippet it wrote, and its report; a refusal fails the
/// test.
fn learn(flights: &[PathBuf], config: &Path, out: &Path) -> (PathBuf, String, String) {
    let output = Command::new(bin())
        .arg("learn")
        .args(flights)
        .arg("--config")
        .arg(config)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run dflat learn");
    let report = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "dflat learn failed:\n{report}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let snippet_path = out.with_extension("snippet.toml");
    let snippet = std::fs::read_to_string(&snippet_path).expect("the config snippet");
    (out.to_path_buf(), snippet, report)
}

/// The matched plant, then stock, identified and learned on the
/// aerodynamic plant (≈ 90 s: four 20 s flights one after the other).
#[test]
fn learned_maps_fly_the_aerodynamic_plant_as_the_matched_one() {
    let matched = fly("learned-matched", &config("", "", false));
    let stock = fly("learned-stock", &config("", "", true));
    let snippet = identified("learned-stock");
    let identified_flight = fly("learned-identified", &config(&snippet, "", true));
    // Learn over the identified table from both flights' records.
    let dir = scratch("learned-model");
    let table = write_config(&dir, "identified.toml", &snippet);
    let flights = [
        csv_in(&scratch_dir("learned-stock")),
        csv_in(&scratch_dir("learned-identified")),
    ];
    let (model, learned_snippet, report) = learn(&flights, &table, &dir.join("model.toml"));
    eprintln!("{report}\n{learned_snippet}");
    assert!(
        learned_snippet.contains("learned_model") && learned_snippet.contains("model.toml"),
        "{learned_snippet}"
    );
    let residual = dflat_daemon::learned::read(&model).expect("the model file");
    let v = residual.validation;
    let learned = fly("learned-learned", &config(&snippet, &learned_snippet, true));
    let log = std::fs::read_to_string(scratch_dir("learned-learned").join("daemon.stderr"))
        .unwrap_or_default();
    println!(
        "from the daemon's CSV (measured against the reference at the tick): racing line {SPEED} m/s, p95 (x, y): matched {:.4} ({:.4}, {:.4}) m; aerodynamic plant: stock \
         {:.4} ({:.4}, {:.4}), identified {:.4} ({:.4}, {:.4}), learned {:.4} ({:.4}, {:.4}) m; \
         learned / matched {:.2}×; held-out 0.5 s prediction {:.4} → {:.4} m ({:.2}×), acceleration \
         left {:.3} → {:.3} m/s²",
        matched.p95,
        matched.axes[0],
        matched.axes[1],
        stock.p95,
        stock.axes[0],
        stock.axes[1],
        identified_flight.p95,
        identified_flight.axes[0],
        identified_flight.axes[1],
        learned.p95,
        learned.axes[0],
        learned.axes[1],
        learned.p95 / matched.p95,
        v.horizon_parametric_m,
        v.horizon_learned_m,
        v.horizon_learned_m / v.horizon_parametric_m,
        v.acceleration_parametric,
        v.acceleration_learned,
    );
    println!(
        "judged, from the SITL's truth against the planner's trajectory at the same SITL time, p95 (x, y): matched {:.4} ({:.4}, {:.4}); stock {:.4} ({:.4}, {:.4}), identified {:.4} ({:.4}, {:.4}), learned {:.4} ({:.4}, {:.4}) m; learned / matched {:.2}×",
        matched.truth,
        matched.truth_axes[0],
        matched.truth_axes[1],
        stock.truth,
        stock.truth_axes[0],
        stock.truth_axes[1],
        identified_flight.truth,
        identified_flight.truth_axes[0],
        identified_flight.truth_axes[1],
        learned.truth,
        learned.truth_axes[0],
        learned.truth_axes[1],
        learned.truth / matched.truth,
    );
    assert!(
        log.contains("learned residual: acting") && learned.said > 0,
        "the daemon did not say the residual acts ({} STATUSTEXTs):\n{log}",
        learned.said
    );
    assert_eq!(identified_flight.said, 0, "no residual, nothing said");
    let budget = learned.truth / matched.truth;
    if vision() {
        assert!(
            budget <= 1.1,
            "vision poses: learned {:.4} m is {budget:.2}× the matched {:.4} m (budget 1.1×)",
            learned.truth,
            matched.truth
        );
    } else {
        println!("exact poses: learned / matched {budget:.2}× printed, not asserted (module docs)");
        assert!(
            v.horizon_learned_m <= 0.5 * v.horizon_parametric_m,
            "held-out prediction {:.4} m vs the parametric model's {:.4} m",
            v.horizon_learned_m,
            v.horizon_parametric_m
        );
    }
    assert!(
        learned.truth < identified_flight.truth,
        "learned {:.4} m not better than identified {:.4} m",
        learned.truth,
        identified_flight.truth
    );
    for axis in 0..2 {
        assert!(
            identified_flight.truth_axes[axis] <= stock.truth_axes[axis],
            "axis {axis}: identified {:?} worse than stock {:?}",
            identified_flight.truth_axes,
            stock.truth_axes
        );
        assert!(
            learned.truth_axes[axis] <= identified_flight.truth_axes[axis],
            "axis {axis}: learned {:?} worse than identified {:?}",
            learned.truth_axes,
            identified_flight.truth_axes
        );
    }
}
