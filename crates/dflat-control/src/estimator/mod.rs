//! A state estimator for the baselines (Flatness MPC and PD): a Kalman
//! filter per position axis over timestamped pose samples, with a
//! white-noise-on-jerk prior — the discrete form of the constant-
//! acceleration Gaussian-process prior that STEAM uses (paper §VII-B) —
//! optionally driven by the commands the controller sent.
//!
//! Per axis the state is `x = [p, v, a]` (position \[m\], velocity [m/s],
//! acceleration [m/s²], the frame of the samples: local NED for flight) and
//! the continuous model is
//!
//! ```text
//! ṗ = v,  v̇ = a,  ȧ = λ·(u(t) − a) + w,   E[w(t)w(s)] = q·δ(t − s)
//! ```
//!
//! * `λ = 0` ([`EstimatorSettings::input_lag`] `None`): the plain
//!   white-noise-on-jerk (constant-acceleration) prior; the input is unused.
//! * `λ = 1/τ` (`Some(τ)`): the acceleration relaxes towards `u(t)`, the
//!   acceleration the sent attitude command asks for (the controller's
//!   model: first-order attitude loop with time constant τ), so the filter
//!   predicts a tilt change before the poses show it. `u(t)` is piecewise
//!   constant, recorded by the controller with
//!   [`StateEstimator::record_input`] at each tick.
//!
//! Each sample is taken at its **capture time** (the shell's clock): the
//! posterior is propagated from the previous sample's time through the
//! inputs sent in between, then updated with `H = [1, 0, 0]` and variance
//! σ². The controller asks for the state at the **tick time** with
//! [`StateEstimator::estimate_at`], which propagates the posterior (a copy)
//! through the inputs sent since: the pose latency is compensated by the
//! model, not ignored.
//!
//! Discretisation over an interval h with constant input, exact for the
//! mean: `x⁺ = F(h) x + G(h) u`. The process covariance `Q(h) =
//! q ∫₀ʰ F(s) b bᵀ F(s)ᵀ ds`, `b = [0, 0, 1]ᵀ`, is the exact closed form
//! for λ = 0 (`q·[[h⁵/20, h⁴/8, h³/6], [h⁴/8, h³/3, h²/2], [h³/6, h²/2, h]]`)
//! and Simpson's rule on 8 intervals otherwise.
//!
//! Pure and allocation-free once built: the input history is a ring of
//! [`INPUT_CAPACITY`] entries.

pub mod differences;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::{ControlError, Limit};

/// Inputs the estimator keeps (one per control tick: 2.56 s at 50 Hz, far
/// longer than any pose latency; older ones are dropped and the oldest
/// kept one stands in for them).
pub const INPUT_CAPACITY: usize = 128;

/// Pose rate the default noise rule assumes when none is given \[Hz\]
/// (the paper's camera, §VII-A).
pub const DEFAULT_POSE_RATE_HZ: f64 = 15.0;

/// Ratio of the pose rate to the filter's bandwidth in the default noise
/// rule ([`EstimatorSettings::for_sensor`]).
pub const BANDWIDTH_DIVISOR: f64 = 10.0;

/// Highest bandwidth of the default noise rule \[Hz\]: the acceleration of
/// a vehicle whose attitude loop lags by τ ≈ 0.2 s changes at ≲ 1/(2πτ) ≈
/// 0.8 Hz, so a wider filter passes noise and no motion. (Uncapped, 50 Hz
/// poses of σ = 1 cm gave a 5 Hz filter whose acceleration noise left
/// estimator-fed Flatness MPC 2 m off a hover setpoint; capped, 5 cm.)
pub const MAX_BANDWIDTH_HZ: f64 = 1.5;

/// Settings of [`StateEstimator`]. [`EstimatorSettings::for_sensor`]
/// derives them from the pose noise and rate; [`Default`] is that rule at
/// σ = 2 cm, 15 Hz.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimatorSettings {
    /// Standard deviation of one pose sample per axis \[m\], finite, > 0.
    pub sigma: f64,
    /// Spectral density q of the white jerk noise [m²/s⁵], finite, > 0:
    /// how fast the acceleration may change beyond the model. Larger
    /// follows manoeuvres faster and passes more noise.
    pub jerk_psd: f64,
    /// Time constant τ \[s\] of the acceleration's response to the sent
    /// command (the attitude loop), finite, > 0; `None` ignores the inputs
    /// (constant-acceleration prior, as STEAM). Default `Some(0.2)`.
    pub input_lag: Option<f64>,
    /// Prior standard deviations of velocity [m/s] and acceleration [m/s²]
    /// at the first sample (its position takes `sigma`), finite, > 0.
    /// Default `[3, 3]`: the vehicle may already be moving.
    pub initial_sigma: [f64; 2],
}

impl Default for EstimatorSettings {
    fn default() -> Self {
        Self::for_sensor(0.02, DEFAULT_POSE_RATE_HZ)
    }
}

fn invalid(field: &'static str, reason: impl Into<String>) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.into(),
    }
}

impl EstimatorSettings {
    /// The default rule from the pose noise σ \[m\] and the pose rate f
    /// \[Hz\]: bandwidth ω = 2π·min(f / [`BANDWIDTH_DIVISOR`],
    /// [`MAX_BANDWIDTH_HZ`]) (1.5 Hz from 15 Hz poses up) and `q = σ²·ω⁶/f`, the white-jerk density whose steady-state
    /// filter has that bandwidth (the continuous-time Kalman–Bucy filter of
    /// a triple integrator with measurement density σ²/f has its poles on
    /// a circle of radius `(q f/σ²)^{1/6}`). Input lag 0.2 s (the paper's
    /// and the lab's attitude τ). Non-positive arguments give settings that
    /// [`EstimatorSettings::validate`] refuses.
    pub fn for_sensor(sigma: f64, pose_rate_hz: f64) -> Self {
        let omega =
            2.0 * std::f64::consts::PI * (pose_rate_hz / BANDWIDTH_DIVISOR).min(MAX_BANDWIDTH_HZ);
        Self {
            sigma,
            jerk_psd: sigma * sigma * omega.powi(6) / pose_rate_hz,
            input_lag: Some(0.2),
            initial_sigma: [3.0, 3.0],
        }
    }

    /// The pose rate of [`EstimatorSettings::for_sensor`] \[Hz\] (the
    /// daemon's `controller.estimator.pose_rate_hz`).
    pub const POSE_RATE_HZ: Limit = Limit::closed(1.0, 400.0, "Hz");
    /// `jerk_psd` \[m²/s⁵\]: wide enough for every value the noise rule
    /// derives from σ in 1e-4..=1 m and a pose rate in 1..=400 Hz.
    pub const JERK_PSD: Limit = Limit::closed(1e-12, 1e6, "m²/s⁵");

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return Err(invalid(
                "sigma",
                format!("must be finite and > 0 m, got {}", self.sigma),
            ));
        }
        Self::JERK_PSD.check("jerk_psd", self.jerk_psd)?;
        if let Some(tau) = self.input_lag
            && !(tau.is_finite() && tau > 0.0)
        {
            return Err(invalid(
                "input_lag",
                format!("must be finite and > 0 s, got {tau}"),
            ));
        }
        if let Some(s) = self
            .initial_sigma
            .iter()
            .find(|s| !(s.is_finite() && **s > 0.0))
        {
            return Err(invalid(
                "initial_sigma",
                format!("must be finite and > 0, got {s}"),
            ));
        }
        Ok(())
    }
}

/// Why a sample was not used. Nothing else changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleRejected {
    /// Time or position not finite.
    NonFinite,
    /// Captured before the newest sample already used.
    OutOfOrder,
}

/// Counters of the samples seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimatorCounts {
    /// Samples used.
    pub used: u64,
    /// Samples refused (non-finite, out of order).
    pub rejected: u64,
}

/// The estimate of one axis at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisEstimate {
    /// `[p, v, a]` \[m, m/s, m/s²\].
    pub mean: Vector3<f64>,
    /// Its covariance.
    pub covariance: Matrix3<f64>,
}

/// The estimator: see the module docs.
#[derive(Debug, Clone)]
pub struct StateEstimator {
    settings: EstimatorSettings,
    /// λ = 1/τ \[1/s\] (0: inputs unused).
    lambda: f64,
    /// Posterior per axis (x, y, z) at `t`.
    mean: [Vector3<f64>; 3],
    cov: [Matrix3<f64>; 3],
    /// Time of the posterior (the newest sample used) \[s\].
    t: f64,
    started: bool,
    /// Sent inputs: (time from which it applies \[s\], acceleration per
    /// axis [m/s²]), oldest first.
    inputs: VecDeque<(f64, Vector3<f64>)>,
    counts: EstimatorCounts,
    /// Normalised innovation squared of the last sample, per axis.
    last_nis: [f64; 3],
}

/// `(1 − e^{−x})/x` and `(x − 1 + e^{−x})/x²` with their limits 1 and ½.
fn lag_factors(x: f64) -> (f64, f64) {
    if x < 1e-3 {
        (
            1.0 - x / 2.0 + x * x / 6.0 - x * x * x / 24.0,
            0.5 - x / 6.0 + x * x / 24.0 - x * x * x / 120.0,
        )
    } else {
        let e = (-x).exp();
        ((1.0 - e) / x, (x - 1.0 + e) / (x * x))
    }
}

/// `F(h)` and `G(h)` of one axis (module docs).
fn transition(h: f64, lambda: f64) -> (Matrix3<f64>, Vector3<f64>) {
    let (f1, f2) = lag_factors(lambda * h);
    let c1 = h * f1; // ∫ e^{−λs} ds
    let c2 = h * h * f2; // ∫∫
    let e = (-lambda * h).exp();
    let f = Matrix3::new(1.0, h, c2, 0.0, 1.0, c1, 0.0, 0.0, e);
    let g = Vector3::new(h * h / 2.0 - c2, h - c1, 1.0 - e);
    (f, g)
}

/// `Q(h)` of one axis for jerk density `q` (module docs).
fn process_noise(h: f64, lambda: f64, q: f64) -> Matrix3<f64> {
    if lambda == 0.0 {
        let (h2, h3) = (h * h, h * h * h);
        let (h4, h5) = (h3 * h, h3 * h2);
        return Matrix3::new(
            h5 / 20.0,
            h4 / 8.0,
            h3 / 6.0,
            h4 / 8.0,
            h3 / 3.0,
            h2 / 2.0,
            h3 / 6.0,
            h2 / 2.0,
            h,
        ) * q;
    }
    const N: usize = 8;
    let mut acc = Matrix3::zeros();
    for i in 0..=N {
        let s = h * i as f64 / N as f64;
        let (f, _) = transition(s, lambda);
        let col = f.column(2).into_owned();
        let w = if i == 0 || i == N {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        };
        acc += col * col.transpose() * w;
    }
    acc * (q * h / (3.0 * N as f64))
}

impl StateEstimator {
    /// A new estimator; errors name an invalid setting.
    pub fn new(settings: EstimatorSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        Ok(Self {
            lambda: settings.input_lag.map_or(0.0, |tau| 1.0 / tau),
            settings,
            mean: [Vector3::zeros(); 3],
            cov: [Matrix3::zeros(); 3],
            t: f64::NEG_INFINITY,
            started: false,
            inputs: VecDeque::with_capacity(INPUT_CAPACITY),
            counts: EstimatorCounts::default(),
            last_nis: [f64::NAN; 3],
        })
    }

    /// The settings.
    pub fn settings(&self) -> &EstimatorSettings {
        &self.settings
    }

    /// True once a sample has been used.
    pub fn is_started(&self) -> bool {
        self.started
    }

    /// Time of the newest sample used \[s\] (−∞ before the first).
    pub fn sample_time(&self) -> f64 {
        self.t
    }

    /// Samples used and refused so far.
    pub fn counts(&self) -> EstimatorCounts {
        self.counts
    }

    /// Normalised innovation squared `ν²/S` of the last sample used, per
    /// axis (x, y, z); NaN before the second sample.
    pub fn last_nis(&self) -> [f64; 3] {
        self.last_nis
    }

    /// Forgets the samples and the inputs (counts are kept).
    pub fn reset(&mut self) {
        self.mean = [Vector3::zeros(); 3];
        self.cov = [Matrix3::zeros(); 3];
        self.t = f64::NEG_INFINITY;
        self.started = false;
        self.inputs.clear();
        self.last_nis = [f64::NAN; 3];
    }

    /// Records the acceleration `a` [m/s²] per axis that the command sent
    /// at time `t` \[s\] asks for (held until the next one). Unused without
    /// an input lag. Non-finite values, and times before the newest input,
    /// are ignored.
    pub fn record_input(&mut self, t: f64, a: &Vector3<f64>) {
        if self.lambda == 0.0 || !t.is_finite() || !a.iter().all(|c| c.is_finite()) {
            return;
        }
        if let Some(last) = self.inputs.back_mut() {
            if t < last.0 {
                return;
            }
            if t == last.0 {
                last.1 = *a;
                return;
            }
        }
        if self.inputs.len() == INPUT_CAPACITY {
            self.inputs.pop_front();
        }
        self.inputs.push_back((t, *a));
    }

    /// Replaces the newest recorded input by `a` (standby: the autopilot
    /// flew its own command). Non-finite values are ignored.
    pub fn correct_last_input(&mut self, a: &Vector3<f64>) {
        if let Some(last) = self.inputs.back_mut()
            && a.iter().all(|c| c.is_finite())
        {
            last.1 = *a;
        }
    }

    /// The input in force at `t` and the time it is next replaced (∞ if
    /// never). Before the first recorded input: the oldest one (zero when
    /// none).
    fn input_at(&self, t: f64) -> (Vector3<f64>, f64) {
        let mut current = self.inputs.front().map_or(Vector3::zeros(), |i| i.1);
        for &(ti, a) in &self.inputs {
            if ti > t {
                return (current, ti);
            }
            current = a;
        }
        (current, f64::INFINITY)
    }

    /// Propagates `mean` (and `cov`, when given) of every axis from `t0`
    /// to `t1` ≥ `t0` through the recorded inputs.
    fn propagate(
        &self,
        mean: &mut [Vector3<f64>; 3],
        mut cov: Option<&mut [Matrix3<f64>; 3]>,
        t0: f64,
        t1: f64,
    ) {
        let mut t = t0;
        while t < t1 {
            let (u, next) = if self.lambda == 0.0 {
                (Vector3::zeros(), f64::INFINITY)
            } else {
                self.input_at(t)
            };
            let end = next.min(t1);
            let h = end - t;
            let (f, g) = transition(h, self.lambda);
            for axis in 0..3 {
                mean[axis] = f * mean[axis] + g * u[axis];
            }
            if let Some(c) = cov.as_deref_mut() {
                let q = process_noise(h, self.lambda, self.settings.jerk_psd);
                for p in c.iter_mut() {
                    *p = f * *p * f.transpose() + q;
                }
            }
            t = end;
        }
    }

    /// Uses the pose sample captured at `t` \[s\] at `position` (per axis,
    /// the frame of the estimate). Samples older than the newest used are
    /// refused (the filter does not re-run the past); a sample at the same
    /// time is fused as a second measurement.
    pub fn observe(&mut self, t: f64, position: &Vector3<f64>) -> Result<(), SampleRejected> {
        if !t.is_finite() || !position.iter().all(|c| c.is_finite()) {
            self.counts.rejected += 1;
            return Err(SampleRejected::NonFinite);
        }
        if !self.started {
            let [sv, sa] = self.settings.initial_sigma;
            let s = self.settings.sigma;
            for axis in 0..3 {
                self.mean[axis] = Vector3::new(position[axis], 0.0, 0.0);
                self.cov[axis] = Matrix3::from_diagonal(&Vector3::new(s * s, sv * sv, sa * sa));
            }
            self.t = t;
            self.started = true;
            self.counts.used += 1;
            return Ok(());
        }
        if t < self.t {
            self.counts.rejected += 1;
            return Err(SampleRejected::OutOfOrder);
        }
        let (mut mean, mut cov) = (self.mean, self.cov);
        self.propagate(&mut mean, Some(&mut cov), self.t, t);
        let r = self.settings.sigma * self.settings.sigma;
        for axis in 0..3 {
            let p = cov[axis];
            let s = p[(0, 0)] + r;
            let k = p.column(0) / s;
            let nu = position[axis] - mean[axis][0];
            mean[axis] += k * nu;
            // Joseph form: (I − K H) P (I − K H)ᵀ + K r Kᵀ.
            let mut ikh = Matrix3::identity();
            ikh.column_mut(0).axpy(-1.0, &k, 1.0);
            cov[axis] = ikh * p * ikh.transpose() + k * k.transpose() * r;
            self.last_nis[axis] = nu * nu / s;
        }
        self.mean = mean;
        self.cov = cov;
        self.t = t;
        self.counts.used += 1;
        // Inputs before the posterior are needed only for the one in force.
        while self.inputs.len() >= 2 && self.inputs[1].0 <= self.t {
            self.inputs.pop_front();
        }
        Ok(())
    }

    /// The state per axis at time `t` \[s\]: the posterior propagated
    /// through the inputs sent since the newest sample (a time before it
    /// gives the posterior itself). `None` before the first sample.
    pub fn estimate_at(&self, t: f64) -> Option<[Vector3<f64>; 3]> {
        if !self.started || !t.is_finite() {
            return None;
        }
        let mut mean = self.mean;
        self.propagate(&mut mean, None, self.t, t.max(self.t));
        Some(mean)
    }

    /// Mean and covariance of `axis` (0..3) at `t` ≥ the newest sample
    /// (earlier: the posterior). `None` before the first sample or for an
    /// axis out of range.
    pub fn axis_at(&self, axis: usize, t: f64) -> Option<AxisEstimate> {
        if !self.started || axis >= 3 || !t.is_finite() {
            return None;
        }
        let (mut mean, mut cov) = (self.mean, self.cov);
        self.propagate(&mut mean, Some(&mut cov), self.t, t.max(self.t));
        Some(AxisEstimate {
            mean: mean[axis],
            covariance: cov[axis],
        })
    }
}

/// Where a baseline (Flatness MPC, PD) takes its state from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StateSource {
    /// Finite differences of the measured positions, one per tick: the
    /// paper's simulation set-up (§VI); the shell feeds the newest pose
    /// at each tick.
    FiniteDifference,
    /// A [`StateEstimator`] fed with every pose at its capture time and
    /// predicted to the tick through the sent commands: the paper's
    /// outdoor set-up (§VII, STEAM). The controller is then multi-rate
    /// ([`crate::Controller::multi_rate`]).
    Estimator(EstimatorSettings),
}

/// The acceleration [m/s²] (model frame, per axis) that `command` asks for
/// once the attitude loop has settled (`θ = k̃·θ_cmd`, `φ = k̃·φ_cmd`, the
/// commanded thrust): the input of a [`StateEstimator`] with an input lag.
/// `None` when the map is singular (90° of tilt) or not finite.
pub fn commanded_acceleration(
    model: &crate::ControlModel,
    command: &crate::AttitudeCommand,
) -> Option<Vector3<f64>> {
    let k = match model {
        crate::ControlModel::Planar(m) => m.params().k,
        crate::ControlModel::Spatial(m) => m.params().k,
    };
    let input = Vector3::new(command.pitch, command.roll, command.thrust);
    acceleration_of_input(model, k, &input)
}

/// As [`commanded_acceleration`], from a model input `[θ_cmd, φ_cmd, T]`.
pub(crate) fn acceleration_of_input(
    model: &crate::ControlModel,
    k: f64,
    input: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let settled = Vector3::new(k * input.x, k * input.y, input.z);
    let (a_g, a_t) = model.acceleration_parts(&settled).ok()?;
    let a = a_g + a_t;
    a.iter().all(|c| c.is_finite()).then_some(a)
}

/// A baseline's estimator with the model that turns its commands into
/// accelerations: the shared part of Flatness MPC and PD in
/// [`StateSource::Estimator`] mode.
#[derive(Debug, Clone)]
pub(crate) struct BaselineEstimator {
    pub(crate) estimator: StateEstimator,
    k: f64,
}

impl BaselineEstimator {
    /// For `source` (None for finite differences).
    pub(crate) fn from_source(
        source: StateSource,
        model: &crate::ControlModel,
    ) -> Result<Option<Self>, ControlError> {
        match source {
            StateSource::FiniteDifference => Ok(None),
            StateSource::Estimator(settings) => Ok(Some(Self {
                estimator: StateEstimator::new(settings)?,
                k: match model {
                    crate::ControlModel::Planar(m) => m.params().k,
                    crate::ControlModel::Spatial(m) => m.params().k,
                },
            })),
        }
    }

    /// Feeds a pose sample to `estimator`, if there is one; a refused
    /// sample (non-finite, out of order) is dropped.
    pub(crate) fn observe(estimator: Option<&mut Self>, sample: &crate::Measurement) {
        if let Some(e) = estimator {
            let _ = e.estimator.observe(sample.t, &sample.position);
        }
    }

    /// The time a baseline's update will take its tick to be
    /// ([`crate::Controller::tick_time`]): with an estimator (multi-rate)
    /// the tick time it is handed, else the next tick of its finite
    /// `differences`.
    pub(crate) fn tick_time(
        estimator: Option<&Self>,
        differences: &differences::PoseDifferences,
        measurement: &crate::Measurement,
    ) -> f64 {
        if estimator.is_some() {
            measurement.t
        } else {
            differences.tick_time(measurement.t)
        }
    }

    /// The state per axis at the time of `measurement` from `estimator`
    /// (None without one); `NonFiniteMeasurement` for a measurement that is
    /// not finite, `NoMeasurement` for an estimator without a sample.
    pub(crate) fn checked_state(
        estimator: Option<&Self>,
        measurement: &crate::Measurement,
    ) -> Result<Option<[Vector3<f64>; 3]>, ControlError> {
        let m = measurement;
        if !(m.t.is_finite() && m.yaw.is_finite() && m.position.iter().all(|c| c.is_finite())) {
            return Err(ControlError::NonFiniteMeasurement);
        }
        estimator.map(|e| e.state_at(measurement.t)).transpose()
    }

    /// The state per axis at tick time `t`, or `NoMeasurement`.
    pub(crate) fn state_at(&self, t: f64) -> Result<[Vector3<f64>; 3], ControlError> {
        self.estimator
            .estimate_at(t)
            .ok_or(ControlError::NoMeasurement)
    }

    /// Records the command sent at tick `t`.
    pub(crate) fn sent(
        &mut self,
        model: &crate::ControlModel,
        t: f64,
        command: &crate::AttitudeCommand,
    ) {
        if let Some(a) = commanded_acceleration(model, command) {
            self.estimator.record_input(t, &a);
        }
    }

    /// Standby: the input `[θ_cmd, φ_cmd, T]` the autopilot applied instead.
    pub(crate) fn correct(&mut self, model: &crate::ControlModel, applied: &Vector3<f64>) {
        if let Some(a) = acceleration_of_input(model, self.k, applied) {
            self.estimator.correct_last_input(&a);
        }
    }
}
