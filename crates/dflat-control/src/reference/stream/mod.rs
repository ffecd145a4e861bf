//! Streamed trajectories: a planner's samples (time, position, optional
//! velocity, acceleration, yaw, yaw rate) → the reference over the horizon:
//! the trajectory the samples give up to the newest, predicted beyond it.
//!
//! # The trajectory sent ahead
//!
//! The samples are the knots of the trajectory the planner has committed
//! to. A sample may lie ahead of the controller's time (up to
//! `max_ahead_s`): a planner that sends the next seconds of its trajectory
//! as samples stamped in the future gives the reference its true future.
//! Between knots the reference is the Hermite interpolant of what they give
//! (`knots`: quintic with p/v/a, cubic with p/v, and for positions alone
//! the velocity of the quadratic through each knot and its neighbours),
//! continuous in position and velocity (and acceleration with p/v/a);
//! after the newest knot, the prediction below takes over. A sample
//! **replaces every knot at or after its time**: a planner that replans
//! sends its new trajectory from its present on, and the old future is
//! dropped — so a batch re-sent each cycle is continuous across updates
//! when the plans agree. A sample that would rewrite the past (older than
//! both the newest knot and the controller's time) is refused. Past knots
//! are kept for [`KEEP_PAST_S`] (at least the three newest), at most
//! [`MAX_KNOTS`] in all, allocated once.
//!
//! # The prediction
//!
//! From a sample at time `t_s` with position `p`, velocity `v` and
//! acceleration `a` (NED), the reference at controller time `t` is
//! `P(σ(t − t_s))`:
//!
//! * `P(σ)` is a **coordinated turn** in the horizontal plane: the
//!   horizontal speed `|v_h|` changes at the tangential acceleration
//!   `a_t = v_h·a_h/|v_h|` while the heading turns at
//!   `ω = (v_x a_y − v_y a_x)/|v_h|²` (closed form), so a circle flown at
//!   constant speed is predicted exactly; slower than
//!   [`TURN_MIN_SPEED`] the horizontal part is constant acceleration,
//!   `p + vσ + aσ²/2`. Vertically it is constant acceleration.
//! * `σ(τ)` is the **decay**: `σ = τ` for the first `extrapolation_s`
//!   after the sample; then the prediction's clock slows as
//!   `dσ/dτ = (1 + cos(π x/decay_s))/2`, `x = τ − extrapolation_s`, and
//!   stops after `decay_s` at `σ = extrapolation_s + decay_s/2`. So the
//!   reference velocity `P'(σ)·σ'` falls smoothly to zero (no step in
//!   velocity or acceleration) and the horizon's tail holds where the
//!   extrapolation stops. The stop's peak deceleration is `π·|v|/(2·decay_s)`
//!   at the speed |v| the extrapolation has when it starts to slow; the
//!   decay is lengthened so that this stays within `stop_acceleration`
//!   (`decay_s = max(decay_s, π·|v|/(2·stop_acceleration))`): DF-MPC flies
//!   a stream as it is (its jerk fed forward), so the stop must be gentle
//!   itself. A stream whose samples stop thus becomes a
//!   smooth stop and hold by itself.
//!
//! Each new sample replaces the prediction. Without a velocity the sample
//! is a point: `v = a = 0` (the reference holds it), unless
//! `implied_velocity` is on and the two previous samples are recent
//! (spacing in [`IMPLIED_MIN_GAP`, `implied_max_gap_s`]): then `v` and
//! `a` are the second-order backward differences of the last three
//! samples, `v = (3p_k − 4p_{k−1} + p_{k−2})/(2h)`, `a = (p_k − 2p_{k−1} +
//! p_{k−2})/h²` (for unequal spacing, the derivatives of the quadratic
//! through them). Without an acceleration, `a = 0`.
//!
//! # The jerk
//!
//! With three recent p/v/a knots (spacing within the implied gap's
//! bounds) the stream's own jerk `j` is the derivative of the quadratic
//! through their accelerations (second order). The prediction then lets
//! the speed and the turn rate change at the rates `j` gives them,
//! `ȧ_t = (v_h·j_h + |a_h|² − a_t²)/|v_h|` and
//! `ω̇ = (v_x j_y − v_y j_x)/|v_h|² − 2ω a_t/|v_h|`, for
//! `jerk_horizon_s`, then goes on as a turn at the speed rate and
//! curvature reached (integrated on a 256-node table, Simpson). The jerk
//! is known over about the attitude lag; carried further it runs away (a
//! figure eight's turn rate reverses within a second), so the default is
//! 0.25 s (docs/controllers.md, "Preview").

use dflat_model::attitude::wrap_angle_difference;
use nalgebra::Vector3;

mod knots;
mod prediction;

use super::{invalid, is_finite3};
use crate::ControlError;
use prediction::{JerkTable, Prediction};

/// Slower than this [m/s] the horizontal prediction is constant
/// acceleration instead of a coordinated turn.
pub const TURN_MIN_SPEED: f64 = 0.3;
/// Samples closer in time than this \[s\] do not imply a velocity.
pub const IMPLIED_MIN_GAP: f64 = 0.005;

/// One sample of a streamed trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSample {
    /// Time of the sample on the controller's clock \[s\].
    pub t: f64,
    /// Position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Velocity, local NED [m/s], if the sender gave one.
    pub velocity: Option<Vector3<f64>>,
    /// Acceleration, local NED [m/s²], if the sender gave one.
    pub acceleration: Option<Vector3<f64>>,
    /// Heading \[rad\], NED, if the sender gave one (carried for yaw).
    pub yaw: Option<f64>,
    /// Heading rate \[rad/s\], if the sender gave one (carried for yaw).
    pub yaw_rate: Option<f64>,
}

/// How a stream is extrapolated (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StreamSettings {
    /// Time after a sample the prediction runs at full rate \[s\] (≥ 0).
    pub extrapolation_s: f64,
    /// Time over which the prediction then slows to a stop \[s\] (> 0).
    pub decay_s: f64,
    /// Position-only samples imply a velocity and an acceleration from the
    /// two before them.
    pub implied_velocity: bool,
    /// Largest sample spacing \[s\] that implies a velocity (> 0).
    pub implied_max_gap_s: f64,
    /// Largest deceleration of the decay's stop [m/s²] (> 0): the decay
    /// is lengthened for a fast stream (module docs).
    pub stop_acceleration: f64,
    /// How long \[s\] the stream's own jerk (the change of acceleration
    /// between consecutive samples) is extrapolated (≥ 0; 0 = the
    /// coordinated turn at constant curvature alone). See the module docs,
    /// "The jerk".
    pub jerk_horizon_s: f64,
    /// How far ahead of the controller's time \[s\] a sample may lie (> 0):
    /// the trajectory sent ahead (module docs).
    pub max_ahead_s: f64,
}

impl Default for StreamSettings {
    /// 1.0 s at full rate, 1.0 s decay (longer for a stop above 2 m/s²),
    /// no implied velocity (0.25 s gap).
    fn default() -> Self {
        Self {
            extrapolation_s: 1.0,
            decay_s: 1.0,
            implied_velocity: false,
            implied_max_gap_s: 0.25,
            stop_acceleration: 2.0,
            jerk_horizon_s: 0.25,
            max_ahead_s: 10.0,
        }
    }
}

impl StreamSettings {
    /// Checks the ranges, naming the field.
    pub fn validate(&self) -> Result<(), ControlError> {
        if !(self.extrapolation_s.is_finite() && self.extrapolation_s >= 0.0) {
            return Err(invalid("extrapolation_s", "must be finite and ≥ 0 s"));
        }
        if !(self.decay_s.is_finite() && self.decay_s > 0.0) {
            return Err(invalid("decay_s", "must be finite and > 0 s"));
        }
        if !(self.implied_max_gap_s.is_finite() && self.implied_max_gap_s > 0.0) {
            return Err(invalid("implied_max_gap_s", "must be finite and > 0 s"));
        }
        if !(self.stop_acceleration.is_finite() && self.stop_acceleration > 0.0) {
            return Err(invalid("stop_acceleration", "must be finite and > 0 m/s²"));
        }
        if !(self.jerk_horizon_s.is_finite() && self.jerk_horizon_s >= 0.0) {
            return Err(invalid("jerk_horizon_s", "must be finite and ≥ 0 s"));
        }
        if !(self.max_ahead_s.is_finite() && self.max_ahead_s > 0.0) {
            return Err(invalid("max_ahead_s", "must be finite and > 0 s"));
        }
        Ok(())
    }
}

/// Samples a stream keeps at most (the past it needs and the future sent
/// ahead: 20 s at 50 Hz); allocated once.
pub const MAX_KNOTS: usize = 1024;
/// Past samples are kept this long \[s\] behind the controller's time (at
/// least the three newest are kept: the jerk and the implied velocity).
const KEEP_PAST_S: f64 = 1.0;

/// A streamed trajectory: the samples it has (the knots: the recent past
/// and any future sent ahead) and the prediction from the newest.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Stream {
    settings: StreamSettings,
    /// The samples, in time order (capacity [`MAX_KNOTS`]).
    knots: Vec<StreamSample>,
    /// The prediction from the newest knot.
    pred: Prediction,
    /// This prediction's decay time \[s\] (≥ `decay_s`; module docs).
    decay: f64,
    /// Controller time now \[s\] (set by `set_time`, else advanced by δt).
    now: f64,
    driven: bool,
}

fn check_sample(s: &StreamSample) -> Result<(), ControlError> {
    let ok = s.t.is_finite()
        && is_finite3(&s.position)
        && s.velocity.is_none_or(|v| is_finite3(&v))
        && s.acceleration.is_none_or(|a| is_finite3(&a))
        && s.yaw.is_none_or(f64::is_finite)
        && s.yaw_rate.is_none_or(f64::is_finite);
    if ok {
        Ok(())
    } else {
        Err(invalid("stream sample", "all given fields must be finite"))
    }
}

impl Stream {
    pub(super) fn new(
        settings: StreamSettings,
        sample: &StreamSample,
    ) -> Result<Self, ControlError> {
        settings.validate()?;
        check_sample(sample)?;
        let mut s = Self {
            settings,
            knots: Vec::with_capacity(MAX_KNOTS),
            pred: Prediction {
                t: sample.t,
                p: sample.position,
                v: Vector3::zeros(),
                a: Vector3::zeros(),
                jerk: None,
            },
            decay: settings.decay_s,
            now: sample.t,
            driven: false,
        };
        s.push(sample)?;
        Ok(s)
    }

    /// Adds a sample (module docs, "The trajectory sent ahead"): it
    /// replaces every sample at or after its time, and the prediction
    /// restarts from the newest. A sample older than both the newest and
    /// the controller's time (it would rewrite the past), or more than
    /// `max_ahead_s` ahead, is refused and changes nothing.
    pub(super) fn push(&mut self, sample: &StreamSample) -> Result<(), ControlError> {
        check_sample(sample)?;
        let newest = self.knots.last().map_or(f64::NEG_INFINITY, |k| k.t);
        if sample.t < newest && sample.t < self.now {
            return Err(invalid("stream sample", "older than the newest sample"));
        }
        if sample.t > self.now + self.settings.max_ahead_s {
            return Err(invalid("stream sample", "further ahead than max_ahead_s"));
        }
        let keep = self.knots.partition_point(|k| k.t < sample.t);
        self.knots.truncate(keep);
        self.prune();
        if self.knots.len() == MAX_KNOTS {
            return Err(invalid(
                "stream sample",
                "more samples ahead than a stream keeps",
            ));
        }
        self.knots.push(*sample);
        self.predict();
        Ok(())
    }

    /// Drops past knots older than [`KEEP_PAST_S`] (keeping the three
    /// newest).
    fn prune(&mut self) {
        let old = self.knots.partition_point(|k| k.t < self.now - KEEP_PAST_S);
        let drop = old.min(self.knots.len().saturating_sub(3));
        if drop > 0 {
            self.knots.drain(..drop);
        }
    }

    /// The prediction from the newest knot (module docs, "The prediction").
    fn predict(&mut self) {
        let n = self.knots.len();
        let sample = self.knots[n - 1];
        let (v, a, jerk) = self.motion();
        self.pred = Prediction {
            t: sample.t,
            p: sample.position,
            v,
            a,
            jerk: None,
        };
        let speed = self.pred.at(self.settings.extrapolation_s).1.norm();
        self.decay = self
            .settings
            .decay_s
            .max(std::f64::consts::FRAC_PI_2 * speed / self.settings.stop_acceleration);
        // A sample at rest ends the trajectory: it holds, whatever the
        // jerk that brought it there.
        let at_rest = v.norm() < 1e-9 && a.norm() < 1e-9;
        if let Some(j) = jerk
            && !at_rest
            && self.settings.jerk_horizon_s > 0.0
            && j.iter().all(|c| c.is_finite())
        {
            let sigma_max = self.settings.extrapolation_s + 0.5 * self.decay;
            self.pred.jerk = Some(JerkTable::new(
                sample.position,
                v,
                a,
                j,
                self.settings.jerk_horizon_s,
                sigma_max,
            ));
        }
    }

    /// Velocity, acceleration and jerk at the newest knot (module docs,
    /// "The prediction" and "The jerk"): what the sample gives, the rest
    /// from the polynomial through the newest knots that give the highest
    /// field it has (spacing within the implied gap's bounds): with p/v/a
    /// the jerk from three accelerations; with p/v the acceleration and
    /// jerk from three velocities (two: the acceleration alone); with
    /// positions alone and `implied_velocity`, velocity, acceleration and
    /// jerk from four positions (three: no jerk). Position alone without
    /// `implied_velocity`: a point, `v = a = 0`.
    fn motion(&self) -> (Vector3<f64>, Vector3<f64>, Option<Vector3<f64>>) {
        let s = self.knots[self.knots.len() - 1];
        let zero = Vector3::zeros();
        match (s.velocity, s.acceleration) {
            (Some(v), Some(a)) => {
                let d = self.derivatives(3, |k| k.acceleration);
                (v, a, d.map(|d| d[1]))
            }
            (Some(v), None) => match self.derivatives(3, |k| k.velocity) {
                Some(d) => (v, d[1], Some(d[2])),
                None => match self.derivatives(2, |k| k.velocity) {
                    Some(d) => (v, d[1], None),
                    None => (v, zero, None),
                },
            },
            (None, a) if self.settings.implied_velocity => {
                let p = |k: &StreamSample| Some(k.position);
                match self.derivatives(4, p) {
                    Some(d) => (d[1], d[2], Some(d[3])),
                    None => match self.derivatives(3, p) {
                        Some(d) => (d[1], d[2], None),
                        None => (zero, a.unwrap_or(zero), None),
                    },
                }
            }
            (None, a) => (zero, a.unwrap_or(zero), None),
        }
    }

    /// The value and first three derivatives at the newest knot's time of
    /// the polynomial through the `m` newest knots' `field` (Newton's
    /// divided differences); `None` unless each of them gives it and they
    /// are spaced within the implied gap's bounds.
    fn derivatives(
        &self,
        m: usize,
        field: impl Fn(&StreamSample) -> Option<Vector3<f64>>,
    ) -> Option<[Vector3<f64>; 4]> {
        let n = self.knots.len();
        if n < m || m == 0 {
            return None;
        }
        let knots = &self.knots[n - m..];
        let (lo, hi) = (IMPLIED_MIN_GAP, self.settings.implied_max_gap_s);
        if knots
            .windows(2)
            .any(|w| !(w[1].t - w[0].t >= lo && w[1].t - w[0].t <= hi))
        {
            return None;
        }
        let t: [f64; 4] = std::array::from_fn(|i| knots.get(i).map_or(0.0, |k| k.t));
        let mut c = [Vector3::zeros(); 4];
        for (ci, k) in c.iter_mut().zip(knots) {
            *ci = field(k)?;
        }
        // Divided differences in place: c[i] = f[t_0 … t_i].
        for order in 1..m {
            for i in (order..m).rev() {
                c[i] = (c[i] - c[i - 1]) / (t[i] - t[i - order]);
            }
        }
        // Horner on the Newton form, with the derivatives, at the newest.
        let x = t[m - 1];
        let mut d = [
            c[m - 1],
            Vector3::zeros(),
            Vector3::zeros(),
            Vector3::zeros(),
        ];
        for k in (0..m - 1).rev() {
            let h = x - t[k];
            d[3] = d[3] * h + d[2] * 3.0;
            d[2] = d[2] * h + d[1] * 2.0;
            d[1] = d[1] * h + d[0];
            d[0] = d[0] * h + c[k];
        }
        Some(d)
    }

    /// Sets the controller time now \[s\].
    pub(super) fn set_time(&mut self, t: f64) {
        if t.is_finite() {
            self.now = t;
            self.driven = true;
        }
    }

    /// The decay's clock `σ` for time `tau` \[s\] after the newest knot, and
    /// its rate `dσ/dτ`.
    fn sigma(&self, tau: f64) -> (f64, f64) {
        let (tc, td) = (self.settings.extrapolation_s, self.decay);
        let tau = tau.max(0.0);
        if tau <= tc {
            return (tau, 1.0);
        }
        let x = tau - tc;
        if x >= td {
            return (tc + 0.5 * td, 0.0);
        }
        let k = std::f64::consts::PI / td;
        (
            tc + 0.5 * x + 0.5 * (k * x).sin() / k,
            0.5 * (1.0 + (k * x).cos()),
        )
    }

    /// Position and velocity at controller time `t`: between knots, the
    /// trajectory sent; after the newest, its prediction; before the
    /// oldest, the oldest knot's.
    pub(super) fn state(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let n = self.knots.len();
        if n >= 2 && t < self.pred.t {
            let k = self.knots.partition_point(|k| k.t <= t);
            if k == 0 {
                return (self.knots[0].position, knots::velocity_at(&self.knots, 0));
            }
            return knots::between(&self.knots, k - 1, t);
        }
        let (sigma, rate) = self.sigma(t - self.pred.t);
        let (p, v) = self.pred.at(sigma);
        (p, v * rate)
    }

    pub(super) fn horizon(&mut self, dt: f64, out: &mut [Vector3<f64>]) {
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.state(self.now + j as f64 * dt).0;
        }
        if !self.driven {
            self.now += dt;
        }
    }

    pub(super) fn closest(&self) -> (Vector3<f64>, Vector3<f64>) {
        self.state(self.now)
    }

    /// Where the prediction stops (the hold after the decay).
    pub(super) fn stop_point(&self) -> Vector3<f64> {
        self.state(self.pred.t + self.settings.extrapolation_s + self.decay)
            .0
    }

    /// The newest sample.
    pub(super) fn last(&self) -> &StreamSample {
        &self.knots[self.knots.len() - 1]
    }

    /// Time since the newest sample \[s\] at the current time (negative
    /// while the trajectory sent ahead lasts).
    pub(super) fn age(&self) -> f64 {
        self.now - self.pred.t
    }

    /// The heading \[rad\] and its rate [rad/s] `ahead` \[s\] after the
    /// current time: between knots that give a heading, interpolated (cubic
    /// Hermite with their rates, else at the mean rate; the shorter way
    /// round); after the newest, carried on at its rate (0 when not
    /// given) for at most `extrapolation_s`. `None`: no heading.
    pub(super) fn yaw(&self, ahead: f64) -> Option<(f64, f64)> {
        let t = self.now + ahead.max(0.0);
        let k = self.knots.partition_point(|k| k.t <= t);
        let before = self.knots[..k].iter().rev().find(|k| k.yaw.is_some());
        let after = self.knots[k..].iter().find(|k| k.yaw.is_some());
        match (before, after) {
            (Some(b), Some(a)) if a.t > b.t => Some(yaw_between(b, a, t)),
            (Some(b), _) => {
                let rate = b.yaw_rate.unwrap_or(0.0);
                let dt = (t - b.t).clamp(0.0, self.settings.extrapolation_s);
                let y = b.yaw? + rate * dt;
                Some((wrap_angle_difference(y), rate))
            }
            (None, Some(a)) => Some((a.yaw?, a.yaw_rate.unwrap_or(0.0))),
            (None, None) => None,
        }
    }
}

/// The heading between two knots that give one, at `t` (module docs of
/// [`Stream::yaw`]).
fn yaw_between(b: &StreamSample, a: &StreamSample, t: f64) -> (f64, f64) {
    let (y0, y1) = (b.yaw.unwrap_or(0.0), a.yaw.unwrap_or(0.0));
    let d = wrap_angle_difference(y1 - y0);
    let h = a.t - b.t;
    let u = ((t - b.t) / h).clamp(0.0, 1.0);
    let (r0, r1) = match (b.yaw_rate, a.yaw_rate) {
        (Some(r0), Some(r1)) => (r0, r1),
        _ => (d / h, d / h),
    };
    let (u2, u3) = (u * u, u * u * u);
    let y = y0 + (-2.0 * u3 + 3.0 * u2) * d + (u3 - 2.0 * u2 + u) * h * r0 + (u3 - u2) * h * r1;
    let r =
        (-6.0 * u2 + 6.0 * u) * d / h + (3.0 * u2 - 4.0 * u + 1.0) * r0 + (3.0 * u2 - 2.0 * u) * r1;
    (wrap_angle_difference(y), r)
}
