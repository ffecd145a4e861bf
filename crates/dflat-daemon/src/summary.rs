//! Measurements of a flight and the summary printed at shutdown.

use std::fmt;

use dflat_link::{LinkStats, MessageCounts};
use serde::Serialize;

use crate::records::CsvReport;
use crate::supervisor::FlightState;
use dflat_control::window::PoseWindowStats;
use dflat_link::transport::TlogReport;

/// Resolution boundary of [`Histogram`]: 1 µs bins below, 100 µs above \[µs\].
const FINE_LIMIT: u64 = 10_000;
/// Width of the coarse bins \[µs\].
const COARSE_WIDTH: u64 = 100;
/// Upper end of the coarse bins \[µs\] (1 s); larger values land in the last bin.
const COARSE_LIMIT: u64 = 1_000_000;

/// A fixed-size histogram of durations in µs: exact to 1 µs below 10 ms,
/// to 100 µs up to 1 s. Recording never allocates.
#[derive(Clone)]
pub struct Histogram {
    bins: Box<[u32]>,
    count: u64,
    sum: u128,
    max: u64,
}

impl fmt::Debug for Histogram {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Histogram")
            .field("count", &self.count)
            .field("max", &self.max)
            .finish()
    }
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    /// An empty histogram (allocates its ~80 KB of bins once).
    pub fn new() -> Self {
        let bins = (FINE_LIMIT + (COARSE_LIMIT - FINE_LIMIT) / COARSE_WIDTH) as usize;
        Self {
            bins: vec![0; bins].into_boxed_slice(),
            count: 0,
            sum: 0,
            max: 0,
        }
    }

    fn bin(us: u64) -> usize {
        if us < FINE_LIMIT {
            us as usize
        } else {
            let coarse = ((us.min(COARSE_LIMIT - 1) - FINE_LIMIT) / COARSE_WIDTH) as usize;
            FINE_LIMIT as usize + coarse
        }
    }

    fn bin_value(bin: usize) -> u64 {
        let bin = bin as u64;
        if bin < FINE_LIMIT {
            bin
        } else {
            FINE_LIMIT + (bin - FINE_LIMIT) * COARSE_WIDTH
        }
    }

    /// Records one value \[µs\].
    pub fn record(&mut self, us: u64) {
        let b = Self::bin(us);
        self.bins[b] = self.bins[b].saturating_add(1);
        self.count += 1;
        self.sum += u128::from(us);
        self.max = self.max.max(us);
    }

    /// Number of values recorded.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The `q`-quantile (0–1) \[µs\]: the smallest recorded bin value with at
    /// least `q·count` values at or below it (lower bin edge; exact below
    /// 10 ms). 0 when empty.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.count == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, n) in self.bins.iter().enumerate() {
            seen += u64::from(*n);
            if seen >= rank {
                // The last bin also holds everything beyond 1 s: report the max.
                if i + 1 == self.bins.len() {
                    return self.max;
                }
                return Self::bin_value(i).min(self.max);
            }
        }
        self.max
    }

    /// p50, p99, max and mean.
    pub fn percentiles(&self) -> Percentiles {
        Percentiles {
            samples: self.count,
            p50: self.quantile(0.5),
            p99: self.quantile(0.99),
            max: self.max,
            mean: if self.count == 0 {
                0.0
            } else {
                self.sum as f64 / self.count as f64
            },
        }
    }
}

/// Distribution of a duration \[µs\].
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Percentiles {
    /// Number of samples.
    pub samples: u64,
    /// Median \[µs\].
    pub p50: u64,
    /// 99th percentile \[µs\].
    pub p99: u64,
    /// Largest \[µs\].
    pub max: u64,
    /// Mean \[µs\].
    pub mean: f64,
}

impl fmt::Display for Percentiles {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "p50 {} µs, p99 {} µs, max {} µs (n = {})",
            self.p50, self.p99, self.max, self.samples
        )
    }
}

/// Seconds spent in each state.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct StateTimes {
    /// WaitingForPose \[s\].
    pub waiting_for_pose: f64,
    /// Standby (streaming, the autopilot in its own mode) \[s\].
    pub standby: f64,
    /// Holding \[s\].
    pub holding: f64,
    /// Tracking \[s\].
    pub tracking: f64,
    /// Failsafe \[s\].
    pub failsafe: f64,
}

impl StateTimes {
    /// From an array indexed by [`FlightState::index`].
    pub fn from_array(t: [f64; 5]) -> Self {
        Self {
            waiting_for_pose: t[FlightState::WaitingForPose.index()],
            standby: t[FlightState::Standby.index()],
            holding: t[FlightState::Holding.index()],
            tracking: t[FlightState::Tracking.index()],
            failsafe: t[FlightState::Failsafe.index()],
        }
    }
}

/// Message counts: the total, and dflat-link's [`MessageCounts`] by type (serialized flat).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct Counts {
    /// All types.
    pub total: u64,
    /// Per type (read through `Deref`: `counts.heartbeat`).
    #[serde(flatten)]
    pub by_type: MessageCounts,
}

impl std::ops::Deref for Counts {
    type Target = MessageCounts;

    fn deref(&self) -> &MessageCounts {
        &self.by_type
    }
}

impl From<&MessageCounts> for Counts {
    fn from(c: &MessageCounts) -> Self {
        Self {
            total: c.total(),
            by_type: *c,
        }
    }
}

/// Link counters (dflat-link's [`LinkStats`], serializable).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct LinkSummary {
    /// Frames received with a valid checksum, before source filtering.
    pub received: Counts,
    /// Messages sent.
    pub sent: Counts,
    /// Dropped: sender not trusted for that message.
    pub ignored_wrong_source: u64,
    /// Dropped: addressed to another system / component.
    pub ignored_not_addressed: u64,
    /// Checksum mismatches.
    pub crc_errors: u64,
    /// Message ids outside the common dialect.
    pub unknown_messages: u64,
    /// Truncated frames, garbage, undecodable payloads, bad quaternions.
    pub malformed: u64,
    /// Messages refused for NaN / infinite numbers.
    pub non_finite: u64,
    /// Well-formed messages outside the contract.
    pub rejected: u64,
    /// Failed or refused sends.
    pub send_errors: u64,
    /// Socket-level receive errors (e.g. ICMP port unreachable).
    pub transport_errors: u64,
    /// Signing on: unsigned frames refused.
    pub unsigned: u64,
    /// Signing on: frames with a bad signature.
    pub bad_signature: u64,
    /// Signing on: replayed (stale-timestamp) frames.
    pub replayed: u64,
    /// Signing on: signed frames dated more than a minute ahead of the clock.
    pub future_timestamp: u64,
}

impl LinkSummary {
    /// Combines the receive side's and the send side's counters.
    pub fn new(rx: &LinkStats, tx: &LinkStats, transport_errors: u64) -> Self {
        Self {
            received: Counts::from(&rx.received),
            sent: Counts::from(&tx.sent),
            ignored_wrong_source: rx.ignored_wrong_source,
            ignored_not_addressed: rx.ignored_not_addressed,
            crc_errors: rx.crc_errors,
            unknown_messages: rx.unknown_messages,
            malformed: rx.malformed,
            non_finite: rx.non_finite,
            rejected: rx.rejected,
            send_errors: rx.send_errors + tx.send_errors,
            transport_errors,
            unsigned: rx.unsigned,
            bad_signature: rx.bad_signature,
            replayed: rx.replayed,
            future_timestamp: rx.future_timestamp,
        }
    }

    /// Sum of the inbound error counters.
    pub fn inbound_errors(&self) -> u64 {
        self.crc_errors
            + self.unknown_messages
            + self.malformed
            + self.non_finite
            + self.rejected
            + self.unsigned
            + self.bad_signature
            + self.replayed
            + self.future_timestamp
    }
}

/// Everything measured during one run of the daemon; printed at shutdown
/// and written as JSON with `--summary-json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FlightSummary {
    /// The connection string used.
    pub link: String,
    /// Controller name (`df-mpc`, `fmpc`, `pd`).
    pub controller: String,
    /// Control model (`planar`, `spatial`).
    pub model: String,
    /// Control rate \[Hz\].
    pub rate_hz: f64,
    /// Wall time from start to shutdown \[s\].
    pub duration_s: f64,
    /// Control ticks run.
    pub ticks: u64,
    /// Ticks skipped because the loop woke more than one period late.
    pub missed_ticks: u64,
    /// `controller.tick`: "pose" or "clock".
    pub tick_mode: String,
    /// Ticks run the moment a pose arrived (pose-locked).
    pub pose_ticks: u64,
    /// Ticks run at their deadline (clock ticks, ticks no pose was expected
    /// for, and the fallbacks).
    pub deadline_ticks: u64,
    /// Deadline ticks that waited for an expected pose in vain (late or
    /// lost pose; the command stream went on).
    pub fallback_ticks: u64,
    /// The control thread's real-time settings in effect.
    pub realtime: crate::realtime::RealtimeApplied,
    /// SET_ATTITUDE_TARGET messages handed to the link.
    pub commands: u64,
    /// Ticks on which the controller returned an error (nothing sent).
    pub control_errors: u64,
    /// Controller update time per tick that ran it \[µs\].
    pub solve_us: Percentiles,
    /// Tick wake time − deadline \[µs\].
    pub jitter_us: Percentiles,
    /// Pose arrival → SET_ATTITUDE_TARGET written to the link \[µs\], for
    /// ticks whose pose arrived since the previous tick. Includes the wait
    /// for the tick: the queue's hand-over with `controller.tick = "pose"`,
    /// up to one period with `"clock"`.
    pub latency_us: Percentiles,
    /// Tick wake → SET_ATTITUDE_TARGET written to the link \[µs\]: the
    /// daemon's own share of the latency (solve, queue, socket).
    pub tick_to_send_us: Percentiles,
    /// Link counters.
    pub link_stats: LinkSummary,
    /// Inbound events dropped because the control loop's queue was full.
    pub events_dropped: u64,
    /// Outbound messages dropped because the send queue was full.
    pub outbound_dropped: u64,
    /// Time in each state \[s\], up to the stop (the stop's own brake and
    /// level are [`FlightSummary::stop`]).
    pub time_in_state_s: StateTimes,
    /// Number of state changes up to the stop.
    pub state_changes: u64,
    /// The stop sequence (SIGTERM / SIGINT / shutdown while engaged: brake,
    /// level, stream off), when one ran.
    pub stop: Option<StopSummary>,
    /// Engagements: the autopilot started applying our commands (standby
    /// → holding, braking).
    pub engagements: u64,
    /// Disengagements: the autopilot stopped applying them (pilot
    /// override, mode change, disarm) while engaged.
    pub disengagements: u64,
    /// The flight state when the stop was asked for (before the stop's own
    /// brake and level; the state at shutdown when the link failed).
    pub final_state: FlightState,
    /// Process CPU time (user + system) over wall time \[%\] (100 = one core).
    pub cpu_percent: Option<f64>,
    /// Peak resident memory (VmHWM) \[KiB\].
    pub peak_rss_kib: Option<u64>,
    /// The per-flight CSV, if written.
    pub csv: Option<CsvReport>,
    /// The .tlog, if written.
    pub tlog: Option<TlogReport>,
    /// The disturbance estimate at the last tick the controller ran
    /// (`controller.disturbance.enabled`), if the controller runs an estimator.
    pub disturbance: Option<DisturbanceSummary>,
    /// What the control loop's guards did (saturations, fallbacks, pose
    /// jumps, residual failsafes).
    pub guards: crate::guard::GuardCounts,
    /// What the controller's successful ticks reported (constrained
    /// solves, solver fallbacks, input saturation).
    pub solves: SolveCounts,
    /// What DF-MPC's window did with the poses, tagged by window: the
    /// classic one (`controller.dfmpc.multi_rate = false`) the ticks
    /// predicted, skipped ticks filled, late poses placed and restarts; the
    /// multi-rate one the poses taken and refused and the ticks with no pose
    /// in the window (`blind_ticks`); `None` for the baselines.
    pub pose_window: Option<PoseWindowStats>,
    /// What the autopilot answered to the stream-rate requests
    /// (`link.request_streams`): per message asked, the rate and the
    /// answer (empty when none were asked).
    pub autopilot_streams: Vec<crate::stream_rates::StreamOutcome>,
    /// The link's guards: foreign senders, reconnects, the command slot,
    /// replies, link-task stalls.
    pub link_guard: crate::link_health::LinkGuardSummary,
    /// The records: quota, flights deleted, disk trouble.
    pub records: crate::record_store::RecordsSummary,
}

/// Counts over the controller's successful ticks, from
/// [`dflat_control::TickOutput`]'s flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct SolveCounts {
    /// Ticks whose unconstrained plan violated a bound, so the
    /// inequality-constrained QP was solved (DF-MPC with constraints).
    pub constrained: u64,
    /// Of those, ticks on which the banded constrained solver did not
    /// converge and clarabel solved instead (`controller.dfmpc.qp_solver =
    /// "banded"`). More than a few per flight is worth a look.
    pub qp_fallbacks: u64,
    /// Of the constrained ticks with the tilt cone
    /// (`controller.dfmpc.plan_tilt_bound = "cone"`), those on which the
    /// augmented Lagrangian did not converge and the banded interior point
    /// solved instead (slower: the first tick of a burst, or a hard one).
    pub cone_interior_point: u64,
    /// Ticks whose command the controller clipped by its input saturation
    /// (before the guard's own tilt / thrust caps).
    pub saturated: u64,
}

impl SolveCounts {
    /// Counts one successful tick.
    pub fn record(&mut self, out: &dflat_control::TickOutput) {
        self.constrained += u64::from(out.constrained);
        self.qp_fallbacks += u64::from(out.qp_fallback);
        self.cone_interior_point += u64::from(out.cone_interior_point);
        self.saturated += u64::from(out.saturated);
    }
}

/// The disturbance estimate for the summary (see
/// [`dflat_control::disturbance`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DisturbanceSummary {
    /// The estimator's report (acceleration offset \[m/s²\], thrust scale,
    /// hover specific thrust \[m/s²\], status).
    pub report: dflat_control::disturbance::DisturbanceReport,
    /// The hover thrust as the autopilot reads it: normalised \[0, 1\]
    /// (PX4's hover-thrust estimate), or the fixed value in `fixed` mode.
    pub hover_thrust_normalized: Option<f64>,
}

/// What the stop sequence did (`docs/safety.md`, "Stopping the daemon").
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StopSummary {
    /// From the stop request to the last command \[s\].
    pub duration_s: f64,
    /// Commands streamed meanwhile (brake and level).
    pub commands: u64,
}

impl fmt::Display for FlightSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "dflat daemon summary: {} ({} model) at {} Hz on {}",
            self.controller, self.model, self.rate_hz, self.link
        )?;
        writeln!(
            f,
            "  duration      {:.1} s, {} ticks, {} missed, {} commands, {} control errors",
            self.duration_s, self.ticks, self.missed_ticks, self.commands, self.control_errors
        )?;
        writeln!(
            f,
            "  tick = {:<7}{} on a pose, {} on the deadline ({} fallbacks for a late or lost pose)",
            format!("{},", self.tick_mode),
            self.pose_ticks,
            self.deadline_ticks,
            self.fallback_ticks
        )?;
        let rt = &self.realtime;
        if rt.fifo_priority > 0 || !rt.cpus.is_empty() || rt.memory_locked {
            writeln!(
                f,
                "  realtime      SCHED_FIFO {}, cpus {:?}, memory locked {}",
                rt.fifo_priority, rt.cpus, rt.memory_locked
            )?;
        }
        self.fmt_timing_and_states(f)?;
        self.fmt_link(f)?;
        self.fmt_guards(f)?;
        self.fmt_resources_and_records(f)
    }
}

impl FlightSummary {
    /// The summary's timing and flight-state lines.
    fn fmt_timing_and_states(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "  solve time    {}", self.solve_us)?;
        writeln!(f, "  tick jitter   {}", self.jitter_us)?;
        writeln!(f, "  pose→command  {}", self.latency_us)?;
        writeln!(f, "  tick→command  {}", self.tick_to_send_us)?;
        let t = &self.time_in_state_s;
        writeln!(
            f,
            "  states        waiting {:.1} s, standby {:.1} s, holding {:.1} s, tracking {:.1} s, failsafe {:.1} s ({} changes, {} engagements, {} disengagements, final {})",
            t.waiting_for_pose,
            t.standby,
            t.holding,
            t.tracking,
            t.failsafe,
            self.state_changes,
            self.engagements,
            self.disengagements,
            self.final_state.name()
        )?;
        if let Some(s) = &self.stop {
            writeln!(
                f,
                "  stop          brake and level for {:.2} s ({} commands), then the stream stopped",
                s.duration_s, s.commands
            )?;
        }
        Ok(())
    }

    /// The link's counters.
    fn fmt_link(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.autopilot_streams.is_empty() {
            let streams: Vec<String> = self
                .autopilot_streams
                .iter()
                .map(|s| format!("{} at {:.0} Hz {}", s.message, s.rate_hz, s.answer))
                .collect();
            writeln!(f, "  streams       {}", streams.join(", "))?;
        }
        let l = &self.link_stats;
        writeln!(
            f,
            "  link          rx {} (pose {} att {} hb {} setpoint {}), tx {} (att_tgt {} hb {} text {})",
            l.received.total,
            l.received.local_position_ned
                + l.received.odometry
                + l.received.vision_position_estimate,
            l.received.attitude,
            l.received.heartbeat,
            l.received.set_position_target_local_ned,
            l.sent.total,
            l.sent.set_attitude_target,
            l.sent.heartbeat,
            l.sent.statustext
        )?;
        writeln!(
            f,
            "  link errors   crc {} unknown {} malformed {} nonfinite {} rejected {} send {} socket {} unsigned {} badsig {} replayed {}; ignored src {} dst {}; dropped events {} outbound {}",
            l.crc_errors,
            l.unknown_messages,
            l.malformed,
            l.non_finite,
            l.rejected,
            l.send_errors,
            l.transport_errors,
            l.unsigned,
            l.bad_signature,
            l.replayed,
            l.ignored_wrong_source,
            l.ignored_not_addressed,
            self.events_dropped,
            self.outbound_dropped
        )?;
        Ok(())
    }

    /// What the guards and the solver did, and the link guard.
    fn fmt_guards(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let g = &self.guards;
        writeln!(
            f,
            "  guards        {} non-finite, {} tilt / {} thrust saturated, {} failures, {} overruns, {} plan / {} held / {} level fallbacks, {} pose jumps, {} residual failsafes, {} control failsafes (stream stopped), {} pose clock faults, {} overspeed brakes",
            g.non_finite,
            g.tilt_saturated,
            g.thrust_saturated,
            g.controller_failures,
            g.deadline_overruns,
            g.plan_steps,
            g.held,
            g.level_hover,
            g.pose_jumps,
            g.residual_failsafes,
            g.control_failsafes,
            g.pose_clock_faults,
            g.overspeed_brakes
        )?;
        let s = &self.solves;
        writeln!(
            f,
            "  solves        {} constrained ({} by clarabel after the banded solver, {} by the cone's interior point), {} saturated by the controller",
            s.constrained, s.qp_fallbacks, s.cone_interior_point, s.saturated
        )?;
        match &self.pose_window {
            Some(PoseWindowStats::Classic(w)) => writeln!(
                f,
                "  pose window   classic: {} ticks predicted (no new pose), {} skipped ticks filled, {} late poses placed, {} restarts",
                w.predicted, w.filled, w.late, w.restarts
            )?,
            Some(PoseWindowStats::MultiRate(w)) => writeln!(
                f,
                "  pose window   multi-rate: {} poses taken, {} refused (not finite or older than the window), {} ticks with no pose in the window",
                w.accepted, w.rejected, w.blind_ticks
            )?,
            None => {}
        }
        let lg = &self.link_guard;
        writeln!(
            f,
            "  link guard    peer {}, {} foreign frames dropped, {} reconnects, {} sends dropped, {} future-dated; commands {} replaced / {} stale; replies {} sent / {} dropped; {} link-task stalls",
            lg.peer.map_or("-".to_owned(), |p| p.to_string()),
            lg.foreign_frames,
            lg.reconnects,
            lg.send_dropped,
            lg.future_timestamp,
            lg.commands_replaced,
            lg.commands_stale,
            lg.replies_sent,
            lg.replies_dropped,
            lg.link_stalls
        )?;
        Ok(())
    }

    /// Resources, the records and the disturbance estimate (no newline at
    /// the end).
    fn fmt_resources_and_records(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let cpu = self
            .cpu_percent
            .map_or("n/a".to_owned(), |c| format!("{c:.1} %"));
        let rss = self.peak_rss_kib.map_or("n/a".to_owned(), |r| {
            format!("{:.1} MiB", r as f64 / 1024.0)
        });
        write!(f, "  resources     CPU {cpu}, peak RSS {rss}")?;
        if let Some(c) = &self.csv {
            write!(
                f,
                "\n  csv           {} ({} rows, {} dropped)",
                c.path.display(),
                c.rows,
                c.dropped
            )?;
        }
        if let Some(t) = &self.tlog {
            write!(
                f,
                "\n  tlog          {} ({} frames, {} dropped)",
                t.path.display(),
                t.records,
                t.dropped
            )?;
        }
        crate::record_store::write_summary(
            f,
            &self.records,
            self.csv.as_ref(),
            self.tlog.as_ref(),
        )?;
        if let Some(d) = &self.disturbance {
            let r = &d.report;
            let hover = d
                .hover_thrust_normalized
                .map_or("n/a".to_owned(), |h| format!("{h:.3}"));
            write!(
                f,
                "\n  disturbance   d = ({:.3}, {:.3}, {:.3}) m/s², thrust scale {:.3}, hover thrust {hover} ({:?}{}, {} pose jumps)",
                r.acceleration[0],
                r.acceleration[1],
                r.acceleration[2],
                r.thrust_scale,
                r.status,
                if r.clamped { ", clamped" } else { "" },
                r.jumps
            )?;
        }
        Ok(())
    }
}

/// Linux reports process times in /proc in USER_HZ = 100 ticks per second
/// on every architecture (it is part of the /proc ABI).
const USER_HZ: f64 = 100.0;

/// User + system CPU time of this process \[s\] from `/proc/self/stat`;
/// `None` where /proc is unavailable.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    parse_cpu_seconds(&stat)
}

fn parse_cpu_seconds(stat: &str) -> Option<f64> {
    // The command name (field 2) may contain spaces: fields after its ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After ')': field 3 (state) is index 0, utime (14) index 11, stime (15) index 12.
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / USER_HZ)
}

/// Peak resident set size (VmHWM) of this process \[KiB\] from
/// `/proc/self/status`; `None` where unavailable.
pub fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    parse_vm_hwm(&status)
}

fn parse_vm_hwm(status: &str) -> Option<u64> {
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_quantiles() {
        let mut h = Histogram::new();
        assert_eq!(h.percentiles(), Percentiles::default());
        for us in 1..=100 {
            h.record(us);
        }
        assert_eq!(h.quantile(0.5), 50);
        assert_eq!(h.quantile(0.99), 99);
        assert_eq!(h.quantile(1.0), 100);
        let p = h.percentiles();
        assert_eq!((p.samples, p.max), (100, 100));
        assert!((p.mean - 50.5).abs() < 1e-12);
        // Coarse range and overflow.
        h.record(12_345);
        h.record(5_000_000);
        assert_eq!(h.quantile(1.0), 5_000_000);
        assert_eq!(h.percentiles().max, 5_000_000);
        let mut g = Histogram::new();
        g.record(12_345);
        assert_eq!(g.quantile(0.5), 12_300);
    }

    #[test]
    fn proc_parsers() {
        let stat =
            "1234 (dflat (x) y) S 1 1234 1234 0 -1 4194560 300 0 0 0 150 50 0 0 20 0 9 0 100 0 0";
        assert_eq!(parse_cpu_seconds(stat), Some(2.0));
        assert_eq!(parse_cpu_seconds("garbage"), None);
        let status = "Name:\tdflat\nVmPeak:\t  100 kB\nVmHWM:\t    8812 kB\nVmRSS:\t 8000 kB\n";
        assert_eq!(parse_vm_hwm(status), Some(8812));
        if cfg!(target_os = "linux") {
            assert!(process_cpu_seconds().is_some());
            assert!(peak_rss_kib().unwrap() > 0);
        }
    }
}
