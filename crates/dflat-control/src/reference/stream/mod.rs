//! Streamed trajectories: a planner's samples (time, position, optional
//! velocity, acceleration, yaw, yaw rate) → the reference over the horizon,
//! predicted from the newest sample.
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

use nalgebra::Vector3;

use super::{invalid, is_finite3};
use crate::ControlError;

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
            jerk_horizon_s: 0.5,
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
        Ok(())
    }
}

/// Nodes of the jerk prediction's table (over `σ ∈ [0, σ_max]`).
const JERK_NODES: usize = 256;

/// The prediction from one sample.
#[derive(Debug, Clone, PartialEq)]
struct Prediction {
    t: f64,
    p: Vector3<f64>,
    v: Vector3<f64>,
    a: Vector3<f64>,
    /// The horizontal prediction with the stream's jerk, tabulated (module
    /// docs, "The jerk"); `None`: the closed-form turn.
    jerk: Option<JerkTable>,
}

/// Positions and velocities of the jerk prediction at `σ = k·step`.
#[derive(Debug, Clone, PartialEq)]
struct JerkTable {
    step: f64,
    p: [[f64; 2]; JERK_NODES + 1],
    v: [[f64; 2]; JERK_NODES + 1],
}

impl JerkTable {
    /// Integrates the horizontal motion from `p`, `v`, `a` with jerk `j`
    /// over `[0, sigma_max]`: speed and heading rate move at their rates
    /// (from `j`) for `horizon` \[s\], then stay (a turn at the curvature
    /// reached); below [`TURN_MIN_SPEED`], acceleration moves at `j` for
    /// `horizon`, then stays.
    fn new(
        p: Vector3<f64>,
        v: Vector3<f64>,
        a: Vector3<f64>,
        j: Vector3<f64>,
        horizon: f64,
        sigma_max: f64,
    ) -> Self {
        let step = (sigma_max / JERK_NODES as f64).max(1e-9);
        // The planar velocity at σ.
        let speed = v.x.hypot(v.y);
        let vel = |s: f64| -> [f64; 2] {
            let sj = s.min(horizon);
            if speed < TURN_MIN_SPEED {
                // a(σ) = a + j·min(σ, T): v = v + a σ + j (σ_j²/2 + σ_j (σ − σ_j)).
                let jj = 0.5 * sj * sj + sj * (s - sj);
                return [v.x + a.x * s + j.x * jj, v.y + a.y * s + j.y * jj];
            }
            let at = (v.x * a.x + v.y * a.y) / speed;
            let omega = (v.x * a.y - v.y * a.x) / (speed * speed);
            // Rates of the tangential acceleration and the turn rate.
            let a2 = a.x * a.x + a.y * a.y;
            let at_dot = (v.x * j.x + v.y * j.y + a2 - at * at) / speed;
            let omega_dot = (v.x * j.y - v.y * j.x) / (speed * speed) - 2.0 * omega * at / speed;
            let spd = speed + at * s + at_dot * (0.5 * sj * sj + sj * (s - sj));
            let th = v.y.atan2(v.x) + omega * s + omega_dot * (0.5 * sj * sj + sj * (s - sj));
            let spd = spd.max(0.0);
            [spd * th.cos(), spd * th.sin()]
        };
        let mut t = Self {
            step,
            p: [[0.0; 2]; JERK_NODES + 1],
            v: [[0.0; 2]; JERK_NODES + 1],
        };
        t.p[0] = [p.x, p.y];
        t.v[0] = vel(0.0);
        for k in 1..=JERK_NODES {
            let s0 = (k - 1) as f64 * step;
            // Simpson over the interval.
            let (va, vm, vb) = (vel(s0), vel(s0 + 0.5 * step), vel(s0 + step));
            for i in 0..2 {
                t.p[k][i] = t.p[k - 1][i] + step / 6.0 * (va[i] + 4.0 * vm[i] + vb[i]);
            }
            t.v[k] = vb;
        }
        t
    }

    /// Position and velocity at `sigma` (cubic Hermite between nodes; held
    /// at the last node's motion beyond it).
    fn at(&self, sigma: f64) -> ([f64; 2], [f64; 2]) {
        let x = (sigma / self.step).max(0.0);
        if x >= JERK_NODES as f64 {
            let extra = (x - JERK_NODES as f64) * self.step;
            let (p, v) = (self.p[JERK_NODES], self.v[JERK_NODES]);
            return ([p[0] + v[0] * extra, p[1] + v[1] * extra], v);
        }
        let k = x.floor() as usize;
        let u = x - k as f64;
        let h = self.step;
        let (p0, p1, v0, v1) = (self.p[k], self.p[k + 1], self.v[k], self.v[k + 1]);
        let (h00, h10, h01, h11) = (
            2.0 * u * u * u - 3.0 * u * u + 1.0,
            u * u * u - 2.0 * u * u + u,
            -2.0 * u * u * u + 3.0 * u * u,
            u * u * u - u * u,
        );
        let (d00, d10, d01, d11) = (
            (6.0 * u * u - 6.0 * u) / h,
            3.0 * u * u - 4.0 * u + 1.0,
            (-6.0 * u * u + 6.0 * u) / h,
            3.0 * u * u - 2.0 * u,
        );
        let mut p = [0.0; 2];
        let mut v = [0.0; 2];
        for i in 0..2 {
            p[i] = h00 * p0[i] + h10 * h * v0[i] + h01 * p1[i] + h11 * h * v1[i];
            v[i] = d00 * p0[i] + d10 * v0[i] + d01 * p1[i] + d11 * v1[i];
        }
        (p, v)
    }
}

impl Prediction {
    /// Position and velocity `sigma` \[s\] along the extrapolation.
    fn at(&self, sigma: f64) -> (Vector3<f64>, Vector3<f64>) {
        if let Some(table) = &self.jerk {
            let s = sigma;
            let z = self.p.z + self.v.z * s + 0.5 * self.a.z * s * s;
            let vz = self.v.z + self.a.z * s;
            let (p, v) = table.at(s);
            return (Vector3::new(p[0], p[1], z), Vector3::new(v[0], v[1], vz));
        }
        self.closed_form(sigma)
    }

    /// The coordinated turn (or constant acceleration) in closed form.
    fn closed_form(&self, sigma: f64) -> (Vector3<f64>, Vector3<f64>) {
        let s = sigma;
        let z = self.p.z + self.v.z * s + 0.5 * self.a.z * s * s;
        let vz = self.v.z + self.a.z * s;
        let speed = self.v.x.hypot(self.v.y);
        if speed < TURN_MIN_SPEED {
            let x = self.p.x + self.v.x * s + 0.5 * self.a.x * s * s;
            let y = self.p.y + self.v.y * s + 0.5 * self.a.y * s * s;
            return (
                Vector3::new(x, y, z),
                Vector3::new(self.v.x + self.a.x * s, self.v.y + self.a.y * s, vz),
            );
        }
        let omega = (self.v.x * self.a.y - self.v.y * self.a.x) / (speed * speed);
        let at = (self.v.x * self.a.x + self.v.y * self.a.y) / speed;
        let th0 = self.v.y.atan2(self.v.x);
        let th = th0 + omega * s;
        let spd = speed + at * s;
        let (c0, s0) = (th0.cos(), th0.sin());
        let (c1, s1) = (th.cos(), th.sin());
        // U(σ) = ∫₀^σ u(θ0 + ωσ') dσ', IU = ∫₀^σ U; small ω: series.
        let (ux, uy, iux, iuy) = if (omega * s).abs() < 1e-4 {
            let w = omega;
            (
                s * c0 - 0.5 * w * s * s * s0,
                s * s0 + 0.5 * w * s * s * c0,
                0.5 * s * s * c0 - w * s * s * s / 6.0 * s0,
                0.5 * s * s * s0 + w * s * s * s / 6.0 * c0,
            )
        } else {
            let w = omega;
            let ux = (s1 - s0) / w;
            let uy = (c0 - c1) / w;
            let iux = (-(c1 - c0) / w - s * s0) / w;
            let iuy = (s * c0 - (s1 - s0) / w) / w;
            (ux, uy, iux, iuy)
        };
        // ∫ (speed + a_t σ') u dσ' = speed·U + a_t (σU − IU).
        let x = self.p.x + speed * ux + at * (s * ux - iux);
        let y = self.p.y + speed * uy + at * (s * uy - iuy);
        (Vector3::new(x, y, z), Vector3::new(spd * c1, spd * s1, vz))
    }
}

/// A streamed trajectory: the newest prediction and the samples before it.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Stream {
    settings: StreamSettings,
    pred: Prediction,
    /// This prediction's decay time \[s\] (≥ `decay_s`; module docs).
    decay: f64,
    /// The newest sample (yaw carried).
    last: StreamSample,
    /// Times and positions of the previous position-only samples.
    history: [Option<(f64, Vector3<f64>)>; 2],
    /// Times and accelerations of the two previous samples that gave one
    /// (the jerk's finite difference), the newer last.
    prev_accel: [Option<(f64, Vector3<f64>)>; 2],
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
            pred: Prediction {
                t: sample.t,
                p: sample.position,
                v: Vector3::zeros(),
                a: Vector3::zeros(),
                jerk: None,
            },
            decay: settings.decay_s,
            last: *sample,
            history: [None, None],
            prev_accel: [None, None],
            now: sample.t,
            driven: false,
        };
        s.push(sample)?;
        Ok(s)
    }

    /// Replaces the prediction with one from `sample`. A sample older than
    /// the newest is refused.
    pub(super) fn push(&mut self, sample: &StreamSample) -> Result<(), ControlError> {
        check_sample(sample)?;
        if sample.t < self.pred.t {
            return Err(invalid("stream sample", "older than the newest sample"));
        }
        let implied = if sample.velocity.is_none() && self.settings.implied_velocity {
            self.implied(sample)
        } else {
            None
        };
        let (v, a) = match (sample.velocity, implied) {
            (Some(v), _) => (v, sample.acceleration.unwrap_or_else(Vector3::zeros)),
            (None, Some(va)) => va,
            (None, None) => (
                Vector3::zeros(),
                sample.acceleration.unwrap_or_else(Vector3::zeros),
            ),
        };
        if sample.velocity.is_none() {
            if self.history[1].is_some_and(|(t, _)| t >= sample.t) {
                // Same time as the previous one: replace it.
                self.history[1] = Some((sample.t, sample.position));
            } else {
                self.history = [self.history[1], Some((sample.t, sample.position))];
            }
        } else {
            self.history = [None, None];
        }
        // The jerk: the change of the sender's acceleration since its
        // previous sample, when recent (the implied gap's bounds).
        let jerk = sample.acceleration.and_then(|a| self.jerk(sample.t, a));
        match sample.acceleration {
            Some(a) => self.prev_accel = [self.prev_accel[1], Some((sample.t, a))],
            None => self.prev_accel = [None, None],
        }
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
        if let Some(j) = jerk
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
        self.last = *sample;
        Ok(())
    }

    /// The jerk at `t` from acceleration `a` and the previous samples'
    /// (spacing within the implied gap's bounds): the derivative at `t` of
    /// the quadratic through three accelerations (second order: a steady
    /// turn's jerk to O(h²)); `None` before three.
    fn jerk(&self, t: f64, a: Vector3<f64>) -> Option<Vector3<f64>> {
        let (lo, hi) = (IMPLIED_MIN_GAP, self.settings.implied_max_gap_s);
        let ok = |h: f64| h >= lo && h <= hi;
        let (t1, a1) = self.prev_accel[1]?;
        let h2 = t - t1;
        if !ok(h2) {
            return None;
        }
        let d21 = (a - a1) / h2;
        match self.prev_accel[0] {
            Some((t0, a0)) if ok(t1 - t0) => {
                let h1 = t1 - t0;
                let d10 = (a1 - a0) / h1;
                let c = (d21 - d10) * (2.0 / (h1 + h2));
                Some(d21 + c * (0.5 * h2))
            }
            // Two samples only: a first-order difference lags by h/2 (on a
            // tight fast turn, tenths of a metre half a second ahead).
            _ => None,
        }
    }

    /// Velocity and acceleration of the quadratic through the two previous
    /// samples and `sample`, at `sample`'s time.
    fn implied(&self, sample: &StreamSample) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let (t1, p1) = self.history[1]?;
        let (t0, p0) = self.history[0]?;
        let (h2, h1) = (sample.t - t1, t1 - t0);
        let (lo, hi) = (IMPLIED_MIN_GAP, self.settings.implied_max_gap_s);
        if !(h2 >= lo && h2 <= hi && h1 >= lo && h1 <= hi) {
            return None;
        }
        // Divided differences of the quadratic through (t0,p0),(t1,p1),(t2,p2).
        let d21 = (sample.position - p1) / h2;
        let d10 = (p1 - p0) / h1;
        let a = (d21 - d10) * (2.0 / (h1 + h2));
        let v = d21 + a * (0.5 * h2);
        Some((v, a))
    }

    /// Sets the controller time now \[s\].
    pub(super) fn set_time(&mut self, t: f64) {
        if t.is_finite() {
            self.now = t;
            self.driven = true;
        }
    }

    /// The decay's clock `σ` for time `tau` \[s\] after the sample, and
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

    /// Position and velocity at controller time `t`.
    pub(super) fn state(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
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
        &self.last
    }

    /// Time since the newest sample \[s\] at the current time.
    pub(super) fn age(&self) -> f64 {
        self.now - self.pred.t
    }
}
