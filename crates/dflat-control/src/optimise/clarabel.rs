//! The bounded per-axis QP in clarabel: the fallback of the banded interior
//! point (and the reference the property tests compare it with).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

use super::bounds::AxisBounds;
use super::cascade::{AxisSolver, Carry, SolveFailure, SolveInfo, SolverFault, SolverMethod};
use super::fast_banded::FastBandedSolver;
use super::problem::{AxisProblem, baseline, invalid};
use super::smoothness::Smoothness;
use super::smoothness::{accel_block, sent_linear_term};
use crate::ControlError;

/// The 1-D DF-MPC problem with inequality bounds, solved by clarabel.
///
/// Variables `[p_0..p_{n−1}, ã_0..ã_{n−1}]`, n = N − 2: `p` the deviations
/// of the free outputs `y_3..y_N` from the zero-jerk baseline `b` of the
/// fixed outputs, `ã_{j−1} = Δ²y_j/δt² − Δ²y_0/δt²` the planned
/// accelerations j = 1..N−2 relative to the fixed one [m/s²]. Cost
/// `Σ q·p² + 2q·(b − ref)·p + Σ_j (r/δt²)·(ã_j − ã_{j−1})²` (ã_{−1} = 0;
/// the jerk term, so the same minimiser as [`FastBandedSolver`]); equality rows
/// `Δ²p_j/δt² − ã_{j−1} = 0`; acceleration bounds are single-entry rows on
/// ã, speed bounds rows on Δp/δt. The sparsity is fixed at construction;
/// each solve updates `q` and `b` only. Without bounds this is the plain DF
/// QP handed to a generic solver (the benchmark baseline).
///
/// The smoothness term ([`Smoothness`]) in these variables: with
/// `A_j = a_j − a_0 = ã_{j−1}`, `c_j − c_{j−1} = κ·ã_j + (1 − 2κ)·ã_{j−1}
/// − (1 − κ)·ã_{j−2}` (ã before 0 is 0) plus `a_0 − c_{−1}` at j = 0: band 2
/// in P, the sent command in q. The tilt-rate rows ([`super::TiltRate`])
/// are the same combination, bounded (row 0: ã_0 alone).
pub struct ClarabelSolver {
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

crate::optimise::problem::debug_without!(ClarabelSolver: horizon, dt, q, bounds);

/// Clarabel's KKT settings for [`ClarabelSolver`] (the rest of its
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
    /// Duality-gap tolerance, absolute and relative (clarabel's
    /// `tol_gap_abs`, `tol_gap_rel`; its default 1e-8).
    pub gap_tolerance: f64,
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
        gap_tolerance: 1e-8,
    };
    /// Clarabel 0.11's defaults (the accuracy reference in tests, and a
    /// benchmark baseline).
    pub const CLARABEL_DEFAULTS: Self = Self {
        static_regularization: 1e-12,
        refinement_reltol: 1e-13,
        refinement_abstol: 1e-12,
        gap_tolerance: 1e-8,
    };
    /// Clarabel's defaults solved to a duality gap of 1e-11: the reference
    /// of tests that compare plans to 1e-5 m on problems whose cost reaches
    /// 1e6 (there a relative gap of 1e-8 leaves the plan ~1e-5 m loose).
    pub const REFERENCE: Self = Self {
        gap_tolerance: 1e-11,
        ..Self::CLARABEL_DEFAULTS
    };
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

/// One axis's columns of P (upper triangle) at `offset`: `2q` on its n
/// deviations p, then on its n accelerations ã the jerk and smoothness
/// block (`band`, [`accel_block`]) — the layout `[p, ã]` of both clarabel
/// problems.
pub(super) fn push_axis_hessian(
    n: usize,
    q: f64,
    band: &[[f64; 3]],
    offset: usize,
    (colptr, prow, pval): (&mut Vec<usize>, &mut Vec<usize>, &mut Vec<f64>),
) {
    for f in 0..n {
        prow.push(offset + f);
        pval.push(2.0 * q);
        colptr.push(prow.len());
    }
    let a_of = |f: usize| offset + n + f;
    for (f, col) in band.iter().enumerate().take(n) {
        if f > 1 && col[2] != 0.0 {
            prow.push(a_of(f - 2));
            pval.push(col[2]);
        }
        if f > 0 {
            prow.push(a_of(f - 1));
            pval.push(col[1]);
        }
        prow.push(a_of(f));
        pval.push(col[0]);
        colptr.push(prow.len());
    }
}

/// The one clarabel set-up of both problems (the box's QP, the cone's
/// SOCP): the time limit checked (> 0 s or infinite), presolve off (the
/// data are updated in place per tick), no equilibration (the variables
/// are in SI units and well scaled: measured on 10 000 random instances,
/// Ruiz equilibration costs speed and two to four orders of accuracy in
/// the first planned jerk), qdldl on one thread, the KKT tuning given.
pub(super) fn build_solver(
    (p, q): (&CscMatrix<f64>, &[f64]),
    (a, b): (&CscMatrix<f64>, &[f64]),
    cones: &[SupportedConeT<f64>],
    time_limit: f64,
    tuning: KktTuning,
) -> Result<DefaultSolver<f64>, ControlError> {
    if time_limit.is_nan() || time_limit <= 0.0 {
        return Err(invalid("solver_time_limit", "> 0 s (or infinity)"));
    }
    let settings: DefaultSettings<f64> = DefaultSettingsBuilder::default()
        .verbose(false)
        .presolve_enable(false)
        .equilibrate_enable(false)
        .iterative_refinement_reltol(tuning.refinement_reltol)
        .iterative_refinement_abstol(tuning.refinement_abstol)
        .tol_gap_abs(tuning.gap_tolerance)
        .tol_gap_rel(tuning.gap_tolerance)
        .static_regularization_constant(tuning.static_regularization)
        .time_limit(time_limit)
        .direct_solve_method("qdldl".to_string())
        .max_threads(1)
        .build()
        .map_err(|_| ControlError::from(SolverFault::SetupRefused))?;
    DefaultSolver::new(p, q, a, b, cones, settings)
        .map_err(|_| ControlError::from(SolverFault::SetupRefused))
}

impl ClarabelSolver {
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

    /// As [`ClarabelSolver::new`], plus the command-smoothness term.
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

    /// As [`ClarabelSolver::with_smoothness`] with the weights as
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
        FastBandedSolver::check_args(horizon, q, r, dt)?;
        smoothness.check()?;
        let n = horizon - 2;
        let nv = 2 * n;
        // P (upper triangle): 2q on p; on ã the jerk and smoothness terms.
        let band = accel_block(n, r, dt, &smoothness);
        let (mut colptr, mut prow, mut pval) = (vec![0usize], Vec::new(), Vec::new());
        push_axis_hessian(n, q, &band, 0, (&mut colptr, &mut prow, &mut pval));
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
        if let Some(rate) = &bounds.tilt_rate {
            rate.check()?;
            // Tilt-rate rows on ã (the stage interior point's rows).
            let kp = rate.kappa;
            for f in 0..n {
                let coeffs = [kp, 1.0 - 2.0 * kp, kp - 1.0];
                let terms = if f == 0 { 1 } else { (f + 1).min(3) };
                for (d, &c) in coeffs.iter().enumerate().take(terms) {
                    let c = if f == 0 { 1.0 } else { c };
                    t.push(m, n + f - d, c);
                    t.push(m + 1, n + f - d, -c);
                }
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
        let solver = build_solver((&p_mat, &qvec), (&a_mat, &bvec), &cones, time_limit, tuning)?;
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

    /// Solves with the bounds; arguments as
    /// [`FastBandedSolver::solve_problem`]. A status other than `Solved`
    /// (infeasible bounds, time limit, numerical trouble) is
    /// [`ControlError::Solver`].
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let (fixed, sent, reference, plan) = a.checked(self.horizon)?;
        self.fill(fixed, sent, reference);
        self.solver
            .update_q(&self.qvec)
            .and_then(|()| self.solver.update_b(&self.bvec))
            .map_err(|_| ControlError::from(SolverFault::SetupRefused))?;
        self.solver.solve();
        let status = self.solver.solution.status;
        if status != SolverStatus::Solved {
            return Err(SolverFault::Clarabel(status).into());
        }
        let x = &self.solver.solution.x;
        let n = self.horizon - 2;
        plan[..3].copy_from_slice(fixed);
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + x[f];
        }
        if plan.iter().any(|v| !v.is_finite()) {
            return Err(SolverFault::NonFinite.into());
        }
        Ok(())
    }

    /// This tick's `q` and `b` (lengths checked by the caller) into the
    /// solver's own vectors, not yet handed to clarabel.
    fn fill(&mut self, fixed: &[f64; 3], sent: Option<f64>, reference: &[f64]) {
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
        self.bounds
            .row_bounds(self.horizon, fixed, sent, dt, |lo, hi| {
                bvec[m] = hi;
                bvec[m + 1] = -lo;
                m += 2;
            });
    }

    /// The QP clarabel is given (`½xᵀPx + qᵀx`, `A·x + s = b`, s in the
    /// cones: the first `m_eq` rows zero, the rest nonnegative) for this
    /// tick's problem, without solving it: P (upper triangle), q, A, b and
    /// `m_eq` (the OSQP anchor of the corner bench takes the same data).
    #[cfg(feature = "osqp-bench")]
    pub(crate) fn qp_for(
        &mut self,
        fixed: &[f64; 3],
        sent: Option<f64>,
        reference: &[f64],
    ) -> (&CscMatrix<f64>, &[f64], &CscMatrix<f64>, &[f64], usize) {
        self.fill(fixed, sent, reference);
        let data = &self.solver.data;
        (&data.P, &self.qvec, &data.A, &self.bvec, self.m_eq)
    }
}

impl AxisSolver for ClarabelSolver {
    fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.bounds.offset = offset;
        self.bounds.offset_slope = slope;
    }

    fn solve(&mut self, axis: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        let method = SolverMethod::Clarabel;
        self.solve_problem(axis)
            .map_err(|e| SolveFailure::from_error(method, 0, e))?;
        Ok(SolveInfo::of(method))
    }

    /// Nothing carries: clarabel solves each QP from its own start.
    fn carry(&mut self, _event: Carry<'_>) {}

    /// None given: the cascade's last solver, whose plan alone is handed
    /// to the solvers before it.
    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }
}
