//! The box's fallback: one axis's inequality-constrained DF-MPC problem
//! ([`StageQp`]) on the banded interior point of [`super::banded_ip`]
//! (one axis: stage `[λ_f, ã_f, p_f]`), and
//! [`BandedInteriorPointSolver`], the box's member of the cascade.
//!
//! Bound rows (all hard): the acceleration bounds act on
//! single ã entries, the speed bounds on two p entries, the tilt-rate
//! rows on three ã entries (`Row::tilt_rate`). The KKT matrix has
//! half-bandwidth 4 (λ_f reaches back to p_{f−2}), 6 with the smoothness
//! term or the tilt-rate rows (ã_f with ã_{f−2}).
//!
//! All storage is allocated in [`StageQp::new`].

use super::banded_ip::{AxisCost, BandedIp, Stages};
use super::bounds::AxisBounds;
use super::bounds::{Row, check_row_data};
use super::cascade::{AxisSolver, Carry, SolveFailure, SolveInfo, SolverFault, SolverMethod};
use super::fast_banded::FastBandedSolver;
use super::problem::{AxisProblem, baseline};
use super::smoothness::Smoothness;
use super::smoothness::{accel_block, sent_linear_term};
use crate::ControlError;

pub use super::banded::BandedLdl;

/// Iteration limit.
pub const MAX_ITERATIONS: usize = 40;
/// Iteration limit with tilt-rate rows (long stretches of active
/// three-entry rows; random cases needed up to ~60 from the witness start).
pub const MAX_ITERATIONS_TILT_RATE: usize = 100;

/// One axis: stage `[λ_f, ã_f, p_f]`.
const STAGES: Stages = Stages { axes: 1 };

/// KKT index of ã_f.
fn a_at(f: usize) -> usize {
    STAGES.accel(0, f)
}
/// KKT index of p_f.
fn p_at(f: usize) -> usize {
    STAGES.output(0, f)
}

/// The axis problem's interior-point solver (see the module docs).
#[derive(Debug, Clone)]
pub struct StageQp {
    ip: BandedIp,
    dt: f64,
}

impl StageQp {
    /// A solver for n ≥ 1 free outputs at step δt: tracking weight q, the
    /// ã block of P (`[diag, (k−1, k), (k−2, k)]` per column, as
    /// clarabel's), and bound rows on ã_f for `acceleration` and on
    /// `(p_{f} − p_{f−1})/δt`, f = −1..n−2 (p_{−1} = 0), for `speed`, and
    /// with `tilt_rate = Some(κ)` the tilt-rate rows on ã
    /// (`Row::tilt_rate`).
    pub fn new(
        n: usize,
        q: f64,
        dt: f64,
        accel: &[[f64; 3]],
        acceleration: bool,
        speed: bool,
        tilt_rate: Option<f64>,
    ) -> Self {
        let mut rows = Vec::new();
        if acceleration {
            rows.extend((0..n).map(|f| Row::single(a_at(f))));
        }
        if speed {
            // Speed rows j = 2..N−1 on y_j, y_{j+1}: p_{j−3}, p_{j−2}.
            rows.extend((0..n).map(|g| Row::speed(g, dt, p_at)));
        }
        if let Some(kappa) = tilt_rate {
            rows.extend((0..n).map(|f| Row::tilt_rate(f, kappa, a_at)));
        }
        let cost = AxisCost {
            q,
            accel: accel.to_vec(),
        };
        let max_iterations = if tilt_rate.is_some() {
            MAX_ITERATIONS_TILT_RATE
        } else {
            MAX_ITERATIONS
        };
        // Every row hard.
        let penalty = vec![f64::INFINITY; rows.len()];
        let ip = BandedIp::new(n, dt, &[&cost], rows, penalty, None, max_iterations);
        Self { ip, dt }
    }

    /// Number of bound rows.
    pub fn rows(&self) -> usize {
        self.ip.rows()
    }

    /// The rows' multipliers `[upper, lower]` of the last iterate (≥ 0;
    /// the Lagrangian's `z_u·(g·x − hi) + z_l·(lo − g·x)`), in row order.
    pub fn duals(&self, out: &mut [[f64; 2]]) {
        self.ip.duals(out);
    }

    /// Solves for the linear terms `c_p` (on p, length n) and `c_a0` (on
    /// ã_0) and the row bounds `lo ≤ g·x ≤ hi` (one pair per row, in row
    /// order); `p` holds the start on entry (the unconstrained optimum is a
    /// good one) and the solution on exit. Returns the iterations.
    pub fn solve(
        &mut self,
        c_p: &[f64],
        c_a0: f64,
        lo: &[f64],
        hi: &[f64],
        p: &mut [f64],
    ) -> Result<usize, ControlError> {
        let m = self.rows();
        check_row_data(
            "stage QP",
            c_p.len() == p.len() && p.len() == self.ip.n() && lo.len() == m && hi.len() == m,
            "c_p and p need n entries, lo and hi one per row",
            &[c_p, p, &[c_a0]],
            lo,
            hi,
        )?;
        let c = self.ip.linear_mut();
        c.fill(0.0);
        for (f, &cp) in c_p.iter().enumerate() {
            c[p_at(f)] = cp;
        }
        c[a_at(0)] = c_a0;
        self.ip.set_start(&[p], self.dt);
        self.ip.set_bounds(lo, hi, [0.0; 2]);
        let iterations = self.ip.solve()?;
        for (f, pf) in p.iter_mut().enumerate() {
            *pf = self.ip.p(0, f);
        }
        Ok(iterations)
    }
}

/// The 1-D DF-MPC problem with inequality bounds, solved by the banded
/// interior-point method of [`StageQp`]: clarabel's variables and
/// cost ([`ClarabelSolver`](super::ClarabelSolver)), the KKT system ordered by stage, so
/// O(N) per iteration. It starts from the unconstrained optimum (computed
/// here with the fast path). [`DfMpc`](crate::dfmpc::DfMpc) uses it first and falls back to
/// clarabel when it does not converge.
#[derive(Debug, Clone)]
pub struct BandedInteriorPointSolver {
    fast: FastBandedSolver,
    bounds: AxisBounds,
    qp: StageQp,
    c_p: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    p: Vec<f64>,
    iterations: usize,
    /// The rows' multipliers of the last solve ([`StageQp::duals`]).
    duals: Vec<[f64; 2]>,
}

impl BandedInteriorPointSolver {
    /// Builds the solver for horizon N, weights `(q, r, δt)` as
    /// [`FastBandedSolver::with_smoothness`], the bounds and the smoothness term.
    pub fn new(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        let fast = bounds.fast_solver(horizon, (q, r, dt), smoothness)?;
        let n = horizon - 2;
        let accel = accel_block(n, r, dt, &smoothness);
        let qp = StageQp::new(
            n,
            q,
            dt,
            &accel,
            bounds.acceleration.is_some(),
            bounds.speed.is_some(),
            bounds.tilt_rate.map(|t| t.kappa),
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
            duals: vec![[0.0; 2]; m],
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

    /// The rows' multipliers `[upper, lower]` of the last solve, in the
    /// order of `AxisBounds::row_bounds` (acceleration, speed, tilt
    /// rate): a warm start for the augmented Lagrangian.
    pub fn row_duals(&self) -> &[[f64; 2]] {
        &self.duals
    }

    /// Solves with the bounds; arguments as [`FastBandedSolver::solve_problem`].
    /// Errors: those of the fast path, and [`ControlError::Solver`] when
    /// the interior-point method does not converge (infeasible bounds,
    /// numerical trouble).
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let (fixed, sent, reference, plan) = a.checked(self.fast.horizon())?;
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
        if let Some(rate) = &self.bounds.tilt_rate {
            // With the tilt-rate rows the start is the witness trajectory
            // at half the rate (strictly inside the rate rows): the
            // unconstrained plan breaks those narrow rows by many times
            // their width and the iterates then crawl (40 iterations were
            // not enough on random cases). p from ã: Δ²p_f = ã_f·δt².
            let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            let (mut pm2, mut pm1, mut f) = (0.0, 0.0, 0);
            let p = &mut self.p;
            rate.witness(
                self.fast.horizon,
                fixed,
                sent,
                self.bounds.acceleration_at(fixed, dt),
                dt,
                0.5,
                |a| {
                    let pf = 2.0 * pm1 - pm2 + (a - a0) * dt * dt;
                    p[f] = pf;
                    (pm2, pm1, f) = (pm1, pf, f + 1);
                },
            );
        }
        let sm = self.fast.smoothness;
        let c_a0 = sent_linear_term(&sm, fixed, sent, dt);
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut i = 0;
        self.bounds
            .row_bounds(self.fast.horizon, fixed, sent, dt, |l, h| {
                lo[i] = l;
                hi[i] = h;
                i += 1;
            });
        self.iterations = self
            .qp
            .solve(&self.c_p, c_a0, &self.lo, &self.hi, &mut self.p)?;
        self.qp.duals(&mut self.duals);
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + self.p[f];
        }
        if plan.iter().any(|v| !v.is_finite()) {
            return Err(SolverFault::NonFinite.into());
        }
        Ok(())
    }
}

impl AxisSolver for BandedInteriorPointSolver {
    fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.bounds.offset = offset;
        self.bounds.offset_slope = slope;
    }

    fn solve(&mut self, axis: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        let method = SolverMethod::InteriorPoint;
        self.solve_problem(axis)
            .map_err(|e| SolveFailure::from_error(method, self.iterations(), e))?;
        Ok(SolveInfo {
            iterations: self.iterations(),
            ..SolveInfo::of(method)
        })
    }

    fn row_duals(&self) -> &[[f64; 2]] {
        BandedInteriorPointSolver::row_duals(self)
    }

    /// Nothing carries: each solve starts from its own interior point.
    fn carry(&mut self, _event: Carry<'_>) {}
}
