//! The two-axis tilt-cone problem ([`super::cone`]) as a second-order cone
//! program in clarabel: the fallback of [`BandedConeSolver`](super::BandedConeSolver)
//! and the reference its property tests compare with.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use super::bounds::Row;
use super::cascade::{Carry, PairSolver, SolveFailure, SolveInfo, SolverFault, SolverMethod};
use super::clarabel::{KktTuning, build_solver, push_axis_hessian};
use super::cone::ConeBounds;
use super::cone_solver::AxisWeights;
use super::fast_banded::FastBandedSolver;
use super::problem::{AxisProblem, baseline};
use super::smoothness::{accel_block, sent_linear_term};
use crate::ControlError;

/// Both horizontal axes with the tilt cone, solved by clarabel.
///
/// Variables `[p_x, ã_x, p_y, ã_y, σ]` (n = N − 2 each; σ the elastic
/// variables of the soft speed sides, 4n of them, when there is a speed
/// bound and it is soft). Per axis the cost, the equality rows
/// `Δ²p_f/δt² − ã_f = 0`, the speed rows and the tilt-rate rows (hard) as
/// [`ClarabelSolver`](super::ClarabelSolver); per stage f the cone
/// `(A, ã_{x,f} + a_{0,x}, ã_{y,f} + a_{0,y}) ∈ SOC₃`. The sparsity is fixed
/// at construction; each solve updates `q` and `b` only.
pub struct ClarabelConeSolver {
    horizon: usize,
    dt: f64,
    weights: [AxisWeights; 2],
    bounds: ConeBounds,
    /// The cone's radius per stage [m/s²] (the bounds' A unless set), and
    /// the one enforced this solve (with a tilt-rate bound the funnel,
    /// [`ConeBounds`]).
    radius: Vec<f64>,
    stage_radius: Vec<f64>,
    /// The cone's centre per stage o_f [m/s²] (zeros unless set).
    centre: Vec<[f64; 2]>,
    soft: bool,
    solver: DefaultSolver<f64>,
    qvec: Vec<f64>,
    bvec: Vec<f64>,
    /// First speed row, first tilt-rate row, first cone row.
    m_speed: usize,
    m_rate: usize,
    m_cone: usize,
}

crate::optimise::problem::debug_without!(ClarabelConeSolver: horizon, dt, bounds, soft);

impl ClarabelConeSolver {
    /// Builds the solver once for horizon N, step δt \[s\], per-axis
    /// weights (x, y), the bounds, the clarabel time limit \[s\], whether
    /// the speed rows are soft (as [`BandedConeSolver`](super::BandedConeSolver):
    /// `true`; `false` gives the hard-bounded reference problem) and
    /// clarabel's KKT settings.
    pub fn new(
        horizon: usize,
        dt: f64,
        weights: [AxisWeights; 2],
        bounds: ConeBounds,
        time_limit: f64,
        soft: bool,
        tuning: KktTuning,
    ) -> Result<Self, ControlError> {
        for w in &weights {
            FastBandedSolver::check_args(horizon, w.q, w.r, dt)?;
            w.smoothness.check()?;
        }
        bounds.check()?;
        let n = horizon - 2;
        let speed = bounds.speed.is_some();
        let soft = soft && speed;
        let n_sig = if soft { 4 * n } else { 0 };
        let nv = 4 * n + n_sig;
        // P, upper triangle, column by column: per axis [p, ã].
        let (mut colptr, mut prow, mut pval) = (vec![0usize], Vec::new(), Vec::new());
        for (i, w) in weights.iter().enumerate() {
            let band = accel_block(n, w.r, dt, &w.smoothness);
            push_axis_hessian(
                n,
                w.q,
                &band,
                2 * n * i,
                (&mut colptr, &mut prow, &mut pval),
            );
        }
        for _ in 0..n_sig {
            colptr.push(prow.len());
        }
        let p_mat = CscMatrix::new(nv, nv, colptr, prow, pval);

        let rows = constraint_rows(n, dt, &bounds, soft);
        let (m, m_speed, m_rate, m_cone) = (rows.m, rows.m_speed, rows.m_rate, rows.m_cone);
        let (tr, tc, tv) = (rows.r, rows.c, rows.v);
        let a_mat = CscMatrix::new_from_triplets(m, nv, tr, tc, tv);
        let mut cones = vec![SupportedConeT::ZeroConeT(2 * n)];
        if m_cone > m_speed {
            cones.push(SupportedConeT::NonnegativeConeT(m_cone - m_speed));
        }
        cones.extend((0..n).map(|_| SupportedConeT::SecondOrderConeT(3)));
        let mut qvec = vec![0.0; nv];
        qvec[4 * n..].fill(bounds.speed_penalty);
        let mut bvec = vec![0.0; m];
        for f in 0..n {
            bvec[m_cone + 3 * f] = bounds.acceleration;
        }
        let solver = build_solver((&p_mat, &qvec), (&a_mat, &bvec), &cones, time_limit, tuning)?;
        Ok(Self {
            horizon,
            dt,
            weights,
            radius: vec![bounds.acceleration; n],
            stage_radius: vec![bounds.acceleration; n],
            centre: vec![[0.0; 2]; n],
            bounds,
            soft,
            solver,
            qvec,
            bvec,
            m_speed,
            m_rate,
            m_cone,
        })
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &ConeBounds {
        &self.bounds
    }

    /// Sets the cone's radius per stage A_f [m/s²] (N − 2 entries, finite
    /// and > 0; stage f bounds the acceleration of output f + 2) for the
    /// next solves, instead of the bounds' constant A.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.radius.len())?;
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// Sets the cone's centre per stage o_f [m/s²] (N − 2 entries,
    /// finite) for the next solves: the cone bounds `‖a_f − o_f‖ ≤ A_f`
    /// (as [`super::BandedConeSolver::set_centre`]).
    pub fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        super::cone::check_centre(centre, self.centre.len())?;
        self.centre.copy_from_slice(centre);
        Ok(())
    }

    /// Solves both axes (arguments as
    /// [`BandedConeSolver::solve_pair`](super::BandedConeSolver::solve_pair);
    /// the plans' contents on entry are not used). A status other than
    /// `Solved` is [`ControlError::Solver`].
    pub fn solve_pair(
        &mut self,
        x: AxisProblem<'_>,
        y: AxisProblem<'_>,
    ) -> Result<(), ControlError> {
        super::problem::check_pair(self.horizon, &x, &y)?;
        let (n, dt) = (self.horizon - 2, self.dt);
        let fixed = [x.fixed, y.fixed];
        let sent = [x.sent, y.sent];
        self.bounds.funnel_radius(
            (&self.radius, &self.centre),
            fixed,
            sent,
            dt,
            &mut self.stage_radius,
        );
        for (i, a) in [&x, &y].into_iter().enumerate() {
            let q = self.weights[i].q;
            for f in 0..n {
                self.qvec[2 * n * i + f] =
                    2.0 * q * (baseline(a.fixed, f + 3) - a.reference[f + 3]);
            }
            self.qvec[2 * n * i + n] =
                sent_linear_term(&self.weights[i].smoothness, a.fixed, a.sent, dt);
            let a0 = (a.fixed[2] - 2.0 * a.fixed[1] + a.fixed[0]) / (dt * dt);
            for f in 0..n {
                self.bvec[self.m_cone + 3 * f] = self.stage_radius[f];
                self.bvec[self.m_cone + 3 * f + 1 + i] = a0 - self.centre[f][i];
            }
        }
        // The rows in `ConeBounds::rows`'s order: the speed rows (each a
        // pair of sides from m_speed), then the tilt-rate rows (from m_rate).
        let bvec = &mut self.bvec;
        let speed_rows = if self.bounds.speed.is_some() {
            2 * n
        } else {
            0
        };
        let (m_speed, m_rate) = (self.m_speed, self.m_rate);
        let mut k = 0;
        self.bounds.row_bounds(
            self.horizon,
            fixed,
            sent,
            &self.radius,
            &self.centre,
            dt,
            |lo, hi| {
                let m = if k < speed_rows {
                    m_speed + 2 * k
                } else {
                    m_rate + 2 * (k - speed_rows)
                };
                bvec[m] = hi;
                bvec[m + 1] = -lo;
                k += 1;
            },
        );
        self.solver
            .update_q(&self.qvec)
            .and_then(|()| self.solver.update_b(&self.bvec))
            .map_err(|_| ControlError::from(SolverFault::SetupRefused))?;
        self.solver.solve();
        let status = self.solver.solution.status;
        if status != SolverStatus::Solved {
            return Err(SolverFault::Clarabel(status).into());
        }
        let sol = &self.solver.solution.x;
        for (i, (plan, fx)) in [x.plan, y.plan].into_iter().zip(fixed).enumerate() {
            plan[..3].copy_from_slice(fx);
            for f in 0..n {
                plan[f + 3] = baseline(fx, f + 3) + sol[2 * n * i + f];
            }
            if plan.iter().any(|v| !v.is_finite()) {
                return Err(SolverFault::NonFinite.into());
            }
        }
        Ok(())
    }
}

impl PairSolver for ClarabelConeSolver {
    fn solve(&mut self, x: AxisProblem<'_>, y: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        let method = SolverMethod::Clarabel;
        self.solve_pair(x, y)
            .map_err(|e| SolveFailure::from_error(method, 0, e))?;
        Ok(SolveInfo::of(method))
    }

    fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        ClarabelConeSolver::set_radius(self, radius)
    }

    fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        ClarabelConeSolver::set_centre(self, centre)
    }

    /// Nothing carries: clarabel solves each SOCP from its own start.
    fn carry(&mut self, _event: Carry<'_>) {}
}

/// The constraint matrix's triplets of [`ClarabelConeSolver`] and where
/// each family of rows starts.
struct ConeRows {
    r: Vec<usize>,
    c: Vec<usize>,
    v: Vec<f64>,
    /// Rows in all; the first speed row, tilt-rate row and cone row.
    m: usize,
    m_speed: usize,
    m_rate: usize,
    m_cone: usize,
}

/// The rows of the two-axis problem over `[p_x, ã_x, p_y, ã_y, σ]` (n
/// each, σ the soft speed sides' elastic variables when `soft`): the
/// equality rows `Δ²p_f/δt² − ã_f = 0`, the speed rows (each side, with
/// its σ when soft) and σ ≥ 0, the tilt-rate rows (hard, each side), and
/// per stage the cone's three rows.
fn constraint_rows(n: usize, dt: f64, bounds: &ConeBounds, soft: bool) -> ConeRows {
    let speed = bounds.speed.is_some();
    let n_sig = if soft { 4 * n } else { 0 };
    let p_of = |i: usize, f: usize| 2 * n * i + f;
    let a_of = |i: usize, f: usize| 2 * n * i + n + f;
    let (mut tr, mut tc, mut tv) = (Vec::new(), Vec::new(), Vec::new());
    let mut push = |r: usize, c: usize, v: f64| {
        tr.push(r);
        tc.push(c);
        tv.push(v);
    };
    let inv_dt2 = 1.0 / (dt * dt);
    let mut m = 0;
    for i in 0..2 {
        for f in 0..n {
            push(m, p_of(i, f), inv_dt2);
            if f >= 1 {
                push(m, p_of(i, f - 1), -2.0 * inv_dt2);
            }
            if f >= 2 {
                push(m, p_of(i, f - 2), inv_dt2);
            }
            push(m, a_of(i, f), -1.0);
            m += 1;
        }
    }
    let m_speed = m;
    if speed {
        let mut sig = 4 * n;
        for i in 0..2 {
            for g in 0..n {
                // ±(p_g − p_{g−1})/δt − σ ≤ b.
                for sign in [1.0, -1.0] {
                    push(m, p_of(i, g), sign / dt);
                    if g >= 1 {
                        push(m, p_of(i, g - 1), -sign / dt);
                    }
                    if soft {
                        push(m, sig, -1.0);
                        sig += 1;
                    }
                    m += 1;
                }
            }
        }
        for s in 0..n_sig {
            push(m, 4 * n + s, -1.0);
            m += 1;
        }
    }
    // The tilt-rate rows per axis, hard: ±(row·ã) ≤ ±bound.
    let m_rate = m;
    if let Some(rates) = &bounds.tilt_rate {
        for (i, rate) in rates.iter().enumerate() {
            for f in 0..n {
                let row = Row::tilt_rate(f, rate.kappa, |s| a_of(i, s));
                for sign in [1.0, -1.0] {
                    for k in 0..row.len {
                        push(m, row.idx[k], sign * row.coef[k]);
                    }
                    m += 1;
                }
            }
        }
    }
    let m_cone = m;
    for f in 0..n {
        // s = b − A·x = (A, a_0x + ã_x, a_0y + ã_y).
        push(m + 1, a_of(0, f), -1.0);
        push(m + 2, a_of(1, f), -1.0);
        m += 3;
    }
    ConeRows {
        r: tr,
        c: tc,
        v: tv,
        m,
        m_speed,
        m_rate,
        m_cone,
    }
}
