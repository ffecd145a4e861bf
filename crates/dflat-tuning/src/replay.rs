//! `dflat replay`: the daemon's pure tick ([`ControlCore`]) re-run offline
//! on a flight's logged inputs — the received frames of its `.tlog`
//! (poses, ATTITUDE, HEARTBEATs, setpoints, through the same source filter
//! and event mapping as the daemon) and the tick times of its CSV — with
//! the flight's own configuration (it reproduces the logged commands) or
//! another one (what that tuning would have commanded, drawn into the
//! review page).
//!
//! Not bit for bit: the daemon stamps an event's arrival on its monotonic
//! clock, the tlog on the wall clock at nearly the same instant, in whole
//! microseconds; the offset between the two is estimated from the sent
//! commands (the earliest send after its tick). An event that arrived
//! within that error of a tick's wake may land one tick off, and the pose
//! clock's offset (hence the capture times) moves by the same few
//! microseconds. The CSV also holds the tick's scheduled time to 0.1 ms and
//! its jitter in whole µs (a CSV with the `t_wake` column has the exact tick
//! time). A CSV with the `events` column (the events each tick had
//! applied so far) fixes which frames each tick saw exactly: a pose that
//! arrived within microseconds of its tick's wake (every pose-locked tick)
//! lands in the same tick as in flight. The report counts the ticks
//! reproduced exactly at the CSV's resolution and the largest difference.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use crate::flightlog::FlightCsv;
use dflat_daemon::config::Config;
use dflat_daemon::control::{build_controller, thrust_mapping};
use dflat_daemon::csv_schema::Column;
use dflat_daemon::tick::{ControlCore, Event, TickTime, event_from, pose_source, source_filter};
use dflat_link::tlog::TlogReader;
use dflat_link::{LinkRx, MavMessage, RxOutcome};

use crate::review::{Overlay, load_tlog_beside, quantile, render};

/// Arguments of `dflat replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The flight's `.csv` (its `.tlog` must be beside it).
    pub flight: PathBuf,
    /// The configuration to re-run with (the flight's own to reproduce it).
    #[arg(long)]
    pub config: PathBuf,
    /// The review page with the re-run's commands drawn over the flown
    /// ones (default `<flight>.replay.html`).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// How a re-run compares with the logged commands.
#[derive(Debug, Clone, Default)]
pub struct ReplayReport {
    /// Ticks re-run.
    pub ticks: usize,
    /// Ticks where both the flight and the re-run sent a command.
    pub compared: usize,
    /// Ticks whose command is the logged one at the CSV's resolution
    /// (angles 1 µrad, thrust 1e-4).
    pub identical: usize,
    /// Ticks where only one of the two sent a command.
    pub stream_differs: usize,
    /// Largest attitude difference \[rad\].
    pub max_angle_diff: f64,
    /// 99th percentile of the attitude difference \[rad\].
    pub p99_angle_diff: f64,
    /// Largest thrust difference.
    pub max_thrust_diff: f64,
    /// The re-run's commands per tick.
    pub overlay: Overlay,
}

/// The received frames of a tlog as daemon events, arrival on the log's
/// clock (seconds since its first record), and the sent
/// SET_ATTITUDE_TARGET times with their `time_boot_ms`.
/// Sent SET_ATTITUDE_TARGET: (log time \[s\], `time_boot_ms`).
type Sent = Vec<(f64, u32)>;

fn tlog_events(path: &Path, cfg: &Config) -> Result<(Vec<Event>, Sent)> {
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut link = LinkRx::new(source_filter(&cfg.link));
    let source = pose_source(cfg.link.pose_source);
    let mut events = Vec::new();
    let mut sent = Vec::new();
    let mut start = None;
    for record in TlogReader::new(BufReader::new(file)) {
        let record = match record {
            Ok(r) => r,
            Err(dflat_link::tlog::TlogError::Truncated { .. }) if start.is_some() => break,
            Err(e) => bail!("{}: {e}", path.display()),
        };
        let t0 = *start.get_or_insert(record.timestamp_us);
        let t = record.timestamp_us.saturating_sub(t0) as f64 * 1e-6;
        let Ok(frame) = record.parse() else { continue };
        if let MavMessage::SET_ATTITUDE_TARGET(d) = &frame.message
            && frame.header.component_id == cfg.link.component_id
        {
            sent.push((t, d.time_boot_ms));
            continue;
        }
        if let RxOutcome::Accepted(inbound) = link.handle(&frame.header, &frame.message)
            && let Some(e) = event_from(&inbound, source, t)
        {
            events.push(e);
        }
    }
    Ok((events, sent))
}

/// Re-runs the flight of `csv` (with its `.tlog` beside it) under `cfg`.
pub fn replay(csv_path: &Path, csv: &FlightCsv, cfg: &Config) -> Result<ReplayReport> {
    let tlog = csv_path.with_extension("tlog");
    if !tlog.exists() {
        bail!(
            "{}: no such file (replay needs the flight's .tlog beside its CSV)",
            tlog.display()
        );
    }
    for needed in [
        Column::Tick,
        Column::T,
        Column::JitterUs,
        Column::Roll,
        Column::Pitch,
        Column::Yaw,
        Column::Thrust,
    ] {
        if !csv.has(needed) {
            bail!("{}: no `{needed}` column", csv_path.display());
        }
    }
    let (events, sent) = tlog_events(&tlog, cfg)?;
    let t_sched = csv.numbers(Column::T);
    let jitter = csv.numbers(Column::JitterUs);
    // The exact tick time when the CSV has it (`t_wake`), else scheduled
    // time (0.1 ms) plus jitter (1 µs).
    let exact = csv.numbers(Column::TWake);
    let wake: Vec<f64> = t_sched
        .iter()
        .zip(&jitter)
        .zip(&exact)
        .map(|((t, j), w)| w.unwrap_or(t.unwrap_or(f64::NAN) + j.unwrap_or(0.0) * 1e-6))
        .collect();
    // Log clock → daemon clock: the earliest send after its tick.
    let by_ms: std::collections::HashMap<u32, f64> = wake
        .iter()
        .map(|w| ((w * 1000.0) as u64 as u32, *w))
        .collect();
    let offset = sent
        .iter()
        .filter_map(|(t, ms)| by_ms.get(ms).map(|w| w - t))
        .fold(f64::NEG_INFINITY, f64::max);
    if !offset.is_finite() {
        bail!(
            "{}: no sent command matches a tick of {} (not the same flight?)",
            tlog.display(),
            csv_path.display()
        );
    }
    // Pass 1 with the send-side estimate; the CSV's pose ages (µs) then
    // tell how far the capture times are off, and pass 2 corrects it.
    let first = run_pass(csv, cfg, &events, &wake, offset)?;
    match first.1 {
        Some(shift) if csv.has(Column::PoseAgeMs) => {
            Ok(run_pass(csv, cfg, &events, &wake, offset + shift)?.0)
        }
        _ => Ok(first.0),
    }
}

/// One re-run with events shifted by `offset` \[s\]: the report and the
/// median (re-run − logged) pose age \[s\], if the CSV has pose ages.
fn run_pass(
    csv: &FlightCsv,
    cfg: &Config,
    events: &[Event],
    wake: &[f64],
    offset: f64,
) -> Result<(ReplayReport, Option<f64>)> {
    let ticks = csv.numbers(Column::Tick);
    // Each tick's cutoff in the events, when logged.
    let cutoff = csv.numbers(Column::Events);
    let t_sched = csv.numbers(Column::T);
    let jitter = csv.numbers(Column::JitterUs);
    let ages = csv.numbers(Column::PoseAgeMs);
    let mut age_diffs = Vec::new();
    let controller = build_controller(cfg).context("cannot build the controller")?;
    let mut core = ControlCore::new(cfg, controller, thrust_mapping(cfg));
    let mut pending = events.iter().map(|e| e.shifted(offset)).peekable();
    let logged = [Column::Roll, Column::Pitch, Column::Yaw, Column::Thrust].map(|c| csv.numbers(c));
    let mut report = ReplayReport {
        ticks: csv.rows.len(),
        overlay: Overlay {
            label: "replay".into(),
            ..Overlay::default()
        },
        ..ReplayReport::default()
    };
    let mut diffs = Vec::new();
    let mut zero = || 0.0;
    let mut taken: u64 = 0;
    for i in 0..csv.rows.len() {
        let w = wake[i];
        let mut batch = Vec::new();
        while let Some(e) = pending.peek() {
            let due = match cutoff[i] {
                Some(n) => (taken as f64) < n,
                None => e.arrival() <= w,
            };
            if !due {
                break;
            }
            batch.extend(pending.next());
            taken += 1;
        }
        let time = TickTime {
            tick: ticks[i].unwrap_or(0.0) as u64,
            t: w,
            scheduled: t_sched[i].unwrap_or(w),
            jitter_us: jitter[i].unwrap_or(0.0) as u32,
        };
        let out = core.step(&time, batch, &mut zero);
        if let (Some(a), Some(b)) = (out.row.pose_age_ms, ages[i]) {
            age_diffs.push((a - b) * 1e-3);
        }
        let mine = out.row.command;
        report.overlay.t.push(t_sched[i].unwrap_or(w));
        report
            .overlay
            .command
            .push(mine.map_or([f64::NAN; 3], |c| [c[0], c[1], c[3]]));
        let theirs = (|| Some([logged[0][i]?, logged[1][i]?, logged[2][i]?, logged[3][i]?]))();
        match (mine, theirs) {
            (Some(a), Some(b)) => {
                report.compared += 1;
                let da = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0, f64::max);
                let dt = (a[3] - b[3]).abs();
                if da <= 0.5e-6 + 1e-12 && dt <= 0.5e-4 + 1e-12 {
                    report.identical += 1;
                }
                diffs.push(da);
                report.max_angle_diff = report.max_angle_diff.max(da);
                report.max_thrust_diff = report.max_thrust_diff.max(dt);
            }
            (None, None) => {}
            _ => report.stream_differs += 1,
        }
    }
    report.p99_angle_diff = quantile(&diffs, 0.99);
    let shift = quantile(&age_diffs, 0.5);
    Ok((report, shift.is_finite().then_some(shift)))
}

/// `dflat replay`.
pub fn run(args: ReplayArgs) -> Result<()> {
    let csv_path = match args.flight.extension().and_then(|e| e.to_str()) {
        Some("tlog") => args.flight.with_extension("csv"),
        _ => args.flight.clone(),
    };
    let csv = crate::read_csv(&csv_path)?;
    let cfg = Config::load(&args.config)?;
    let mut report = replay(&csv_path, &csv, &cfg)?;
    report.overlay.label = format!("replay with {}", args.config.display());
    println!(
        "replayed {} ticks with {}: {} commands compared, {} identical at the CSV's resolution, \
         {} ticks where only one side streamed; largest attitude difference {:.2e} rad (p99 {:.2e}), thrust {:.2e}",
        report.ticks,
        args.config.display(),
        report.compared,
        report.identical,
        report.stream_differs,
        report.max_angle_diff,
        report.p99_angle_diff,
        report.max_thrust_diff
    );
    let log = load_tlog_beside(&csv_path)?;
    let html = render(&csv_path, &csv, log.as_ref(), Some(&report.overlay));
    let out = args
        .out
        .unwrap_or_else(|| csv_path.with_extension("replay.html"));
    std::fs::write(&out, html).with_context(|| format!("cannot write {}", out.display()))?;
    println!("{}", out.display());
    Ok(())
}
