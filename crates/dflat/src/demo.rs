//! `dflat demo`: the SITL and the daemon in one process, on loopback.
//!
//! The README's first command. With the shipped configuration
//! (`config/sitl.toml`, embedded in the binary so it runs from any
//! directory; its controller and vehicle sections are those of
//! `config/default.toml`):
//!
//! 1. start the SITL ([`dflat_sitl`]) on `udpin:127.0.0.1:0` and read back
//!    its port; the vehicle starts at the first waypoint of the L path
//!    (−20, −30) → (0, −30) → (0, 0) at z = −10 m;
//! 2. start the daemon ([`dflat_daemon::run`]) with `--link
//!    udpout:127.0.0.1:PORT`; it streams in STANDBY while the SITL hovers
//!    in position mode;
//! 3. play the pilot (the SITL's `engage = "pilot"`): after
//!    [`ENGAGE_AFTER_S`] of streaming switch to OFFBOARD — the daemon
//!    engages and flies the path at `--speed`; [`OVERRIDE_AFTER_S`] later
//!    take over in position mode for [`OVERRIDE_S`], then hand back — the
//!    daemon resumes the path from where the vehicle is;
//! 4. follow the SITL's true state until the vehicle is within
//!    [`ARRIVAL_RADIUS`] of the last waypoint and has settled for
//!    [`SETTLE_S`], or until the time limit;
//! 5. stop both, measure the true path error while the daemon flew,
//!    draw the flown path (reference black, daemon red, pilot blue) as SVG
//!    and PNG, and report.
//!
//! [`DemoOutcome::failure`] says whether the flight counts as failed (no
//! commands, diverged, path not finished, strayed from the path).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use dflat_lab::harness::{ErrorStats, polyline_distance};
use dflat_lab::plot::{DF_RED, FMPC_BLUE, PathPlot, Series, north_up, write_path_plot};
use nalgebra::Vector3;
use thiserror::Error;

use dflat_daemon::DaemonError;
use dflat_daemon::FlightSummary;
use dflat_daemon::config::{Config, ConfigError, MissionStart};
use dflat_sitl::{
    self as sitl, SitlConfigError, SitlCounters, SitlEngage, SitlError, SitlHandle, SitlMode,
    SitlOptions, SitlReport, SitlSettings, TruthSample,
};

/// The shipped SITL configuration (daemon + SITL on loopback).
pub const SITL_TOML: &str = include_str!("../../../config/sitl.toml");
/// The shipped default configuration (the controller the demo flies must
/// match its `[vehicle]` and `[controller]`).
pub const DEFAULT_TOML: &str = include_str!("../../../config/default.toml");

/// The path counts as done within this distance of its last waypoint \[m\].
pub const ARRIVAL_RADIUS: f64 = 0.5;
/// Time flown after arrival before stopping \[s\].
pub const SETTLE_S: f64 = 2.0;
/// A true path error above this fails the demo \[m\].
pub const MAX_PATH_ERROR: f64 = 5.0;
/// Extra time beyond path length / speed before the demo gives up \[s\]
/// (hover, speed ramp, override and braking included).
pub const TIME_MARGIN_S: f64 = 16.0;
/// The pilot engages after the daemon's stream has run this long \[s\].
pub const ENGAGE_AFTER_S: f64 = 1.5;
/// The pilot takes over this long after engaging \[s\].
pub const OVERRIDE_AFTER_S: f64 = 4.0;
/// The pilot keeps control this long before handing back \[s\].
pub const OVERRIDE_S: f64 = 2.0;

/// Why the demo could not run (a failed *flight* is a [`DemoOutcome`]).
#[derive(Debug, Error)]
pub enum DemoError {
    /// The embedded configuration did not validate (a bug) or the speed is
    /// out of range.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The embedded `[sitl]` table did not validate (a bug).
    #[error(transparent)]
    SitlConfig(#[from] SitlConfigError),
    /// The SITL failed.
    #[error(transparent)]
    Sitl(#[from] SitlError),
    /// The daemon failed.
    #[error("daemon: {0}")]
    Daemon(#[from] DaemonError),
    /// The daemon task panicked (a bug).
    #[error("the daemon task ended abnormally: {0}")]
    Join(String),
    /// The plot could not be written.
    #[error("plot: {0}")]
    Plot(#[from] dflat_sim::SimError),
    /// The output directory could not be created.
    #[error("{dir}: cannot create: {source}")]
    OutDir {
        /// The directory.
        dir: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Options of `dflat demo`.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoOptions {
    /// Speed along the path \[m/s\] (0.1–20).
    pub speed: f64,
    /// Output directory (plot, truth CSV, flight records).
    pub out: PathBuf,
    /// Time limit \[s\]; default path length / speed + [`TIME_MARGIN_S`].
    pub seconds: Option<f64>,
}

impl Default for DemoOptions {
    fn default() -> Self {
        Self {
            speed: 5.0,
            out: PathBuf::from("out/demo"),
            seconds: None,
        }
    }
}

/// The result of a demo flight.
#[derive(Debug, Clone)]
pub struct DemoOutcome {
    /// The daemon's configuration flown.
    pub config: Config,
    /// The SITL's configuration.
    pub sitl_config: SitlSettings,
    /// Distance of the *true* position to the path \[m\], from the first
    /// command to the end of the flight.
    pub path_error: Option<ErrorStats>,
    /// The vehicle reached the end of the path.
    pub completed: bool,
    /// Time from the first command to arrival at the end \[s\].
    pub path_time_s: Option<f64>,
    /// Wall time of the flight \[s\].
    pub wall_s: f64,
    /// The daemon's summary.
    pub daemon: FlightSummary,
    /// The SITL's counters.
    pub sitl: SitlCounters,
    /// The SITL's plant diverged.
    pub diverged: bool,
    /// The flown path plot (SVG, PNG).
    pub plot: [PathBuf; 2],
    /// The SITL's truth CSV.
    pub truth_csv: PathBuf,
    /// What the pilot did, SITL time \[s\] and words.
    pub pilot: Vec<(f64, &'static str)>,
    /// Largest change of the command between consecutive telemetry
    /// samples (50 Hz) in the second after the hand-back \[deg\].
    pub handback_step_deg: Option<f64>,
}

impl DemoOutcome {
    /// Why the flight failed, or `None` when it succeeded.
    pub fn failure(&self) -> Option<String> {
        if self.sitl.commands_accepted == 0 {
            return Some("the SITL received no attitude commands from the daemon".into());
        }
        if self.diverged {
            return Some("the simulated vehicle diverged (non-finite state)".into());
        }
        if let Some(e) = &self.path_error
            && e.max > MAX_PATH_ERROR
        {
            return Some(format!(
                "the vehicle strayed {:.2} m from the path (limit {MAX_PATH_ERROR} m)",
                e.max
            ));
        }
        if !self.completed {
            return Some(format!(
                "the vehicle did not reach the end of the path within {:.0} s",
                self.wall_s
            ));
        }
        None
    }

    /// The printed summary.
    pub fn summary_text(&self) -> String {
        let mut s = String::new();
        let m = &self.config.mission;
        let d = &self.daemon;
        let _ = writeln!(
            s,
            "dflat demo: {} on the L path at {} m/s, SITL {:?} plant, in one process on loopback",
            d.controller, m.speed, self.sitl_config.sitl.plant
        );
        let pilot: Vec<String> = self
            .pilot
            .iter()
            .map(|(t, what)| format!("{t:.1} s {what}"))
            .collect();
        let _ = writeln!(s, "  pilot (SITL time)           {}", pilot.join(" → "));
        let t = &d.time_in_state_s;
        let _ = writeln!(
            s,
            "  engagement                  {} engagements, {} disengagements; standby {:.1} s; hand-back: largest command step {} in the first second",
            d.engagements,
            d.disengagements,
            t.standby,
            self.handback_step_deg
                .map_or("n/a".to_owned(), |v| format!("{v:.1}°/tick"))
        );
        match (&self.path_error, self.path_time_s) {
            (Some(e), t) => {
                let _ = writeln!(
                    s,
                    "  path error (true position)  median {:.3} m, p95 {:.3} m, max {:.3} m ({} samples, daemon in control)",
                    e.median, e.p95, e.max, e.count
                );
                let _ = writeln!(
                    s,
                    "  path                        {}{}",
                    if self.completed {
                        "completed"
                    } else {
                        "NOT completed"
                    },
                    t.map_or(String::new(), |t| format!(" in {t:.1} s"))
                );
            }
            (None, _) => {
                let _ = writeln!(s, "  path error (true position)  n/a (no commanded flight)");
            }
        }
        let _ = writeln!(s, "  solve time                  {}", d.solve_us);
        let _ = writeln!(
            s,
            "  constrained ticks           {} ({} by clarabel after the banded solver, {} by the cone's interior point), {} saturated",
            d.solves.constrained,
            d.solves.qp_fallbacks,
            d.solves.cone_interior_point,
            d.solves.saturated
        );
        let _ = writeln!(s, "  tick jitter                 {}", d.jitter_us);
        let _ = writeln!(
            s,
            "  pose→command latency        {} (arrival → sent, includes the wait for the tick)",
            d.latency_us
        );
        let _ = writeln!(s, "  tick→command                {}", d.tick_to_send_us);
        let pl = &self.sitl.pose_latency;
        let _ = writeln!(
            s,
            "  at the SITL                 pose departure→command p50 {} µs, p99 {} µs, max {} µs ({} matched, {} without a new pose); command interval p50 {} µs, jitter p99 {} µs",
            pl.p50_us,
            pl.p99_us,
            pl.max_us,
            pl.matched,
            pl.unmatched,
            pl.interval_p50_us,
            pl.jitter_p99_us
        );
        let _ = writeln!(
            s,
            "  ticks placed                tick = {}: {} on a pose, {} on the deadline ({} fallbacks)",
            d.tick_mode, d.pose_ticks, d.deadline_ticks, d.fallback_ticks
        );
        let _ = writeln!(
            s,
            "  ticks                       {} run, {} missed, {} commands, {} control errors",
            d.ticks, d.missed_ticks, d.commands, d.control_errors
        );
        let l = &d.link_stats;
        let c = &self.sitl;
        let _ = writeln!(
            s,
            "  daemon link                 rx {} (pose {}, attitude {}, heartbeat {}), tx {} (attitude targets {}, heartbeat {}, statustext {}), errors {}",
            l.received.total,
            l.received.local_position_ned,
            l.received.attitude,
            l.received.heartbeat,
            l.sent.total,
            l.sent.set_attitude_target,
            l.sent.heartbeat,
            l.sent.statustext,
            l.inbound_errors() + l.send_errors
        );
        let _ = writeln!(
            s,
            "  sitl                        sent pose {}, attitude {}, heartbeat {}; commands {} accepted, {} ignored, {} rejected, {} unauthenticated; late plant steps {} (the latest {:.1} ms behind)",
            c.positions_sent,
            c.attitudes_sent,
            c.heartbeats_sent,
            c.commands_accepted,
            c.commands_ignored,
            c.commands_rejected,
            c.commands_unauthenticated,
            c.late_steps,
            c.step_lag_max_us as f64 / 1000.0
        );
        let cpu = d
            .cpu_percent
            .map_or("n/a".to_owned(), |c| format!("{c:.1} %"));
        let rss = d.peak_rss_kib.map_or("n/a".to_owned(), |r| {
            format!("{:.1} MiB", r as f64 / 1024.0)
        });
        let _ = writeln!(
            s,
            "  process (daemon + SITL)     CPU {cpu} of one core, peak RSS {rss}, wall {:.1} s",
            self.wall_s
        );
        let _ = writeln!(
            s,
            "  plot                        {} , {}",
            self.plot[0].display(),
            self.plot[1].display()
        );
        let _ = writeln!(
            s,
            "  truth                       {}",
            self.truth_csv.display()
        );
        if let Some(csv) = &d.csv {
            let _ = writeln!(s, "  flight record               {}", csv.path.display());
        }
        s
    }
}

/// The demo's configuration: `config/sitl.toml` with the speed and the
/// output directory applied, the SITL on a free port.
pub fn demo_config(options: &DemoOptions) -> Result<(Config, SitlSettings), DemoError> {
    let file = Path::new("config/sitl.toml (embedded)");
    let mut cfg = Config::parse(SITL_TOML, file)?;
    cfg.mission.speed = options.speed;
    cfg.mission.start = MissionStart::Path;
    cfg.logging.dir = options.out.join("flights").display().to_string();
    cfg.validate(file)?;
    let mut sitl = SitlSettings::parse(SITL_TOML, file)?;
    sitl.sitl.url = "udpin:127.0.0.1:0".into();
    // The demo plays the pilot (see the module docs).
    sitl.sitl.engage = SitlEngage::Pilot;
    Ok((cfg, sitl))
}

fn waypoints(cfg: &Config) -> Vec<Vector3<f64>> {
    cfg.mission.path.iter().map(|w| Vector3::from(*w)).collect()
}

fn path_length(w: &[Vector3<f64>]) -> f64 {
    w.windows(2).map(|p| (p[1] - p[0]).norm()).sum()
}

/// Runs the demo flight (see the module docs).
pub async fn run(options: &DemoOptions) -> Result<DemoOutcome, DemoError> {
    let (cfg, sitl_cfg) = demo_config(options)?;
    std::fs::create_dir_all(&options.out).map_err(|source| DemoError::OutDir {
        dir: options.out.clone(),
        source,
    })?;
    let truth_csv = options.out.join("truth.csv");
    let wps = waypoints(&cfg);
    let limit = options
        .seconds
        .unwrap_or(path_length(&wps) / cfg.mission.speed + TIME_MARGIN_S);

    let pair = Pair::start(
        &cfg,
        &sitl_cfg,
        SitlOptions {
            truth_csv: Some(truth_csv.clone()),
            record_trace: true,
            ..SitlOptions::default()
        },
    )?;

    let started = Instant::now();
    let end = *wps.last().unwrap_or(&Vector3::zeros());
    let (arrival, pilot) = watch(&pair.sitl, end, limit, started).await;
    let (summary, report) = pair.stop().await?;
    let wall_s = started.elapsed().as_secs_f64();

    let first_command = report
        .trace
        .iter()
        .find(|s| s.command.is_some())
        .map(|s| s.t);
    let flown: Vec<&TruthSample> = match first_command {
        Some(t0) => report.trace.iter().filter(|s| s.t >= t0).collect(),
        None => Vec::new(),
    };
    // The controller's error: while the daemon flew (not the pilot).
    let path_error = ErrorStats::from_values(
        flown
            .iter()
            .filter(|s| s.mode == SitlMode::Offboard)
            .map(|s| polyline_distance(&wps, &Vector3::from(s.position), false)),
    );
    let handback_step_deg = pilot
        .iter()
        .rev()
        .find(|(_, what)| *what == HAND_BACK)
        .and_then(|(t, _)| {
            let cmds: Vec<[f64; 2]> = report
                .trace
                .iter()
                .filter(|s| s.t >= *t && s.t <= t + 1.0 && s.mode == SitlMode::Offboard)
                .filter_map(|s| s.command.map(|c| [c.roll, c.pitch]))
                .collect();
            cmds.windows(2)
                .map(|w| ((w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).to_degrees())
                .reduce(f64::max)
        });
    let path_time_s = match (first_command, arrival) {
        (Some(t0), Some(ta)) => Some(ta - t0),
        _ => None,
    };

    let mut plot = PathPlot::new(
        format!(
            "dflat demo: L path at {} m/s ({}, SITL)",
            cfg.mission.speed, summary.controller
        ),
        "east [m]",
        "north [m]",
    );
    plot.reference = north_up(&wps);
    // One series per stretch flown by the daemon (red) or the pilot in
    // position mode (blue); one legend entry each.
    let mut named = [false; 2];
    for stretch in flown.chunk_by(|a, b| a.mode == b.mode) {
        let daemon = stretch[0].mode == SitlMode::Offboard;
        let (name, color, i) = if daemon {
            ("daemon (true position)", DF_RED, 0)
        } else {
            ("pilot, position mode", FMPC_BLUE, 1)
        };
        let points: Vec<Vector3<f64>> = stretch.iter().map(|s| Vector3::from(s.position)).collect();
        let name = if named[i] { "" } else { name };
        named[i] = true;
        plot.series
            .push(Series::new(name, color, north_up(&points)));
    }
    let plot = write_path_plot(&options.out.join("demo_path"), &plot)?;

    Ok(DemoOutcome {
        config: cfg,
        sitl_config: sitl_cfg,
        path_error,
        completed: arrival.is_some(),
        path_time_s,
        wall_s,
        daemon: summary,
        sitl: report.counters,
        diverged: report.diverged,
        plot,
        truth_csv,
        pilot,
        handback_step_deg,
    })
}

/// The SITL and the daemon, started in this process on loopback (the
/// daemon's link `udpout` to the SITL's port).
pub(crate) struct Pair {
    /// The SITL.
    pub(crate) sitl: SitlHandle,
    stop: tokio::sync::oneshot::Sender<()>,
    daemon: tokio::task::JoinHandle<Result<FlightSummary, DaemonError>>,
}

impl Pair {
    /// Starts the SITL with `options`, then the daemon on a runtime task.
    pub(crate) fn start(
        cfg: &Config,
        sitl_cfg: &SitlSettings,
        options: SitlOptions,
    ) -> Result<Self, DemoError> {
        let sitl = sitl::spawn(sitl_cfg, options)?;
        let link = format!("udpout:127.0.0.1:{}", sitl.local_addr().port());
        let (stop, stop_rx) = tokio::sync::oneshot::channel::<()>();
        let daemon_cfg = cfg.clone();
        let daemon = tokio::spawn(async move {
            let shutdown = async move {
                // A dropped sender also means "stop".
                let _ = stop_rx.await;
            };
            dflat_daemon::run(daemon_cfg, Some(link), shutdown).await
        });
        Ok(Self { sitl, stop, daemon })
    }

    /// Stops the daemon, then the SITL: the daemon's summary and the
    /// SITL's report.
    pub(crate) async fn stop(self) -> Result<(FlightSummary, SitlReport), DemoError> {
        let _ = self.stop.send(());
        let summary = self
            .daemon
            .await
            .map_err(|e| DemoError::Join(e.to_string()))??;
        let report = self.sitl.stop()?;
        Ok((summary, report))
    }
}

/// Words of the pilot's hand-back in [`DemoOutcome::pilot`].
const HAND_BACK: &str = "hand-back (OFFBOARD)";

/// Follows the truth until arrival + settling or the time limit, playing
/// the pilot on the way (engage, override, hand back); returns the SITL
/// time of arrival at `end`, if any, and what the pilot did when.
async fn watch(
    sitl: &SitlHandle,
    end: Vector3<f64>,
    limit_s: f64,
    started: Instant,
) -> (Option<f64>, Vec<(f64, &'static str)>) {
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut arrived: Option<f64> = None;
    let mut pilot: Vec<(f64, &'static str)> = Vec::new();
    let mut stream_since: Option<f64> = None;
    loop {
        tick.tick().await;
        let truth = sitl.truth();
        // The pilot's script, on the SITL's clock.
        let t = truth.t;
        if stream_since.is_none() && sitl.counters().commands_accepted > 0 {
            stream_since = Some(t);
            pilot.push((t, "hover in POSCTL, daemon streaming"));
        }
        let last = pilot.last().map(|(at, what)| (*at, *what));
        match (stream_since, last) {
            (Some(s), Some((_, "hover in POSCTL, daemon streaming")))
                if t >= s + ENGAGE_AFTER_S =>
            {
                sitl.request_mode(SitlMode::Offboard);
                pilot.push((t, "engage (OFFBOARD)"));
            }
            (_, Some((at, "engage (OFFBOARD)")))
                if t >= at + OVERRIDE_AFTER_S && arrived.is_none() =>
            {
                sitl.request_mode(SitlMode::Hold);
                pilot.push((t, "override (POSCTL)"));
            }
            (_, Some((at, "override (POSCTL)"))) if t >= at + OVERRIDE_S => {
                sitl.request_mode(SitlMode::Offboard);
                pilot.push((t, HAND_BACK));
            }
            _ => {}
        }
        if arrived.is_none()
            && truth.command.is_some()
            && (Vector3::from(truth.position) - end).norm() < ARRIVAL_RADIUS
        {
            arrived = Some(truth.t);
        }
        if let Some(ta) = arrived
            && truth.t - ta >= SETTLE_S
        {
            return (arrived, pilot);
        }
        if started.elapsed().as_secs_f64() >= limit_s || sitl.diverged() {
            return (arrived, pilot);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_configs_parse_and_match_the_defaults() {
        let (cfg, sitl) = demo_config(&DemoOptions::default()).unwrap();
        let default = Config::parse(DEFAULT_TOML, Path::new("default.toml")).unwrap();
        assert_eq!(cfg.vehicle, default.vehicle, "sitl.toml [vehicle] drifted");
        assert_eq!(
            cfg.controller, default.controller,
            "sitl.toml [controller] drifted"
        );
        assert_eq!(cfg.safety, default.safety);
        assert_eq!(cfg.mission.path, default.mission.path);
        assert_eq!(
            sitl.sitl.start, cfg.mission.path[0],
            "SITL starts at the path start"
        );
        assert_eq!(cfg.mission.start, MissionStart::Path);
    }

    #[test]
    fn l_path_is_fifty_metres() {
        let (cfg, _) = demo_config(&DemoOptions::default()).unwrap();
        assert!((path_length(&waypoints(&cfg)) - 50.0).abs() < 1e-12);
    }
}
