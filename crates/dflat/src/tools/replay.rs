//! `dflat replay`: the daemon's pure tick ([`ControlCore`]) re-run offline
//! on a flight's logged inputs — the received frames of its `.tlog`
//! (poses, ATTITUDE, HEARTBEATs, setpoints, through the same source filter
//! and event mapping as the daemon) and the tick times of its CSV — with
//! the flight's own configuration (it reproduces the logged commands) or
//! another one (what that tuning would have commanded, drawn into the
//! review page).
//!
//! **The clocks.** The daemon stamps each received frame's arrival in whole
//! microseconds since its epoch ([`dflat_daemon::tick::arrival_secs`]) and
//! logs the frame at the epoch's UNIX time plus that arrival, so a log
//! stamp is the arrival plus one constant, the epoch. The replay finds the
//! epoch in two passes: first from the sent commands (the earliest send
//! after its tick), to within the send latency; then to the microsecond
//! from the CSV's pose ages (1 µs resolution), which move one for one with
//! it. With the epoch exact every arrival, and so the pose clock's capture
//! times, are the flight's bit for bit. (A log written before 2026-11-27
//! stamped frames on the wall clock at nearly the same instant: its
//! arrivals are off by a few microseconds each, and a sample near the edge
//! of the multi-rate window may fall on the other side.)
//!
//! **The ticks.** A CSV with the `t_wake` column has each tick's exact time
//! (older ones: the scheduled time to 0.1 ms plus the jitter in whole µs).
//! A CSV with the `events` column (the events each tick had applied so
//! far) fixes which frames each tick saw exactly. The report counts the
//! ticks reproduced exactly at the CSV's resolution and the largest
//! difference.
//!
//! **Missions.** The logged mission protocol frames (MISSION_COUNT,
//! MISSION_ITEM_INT, …) run through the daemon's own [`MissionProtocol`],
//! and an upload it accepts is loaded at the next tick, as the control
//! thread does; each logged COMMAND_LONG/INT is answered as the receive
//! task answers it ([`dflat_daemon::commands::answer`], with the flight
//! state of the re-run's last tick and the protocol's mission), and a
//! mission command it accepts (start, pause, continue, speed) enters the
//! tick's events where the daemon's did. A mission flight is re-run
//! through its uploads and commands.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use dflat_daemon::commands::{CommandContext, answer};
use dflat_daemon::config::Config;
use dflat_daemon::control::{build_controller, thrust_mapping};
use dflat_daemon::mission::{ItemRules, Mission, MissionChange, MissionProtocol};
use dflat_daemon::supervisor::FlightState;
use dflat_daemon::tick::{
    ControlCore, Event, TickTime, arrival_secs, event_from, pose_source, source_filter,
};
use dflat_link::tlog::TlogReader;
use dflat_link::{CommandRequest, Inbound, LinkRx, MavMessage, RxOutcome};
use dflat_records::Column;
use dflat_tuning::flightlog::FlightCsv;

use super::review::load_tlog_beside;
use dflat_tuning::review::{Overlay, quantile, render};

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

/// A received frame as the daemon's receive task acts on it.
#[derive(Debug, Clone)]
enum Received {
    /// A daemon event (its arrival set by the clock mapping).
    Event(Event),
    /// A command (COMMAND_LONG/INT) to answer; a mission command the
    /// answer accepts becomes an event.
    Command(CommandRequest),
    /// A frame for the mission protocol, from (system, component).
    Protocol(MavMessage, (u8, u8)),
}

/// A flight's logged frames.
struct Logged {
    /// The received frames the daemon's filter accepts, in the order the
    /// receive task handled them, with their log stamps \[µs since 1970\].
    received: Vec<(u64, Received)>,
    /// Sent SET_ATTITUDE_TARGET: (log stamp \[µs since 1970\],
    /// `time_boot_ms`).
    sent: Vec<(u64, u32)>,
}

/// Reads the tlog at `path` (see [`Logged`]).
fn tlog_frames(path: &Path, cfg: &Config) -> Result<Logged> {
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut link = LinkRx::new(source_filter(&cfg.link));
    let source = pose_source(cfg.link.pose_source);
    let mut received = Vec::new();
    let mut sent = Vec::new();
    let mut any = false;
    for record in TlogReader::new(BufReader::new(file)) {
        let record = match record {
            Ok(r) => r,
            Err(dflat_link::tlog::TlogError::Truncated { .. }) if any => break,
            Err(e) => bail!("{}: {e}", path.display()),
        };
        any = true;
        let stamp = record.timestamp_us;
        let Ok(frame) = record.parse() else { continue };
        if let MavMessage::SET_ATTITUDE_TARGET(d) = &frame.message
            && frame.header.component_id == cfg.link.component_id
        {
            sent.push((stamp, d.time_boot_ms));
            continue;
        }
        // As the receive task: the command answered first, then the
        // mission protocol, then the event.
        if let RxOutcome::Accepted(inbound) = link.handle(&frame.header, &frame.message) {
            let sender = (frame.header.system_id as u8, frame.header.component_id);
            if let Some(req) = CommandRequest::from_message(&frame.message, sender.0, sender.1) {
                received.push((stamp, Received::Command(req)));
            }
            if matches!(inbound, Inbound::Other(_)) {
                received.push((stamp, Received::Protocol(frame.message.clone(), sender)));
            }
            if let Some(e) = event_from(&inbound, source, 0.0) {
                received.push((stamp, Received::Event(e)));
            }
        }
    }
    Ok(Logged { received, sent })
}

/// The arrival \[s since the daemon's epoch\] of a frame logged at
/// `stamp` when the epoch is at `epoch` on the log's clock (both µs since
/// 1970): exactly the daemon's own value for a frame it logged.
fn arrival_at(stamp: u64, epoch: u64) -> f64 {
    match stamp.checked_sub(epoch) {
        Some(us) => arrival_secs(us),
        None => -arrival_secs(epoch - stamp),
    }
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
    let logged = tlog_frames(&tlog, cfg)?;
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
    // The daemon's epoch on the log's clock, first from the sends: a
    // command is logged after its tick, the earliest send the closest.
    let by_ms: std::collections::HashMap<u32, f64> = wake
        .iter()
        .map(|w| ((w * 1000.0) as u64 as u32, *w))
        .collect();
    let epoch = logged
        .sent
        .iter()
        .filter_map(|(stamp, ms)| by_ms.get(ms).map(|w| *stamp as f64 - w * 1e6))
        .fold(f64::INFINITY, f64::min);
    if !epoch.is_finite() || epoch < 0.0 {
        bail!(
            "{}: no sent command matches a tick of {} (not the same flight?)",
            tlog.display(),
            csv_path.display()
        );
    }
    let epoch = epoch.round() as u64;
    // Pass 1 with that epoch; the CSV's pose ages (µs) then move one for
    // one with its error, and pass 2 runs on the corrected epoch.
    let first = run_pass(csv, cfg, &logged.received, &wake, epoch)?;
    match first.1 {
        Some(shift) if csv.has(Column::PoseAgeMs) => {
            // Replay ages larger than the logged: the arrivals are early,
            // the epoch too late.
            let corrected = epoch.saturating_add_signed(-((shift * 1e6).round() as i64));
            Ok(run_pass(csv, cfg, &logged.received, &wake, corrected)?.0)
        }
        _ => Ok(first.0),
    }
}

/// The receive task's mission side, re-run: the protocol, the uploads it
/// accepted for the next tick, and the flight state the control thread
/// last published (what a command is answered against).
struct MissionSide {
    own: (u8, u8),
    protocol: MissionProtocol,
    loaded: Vec<Option<Mission>>,
    state: Option<FlightState>,
}

impl MissionSide {
    fn new(cfg: &Config) -> Self {
        let own = (cfg.link.system_id, cfg.link.component_id);
        Self {
            own,
            protocol: MissionProtocol::new(own, ItemRules::of(&cfg.mission)),
            loaded: Vec::new(),
            state: None,
        }
    }

    /// A protocol frame at `t` \[s\] (its timeouts polled first).
    fn protocol_frame(&mut self, msg: &MavMessage, sender: (u8, u8), t: f64) {
        let polled = self.protocol.poll(t).change;
        self.change(polled);
        let change = self.protocol.handle(msg, sender, t).change;
        self.change(change);
    }

    fn change(&mut self, change: Option<MissionChange>) {
        match change {
            Some(MissionChange::Uploaded(m)) => self.loaded.push(Some(m)),
            Some(MissionChange::Cleared) => self.loaded.push(None),
            None => {}
        }
    }

    /// The mission command the receive task would pass on for `req`.
    fn action(&self, req: &CommandRequest) -> Option<dflat_daemon::tick::MissionAction> {
        let context = CommandContext::new(self.protocol.mission().has_navigation(), self.state);
        answer(req, self.own, &context)?.action
    }
}

/// One re-run with the daemon's epoch at `epoch` on the log's clock \[µs
/// since 1970\]: the report and the median (re-run − logged) pose age
/// \[s\], if the CSV has pose ages.
fn run_pass(
    csv: &FlightCsv,
    cfg: &Config,
    received: &[(u64, Received)],
    wake: &[f64],
    epoch: u64,
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
    let mut pending = received
        .iter()
        .map(|(stamp, r)| {
            let arrival = arrival_at(*stamp, epoch);
            match r {
                Received::Event(e) => (arrival, Received::Event(e.arriving_at(arrival))),
                other => (arrival, other.clone()),
            }
        })
        .peekable();
    let mut missions = MissionSide::new(cfg);
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
    let solve_us = csv.numbers(Column::SolveUs);
    // The tick at which the flight's stop (SIGTERM) was asked for.
    let guards = csv.texts(Column::Guard);
    let mut taken: u64 = 0;
    for i in 0..csv.rows.len() {
        let w = wake[i];
        let mut batch = Vec::new();
        // An event is due by the tick's cutoff (the count of events it
        // had applied), or by its arrival; mission events and what the
        // receive task handles without an event (protocol frames,
        // commands answered without a mission action) by their arrival.
        // Order is kept.
        let event_due = |arrival: f64, taken: u64| match cutoff[i] {
            Some(n) => (taken as f64) < n,
            None => arrival <= w,
        };
        while let Some((arrival, r)) = pending.peek() {
            let arrival = *arrival;
            match r {
                Received::Event(e) => {
                    if !event_due(arrival, taken) {
                        break;
                    }
                    batch.push(*e);
                    taken += 1;
                }
                // A mission event is not among the events the cutoff
                // counts (`ControlCore::step`): due by its arrival.
                Received::Command(req) => match missions.action(req) {
                    Some(action) => {
                        if arrival > w {
                            break;
                        }
                        batch.push(Event::Mission { arrival, action });
                    }
                    None if arrival <= w => {}
                    None => break,
                },
                Received::Protocol(msg, sender) => {
                    if arrival > w {
                        break;
                    }
                    missions.protocol_frame(msg, *sender, arrival);
                }
            }
            pending.next();
        }
        let time = TickTime {
            tick: ticks[i].unwrap_or(0.0) as u64,
            t: w,
            scheduled: t_sched[i].unwrap_or(w),
            jitter_us: jitter[i].unwrap_or(0.0) as u32,
        };
        // The stopwatch around the solve reads the logged solve time, so a
        // deadline overrun in flight is one here too.
        let solve = solve_us[i].unwrap_or(0.0) * 1e-6;
        let mut readings = 0u32;
        let mut stopwatch = || {
            readings += 1;
            if readings.is_multiple_of(2) {
                solve
            } else {
                0.0
            }
        };
        for mission in missions.loaded.drain(..) {
            core.load_mission(w, mission);
        }
        if guards
            .get(i)
            .is_some_and(|g| *g == dflat_daemon::tick::STOP_GUARD)
        {
            core.begin_stop(w);
        }
        let out = core.step(&time, batch, &mut stopwatch);
        if let Some(tr) = out.transitions.last() {
            missions.state = Some(tr.to);
        }
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
    let csv = super::read_csv(&csv_path)?;
    let cfg = Config::load(&args.config)?;
    let mut report = replay(&csv_path, &csv, &cfg)?;
    report.overlay.label = format!("replay with {}", args.config.display());
    outln!(
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
    outln!("{}", out.display());
    Ok(())
}
