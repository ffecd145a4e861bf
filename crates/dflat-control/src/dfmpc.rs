//! The discrete-flatness MPC (DF-MPC) of *Fly Out The Window*, §IV-C and §V.
//!
//! # The problem solved at tick k
//!
//! Per position axis (x, y; and z for the spatial model), over the output
//! trajectory `y_k..y_{k+N}` (horizon N, control step δt):
//!
//! ```text
//! minimise   Σ_{j=0..N} q·(y_{k+j} − y_ref,{k+j})²  +  Σ_{j=0..N−3} r·(Δ³y_{k+j}/δt³)²
//!            Δ³y_j = y_{j+3} − 3y_{j+2} + 3y_{j+1} − y_j          (jerk × δt³)
//! subject to y_k = y^m_k                                 (newest measurement)
//!            y_{k+1}, y_{k+2} = F⁻¹ chained over the window (paper eq. input_to_output)
//!            and, when configured (all optional):
//!            |Δ²y_j/δt²| ≤ g·tan(tilt_max)     j = 1..N−2, horizontal axes
//!            a_min ≤ Δ²z_j/δt² ≤ a_max          j = 1..N−2, vertical axis (spatial)
//!            |Δy_j/δt| ≤ v_max                   j = 2..N−1, every axis
//! ```
//!
//! The paper weights the raw third difference with R; here r weights the
//! jerk, `R = r/δt⁶` (the paper's R = 1.25e9 at δt = 0.02 s is r = 0.08), so
//! weights are O(0.01–1). Then `u_k = F(y*_k..y*_{k+3})`, saturated, is sent
//! and recorded in the [`Window`].
//!
//! # How it is solved
//!
//! With the three fixed outputs eliminated, the n = N − 2 free outputs enter
//! a banded SPD system (half-bandwidth 3): `(q·I + r/δt⁶·DᵀD)·p = q·(y_ref − b)`
//! where D is the (square, lower-triangular) third-difference matrix and `p`
//! the deviation of the free outputs from the *baseline* `b`: the fixed
//! outputs continued with zero jerk (`b_j = y_k + j·Δy_k + j(j−1)/2·Δ²y_k`).
//! The baseline has no third difference, so the right-hand side is formed
//! without cancellation. The Hessian is factored once in [`AxisSolver::new`]
//! (banded Cholesky, [`crate::banded`]); each tick is one O(N) banded solve
//! plus one step of iterative refinement whose residual is evaluated by
//! repeated differencing, never with the assembled Hessian. That matters:
//! the Hessian's condition number is near 1e11 for the paper's weights, a
//! plain solve leaves ~1e-11 m in y*_{k+3} (≈ 3e-8 rad in the command, the
//! command is ≈ 2500 rad per metre of y*_{k+3}), the refined solve is within
//! ~1e-17 m of the exact optimum. x and y share one factor when their
//! weights are equal and are solved together ([`AxisSolver::solve_pair`]).
//! This fast path allocates nothing.
//!
//! When inequality constraints are configured and the fast plan violates
//! one, the axis is re-solved in the same deviation variables plus the
//! planned accelerations (cost `q·(b + p − y_ref)² + r·(Δã/δt)²`, equality
//! rows tie ã to Δ²p/δt², bounds on ã are single-entry rows): a
//! well-scaled QP (the raw one in p alone has a Hessian condition number
//! near 1e10). By default ([`QpSolver::Banded`]) with a primal-dual
//! interior-point method on its KKT system ordered by stage, which is
//! banded ([`crate::stage_qp`], [`BoundedAxisSolver`]): O(N) per iteration,
//! 2–3× faster than clarabel here (`examples/kkt_tuning.rs`). If it does
//! not converge, clarabel ([`ConstrainedAxisSolver`]) solves the same QP:
//! its structure is fixed,
//! so one solver per axis is built once and only `q` and `b` are updated
//! per tick. A clarabel status other than `Solved` is
//! [`ControlError::Solver`].
//!
//! # Command smoothness (optional)
//!
//! With [`DfMpcSettings::smoothness_weight`] s > 0 on an axis, the cost also
//! weighs the change of the commanded attitude between ticks, linearised
//! through the output-to-input map about hover. Per axis the command asks
//! for the acceleration the attitude settles to,
//!
//! ```text
//! c_j = a_j + κ·(a_{j+1} − a_j),   a_j = Δ²y_j/δt²,   κ = τ/δt
//! ```
//!
//! (F linearised: `θ_cmd = (θ_j + κ·(θ_{j+1} − θ_j))/k̃`, and tilt ≈
//! acceleration/g; for z of the spatial model κ = τ_T/δt and the thrust).
//! The added cost is
//!
//! ```text
//! Σ_{j=0..N−3} s·((c_j − c_{j−1})/g)²,   c_{−1} = acceleration the command SENT at k−1 asks for
//! ```
//!
//! (≈ s·Δθ_cmd² \[rad²\] per tick; the first term ties the plan to the
//! command actually sent, after saturation). In the free outputs this is
//! `‖E·p + e‖²` with `E = T·D`, `T = κ·I + (1 − κ)·S` (S the one-step
//! delay, D the third-difference matrix above): the Hessian becomes
//! `q·I + Dᵀ(w·I + s'·TᵀT)·D`, half-bandwidth 4 instead of 3, still
//! factored once and solved in O(N), the residual still evaluated by
//! differencing. The sent command enters only the right-hand side (first
//! free output). Linearising about hover keeps the Hessian constant; at
//! 35° the true Δθ is ~0.67 times the linearised one (a milder weight at
//! large tilt). Default off: the paper's problem is unchanged. The clarabel
//! path carries the same term (band 2 in the acceleration variables).
//!
//! # Multi-rate windows (optional)
//!
//! With [`DfMpcSettings::multi_rate`] the fixed outputs `y_k, y_{k+1},
//! y_{k+2}` come from a [`MultiRateWindow`]: timestamped pose samples
//! (vision at 10–35 Hz, latency, dropouts) fitted by a chain of F⁻¹ through
//! the inputs sent over the last M ticks (maths in [`crate::window`]). The
//! shell calls [`Controller::observe`] per sample and [`Controller::update`]
//! per tick with the tick time. Everything after the fixed outputs is as
//! above.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::banded::{BandedCholesky, SymBand};
use crate::disturbance::{DisturbanceEstimate, DisturbanceEstimator, DisturbanceSettings};
use crate::model::ControlModel;
use crate::stage_qp::StageQp;
use crate::window::{MultiRateSettings, MultiRateWindow, Window, input_lags};
use crate::{
    ControlError, Controller, Measurement, ReferenceSource, TickOutput, TiltLimit, limit_tilt,
};

/// Coefficients of the third difference `Δ³y_j` on `y_j..y_{j+3}`.
const D3: [f64; 4] = [-1.0, 3.0, -3.0, 1.0];
/// Half-bandwidth of the fast-path Hessian.
const BANDWIDTH: usize = 3;
/// Largest horizon accepted \[steps\].
pub const MAX_HORIZON: usize = 100_000;
/// Most ticks [`Controller::plan_fallback`] flies the last good plan (and
/// at most N − 3: the plan's end).
pub const MAX_FALLBACK_STEPS: usize = 50;

// ---------------------------------------------------------------------------
// Settings
// ---------------------------------------------------------------------------

/// Input saturation applied to the command after the output-to-input map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputSaturation {
    /// Tilt limit of the pitch / roll command \[rad\], applied as
    /// `tilt_limit` says. Default 35° (the DJI SDK limit).
    pub max_tilt: f64,
    /// How `max_tilt` applies: each channel clipped (default, the paper) or
    /// the combined tilt bounded ([`TiltLimit::Cone`], the daemon).
    pub tilt_limit: TiltLimit,
    /// Smallest specific thrust command [m/s²] (spatial model only). Default 2.
    pub thrust_min: f64,
    /// Largest specific thrust command [m/s²] (spatial model only). Default 20.
    pub thrust_max: f64,
}

impl Default for InputSaturation {
    fn default() -> Self {
        Self {
            max_tilt: 35f64.to_radians(),
            tilt_limit: TiltLimit::PerAxis,
            thrust_min: 2.0,
            thrust_max: 20.0,
        }
    }
}

/// Optional inequality constraints on the planned outputs (solved with
/// clarabel when the unconstrained plan violates them).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConstraints {
    /// Max tilt \[rad\] as a bound on the horizontal acceleration per axis,
    /// `|Δ²y/δt²| ≤ g·tan(max_tilt)`. Default none.
    pub max_tilt: Option<f64>,
    /// Max speed per axis `|Δy/δt|` [m/s]; when the window is already
    /// faster, the plan brakes to it at 90 % of the acceleration bound
    /// ([`AxisBounds::speed`]). Default none.
    pub max_speed: Option<f64>,
    /// Bounds `[a_min, a_max]` on the vertical acceleration `Δ²z/δt²`
    /// [m/s²] in the model frame (NED: positive down); spatial model only.
    /// Default none.
    pub vertical_acceleration: Option<[f64; 2]>,
}

impl OutputConstraints {
    /// True when at least one constraint is configured.
    pub fn any(&self) -> bool {
        self.max_tilt.is_some() || self.max_speed.is_some() || self.vertical_acceleration.is_some()
    }
}

/// Which solver handles an axis whose fast plan violates a bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QpSolver {
    /// The banded interior-point method ([`BoundedAxisSolver`], O(N) per
    /// iteration), with clarabel as the fallback when it does not
    /// converge. Default.
    #[default]
    Banded,
    /// Clarabel alone ([`ConstrainedAxisSolver`]).
    Clarabel,
}

/// Settings of [`DfMpc`], checked by [`DfMpcSettings::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DfMpcSettings {
    /// Horizon N [control steps]: outputs y_k..y_{k+N}. Default 100 (2 s at 50 Hz).
    pub horizon: usize,
    /// Tracking weight q per axis `[x, y, z]` [1/m²]. Default 5.
    pub tracking_weight: [f64; 3],
    /// Jerk weight r per axis `[x, y, z]` [s⁶/m²] on `(Δ³y/δt³)²`.
    /// Default 0.01. Only r/q shapes the plan: the default 0.002 s⁶ settles
    /// a 10 m step to 1 cm in ~6 s at 35° saturation; the paper's (q = 1,
    /// r = 0.08, N = 200) is slower, with ~5 % overshoot.
    pub jerk_weight: [f64; 3],
    /// Input saturation; `None` sends F's output unclipped. Default on.
    pub saturation: Option<InputSaturation>,
    /// Optional inequality constraints on the plan. Default none.
    pub constraints: OutputConstraints,
    /// The solver for a plan that violates a constraint. Default
    /// [`QpSolver::Banded`].
    pub qp_solver: QpSolver,
    /// Wall-time limit for one clarabel solve \[s\] (`f64::INFINITY` for
    /// none). Default 0.01.
    pub solver_time_limit: f64,
    /// Command-smoothness weight s per axis `[x, y, z]` [1/rad²] on the
    /// squared change of the (linearised) command between ticks,
    /// `s·((c_j − c_{j−1})/g)²` (see the module docs). Default 0 (off: the
    /// paper's cost). Useful values are O(0.1–10) with q = 1.
    pub smoothness_weight: [f64; 3],
    /// Multi-rate windows: timestamped samples through
    /// [`Controller::observe`] instead of one measurement per tick
    /// ([`MultiRateWindow`]). `None` (default): the paper's window.
    pub multi_rate: Option<MultiRateSettings>,
    /// Disturbance estimation for offset-free tracking
    /// ([`crate::disturbance`]): acceleration offset and thrust scale, used
    /// in F⁻¹ and F. `None` (default) runs the paper's DF-MPC unchanged.
    pub disturbance: Option<DisturbanceSettings>,
}

impl Default for DfMpcSettings {
    fn default() -> Self {
        Self {
            horizon: 100,
            tracking_weight: [5.0; 3],
            jerk_weight: [0.01; 3],
            saturation: Some(InputSaturation::default()),
            constraints: OutputConstraints::default(),
            qp_solver: QpSolver::Banded,
            solver_time_limit: 0.01,
            smoothness_weight: [0.0; 3],
            multi_rate: None,
            disturbance: None,
        }
    }
}

fn invalid(field: &'static str, reason: &str) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.to_string(),
    }
}

fn tilt_ok(v: f64) -> bool {
    v.is_finite() && v > 0.0 && v < std::f64::consts::FRAC_PI_2
}

impl DfMpcSettings {
    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        if !(3..=MAX_HORIZON).contains(&self.horizon) {
            return Err(invalid("horizon", "an integer in 3..=100000 (steps)"));
        }
        if !self
            .tracking_weight
            .iter()
            .all(|q| q.is_finite() && *q >= 0.0)
        {
            return Err(invalid("tracking_weight", "finite and >= 0 (1/m²)"));
        }
        if !self.jerk_weight.iter().all(|r| r.is_finite() && *r > 0.0) {
            return Err(invalid("jerk_weight", "finite and > 0 (s⁶/m²)"));
        }
        if let Some(s) = &self.saturation {
            if !tilt_ok(s.max_tilt) {
                return Err(invalid("saturation.max_tilt", "in (0, π/2) rad"));
            }
            if !(s.thrust_min.is_finite() && s.thrust_min >= 0.0) {
                return Err(invalid("saturation.thrust_min", "finite and >= 0 (m/s²)"));
            }
            if !(s.thrust_max.is_finite() && s.thrust_max > s.thrust_min) {
                return Err(invalid(
                    "saturation.thrust_max",
                    "finite and > thrust_min (m/s²)",
                ));
            }
        }
        let c = &self.constraints;
        if c.max_tilt.is_some_and(|t| !tilt_ok(t)) {
            return Err(invalid("constraints.max_tilt", "in (0, π/2) rad"));
        }
        if c.max_speed.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(invalid("constraints.max_speed", "finite and > 0 (m/s)"));
        }
        if let Some([lo, hi]) = c.vertical_acceleration
            && !(lo.is_finite() && hi.is_finite() && lo < 0.0 && hi > 0.0)
        {
            return Err(invalid(
                "constraints.vertical_acceleration",
                "[a_min, a_max] finite with a_min < 0 < a_max (m/s²)",
            ));
        }
        if self.solver_time_limit.is_nan() || self.solver_time_limit <= 0.0 {
            return Err(invalid("solver_time_limit", "> 0 s (or infinity)"));
        }
        if !self
            .smoothness_weight
            .iter()
            .all(|s| s.is_finite() && *s >= 0.0)
        {
            return Err(invalid("smoothness_weight", "finite and >= 0 (1/rad²)"));
        }
        if let Some(m) = &self.multi_rate {
            m.validate()?;
        }
        if let Some(d) = &self.disturbance {
            d.validate()?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// The 1-D problem: fast path
// ---------------------------------------------------------------------------

fn check_lengths(horizon: usize, reference: &[f64], plan: &[f64]) -> Result<(), ControlError> {
    if reference.len() != horizon + 1 {
        return Err(invalid("reference", "length must be horizon + 1"));
    }
    if plan.len() != horizon + 1 {
        return Err(invalid("plan", "length must be horizon + 1"));
    }
    Ok(())
}

/// The baseline `b_j`, j = 0..=N: the fixed outputs continued with zero
/// third difference (constant second difference).
#[inline]
fn baseline(fixed: &[f64; 3], j: usize) -> f64 {
    let d1 = fixed[1] - fixed[0];
    let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
    let jf = j as f64;
    fixed[0] + jf * d1 + 0.5 * jf * (jf - 1.0) * d2
}

/// One axis's data for [`AxisSolver::solve_pair`]: `fixed` = `[y_0, y_1,
/// y_2]` \[m\], `reference` = `ref_0..ref_N` \[m\], `plan` receives `y*_0..y*_N`.
#[derive(Debug)]
pub struct AxisProblem<'a> {
    /// The fixed outputs `[y_0, y_1, y_2]` \[m\].
    pub fixed: &'a [f64; 3],
    /// `c_{−1}` [m/s²]: the acceleration the command sent at the previous
    /// tick asks for on this axis (used only with a smoothness weight;
    /// `None`: the fixed window's acceleration, i.e. the first change is
    /// free).
    pub sent: Option<f64>,
    /// The reference `ref_0..ref_N` \[m\] (length N + 1).
    pub reference: &'a [f64],
    /// Output: the optimal `y*_0..y*_N` \[m\] (length N + 1).
    pub plan: &'a mut [f64],
}

/// Per-right-hand-side workspace of [`AxisSolver`].
#[derive(Debug, Clone)]
struct Slot {
    /// Baseline b_3..b_N \[m\].
    base: Vec<f64>,
    /// q·(ref − b) on the free outputs.
    rhs: Vec<f64>,
    /// Deviation from the baseline.
    p: Vec<f64>,
    /// Residual, then the refinement correction.
    work: Vec<f64>,
}

/// The command-smoothness term of one axis: weight s on
/// `((c_j − c_{j−1})/g)²`, `c_j = a_j + κ·(a_{j+1} − a_j)` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Smoothness {
    /// Weight s ≥ 0 [1/rad²]; 0 turns the term off.
    pub weight: f64,
    /// κ = τ/δt > 0: the input lag (attitude τ, thrust τ_T) in steps.
    pub kappa: f64,
    /// Gravity g > 0 [m/s²]: accelerations over g are tilts \[rad\].
    pub gravity: f64,
}

impl Smoothness {
    /// Coefficients of `δt²·(c_j − c_{j−1})` on `y_{j−1}..y_{j+3}`.
    fn stencil(&self) -> [f64; 5] {
        let k = self.kappa;
        [k - 1.0, 3.0 - 4.0 * k, 6.0 * k - 3.0, 1.0 - 4.0 * k, k]
    }

    fn check(&self) -> Result<(), ControlError> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(invalid("smoothness_weight", "finite and >= 0 (1/rad²)"));
        }
        if self.weight > 0.0
            && !(self.kappa.is_finite()
                && self.kappa > 0.0
                && self.gravity.is_finite()
                && self.gravity > 0.0)
        {
            return Err(invalid("smoothness", "κ and g finite and > 0"));
        }
        Ok(())
    }
}

/// The unconstrained 1-D DF-MPC problem on one axis, solved in O(N).
///
/// Minimises `Σ_{j=0..N} q·(y_j − ref_j)² + Σ_{j=0..N−3} r·(Δ³y_j/δt³)²`
/// (plus the smoothness term when configured, [`Smoothness`]) over
/// `y_0..y_N` with `y_0, y_1, y_2` fixed (relative indices: y_j is
/// `y_{k+j}`). The Hessian is factored once here; [`AxisSolver::solve`]
/// and [`AxisSolver::solve_pair`] allocate nothing.
#[derive(Debug, Clone)]
pub struct AxisSolver {
    horizon: usize,
    q: f64,
    /// Weight on the raw third difference, r/δt⁶.
    w: f64,
    smoothness: Smoothness,
    /// Weight on `(δt²·Δc)²`, s/(g²·δt⁴) (0: off).
    s: f64,
    /// `s/(g²·δt²)·κ`: the sent command's gain on the first free output.
    sent_gain: f64,
    dt: f64,
    factor: BandedCholesky,
    slots: [Slot; 2],
}

impl AxisSolver {
    /// Builds and factors the problem for horizon N ≥ 3 \[steps\], tracking
    /// weight q ≥ 0 [1/m²], jerk weight r > 0 [s⁶/m²], step δt > 0 \[s\].
    pub fn new(horizon: usize, q: f64, r: f64, dt: f64) -> Result<Self, ControlError> {
        Self::with_smoothness(horizon, q, r, dt, Smoothness::default())
    }

    /// As [`AxisSolver::new`], plus the command-smoothness term (half-
    /// bandwidth 4 when its weight is > 0).
    pub fn with_smoothness(
        horizon: usize,
        q: f64,
        r: f64,
        dt: f64,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        Self::check_args(horizon, q, r, dt)?;
        smoothness.check()?;
        let n = horizon - 2;
        let w = r / dt.powi(6);
        let (s, sent_gain) = if smoothness.weight > 0.0 {
            let sg = smoothness.weight / smoothness.gravity.powi(2);
            (sg / dt.powi(4), sg / (dt * dt) * smoothness.kappa)
        } else {
            (0.0, 0.0)
        };
        let bandwidth = if s > 0.0 { BANDWIDTH + 1 } else { BANDWIDTH };
        let mut hessian = SymBand::zeros(n, bandwidth);
        for i in 0..n {
            hessian.add(i, i, q);
        }
        // Row i of D: Δ³ over y_i..y_{i+3}; free unknown f ↔ y_{f+3}.
        for i in 0..n {
            for (a, &ca) in D3.iter().enumerate() {
                let Some(fa) = (i + a).checked_sub(3) else {
                    continue;
                };
                for (b, &cb) in D3.iter().enumerate().take(a + 1) {
                    let Some(fb) = (i + b).checked_sub(3) else {
                        continue;
                    };
                    hessian.add(fa, fb, w * ca * cb);
                }
            }
        }
        if s > 0.0 {
            // Row i of E = T·D: δt²·Δc_i over y_{i−1}..y_{i+3}.
            let e = smoothness.stencil();
            for i in 0..n {
                for (a, &ca) in e.iter().enumerate() {
                    let Some(fa) = (i + a).checked_sub(4) else {
                        continue;
                    };
                    for (b, &cb) in e.iter().enumerate().take(a + 1) {
                        let Some(fb) = (i + b).checked_sub(4) else {
                            continue;
                        };
                        hessian.add(fa, fb, s * ca * cb);
                    }
                }
            }
        }
        let mut factor = BandedCholesky::new(n, bandwidth);
        factor.factor(&hessian)?;
        let slot = Slot {
            base: vec![0.0; n],
            rhs: vec![0.0; n],
            p: vec![0.0; n],
            work: vec![0.0; n],
        };
        Ok(Self {
            horizon,
            q,
            w,
            smoothness,
            s,
            sent_gain,
            dt,
            factor,
            slots: [slot.clone(), slot],
        })
    }

    /// The smoothness term this solver carries (weight 0: none).
    pub fn smoothness(&self) -> Smoothness {
        self.smoothness
    }

    /// The right-hand side's shift on the first free output from the sent
    /// command: `−s/(g²δt²)·κ·(a_0 − c_{−1})` (0 without smoothness or
    /// without `sent`).
    fn sent_shift(&self, fixed: &[f64; 3], sent: Option<f64>) -> f64 {
        match sent {
            Some(c) if self.s > 0.0 => {
                let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (self.dt * self.dt);
                -self.sent_gain * (a0 - c)
            }
            _ => 0.0,
        }
    }

    /// Horizon N \[steps\].
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Tracking weight q [1/m²] and weight on the raw third difference
    /// `r/δt⁶` [1/m²].
    pub fn weights(&self) -> (f64, f64) {
        (self.q, self.w)
    }

    /// Baseline, right-hand side `q·(ref − b)` on the free outputs (plus
    /// `shift` on the first), `p = rhs`.
    fn prepare(q: f64, slot: &mut Slot, fixed: &[f64; 3], reference: &[f64], shift: f64) {
        let d1 = fixed[1] - fixed[0];
        let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
        let it = slot
            .base
            .iter_mut()
            .zip(slot.rhs.iter_mut())
            .zip(slot.p.iter_mut());
        for (f, (((b, r), p), &y_ref)) in it.zip(&reference[3..]).enumerate() {
            let j = (f + 3) as f64;
            *b = fixed[0] + j * d1 + 0.5 * j * (j - 1.0) * d2;
            *r = q * (y_ref - *b);
            *p = *r;
        }
        if shift != 0.0 {
            slot.rhs[0] += shift;
            slot.p[0] = slot.rhs[0];
        }
    }

    /// `work = rhs − (q·I + w·DᵀD)·p`, evaluated by repeated differencing
    /// rather than with the assembled Hessian: the products of entries
    /// ~1e10 with outputs ~10 m would leave an absolute rounding error near
    /// 1e-4 in the residual, while differences of neighbouring samples are
    /// nearly exact, so the residual is accurate to ~ε·|rhs|.
    ///
    /// With smoothness (s > 0, κ) the middle factor is `w·I + s·TᵀT`,
    /// `T = κ·I + (1 − κ)·S`, applied to `d = D·p` as a two-tap filter and
    /// its transpose.
    fn residual(q: f64, w: f64, smooth: (f64, f64), slot: &mut Slot) {
        let (s, kappa) = smooth;
        // x = w·D·p: third backward difference by three first differences,
        // fused in one pass (p before the horizon is 0).
        let (mut p1, mut e1, mut f1) = (0.0, 0.0, 0.0);
        let scale = if s > 0.0 { 1.0 } else { w };
        for (x, &p) in slot.work.iter_mut().zip(&slot.p) {
            let e = p - p1;
            let f = e - e1;
            *x = scale * (f - f1);
            (p1, e1, f1) = (p, e, f);
        }
        if s > 0.0 {
            // x = (w·I + s·TᵀT)·d in place, backwards: g_f = (T·d)_f needs
            // d_{f−1} (not yet overwritten), (Tᵀg)_f needs g_{f+1} (carried).
            let mut g_next = 0.0;
            for f in (0..slot.work.len()).rev() {
                let d = slot.work[f];
                let d_prev = if f > 0 { slot.work[f - 1] } else { 0.0 };
                let g = d_prev + kappa * (d - d_prev);
                let tg = g_next + kappa * (g - g_next);
                slot.work[f] = w * d + s * tg;
                g_next = g;
            }
        }
        // work = rhs − q·p − Dᵀ·x: three forward differences (x beyond
        // the horizon is 0), fused with the combination, in one pass.
        let (mut x1, mut e1, mut f1) = (0.0, 0.0, 0.0);
        let it = slot.work.iter_mut().zip(&slot.rhs).zip(&slot.p).rev();
        for ((r, &b), &p) in it {
            let x = *r;
            let e = x - x1;
            let f = e - e1;
            let g = f - f1;
            (x1, e1, f1) = (x, e, f);
            *r = b - q * p - g;
        }
    }

    /// The refined plan `y_j = b_j + (p + correction)_j` after the fixed outputs.
    fn write_plan(slot: &Slot, fixed: &[f64; 3], plan: &mut [f64]) {
        plan[..3].copy_from_slice(fixed);
        let it = plan[3..]
            .iter_mut()
            .zip(&slot.base)
            .zip(&slot.p)
            .zip(&slot.work);
        for (((y, &b), &p), &dp) in it {
            *y = b + (p + dp);
        }
    }

    /// Solves for the optimal outputs. `fixed` = `[y_0, y_1, y_2]` \[m\],
    /// `reference` = `ref_0..ref_N` \[m\] (length N + 1); writes `y*_0..y*_N`
    /// into `plan` (length N + 1). Errors name a wrong length.
    ///
    /// One banded solve for the deviation from the baseline, then one step
    /// of iterative refinement with the accurate residual: the result is
    /// within a few ulps of the exact optimum in the first outputs.
    pub fn solve(
        &mut self,
        fixed: &[f64; 3],
        reference: &[f64],
        plan: &mut [f64],
    ) -> Result<(), ControlError> {
        self.solve_problem(AxisProblem {
            fixed,
            sent: None,
            reference,
            plan,
        })
    }

    /// As [`AxisSolver::solve`], with the previously sent command
    /// ([`AxisProblem::sent`]) for the smoothness term.
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        check_lengths(self.horizon, a.reference, a.plan)?;
        let (q, w) = (self.q, self.w);
        let smooth = (self.s, self.smoothness.kappa);
        let shift = self.sent_shift(a.fixed, a.sent);
        let slot = &mut self.slots[0];
        Self::prepare(q, slot, a.fixed, a.reference, shift);
        self.factor.solve_in_place(&mut slot.p)?;
        Self::residual(q, w, smooth, slot);
        self.factor.solve_in_place(&mut slot.work)?;
        Self::write_plan(slot, a.fixed, a.plan);
        Ok(())
    }

    /// Solves two axes that share these weights (x and y, usually) at once;
    /// same results as two [`AxisSolver::solve`] calls, bit for bit, at
    /// little more than the cost of one.
    pub fn solve_pair(
        &mut self,
        a: AxisProblem<'_>,
        b: AxisProblem<'_>,
    ) -> Result<(), ControlError> {
        check_lengths(self.horizon, a.reference, a.plan)?;
        check_lengths(self.horizon, b.reference, b.plan)?;
        let (q, w) = (self.q, self.w);
        let smooth = (self.s, self.smoothness.kappa);
        let (shift_a, shift_b) = (
            self.sent_shift(a.fixed, a.sent),
            self.sent_shift(b.fixed, b.sent),
        );
        let [sa, sb] = &mut self.slots;
        Self::prepare(q, sa, a.fixed, a.reference, shift_a);
        Self::prepare(q, sb, b.fixed, b.reference, shift_b);
        self.factor.solve2_in_place(&mut sa.p, &mut sb.p)?;
        Self::residual(q, w, smooth, sa);
        Self::residual(q, w, smooth, sb);
        self.factor.solve2_in_place(&mut sa.work, &mut sb.work)?;
        Self::write_plan(sa, a.fixed, a.plan);
        Self::write_plan(sb, b.fixed, b.plan);
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// The 1-D problem: constrained (clarabel)
// ---------------------------------------------------------------------------

/// Inequality bounds on one axis's planned outputs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisBounds {
    /// `[lo, hi]` on the acceleration `Δ²y_j/δt²` [m/s²], j = 1..N−2.
    pub acceleration: Option<[f64; 2]>,
    /// `v` with `|Δy_j/δt| ≤ v` [m/s], j = 2..N−1. With an acceleration
    /// bound too, a window already faster than v gets a funnel instead of
    /// an infeasible problem: the bound at step j is
    /// `max(v, |v_1| − 0.9·a·(j − 1)·δt)`, v_1 the window's speed, a the
    /// braking bound (the plan slows at 90 % of it).
    pub speed: Option<f64>,
}

impl AxisBounds {
    /// The speed funnel for a window moving faster than the speed bound:
    /// `(|v_1|, a)` with v_1 = (y_2 − y_1)/δt [m/s] and a [m/s²] 90 % of
    /// the acceleration bound that slows it down; the bound at step j is
    /// then `max(v, |v_1| − a·(j − 1)·δt)`. `None` (the plain bound) when
    /// there is no acceleration bound — the first free output can then
    /// meet any speed — or the window is within the bound.
    fn speed_funnel(&self, fixed: &[f64; 3], dt: f64) -> Option<(f64, f64)> {
        let v = self.speed?;
        let [lo, hi] = self.acceleration?;
        let v1 = (fixed[2] - fixed[1]) / dt;
        let brake = if v1 > 0.0 { -lo } else { hi };
        (v1.abs() > v).then_some((v1.abs(), 0.9 * brake))
    }

    /// The bounds `(lo, hi)` of each constraint row for this window, in row
    /// order — the acceleration rows `Δ²p_j/δt²`, j = 1..N−2, then the speed
    /// rows `Δp_j/δt`, j = 2..N−1, on the deviation p from the baseline
    /// (so the baseline's own acceleration and speed are subtracted).
    fn row_bounds(&self, horizon: usize, fixed: &[f64; 3], dt: f64, mut out: impl FnMut(f64, f64)) {
        let d1 = fixed[1] - fixed[0];
        let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
        if let Some([lo, hi]) = self.acceleration {
            let a_base = d2 / (dt * dt);
            for _ in 1..=horizon - 2 {
                out(lo - a_base, hi - a_base);
            }
        }
        if let Some(v) = self.speed {
            let funnel = self.speed_funnel(fixed, dt);
            for j in 2..=horizon - 1 {
                let s_base = (d1 + j as f64 * d2) / dt;
                let limit = funnel.map_or(v, |(v1, a)| v.max(v1 - a * (j - 1) as f64 * dt));
                out(-limit - s_base, limit - s_base);
            }
        }
    }

    /// True when no bound is set.
    pub fn is_empty(&self) -> bool {
        self.acceleration.is_none() && self.speed.is_none()
    }

    /// True when `plan` (`y_0..y_N` \[m\], step δt \[s\]) violates a bound by
    /// more than a relative 1e-6 (absolute 1e-9 near zero bounds).
    pub fn violated_by(&self, plan: &[f64], dt: f64) -> bool {
        let tol = |b: f64| 1e-6 * b.abs() + 1e-9;
        let n = plan.len();
        if let Some([lo, hi]) = self.acceleration {
            let dt2 = dt * dt;
            for j in 1..n.saturating_sub(2) {
                let a = (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / dt2;
                if a > hi + tol(hi) || a < lo - tol(lo) {
                    return true;
                }
            }
        }
        if let Some(v) = self.speed {
            for j in 2..n.saturating_sub(1) {
                let s = (plan[j + 1] - plan[j]) / dt;
                if s.abs() > v + tol(v) {
                    return true;
                }
            }
        }
        false
    }
}

/// The 1-D DF-MPC problem with inequality bounds, solved by clarabel.
///
/// Variables `[p_0..p_{n−1}, ã_0..ã_{n−1}]`, n = N − 2: `p` the deviations
/// of the free outputs `y_3..y_N` from the zero-jerk baseline `b` of the
/// fixed outputs, `ã_{j−1} = Δ²y_j/δt² − Δ²y_0/δt²` the planned
/// accelerations j = 1..N−2 relative to the fixed one [m/s²]. Cost
/// `Σ q·p² + 2q·(b − ref)·p + Σ_j (r/δt²)·(ã_j − ã_{j−1})²` (ã_{−1} = 0;
/// the jerk term, so the same minimiser as [`AxisSolver`]); equality rows
/// `Δ²p_j/δt² − ã_{j−1} = 0`; acceleration bounds are single-entry rows on
/// ã, speed bounds rows on Δp/δt. The sparsity is fixed at construction;
/// each solve updates `q` and `b` only. Without bounds this is the plain DF
/// QP handed to a generic solver (the benchmark baseline).
///
/// The smoothness term ([`Smoothness`]) in these variables: with
/// `A_j = a_j − a_0 = ã_{j−1}`, `c_j − c_{j−1} = κ·ã_j + (1 − 2κ)·ã_{j−1}
/// − (1 − κ)·ã_{j−2}` (ã before 0 is 0) plus `a_0 − c_{−1}` at j = 0: band 2
/// in P, the sent command in q.
pub struct ConstrainedAxisSolver {
    horizon: usize,
    dt: f64,
    q: f64,
    smoothness: Smoothness,
    bounds: AxisBounds,
    solver: DefaultSolver<f64>,
    qvec: Vec<f64>,
    bvec: Vec<f64>,
    /// Equality rows before the inequality rows.
    m_eq: usize,
}

impl std::fmt::Debug for ConstrainedAxisSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConstrainedAxisSolver")
            .field("horizon", &self.horizon)
            .field("dt", &self.dt)
            .field("q", &self.q)
            .field("bounds", &self.bounds)
            .finish_non_exhaustive()
    }
}

/// Clarabel's KKT settings for [`ConstrainedAxisSolver`] (the rest of its
/// settings are fixed: no presolve, no equilibration, QDLDL, one thread).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KktTuning {
    /// Static regularisation of the KKT factor (clarabel's
    /// `static_regularization_constant`).
    pub static_regularization: f64,
    /// Iterative-refinement relative tolerance.
    pub refinement_reltol: f64,
    /// Iterative-refinement absolute tolerance.
    pub refinement_abstol: f64,
}

impl KktTuning {
    /// What ships: static regularisation 1e-10 instead of clarabel's 1e-8,
    /// refinement tolerance 1e-9 instead of 1e-13/1e-12. With the defaults,
    /// iterative refinement takes about a third of each solve here. Chosen
    /// on four problem types — the N = 200 benchmark problem, N = 100 with
    /// and without the smoothness term, a turn — by `cargo run --release
    /// -p dflat-control --example kkt_tuning`: 27–32 % faster than the
    /// defaults on all four (1e-12 is faster still without smoothness but
    /// slower than the defaults with it). The first planned jerk agrees
    /// with the defaults' to the 10 digits printed; the test
    /// `constrained_solvers_match_clarabel_defaults` checks 1e-6 on random
    /// instances.
    pub const SHIPPED: Self = Self {
        static_regularization: 1e-10,
        refinement_reltol: 1e-9,
        refinement_abstol: 1e-9,
    };
    /// Clarabel 0.11's defaults (the accuracy reference in tests, and a
    /// benchmark baseline).
    pub const CLARABEL_DEFAULTS: Self = Self {
        static_regularization: 1e-12,
        refinement_reltol: 1e-13,
        refinement_abstol: 1e-12,
    };
}

/// The ã block of the doubled Hessian `P` (objective `½xᵀPx`) in the
/// variables of [`ConstrainedAxisSolver`]: the jerk term `(r/δt²)·Σ_j
/// (ã_j − ã_{j−1})²` (ã_{−1} = 0) and the smoothness term (band 2), as
/// `[diagonal, (k−1, k), (k−2, k)]` per column k.
fn accel_block(n: usize, r: f64, dt: f64, smoothness: &Smoothness) -> Vec<[f64; 3]> {
    let ja = 2.0 * r / (dt * dt);
    let mut band = vec![[0.0f64; 3]; n];
    for (k, col) in band.iter_mut().enumerate() {
        col[0] = if k + 1 < n { 2.0 * ja } else { ja };
        if k > 0 {
            col[1] = -ja;
        }
    }
    if smoothness.weight > 0.0 {
        let sg = 2.0 * smoothness.weight / smoothness.gravity.powi(2);
        let kp = smoothness.kappa;
        let coeffs = [kp, 1.0 - 2.0 * kp, -(1.0 - kp)]; // on ã_j, ã_{j−1}, ã_{j−2}
        for j in 0..n {
            for (da, &ca) in coeffs.iter().enumerate() {
                let Some(a) = j.checked_sub(da) else { continue };
                for (db, &cb) in coeffs.iter().enumerate().skip(da) {
                    let Some(b) = j.checked_sub(db) else { continue };
                    // a ≥ b: entry (b, a) of the upper triangle.
                    band[a][a - b] += sg * ca * cb;
                }
            }
        }
    }
    band
}

/// The smoothness term's linear coefficient on ã_0 (objective `½xᵀPx +
/// cᵀx`, [`ConstrainedAxisSolver`]'s variables): `2s/g²·κ·(a_0 − c_{−1})`
/// with the sent command's acceleration c_{−1}; 0 without either.
fn sent_linear_term(sm: &Smoothness, fixed: &[f64; 3], sent: Option<f64>, dt: f64) -> f64 {
    match sent {
        Some(c) if sm.weight > 0.0 => {
            let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            2.0 * sm.weight / sm.gravity.powi(2) * sm.kappa * (a0 - c)
        }
        _ => 0.0,
    }
}

/// Row-builder for the sparse constraint matrix (column-wise triplets).
struct Triplets {
    rows: Vec<usize>,
    cols: Vec<usize>,
    vals: Vec<f64>,
}

impl Triplets {
    fn push(&mut self, r: usize, c: usize, v: f64) {
        self.rows.push(r);
        self.cols.push(c);
        self.vals.push(v);
    }
    /// Adds `scale·Σ coeffs[a]·y_{j+a}` on the free unknowns (y_f+3 ↔ p_f).
    fn push_difference(&mut self, row: usize, j: usize, coeffs: &[f64], scale: f64) {
        for (a, &c) in coeffs.iter().enumerate() {
            if let Some(f) = (j + a).checked_sub(3) {
                self.push(row, f, scale * c);
            }
        }
    }
}

impl ConstrainedAxisSolver {
    /// Builds the solver once for horizon N, weights q ≥ 0 [1/m²], r > 0
    /// [s⁶/m²], step δt \[s\], bounds and clarabel time limit \[s\].
    pub fn new(
        horizon: usize,
        q: f64,
        r: f64,
        dt: f64,
        bounds: AxisBounds,
        time_limit: f64,
    ) -> Result<Self, ControlError> {
        Self::with_smoothness(horizon, q, r, dt, bounds, time_limit, Smoothness::default())
    }

    /// As [`ConstrainedAxisSolver::new`], plus the command-smoothness term.
    pub fn with_smoothness(
        horizon: usize,
        q: f64,
        r: f64,
        dt: f64,
        bounds: AxisBounds,
        time_limit: f64,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        let weights = (q, r, dt);
        Self::with_tuning(
            horizon,
            weights,
            bounds,
            time_limit,
            smoothness,
            KktTuning::SHIPPED,
        )
    }

    /// As [`ConstrainedAxisSolver::with_smoothness`] with the weights as
    /// `(q, r, δt)` and clarabel's KKT settings chosen (benchmarks, tests).
    pub fn with_tuning(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        bounds: AxisBounds,
        time_limit: f64,
        smoothness: Smoothness,
        tuning: KktTuning,
    ) -> Result<Self, ControlError> {
        // Same argument checks as the fast path.
        AxisSolver::check_args(horizon, q, r, dt)?;
        smoothness.check()?;
        if time_limit.is_nan() || time_limit <= 0.0 {
            return Err(invalid("solver_time_limit", "> 0 s (or infinity)"));
        }
        let n = horizon - 2;
        let nv = 2 * n;
        // P (upper triangle): 2q on p; on ã the jerk and smoothness terms.
        let band = accel_block(n, r, dt, &smoothness);
        let smooth = smoothness.weight > 0.0;
        let mut colptr = vec![0usize];
        let (mut prow, mut pval) = (Vec::new(), Vec::new());
        for c in 0..nv {
            if c < n {
                prow.push(c);
                pval.push(2.0 * q);
            } else {
                let k = c - n;
                if smooth && k > 1 {
                    prow.push(c - 2);
                    pval.push(band[k][2]);
                }
                if k > 0 {
                    prow.push(c - 1);
                    pval.push(band[k][1]);
                }
                prow.push(c);
                pval.push(band[k][0]);
            }
            colptr.push(prow.len());
        }
        let p_mat = CscMatrix::new(nv, nv, colptr, prow, pval);

        let mut t = Triplets {
            rows: Vec::new(),
            cols: Vec::new(),
            vals: Vec::new(),
        };
        let dt2 = dt * dt;
        // Equality rows: Δ²p_j/δt² − ã_{j−1} = 0, j = 1..N−2.
        for j in 1..=horizon - 2 {
            t.push_difference(j - 1, j, &[1.0, -2.0, 1.0], 1.0 / dt2);
            t.push(j - 1, n + j - 1, -1.0);
        }
        let m_eq = n;
        let mut m = m_eq;
        if bounds.acceleration.is_some() {
            for k in 0..n {
                t.push(m, n + k, 1.0);
                t.push(m + 1, n + k, -1.0);
                m += 2;
            }
        }
        if bounds.speed.is_some() {
            for j in 2..=horizon - 1 {
                t.push_difference(m, j, &[-1.0, 1.0], 1.0 / dt);
                t.push_difference(m + 1, j, &[-1.0, 1.0], -1.0 / dt);
                m += 2;
            }
        }
        let a_mat = CscMatrix::new_from_triplets(m, nv, t.rows, t.cols, t.vals);
        let mut cones = Vec::new();
        if m_eq > 0 {
            cones.push(SupportedConeT::ZeroConeT(m_eq));
        }
        if m > m_eq {
            cones.push(SupportedConeT::NonnegativeConeT(m - m_eq));
        }
        let qvec = vec![0.0; nv];
        let bvec = vec![0.0; m];
        let settings: DefaultSettings<f64> = DefaultSettingsBuilder::default()
            .verbose(false)
            // Data updates need the problem unchanged by presolve.
            .presolve_enable(false)
            // The variables are in SI units (m, m/s²) and the data well
            // scaled; measured on 10 000 random instances, Ruiz
            // equilibration costs speed and two to four orders of accuracy
            // in the first planned jerk (what the command depends on).
            .equilibrate_enable(false)
            .iterative_refinement_reltol(tuning.refinement_reltol)
            .iterative_refinement_abstol(tuning.refinement_abstol)
            .static_regularization_constant(tuning.static_regularization)
            .time_limit(time_limit)
            .direct_solve_method("qdldl".to_string())
            .max_threads(1)
            .build()
            .map_err(|e| ControlError::Solver(format!("settings: {e}")))?;
        let solver = DefaultSolver::new(&p_mat, &qvec, &a_mat, &bvec, &cones, settings)
            .map_err(|e| ControlError::Solver(format!("setup: {e}")))?;
        Ok(Self {
            horizon,
            dt,
            q,
            smoothness,
            bounds,
            solver,
            qvec,
            bvec,
            m_eq,
        })
    }

    /// Horizon N \[steps\].
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &AxisBounds {
        &self.bounds
    }

    /// Solves with the bounds; arguments as [`AxisSolver::solve`]. A status
    /// other than `Solved` (infeasible bounds, time limit, numerical
    /// trouble) is [`ControlError::Solver`].
    pub fn solve(
        &mut self,
        fixed: &[f64; 3],
        reference: &[f64],
        plan: &mut [f64],
    ) -> Result<(), ControlError> {
        self.solve_problem(AxisProblem {
            fixed,
            sent: None,
            reference,
            plan,
        })
    }

    /// As [`ConstrainedAxisSolver::solve`], with the previously sent
    /// command ([`AxisProblem::sent`]) for the smoothness term.
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let AxisProblem {
            fixed,
            sent,
            reference,
            plan,
        } = a;
        check_lengths(self.horizon, reference, plan)?;
        let n = self.horizon - 2;
        for f in 0..n {
            self.qvec[f] = 2.0 * self.q * (baseline(fixed, f + 3) - reference[f + 3]);
        }
        let dt = self.dt;
        let sm = self.smoothness;
        self.qvec[n] = sent_linear_term(&sm, fixed, sent, dt);
        // Rows `±row ≤ b`: the upper bound, then minus the lower.
        let mut m = self.m_eq;
        let bvec = &mut self.bvec;
        self.bounds.row_bounds(self.horizon, fixed, dt, |lo, hi| {
            bvec[m] = hi;
            bvec[m + 1] = -lo;
            m += 2;
        });
        self.solver
            .update_q(&self.qvec)
            .and_then(|()| self.solver.update_b(&self.bvec))
            .map_err(|e| ControlError::Solver(format!("update: {e}")))?;
        self.solver.solve();
        let status = self.solver.solution.status;
        if status != SolverStatus::Solved {
            return Err(ControlError::Solver(format!("{status:?}")));
        }
        let x = &self.solver.solution.x;
        plan[..3].copy_from_slice(fixed);
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + x[f];
        }
        if plan.iter().any(|v| !v.is_finite()) {
            return Err(ControlError::Solver("non-finite solution".to_string()));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// The 1-D problem: constrained (banded interior point)
// ---------------------------------------------------------------------------

/// The 1-D DF-MPC problem with inequality bounds, solved by the banded
/// interior-point method of [`crate::stage_qp`]: clarabel's variables and
/// cost ([`ConstrainedAxisSolver`]), the KKT system ordered by stage, so
/// O(N) per iteration. It starts from the unconstrained optimum (computed
/// here with the fast path). [`DfMpc`] uses it first and falls back to
/// clarabel when it does not converge.
#[derive(Debug, Clone)]
pub struct BoundedAxisSolver {
    fast: AxisSolver,
    bounds: AxisBounds,
    qp: StageQp,
    c_p: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    p: Vec<f64>,
    iterations: usize,
}

impl BoundedAxisSolver {
    /// Builds the solver for horizon N, weights `(q, r, δt)` as
    /// [`AxisSolver::with_smoothness`], the bounds and the smoothness term.
    pub fn new(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        let fast = AxisSolver::with_smoothness(horizon, q, r, dt, smoothness)?;
        let n = horizon - 2;
        let accel = accel_block(n, r, dt, &smoothness);
        let qp = StageQp::new(
            n,
            q,
            dt,
            &accel,
            bounds.acceleration.is_some(),
            bounds.speed.is_some(),
        );
        let m = qp.rows();
        Ok(Self {
            fast,
            bounds,
            qp,
            c_p: vec![0.0; n],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            p: vec![0.0; n],
            iterations: 0,
        })
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &AxisBounds {
        &self.bounds
    }

    /// Interior-point iterations of the last solve.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// Solves with the bounds; arguments as [`AxisSolver::solve_problem`].
    /// Errors: those of the fast path, and [`ControlError::Solver`] when
    /// the interior-point method does not converge (infeasible bounds,
    /// numerical trouble).
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let AxisProblem {
            fixed,
            sent,
            reference,
            plan,
        } = a;
        self.fast.solve_problem(AxisProblem {
            fixed,
            sent,
            reference,
            plan: &mut *plan,
        })?;
        let dt = self.fast.dt;
        let q = self.fast.q;
        let n = self.p.len();
        for f in 0..n {
            let b = baseline(fixed, f + 3);
            self.c_p[f] = 2.0 * q * (b - reference[f + 3]);
            self.p[f] = plan[f + 3] - b;
        }
        let sm = self.fast.smoothness;
        let c_a0 = sent_linear_term(&sm, fixed, sent, dt);
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut i = 0;
        self.bounds
            .row_bounds(self.fast.horizon, fixed, dt, |l, h| {
                lo[i] = l;
                hi[i] = h;
                i += 1;
            });
        self.iterations = self
            .qp
            .solve(&self.c_p, c_a0, &self.lo, &self.hi, &mut self.p)?;
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + self.p[f];
        }
        if plan.iter().any(|v| !v.is_finite()) {
            return Err(ControlError::Solver("non-finite solution".to_string()));
        }
        Ok(())
    }
}

impl AxisSolver {
    fn check_args(horizon: usize, q: f64, r: f64, dt: f64) -> Result<(), ControlError> {
        if !(3..=MAX_HORIZON).contains(&horizon) {
            return Err(invalid("horizon", "an integer in 3..=100000 (steps)"));
        }
        if !(q.is_finite() && q >= 0.0) {
            return Err(invalid("tracking_weight", "finite and >= 0 (1/m²)"));
        }
        if !(r.is_finite() && r > 0.0) {
            return Err(invalid("jerk_weight", "finite and > 0 (s⁶/m²)"));
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid("dt", "finite and > 0 (s)"));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// The controller
// ---------------------------------------------------------------------------

/// The discrete-flatness MPC controller (see the module docs).
///
/// One [`Controller::update`] per control step δt: window → F⁻¹ prediction
/// of y_{k+1}, y_{k+2} → reference over the horizon → per-axis optimisation
/// → F on y*_k..y*_{k+3} → saturation → the sent input into the window.
/// A measurement whose time `t` is not newer than the last one used (a
/// tick without a new pose) is not entered as new: y_k is then the model's
/// own prediction, F⁻¹ over the window with the input already sent (dead
/// reckoning; the shell's pose timeout bounds how long).
/// With [`DfMpcSettings::multi_rate`] the window is a [`MultiRateWindow`]:
/// samples come through [`Controller::observe`], `update` takes the tick
/// time. Commands use the model's fixed yaw ψ⋆ (the measured yaw is only
/// checked for being finite). Without binding constraints `update` allocates nothing
/// (all workspaces are sized in [`DfMpc::new`]); clarabel's solve may.
#[derive(Debug)]
pub struct DfMpc {
    model: ControlModel,
    settings: DfMpcSettings,
    window: Window,
    /// Fast-path solver per controlled axis.
    fast: Vec<AxisSolver>,
    /// Clarabel solver per axis that has bounds.
    constrained: Vec<Option<ConstrainedAxisSolver>>,
    /// Banded interior-point solver per axis that has bounds (tried before
    /// clarabel, with [`QpSolver::Banded`]).
    bounded: Vec<Option<BoundedAxisSolver>>,
    /// Bounds per axis (empty when none).
    bounds: Vec<AxisBounds>,
    /// Reference y_ref,k..y_ref,k+N (model frame, m).
    reference: Vec<Vector3<f64>>,
    /// The reference split per axis.
    reference_axis: Vec<Vec<f64>>,
    /// Last plan y*_k..y*_{k+N} per axis.
    plans: Vec<Vec<f64>>,
    plan_valid: bool,
    /// Time of the newest measurement used (classic mode) \[s\]; a tick whose
    /// measurement is not newer is predicted instead (see [`DfMpc`]).
    last_t: f64,
    /// The previous tick's F⁻¹ prediction of this tick's output, y_{k+1}
    /// then (classic mode) \[m\].
    predicted: Vector3<f64>,
    /// Multi-rate window, when configured (else `window` is used).
    multi: Option<MultiRateWindow>,
    /// True when some axis has a smoothness weight.
    smooth: bool,
    /// Disturbance estimator, when configured.
    estimator: Option<DisturbanceEstimator>,
    /// The last good tick's plan y*_k..y*_{k+N} per axis and its
    /// reference (model frame, m), for [`DfMpc::plan`] and
    /// [`Controller::plan_fallback`]; swapped with `plans` / `reference`
    /// (the next tick's workspaces) after each good tick.
    good_plans: Vec<Vec<f64>>,
    good_reference: Vec<Vector3<f64>>,
    /// y_k of the last good tick (the z of planar plans) \[m\].
    good_y0: Vector3<f64>,
    /// Plan steps flown by `plan_fallback` since the last good tick
    /// (`None`: no plan to fly).
    fallback_step: Option<usize>,
    /// This tick started (`update` called) and is not recorded yet.
    pending: bool,
    /// An earlier tick was never recorded (failed `update`, no plan
    /// fallback): the classic window has a gap, the next recorded tick
    /// restarts it.
    gap: bool,
}

impl DfMpc {
    /// Builds the controller: validates the settings, factors the fast-path
    /// Hessians and builds the clarabel solvers (all allocation happens here).
    pub fn new(model: ControlModel, settings: DfMpcSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let axes = model.axes();
        let c = &settings.constraints;
        if axes < 3 && c.vertical_acceleration.is_some() {
            return Err(invalid(
                "constraints.vertical_acceleration",
                "needs the spatial model (the planar model does not control z)",
            ));
        }
        let dt = model.dt();
        let n = settings.horizon;
        let mut fast = Vec::with_capacity(axes);
        let mut constrained = Vec::with_capacity(axes);
        let mut bounded = Vec::with_capacity(axes);
        let mut bounds = Vec::with_capacity(axes);
        let lags = input_lags(&model);
        for (axis, lag) in lags.iter().enumerate().take(axes) {
            let (q, r) = (settings.tracking_weight[axis], settings.jerk_weight[axis]);
            let smoothness = Smoothness {
                weight: settings.smoothness_weight[axis],
                kappa: lag / dt,
                gravity: model.gravity(),
            };
            fast.push(AxisSolver::with_smoothness(n, q, r, dt, smoothness)?);
            let acceleration = if axis < 2 {
                c.max_tilt.map(|t| {
                    let a = model.gravity() * t.tan();
                    [-a, a]
                })
            } else {
                c.vertical_acceleration
            };
            let b = AxisBounds {
                acceleration,
                speed: c.max_speed,
            };
            constrained.push(if b.is_empty() {
                None
            } else {
                Some(ConstrainedAxisSolver::with_smoothness(
                    n,
                    q,
                    r,
                    dt,
                    b,
                    settings.solver_time_limit,
                    smoothness,
                )?)
            });
            bounded.push(if b.is_empty() || settings.qp_solver != QpSolver::Banded {
                None
            } else {
                Some(BoundedAxisSolver::new(n, (q, r, dt), b, smoothness)?)
            });
            bounds.push(b);
        }
        Ok(Self {
            model,
            settings,
            window: Window::new(model.hover_input()),
            fast,
            constrained,
            bounded,
            bounds,
            reference: vec![Vector3::zeros(); n + 1],
            reference_axis: vec![vec![0.0; n + 1]; axes],
            plans: vec![vec![0.0; n + 1]; axes],
            plan_valid: false,
            last_t: f64::NEG_INFINITY,
            predicted: Vector3::zeros(),
            multi: settings
                .multi_rate
                .map(|m| MultiRateWindow::new(&model, m))
                .transpose()?,
            smooth: settings
                .smoothness_weight
                .iter()
                .take(axes)
                .any(|s| *s > 0.0),
            estimator: settings
                .disturbance
                .map(|d| DisturbanceEstimator::new(model, d))
                .transpose()?,
            good_plans: vec![vec![0.0; n + 1]; axes],
            good_reference: vec![Vector3::zeros(); n + 1],
            good_y0: Vector3::zeros(),
            fallback_step: None,
            pending: false,
            gap: false,
        })
    }

    /// The model.
    pub fn model(&self) -> &ControlModel {
        &self.model
    }

    /// The settings.
    pub fn settings(&self) -> &DfMpcSettings {
        &self.settings
    }

    /// The disturbance estimator, when configured.
    pub fn disturbance_estimator(&self) -> Option<&DisturbanceEstimator> {
        self.estimator.as_ref()
    }

    /// The window of past measurements and sent inputs (classic mode; it
    /// stays empty in multi-rate mode).
    pub fn window(&self) -> &Window {
        &self.window
    }

    /// The multi-rate window, when configured.
    pub fn multi_rate_window(&self) -> Option<&MultiRateWindow> {
        self.multi.as_ref()
    }

    /// The full plan `y*_k..y*_{k+N}` \[m\] of `axis` (0 = x, 1 = y, 2 = z)
    /// from the last successful update; `None` before one, after a failed
    /// one or for an axis the model does not control.
    pub fn plan(&self, axis: usize) -> Option<&[f64]> {
        if self.plan_valid {
            self.good_plans.get(axis).map(|p| p.as_slice())
        } else {
            None
        }
    }

    /// The per-axis bounds derived from the constraints (x, y, z order).
    pub fn bounds(&self, axis: usize) -> Option<&AxisBounds> {
        self.bounds.get(axis)
    }

    /// Clips `u` to the input saturation; returns it and whether it clipped.
    fn saturate(&self, u: Vector3<f64>) -> (Vector3<f64>, bool) {
        let Some(s) = &self.settings.saturation else {
            return (u, false);
        };
        let mut out = u;
        (out.x, out.y, _) = limit_tilt(u.x, u.y, s.max_tilt, s.tilt_limit);
        if matches!(self.model, ControlModel::Spatial(_)) {
            out.z = u.z.clamp(s.thrust_min, s.thrust_max);
        }
        (out, out != u)
    }
}

/// What [`DfMpc::fixed_outputs`] gives a tick.
struct FixedOutputs {
    /// The classic window with y_k pushed (a copy; unused in multi-rate).
    window: Window,
    /// `[y_k, y_{k+1}, y_{k+2}]` \[m\], model frame.
    fixed: [Vector3<f64>; 3],
    /// The input sent at k−1.
    previous_input: Vector3<f64>,
}

impl DfMpc {
    /// The fixed outputs `[y_k, y_{k+1}, y_{k+2}]` and the input sent at
    /// k−1: from the multi-rate window (moved to `measurement.t`, committed
    /// by [`DfMpc::commit`]), or from a copy of the classic window with y_k
    /// pushed — the measurement, or the model's own prediction on a tick
    /// without a new pose (F⁻¹ over the window with u_{k−3}, computed at the
    /// previous tick as its y_{k+1}; u_{k−3} has left the window since) —
    /// then F⁻¹ for y_{k+1}, y_{k+2}. The copy is returned for `commit`;
    /// after a gap it starts from the start-up padding.
    fn fixed_outputs(
        &mut self,
        measurement: &Measurement,
        d: &DisturbanceEstimate,
    ) -> Result<FixedOutputs, ControlError> {
        let mut window = self.window;
        let mut last_t = self.last_t;
        if self.gap {
            window.reset();
            last_t = f64::NEG_INFINITY;
        }
        if let Some(multi) = &mut self.multi {
            let model = self.model;
            let e = multi.estimate(measurement.t, |y, u| model.next_output_disturbed(y, u, d))?;
            return Ok(FixedOutputs {
                window,
                fixed: e.fixed,
                previous_input: e.previous_input,
            });
        }
        let y_k = if !window.is_empty() && measurement.t <= last_t {
            self.predicted
        } else {
            measurement.position
        };
        window.push_measurement(y_k);
        let [ym2, ym1, y0] = *window.outputs();
        let [u2, u1] = *window.inputs();
        let y1 = self.model.next_output_disturbed(&[ym2, ym1, y0], &u2, d)?;
        let y2 = self.model.next_output_disturbed(&[ym1, y0, y1], &u1, d)?;
        Ok(FixedOutputs {
            window,
            fixed: [y0, y1, y2],
            previous_input: u1,
        })
    }

    /// Records `sent` as this tick's input: the disturbance estimator, then
    /// the classic window (the copy from [`DfMpc::fixed_outputs`]) and the
    /// prediction of the next tick's output, or the multi-rate commit.
    fn commit(
        &mut self,
        mut window: Window,
        t: f64,
        fixed: &[Vector3<f64>; 3],
        sent: &Vector3<f64>,
        saturated: bool,
    ) {
        if let Some(e) = &mut self.estimator {
            if self.multi.is_some() {
                // Multi-rate: the estimator fits the timestamped samples it
                // got through `observe`, never the window's estimate of y_k.
                e.record_input(t, sent, saturated);
            } else {
                // A tick without a new pose: the predicted y_k stands in.
                e.record(&fixed[0], sent, saturated);
            }
        }
        if let Some(multi) = &mut self.multi {
            multi.commit(sent);
        } else {
            window.push_input(*sent);
            self.window = window;
            let last_t = if self.gap {
                f64::NEG_INFINITY
            } else {
                self.last_t
            };
            self.last_t = last_t.max(t);
            self.predicted = fixed[1];
        }
        self.pending = false;
        self.gap = false;
    }
}

/// The acceleration [m/s²] (model frame) that input `u` asks for: the
/// model's acceleration at the attitude (and thrust) the input dynamics
/// settle to, `k̃·(θ_cmd, φ_cmd)` (and `T_cmd`). Planar: z = 0.
fn commanded_acceleration(
    model: &ControlModel,
    u: &Vector3<f64>,
) -> Result<Vector3<f64>, ControlError> {
    Ok(match model {
        ControlModel::Planar(m) => {
            let k = m.params().k;
            let a = m.acceleration(k * u.x, k * u.y)?;
            Vector3::new(a.x, a.y, 0.0)
        }
        ControlModel::Spatial(m) => {
            let k = m.params().k;
            m.acceleration(k * u.x, k * u.y, u.z)
        }
    })
}

impl Controller for DfMpc {
    fn name(&self) -> &'static str {
        "df-mpc"
    }

    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        if self.pending {
            // The previous tick sent something this controller did not
            // record (failed update, no plan fallback).
            self.gap = true;
        }
        self.pending = true;
        self.plan_valid = false;
        if let Some(e) = &mut self.estimator {
            e.begin_tick();
        }
        let d = self
            .estimator
            .as_ref()
            .map_or(DisturbanceEstimate::NOMINAL, |e| e.estimate());
        let axes = self.model.axes();
        // Multi-rate mode takes only the tick time (and checks the yaw).
        let position_ok = self.multi.is_some()
            || measurement
                .position
                .iter()
                .take(axes)
                .all(|v| v.is_finite());
        if !(position_ok && measurement.yaw.is_finite()) {
            return Err(ControlError::NonFiniteMeasurement);
        }
        // Input-to-output map over the window: y_{k+1}, y_{k+2}; and the
        // input sent at k−1 (for the smoothness term). The window is a copy:
        // on error nothing is recorded.
        let FixedOutputs {
            window,
            fixed,
            previous_input,
        } = self.fixed_outputs(measurement, &d)?;
        let y0 = fixed[0];
        let sent_acceleration = if self.smooth {
            Some(commanded_acceleration(&self.model, &previous_input)? + d.acceleration)
        } else {
            None
        };

        // Reference over the horizon.
        reference.horizon(&y0, self.model.dt(), &mut self.reference);
        if !self
            .reference
            .iter()
            .all(|r| r.iter().take(axes).all(|v| v.is_finite()))
        {
            return Err(ControlError::NonFiniteReference);
        }

        // Output trajectory optimisation, per axis: the fast path first
        // (x and y together when they share weights), then clarabel for an
        // axis whose fast plan violates a configured bound.
        let mut fixed_axis = [[0.0; 3]; 3];
        for axis in 0..axes {
            fixed_axis[axis] = [fixed[0][axis], fixed[1][axis], fixed[2][axis]];
            for (dst, r) in self.reference_axis[axis].iter_mut().zip(&self.reference) {
                *dst = r[axis];
            }
        }
        let sent = |axis: usize| sent_acceleration.map(|c| c[axis]);
        let paired = self.fast[0].weights() == self.fast[1].weights()
            && self.fast[0].smoothness() == self.fast[1].smoothness();
        let [px, py, pz @ ..] = self.plans.as_mut_slice() else {
            unreachable!("DfMpc::new makes at least two plans")
        };
        let ra = &self.reference_axis;
        let problem = |axis: usize, plan| AxisProblem {
            fixed: &fixed_axis[axis],
            sent: sent(axis),
            reference: &ra[axis],
            plan,
        };
        if paired {
            self.fast[0].solve_pair(problem(0, px), problem(1, py))?;
        } else {
            self.fast[0].solve_problem(problem(0, px))?;
            self.fast[1].solve_problem(problem(1, py))?;
        }
        if let Some(plan) = pz.first_mut() {
            self.fast[2].solve_problem(problem(2, plan))?;
        }
        let mut constrained = false;
        let mut qp_fallback = false;
        let dt = self.model.dt();
        let axes_data = self
            .constrained
            .iter_mut()
            .zip(&mut self.bounded)
            .zip(&mut self.plans)
            .zip(&self.reference_axis);
        for (axis, ((((cs, bs), plan), reference), fixed)) in axes_data.zip(&fixed_axis).enumerate()
        {
            if let Some(cs) = cs
                && cs.bounds().violated_by(plan, dt)
            {
                // The banded solver first; clarabel when it does not
                // converge (its own failure is the tick's).
                let has_banded = bs.is_some();
                let banded = match bs {
                    Some(bs) => bs
                        .solve_problem(AxisProblem {
                            fixed,
                            sent: sent(axis),
                            reference,
                            plan: &mut *plan,
                        })
                        .is_ok(),
                    None => false,
                };
                if !banded {
                    qp_fallback |= has_banded;
                    cs.solve_problem(AxisProblem {
                        fixed,
                        sent: sent(axis),
                        reference,
                        plan,
                    })?;
                }
                constrained = true;
            }
        }

        // Output-to-input map on y*_k..y*_{k+3}.
        let mut plan4 = [y0; 4];
        for (j, p) in plan4.iter_mut().enumerate() {
            for axis in 0..axes {
                p[axis] = self.plans[axis][j];
            }
        }
        let u = self.model.input_from_outputs_disturbed(&plan4, &d)?;
        if !u.iter().all(|v| v.is_finite()) {
            return Err(ControlError::Flat(dflat_model::FlatError::NonFinite(
                "input",
            )));
        }
        let (sent, saturated) = self.saturate(u);
        self.commit(window, measurement.t, &fixed, &sent, saturated);
        // Keep the plan for `plan` and `plan_fallback` (O(1): the buffers
        // swap; the next tick overwrites the other pair in full).
        std::mem::swap(&mut self.plans, &mut self.good_plans);
        std::mem::swap(&mut self.reference, &mut self.good_reference);
        self.good_y0 = y0;
        self.fallback_step = Some(0);
        self.plan_valid = true;
        Ok(TickOutput {
            command: self.model.command(&sent),
            plan: plan4,
            reference: self.good_reference[0],
            saturated,
            constrained,
            qp_fallback,
        })
    }

    fn multi_rate(&self) -> bool {
        self.multi.is_some()
    }

    /// Flies the last good plan: step s = 1, 2, … of it through F (with
    /// the current disturbance estimate) and saturation. A non-finite
    /// measurement is not used (classic mode: y_k is the model's
    /// prediction, as on a tick without a new pose). In multi-rate mode a
    /// tick time not after the last committed tick (a late update's tick)
    /// is taken as the step after it. `None` once
    /// `max_steps` or [`MAX_FALLBACK_STEPS`] steps are flown, the kept plan
    /// is used up, or the map fails.
    fn plan_fallback(&mut self, measurement: &Measurement, max_steps: usize) -> Option<TickOutput> {
        // Until a plan step is recorded, this tick's command is unknown.
        self.pending = true;
        let step = self.fallback_step.take()? + 1;
        if step > max_steps.min(MAX_FALLBACK_STEPS) || step + 3 > self.settings.horizon {
            return None;
        }
        let d = self
            .estimator
            .as_ref()
            .map_or(DisturbanceEstimate::NOMINAL, |e| e.estimate());
        let axes = self.model.axes();
        let mut m = *measurement;
        match &self.multi {
            // A tick already committed at this time (the shell could not
            // use a late update's result): this is the step after it.
            Some(multi) => {
                if let Some(last) = multi.last_tick()
                    && (m.t.is_nan() || m.t <= last)
                {
                    m.t = last + self.model.dt();
                }
            }
            None => {
                if !m.position.iter().take(axes).all(|v| v.is_finite()) {
                    m.t = f64::NEG_INFINITY;
                }
            }
        }
        let FixedOutputs { window, fixed, .. } = self.fixed_outputs(&m, &d).ok()?;
        let plan4: [Vector3<f64>; 4] = std::array::from_fn(|j| {
            let mut p = self.good_y0;
            for (axis, plan) in self.good_plans.iter().enumerate() {
                p[axis] = plan[step + j];
            }
            p
        });
        let u = self.model.input_from_outputs_disturbed(&plan4, &d).ok()?;
        if !u.iter().all(|v| v.is_finite()) {
            return None;
        }
        let (sent, saturated) = self.saturate(u);
        self.commit(window, m.t, &fixed, &sent, saturated);
        self.fallback_step = Some(step);
        Some(TickOutput {
            command: self.model.command(&sent),
            plan: plan4,
            reference: self.good_reference[step],
            saturated,
            constrained: false,
            qp_fallback: false,
        })
    }

    fn observe(&mut self, sample: &Measurement) {
        if let Some(multi) = &mut self.multi {
            multi.observe(sample.t, &sample.position);
            if let Some(e) = &mut self.estimator {
                e.observe(sample.t, &sample.position);
            }
        }
    }

    fn reset(&mut self) {
        self.window.reset();
        self.last_t = f64::NEG_INFINITY;
        if let Some(multi) = &mut self.multi {
            multi.reset();
        }
        self.plan_valid = false;
        self.fallback_step = None;
        self.pending = false;
        self.gap = false;
        if let Some(e) = &mut self.estimator {
            e.reset();
        }
    }

    fn disturbance(&self) -> Option<crate::disturbance::DisturbanceReport> {
        self.estimator.as_ref().map(|e| e.report())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.02;

    /// Exact optima (80-digit decimal arithmetic, independent code) of the
    /// paper's problem: N = 200, q = 1, R = 1.25e9 (r = 0.08), for three
    /// fixed windows and references; y_3, y_4, y_5, y_100, y_200.
    #[allow(clippy::excessive_precision)] // the digits of the exact values
    const EXACT: [([f64; 3], f64, [f64; 5]); 3] = [
        (
            [0.0, 0.0, 0.0],
            0.0,
            [
                2.72675475085858078517e-04,
                1.07424301111137365621e-03,
                2.64496673212843459722e-03,
                8.45180325427767975555e+00,
                8.91593139813904400626e+00,
            ],
        ),
        (
            [2.5, 2.625, 2.75],
            0.0,
            [
                2.87497597001641924663e+00,
                2.99990197984912443374e+00,
                3.12475036050520094122e+00,
                1.05579462561709682689e+01,
                9.27165464345517875699e+00,
            ],
        ),
        (
            [-1.0, -0.984375, -0.953125],
            0.125,
            [
                -9.06970419872583422105e-01,
                -8.46613469096172632788e-01,
                -7.72738357578821921656e-01,
                1.61152326483895080855e+01,
                2.35161257238214140841e+01,
            ],
        ),
    ];

    /// Reference of the fixtures: 10 m, or a ramp `slope·j` when slope ≠ 0.
    fn fixture_reference(slope: f64) -> Vec<f64> {
        (0..=200)
            .map(|j| if slope == 0.0 { 10.0 } else { slope * j as f64 })
            .collect()
    }

    #[test]
    fn fast_path_matches_exact_optimum() {
        let mut s = AxisSolver::new(200, 1.0, 0.08, DT).unwrap();
        let mut plan = vec![0.0; 201];
        for (fixed, slope, exact) in EXACT {
            s.solve(&fixed, &fixture_reference(slope), &mut plan)
                .unwrap();
            assert_eq!(&plan[..3], &fixed);
            for (&j, &e) in [3usize, 4, 5, 100, 200].iter().zip(&exact) {
                let err = (plan[j] - e).abs() / e.abs();
                // The command needs y_3 to ~1e-12 m; we get ~1e-17 m.
                let tol = if j <= 5 { 1e-12 } else { 1e-11 };
                assert!(
                    err < tol,
                    "y_{j} = {} vs exact {e}: rel err {err:e}",
                    plan[j]
                );
            }
        }
    }

    #[test]
    fn clarabel_without_bounds_agrees_with_fast_path() {
        let mut fast = AxisSolver::new(100, 1.0, 0.08, DT).unwrap();
        let mut generic =
            ConstrainedAxisSolver::new(100, 1.0, 0.08, DT, AxisBounds::default(), f64::INFINITY)
                .unwrap();
        let reference = vec![10.0; 101];
        let fixed = [1.0, 1.05, 1.11];
        let (mut a, mut b) = (vec![0.0; 101], vec![0.0; 101]);
        fast.solve(&fixed, &reference, &mut a).unwrap();
        generic.solve(&fixed, &reference, &mut b).unwrap();
        for j in 0..=100 {
            assert!(
                (a[j] - b[j]).abs() < 1e-5 * (1.0 + a[j].abs()),
                "j={j}: {} vs {}",
                a[j],
                b[j]
            );
        }
        // The jerk at the first free output (what the command depends on).
        let jerk = |p: &[f64]| (p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0]) / DT.powi(3);
        assert!(
            (jerk(&a) - jerk(&b)).abs() < 1e-3 * jerk(&a).abs(),
            "{} vs {}",
            jerk(&a),
            jerk(&b)
        );
    }

    #[test]
    fn constrained_plan_respects_bounds() {
        let a_max = 2.0;
        let v_max = 3.0;
        let bounds = AxisBounds {
            acceleration: Some([-a_max, a_max]),
            speed: Some(v_max),
        };
        let mut fast = AxisSolver::new(100, 1.0, 0.08, DT).unwrap();
        let mut cs = ConstrainedAxisSolver::new(100, 1.0, 0.08, DT, bounds, f64::INFINITY).unwrap();
        let reference = vec![10.0; 101];
        let mut plan = vec![0.0; 101];
        fast.solve(&[0.0; 3], &reference, &mut plan).unwrap();
        assert!(bounds.violated_by(&plan, DT));
        cs.solve(&[0.0; 3], &reference, &mut plan).unwrap();
        assert!(
            !AxisBounds {
                acceleration: Some([-a_max * 1.0001, a_max * 1.0001]),
                speed: Some(v_max * 1.0001)
            }
            .violated_by(&plan, DT)
        );
        // The bound binds: some planned acceleration is at the limit.
        let amax = (1..99)
            .map(|j| ((plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / (DT * DT)).abs())
            .fold(0.0, f64::max);
        assert!(amax > 0.99 * a_max, "{amax}");
    }

    /// Clarabel's objective `½xᵀPx + cᵀx` ([`ConstrainedAxisSolver`]) of a
    /// plan: p its deviation from the baseline, ã = Δ²p/δt².
    fn qp_objective(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        smoothness: &Smoothness,
        fixed: &[f64; 3],
        sent: Option<f64>,
        reference: &[f64],
        plan: &[f64],
    ) -> f64 {
        let n = horizon - 2;
        let p: Vec<f64> = (0..n)
            .map(|f| plan[f + 3] - baseline(fixed, f + 3))
            .collect();
        let at = |f: isize| if f < 0 { 0.0 } else { p[f as usize] };
        let a: Vec<f64> = (0..n as isize)
            .map(|f| (at(f) - 2.0 * at(f - 1) + at(f - 2)) / (dt * dt))
            .collect();
        let band = accel_block(n, r, dt, smoothness);
        let mut obj = 0.0;
        for f in 0..n {
            obj += q * p[f] * p[f] + 2.0 * q * (baseline(fixed, f + 3) - reference[f + 3]) * p[f];
            obj += 0.5 * band[f][0] * a[f] * a[f];
            if f >= 1 {
                obj += band[f][1] * a[f - 1] * a[f];
            }
            if f >= 2 {
                obj += band[f][2] * a[f - 2] * a[f];
            }
        }
        if let Some(c) = sent
            && smoothness.weight > 0.0
        {
            let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            let g2 = smoothness.gravity.powi(2);
            obj += 2.0 * smoothness.weight / g2 * smoothness.kappa * (a0 - c) * a[0];
        }
        obj
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(256))]
        /// Clarabel with the shipped KKT tuning ([`KktTuning::SHIPPED`]) and
        /// the banded interior point ([`BoundedAxisSolver`]) both give the
        /// plan of clarabel's default settings on random constrained
        /// instances — with and without the smoothness term, windows faster
        /// than the speed bound (funnel) included — to the tolerances
        /// below; the acceleration bounds hold. 256 cases per run
        /// (`PROPTEST_CASES=2000` for more: five such runs passed).
        #[test]
        fn constrained_solvers_match_clarabel_defaults(
            horizon in 20usize..=200,
            q in 0.5f64..10.0,
            r in 1e-3f64..0.1,
            a_max in 1.0f64..5.0,
            speed in proptest::option::of(2.0f64..8.0),
            y0 in -5.0f64..5.0,
            v0_frac in -1.5f64..1.5,
            a0_frac in -0.8f64..0.8,
            target in -20.0f64..20.0,
            slope in -3.0f64..3.0,
            smooth in proptest::option::of((1.0f64..50.0, 1.0f64..8.0, -0.5f64..0.5)),
        ) {
            let v0 = v0_frac * speed.unwrap_or(4.0);
            let a0 = a0_frac * a_max;
            let fixed = [y0, y0 + v0 * DT, y0 + 2.0 * v0 * DT + a0 * DT * DT];
            let reference: Vec<f64> =
                (0..=horizon).map(|j| target + slope * DT * j as f64).collect();
            let bounds = AxisBounds { acceleration: Some([-a_max, a_max]), speed };
            let (smoothness, sent) = match smooth {
                Some((weight, kappa, delta)) => (
                    Smoothness { weight, kappa, gravity: 9.81 },
                    Some(a0 + delta),
                ),
                None => (Smoothness::default(), None),
            };
            let build = |tuning| {
                ConstrainedAxisSolver::with_tuning(
                    horizon, (q, r, DT), bounds, f64::INFINITY, smoothness, tuning,
                )
                .unwrap()
            };
            let (mut shipped, mut reference_solver) =
                (build(KktTuning::SHIPPED), build(KktTuning::CLARABEL_DEFAULTS));
            let mut want = vec![0.0; horizon + 1];
            let ok = reference_solver.solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut want,
            });
            proptest::prop_assume!(ok.is_ok(), "reference solver: {:?}", ok);
            let mut got = vec![0.0; horizon + 1];
            shipped
                .solve_problem(AxisProblem {
                    fixed: &fixed, sent, reference: &reference, plan: &mut got,
                })
                .unwrap();
            let mut banded = BoundedAxisSolver::new(horizon, (q, r, DT), bounds, smoothness).unwrap();
            let mut got_banded = vec![0.0; horizon + 1];
            banded
                .solve_problem(AxisProblem {
                    fixed: &fixed, sent, reference: &reference, plan: &mut got_banded,
                })
                .unwrap();
            let jerk = |p: &[f64]| (p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0]) / DT.powi(3);
            let jw = jerk(&want);
            // Both stop at ~1e-8 relative gaps, so outputs far out in the
            // horizon (flat directions of the cost) may differ by µm even
            // between the two clarabel tunings (1e-5 m over 2000 cases),
            // more for the independent banded interior point: it is held to
            // a cost no higher than clarabel's (1e-7 relative, the gap it
            // accepts from a stalled iterate: the measure of a QP solution), the first jerk to 1e-3 relative (near a
            // bound the cost can be flat in it too: 2000 cases showed 1.1e-4,
            // 0.035° of command at −269 m/s³), the first ten outputs to
            // 1e-5 m.
            let objective = |plan: &[f64]| {
                qp_objective(horizon, (q, r, DT), &smoothness, &fixed, sent, &reference, plan)
            };
            let (ow, ob) = (objective(&want), objective(&got_banded));
            proptest::prop_assert!(
                ob <= ow + 1e-7 * (1.0 + ow.abs()),
                "banded cost {ob} above clarabel's {ow}"
            );
            // (name, plan, first-jerk tolerance (relative), tolerance on
            // the first ten outputs, on the rest [m]).
            let cases = [
                ("clarabel shipped", &got, 1e-6, 1e-6, 1e-5),
                ("banded", &got_banded, 1e-3, 1e-5, 1e-3),
            ];
            for (name, got, jerk_tol, near_tol, far_tol) in cases {
                let jg = jerk(got);
                proptest::prop_assert!(
                    (jg - jw).abs() <= jerk_tol * jw.abs().max(1.0),
                    "{name}: first jerk {jg} vs {jw}"
                );
                for (j, (g, w)) in got.iter().zip(&want).enumerate() {
                    let tol = if j <= 10 { near_tol } else { far_tol };
                    proptest::prop_assert!((g - w).abs() <= tol, "{name}: y_{j}: {g} vs {w}");
                }
                // The funnel relaxes the speed bound near the start.
                let check = AxisBounds { speed: None, ..bounds };
                proptest::prop_assert!(!check.violated_by(got, DT), "{name}");
            }
        }
    }

    #[test]
    fn faster_than_the_speed_bound_brakes_in_a_funnel() {
        // Moving at 5 m/s with |v| ≤ 1 m/s and |a| ≤ 1 m/s²: a hard bound
        // from the first free step would be infeasible (the window cannot
        // slow down in one step); the funnel brakes at 0.9 m/s² instead.
        let (v_max, a_max) = (1.0, 1.0);
        let bounds = AxisBounds {
            acceleration: Some([-a_max, a_max]),
            speed: Some(v_max),
        };
        let n = 300; // 6 s: long enough to get down to 1 m/s
        let mut cs = ConstrainedAxisSolver::new(n, 1.0, 0.08, DT, bounds, f64::INFINITY).unwrap();
        let mut plan = vec![0.0; n + 1];
        let fixed = [0.0, 0.1, 0.2];
        cs.solve(&fixed, &vec![10.0; n + 1], &mut plan).unwrap();
        let speed = |j: usize| (plan[j + 1] - plan[j]) / DT;
        for j in 2..n {
            let funnel = v_max.max(5.0 - 0.9 * a_max * (j - 1) as f64 * DT);
            assert!(
                speed(j).abs() <= funnel * (1.0 + 1e-6),
                "j={j}: {}",
                speed(j)
            );
            let a = (plan[j + 1] - 2.0 * plan[j] + plan[j - 1]) / (DT * DT);
            assert!(a.abs() <= a_max * (1.0 + 1e-6), "j={j}: a = {a}");
        }
        // It brakes: within the bound once the funnel has closed (4.4 s).
        assert!(speed(250).abs() <= v_max * (1.0 + 1e-6), "{}", speed(250));
        assert!(speed(10) < 5.0 && speed(100) < speed(10));
    }

    #[test]
    fn solver_failure_is_an_error() {
        // A time limit no solve can meet.
        let bounds = AxisBounds {
            acceleration: Some([-1.0, 1.0]),
            speed: Some(1.0),
        };
        let mut cs = ConstrainedAxisSolver::new(50, 1.0, 0.08, DT, bounds, 1e-12).unwrap();
        let mut plan = vec![0.0; 51];
        let r = cs.solve(&[0.0, 0.1, 0.2], &[10.0; 51], &mut plan);
        assert!(matches!(r, Err(ControlError::Solver(_))), "{r:?}");
    }

    #[test]
    fn lengths_and_arguments_are_checked() {
        assert!(matches!(
            AxisSolver::new(2, 1.0, 0.08, DT),
            Err(ControlError::InvalidSetting {
                field: "horizon",
                ..
            })
        ));
        assert!(matches!(
            AxisSolver::new(10, 1.0, 0.0, DT),
            Err(ControlError::InvalidSetting {
                field: "jerk_weight",
                ..
            })
        ));
        let mut s = AxisSolver::new(10, 1.0, 0.08, DT).unwrap();
        let mut plan = vec![0.0; 11];
        assert!(matches!(
            s.solve(&[0.0; 3], &[0.0; 10], &mut plan),
            Err(ControlError::InvalidSetting {
                field: "reference",
                ..
            })
        ));
    }

    #[test]
    fn validate_names_the_field() {
        let field = |s: DfMpcSettings| match s.validate() {
            Err(ControlError::InvalidSetting { field, .. }) => field,
            other => panic!("expected an invalid setting, got {other:?}"),
        };
        assert!(DfMpcSettings::default().validate().is_ok());
        let d = DfMpcSettings::default();
        assert_eq!(field(DfMpcSettings { horizon: 1, ..d }), "horizon");
        assert_eq!(
            field(DfMpcSettings {
                tracking_weight: [1.0, f64::NAN, 1.0],
                ..d
            }),
            "tracking_weight"
        );
        assert_eq!(
            field(DfMpcSettings {
                jerk_weight: [0.08, 0.08, -1.0],
                ..d
            }),
            "jerk_weight"
        );
        let sat = InputSaturation {
            max_tilt: 2.0,
            ..Default::default()
        };
        assert_eq!(
            field(DfMpcSettings {
                saturation: Some(sat),
                ..d
            }),
            "saturation.max_tilt"
        );
        let sat = InputSaturation {
            thrust_max: 1.0,
            ..Default::default()
        };
        assert_eq!(
            field(DfMpcSettings {
                saturation: Some(sat),
                ..d
            }),
            "saturation.thrust_max"
        );
        let c = OutputConstraints {
            max_speed: Some(0.0),
            ..Default::default()
        };
        assert_eq!(
            field(DfMpcSettings {
                constraints: c,
                ..d
            }),
            "constraints.max_speed"
        );
        let c = OutputConstraints {
            vertical_acceleration: Some([1.0, 2.0]),
            ..Default::default()
        };
        assert_eq!(
            field(DfMpcSettings {
                constraints: c,
                ..d
            }),
            "constraints.vertical_acceleration"
        );
        assert_eq!(
            field(DfMpcSettings {
                solver_time_limit: 0.0,
                ..d
            }),
            "solver_time_limit"
        );
    }

    #[test]
    fn banded_failure_falls_back_to_clarabel_and_says_so() {
        let model = || {
            ControlModel::Planar(
                dflat_model::PlanarModel::new(dflat_model::PlanarParams::default()).unwrap(),
            )
        };
        let settings = |qp_solver| DfMpcSettings {
            constraints: OutputConstraints {
                max_tilt: Some(20f64.to_radians()),
                ..Default::default()
            },
            qp_solver,
            solver_time_limit: f64::INFINITY,
            ..Default::default()
        };
        let mut banded = DfMpc::new(model(), settings(QpSolver::Banded)).unwrap();
        let mut broken = DfMpc::new(model(), settings(QpSolver::Banded)).unwrap();
        let mut clarabel = DfMpc::new(model(), settings(QpSolver::Clarabel)).unwrap();
        // A banded solver built for another horizon refuses every problem
        // of this controller (length check): the axis goes to clarabel.
        let bounds = AxisBounds {
            acceleration: Some([-1.0, 1.0]),
            speed: None,
        };
        for b in &mut broken.bounded {
            *b = Some(
                BoundedAxisSolver::new(10, (1.0, 0.08, DT), bounds, Smoothness::default()).unwrap(),
            );
        }
        let m = Measurement {
            t: 0.0,
            position: Vector3::zeros(),
            yaw: 0.0,
        };
        let target = Vector3::new(10.0, -10.0, 0.0);
        let tick = |c: &mut DfMpc| {
            let mut r = crate::reference::Reference::setpoint(target).unwrap();
            c.update(&m, &mut r).unwrap()
        };
        let (a, b, c) = (tick(&mut banded), tick(&mut broken), tick(&mut clarabel));
        assert!(a.constrained && b.constrained && c.constrained);
        assert!(!a.qp_fallback && b.qp_fallback && !c.qp_fallback);
        // The fallback's command is clarabel's.
        assert_eq!(b.command, c.command);
        assert!(
            (a.command.pitch - c.command.pitch).abs() < 1e-4,
            "{a:?} {c:?}"
        );
    }
}
