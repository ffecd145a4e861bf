//! The solve (module docs of [`super`]) in named phases: the data
//! checked ([`BandedAlm::check_data`]), the solve begun and its
//! tolerances set ([`BandedAlm::begin`]), one axis with rows handed to the
//! active-set method, a cold solve's start (the rollout or the window),
//! then outer iterations of an inner semismooth Newton solve on the
//! augmented Lagrangian ([`BandedAlm::inner_solve`]) and the multiplier
//! and σ update with its stopping tests ([`BandedAlm::outer_update`]).

use super::super::bounds::check_solve_data;
use super::super::cascade::SolverFault;
use super::{
    BLOCKED_STEP, BandedAlm, DECREMENT_TOLERANCE, DUAL_TOLERANCE, Factored, GAP_TOLERANCE,
    GAP_TOLERANCE_AFTER_INTERIOR, INEXACT, LOCAL_STOP, LOOSE_REUSE, MAX_OUTER, PRIMAL_TOLERANCE,
    REUSE_DECREMENT, REUSE_DECREMENT_DISCS, ROW_TOLERANCE, SIGMA_GROWTH, STALL_TOLERANCE, StageSet,
};
use crate::ControlError;

/// The scales and tolerances of one solve (module docs of [`super`]).
#[derive(Debug, Clone, Copy)]
struct Tolerances {
    /// `1 + max|c|` and `1 + max|x|` at the start.
    c_scale: f64,
    x_scale: f64,
    /// The rounding floor of a freshly computed gradient.
    floor: f64,
    /// The gradient's, the Newton decrement's, the stage and row
    /// residuals' and the residuals' cost's tolerances.
    dual: f64,
    decrement: f64,
    stage: f64,
    row: f64,
    gap: f64,
    /// The rows' largest σ scale (for the inexact tolerance).
    row_scale_max: f64,
    /// Newton steps allowed.
    max_steps: usize,
    /// Whether the inner solve gives up at a blocked step
    /// ([`BLOCKED_STEP`]: a warm start's first, when the caller has a
    /// better start).
    give_up_blocked: bool,
}

/// The inner loop's memory across Newton steps and outer iterations.
#[derive(Debug, Clone, Copy)]
struct NewtonMemory {
    /// Whether the last step was full, and its decrement.
    last_full: bool,
    last_decrement: f64,
    /// Whether the next step may reuse the factor.
    reuse_allowed: bool,
    /// The decrement a reused factor must beat tenfold.
    compare_decrement: f64,
    /// Whether the last step was a full Newton step on a fresh factor.
    exact_full: bool,
}

/// How an inner solve ended: its residuals and whether it converged
/// (not merely accurate enough for the next update).
#[derive(Debug, Clone, Copy)]
struct InnerEnd {
    stage_res: f64,
    row_res: f64,
    converged: bool,
}

/// What the outer update decided.
enum Outer {
    /// Solved: the Newton steps.
    Done(usize),
    /// On to the next outer iteration (`previous_res` the residual).
    Continue(f64),
}

impl BandedAlm {
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
        let result = self.solve_from_start(c, a0, lo, hi);
        if result.is_err() && self.ws.window > 0 {
            // A window left open would leave its cut to the next solve
            // (whose steps would then skip the head, and whose first
            // substitution panics), and the head unmoved by its steps:
            // closed, the iterate is whole for a restart from it.
            self.close_window();
        }
        result
    }

    /// [`BandedAlm::solve`] itself, which may leave a window open on an
    /// error.
    fn solve_from_start(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<usize, ControlError> {
        self.check_data(c, a0, lo, hi)?;
        let cold = self.begin(c);
        let mut tol = self.tolerances(cold, lo, hi);
        if std::mem::take(&mut self.handed_over) {
            tol.gap *= GAP_TOLERANCE_AFTER_INTERIOR / GAP_TOLERANCE;
        }
        self.hard_row_weight = self.hard_row_residual_weight(lo, hi, tol.row);
        if self.polish.is_some() {
            return self.solve_rows(a0[0], (lo, hi), &tol);
        }
        // Whether σ climbs to the warm σ after each update (module docs):
        // a cold solve's, unless the rollout start gave it multipliers.
        let mut climb = cold;
        // The window's first gradient is the loop's first.
        let mut first_gradient = None;
        if cold && self.tuning.rollout_start && self.rollout_start(a0) {
            climb = false;
            self.ws.rollout_started = true;
        } else if cold && self.tuning.eliminate_head {
            let head_tol = 10.0 * tol.floor.max(tol.dual);
            first_gradient = Some(self.open_window(a0, lo, hi, head_tol));
        }
        let mut memory = NewtonMemory {
            last_full: false,
            last_decrement: f64::INFINITY,
            reuse_allowed: true,
            compare_decrement: f64::INFINITY,
            exact_full: false,
        };
        let mut previous_res = f64::INFINITY;
        for outer in 0..MAX_OUTER {
            // A warm start far from its optimum gives up early when told
            // to (`first_inner_steps`: the caller has a better start).
            let mut inner_tol = tol;
            if outer == 0 && !cold {
                inner_tol.max_steps = tol.max_steps.min(self.first_inner_steps);
                inner_tol.give_up_blocked = self.first_inner_steps < usize::MAX;
            }
            let end =
                self.inner_solve(a0, (lo, hi), &inner_tol, &mut memory, first_gradient.take())?;
            match self.outer_update(end, (lo, hi), &tol, climb, previous_res)? {
                Outer::Done(steps) => return Ok(steps),
                Outer::Continue(res) => previous_res = res,
            }
            // The multipliers moved: the next decrement is not comparable.
            memory.compare_decrement = f64::INFINITY;
        }
        Err(SolverFault::NotConverged {
            iterations: self.ws.newton_steps,
        }
        .into())
    }

    /// The data's shapes and finiteness, and the stage intervals' order.
    fn check_data(
        &self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<(), ControlError> {
        check_solve_data(
            "ALM",
            (c, self.k * self.n),
            self.rows.len(),
            &self.ws.x,
            &a0,
            (lo, hi),
            "c needs K·n entries, lo and hi one per row",
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
        Ok(())
    }

    /// Begins a solve: the linear term taken, the workspace's per-solve
    /// state cleared, σ the cold one when every multiplier is zero.
    /// Returns whether the solve is cold.
    fn begin(&mut self, c: &[f64]) -> bool {
        self.ws.c.copy_from_slice(c);
        self.ws.px_current = false;
        self.ws.window = 0;
        self.ws.cut = 0;
        self.ws.last_window = 0;
        self.ws.rollout_started = false;
        self.ws.newton_steps = 0;
        self.ws.factorisations = 0;
        self.factored = Factored::Stale;
        // Held only from a line search's full step to the gradient right
        // after it, so None here; cleared all the same, the one place a
        // stale stage pass could enter.
        self.ws.full_step = None;
        let cold = self.warm.y.iter().all(|y| *y == [0.0; 2])
            && self.warm.v.iter().all(|v| *v == [0.0; 2]);
        if cold {
            // Cold: a softer first subproblem (AlmTuning::sigma_cold).
            self.sigma = self.tuning.sigma_cold;
        }
        cold
    }

    /// The factor of hard rows' residuals beside soft rows
    /// (the field `hard_row_weight`): `row_tol` over
    /// [`ROW_TOLERANCE`] of the hard rows' bounds' scale; 1 without soft
    /// rows (`row_tol` is then the hard rows' own).
    fn hard_row_residual_weight(&self, lo: &[f64], hi: &[f64], row_tol: f64) -> f64 {
        if self.row_penalty.iter().all(|r| r.is_infinite()) {
            return 1.0;
        }
        row_tol / (ROW_TOLERANCE * self.hard_row_scale(lo, hi))
    }

    /// The solve's scales and tolerances (module docs of [`super`]).
    fn tolerances(&self, cold: bool, lo: &[f64], hi: &[f64]) -> Tolerances {
        let c_scale = 1.0 + self.ws.c.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let x_scale = 1.0 + self.ws.x.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let b_scale = 1.0 + lo.iter().chain(hi).fold(0.0f64, |a, b| a.max(b.abs()));
        // A soft side's violation costs ρ per unit: its tolerance is ρ
        // times tighter so that the cost is as accurate as the stages'.
        let rho = self
            .row_penalty
            .iter()
            .filter(|r| r.is_finite())
            .fold(1.0f64, |a, b| a.max(*b));
        let row = if self.row_penalty.iter().all(|r| r.is_infinite()) {
            ROW_TOLERANCE * b_scale
        } else {
            PRIMAL_TOLERANCE * b_scale / rho
        };
        Tolerances {
            c_scale,
            x_scale,
            // P·x has entries ~1e10 even by differencing: its rounding
            // floor, ε·max|P_ii|·|x| (1e-5 at δt = 0.02 s, r = 0.01),
            // bounds how small a freshly computed gradient can be made.
            // The gradient carried along full steps (P·x and u updated by
            // the step's) goes below it, and after a step on a reused
            // factor (a chord step, which converges linearly) a gradient
            // below it can still hide a decrement above tolerance in the
            // cost's flat directions: the floor ends the inner solve only
            // right after a full Newton step on a fresh factor, whose next
            // decrement is of its square.
            floor: 16.0 * f64::EPSILON * self.diag_max * x_scale,
            dual: DUAL_TOLERANCE * c_scale,
            decrement: DECREMENT_TOLERANCE * c_scale * x_scale,
            stage: PRIMAL_TOLERANCE * (1.0 + self.stage_scale()),
            row,
            gap: GAP_TOLERANCE * c_scale * x_scale,
            row_scale_max: self.row_scale.iter().fold(0.0f64, |a, b| a.max(*b)),
            max_steps: if cold {
                2 * self.tuning.max_newton_steps
            } else {
                self.tuning.max_newton_steps
            },
            give_up_blocked: false,
        }
    }

    /// One axis with rows: the active-set method alone (module docs; its
    /// cold start reads its working set off a condensed interior point).
    fn solve_rows(
        &mut self,
        a0: f64,
        (lo, hi): (&[f64], &[f64]),
        tol: &Tolerances,
    ) -> Result<usize, ControlError> {
        if self.polish(a0, (lo, hi), (tol.stage, tol.row))? {
            Ok(0)
        } else {
            Err(SolverFault::NotConverged {
                iterations: self.ws.newton_steps,
            }
            .into())
        }
    }

    /// Assembles and factors the generalised Hessian at x: in the window,
    /// its rows only, into the head's factor (whose rows before the window
    /// are P's: `window.rs`); else all of it.
    fn factor_newton_matrix(&mut self, lo: &[f64], hi: &[f64]) -> Result<(), ControlError> {
        if self.ws.window > 0 {
            let from = self.window_unknown();
            // Rows the last window changed before this one's are P's again.
            let start = from.min(self.head.p_until);
            self.assemble(lo, hi, start);
            if let Err(e) = self.head.factor.refactor_rows_from(&self.kkt, start) {
                self.head.valid = false;
                return Err(e);
            }
            self.head.p_until = from;
            self.factored = Factored::Window;
        } else {
            self.assemble(lo, hi, 0);
            self.chol.refactor_taking(&mut self.kkt)?;
            self.factored = Factored::Whole;
        }
        self.ws.factorisations += 1;
        self.ws.factored_active.clone_from(&self.ws.active);
        Ok(())
    }

    /// The inner solve: L(·; y, v, σ) minimised by semismooth Newton until
    /// the gradient or the Newton decrement −gᵀd is negligible (or, while
    /// the multipliers are far off, small against the next update's
    /// change). `first`: the window's first gradient, when it opened.
    fn inner_solve(
        &mut self,
        a0: [f64; 2],
        (lo, hi): (&[f64], &[f64]),
        tol: &Tolerances,
        memory: &mut NewtonMemory,
        mut first: Option<(f64, f64, f64)>,
    ) -> Result<InnerEnd, ControlError> {
        loop {
            let (gn, stage_res, row_res) = match first.take() {
                Some(done) => done,
                None => self.gradient(a0, lo, hi),
            };
            let end = |converged| InnerEnd {
                stage_res,
                row_res,
                converged,
            };
            if gn <= tol.dual || (gn <= tol.floor && memory.exact_full) {
                return Ok(end(true));
            }
            if self.ws.newton_steps == tol.max_steps {
                return Err(SolverFault::NotConverged {
                    iterations: tol.max_steps,
                }
                .into());
            }
            self.ws.newton_steps += 1;
            // Inexact inner solves while the multipliers are far off: the
            // subproblem's error (≈ decrement/2) need only be small against
            // the change the next update will make, σ·res².
            let row_sigma = tol.row_scale_max * self.sigma;
            let loose = self.sigma * (INEXACT * stage_res).powi(2)
                + row_sigma * (INEXACT * row_res).powi(2);
            let Some((decrement, reuse)) = self.newton_direction(lo, hi, tol, memory, loose)?
            else {
                continue;
            };
            if decrement <= tol.decrement.max(loose) {
                // Converged to rounding (or enough for this update): the
                // full step, and done.
                self.move_x(1.0);
                self.ws.px_current = false;
                let (_, stage_res, row_res) = self.gradient(a0, lo, hi);
                return Ok(InnerEnd {
                    stage_res,
                    row_res,
                    converged: decrement <= tol.decrement,
                });
            }
            let (full, alpha) = self.line_search(decrement, lo, hi)?;
            memory.last_full = full;
            if tol.give_up_blocked && alpha < BLOCKED_STEP {
                return Err(SolverFault::WarmStepBlocked { alpha }.into());
            }
            memory.exact_full = memory.last_full && !reuse;
            if memory.exact_full && decrement <= LOCAL_STOP * tol.c_scale * tol.x_scale {
                // A full step from a small decrement: the next one is of
                // its square (Newton's local rate), below tolerance.
                let (_, stage_res, row_res) = self.gradient(a0, lo, hi);
                return Ok(InnerEnd {
                    stage_res,
                    row_res,
                    converged: true,
                });
            }
        }
    }

    /// The Newton direction d at x (the factor reused or refactored) and
    /// its decrement −gᵀd, with whether the factor was reused; `None`
    /// when a reused factor gave no descent (the next step refactors).
    fn newton_direction(
        &mut self,
        lo: &[f64],
        hi: &[f64],
        tol: &Tolerances,
        memory: &mut NewtonMemory,
        loose: f64,
    ) -> Result<Option<(f64, bool)>, ControlError> {
        // Intervals: the matrix is fixed by σ and the active set, so with
        // the active set the one factored the factor is exact. Discs: in
        // the local phase (last step full, its decrement small, the active
        // set the one factored) the matrix changes only in the active
        // stages' curvature: its factor is reused.
        let exact_reuse = matches!(self.stages, StageSet::Interval(_));
        let same_set =
            self.factored != Factored::Stale && self.ws.active == self.ws.factored_active;
        let reuse_decrement = if self.rows.is_empty() {
            REUSE_DECREMENT_DISCS
        } else {
            REUSE_DECREMENT
        };
        let small = (reuse_decrement * tol.c_scale * tol.x_scale).max(LOOSE_REUSE * loose);
        let reuse = same_set
            && memory.reuse_allowed
            && (exact_reuse || memory.last_full && memory.last_decrement <= small);
        memory.reuse_allowed = true;
        if !reuse {
            self.factor_newton_matrix(lo, hi)?;
        }
        // −g on the window (the eliminated head's gradient is 0; the
        // solve sets d there).
        let j0 = self.window_unknown();
        for (d, g) in self.ws.d[j0..].iter_mut().zip(&self.ws.g[j0..]) {
            *d = -g;
        }
        let factor = match self.factored {
            Factored::Window => &self.head.factor,
            _ => &self.chol,
        };
        factor.solve_in_place_cut(&mut self.ws.d, j0, self.ws.cut)?;
        let decrement: f64 = -self.ws.g[j0..]
            .iter()
            .zip(&self.ws.d[j0..])
            .map(|(g, d)| g * d)
            .sum::<f64>();
        if (decrement.is_nan() || decrement <= 0.0) && reuse {
            // The old factor no longer gives a descent direction.
            memory.last_full = false;
            memory.reuse_allowed = false;
            return Ok(None);
        }
        if reuse && !exact_reuse && decrement > 0.1 * memory.compare_decrement {
            // The old factor converges slowly here: refactor next.
            memory.reuse_allowed = false;
        }
        memory.last_decrement = decrement;
        memory.compare_decrement = decrement;
        Ok(Some((decrement, reuse)))
    }

    /// After an inner solve: the stopping tests (module docs), the
    /// multiplier update, the window closed when it converged, and σ
    /// grown when the residual stalls (or, `climb`, on a cold solve until
    /// the warm σ).
    fn outer_update(
        &mut self,
        end: InnerEnd,
        (lo, hi): (&[f64], &[f64]),
        tol: &Tolerances,
        climb: bool,
        previous_res: f64,
    ) -> Result<Outer, ControlError> {
        let (stage_res, row_res) = (end.stage_res, end.row_res);
        // What the residuals can cost, needed only once they are small
        // (before the multipliers move).
        let residuals_small = stage_res <= tol.stage && row_res <= tol.row;
        // At the largest σ the residual can stall at rounding: a stage on
        // its boundary with a vanishing multiplier flipped in and out of
        // the set with every update (a 2-cycle at 17× the tolerance, 7e-7
        // m/s², `PROPTEST_RNG_SEED=15`), σ unable to grow. There a stage
        // residual within STALL_TOLERANCE× its tolerance ends the solve,
        // if what it can cost is as small (the rows, whose hard bounds are
        // checked to 1e-9, keep theirs).
        let stalled = self.sigma >= self.tuning.sigma_max
            && stage_res <= STALL_TOLERANCE * tol.stage
            && row_res <= tol.row;
        // An inexact inner solve's residuals are no proof: the step that
        // ended it was the model's with the active set it started from (a
        // warm start whose rows all let go at once stopped there 0.6 %
        // above the optimum's cost).
        let mut gap_ratio = 0.0;
        let gap_small = end.converged && (residuals_small || stalled) && {
            let cost = self.residual_cost(lo, hi);
            gap_ratio = cost / tol.gap;
            cost <= tol.gap
        };
        self.update_multipliers(lo, hi);
        if gap_small && self.ws.window > 0 {
            // The window converged: on to the whole horizon, whose first
            // gradient finds whether a stage or row of the head binds
            // after all (then the solve goes on there).
            self.close_window();
            return Ok(Outer::Continue(previous_res));
        }
        if gap_small {
            if self.ws.x.iter().any(|v| !v.is_finite()) {
                return Err(SolverFault::NonFinite.into());
            }
            return Ok(Outer::Done(self.ws.newton_steps));
        }
        let mut res = (stage_res / tol.stage).max(row_res / tol.row);
        if !self.rows.is_empty() && matches!(self.stages, StageSet::Disc(_)) {
            // Discs with rows (the cone with the tilt rate): residuals
            // within their tolerances whose cost is not (a chain of rate
            // rows with large multipliers, its residual falling a few
            // percent per update) count as a residual too, so that σ
            // grows there (corner bench, N = 200: p99 1370 → 1108 µs,
            // Newton steps per solve at most 35 → 22).
            res = res.max(gap_ratio);
        }
        // σ grows tenfold when the residual stalls, and on a cold solve
        // after every update until it reaches the warm σ: the soft first
        // subproblem found the active set, and at σ = 1e2 an update gains
        // only ~3× (corner bench, N = 200, warm starts off: 8.53 → 7.81 G
        // instructions, interior-point fallbacks 10 → 0 of 1905).
        let climbing = climb && self.sigma < self.tuning.sigma;
        if res > 1.0 && (climbing || res > 0.1 * previous_res) && self.sigma < self.tuning.sigma_max
        {
            self.sigma = (self.sigma * SIGMA_GROWTH).min(self.tuning.sigma_max);
            self.factored = Factored::Stale;
        }
        Ok(Outer::Continue(res))
    }

    /// The multiplier update (the gradient just computed is the
    /// Lagrangian's with the updated multipliers: stationarity holds).
    fn update_multipliers(&mut self, lo: &[f64], hi: &[f64]) {
        self.warm.y.copy_from_slice(&self.ws.y_next);
        for r in 0..self.rows.len() {
            let h = self.ws.hx[r];
            for j in 0..2 {
                let t = Self::side(j, h, lo[r], hi[r]);
                self.warm.v[r][j] = self.side_multiplier(r, self.warm.v[r][j], t);
            }
        }
    }
}
