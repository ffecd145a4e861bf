//! Offset-free tracking: estimation of slowly varying disturbances from the
//! window of measured outputs and sent inputs.
//!
//! The DF-MPC of the paper has no integral action: wind, drag, a wrong mass
//! or hover thrust leave a steady-state error. The data the controller keeps
//! anyway — measured positions and the inputs it sent — show that error
//! directly: it is the part of the measured motion that the model does not
//! explain from the inputs. [`DisturbanceEstimator`] measures it and
//! [`crate::dfmpc::DfMpc`] adds it to the model used by the input-to-output
//! map F⁻¹ (the prediction of y_{k+1}, y_{k+2} from past inputs) and the
//! output-to-input map F (the command), see
//! [`crate::ControlModel::next_output_disturbed`]. Pure, deterministic, all
//! buffers sized in [`DisturbanceEstimator::new`]; no allocation per tick.
//!
//! # What is estimated
//!
//! The control model's Euler step with a constant acceleration offset d
//! \[m/s²\] (model frame, local NED for flight) and a thrust scale κ \[-\]
//! (actual specific thrust = κ · the model's):
//!
//! ```text
//! y_{k+1} = y_k + δt·v_k,   v_{k+1} = v_k + δt·(a_g(s_k) + κ·a_T(s_k) + d)
//! s_{k+1} = step(s_k, u_k)          s = [θ, φ, T]: the model's input dynamics
//! ```
//!
//! * **planar model**: d_x, d_y (wind, drag, attitude bias); `a_T = 0`.
//! * **spatial model**: d_x, d_y, and κ from the vertical channel (mass,
//!   hover thrust, battery sag): κ and a vertical offset are the same thing
//!   at hover, the scale also corrects the thrust's horizontal share when
//!   tilted. The hover thrust is `g/κ` \[m/s²\] in the model's thrust units
//!   ([`DisturbanceEstimate::hover_thrust`]); normalised by the autopilot's
//!   thrust range it is PX4's hover-thrust estimate. d_z stays 0.
//!
//! # How: a window fit, then a low-pass
//!
//! The estimator runs the model's input dynamics `s_{k+1} = step(s_k, u_k)`
//! on the *sent* inputs (a stable first-order filter: no measurement enters
//! it, so no noise), and keeps the last L measured outputs `y^m_j` with the
//! model's accelerations `a_j = a_g(s_j) + κ̂·a_T(s_j)`, j = 0..L−1 oldest
//! first. Double-integrating the model accelerations from rest,
//! `S_0 = S_1 = 0`, `S_j = δt²·Σ_{i≤j−2} (j−1−i)·a_i`, the measured
//! positions of the disturbed model are exactly
//!
//! ```text
//! y^m_j = p_0 + v_0·jδt + S_j + δ·c_j + n_j,    c_j = δt²·j(j−1)/2
//! ```
//!
//! with the unknown initial position p_0 and velocity v_0, the unexplained
//! acceleration δ and the measurement noise n_j. Per axis, the least-squares
//! fit of (p_0, v_0, δ) to the residual `r_j = y^m_j − S_j` is linear with a
//! fixed design matrix, so `δ̂ = Σ_j h_j·r_j` with weights h precomputed once
//! (`Σh_j = 0`, `Σh_j·j = 0`: blind to position and velocity). Then, with
//! `α = 1 − exp(−2π·f_c·δt)` for the bandwidth f_c \[Hz\]:
//!
//! ```text
//! d̂ ← clamp(d̂ + α·(δ̂ − d̂))                      (x, y: δ̂ is the whole offset)
//! κ̂ ← clamp(κ̂ + α·δ̂_z / mean_j(a_T,z,j))         (spatial z: δ̂_z = (κ − κ̂)·a_T,z)
//! ```
//!
//! For the plant equal to the model with a constant d and κ the fit is
//! exact whatever the inputs were, so d̂ and κ̂ converge as a first-order lag
//! with time constant 1/(2π f_c) after the window delay; the estimate does
//! not depend on the controller (no loop is closed through it).
//!
//! # Drag
//!
//! With the model's linear drag D (`ControlModel::drag`) the velocity
//! decays by `β = 1 − D·δt` per tick and the double integral and the
//! regressors of v_0 and δ decay with it (`drag.rs`); the fit stays linear
//! and exact for the plant equal to the model, with weights h per axis. With
//! D = 0 the plain fit below runs unchanged. The noise gains reported are
//! the drag-free ones (at D·T ≪ 1 they differ little).
//!
//! # Noise gain
//!
//! With white position noise of standard deviation σ, the fit gives
//! `std(δ̂) = σ·√(Σ h_j²)` (about `σ·√(720/(L·T⁴))` for a window of
//! T = L·δt seconds), and the low-pass
//!
//! ```text
//! std(d̂) = σ·G,   G² = α²/(1 − β²) · Σ_{|s|<L} β^|s|·Σ_j h_j·h_{j+|s|},   β = 1 − α
//! ```
//!
//! ([`DisturbanceEstimator::noise_gain`], [`DisturbanceEstimator::fit_noise_gain`]).
//! At the defaults δt = 0.02 s, L = 50 (1 s), f_c = 0.1 Hz: `√Σh² = 3.8 s⁻²`
//! and G = 0.36 s⁻²: σ = 1 cm gives std(d̂) = 0.0036 m/s² (0.02° of tilt)
//! and std(κ̂) ≈ G·σ/g = 0.0004. The one-step residual `Δ²y/δt²` instead
//! has gain `√6/δt² ≈ 6100 s⁻²` (61 m/s² at σ = 1 cm) and still ≈ 490 s⁻²
//! after the same low-pass: 1300 times more. Other settings (G in s⁻²):
//!
//! | L, f_c | 0.1 Hz | 0.2 Hz | 0.5 Hz | 1 Hz |
//! |---------|--------|--------|--------|------|
//! | 25      | 1.05   | 2.07   | 4.92   | 8.71 |
//! | 50      | 0.36   | 0.70   | 1.53   | 2.35 |
//! | 100     | 0.12   | 0.23   | 0.41   | 0.53 |
//!
//! The unit test `noise_gain_matches_monte_carlo` checks G by simulation.
//!
//! # Multi-rate mode: timestamped samples
//!
//! With DF-MPC's multi-rate windows ([`crate::window::MultiRateWindow`])
//! the poses arrive as timestamped samples, not one per tick. The
//! estimator then works from those samples, never from the window's
//! estimate of y_k (that estimate is a chain of the model with the current
//! d̂, κ̂: fitting it would partly fit the estimator's own prediction and
//! slow or bias it). The controller hands every sample to
//! [`DisturbanceEstimator::observe`] (capture time t_i, position) and
//! records each tick with [`DisturbanceEstimator::record_input`] (tick time,
//! input sent). The fit is the same least squares with the samples at
//! their fractional tick positions `τ_i = (t_i − t_0)/δt` in the window
//! (t_0 the oldest tick of the window, samples outside `[t_0, t_k]`
//! ignored), `S(τ)` and `c(τ)` interpolated linearly between the ticks (as
//! the multi-rate window does): a 3×3 normal system per tick, O(L +
//! samples), no allocation (the samples live in a ring of
//! [`SAMPLES_PER_TICK`]·L). With one sample exactly at every tick it is the
//! tick fit above, the same weights h and the same noise gain; with n_s
//! samples per second instead of 1/δt, `std(δ̂)` grows by about
//! `√(1/(n_s·δt))` (×1.8 at 15 Hz). Latency costs nothing but delay: the
//! newest ticks simply have no samples yet. The fit is skipped (estimate
//! held, status `Filling`) with fewer than three samples or none in the
//! first or the last third of the window (a dropout). Missed ticks (tick
//! time more than δt after the last) step the input dynamics with the held
//! input and restart the window.
//!
//! Bandwidth and window: the defaults (0.1 Hz, L = 50) are kept for both
//! modes. At σ = 1 cm the estimate's noise (0.0036 m/s², ≈ 0.02° of tilt;
//! κ̂ ± 0.0004) is far below what the plan passes on anyway, and
//! `dflat experiment mismatch` meets its budgets with them (multi-rate DF
//! with the estimator ≤ 0.9 cm steady-state error in every scenario at
//! σ = 1 cm; noise-sweep error within 0.3 % of DF without it); a higher
//! bandwidth mostly amplifies the phantom disturbance of k̃/τ mismatches
//! during manoeuvres (see [`DisturbanceSettings::bandwidth_hz`]).
//!
//! # Guards
//!
//! * **bounded**: d̂ clamped to ±`max_acceleration` per axis, κ̂ to
//!   `thrust_scale_range` (anti-windup: a clamped estimate recovers at once
//!   when the disturbance drops).
//! * **frozen while saturated**: a tick whose command was clipped updates
//!   the buffers but not the estimate.
//! * **pose jumps**: a measured step larger than `max_step` \[m\] between two
//!   consecutive ticks (faster than the vehicle can fly) resets the estimate
//!   and restarts the window (a re-initialised pose source; data across the
//!   jump is not the vehicle's motion). Multi-rate: between consecutive
//!   samples, `max_step` per control step elapsed (at least one); the
//!   samples before the jump are forgotten.
//! * **reset** ([`DisturbanceEstimator::reset`], the controller's reset,
//!   i.e. failsafe): everything back to the initial state.
//! * **gaps**: a tick that did not record (controller error) restarts the
//!   window; non-finite data or a singular attitude restarts it too.
//! * **settling**: after a reset the input dynamics start at hover; the
//!   window starts filling only after `5·max(τ, τ_T)` so that start is
//!   forgotten. The first estimate comes L ticks later.

use nalgebra::Vector3;

use crate::ControlError;
use crate::model::ControlModel;
/// The estimate's type lives with the maps that use it ([`crate::model`]).
pub use crate::model::DisturbanceEstimate;

mod report;
mod settings;
pub use report::*;
use settings::invalid;
pub use settings::*;

/// The disturbance estimator (see the module docs).
///
/// Protocol, once per control tick: [`DisturbanceEstimator::begin_tick`]
/// before the controller's update, [`DisturbanceEstimator::estimate`] for
/// the maps, then, when the tick succeeded,
/// [`DisturbanceEstimator::record`] with the measurement and the input sent
/// (classic mode) or [`DisturbanceEstimator::record_input`] with the tick
/// time and the input sent (multi-rate mode, the samples given to
/// [`DisturbanceEstimator::observe`] as they arrive).
#[derive(Debug, Clone)]
pub struct DisturbanceEstimator {
    model: ControlModel,
    settings: DisturbanceSettings,
    /// Low-pass coefficient α.
    alpha: f64,
    /// Fit weights h_j, j = 0..L−1 oldest first \[1/s²\].
    weights: Vec<f64>,
    /// The per-axis basis and weights of the fit with the model's drag.
    drag: DragBasis,
    /// √Σh² \[1/s²\].
    fit_gain: f64,
    /// std(d̂)/σ \[1/s²\].
    noise_gain: f64,
    /// Ticks of input dynamics needed after a reset.
    settle_ticks: usize,

    estimate: DisturbanceEstimate,
    /// The model's input-driven state \[θ, φ, T\] at the next recorded tick.
    state: Vector3<f64>,
    /// `state` before the last recorded input was applied (for
    /// [`DisturbanceEstimator::correct_last_input`]).
    state_before_last: Vector3<f64>,
    /// Ticks recorded since the last reset (saturating).
    settled: usize,
    /// Ring buffers (L each), oldest at `head` once full.
    outputs: Vec<Vector3<f64>>,
    accel_g: Vec<Vector3<f64>>,
    accel_t: Vec<Vector3<f64>>,
    head: usize,
    len: usize,
    /// The previous recorded measurement (jump detection).
    last: Option<Vector3<f64>>,
    /// Multi-rate mode: the last ticks came through
    /// [`DisturbanceEstimator::record_input`] and the fit uses `samples`.
    timed: bool,
    /// Multi-rate mode: tick times of the window slots \[s\] (parallel to
    /// `accel_g`).
    tick_times: Vec<f64>,
    /// Multi-rate mode: timestamped pose samples, a ring of
    /// [`SAMPLES_PER_TICK`]·L, oldest at `sample_head`.
    samples: Vec<(f64, Vector3<f64>)>,
    sample_head: usize,
    sample_len: usize,
    /// Multi-rate mode: the newest sample (jump detection).
    last_sample: Option<(f64, Vector3<f64>)>,
    /// Multi-rate mode: time \[s\] and input of the last recorded tick.
    last_tick: Option<(f64, Vector3<f64>)>,
    /// Scratch: the model's double integral S_j at the window ticks.
    integral: Vec<Vector3<f64>>,
    /// A tick has begun and not recorded yet.
    open: bool,
    status: EstimatorStatus,
    clamped: bool,
    jumps: u64,
}

impl DisturbanceEstimator {
    /// Builds the estimator for `model` (all allocation happens here).
    /// Errors name an invalid setting; the bandwidth must be in
    /// [`DisturbanceSettings::bandwidth_limit`] of the model's δt.
    pub fn new(model: ControlModel, settings: DisturbanceSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let dt = model.dt();
        DisturbanceSettings::bandwidth_limit(dt)
            .check("disturbance.bandwidth_hz", settings.bandwidth_hz)?;
        let l = settings.fit_span;
        let weights = fit_weights(l, dt)
            .ok_or_else(|| invalid("disturbance.fit_span", "too short for the fit"))?;
        let alpha = 1.0 - (-2.0 * std::f64::consts::PI * settings.bandwidth_hz * dt).exp();
        let drag = DragBasis::new(model.drag(), l, dt)
            .ok_or_else(|| invalid("disturbance.fit_span", "too short for the fit"))?;
        let fit_gain = weights.iter().map(|h| h * h).sum::<f64>().sqrt();
        let noise_gain = low_pass_noise_gain(&weights, alpha);
        let slowest = match &model {
            ControlModel::Planar(m) => m.params().tau,
            ControlModel::Spatial(m) => m.params().tau.max(m.params().tau_thrust),
        };
        let settle_ticks = (5.0 * slowest / dt).ceil() as usize;
        Ok(Self {
            model,
            settings,
            alpha,
            weights,
            drag,
            fit_gain,
            noise_gain,
            settle_ticks,
            estimate: DisturbanceEstimate::NOMINAL,
            state: model.hover_input(),
            state_before_last: model.hover_input(),
            settled: 0,
            outputs: vec![Vector3::zeros(); l],
            accel_g: vec![Vector3::zeros(); l],
            accel_t: vec![Vector3::zeros(); l],
            head: 0,
            len: 0,
            last: None,
            timed: false,
            tick_times: vec![0.0; l],
            samples: vec![(0.0, Vector3::zeros()); SAMPLES_PER_TICK * l],
            sample_head: 0,
            sample_len: 0,
            last_sample: None,
            last_tick: None,
            integral: vec![Vector3::zeros(); l],
            open: false,
            status: EstimatorStatus::Settling,
            clamped: false,
            jumps: 0,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &DisturbanceSettings {
        &self.settings
    }

    /// The current estimate (d̂ \[m/s²\] model frame, κ̂).
    pub fn estimate(&self) -> DisturbanceEstimate {
        self.estimate
    }

    /// Hover specific thrust g/κ̂ \[m/s²\] in the model's thrust units.
    pub fn hover_thrust(&self) -> f64 {
        self.estimate.hover_thrust(self.model.gravity())
    }

    /// A snapshot for logs and telemetry.
    pub fn report(&self) -> DisturbanceReport {
        let a = self.estimate.acceleration;
        DisturbanceReport {
            acceleration: [a.x, a.y, a.z],
            thrust_scale: self.estimate.thrust_scale,
            hover_thrust: self.hover_thrust(),
            status: self.status,
            clamped: self.clamped,
            jumps: self.jumps,
        }
    }

    /// What happened at the last recorded tick.
    pub fn status(&self) -> EstimatorStatus {
        self.status
    }

    /// True when the last update hit a clamp (the estimate is at a bound).
    pub fn clamped(&self) -> bool {
        self.clamped
    }

    /// Pose jumps detected since construction (each reset the estimate).
    pub fn jumps(&self) -> u64 {
        self.jumps
    }

    /// Low-pass coefficient α = 1 − exp(−2π·f_c·δt) \[-\].
    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// Noise gain of the window fit alone, `std(δ̂)/σ = √Σh²` \[1/s²\], for
    /// white position noise of standard deviation σ \[m\].
    pub fn fit_noise_gain(&self) -> f64 {
        self.fit_gain
    }

    /// Noise gain of the estimate, `std(d̂)/σ` \[1/s²\], for white position
    /// noise of standard deviation σ \[m\] (plant = model; module docs).
    pub fn noise_gain(&self) -> f64 {
        self.noise_gain
    }

    /// The last recorded input was not the one applied (standby): the
    /// estimator's input-driven state is re-stepped with `u`, the input
    /// that explains the measured attitude. Non-finite `u` is ignored.
    pub fn correct_last_input(&mut self, u: &Vector3<f64>) {
        if u.iter().all(|v| v.is_finite()) {
            self.state = self.model.input_state_step(&self.state_before_last, u);
            if let Some((t, _)) = self.last_tick {
                self.last_tick = Some((t, *u));
            }
        }
    }

    /// Marks the start of a control tick: if the previous tick began but
    /// did not [`record`](Self::record) (a controller error; the vehicle
    /// flew a command this estimator did not see), the window restarts.
    pub fn begin_tick(&mut self) {
        if self.open {
            self.restart_window();
        }
        self.open = true;
    }

    /// Forgets everything (controller reset, failsafe): nominal estimate,
    /// input dynamics at hover, empty window.
    pub fn reset(&mut self) {
        self.estimate = DisturbanceEstimate::NOMINAL;
        self.state = self.model.hover_input();
        self.state_before_last = self.state;
        self.settled = 0;
        self.last = None;
        self.last_sample = None;
        self.last_tick = None;
        self.sample_head = 0;
        self.sample_len = 0;
        self.open = false;
        self.status = EstimatorStatus::Settling;
        self.clamped = false;
        self.restart_window();
    }

    /// Ticks went unrecorded (a stall longer than the classic window's
    /// slots): the window of consecutive ticks starts again and the pose
    /// jump check has no tick before the next one, the estimate kept.
    pub fn after_gap(&mut self) {
        self.restart_window();
        self.last = None;
    }

    fn restart_window(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// Records one successful tick (classic mode, one measurement per
    /// tick): the measured output `y` \[m\] (model frame) at the tick, the
    /// input `u = [θ_cmd, φ_cmd, T_cmd]` sent at it, and whether that input
    /// was clipped by saturation. Updates the estimate when the window is
    /// full and the input was not clipped.
    pub fn record(&mut self, y: &Vector3<f64>, u: &Vector3<f64>, saturated: bool) {
        self.open = false;
        let axes = self.model.axes();
        if self.timed {
            // Switching from multi-rate ticks: the window holds no outputs.
            self.timed = false;
            self.restart_window();
        }
        if !(y.iter().take(axes).all(|v| v.is_finite()) && u.iter().all(|v| v.is_finite())) {
            self.restart_window();
            self.status = EstimatorStatus::Filling;
            return;
        }
        if let Some(prev) = self.last {
            let step = (0..axes)
                .map(|i| (y[i] - prev[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            if step > self.settings.max_step {
                self.jump();
            }
        }
        self.last = Some(*y);
        self.push_tick(y, 0.0, u, saturated);
    }

    /// Multi-rate mode: one pose sample measured at time `t` \[s\] (the
    /// clock of the tick times) at `y` \[m\] (model frame), as the shell
    /// hands it to [`crate::Controller::observe`]. Samples may arrive late
    /// and out of order; non-finite ones are dropped. A step from the
    /// newest sample larger than `max_step` per control step elapsed (at
    /// least one) is a pose jump: the estimate resets and older samples are
    /// forgotten.
    pub fn observe(&mut self, t: f64, y: &Vector3<f64>) {
        let axes = self.model.axes();
        if !(t.is_finite() && y.iter().take(axes).all(|v| v.is_finite())) {
            return;
        }
        match self.last_sample {
            Some((tp, yp)) if t > tp => {
                let ticks = ((t - tp) / self.model.dt()).max(1.0);
                let step = (0..axes)
                    .map(|i| (y[i] - yp[i]).powi(2))
                    .sum::<f64>()
                    .sqrt();
                if step > self.settings.max_step * ticks {
                    self.jump();
                    self.sample_head = 0;
                    self.sample_len = 0;
                }
                self.last_sample = Some((t, *y));
            }
            Some(_) => {}
            None => self.last_sample = Some((t, *y)),
        }
        let cap = self.samples.len();
        let slot = (self.sample_head + self.sample_len) % cap;
        self.samples[slot] = (t, *y);
        if self.sample_len < cap {
            self.sample_len += 1;
        } else {
            self.sample_head = (self.sample_head + 1) % cap;
        }
    }

    /// Records one successful tick in multi-rate mode: the tick time `t`
    /// \[s\], the input `u` sent at it and whether it was clipped. The fit
    /// uses the samples given to [`observe`](Self::observe) whose times lie
    /// in the window's span of tick times (never the controller's own
    /// estimate of the outputs). A tick more than one and a half steps
    /// after the previous one (missed ticks: the shell held the last input)
    /// steps the input dynamics with that input and restarts the window; so
    /// does one less than half a step after it. A tick within half a step
    /// of its time (a late pose's deadline tick, jitter) keeps the window:
    /// restarting there (the rule was ±¼ step until 2026-11-29) starved the
    /// fit under load — 150–270 deadline ticks in a 16 s hover beside eight
    /// busy loops left the hover sag 0.2–1.2 m after 13 s, against 0.001 m
    /// with the window kept (`tests/e2e_px4_config.rs`).
    pub fn record_input(&mut self, t: f64, u: &Vector3<f64>, saturated: bool) {
        self.open = false;
        if !self.timed {
            self.timed = true;
            self.restart_window();
        }
        if !(t.is_finite() && u.iter().all(|v| v.is_finite())) {
            self.restart_window();
            self.status = EstimatorStatus::Filling;
            return;
        }
        let dt = self.model.dt();
        if let Some((tl, ul)) = self.last_tick {
            let n = ((t - tl) / dt).round();
            if n != 1.0 {
                self.restart_window();
                // The held input, at most until the start is forgotten.
                let held = (n.max(1.0) - 1.0).min(self.settle_ticks as f64) as usize;
                for _ in 0..held {
                    self.state = self.model.input_state_step(&self.state, &ul);
                }
            }
        }
        self.last_tick = Some((t, *u));
        self.push_tick(&Vector3::zeros(), t, u, saturated);
    }

    /// A pose jump: nominal estimate, window restarted.
    fn jump(&mut self) {
        self.jumps += 1;
        self.estimate = DisturbanceEstimate::NOMINAL;
        self.clamped = false;
        self.restart_window();
    }

    /// The common part of a recorded tick: the model's acceleration at this
    /// tick's input-driven state, that state stepped with the input sent
    /// now, the window buffers, and the update.
    fn push_tick(&mut self, y: &Vector3<f64>, t: f64, u: &Vector3<f64>, saturated: bool) {
        let parts = self.model.acceleration_parts(&self.state);
        self.state_before_last = self.state;
        self.state = self.model.input_state_step(&self.state, u);
        let Ok((a_g, a_t)) = parts else {
            self.restart_window();
            self.status = EstimatorStatus::Filling;
            return;
        };
        if self.settled < self.settle_ticks {
            self.settled += 1;
            self.status = EstimatorStatus::Settling;
            return;
        }

        let l = self.settings.fit_span;
        let slot = (self.head + self.len) % l;
        self.outputs[slot] = *y;
        self.tick_times[slot] = t;
        self.accel_g[slot] = a_g;
        self.accel_t[slot] = a_t;
        if self.len < l {
            self.len += 1;
        } else {
            self.head = (self.head + 1) % l;
        }
        if self.len < l {
            self.status = EstimatorStatus::Filling;
            return;
        }
        if saturated {
            self.status = EstimatorStatus::Frozen;
            return;
        }
        let delta = if self.timed {
            self.sample_fit()
        } else {
            Some(self.tick_fit())
        };
        match delta {
            Some(delta) => {
                self.update(&delta);
                self.status = EstimatorStatus::Tracking;
            }
            // Too few samples in the window (a dropout): hold.
            None => self.status = EstimatorStatus::Filling,
        }
    }

    /// The window fit and the low-pass (module docs).
    fn update(&mut self, delta: &Vector3<f64>) {
        let l = self.settings.fit_span;
        let kappa = self.estimate.thrust_scale;
        let thrust_z = self.accel_t.iter().map(|a| a.z).sum::<f64>() / l as f64;

        let a = self.alpha;
        let lim = self.settings.max_acceleration;
        let mut clamped = false;
        let mut d = self.estimate.acceleration;
        for i in 0..2 {
            let v = d[i] + a * (delta[i] - d[i]);
            d[i] = v.clamp(-lim, lim);
            clamped |= d[i] != v;
        }
        let mut k = kappa;
        if let ControlModel::Spatial(_) = self.model
            && thrust_z.abs() > 0.5 * self.model.gravity()
        {
            let v = kappa + a * delta.z / thrust_z;
            let [lo, hi] = self.settings.thrust_scale_range;
            k = v.clamp(lo, hi);
            clamped |= k != v;
        }
        if d.iter().all(|v| v.is_finite()) && k.is_finite() {
            self.estimate = DisturbanceEstimate {
                acceleration: d,
                thrust_scale: k,
            };
        }
        self.clamped = clamped;
    }
}

mod drag;
mod fit;
use drag::DragBasis;
use fit::{fit_weights, low_pass_noise_gain, weights_of_rows};

#[cfg(test)]
mod tests;
