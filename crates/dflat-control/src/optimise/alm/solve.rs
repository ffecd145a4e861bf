//! The solve (module docs of [`super`]): semismooth Newton on the
//! augmented Lagrangian inside, the multiplier and σ updates outside, the
//! window and the rollout start at a cold solve's beginning.

use super::super::bounds::check_row_data;
use super::{
    BandedAlm, DECREMENT_TOLERANCE, DUAL_TOLERANCE, GAP_TOLERANCE, INEXACT, LOCAL_STOP,
    LOOSE_REUSE, MAX_OUTER, PRIMAL_TOLERANCE, REUSE_DECREMENT, ROW_TOLERANCE, SIGMA_GROWTH,
    STALL_TOLERANCE, StageSet,
};
use crate::ControlError;

impl BandedAlm {
    /// Assembles and factors the generalised Hessian at x: in the window,
    /// its rows only, into the head's factor (`head`, whose rows before
    /// the window are P's: `window.rs`); else all of it.
    fn factor_newton_matrix(&mut self, lo: &[f64], hi: &[f64]) -> Result<(), ControlError> {
        if self.window > 0 {
            let from = self.window_unknown();
            // Rows the last window changed before this one's are P's again.
            let start = from.min(self.head_base_until);
            self.assemble(lo, hi, start);
            if let Err(e) = self.head.refactor_rows_from(&self.kkt, start) {
                self.head_valid = false;
                return Err(e);
            }
            self.head_base_until = from;
            self.head_factored = true;
        } else {
            self.assemble(lo, hi, 0);
            self.chol.refactor_taking(&mut self.kkt)?;
            self.head_factored = false;
        }
        self.factorisations += 1;
        self.factored_active.clone_from(&self.active);
        Ok(())
    }

    /// Solves for the linear term `c` (K·n, interleaved), fixed relative
    /// accelerations `a0` [m/s²] and row bounds `lo ≤ h·x ≤ hi` from the
    /// primal start ([`BandedAlm::set_start`]) and the multipliers held
    /// (zero, or shifted from the last solve). Returns the Newton steps;
    /// errors when it does not converge within [`MAX_NEWTON_STEPS`](super::MAX_NEWTON_STEPS).
    pub fn solve(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<usize, ControlError> {
        let m = self.rows.len();
        check_row_data(
            "ALM",
            c.len() == self.k * self.n && lo.len() == m && hi.len() == m,
            "c needs K·n entries, lo and hi one per row",
            &[c, &self.x, &a0],
            lo,
            hi,
        )?;
        if let StageSet::Interval(b) = &self.stages
            && b.iter()
                .flat_map(|s| s.iter().take(self.k))
                .any(|[l, h]| l.is_nan() || h.is_nan() || l > h)
        {
            return Err(super::super::problem::invalid(
                "ALM",
                "stage intervals with lo ≤ hi",
            ));
        }
        self.c.copy_from_slice(c);
        self.px_current = false;
        self.window = 0;
        self.last_window = 0;
        self.rollout_started = false;
        // Held only from a line search's full step to the gradient right
        // after it, so None here; cleared all the same, the one place a
        // stale stage pass could enter.
        self.full_step = None;
        let mut cold = false;
        if self.y.iter().all(|y| *y == [0.0; 2]) && self.v.iter().all(|v| *v == [0.0; 2]) {
            // Cold: a softer first subproblem (AlmTuning::sigma_cold).
            self.sigma = self.tuning.sigma_cold;
            cold = true;
        }
        let max_steps = if cold {
            2 * self.tuning.max_newton_steps
        } else {
            self.tuning.max_newton_steps
        };
        let c_scale = 1.0 + c.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        // P·x has entries ~1e10 even by differencing: its rounding floor,
        // ε·max|P_ii|·|x| (1e-5 at δt = 0.02 s, r = 0.01), bounds how
        // small a freshly computed gradient can be made. The gradient
        // carried along full steps (P·x and u updated by the step's) goes
        // below it, and after a step on a reused factor (a chord step,
        // which converges linearly) a gradient below it can still hide a
        // decrement above tolerance in the cost's flat directions: the
        // floor ends the inner solve only right after a full Newton step
        // on a fresh factor, whose next decrement is of its square.
        let x_scale = 1.0 + self.x.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let floor = 16.0 * f64::EPSILON * self.diag_max * x_scale;
        let dual_tol = DUAL_TOLERANCE * c_scale;
        let decrement_tol = DECREMENT_TOLERANCE * c_scale * x_scale;
        self.factorisations = 0;
        let (mut last_full, mut last_decrement) = (false, f64::INFINITY);
        let mut reuse_allowed = true;
        let mut compare_decrement = f64::INFINITY;
        // Whether the factor is of this solve's matrix at the current σ.
        let mut factor_current = false;
        // Whether the last step was a full Newton step on a fresh factor.
        let mut exact_full = false;
        let exact_reuse = matches!(self.stages, StageSet::Interval(_));
        // The rows' largest σ scale (σ_h = scale·σ), for the inexact
        // tolerance.
        let row_scale_max = self.row_scale.iter().fold(0.0f64, |a, b| a.max(*b));
        let inner_tol = decrement_tol;
        let stage_tol = PRIMAL_TOLERANCE * (1.0 + self.stage_scale());
        let gap_tol = GAP_TOLERANCE * c_scale * x_scale;
        let b_scale = 1.0 + lo.iter().chain(hi).fold(0.0f64, |a, b| a.max(b.abs()));
        // A soft side's violation costs ρ per unit: its tolerance is ρ
        // times tighter so that the cost is as accurate as the stages'.
        let rho = self
            .row_penalty
            .iter()
            .filter(|r| r.is_finite())
            .fold(1.0f64, |a, b| a.max(*b));
        let row_tol = if self.row_penalty.iter().all(|r| r.is_infinite()) {
            ROW_TOLERANCE * b_scale
        } else {
            PRIMAL_TOLERANCE * b_scale / rho
        };
        self.newton_steps = 0;
        if self.polish.is_some() {
            // One axis with rows: the active-set method alone (module docs),
            // or from rest the interior point.
            if cold
                && self.tuning.interior_point_from_rest
                && self.breaks_early(a0[0], super::FROM_REST_STAGES)
            {
                return Err(ControlError::Solver(
                    "active set: a cold start from rest".into(),
                ));
            }
            return if self.polish(a0[0], (lo, hi), (stage_tol, row_tol))? {
                Ok(0)
            } else {
                Err(ControlError::Solver(
                    "active set: no convergence within its KKT solves".into(),
                ))
            };
        }
        // The window's first gradient is the loop's first.
        let mut first_gradient = None;
        // Whether σ climbs to the warm σ after each update (module docs):
        // a cold solve's, unless the rollout start gave it multipliers.
        let mut climb = cold;
        if cold && self.tuning.rollout_start && self.rollout_start(a0) {
            climb = false;
            self.rollout_started = true;
        } else if cold && self.tuning.eliminate_head {
            first_gradient = Some(self.open_window(a0, lo, hi, 10.0 * floor.max(dual_tol)));
        }
        let mut previous_res = f64::INFINITY;
        for _outer in 0..MAX_OUTER {
            // Inner: minimise L(·; y, v, σ) by semismooth Newton, until
            // the gradient or the Newton decrement −gᵀd is negligible.
            let (mut stage_res, mut row_res);
            // Whether the inner solve ended converged, not merely accurate
            // enough for the next update (only then may the solve stop).
            let mut inner_done = true;
            loop {
                let gn;
                (gn, stage_res, row_res) = match first_gradient.take() {
                    Some(done) => done,
                    None => self.gradient(a0, lo, hi),
                };
                if gn <= dual_tol || (gn <= floor && exact_full) {
                    break;
                }
                if self.newton_steps == max_steps {
                    return Err(ControlError::Solver(format!(
                        "ALM: no convergence in {} Newton steps \
                         (gradient {gn:.1e}, residual {:.1e})",
                        max_steps,
                        stage_res.max(row_res)
                    )));
                }
                self.newton_steps += 1;
                // Inexact inner solves while the multipliers are far off:
                // the subproblem's error (≈ decrement/2) need only be small
                // against the change the next update will make, σ·res².
                let row_sigma = row_scale_max * self.sigma;
                let loose = self.sigma * (INEXACT * stage_res).powi(2)
                    + row_sigma * (INEXACT * row_res).powi(2);
                // Intervals: the matrix is fixed by σ and the active set,
                // so with the active set the one factored the factor is
                // exact. Discs: in the local phase (last step full, its
                // decrement small, the active set the one factored) the
                // matrix changes only in the active stages' curvature: its
                // factor is reused.
                let same_set = factor_current && self.active == self.factored_active;
                let reuse = same_set
                    && reuse_allowed
                    && (exact_reuse
                        || last_full
                            && last_decrement
                                <= (REUSE_DECREMENT * c_scale * x_scale).max(LOOSE_REUSE * loose));
                reuse_allowed = true;
                if !reuse {
                    self.factor_newton_matrix(lo, hi)?;
                    factor_current = true;
                }
                // −g on the window (the eliminated head's gradient is 0;
                // the solve sets d there).
                let j0 = self.window_unknown();
                for (d, g) in self.d[j0..].iter_mut().zip(&self.g[j0..]) {
                    *d = -g;
                }
                let factor = if self.head_factored {
                    &self.head
                } else {
                    &self.chol
                };
                factor.solve_in_place_cut(&mut self.d, j0, self.cut)?;
                let decrement: f64 = -self.g[j0..]
                    .iter()
                    .zip(&self.d[j0..])
                    .map(|(g, d)| g * d)
                    .sum::<f64>();
                if (decrement.is_nan() || decrement <= 0.0) && reuse {
                    // The old factor no longer gives a descent direction.
                    last_full = false;
                    reuse_allowed = false;
                    continue;
                }
                if reuse && !exact_reuse && decrement > 0.1 * compare_decrement {
                    // The old factor converges slowly here: refactor next.
                    reuse_allowed = false;
                }
                last_decrement = decrement;
                compare_decrement = decrement;
                if decrement <= inner_tol.max(loose) {
                    // Converged to rounding (or enough for this update):
                    // the full step, and done.
                    inner_done = decrement <= inner_tol;
                    self.move_x(1.0);
                    self.px_current = false;
                    (_, stage_res, row_res) = self.gradient(a0, lo, hi);
                    break;
                }
                last_full = self.line_search(decrement, lo, hi)?;
                exact_full = last_full && !reuse;
                if last_full && !reuse && decrement <= LOCAL_STOP * c_scale * x_scale {
                    // A full step from a small decrement: the next one is
                    // of its square (Newton's local rate), below tolerance.
                    (_, stage_res, row_res) = self.gradient(a0, lo, hi);
                    break;
                }
            }
            // What the residuals can cost, needed only once they are small
            // (before the multipliers move).
            let residuals_small = stage_res <= stage_tol && row_res <= row_tol;
            // At the largest σ the residual can stall at rounding: a
            // stage on its boundary with a vanishing multiplier flipped
            // in and out of the set with every update (a 2-cycle at 17×
            // the tolerance, 7e-7 m/s², `PROPTEST_RNG_SEED=15`), σ unable
            // to grow. There a stage residual within STALL_TOLERANCE× its
            // tolerance ends the solve, if what it can cost is as small
            // (the rows, whose hard bounds are checked to 1e-9, keep
            // theirs).
            let stalled = self.sigma >= self.tuning.sigma_max
                && stage_res <= STALL_TOLERANCE * stage_tol
                && row_res <= row_tol;
            // An inexact inner solve's residuals are no proof: the step
            // that ended it was the model's with the active set it
            // started from (a warm start whose rows all let go at once
            // stopped there 0.6 % above the optimum's cost).
            let gap_small =
                inner_done && (residuals_small || stalled) && self.residual_cost(lo, hi) <= gap_tol;
            // Multiplier update (the gradient above is the Lagrangian's
            // with the updated multipliers: stationarity holds).
            self.y.copy_from_slice(&self.y_next);
            for r in 0..m {
                let h = self.hx[r];
                for j in 0..2 {
                    let t = Self::side(j, h, lo[r], hi[r]);
                    self.v[r][j] = self.side_multiplier(r, self.v[r][j], t);
                }
            }
            if gap_small && self.window > 0 {
                // The window converged: on to the whole horizon, whose
                // first gradient finds whether a stage or row of the head
                // binds after all (then the solve goes on there).
                self.close_window();
                compare_decrement = f64::INFINITY;
                continue;
            }
            if gap_small {
                if self.x.iter().any(|v| !v.is_finite()) {
                    return Err(ControlError::Solver("ALM: non-finite iterate".into()));
                }
                return Ok(self.newton_steps);
            }
            let res = (stage_res / stage_tol).max(row_res / row_tol);
            // σ grows tenfold when the residual stalls, and on a cold
            // solve after every update until it reaches the warm σ: the
            // soft first subproblem found the active set, and at σ = 1e2
            // an update gains only ~3× (corner bench, N = 200, warm starts
            // off: 8.53 → 7.81 G instructions, interior-point fallbacks
            // 10 → 0 of 1905).
            let climbing = climb && self.sigma < self.tuning.sigma;
            if res > 1.0
                && (climbing || res > 0.1 * previous_res)
                && self.sigma < self.tuning.sigma_max
            {
                self.sigma = (self.sigma * SIGMA_GROWTH).min(self.tuning.sigma_max);
                factor_current = false;
            }
            // The multipliers moved: the next decrement is not comparable.
            compare_decrement = f64::INFINITY;
            previous_res = res;
        }
        Err(ControlError::Solver(
            "ALM: no convergence in the multiplier updates".into(),
        ))
    }
}
