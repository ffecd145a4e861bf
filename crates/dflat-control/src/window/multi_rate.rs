//! The multi-rate window (module docs of [`crate::window`], "Multi-rate"):
//! timestamped pose samples fitted by a chain of F⁻¹ through the sent
//! inputs.

use dflat_model::FlatError;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::classic::PENDING_INPUTS;
use crate::model::ControlModel;
use crate::{ControlError, Limit};

/// Largest multi-rate window M [control steps].
pub const MAX_WINDOW: usize = 250;
/// Pose samples a [`MultiRateWindow`] keeps; when full, the oldest is
/// dropped (at 50 Hz samples and M ≤ 100 it never fills).
pub const SAMPLE_CAPACITY: usize = 128;
/// Sample times within this many control steps of a tick count as on it.
const SNAP: f64 = 1e-9;
/// "No information" standard deviations of the arrival cost: position
/// \[m\], velocity [m/s], acceleration [m/s²] (also the cap of its growth).
const UNKNOWN_SIGMA: [f64; 3] = [100.0, 10.0, 10.0];

/// Settings of the multi-rate window ([`MultiRateWindow`]); part of
/// [`crate::dfmpc::DfMpcSettings`]. Checked by [`MultiRateSettings::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MultiRateSettings {
    /// Fit span M [control steps]: samples captured in the last M steps are
    /// fitted, older ones live on in the arrival cost (2 ..= [`MAX_WINDOW`]).
    /// Default 25 (0.5 s at 50 Hz: three or more samples at 10 Hz with
    /// 60 ms latency). Serialized as `window` (the lab's JSON).
    #[serde(rename = "window")]
    pub fit_span: usize,
    /// Standard deviation of one pose sample per axis \[m\]. Default 0.02.
    pub sample_sigma: f64,
    /// Random-walk process noise per control step of the window start's
    /// position \[m\], velocity [m/s] and acceleration [m/s²]: what the model
    /// is allowed not to explain. Smaller is smoother, larger follows
    /// unmodelled motion faster. All `f64::INFINITY`: no arrival cost (the
    /// window alone). Default `[0.001, 0.01, 0.1]` (in the lab's L-path
    /// study anything from `[0.0005, 0.002, 0.02]` to `[0.002, 0.05, 1]`
    /// flies within a few per cent of it; smaller is smoother).
    pub process_sigma: [f64; 3],
}

impl Default for MultiRateSettings {
    fn default() -> Self {
        Self {
            fit_span: 25,
            sample_sigma: 0.02,
            process_sigma: [0.001, 0.01, 0.1],
        }
    }
}

impl MultiRateSettings {
    /// `fit_span` (the daemon's `multi_rate_window`) [control steps].
    pub const WINDOW: Limit = Limit::closed(2.0, MAX_WINDOW as f64, "ticks");
    /// `sample_sigma` \[m\] (also the baselines' estimator's pose noise).
    pub const SAMPLE_SIGMA: Limit = Limit::closed(1e-4, 1.0, "m");

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        let bad = |field: &'static str, reason: &str| ControlError::InvalidSetting {
            field,
            reason: reason.to_string(),
        };
        Self::WINDOW.check("multi_rate.fit_span", self.fit_span as f64)?;
        Self::SAMPLE_SIGMA.check("multi_rate.sample_sigma", self.sample_sigma)?;
        if !self.process_sigma.iter().all(|s| *s > 0.0) {
            return Err(bad(
                "multi_rate.process_sigma",
                "> 0 (m, m/s, m/s² per step; infinity for none)",
            ));
        }
        Ok(())
    }
}

/// One pose sample in the multi-rate window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// Measurement (capture) time \[s\], on the clock of the tick times.
    pub t: f64,
    /// Position \[m\] in the model frame.
    pub position: Vector3<f64>,
}

/// Counters of a [`MultiRateWindow`] since construction (a reset keeps
/// them: the daemon's summary counts the whole flight).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct MultiRateStats {
    /// Samples accepted by [`MultiRateWindow::observe`].
    pub accepted: u64,
    /// Samples rejected: non-finite, or older than the window.
    pub rejected: u64,
    /// Samples fitted at the last tick (padding included; a gauge, not a
    /// count: left out of the serialised form).
    #[serde(skip)]
    pub fitted: usize,
    /// Ticks that had no sample in the window (pure prediction).
    pub blind_ticks: u64,
}

/// The time constants \[s\] of the model's input dynamics per axis
/// `[x, y, z]`: attitude τ for x, y; thrust τ_T for z (spatial; planar: τ).
pub(crate) fn input_lags(model: &ControlModel) -> [f64; 3] {
    match model {
        ControlModel::Planar(m) => [m.params().tau; 3],
        ControlModel::Spatial(m) => {
            let p = m.params();
            [p.tau, p.tau, p.tau_thrust]
        }
    }
}

/// The fixed outputs and what the smoothness term needs, from
/// [`MultiRateWindow::estimate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MultiRateEstimate {
    /// `[y_k, y_{k+1}, y_{k+2}]` \[m\]: the fixed outputs of the optimisation.
    pub fixed: [Vector3<f64>; 3],
    /// The input sent at the previous tick, `u_{k−1}` (hover before any).
    pub previous_input: Vector3<f64>,
    /// Samples fitted in the window (padding included); 0 = pure prediction.
    pub fitted: usize,
}

/// 3×3 symmetric matrix (full storage).
type M3 = [[f64; 3]; 3];

/// The arrival cost at the window start: mean outputs and the covariance
/// of the (c, d, h) deviation per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Arrival {
    /// Mean of `y_s, y_{s+1}, y_{s+2}` \[m\].
    mean: [Vector3<f64>; 3],
    /// Covariance of (c, d, h) per axis [m², (m/step)², (m/step²)²].
    cov: [M3; 3],
}

/// The multi-rate input-to-output map: timestamped pose samples and the
/// inputs at the control rate (see the module docs for the maths).
///
/// Use: [`MultiRateWindow::observe`] for every pose sample as it arrives,
/// then per tick [`MultiRateWindow::estimate`] (the fixed outputs
/// `y_k, y_{k+1}, y_{k+2}`) and, once the input is sent,
/// [`MultiRateWindow::commit`]. An estimate that is not committed leaves the
/// window as it was.
#[derive(Debug, Clone)]
pub struct MultiRateWindow {
    settings: MultiRateSettings,
    dt: f64,
    axes: usize,
    hover: Vector3<f64>,
    /// `[g_m]` per axis, m = 0..=M + 2.
    gains: Vec<[f64; 3]>,
    /// Process noise covariance per step, diagonal in (c, d, h); None: no
    /// arrival cost.
    process: Option<[f64; 3]>,
    /// "No information" variances in (c, d, h).
    unknown: [f64; 3],
    /// Samples, ascending in time.
    samples: Vec<PoseSample>,
    /// Estimated outputs `y_{k−M} … y_{k+2}` after the last commit.
    trajectory: Vec<Vector3<f64>>,
    /// Sent inputs `u_{k−M} … u_k` after the last commit (M + 1).
    inputs: Vec<Vector3<f64>>,
    /// Arrival cost at `k − M` after the last commit.
    arrival: Arrival,
    /// Workspace of the tick being estimated.
    next_trajectory: Vec<Vector3<f64>>,
    next_inputs: Vec<Vector3<f64>>,
    next_arrival: Arrival,
    /// Scratch chain for the arrival cost (M + 3).
    chain: Vec<Vector3<f64>>,
    /// Time of the last committed tick \[s\].
    last_tick: Option<f64>,
    /// Time of the tick estimated last (committed by `commit`).
    pending_tick: Option<f64>,
    /// The inputs in effect at the ticks after the last committed one,
    /// oldest first, the last repeated beyond them (an input delay's
    /// pending inputs); empty: the last input, held.
    pending_inputs: Vec<Vector3<f64>>,
    stats: MultiRateStats,
}

impl MultiRateWindow {
    /// An empty window for `model` (allocates all buffers once).
    pub fn new(model: &ControlModel, settings: MultiRateSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let m = settings.fit_span;
        let dt = model.dt();
        let mut gains = vec![[0.0; 3]; m + 3];
        for (axis, lag) in input_lags(model).iter().enumerate() {
            // Second differences β^i, summed twice: g_0 = g_1 = 0, g_2 = 1,
            // g_3 = 2 + β, …
            let beta = 1.0 - dt / lag;
            let (mut g, mut d1, mut b) = (0.0, 0.0, 1.0);
            for gm in gains.iter_mut() {
                gm[axis] = g;
                g += d1;
                d1 += b;
                b *= beta;
            }
        }
        let to_cdh = |s: [f64; 3]| [s[0] * s[0], (s[1] * dt).powi(2), (s[2] * dt * dt).powi(2)];
        let process = settings
            .process_sigma
            .iter()
            .any(|s| s.is_finite())
            .then(|| to_cdh(settings.process_sigma));
        let unknown = to_cdh(UNKNOWN_SIGMA);
        let hover = model.hover_input();
        let arrival = Arrival {
            mean: [Vector3::zeros(); 3],
            cov: [diag(unknown); 3],
        };
        Ok(Self {
            settings,
            dt,
            axes: model.axes(),
            hover,
            gains,
            process,
            unknown,
            samples: Vec::with_capacity(SAMPLE_CAPACITY),
            trajectory: vec![Vector3::zeros(); m + 3],
            inputs: vec![hover; m + 1],
            arrival,
            next_trajectory: vec![Vector3::zeros(); m + 3],
            next_inputs: vec![hover; m],
            next_arrival: arrival,
            chain: vec![Vector3::zeros(); m + 3],
            last_tick: None,
            pending_tick: None,
            pending_inputs: Vec::with_capacity(PENDING_INPUTS),
            stats: MultiRateStats::default(),
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MultiRateSettings {
        &self.settings
    }

    /// Counters since construction.
    pub fn stats(&self) -> MultiRateStats {
        self.stats
    }

    /// The samples held, oldest first (start-up padding included).
    pub fn samples(&self) -> &[PoseSample] {
        &self.samples
    }

    /// The estimated outputs `y_{k−M} … y_{k+2}` \[m\] of the last committed
    /// tick k, oldest first; empty before the first.
    pub fn trajectory(&self) -> &[Vector3<f64>] {
        if self.last_tick.is_some() {
            &self.trajectory
        } else {
            &[]
        }
    }

    /// The inputs sent at the last M + 1 ticks, `u_{k−M} … u_k`, oldest
    /// first (hover before the first tick).
    pub fn inputs(&self) -> &[Vector3<f64>] {
        &self.inputs
    }

    /// Standard deviations of the arrival cost's position \[m\] and velocity
    /// [m/s] at the window start, per axis `[x, y, z]` (planar: z is 0).
    pub fn arrival_sigma(&self) -> [[f64; 2]; 3] {
        let mut out = [[0.0; 2]; 3];
        for (axis, o) in out.iter_mut().enumerate().take(self.axes) {
            let p = &self.arrival.cov[axis];
            *o = [p[0][0].sqrt(), p[1][1].sqrt() / self.dt];
        }
        out
    }

    /// Time \[s\] of the last committed tick.
    pub fn last_tick(&self) -> Option<f64> {
        self.last_tick
    }

    /// Forgets the samples, estimate and inputs (the counters stay).
    pub fn reset(&mut self) {
        self.samples.clear();
        self.inputs.fill(self.hover);
        self.arrival.cov = [diag(self.unknown); 3];
        self.last_tick = None;
        self.pending_tick = None;
        self.stats.fitted = 0;
    }

    /// Adds one pose sample taken at time `t` \[s\] (the clock of the tick
    /// times) at `position` \[m\] (model frame). Returns false, and keeps
    /// nothing, for a non-finite sample or one older than the window of the
    /// last tick. A sample at the time of a held one replaces it (a repeated
    /// message); samples may arrive out of order.
    pub fn observe(&mut self, t: f64, position: &Vector3<f64>) -> bool {
        let finite = t.is_finite() && position.iter().take(self.axes).all(|v| v.is_finite());
        let horizon = self.settings.fit_span as f64 * self.dt;
        let too_old = self
            .last_tick
            .is_some_and(|tl| t < tl - horizon - SNAP * self.dt);
        if !finite || too_old {
            self.stats.rejected += 1;
            return false;
        }
        let sample = PoseSample {
            t,
            position: *position,
        };
        let mut at = self.samples.partition_point(|s| s.t < t);
        if self.samples.get(at).is_some_and(|s| s.t == t) {
            self.samples[at] = sample;
        } else {
            if self.samples.len() == SAMPLE_CAPACITY {
                if at == 0 {
                    self.stats.rejected += 1;
                    return false;
                }
                self.samples.remove(0);
                at -= 1;
            }
            self.samples.insert(at, sample);
        }
        self.stats.accepted += 1;
        true
    }

    /// The fixed outputs at the tick at time `t` \[s\], through
    /// `next_output` (F⁻¹, possibly with a disturbance estimate): moves the
    /// window to `t` (a gap of several steps repeats the last input, as the
    /// shell holds it; a gap beyond the window counts as M steps), absorbs
    /// the samples that leave it into the arrival cost, fits the window
    /// start to the samples in it and propagates. Errors: a non-finite `t`,
    /// no sample ever ([`ControlError::NoMeasurement`]), a failing F⁻¹.
    pub fn estimate<F>(&mut self, t: f64, next_output: F) -> Result<MultiRateEstimate, ControlError>
    where
        F: Fn(&[Vector3<f64>; 3], &Vector3<f64>) -> Result<Vector3<f64>, FlatError>,
    {
        if !t.is_finite() {
            return Err(ControlError::NonFiniteMeasurement);
        }
        self.pending_tick = None;
        let m = self.settings.fit_span;
        let dt = self.dt;
        let start = t - m as f64 * dt;

        match self.last_tick {
            None => {
                let Some(oldest) = self
                    .samples
                    .iter()
                    .find(|s| s.t >= start - SNAP * dt)
                    .copied()
                else {
                    return Err(ControlError::NoMeasurement);
                };
                // At rest before the oldest sample (the classic padding).
                for back in [1.0, 2.0] {
                    let pad = PoseSample {
                        t: oldest.t - back * dt,
                        position: oldest.position,
                    };
                    if pad.t >= start - SNAP * dt && self.samples.len() < SAMPLE_CAPACITY {
                        let at = self.samples.partition_point(|s| s.t < pad.t);
                        self.samples.insert(at, pad);
                    }
                }
                self.next_trajectory.fill(oldest.position);
                self.next_inputs.fill(self.hover);
                self.next_arrival = Arrival {
                    mean: [oldest.position; 3],
                    cov: [diag(self.unknown); 3],
                };
            }
            Some(last) => {
                let n = ((t - last) / dt).round().clamp(1.0, m as f64) as usize;
                // Tick `last + i` (i = j + n − m ≥ 1, a tick skipped) had
                // the pending input i told, or the last one held.
                let held = self.inputs[m];
                let pending = &self.pending_inputs;
                for (j, u) in self.next_inputs.iter_mut().enumerate() {
                    *u = self.inputs.get(j + n).copied().unwrap_or_else(|| {
                        let i = j + n - m;
                        pending
                            .get(i - 1)
                            .or(pending.last())
                            .copied()
                            .unwrap_or(held)
                    });
                }
                self.next_trajectory[..3].copy_from_slice(&self.trajectory[n..n + 3]);
                self.advance_arrival(n, start - n as f64 * dt, &next_output)?;
            }
        }
        if self.axes == 2
            && let Some(newest) = self.samples.last()
        {
            // The planar model carries the altitude: the newest one.
            for y in self.next_trajectory[..3]
                .iter_mut()
                .chain(&mut self.next_arrival.mean)
            {
                y.z = newest.position.z;
            }
        }
        propagate(&mut self.next_trajectory, &self.next_inputs, &next_output)?;
        let fitted = self.fit(start);
        self.stats.fitted = fitted;
        if fitted == 0 {
            self.stats.blind_ticks += 1;
        }
        propagate(&mut self.next_trajectory, &self.next_inputs, &next_output)?;
        self.pending_tick = Some(t);
        Ok(MultiRateEstimate {
            fixed: [
                self.next_trajectory[m],
                self.next_trajectory[m + 1],
                self.next_trajectory[m + 2],
            ],
            previous_input: self.next_inputs[m - 1],
            fitted,
        })
    }

    /// The sensitivity row φ(pos) of one axis and the linear interpolation
    /// of `chain` at the fractional tick position `pos` ∈ [0, len − 2].
    fn row(&self, chain: &[Vector3<f64>], pos: f64, axis: usize) -> ([f64; 3], f64) {
        let last = chain.len() - 2;
        let j = (pos.floor() as usize).min(last);
        let alpha = pos - j as f64;
        let lerp = |a: f64, b: f64| {
            if alpha == 0.0 {
                a
            } else if alpha == 1.0 {
                b
            } else {
                a + alpha * (b - a)
            }
        };
        let g = lerp(self.gains[j][axis], self.gains[j + 1][axis]);
        ([1.0, pos, g], lerp(chain[j][axis], chain[j + 1][axis]))
    }

    /// Position of time `ts` on the tick grid starting at `t0`, snapped to
    /// a tick when within [`SNAP`].
    fn position(&self, ts: f64, t0: f64) -> f64 {
        let pos = (ts - t0) / self.dt;
        let nearest = pos.round();
        if (pos - nearest).abs() < SNAP {
            nearest
        } else {
            pos
        }
    }

    /// Moves the arrival cost from the old window start (time `t_old`) n
    /// steps on: Kalman updates with the samples in `[t_old, t_old + n·δt)`,
    /// the mean along the chain of the sent inputs, `P ← T·P·Tᵀ + n·Q`.
    fn advance_arrival<F>(&mut self, n: usize, t_old: f64, next_output: &F) -> Result<(), FlatError>
    where
        F: Fn(&[Vector3<f64>; 3], &Vector3<f64>) -> Result<Vector3<f64>, FlatError>,
    {
        let Some(q) = self.process else {
            // No arrival cost: the window alone (information stays zero).
            self.next_arrival = self.arrival;
            return Ok(());
        };
        let sigma2 = self.settings.sample_sigma.powi(2);
        let held = self.inputs[self.settings.fit_span];
        let chain = &mut self.chain[..n + 3];
        chain[..3].copy_from_slice(&self.arrival.mean);
        for j in 0..n {
            let u = self.inputs.get(j).copied().unwrap_or(held);
            chain[j + 3] = next_output(&[chain[j], chain[j + 1], chain[j + 2]], &u)?;
        }
        let mut cov = self.arrival.cov;
        let mut delta = [[0.0; 3]; 3];
        for s in &self.samples {
            let pos = self.position(s.t, t_old);
            if pos < -SNAP {
                continue;
            }
            if pos >= n as f64 {
                break;
            }
            let pos = pos.max(0.0);
            for axis in 0..self.axes {
                let (phi, y) = self.row(&self.chain[..n + 3], pos, axis);
                let p = &mut cov[axis];
                let d = &mut delta[axis];
                let e = s.position[axis] - y - dot(&phi, d);
                let pphi = mul(p, &phi);
                let var = dot(&phi, &pphi) + sigma2;
                for a in 0..3 {
                    d[a] += pphi[a] * e / var;
                    for b in 0..3 {
                        p[a][b] -= pphi[a] * pphi[b] / var;
                    }
                }
            }
        }
        // The updated mean at the old start, carried n steps.
        let chain = &mut self.chain[..n + 3];
        for axis in 0..self.axes {
            let [c, d, h] = delta[axis];
            chain[0][axis] = self.arrival.mean[0][axis] + c;
            chain[1][axis] = self.arrival.mean[1][axis] + c + d;
            chain[2][axis] = self.arrival.mean[2][axis] + c + 2.0 * d + h;
        }
        for j in 0..n {
            let u = self.inputs.get(j).copied().unwrap_or(held);
            chain[j + 3] = next_output(&[chain[j], chain[j + 1], chain[j + 2]], &u)?;
        }
        self.next_arrival.mean = [chain[n], chain[n + 1], chain[n + 2]];
        for (axis, p) in cov.iter_mut().enumerate().take(self.axes) {
            let g = &self.gains;
            let (gn, gn1, gn2) = (g[n][axis], g[n + 1][axis], g[n + 2][axis]);
            let t = [
                [1.0, n as f64, gn],
                [0.0, 1.0, gn1 - gn],
                [0.0, 0.0, gn2 - 2.0 * gn1 + gn],
            ];
            let mut tp = [[0.0; 3]; 3];
            for a in 0..3 {
                for b in 0..3 {
                    tp[a][b] = (0..3).map(|k| t[a][k] * p[k][b]).sum();
                }
            }
            for a in 0..3 {
                for b in 0..3 {
                    p[a][b] = (0..3).map(|k| tp[a][k] * t[b][k]).sum();
                }
                p[a][a] += n as f64 * q[a];
            }
            // No coordinate more uncertain than "no information": scale its
            // row and column down (keeps P positive definite); NaN restarts.
            for (a, &cap) in self.unknown.iter().enumerate() {
                if p[a][a] > cap {
                    let f = (cap / p[a][a]).sqrt();
                    for row in p.iter_mut() {
                        row[a] *= f;
                    }
                    for v in p[a].iter_mut() {
                        *v *= f;
                    }
                }
            }
            if p.iter().flatten().any(|v| !v.is_finite()) {
                *p = diag(self.unknown);
            }
        }
        self.next_arrival.cov = cov;
        Ok(())
    }

    /// One Gauss–Newton step of the window-start fit about the nominal
    /// chain in `next_trajectory` (window start at time `start`): samples in
    /// the window plus the arrival cost; corrects the first three outputs.
    /// Returns the number of samples fitted.
    fn fit(&mut self, start: f64) -> usize {
        let m = self.settings.fit_span;
        let w = self.settings.sample_sigma.powi(-2);
        let mut normal = [[[0.0; 3]; 3]; 3];
        let mut rhs = [[0.0; 3]; 3];
        let mut fitted = 0;
        for s in &self.samples {
            let pos = self.position(s.t, start);
            if pos < -SNAP {
                continue;
            }
            let pos = pos.clamp(0.0, m as f64);
            fitted += 1;
            for axis in 0..self.axes {
                let (phi, y) = self.row(&self.next_trajectory[..m + 1], pos, axis);
                let e = s.position[axis] - y;
                for a in 0..3 {
                    rhs[axis][a] += w * phi[a] * e;
                    for b in 0..3 {
                        normal[axis][a][b] += w * phi[a] * phi[b];
                    }
                }
            }
        }
        for axis in 0..self.axes {
            let mut n = normal[axis];
            let mut r = rhs[axis];
            if self.process.is_some() {
                // Arrival cost: (δ − Δ)ᵀ·P⁻¹·(δ − Δ), Δ = the arrival mean
                // relative to the nominal, in (c, d, h).
                let z = &self.next_trajectory;
                let a = &self.next_arrival.mean;
                let e0 = a[0][axis] - z[0][axis];
                let e1 = a[1][axis] - z[1][axis];
                let e2 = a[2][axis] - z[2][axis];
                let big_delta = [e0, e1 - e0, e2 - 2.0 * e1 + e0];
                if let Some(info) = inverse_spd3(&self.next_arrival.cov[axis]) {
                    let id = mul(&info, &big_delta);
                    for a in 0..3 {
                        r[a] += id[a];
                        for b in 0..3 {
                            n[a][b] += info[a][b];
                        }
                    }
                }
            }
            let Some([c, d, h]) = solve_spd3(n, r) else {
                continue;
            };
            let z = &mut self.next_trajectory;
            z[0][axis] += c;
            z[1][axis] += c + d;
            z[2][axis] += c + 2.0 * d + h;
        }
        fitted
    }

    /// Replaces the input of the last committed tick with `u` (the input
    /// actually applied, when it was not the one sent: standby). Before a
    /// commit it does nothing.
    pub fn replace_last_input(&mut self, u: &Vector3<f64>) {
        if self.last_tick.is_some() {
            let m = self.settings.fit_span;
            self.inputs[m] = *u;
        }
    }

    /// Tells the window the inputs in effect at the ticks after the last
    /// committed one, oldest first, when they are not the last input held:
    /// with an input delay of d ticks, the d inputs sent and not yet in
    /// effect (beyond them the newest repeats, as the autopilot holds it).
    /// A tick the shell skipped is estimated under them; at most
    /// [`PENDING_INPUTS`] are kept. The next [`MultiRateWindow::commit`]
    /// forgets them.
    pub fn set_pending_inputs(&mut self, inputs: &[Vector3<f64>]) {
        self.pending_inputs.clear();
        self.pending_inputs
            .extend_from_slice(&inputs[..inputs.len().min(PENDING_INPUTS)]);
    }

    /// Records the input `u` in effect at the tick last estimated (the one
    /// sent, or with an input delay the one sent d ticks before) and makes
    /// that estimate the window's: forgets the samples now in the arrival
    /// cost and the pending inputs told. Without a pending estimate it does
    /// nothing.
    pub fn commit(&mut self, u: &Vector3<f64>) {
        let Some(t) = self.pending_tick.take() else {
            return;
        };
        self.pending_inputs.clear();
        std::mem::swap(&mut self.trajectory, &mut self.next_trajectory);
        let m = self.settings.fit_span;
        self.inputs[..m].copy_from_slice(&self.next_inputs);
        self.inputs[m] = *u;
        self.arrival = self.next_arrival;
        self.last_tick = Some(t);
        let start = t - m as f64 * self.dt;
        let dt = self.dt;
        self.samples.retain(|s| s.t >= start - SNAP * dt);
    }
}

fn diag(d: [f64; 3]) -> M3 {
    [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn mul(m: &M3, v: &[f64; 3]) -> [f64; 3] {
    [dot(&m[0], v), dot(&m[1], v), dot(&m[2], v)]
}

/// Chains F⁻¹ over the window: `y[j + 3] = F⁻¹(y[j..j + 3], u[j])`.
fn propagate<F>(
    y: &mut [Vector3<f64>],
    u: &[Vector3<f64>],
    next_output: &F,
) -> Result<(), FlatError>
where
    F: Fn(&[Vector3<f64>; 3], &Vector3<f64>) -> Result<Vector3<f64>, FlatError>,
{
    for (j, uj) in u.iter().enumerate() {
        y[j + 3] = next_output(&[y[j], y[j + 1], y[j + 2]], uj)?;
    }
    Ok(())
}

/// Cholesky factor of a 3×3 SPD matrix (lower), with a relative ridge of
/// 1e-10 when (near-)singular; None for non-finite data.
#[allow(clippy::needless_range_loop)] // dense 3×3 index arithmetic
fn cholesky3(n: &M3) -> Option<M3> {
    let scale = n[0][0].max(n[1][1]).max(n[2][2]);
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let chol = |ridge: f64| -> Option<M3> {
        let mut l = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..=i {
                let mut s = n[i][j] + if i == j { ridge } else { 0.0 };
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                if i == j {
                    if s.is_nan() || s <= 1e-12 * scale {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(l)
    };
    chol(0.0).or_else(|| chol(1e-10 * scale))
}

/// Solves `L·Lᵀ·x = r`.
#[allow(clippy::needless_range_loop)] // dense 3×3 index arithmetic
fn cholesky_solve(l: &M3, r: [f64; 3]) -> [f64; 3] {
    let mut x = r;
    for i in 0..3 {
        for k in 0..i {
            x[i] -= l[i][k] * x[k];
        }
        x[i] /= l[i][i];
    }
    for i in (0..3).rev() {
        for k in i + 1..3 {
            x[i] -= l[k][i] * x[k];
        }
        x[i] /= l[i][i];
    }
    x
}

/// Solves the 3×3 SPD system `n·x = r`; None only for non-finite data.
fn solve_spd3(n: M3, r: [f64; 3]) -> Option<[f64; 3]> {
    let x = cholesky_solve(&cholesky3(&n)?, r);
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Inverse of a 3×3 SPD matrix.
fn inverse_spd3(p: &M3) -> Option<M3> {
    let l = cholesky3(p)?;
    let mut inv = [[0.0; 3]; 3];
    for c in 0..3 {
        let mut e = [0.0; 3];
        e[c] = 1.0;
        let col = cholesky_solve(&l, e);
        for r in 0..3 {
            inv[r][c] = col[r];
        }
    }
    inv.iter().flatten().all(|v| v.is_finite()).then_some(inv)
}
