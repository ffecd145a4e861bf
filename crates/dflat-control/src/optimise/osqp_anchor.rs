//! OSQP on the box's QP: the anchor of the corner bench (feature
//! `osqp-bench`, never in the default build; `docs/performance.md`, "OSQP
//! beside clarabel").
//!
//! The QP is clarabel's ([`ClarabelSolver`], built from the same
//! arguments): the same P (upper triangle), q, A and b, read from the
//! clarabel set-up each tick without solving it. Clarabel's rows are
//! `A·x + s = b`: the equality rows become `l = u = b`; its inequality
//! rows come in pairs `row ≤ hi`, `−row ≤ −lo` (every row of the box's
//! bounds), merged into one OSQP row `lo ≤ row ≤ hi` (OSQP's own form: one
//! KKT row per bound instead of two); a row without its negation after it
//! would stay one-sided (`−∞ ≤ row ≤ b`).
//!
//! Set up once; per tick `update_lin_cost`, `update_bounds`, then
//! `warm_start(x, y)` from the previous solve's primal and dual solution,
//! shifted one stage (the horizon moves one tick: variable f takes
//! f + 1's value, each row block likewise; [`OsqpWarm::Previous`] for the
//! unshifted previous solution), and `solve`. Polishing off.

use std::time::Duration;

use clarabel::algebra::CscMatrix as ClarabelCsc;
use osqp::{CscMatrix, Problem, Settings, Status};

use super::bounds::AxisBounds;
use super::cascade::{AxisSolver, SolverFault};
use super::clarabel::{ClarabelSolver, KktTuning};
use super::problem::{AxisProblem, baseline};
use super::smoothness::Smoothness;
use crate::ControlError;

/// Bounds at or beyond this magnitude are infinite to OSQP.
const OSQP_INFINITY: f64 = 1e30;

/// What OSQP's warm start is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OsqpWarm {
    /// The previous tick's solution and duals, shifted one stage.
    Shifted,
    /// The previous tick's solution and duals as they are.
    Previous,
    /// Cold: OSQP's zero start every tick.
    Cold,
}

/// OSQP's tolerances and iteration cap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OsqpTuning {
    /// `eps_abs` and `eps_rel`.
    pub eps: f64,
    /// `max_iter`.
    pub max_iter: u32,
    /// The warm start.
    pub warm: OsqpWarm,
}

/// The outcome of one OSQP solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OsqpOutcome {
    /// `Solved`.
    Solved,
    /// Any other status (named).
    Not(&'static str),
}

/// One axis's box QP in OSQP (module docs).
pub struct OsqpBoxSolver {
    horizon: usize,
    dt: f64,
    clarabel: ClarabelSolver,
    problem: Problem,
    tuning: OsqpTuning,
    /// Per OSQP row: the clarabel row of its upper bound, and of its
    /// negated lower bound (none: equality row when `eq`, else one-sided).
    rows: Vec<(usize, Option<usize>, bool)>,
    l: Vec<f64>,
    u: Vec<f64>,
    /// The last solve's primal and dual solution (empty before one), and
    /// its planned outputs y_3..y_N.
    x: Vec<f64>,
    y: Vec<f64>,
    outputs: Vec<f64>,
    /// Scratch: the warm start.
    wx: Vec<f64>,
    wy: Vec<f64>,
    /// The last solve's status, ADMM iterations and OSQP's own run time.
    outcome: OsqpOutcome,
    iterations: u32,
    run_time: Duration,
}

crate::optimise::problem::debug_without!(OsqpBoxSolver: horizon, tuning);

/// Row `r` of a CSC matrix as (column, value) pairs.
fn csc_rows(a: &ClarabelCsc<f64>) -> Vec<Vec<(usize, f64)>> {
    let mut rows = vec![Vec::new(); a.m];
    for c in 0..a.n {
        for k in a.colptr[c]..a.colptr[c + 1] {
            rows[a.rowval[k]].push((c, a.nzval[k]));
        }
    }
    rows
}

fn negation(a: &[(usize, f64)], b: &[(usize, f64)]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && x.1 == -y.1)
}

impl OsqpBoxSolver {
    /// OSQP on the QP of `ClarabelSolver::with_tuning(horizon, weights,
    /// bounds, ∞, smoothness, SHIPPED)`.
    pub fn new(
        horizon: usize,
        weights: (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
        tuning: OsqpTuning,
    ) -> Result<Self, ControlError> {
        let mut clarabel = ClarabelSolver::with_tuning(
            horizon,
            weights,
            bounds,
            f64::INFINITY,
            smoothness,
            KktTuning::SHIPPED,
        )?;
        let zeros = [0.0; 3];
        let reference = vec![0.0; horizon + 1];
        let (p, q, a, _, m_eq) = clarabel.qp_for(&zeros, None, &reference);
        let a_rows = csc_rows(a);
        let mut rows = Vec::new();
        let mut r = 0;
        while r < a_rows.len() {
            if r < m_eq {
                rows.push((r, None, true));
                r += 1;
            } else if r + 1 < a_rows.len() && negation(&a_rows[r], &a_rows[r + 1]) {
                rows.push((r, Some(r + 1), false));
                r += 2;
            } else {
                rows.push((r, None, false));
                r += 1;
            }
        }
        // A in OSQP's rows, column by column.
        let nv = a.n;
        let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); nv];
        for (i, &(r, _, _)) in rows.iter().enumerate() {
            for &(c, v) in &a_rows[r] {
                cols[c].push((i, v));
            }
        }
        let (mut indptr, mut indices, mut data) = (vec![0], Vec::new(), Vec::new());
        for col in &cols {
            for &(i, v) in col {
                indices.push(i);
                data.push(v);
            }
            indptr.push(indices.len());
        }
        let a_osqp = CscMatrix {
            nrows: rows.len(),
            ncols: nv,
            indptr: indptr.into(),
            indices: indices.into(),
            data: data.into(),
        };
        let p_osqp = CscMatrix {
            nrows: p.m,
            ncols: p.n,
            indptr: p.colptr.clone().into(),
            indices: p.rowval.clone().into(),
            data: p.nzval.clone().into(),
        };
        let settings = Settings::default()
            .verbose(false)
            .polishing(false)
            .warm_starting(true)
            .eps_abs(tuning.eps)
            .eps_rel(tuning.eps)
            .max_iter(tuning.max_iter);
        let m = rows.len();
        let (l, u) = (vec![-OSQP_INFINITY; m], vec![OSQP_INFINITY; m]);
        let problem = Problem::new(p_osqp, q, a_osqp, &l, &u, &settings)
            .map_err(|_| ControlError::from(SolverFault::SetupRefused))?;
        Ok(Self {
            horizon,
            dt: weights.2,
            clarabel,
            problem,
            tuning,
            rows,
            l,
            u,
            x: Vec::new(),
            y: Vec::new(),
            outputs: Vec::new(),
            wx: vec![0.0; nv],
            wy: vec![0.0; m],
            outcome: OsqpOutcome::Not("not run"),
            iterations: 0,
            run_time: Duration::ZERO,
        })
    }

    /// OSQP rows (after merging clarabel's pairs).
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// The last solve's outcome.
    pub fn outcome(&self) -> OsqpOutcome {
        self.outcome
    }

    /// The last solve's ADMM iterations.
    pub fn iterations(&self) -> u32 {
        self.iterations
    }

    /// OSQP's own run time of the last solve (its profiler).
    pub fn run_time(&self) -> Duration {
        self.run_time
    }

    /// Forgets the previous solution: the next solve starts from the plan
    /// it is given (the fast path's at a burst's first tick), duals zero.
    pub fn forget(&mut self) {
        self.x.clear();
        self.y.clear();
        self.outputs.clear();
    }

    /// The warm start from the previous solution (module docs) for the
    /// problem of `fixed` (the new baseline), into `wx`, `wy`.
    fn shifted_start(&mut self, fixed: &[f64; 3]) {
        let n = self.horizon - 2;
        let dt2 = self.dt * self.dt;
        // The previous plan's outputs one step on: y'_j = y_{j+1} (free
        // output f takes f + 1's), the last continued linearly; then its
        // deviations from the new baseline and its accelerations.
        let prev = &self.outputs;
        let out = |f: usize| -> f64 {
            if f + 1 < n {
                prev[f + 1]
            } else {
                2.0 * prev[n - 1] - prev[n - 2]
            }
        };
        let y = |j: usize| -> f64 { if j < 3 { fixed[j] } else { out(j - 3) } };
        let d2_0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / dt2;
        for f in 0..n {
            self.wx[f] = out(f) - baseline(fixed, f + 3);
            let j = f + 1;
            self.wx[n + f] = (y(j + 2) - 2.0 * y(j + 1) + y(j)) / dt2 - d2_0;
        }
        // Duals: each block of n rows shifted one stage (blocks: the
        // equality rows, then each bound's rows, n per bound).
        let m = self.rows.len();
        for (block, chunk) in self.wy.chunks_mut(n).enumerate() {
            let start = block * n;
            for (f, v) in chunk.iter_mut().enumerate() {
                let src = (start + f + 1).min(start + n - 1).min(m - 1);
                *v = self.y[src];
            }
        }
    }

    /// The warm start from the plan `y_0..y_N` given on entry (this
    /// tick's, not shifted), duals zero, into `wx`, `wy`.
    fn entry_start(&mut self, fixed: &[f64; 3], plan: &[f64]) {
        let n = self.horizon - 2;
        let dt2 = self.dt * self.dt;
        let y = |j: usize| if j < 3 { fixed[j] } else { plan[j] };
        let d2_0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / dt2;
        for f in 0..n {
            self.wx[f] = plan[f + 3] - baseline(fixed, f + 3);
            let j = f + 1;
            self.wx[n + f] = (y(j + 2) - 2.0 * y(j + 1) + y(j)) / dt2 - d2_0;
        }
        self.wy.fill(0.0);
    }

    /// This tick's offset of the plan's acceleration from the thrust's and
    /// its change per stage ([`AxisSolver::set_offset`]): the bounds OSQP
    /// is given move with them, as clarabel's do.
    pub fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.clarabel.set_offset(offset, slope);
    }

    /// Solves one axis's problem (plan on exit: OSQP's solution when it
    /// solved, untouched otherwise).
    pub fn solve_axis(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let (fixed, sent, reference, plan) = a.checked(self.horizon)?;
        let (_, q, _, b, _) = self.clarabel.qp_for(fixed, sent, reference);
        for (i, &(hi_row, lo_row, eq)) in self.rows.iter().enumerate() {
            let hi = b[hi_row];
            if eq {
                self.l[i] = hi;
                self.u[i] = hi;
            } else {
                self.u[i] = hi.min(OSQP_INFINITY);
                self.l[i] = lo_row.map_or(-OSQP_INFINITY, |r| (-b[r]).max(-OSQP_INFINITY));
            }
        }
        self.problem.update_lin_cost(q);
        self.problem.update_bounds(&self.l, &self.u);
        let n = self.horizon - 2;
        if self.x.is_empty() && self.tuning.warm != OsqpWarm::Cold {
            // No previous solve (or forgotten: a burst's first tick): the
            // plan given on entry (the fast path's), duals zero.
            self.entry_start(fixed, plan);
            self.problem.warm_start(&self.wx, &self.wy);
        }
        let warm = if self.x.is_empty() {
            None
        } else {
            Some(self.tuning.warm)
        };
        match warm {
            None => {}
            Some(OsqpWarm::Shifted) => {
                self.shifted_start(fixed);
                self.problem.warm_start(&self.wx, &self.wy);
            }
            Some(OsqpWarm::Previous) => self.problem.warm_start(&self.x, &self.y),
            Some(OsqpWarm::Cold) => {
                self.wx.fill(0.0);
                self.wy.fill(0.0);
                self.problem.warm_start(&self.wx, &self.wy);
            }
        }
        let status = self.problem.solve();
        self.iterations = status.iter();
        self.run_time = status.run_time();
        let (outcome, solution) = match &status {
            Status::Solved(s) => (OsqpOutcome::Solved, Some(s.clone())),
            Status::SolvedInaccurate(_) => (OsqpOutcome::Not("SolvedInaccurate"), None),
            Status::MaxIterationsReached(_) => (OsqpOutcome::Not("MaxIterationsReached"), None),
            Status::TimeLimitReached(_) => (OsqpOutcome::Not("TimeLimitReached"), None),
            Status::PrimalInfeasible(_) | Status::PrimalInfeasibleInaccurate(_) => {
                (OsqpOutcome::Not("PrimalInfeasible"), None)
            }
            Status::DualInfeasible(_) | Status::DualInfeasibleInaccurate(_) => {
                (OsqpOutcome::Not("DualInfeasible"), None)
            }
            _ => (OsqpOutcome::Not("other"), None),
        };
        self.outcome = outcome;
        let Some(s) = solution else {
            // The next tick starts from the last solution it had.
            let status = match outcome {
                OsqpOutcome::Not(status) => status,
                OsqpOutcome::Solved => "Solved without a solution",
            };
            return Err(SolverFault::Osqp(status).into());
        };
        let (x, y) = (s.x(), s.y());
        plan[..3].copy_from_slice(fixed);
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + x[f];
        }
        self.x.clear();
        self.x.extend_from_slice(x);
        self.outputs.clear();
        self.outputs.extend_from_slice(&plan[3..]);
        self.y.clear();
        self.y.extend_from_slice(y);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optimise::cascade::SolverFault;

    /// A 10 m step from rest under a ±3 m/s² interval, N = 100.
    fn step(solver: &mut OsqpBoxSolver) -> Result<Vec<f64>, ControlError> {
        let horizon = 100;
        let mut plan = vec![0.0; horizon + 1];
        solver.solve_axis(AxisProblem {
            fixed: &[0.0; 3],
            sent: Some(0.0),
            reference: &vec![10.0; horizon + 1],
            plan: &mut plan,
        })?;
        Ok(plan)
    }

    fn solver(max_iter: u32) -> OsqpBoxSolver {
        let bounds = AxisBounds {
            acceleration: Some([-3.0, 3.0]),
            ..Default::default()
        };
        let tuning = OsqpTuning {
            eps: 1e-6,
            max_iter,
            warm: OsqpWarm::Shifted,
        };
        OsqpBoxSolver::new(
            100,
            (1.0, 0.003, 0.02),
            bounds,
            Smoothness::default(),
            tuning,
        )
        .unwrap()
    }

    /// OSQP stopped at its iteration cap says so by its status (not as our
    /// own solvers' "not converged"), and gives no plan; with room it
    /// solves the same step within its bounds.
    #[test]
    fn an_unsolved_status_is_named_in_the_fault() {
        let err = step(&mut solver(2)).unwrap_err();
        assert_eq!(
            err,
            ControlError::Solver {
                method: None,
                fault: SolverFault::Osqp("MaxIterationsReached"),
            }
        );
        assert_eq!(
            err.to_string(),
            "QP solver failed: OSQP status MaxIterationsReached"
        );
        let mut s = solver(20_000);
        let plan = step(&mut s).unwrap();
        assert_eq!(s.outcome(), OsqpOutcome::Solved);
        for w in plan.windows(3) {
            let a = (w[2] - 2.0 * w[1] + w[0]) / (0.02 * 0.02);
            assert!(a.abs() <= 3.0 + 1e-3, "acceleration {a}");
        }
    }
}
