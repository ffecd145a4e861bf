//! The control loop's tick schedule. Pure (the caller reads the clock,
//! sleeps or waits for events, and reports what it saw).
//!
//! Two schedules:
//!
//! * [`Schedule`] — the plain clock: tick `k` is due at `start + k·δt`.
//!   The loop sleeps until the next deadline and reports the time it
//!   actually woke. If it wakes at or after the deadline of a *later* tick
//!   (a stall longer than one period), the ticks in between are skipped and
//!   counted — never run in a burst — and the schedule stays anchored to
//!   `start` (no drift).
//! * [`TickPlanner`] — `controller.tick = "pose"`: one tick per period,
//!   each run the moment a fresh pose arrives, on a grid whose phase is
//!   locked to the pose stream, with the period's deadline as the fallback
//!   (see its docs). With `lock = false` it is the plain clock.

use std::time::Duration;

/// One scheduled tick as decided by [`Schedule::on_wake`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TickSlot {
    /// Index of the tick to run now (deadline `start + tick·δt`).
    pub tick: u64,
    /// Ticks skipped just before this one (0 when on time).
    pub missed: u64,
    /// Wake time minus this tick's deadline (≥ 0, < δt).
    pub jitter: Duration,
}

/// Absolute-deadline schedule of a periodic loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schedule {
    period: Duration,
    next: u64,
    missed_total: u64,
}

impl Schedule {
    /// A schedule with period δt (must be > 0; a zero period is raised to 1 ns).
    pub fn new(period: Duration) -> Self {
        Self {
            period: period.max(Duration::from_nanos(1)),
            next: 0,
            missed_total: 0,
        }
    }

    /// The period δt.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Deadline of tick `k`, as an offset from the start.
    pub fn deadline(&self, k: u64) -> Duration {
        // Exact in nanoseconds (saturates after ~584 years).
        let ns = self.period.as_nanos().saturating_mul(u128::from(k));
        Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
    }

    /// Offset from the start at which the loop should next wake.
    pub fn next_deadline(&self) -> Duration {
        self.deadline(self.next)
    }

    /// Ticks skipped so far.
    pub fn missed_total(&self) -> u64 {
        self.missed_total
    }

    /// The loop woke at `wake` (offset from the start). Returns the tick to
    /// run, or `None` if it woke early (sleep again until
    /// [`next_deadline`](Self::next_deadline)).
    pub fn on_wake(&mut self, wake: Duration) -> Option<TickSlot> {
        let due = self.next_deadline();
        if wake < due {
            return None;
        }
        // Latest tick whose deadline is at or before `wake`.
        let latest = u64::try_from(wake.as_nanos() / self.period.as_nanos()).unwrap_or(u64::MAX);
        let tick = latest.max(self.next);
        let missed = tick - self.next;
        self.missed_total += missed;
        self.next = tick + 1;
        Some(TickSlot {
            tick,
            missed,
            jitter: wake - self.deadline(tick),
        })
    }
}

/// Why a tick of the [`TickPlanner`] ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TickCause {
    /// A fresh pose arrived in the tick's window (pose-locked).
    Pose,
    /// The tick's deadline passed: the clock mode, a tick no pose was
    /// expected for (slower vision), or the fallback for a late or lost
    /// pose ([`PlannedTick::fallback`]).
    Deadline,
}

/// A tick decided by [`TickPlanner::poll`]. Times are seconds since the
/// caller's epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedTick {
    /// Index of the tick (one per period, skipped ones included).
    pub tick: u64,
    /// Ticks skipped just before this one (a stall longer than a period).
    pub missed: u64,
    /// What made it run.
    pub cause: TickCause,
    /// When it was due \[s\]: the fresh pose's arrival (or the window's
    /// opening if the pose came before), else the deadline.
    pub due: f64,
    /// Wake time − due \[s\] (≥ 0).
    pub lateness: f64,
    /// A pose was expected for this tick and did not come by the deadline:
    /// the tick ran on the previous pose (the deadline fallback).
    pub fallback: bool,
    /// The tick found a pose that arrived since the previous tick.
    pub fresh_pose: bool,
}

/// Counters of a [`TickPlanner`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TickCounts {
    /// Ticks run because a pose arrived.
    pub by_pose: u64,
    /// Ticks run at their deadline.
    pub by_deadline: u64,
    /// Of those, ticks that waited for an expected pose in vain.
    pub fallbacks: u64,
    /// Ticks skipped (stalls).
    pub missed: u64,
}

/// Pose-locked tick placement (`controller.tick = "pose"`), or the plain
/// clock (`lock = false`). Pure: times in seconds since the caller's epoch.
///
/// One tick per period δt, on a grid of nominal times `E_k`:
///
/// * **Fire on the pose.** Tick `k` runs the moment a fresh pose arrives in
///   its window `[E_k − δt/4, E_k + wait]` (a pose that came earlier in
///   the half period before `E_k` runs it at `E_k − δt/4`).
/// * **Deadline fallback.** Without one it runs at `E_k + wait` when a pose
///   was expected for it (late or lost: it runs on the previous pose and
///   the controller predicts), else at `E_k`. A lost pose never stops the
///   command stream and never runs two ticks in a burst.
/// * **Phase lock.** After each tick that found a fresh pose, the grid
///   moves by that pose's phase error (arrival − `E_k`, wrapped to ±δt/2),
///   clamped to `[−δt/4, +wait]` per tick: the next pose then lands at the
///   next `E`, and a one-off late pose or a jittery arrival moves the grid
///   by a bounded amount. Tick spacing stays within
///   `[δt − δt/4 − wait, δt + δt/4 + wait]`.
/// * **Which streams.** The pose period is estimated from the arrivals
///   (outliers such as a dropped pose's double interval ignored). The lock
///   acts when it is within 5 % of n·δt, n = 1…5 (50, 25, 16.7, 12.5, 10 Hz
///   at a 50 Hz loop): every pose then lands on a tick. Other rates (30 Hz
///   vision at 50 Hz, or faster than the loop) leave the grid alone and
///   every tick runs at its nominal time with the newest pose, as the clock
///   does.
#[derive(Debug, Clone, PartialEq)]
pub struct TickPlanner {
    period: f64,
    wait: f64,
    early: f64,
    lock: bool,
    /// Nominal time of the next tick.
    next: f64,
    tick: u64,
    /// Arrival of the newest pose since the previous tick.
    pending: Option<f64>,
    last_pose: Option<f64>,
    pose_period: Option<f64>,
    /// Consecutive intervals rejected as outliers.
    rejected: u32,
    /// Intervals the current period estimate has taken in (since its
    /// last restart).
    accepted: u32,
    counts: TickCounts,
}

/// Intervals rejected in a row before the period estimate restarts.
const PERIOD_RESTART: u32 = 8;
/// Gain of the period estimate (exponential average).
const PERIOD_GAIN: f64 = 0.125;
/// Intervals in a row the period estimate takes in before it counts as
/// settled ([`TickPlanner::settled_pose_period`]).
pub const PERIOD_SETTLED: u32 = 16;

/// The stale-pose failsafe's timeout must be at least this many pose
/// intervals: one lost pose leaves two intervals between poses, and a
/// shorter timeout lets it trip the failsafe (docs/safety.md, "Losing
/// pose").
pub const POSE_TIMEOUT_MIN_INTERVALS: f64 = 2.0;

/// Whether `pose_timeout` \[s\] (`safety.pose_timeout_ms`) is too tight
/// for a pose stream of period `pose_period` \[s\]: under
/// [`POSE_TIMEOUT_MIN_INTERVALS`] of its intervals.
pub fn pose_timeout_too_tight(pose_timeout: f64, pose_period: f64) -> bool {
    pose_timeout < POSE_TIMEOUT_MIN_INTERVALS * pose_period
}

impl TickPlanner {
    /// A planner with period `period` \[s\] (> 0), waiting up to `wait`
    /// \[s\] past a tick's nominal time for an expected pose, locking to
    /// the poses when `lock` (else the plain clock); the first tick is due
    /// at `first` \[s\].
    pub fn new(period: f64, wait: f64, lock: bool, first: f64) -> Self {
        let period = if period > 0.0 { period } else { 1e-9 };
        Self {
            period,
            wait: wait.clamp(0.0, period / 2.0),
            early: period / 4.0,
            lock,
            next: first,
            tick: 0,
            pending: None,
            last_pose: None,
            pose_period: None,
            rejected: 0,
            accepted: 0,
            counts: TickCounts::default(),
        }
    }

    /// The counters so far.
    pub fn counts(&self) -> TickCounts {
        self.counts
    }

    /// The estimated pose period \[s\], once two poses came.
    pub fn pose_period(&self) -> Option<f64> {
        self.pose_period
    }

    /// The estimated pose period \[s\] once it has taken in
    /// [`PERIOD_SETTLED`] intervals in a row (none rejected in between
    /// enough to restart it).
    pub fn settled_pose_period(&self) -> Option<f64> {
        self.pose_period.filter(|_| self.accepted >= PERIOD_SETTLED)
    }

    /// Nominal time of the next tick \[s\].
    pub fn nominal(&self) -> f64 {
        self.next
    }

    /// A pose arrived at `arrival` \[s\].
    pub fn on_pose(&mut self, arrival: f64) {
        if let Some(last) = self.last_pose {
            let interval = arrival - last;
            match self.pose_period {
                _ if interval <= 0.0 => {}
                Some(p) if (interval - p).abs() <= 0.25 * p => {
                    self.pose_period = Some(p + PERIOD_GAIN * (interval - p));
                    self.rejected = 0;
                    self.accepted = self.accepted.saturating_add(1);
                }
                Some(_) if self.rejected + 1 < PERIOD_RESTART => self.rejected += 1,
                _ => {
                    self.pose_period = Some(interval);
                    self.rejected = 0;
                    self.accepted = 0;
                }
            }
        }
        self.last_pose = Some(arrival);
        self.pending = Some(arrival);
    }

    /// Whether the pose stream's rate lets the grid lock to it (unknown
    /// yet: yes).
    pub fn lockable(&self) -> bool {
        if !self.lock {
            return false;
        }
        let Some(p) = self.pose_period else {
            return true;
        };
        let r = p / self.period;
        let n = r.round();
        (1.0..=5.0).contains(&n) && (r - n).abs() <= 0.05 * n
    }

    /// Whether a pose is expected in this tick's half-period window.
    fn expecting(&self) -> bool {
        let (Some(last), Some(p)) = (self.last_pose, self.pose_period) else {
            return false;
        };
        if !self.lockable() {
            return false;
        }
        let lo = self.next - self.period / 2.0;
        let m = ((lo - last) / p).ceil().max(1.0);
        let expected = last + m * p;
        expected > lo && expected <= self.next + self.period / 2.0
    }

    fn deadline(&self) -> f64 {
        if self.expecting() {
            self.next + self.wait
        } else {
            self.next
        }
    }

    /// The pending pose, if it may fire this tick (it arrived in this
    /// tick's half period, not late for the previous one).
    fn firing_pose(&self) -> Option<f64> {
        self.pending
            .filter(|a| self.lockable() && *a >= self.next - self.period / 2.0)
    }

    /// When the caller must call [`poll`](Self::poll) again at the latest
    /// \[s\] (events may come earlier: poll then too).
    pub fn wake_at(&self) -> f64 {
        match self.firing_pose() {
            Some(_) => self.next - self.early,
            None => self.deadline(),
        }
    }

    /// The caller is awake at `now` \[s\]: the tick to run now, or `None`
    /// (wait for events until [`wake_at`](Self::wake_at)).
    pub fn poll(&mut self, now: f64) -> Option<PlannedTick> {
        let opens = self.next - self.early;
        let expecting = self.expecting();
        let (cause, due) = match self.firing_pose() {
            Some(a) if now >= opens => (TickCause::Pose, a.max(opens)),
            _ if now >= self.deadline() => (TickCause::Deadline, self.deadline()),
            _ => return None,
        };
        let missed = if now - due >= self.period {
            ((now - due) / self.period).floor() as u64
        } else {
            0
        };
        let correction = match self.pending {
            Some(a) if self.lockable() && missed == 0 => {
                let e = a - self.next;
                let wrapped = e - self.period * (e / self.period).round();
                wrapped.clamp(-self.early, self.wait)
            }
            _ => 0.0,
        };
        let planned = PlannedTick {
            tick: self.tick + missed,
            missed,
            cause,
            due,
            lateness: (now - due).max(0.0),
            fallback: cause == TickCause::Deadline && expecting,
            fresh_pose: self.pending.is_some(),
        };
        match cause {
            TickCause::Pose => self.counts.by_pose += 1,
            TickCause::Deadline => self.counts.by_deadline += 1,
        }
        if planned.fallback {
            self.counts.fallbacks += 1;
        }
        self.counts.missed += missed;
        self.tick += missed + 1;
        self.next += self.period * (missed + 1) as f64 + correction;
        self.pending = None;
        Some(planned)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(x: u64) -> Duration {
        Duration::from_millis(x)
    }
    fn us(x: u64) -> Duration {
        Duration::from_micros(x)
    }

    #[test]
    fn on_time_wakes_run_every_tick_with_their_jitter() {
        let mut s = Schedule::new(ms(20));
        let wakes = [us(50), us(20_100), us(40_000), us(60_900)];
        let slots: Vec<_> = wakes.iter().map(|w| s.on_wake(*w).unwrap()).collect();
        assert_eq!(
            slots.iter().map(|t| t.tick).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        assert!(slots.iter().all(|t| t.missed == 0));
        assert_eq!(slots[1].jitter, us(100));
        assert_eq!(slots[3].jitter, us(900));
        assert_eq!(s.missed_total(), 0);
        assert_eq!(s.next_deadline(), ms(80));
    }

    #[test]
    fn early_wake_is_not_a_tick() {
        let mut s = Schedule::new(ms(20));
        assert!(s.on_wake(ms(0)).is_some());
        assert_eq!(s.on_wake(us(19_999)), None);
        assert_eq!(s.on_wake(ms(20)).unwrap().tick, 1);
    }

    #[test]
    fn a_stall_skips_and_counts_without_burst_or_drift() {
        let mut s = Schedule::new(ms(20));
        s.on_wake(ms(0)).unwrap();
        // Stalled until 95 ms: ticks 1, 2, 3 are missed, tick 4 runs late by 15 ms.
        let slot = s.on_wake(ms(95)).unwrap();
        assert_eq!(
            slot,
            TickSlot {
                tick: 4,
                missed: 3,
                jitter: ms(15)
            }
        );
        // Next deadline stays on the grid: 100 ms, not 95 + 20.
        assert_eq!(s.next_deadline(), ms(100));
        assert_eq!(s.on_wake(us(100_010)).unwrap().missed, 0);
        assert_eq!(s.missed_total(), 3);
    }

    #[test]
    fn late_by_less_than_a_period_is_jitter_not_a_miss() {
        let mut s = Schedule::new(ms(20));
        s.on_wake(ms(0)).unwrap();
        let slot = s.on_wake(us(39_999)).unwrap();
        assert_eq!((slot.tick, slot.missed), (1, 0));
        assert_eq!(slot.jitter, us(19_999));
        // Exactly on the next deadline: one missed.
        let slot = s.on_wake(ms(80)).unwrap();
        assert_eq!((slot.tick, slot.missed), (4, 2));
    }

    #[test]
    fn pure_over_a_sequence_of_wake_times() {
        // 50 Hz with a 1-second stall in the middle.
        let mut s = Schedule::new(ms(20));
        let mut ran = Vec::new();
        for k in 0..10u64 {
            ran.push(s.on_wake(ms(20 * k) + us(30)).unwrap().tick);
        }
        ran.push(s.on_wake(ms(1_200) + us(30)).unwrap().tick);
        for k in 61..64u64 {
            ran.push(s.on_wake(ms(20 * k) + us(30)).unwrap().tick);
        }
        assert_eq!(ran[9..], [9, 60, 61, 62, 63]);
        assert_eq!(s.missed_total(), 50);
    }
}

#[cfg(test)]
mod planner_tests {
    use super::*;

    const DT: f64 = 0.02;
    const WAIT: f64 = 0.003;

    /// Drives a planner over poses arriving at `poses` (sorted) until
    /// `until`; returns the ticks. The caller wakes at each pose arrival
    /// and at each `wake_at`.
    fn drive(p: &mut TickPlanner, poses: &[f64], until: f64) -> Vec<PlannedTick> {
        let mut out = Vec::new();
        let mut i = 0;
        loop {
            let wake = p.wake_at();
            let next_pose = poses.get(i).copied();
            let now = match next_pose {
                Some(a) if a <= wake => {
                    p.on_pose(a);
                    i += 1;
                    a
                }
                _ => wake,
            };
            if now > until {
                return out;
            }
            if let Some(t) = p.poll(now) {
                out.push(t);
            }
        }
    }

    fn stream(phase: f64, period: f64, n: usize) -> Vec<f64> {
        (0..n).map(|k| phase + k as f64 * period).collect()
    }

    #[test]
    fn a_50_hz_stream_at_any_phase_is_locked_within_a_few_ticks() {
        for phase in [0.0013, 0.007, 0.0119, 0.0185] {
            let mut p = TickPlanner::new(DT, WAIT, true, 0.0);
            let ticks = drive(&mut p, &stream(phase, DT, 200), 3.9);
            // After the first 5 ticks every tick runs on its pose's arrival.
            let late: Vec<_> = ticks[5..]
                .iter()
                .filter(|t| t.cause != TickCause::Pose || t.lateness > 1e-9)
                .collect();
            assert!(late.is_empty(), "phase {phase}: {late:?}");
            assert!(ticks.iter().all(|t| t.missed == 0));
            // One tick per pose (no extra, none skipped).
            assert!((ticks.len() as i64 - 195).abs() <= 1, "{}", ticks.len());
        }
    }

    #[test]
    fn a_lost_pose_fires_the_deadline_fallback_and_the_lock_holds() {
        let mut poses = stream(0.005, DT, 100);
        poses.remove(50);
        let mut p = TickPlanner::new(DT, WAIT, true, 0.0);
        let ticks = drive(&mut p, &poses, 1.99);
        let fallbacks: Vec<_> = ticks.iter().filter(|t| t.fallback).collect();
        assert_eq!(fallbacks.len(), 1, "{fallbacks:?}");
        // It ran `wait` after the lost pose's time, on no fresh pose.
        let f = fallbacks[0];
        assert!((f.due - (0.005 + 50.0 * DT + WAIT)).abs() < 1e-9, "{f:?}");
        assert!(!f.fresh_pose);
        // The next pose fires its tick on arrival again.
        let after = ticks.iter().find(|t| t.tick == f.tick + 1).unwrap();
        assert_eq!(after.cause, TickCause::Pose);
        assert!((after.due - (0.005 + 51.0 * DT)).abs() < 1e-9);
        // Tick spacing never collapses: no burst.
        for w in ticks.windows(2) {
            assert!(w[1].due - w[0].due >= DT - DT / 4.0 - WAIT - 1e-9);
        }
    }

    #[test]
    fn a_late_pose_is_waited_for_then_used_and_the_grid_barely_moves() {
        // Pose 40 is 2 ms late (within the wait), pose 60 is 8 ms late.
        let mut poses = stream(0.004, DT, 100);
        poses[40] += 0.002;
        poses[60] += 0.008;
        let mut p = TickPlanner::new(DT, WAIT, true, 0.0);
        let ticks = drive(&mut p, &poses, 1.99);
        let at = |a: f64| ticks.iter().find(|t| (t.due - a).abs() < 1e-9);
        let t40 = at(poses[40]).expect("pose 40 fired its tick");
        assert_eq!(t40.cause, TickCause::Pose);
        // Pose 60: the deadline fallback ran first, the next pose is on time.
        assert!(ticks.iter().any(|t| t.fallback));
        let t61 = at(poses[61]).expect("pose 61 fired its tick");
        assert_eq!(t61.cause, TickCause::Pose);
        assert_eq!(ticks.iter().filter(|t| t.fallback).count(), 1);
    }

    #[test]
    fn vision_at_25_and_10_hz_lands_on_ticks_and_the_loop_keeps_50_hz() {
        for (n, phase) in [(2usize, 0.013), (5, 0.031)] {
            let period = DT * n as f64;
            let poses = stream(phase, period, (4.0 / period) as usize);
            let mut p = TickPlanner::new(DT, WAIT, true, 0.0);
            let ticks = drive(&mut p, &poses, 3.9);
            assert!(
                (ticks.len() as i64 - 195).abs() <= 2,
                "n {n}: {}",
                ticks.len()
            );
            // After locking, every pose runs a tick on arrival.
            let fresh: Vec<_> = ticks[20..].iter().filter(|t| t.fresh_pose).collect();
            assert!(!fresh.is_empty());
            assert!(
                fresh
                    .iter()
                    .all(|t| t.cause == TickCause::Pose && t.lateness < 1e-9),
                "n {n}"
            );
            // Ticks without a pose are not fallbacks: none was expected.
            assert!(ticks[20..].iter().all(|t| !t.fallback), "n {n}");
        }
    }

    #[test]
    fn vision_at_30_hz_leaves_the_clock_alone() {
        let poses = stream(0.004, 1.0 / 30.0, 120);
        let mut p = TickPlanner::new(DT, WAIT, true, 0.0);
        let ticks = drive(&mut p, &poses, 3.9);
        // Once the period is known (the first two poses may nudge the
        // grid), the ticks run at their nominal times, δt apart.
        for w in ticks[10..].windows(2) {
            assert!((w[1].due - w[0].due - DT).abs() < 1e-9, "{w:?}");
            assert_eq!(w[1].cause, TickCause::Deadline);
        }
    }

    #[test]
    fn the_clock_mode_ignores_poses() {
        let mut p = TickPlanner::new(DT, WAIT, false, 0.0);
        let ticks = drive(&mut p, &stream(0.007, DT, 100), 1.99);
        assert_eq!(ticks.len(), 100);
        for (k, t) in ticks.iter().enumerate() {
            assert_eq!(t.cause, TickCause::Deadline);
            assert!((t.due - k as f64 * DT).abs() < 1e-9);
            assert!(!t.fallback);
        }
    }

    #[test]
    fn a_stall_skips_ticks_without_a_burst() {
        let mut p = TickPlanner::new(DT, WAIT, false, 0.0);
        assert_eq!(p.poll(0.0).unwrap().tick, 0);
        let t = p.poll(0.095).unwrap();
        assert_eq!((t.tick, t.missed), (4, 3));
        assert!((p.nominal() - 0.1).abs() < 1e-12);
        assert_eq!(p.poll(0.099), None);
        assert_eq!(p.counts().missed, 3);
    }
}

#[cfg(test)]
mod pose_timeout_tests {
    use super::*;

    /// Feeds `n` poses `period` apart from `from`; returns the next time.
    fn feed(p: &mut TickPlanner, from: f64, period: f64, n: usize) -> f64 {
        for k in 0..n {
            p.on_pose(from + k as f64 * period);
        }
        from + n as f64 * period
    }

    #[test]
    fn the_pose_period_settles_after_a_run_of_intervals_and_a_restart_unsettles_it() {
        let mut p = TickPlanner::new(0.02, 0.003, true, 0.0);
        assert_eq!(p.settled_pose_period(), None);
        // 15 Hz vision: the first interval sets the estimate, 16 more
        // settle it.
        let t = feed(&mut p, 0.0, 1.0 / 15.0, 17);
        assert_eq!(p.settled_pose_period(), None);
        let t = feed(&mut p, t, 1.0 / 15.0, 1);
        let settled = p.settled_pose_period().expect("settled");
        assert!((settled - 1.0 / 15.0).abs() < 1e-9, "{settled}");
        // A lost pose (a double interval) is an outlier: still settled.
        let t = feed(&mut p, t + 1.0 / 15.0, 1.0 / 15.0, 1);
        assert!(p.settled_pose_period().is_some());
        // The stream changes to 50 Hz: the estimate restarts after
        // PERIOD_RESTART outliers and is unsettled until 16 more.
        let t = feed(&mut p, t, 0.02, PERIOD_RESTART as usize + 1);
        assert_eq!(p.settled_pose_period(), None);
        assert!((p.pose_period().unwrap() - 0.02).abs() < 1e-9);
        feed(&mut p, t, 0.02, PERIOD_SETTLED as usize);
        assert!((p.settled_pose_period().unwrap() - 0.02).abs() < 1e-9);
    }

    #[test]
    fn a_timeout_under_two_intervals_is_too_tight() {
        // The default 100 ms: fine at 50 and 30 Hz, not at 15 Hz (one
        // lost pose leaves 133 ms between poses).
        assert!(!pose_timeout_too_tight(0.1, 0.02));
        assert!(!pose_timeout_too_tight(0.1, 1.0 / 30.0));
        assert!(pose_timeout_too_tight(0.1, 1.0 / 15.0));
        assert!(!pose_timeout_too_tight(0.3, 1.0 / 15.0));
        assert!(!pose_timeout_too_tight(0.1, 0.05));
        assert!(pose_timeout_too_tight(0.1, 0.0501));
    }
}
