//! `dflat demo --stream`: a planner's stream, flown on the SITL in one
//! process on loopback.
//!
//! The SITL of `config/sitl.toml` (autopilot `engage = "auto"`) also plays
//! a planner (`[sitl.planner]`): once the autopilot is in offboard it
//! streams SET_POSITION_TARGET_LOCAL_NED with position, velocity,
//! acceleration and yaw along a circle (radius 6 m at `--speed`, 20 Hz)
//! that starts where the vehicle holds, for `STREAM_S`; then the stream
//! ends and the daemon stops smoothly and holds. The demo reports the
//! horizontal error against the planner's own trajectory at the same SITL
//! time (at full speed), the largest command step, the heading's lag and
//! the drift after the stop, and draws the flight.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use dflat_daemon::FlightSummary;
use dflat_daemon::config::MissionStart;
use dflat_lab::harness::ErrorStats;
use dflat_lab::plot::{DF_RED, PathPlot, Series, north_up, write_path_plot};
use dflat_sim::trajectory::{Shape, Trajectory};
use dflat_sitl::planner::PlannerConfig;
use dflat_sitl::{SitlCounters, SitlEngage, SitlMode, SitlOptions};
use nalgebra::Vector3;

use crate::demo::{DemoError, DemoOptions, Pair, demo_config};

/// How long the planner streams \[s\].
pub const STREAM_S: f64 = 16.0;
/// The planner starts this long after the autopilot enters offboard \[s\].
pub const START_AFTER_S: f64 = 1.0;
/// The circle's radius \[m\].
pub const RADIUS: f64 = 6.0;
/// The speed ramp \[s\]; the error is judged from 2 s after it.
pub const RAMP_S: f64 = 3.0;
/// Flown after the stream ends: its stop and the hold \[s\].
pub const AFTER_S: f64 = 7.0;
/// A p95 error above this fails the demo \[m\] (the stream's budget).
pub const MAX_P95: f64 = 0.098;

/// What the stream demo measured.
#[derive(Debug, Clone)]
pub struct StreamDemoOutcome {
    /// Circle speed [m/s].
    pub speed: f64,
    /// Horizontal error against the planner's trajectory at full speed \[m\].
    pub error: Option<ErrorStats>,
    /// Largest change of the commanded tilt between consecutive 50 Hz
    /// telemetry samples while the daemon flew \[deg\].
    pub largest_step_deg: Option<f64>,
    /// Heading error against the stream's yaw, p95 at full speed \[deg\].
    pub heading_p95_deg: Option<f64>,
    /// Movement over the last second, after the stream's stop \[m\].
    pub drift_m: Option<f64>,
    /// Samples the planner sent.
    pub samples: u64,
    /// The daemon's summary.
    pub daemon: FlightSummary,
    /// The SITL's counters.
    pub sitl: SitlCounters,
    /// The plant diverged.
    pub diverged: bool,
    /// The plot (SVG, PNG).
    pub plot: [PathBuf; 2],
    /// Wall time \[s\].
    pub wall_s: f64,
}

impl StreamDemoOutcome {
    /// Why the flight failed, or `None`.
    pub fn failure(&self) -> Option<String> {
        if self.diverged {
            return Some("the simulated vehicle diverged (non-finite state)".into());
        }
        if self.samples == 0 {
            return Some("the planner never streamed (the autopilot never went offboard)".into());
        }
        match &self.error {
            None => Some("no full-speed samples to judge".into()),
            Some(e) if e.p95 > MAX_P95 => {
                Some(format!("error p95 {:.3} m above {MAX_P95} m", e.p95))
            }
            _ => None,
        }
    }

    /// The printed summary.
    pub fn summary_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "dflat demo --stream: {} flying a planner's circle (r {RADIUS} m, {} m/s, p/v/a/yaw at 20 Hz from 255/190) on the SITL, one process on loopback",
            self.daemon.controller, self.speed
        );
        let fmt = |v: Option<f64>, unit: &str, digits: usize| {
            v.map_or("n/a".to_owned(), |v| format!("{v:.digits$} {unit}"))
        };
        match &self.error {
            Some(e) => {
                let _ = writeln!(
                    s,
                    "  error vs the stream          median {:.4} m, p95 {:.4} m, max {:.4} m ({} samples at full speed; budget p95 {MAX_P95} m)",
                    e.median, e.p95, e.max, e.count
                );
            }
            None => {
                let _ = writeln!(s, "  error vs the stream          n/a");
            }
        }
        let _ = writeln!(
            s,
            "  largest command step         {} per tick",
            fmt(self.largest_step_deg, "°", 2)
        );
        let _ = writeln!(
            s,
            "  heading vs the stream's yaw  p95 {}",
            fmt(self.heading_p95_deg, "°", 1)
        );
        let _ = writeln!(
            s,
            "  after the stream ended       smooth stop, then {} drift over the last second",
            fmt(self.drift_m, "m", 4)
        );
        let _ = writeln!(
            s,
            "  planner samples              {} sent, daemon {} commands, {} control errors",
            self.samples, self.daemon.commands, self.daemon.control_errors
        );
        let _ = writeln!(s, "  solve time                   {}", self.daemon.solve_us);
        let _ = writeln!(
            s,
            "  plot                         {} , {}",
            self.plot[0].display(),
            self.plot[1].display()
        );
        let _ = writeln!(s, "  wall                         {:.1} s", self.wall_s);
        s
    }
}

/// Runs the stream demo (`options.speed` is the circle's speed).
pub async fn run(options: &DemoOptions) -> Result<StreamDemoOutcome, DemoError> {
    let (mut cfg, mut sitl_cfg) = demo_config(options)?;
    cfg.mission.start = MissionStart::Hold;
    cfg.logging.dir = options.out.join("flights").display().to_string();
    sitl_cfg.sitl.engage = SitlEngage::Auto;
    sitl_cfg.sitl.planner = Some(PlannerConfig {
        shape: Shape::Circle,
        size: RADIUS,
        speed: options.speed,
        ramp_s: RAMP_S,
        start_after_s: START_AFTER_S,
        duration_s: STREAM_S,
        ..PlannerConfig::default()
    });
    std::fs::create_dir_all(&options.out).map_err(|source| DemoError::OutDir {
        dir: options.out.clone(),
        source,
    })?;
    let pair = Pair::start(
        &cfg,
        &sitl_cfg,
        SitlOptions {
            record_trace: true,
            ..SitlOptions::default()
        },
    )?;
    let sitl = &pair.sitl;
    let started = Instant::now();
    let limit = options
        .seconds
        .unwrap_or(START_AFTER_S + STREAM_S + AFTER_S + 5.0);
    // Until the stream has ended and the stop has settled, or the limit.
    let mut offboard_at: Option<f64> = None;
    loop {
        tokio::time::sleep(Duration::from_millis(50)).await;
        let truth = sitl.truth();
        if offboard_at.is_none() && truth.mode == SitlMode::Offboard {
            offboard_at = Some(truth.t);
        }
        let done = offboard_at.is_some_and(|t| truth.t >= t + START_AFTER_S + STREAM_S + AFTER_S);
        if done || started.elapsed().as_secs_f64() >= limit || sitl.diverged() {
            break;
        }
    }
    let (summary, report) = pair.stop().await?;
    let wall_s = started.elapsed().as_secs_f64();

    let circle = |start: Vector3<f64>| Trajectory {
        shape: Shape::Circle,
        size: RADIUS,
        speed: options.speed,
        ramp_s: RAMP_S,
        start,
    };
    let t0 = report.planner_start;
    // The planner starts where the vehicle was at its first sample.
    let start = t0.and_then(|t0| {
        report
            .trace
            .iter()
            .find(|s| s.t >= t0)
            .map(|s| Vector3::from(s.position))
    });
    let judged: Vec<_> = match (t0, start) {
        (Some(t0), Some(_)) => report
            .trace
            .iter()
            .filter(|s| {
                s.mode == SitlMode::Offboard && s.t >= t0 + RAMP_S + 2.0 && s.t <= t0 + STREAM_S
            })
            .collect(),
        _ => Vec::new(),
    };
    let (error, heading_p95_deg) = match (t0, start) {
        (Some(t0), Some(p0)) => {
            let c = circle(p0);
            let e = ErrorStats::from_values(judged.iter().map(|s| {
                (Vector3::from(s.position) - c.at(s.t - t0).position)
                    .xy()
                    .norm()
            }));
            let h = ErrorStats::from_values(judged.iter().map(|s| {
                dflat_link::math::wrap_pi(s.euler[2] - c.at(s.t - t0).yaw)
                    .abs()
                    .to_degrees()
            }));
            (e, h.map(|h| h.p95))
        }
        _ => (None, None),
    };
    let commands: Vec<[f64; 2]> = report
        .trace
        .iter()
        .filter(|s| s.mode == SitlMode::Offboard)
        .filter_map(|s| s.command.map(|c| [c.roll, c.pitch]))
        .collect();
    let largest_step_deg = commands
        .windows(2)
        .map(|w| ((w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).to_degrees())
        .reduce(f64::max);
    let drift_m = report.trace.last().and_then(|end| {
        report
            .trace
            .iter()
            .rev()
            .find(|s| s.t <= end.t - 1.0)
            .map(|s| (Vector3::from(end.position) - Vector3::from(s.position)).norm())
    });

    let mut plot = PathPlot::new(
        format!(
            "dflat demo --stream: a planner's circle at {} m/s ({}, SITL)",
            options.speed, summary.controller
        ),
        "east [m]",
        "north [m]",
    );
    if let (Some(p0), Some(_)) = (start, t0) {
        let c = circle(p0);
        let lap = std::f64::consts::TAU * RADIUS / options.speed;
        let reference: Vec<Vector3<f64>> = (0..=400)
            .map(|i| c.at(RAMP_S + lap * i as f64 / 400.0).position)
            .collect();
        plot.reference = north_up(&reference);
    }
    let flown: Vec<Vector3<f64>> = report
        .trace
        .iter()
        .filter(|s| s.mode == SitlMode::Offboard)
        .map(|s| Vector3::from(s.position))
        .collect();
    plot.series.push(Series::new(
        "daemon (true position)",
        DF_RED,
        north_up(&flown),
    ));
    let plot = write_path_plot(&options.out.join("demo_stream"), &plot)?;

    Ok(StreamDemoOutcome {
        speed: options.speed,
        error,
        largest_step_deg,
        heading_p95_deg,
        drift_m,
        samples: report.counters.planner_samples,
        daemon: summary,
        sitl: report.counters,
        diverged: report.diverged,
        plot,
        wall_s,
    })
}
