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
//! one, the axis is re-solved with clarabel ([`ConstrainedAxisSolver`]) in
//! the same deviation variables plus the planned accelerations (cost
//! `q·(b + p − y_ref)² + r·(Δã/δt)²`, equality rows tie ã to Δ²p/δt², bounds
//! on ã are single-entry rows): a well-scaled sparse QP whose structure is
//! fixed, so one solver per axis is built once and only `q` and `b` are
//! updated per tick. A status other than `Solved` is [`ControlError::Solver`].

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::banded::{BandedCholesky, SymBand};
use crate::model::ControlModel;
use crate::window::Window;
use crate::{ControlError, Controller, Measurement, ReferenceSource, TickOutput};

/// Coefficients of the third difference `Δ³y_j` on `y_j..y_{j+3}`.
const D3: [f64; 4] = [-1.0, 3.0, -3.0, 1.0];
/// Half-bandwidth of the fast-path Hessian.
const BANDWIDTH: usize = 3;
/// Largest horizon accepted [steps].
pub const MAX_HORIZON: usize = 100_000;

// ---------------------------------------------------------------------------
// Settings
// ---------------------------------------------------------------------------

/// Input saturation applied to the command after the output-to-input map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputSaturation {
    /// Largest |pitch| and |roll| command [rad], each clipped separately.
    /// Default 35° (the DJI SDK limit).
    pub max_tilt: f64,
    /// Smallest specific thrust command [m/s²] (spatial model only). Default 2.
    pub thrust_min: f64,
    /// Largest specific thrust command [m/s²] (spatial model only). Default 20.
    pub thrust_max: f64,
}

impl Default for InputSaturation {
    fn default() -> Self {
        Self {
            max_tilt: 35f64.to_radians(),
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
    /// Max tilt [rad] as a bound on the horizontal acceleration per axis,
    /// `|Δ²y/δt²| ≤ g·tan(max_tilt)`. Default none.
    pub max_tilt: Option<f64>,
    /// Max speed per axis `|Δy/δt|` [m/s]. Default none.
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
    /// Wall-time limit for one clarabel solve [s] (`f64::INFINITY` for
    /// none). Default 0.01.
    pub solver_time_limit: f64,
}

impl Default for DfMpcSettings {
    fn default() -> Self {
        Self {
            horizon: 100,
            tracking_weight: [5.0; 3],
            jerk_weight: [0.01; 3],
            saturation: Some(InputSaturation::default()),
            constraints: OutputConstraints::default(),
            solver_time_limit: 0.01,
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
/// y_2]` [m], `reference` = `ref_0..ref_N` [m], `plan` receives `y*_0..y*_N`.
#[derive(Debug)]
pub struct AxisProblem<'a> {
    /// The fixed outputs `[y_0, y_1, y_2]` [m].
    pub fixed: &'a [f64; 3],
    /// The reference `ref_0..ref_N` [m] (length N + 1).
    pub reference: &'a [f64],
    /// Output: the optimal `y*_0..y*_N` [m] (length N + 1).
    pub plan: &'a mut [f64],
}

/// Per-right-hand-side workspace of [`AxisSolver`].
#[derive(Debug, Clone)]
struct Slot {
    /// Baseline b_3..b_N [m].
    base: Vec<f64>,
    /// q·(ref − b) on the free outputs.
    rhs: Vec<f64>,
    /// Deviation from the baseline.
    p: Vec<f64>,
    /// Residual, then the refinement correction.
    work: Vec<f64>,
}

/// The unconstrained 1-D DF-MPC problem on one axis, solved in O(N).
///
/// Minimises `Σ_{j=0..N} q·(y_j − ref_j)² + Σ_{j=0..N−3} r·(Δ³y_j/δt³)²`
/// over `y_0..y_N` with `y_0, y_1, y_2` fixed (relative indices: y_j is
/// `y_{k+j}`). The Hessian is factored once here; [`AxisSolver::solve`]
/// and [`AxisSolver::solve_pair`] allocate nothing.
#[derive(Debug, Clone)]
pub struct AxisSolver {
    horizon: usize,
    q: f64,
    /// Weight on the raw third difference, r/δt⁶.
    w: f64,
    factor: BandedCholesky,
    slots: [Slot; 2],
}

impl AxisSolver {
    /// Builds and factors the problem for horizon N ≥ 3 [steps], tracking
    /// weight q ≥ 0 [1/m²], jerk weight r > 0 [s⁶/m²], step δt > 0 [s].
    pub fn new(horizon: usize, q: f64, r: f64, dt: f64) -> Result<Self, ControlError> {
        Self::check_args(horizon, q, r, dt)?;
        let n = horizon - 2;
        let w = r / dt.powi(6);
        let mut hessian = SymBand::zeros(n, BANDWIDTH);
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
        let mut factor = BandedCholesky::new(n, BANDWIDTH);
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
            factor,
            slots: [slot.clone(), slot],
        })
    }

    /// Horizon N [steps].
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Tracking weight q [1/m²] and weight on the raw third difference
    /// `r/δt⁶` [1/m²].
    pub fn weights(&self) -> (f64, f64) {
        (self.q, self.w)
    }

    /// Baseline, right-hand side `q·(ref − b)` on the free outputs, `p = rhs`.
    fn prepare(q: f64, slot: &mut Slot, fixed: &[f64; 3], reference: &[f64]) {
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
    }

    /// `work = rhs − (q·I + w·DᵀD)·p`, evaluated by repeated differencing
    /// rather than with the assembled Hessian: the products of entries
    /// ~1e10 with outputs ~10 m would leave an absolute rounding error near
    /// 1e-4 in the residual, while differences of neighbouring samples are
    /// nearly exact, so the residual is accurate to ~ε·|rhs|.
    fn residual(q: f64, w: f64, slot: &mut Slot) {
        // x = w·D·p: third backward difference by three first differences,
        // fused in one pass (p before the horizon is 0).
        let (mut p1, mut e1, mut f1) = (0.0, 0.0, 0.0);
        for (x, &p) in slot.work.iter_mut().zip(&slot.p) {
            let e = p - p1;
            let f = e - e1;
            *x = w * (f - f1);
            (p1, e1, f1) = (p, e, f);
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

    /// Solves for the optimal outputs. `fixed` = `[y_0, y_1, y_2]` [m],
    /// `reference` = `ref_0..ref_N` [m] (length N + 1); writes `y*_0..y*_N`
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
        check_lengths(self.horizon, reference, plan)?;
        let (q, w) = (self.q, self.w);
        let slot = &mut self.slots[0];
        Self::prepare(q, slot, fixed, reference);
        self.factor.solve_in_place(&mut slot.p)?;
        Self::residual(q, w, slot);
        self.factor.solve_in_place(&mut slot.work)?;
        Self::write_plan(slot, fixed, plan);
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
        let [sa, sb] = &mut self.slots;
        Self::prepare(q, sa, a.fixed, a.reference);
        Self::prepare(q, sb, b.fixed, b.reference);
        self.factor.solve2_in_place(&mut sa.p, &mut sb.p)?;
        Self::residual(q, w, sa);
        Self::residual(q, w, sb);
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
    /// `v` with `|Δy_j/δt| ≤ v` [m/s], j = 2..N−1.
    pub speed: Option<f64>,
}

impl AxisBounds {
    /// True when no bound is set.
    pub fn is_empty(&self) -> bool {
        self.acceleration.is_none() && self.speed.is_none()
    }

    /// True when `plan` (`y_0..y_N` [m], step δt [s]) violates a bound by
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
pub struct ConstrainedAxisSolver {
    horizon: usize,
    dt: f64,
    q: f64,
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
    /// [s⁶/m²], step δt [s], bounds and clarabel time limit [s].
    pub fn new(
        horizon: usize,
        q: f64,
        r: f64,
        dt: f64,
        bounds: AxisBounds,
        time_limit: f64,
    ) -> Result<Self, ControlError> {
        // Same argument checks as the fast path.
        AxisSolver::check_args(horizon, q, r, dt)?;
        if time_limit.is_nan() || time_limit <= 0.0 {
            return Err(invalid("solver_time_limit", "> 0 s (or infinity)"));
        }
        let n = horizon - 2;
        let nv = 2 * n;
        // P (upper triangle): 2q on p; on ã the jerk term
        // (r/δt²)·Σ_j (ã_j − ã_{j−1})² (ã_{−1} = 0), doubled for ½xᵀPx.
        let ja = 2.0 * r / (dt * dt);
        let mut colptr = vec![0usize];
        let (mut prow, mut pval) = (Vec::new(), Vec::new());
        for c in 0..nv {
            if c < n {
                prow.push(c);
                pval.push(2.0 * q);
            } else {
                let k = c - n;
                if k > 0 {
                    prow.push(c - 1);
                    pval.push(-ja);
                }
                prow.push(c);
                pval.push(if k + 1 < n { 2.0 * ja } else { ja });
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
            // Looser than the default 1e-13/1e-12: ~20 % faster, same
            // accuracy of the plan (first jerk within 1e-9 m/s³ of the fast
            // path on unconstrained instances).
            .iterative_refinement_reltol(1e-10)
            .iterative_refinement_abstol(1e-10)
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
            bounds,
            solver,
            qvec,
            bvec,
            m_eq,
        })
    }

    /// Horizon N [steps].
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
        check_lengths(self.horizon, reference, plan)?;
        let n = self.horizon - 2;
        for f in 0..n {
            self.qvec[f] = 2.0 * self.q * (baseline(fixed, f + 3) - reference[f + 3]);
        }
        let mut m = self.m_eq;
        let dt = self.dt;
        if let Some([lo, hi]) = self.bounds.acceleration {
            let a_base = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            for _ in 1..=self.horizon - 2 {
                self.bvec[m] = hi - a_base;
                self.bvec[m + 1] = a_base - lo;
                m += 2;
            }
        }
        if let Some(v) = self.bounds.speed {
            let d1 = fixed[1] - fixed[0];
            let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
            for j in 2..=self.horizon - 1 {
                let s_base = (d1 + j as f64 * d2) / dt;
                self.bvec[m] = v - s_base;
                self.bvec[m + 1] = v + s_base;
                m += 2;
            }
        }
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
/// Commands use the model's fixed yaw ψ⋆ (the measured yaw is only checked
/// for being finite). Without binding constraints `update` allocates nothing
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
    /// Bounds per axis (empty when none).
    bounds: Vec<AxisBounds>,
    /// Reference y_ref,k..y_ref,k+N (model frame, m).
    reference: Vec<Vector3<f64>>,
    /// The reference split per axis.
    reference_axis: Vec<Vec<f64>>,
    /// Last plan y*_k..y*_{k+N} per axis.
    plans: Vec<Vec<f64>>,
    plan_valid: bool,
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
        let mut bounds = Vec::with_capacity(axes);
        for axis in 0..axes {
            let (q, r) = (settings.tracking_weight[axis], settings.jerk_weight[axis]);
            fast.push(AxisSolver::new(n, q, r, dt)?);
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
                Some(ConstrainedAxisSolver::new(
                    n,
                    q,
                    r,
                    dt,
                    b,
                    settings.solver_time_limit,
                )?)
            });
            bounds.push(b);
        }
        Ok(Self {
            model,
            settings,
            window: Window::new(model.hover_input()),
            fast,
            constrained,
            bounds,
            reference: vec![Vector3::zeros(); n + 1],
            reference_axis: vec![vec![0.0; n + 1]; axes],
            plans: vec![vec![0.0; n + 1]; axes],
            plan_valid: false,
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

    /// The window of past measurements and sent inputs.
    pub fn window(&self) -> &Window {
        &self.window
    }

    /// The full plan `y*_k..y*_{k+N}` [m] of `axis` (0 = x, 1 = y, 2 = z)
    /// from the last successful update; `None` before one, after a failed
    /// one or for an axis the model does not control.
    pub fn plan(&self, axis: usize) -> Option<&[f64]> {
        if self.plan_valid {
            self.plans.get(axis).map(|p| p.as_slice())
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
        out.x = u.x.clamp(-s.max_tilt, s.max_tilt);
        out.y = u.y.clamp(-s.max_tilt, s.max_tilt);
        if matches!(self.model, ControlModel::Spatial(_)) {
            out.z = u.z.clamp(s.thrust_min, s.thrust_max);
        }
        (out, out != u)
    }
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
        self.plan_valid = false;
        let axes = self.model.axes();
        if !(measurement
            .position
            .iter()
            .take(axes)
            .all(|v| v.is_finite())
            && measurement.yaw.is_finite())
        {
            return Err(ControlError::NonFiniteMeasurement);
        }
        // Work on a copy: on error nothing is recorded.
        let mut window = self.window;
        window.push_measurement(measurement.position);

        // Input-to-output map over the window: y_{k+1}, y_{k+2}.
        let [ym2, ym1, y0] = *window.outputs();
        let [u2, u1] = *window.inputs();
        let y1 = self.model.next_output(&[ym2, ym1, y0], &u2)?;
        let y2 = self.model.next_output(&[ym1, y0, y1], &u1)?;
        let fixed = [y0, y1, y2];

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
        let paired = self.fast[0].weights() == self.fast[1].weights();
        let [px, py, pz @ ..] = self.plans.as_mut_slice() else {
            unreachable!("DfMpc::new makes at least two plans")
        };
        if paired {
            self.fast[0].solve_pair(
                AxisProblem {
                    fixed: &fixed_axis[0],
                    reference: &self.reference_axis[0],
                    plan: px,
                },
                AxisProblem {
                    fixed: &fixed_axis[1],
                    reference: &self.reference_axis[1],
                    plan: py,
                },
            )?;
        } else {
            self.fast[0].solve(&fixed_axis[0], &self.reference_axis[0], px)?;
            self.fast[1].solve(&fixed_axis[1], &self.reference_axis[1], py)?;
        }
        if let Some(plan) = pz.first_mut() {
            self.fast[2].solve(&fixed_axis[2], &self.reference_axis[2], plan)?;
        }
        let mut constrained = false;
        let dt = self.model.dt();
        let axes_data = self
            .constrained
            .iter_mut()
            .zip(&mut self.plans)
            .zip(&self.reference_axis);
        for (((cs, plan), reference), fixed) in axes_data.zip(&fixed_axis) {
            if let Some(cs) = cs
                && cs.bounds().violated_by(plan, dt)
            {
                cs.solve(fixed, reference, plan)?;
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
        let u = self.model.input_from_outputs(&plan4)?;
        if !u.iter().all(|v| v.is_finite()) {
            return Err(ControlError::Flat(dflat_model::FlatError::NonFinite(
                "input",
            )));
        }
        let (sent, saturated) = self.saturate(u);
        window.push_input(sent);
        self.window = window;
        self.plan_valid = true;
        Ok(TickOutput {
            command: self.model.command(&sent),
            plan: plan4,
            reference: self.reference[0],
            saturated,
            constrained,
        })
    }

    fn reset(&mut self) {
        self.window.reset();
        self.plan_valid = false;
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

    #[test]
    fn infeasible_bounds_are_a_solver_error() {
        // Moving at 5 m/s with |v| ≤ 1 m/s and |a| ≤ 1 m/s²: cannot slow down in time.
        let bounds = AxisBounds {
            acceleration: Some([-1.0, 1.0]),
            speed: Some(1.0),
        };
        let mut cs = ConstrainedAxisSolver::new(50, 1.0, 0.08, DT, bounds, f64::INFINITY).unwrap();
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
}
