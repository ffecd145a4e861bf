//! The control loop's safety guards, as pure parts:
//!
//! * [`CommandGuard`] — the one exit point every attitude command passes:
//!   no NaN / Inf leaves, tilt and thrust are saturated, violations counted.
//! * [`Fallback`] — what a failed or late tick can fall back on: the last
//!   good command (held) and level hover; the failsafe machine
//!   (`tick/failsafe.rs`) chooses between them and the controller's plan.
//! * [`is_pose_jump`] — a pose further from the previous one than the
//!   vehicle can fly in the time between them (or an estimator reset).
//! * [`ResidualMonitor`] — the model-consistency residual (measured minus
//!   predicted position) and its failsafe threshold.
//! * [`WatchdogCadence`] — when the control loop feeds systemd's watchdog.

use std::time::{Duration, Instant};

use dflat_control::{TiltLimit, limit_tilt};
use dflat_link::AttitudeCommand;
use serde::Serialize;

/// Counters of the exit guard (in the summary).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct GuardCounts {
    /// Commands refused for a NaN / infinite field (replaced by the fallback).
    pub non_finite: u64,
    /// Commands whose tilt was saturated.
    pub tilt_saturated: u64,
    /// Commands whose thrust was clamped into [0, 1].
    pub thrust_saturated: u64,
    /// Ticks the controller failed (error or panic).
    pub controller_failures: u64,
    /// Ticks whose solve overran the tick period.
    pub deadline_overruns: u64,
    /// Ticks that sent the controller's previous plan, shifted.
    pub plan_steps: u64,
    /// Ticks that sent the held previous command.
    pub held: u64,
    /// Ticks that sent level hover.
    pub level_hover: u64,
    /// Pose jumps (re-anchored).
    pub pose_jumps: u64,
    /// Residual failsafes.
    pub residual_failsafes: u64,
    /// Times the stream was stopped after `safety.level_hover_max_ms` of
    /// level hover (the controller could not fly).
    pub control_failsafes: u64,
    /// Times a pose source's clock was found running slow or ever later
    /// (`safety.pose_max_latency_ms`) and its poses re-stamped with their
    /// arrival time.
    pub pose_clock_faults: u64,
    /// Times the vehicle was braked for flying faster than
    /// `safety.max_speed_mps` (the envelope).
    pub overspeed_brakes: u64,
}

/// Why [`CommandGuard::check`] refused a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("command not finite")]
pub struct NonFinite;

/// The exit point's limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandGuard {
    /// Largest tilt \[rad\] (0 < max_tilt < π/2).
    pub max_tilt: f64,
}

impl CommandGuard {
    /// Checks and saturates `cmd` (normalised thrust): `Err` if any field is
    /// NaN / infinite; otherwise roll and pitch scaled together so that the
    /// tilt is at most `max_tilt` ([`limit_tilt`], direction kept — the
    /// daemon's controllers apply the same bound, so this changes nothing
    /// they send unless `vehicle.max_tilt_deg` and theirs differ), yaw
    /// wrapped to (−π, π], thrust clamped into [0, 1]. Counts what it
    /// changed.
    pub fn check(
        &self,
        cmd: AttitudeCommand,
        counts: &mut GuardCounts,
    ) -> Result<AttitudeCommand, NonFinite> {
        let AttitudeCommand {
            roll,
            pitch,
            yaw,
            thrust,
        } = cmd;
        if ![roll, pitch, yaw, thrust].iter().all(|v| v.is_finite()) {
            counts.non_finite += 1;
            return Err(NonFinite);
        }
        let (pitch, roll, limited) = limit_tilt(pitch, roll, self.max_tilt, TiltLimit::Cone);
        if limited {
            counts.tilt_saturated += 1;
        }
        let thrust_c = thrust.clamp(0.0, 1.0);
        if thrust_c != thrust {
            counts.thrust_saturated += 1;
        }
        let yaw = wrap_pi(yaw);
        Ok(AttitudeCommand {
            roll,
            pitch,
            yaw,
            thrust: thrust_c,
        })
    }
}

/// `a` wrapped into (−π, π].
pub fn wrap_pi(a: f64) -> f64 {
    use std::f64::consts::PI;
    let w = a.rem_euclid(2.0 * PI);
    if w > PI { w - 2.0 * PI } else { w }
}

/// The commands a failed or late tick falls back on: the last good
/// command (to hold) and level hover at the yaw of the last command sent.
/// Which one is sent is the failsafe machine's choice
/// (`tick/failsafe.rs`); this only remembers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fallback {
    /// Ticks the last good command may be held.
    pub hold_ticks: u32,
    /// Normalised hover thrust for level hover.
    pub hover_thrust: f64,
    /// Yaw for level hover without any good command yet \[rad\].
    pub default_yaw: f64,
    last_good: Option<AttitudeCommand>,
    /// Yaw of the last command sent by the controller or its plan \[rad\].
    last_yaw: Option<f64>,
}

impl Fallback {
    /// A fallback with no good command yet.
    pub fn new(hold_ticks: u32, hover_thrust: f64, default_yaw: f64) -> Self {
        Self {
            hold_ticks,
            hover_thrust,
            default_yaw,
            last_good: None,
            last_yaw: None,
        }
    }

    /// A good command was sent.
    pub fn good(&mut self, cmd: AttitudeCommand) {
        self.last_good = Some(cmd);
        self.last_yaw = Some(cmd.yaw);
    }

    /// A step of the controller's previous plan was sent: the (older) last
    /// good command is not held after it.
    pub fn planned(&mut self, cmd: AttitudeCommand) {
        self.last_good = None;
        self.last_yaw = Some(cmd.yaw);
    }

    /// Forgets the last good command (failsafe, re-anchor).
    pub fn forget(&mut self) {
        self.last_good = None;
        self.last_yaw = None;
    }

    /// The last good command, if one may be held.
    pub fn held(&self) -> Option<AttitudeCommand> {
        self.last_good
    }

    /// Level attitude at hover thrust, yaw of the last command sent (else
    /// the default yaw): the level-hover fallback, and what a failsafe
    /// leaves in the autopilot.
    pub fn level_command(&self) -> AttitudeCommand {
        AttitudeCommand {
            roll: 0.0,
            pitch: 0.0,
            yaw: self.last_yaw.unwrap_or(self.default_yaw),
            thrust: self.hover_thrust.clamp(0.0, 1.0),
        }
    }
}

/// The test both pose-jump rules share: a reset counter that changed, or
/// `new` further than `margin + reach(dt)` \[m\] from `prev` moved on by
/// `velocity` \[m/s\] for `dt` \[s\] (at least `min_dt`; a NaN distance
/// departs too).
fn departs(
    (prev, velocity, new): ([f64; 3], [f64; 3], [f64; 3]),
    dt: f64,
    min_dt: f64,
    margin: f64,
    reset_counters: (Option<u8>, Option<u8>),
    reach: impl Fn(f64) -> f64,
) -> bool {
    if let (Some(a), Some(b)) = reset_counters
        && a != b
    {
        return true;
    }
    let dt = if dt.is_finite() {
        dt.max(min_dt)
    } else {
        min_dt
    };
    let predicted = [
        prev[0] + velocity[0] * dt,
        prev[1] + velocity[1] * dt,
        prev[2] + velocity[2] * dt,
    ];
    let d = distance(predicted, new);
    d.is_nan() || d > margin + reach(dt)
}

/// True when `new` departs from where the previous pose `prev` and the
/// vehicle's measured `velocity` \[m/s\] put it after `dt` \[s\] (at least
/// `min_dt`) by more than `margin` \[m\] (noise) plus what
/// `max_acceleration` \[m/s²\] can change in between (½·a·dt²), or when the
/// estimator's reset counter changed. A fast vehicle is not a jump: its
/// poses follow its motion, whatever its speed.
#[allow(clippy::too_many_arguments)]
pub fn departs_from_motion(
    prev: [f64; 3],
    velocity: [f64; 3],
    new: [f64; 3],
    dt: f64,
    min_dt: f64,
    max_acceleration: f64,
    margin: f64,
    reset_counters: (Option<u8>, Option<u8>),
) -> bool {
    departs(
        (prev, velocity, new),
        dt,
        min_dt,
        margin,
        reset_counters,
        |dt| 0.5 * max_acceleration * dt * dt,
    )
}

/// True when `new` is further from `prev` than the vehicle can fly at
/// `max_speed` \[m/s\] in `dt` \[s\] (at least `min_dt`) plus `margin` \[m\]
/// (noise), or when the estimator's reset counter changed (the rule before
/// a velocity is known).
pub fn is_pose_jump(
    prev: [f64; 3],
    new: [f64; 3],
    dt: f64,
    max_speed: f64,
    min_dt: f64,
    margin: f64,
    reset_counters: (Option<u8>, Option<u8>),
) -> bool {
    departs(
        (prev, [0.0; 3], new),
        dt,
        min_dt,
        margin,
        reset_counters,
        |dt| max_speed * dt,
    )
}

/// Euclidean distance \[m\].
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Consecutive ticks above the threshold that trigger the residual failsafe.
pub const RESIDUAL_TICKS: u32 = 5;

/// The model-consistency residual: the measured position minus the position
/// the controller predicted for this tick at the previous one (its plan's
/// y*_{k+1}).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ResidualMonitor {
    /// Failsafe threshold \[m\] (0 = off).
    pub threshold: f64,
    predicted: Option<[f64; 3]>,
    above: u32,
}

impl ResidualMonitor {
    /// A monitor with this threshold (0 = never fails safe).
    pub fn new(threshold: f64) -> Self {
        Self {
            threshold,
            predicted: None,
            above: 0,
        }
    }

    /// The prediction for the next tick (the plan's y*_{k+1}).
    pub fn predict(&mut self, next: [f64; 3]) {
        self.predicted = Some(next);
    }

    /// Forgets the prediction (reset, re-anchor, failsafe).
    pub fn forget(&mut self) {
        self.predicted = None;
        self.above = 0;
    }

    /// The residual at this tick \[m\] (`None` without a prediction), and
    /// whether it stayed above the threshold for [`RESIDUAL_TICKS`] ticks.
    /// Consumes the prediction.
    pub fn measure(&mut self, measured: [f64; 3]) -> (Option<f64>, bool) {
        let Some(p) = self.predicted.take() else {
            return (None, false);
        };
        let r = distance(measured, p);
        if self.threshold > 0.0 && (r.is_nan() || r > self.threshold) {
            self.above += 1;
        } else {
            self.above = 0;
        }
        let trip = self.above >= RESIDUAL_TICKS;
        if trip {
            self.above = 0;
        }
        (Some(r), trip)
    }
}

/// When the control loop sends `WATCHDOG=1`: every `interval`, which is a
/// quarter of systemd's `WatchdogSec` (≥ 2× the rate systemd asks for).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WatchdogCadence {
    interval: Duration,
    last: Option<Instant>,
}

impl WatchdogCadence {
    /// From systemd's watchdog timeout (`None`: not enabled → never due).
    pub fn new(timeout: Option<Duration>) -> Option<Self> {
        timeout.map(|t| Self {
            interval: (t / 4).max(Duration::from_millis(1)),
            last: None,
        })
    }

    /// The notification interval.
    pub fn interval(&self) -> Duration {
        self.interval
    }

    /// True (and remembers `now`) when a notification is due at `now`.
    pub fn due(&mut self, now: Instant) -> bool {
        let due = self
            .last
            .is_none_or(|l| now.saturating_duration_since(l) >= self.interval);
        if due {
            self.last = Some(now);
        }
        due
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmd(roll: f64, pitch: f64, yaw: f64, thrust: f64) -> AttitudeCommand {
        AttitudeCommand {
            roll,
            pitch,
            yaw,
            thrust,
        }
    }

    #[test]
    fn guard_refuses_non_finite_and_saturates() {
        let g = CommandGuard {
            max_tilt: 20f64.to_radians(),
        };
        let mut n = GuardCounts::default();
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(g.check(cmd(bad, 0.0, 0.0, 0.5), &mut n).is_err());
            assert!(g.check(cmd(0.0, 0.0, 0.0, bad), &mut n).is_err());
            assert!(g.check(cmd(0.0, 0.0, bad, 0.5), &mut n).is_err());
        }
        assert_eq!(n.non_finite, 9);
        let ok = g.check(cmd(0.1, -0.1, 0.3, 0.5), &mut n).unwrap();
        assert_eq!(ok, cmd(0.1, -0.1, 0.3, 0.5));
        let mut worst: f64 = 0.0;
        for i in 0..200 {
            let a = i as f64 * 0.1;
            let (r, p) = (1.4 * a.sin(), 1.5 * (1.7 * a).cos());
            let c = g.check(cmd(r, p, 7.0, 1.5 - a * 0.01), &mut n).unwrap();
            worst = worst.max(dflat_control::tilt::tilt(c.pitch, c.roll));
            assert!((0.0..=1.0).contains(&c.thrust));
            assert!(c.yaw.abs() <= std::f64::consts::PI);
        }
        assert!(worst <= 20f64.to_radians() + 1e-12, "{worst}");
        assert!(n.tilt_saturated > 100 && n.thrust_saturated > 0);
        // Whole turns have cos = 1 ("level" by the tilt formula): still cut.
        for a in [
            std::f64::consts::PI,
            2.0 * std::f64::consts::PI,
            5.0 * std::f64::consts::PI,
        ] {
            let c = g.check(cmd(a, -a, 0.0, 0.5), &mut n).unwrap();
            let max = 20f64.to_radians();
            assert!(c.roll.abs() <= max && c.pitch.abs() <= max, "{c:?}");
        }
    }

    #[test]
    fn fallback_remembers_the_last_good_command_and_the_yaw_flown() {
        let mut f = Fallback::new(3, 1.45, 0.2);
        assert_eq!(f.held(), None);
        // Level hover: default yaw, thrust clamped into [0, 1].
        assert_eq!(f.level_command(), cmd(0.0, 0.0, 0.2, 1.0));
        f.hover_thrust = 0.45;
        f.good(cmd(0.1, 0.05, 1.0, 0.6));
        assert_eq!(f.held(), Some(cmd(0.1, 0.05, 1.0, 0.6)));
        assert_eq!(f.level_command(), cmd(0.0, 0.0, 1.0, 0.45));
        // A plan step: nothing older is held after it; level at its yaw.
        f.planned(cmd(0.1, 0.0, 1.1, 0.6));
        assert_eq!(f.held(), None);
        assert_eq!(f.level_command(), cmd(0.0, 0.0, 1.1, 0.45));
        f.good(cmd(0.2, 0.0, 1.0, 0.6));
        f.forget();
        assert_eq!(f.held(), None);
        assert_eq!(f.level_command(), cmd(0.0, 0.0, 0.2, 0.45));
    }

    /// A vehicle at 41 m/s (the coasting vehicle, 0.8 m per tick)
    /// is not a jump when its poses follow its motion; a 5 m jump is one
    /// whatever the speed; at 15 Hz vision, 22.5 m/s is not a jump either.
    #[test]
    fn a_fast_vehicle_is_not_a_pose_jump() {
        let p = [0.0, 0.0, -10.0];
        let a = 6.87; // g·tan(35°)
        let fast = [41.0, 0.0, 0.0];
        let next = [0.82, 0.0, -10.0];
        assert!(!departs_from_motion(
            p,
            fast,
            next,
            0.02,
            0.02,
            a,
            0.5,
            (None, None)
        ));
        assert!(is_pose_jump(p, next, 0.02, 15.0, 0.02, 0.5, (None, None)));
        let jumped = [5.82, 0.0, -10.0];
        assert!(departs_from_motion(
            p,
            fast,
            jumped,
            0.02,
            0.02,
            a,
            0.5,
            (None, None)
        ));
        let vision = [22.5 / 15.0, 0.0, -10.0];
        assert!(!departs_from_motion(
            p,
            [22.5, 0.0, 0.0],
            vision,
            1.0 / 15.0,
            0.02,
            a,
            0.5,
            (None, None)
        ));
        // Braking at the tilt limit for 1 s without pose: inside.
        let braked = [41.0 - 0.5 * a, 0.0, -10.0];
        assert!(!departs_from_motion(
            p,
            fast,
            braked,
            1.0,
            0.02,
            a,
            0.5,
            (None, None)
        ));
        // NaN and a reset counter change are jumps.
        assert!(departs_from_motion(
            p,
            fast,
            [f64::NAN; 3],
            0.02,
            0.02,
            a,
            0.5,
            (None, None)
        ));
        assert!(departs_from_motion(
            p,
            [0.0; 3],
            p,
            0.02,
            0.02,
            a,
            0.5,
            (Some(1), Some(2))
        ));
    }

    #[test]
    fn pose_jumps() {
        let p = [0.0, 0.0, -10.0];
        // At 15 m/s, a 20 ms tick and a 0.5 m margin, reset counters `c`.
        let jump = |to: [f64; 3], dt: f64, c: (Option<u8>, Option<u8>)| {
            is_pose_jump(p, to, dt, 15.0, 0.02, 0.5, c)
        };
        // 15 m/s for 20 ms + 0.5 m margin = 0.8 m.
        assert!(!jump([0.7, 0.0, -10.0], 0.02, (None, None)));
        assert!(jump([5.0, 0.0, -10.0], 0.02, (None, None)));
        // After 1 s without pose 5 m is possible.
        assert!(!jump([5.0, 0.0, -10.0], 1.0, (None, None)));
        // dt below the tick (or not finite) counts as one tick.
        assert!(jump([0.9, 0.0, -10.0], 0.0, (None, None)));
        assert!(jump([0.9, 0.0, -10.0], f64::NAN, (None, None)));
        // An estimator reset is a jump wherever the pose is.
        assert!(jump(p, 0.02, (Some(1), Some(2))));
        assert!(!jump(p, 0.02, (Some(2), Some(2))));
    }

    #[test]
    fn residual_trips_after_consecutive_ticks() {
        let mut m = ResidualMonitor::new(1.0);
        assert_eq!(m.measure([0.0; 3]), (None, false));
        for i in 0..RESIDUAL_TICKS {
            m.predict([0.0; 3]);
            let (r, trip) = m.measure([2.0, 0.0, 0.0]);
            assert_eq!(r, Some(2.0));
            assert_eq!(trip, i + 1 == RESIDUAL_TICKS);
        }
        m.predict([0.0; 3]);
        assert!(!m.measure([f64::NAN, 0.0, 0.0]).1);
        let mut off = ResidualMonitor::new(0.0);
        for _ in 0..20 {
            off.predict([0.0; 3]);
            assert!(!off.measure([100.0, 0.0, 0.0]).1);
        }
    }

    #[test]
    fn watchdog_cadence_is_a_quarter_of_the_timeout() {
        assert!(WatchdogCadence::new(None).is_none());
        let mut w = WatchdogCadence::new(Some(Duration::from_secs(2))).unwrap();
        assert_eq!(w.interval(), Duration::from_millis(500));
        let t0 = Instant::now();
        assert!(w.due(t0));
        assert!(!w.due(t0 + Duration::from_millis(20)));
        assert!(!w.due(t0 + Duration::from_millis(499)));
        assert!(w.due(t0 + Duration::from_millis(500)));
        assert!(!w.due(t0 + Duration::from_millis(600)));
        assert!(w.due(t0 + Duration::from_millis(1000)));
    }
}
