//! [`BoxAlmSolver`]: one axis with its box bounds ([`AxisBounds`]: the
//! acceleration interval per stage, speed rows, tilt-rate rows), solved by
//! the augmented Lagrangian of [`super::alm`] that also serves the tilt
//! cone — the interval per stage in place of the disc, hard rows with
//! their multipliers clamped at 0 — warm-started across ticks.

use super::alm::{AlmTuning, BandedAlm, RowBlock, StageSet};
use super::bounds::AxisBounds;
use super::bounds::Row;
use super::cascade::{AxisSolver, Carry, SolveFailure, SolveInfo, SolverFault, SolverMethod};
use super::problem::{AxisProblem, shifted_plan};
use super::smoothness::Smoothness;
use crate::ControlError;

/// One axis's box-bounded plan by the augmented Lagrangian
/// ([`BandedAlm`], one axis, O(N) per Newton step). Its start is the
/// previous tick's plan one step on with the multipliers shifted, when the
/// previous tick solved with it and warm starts are on; else the plan
/// given (the fast path's) with the multipliers the last constrained
/// burst left ([`BoxAlmSolver::skip`] ages them a stage per tick).
#[derive(Debug, Clone)]
pub struct BoxAlmSolver {
    horizon: usize,
    dt: f64,
    bounds: AxisBounds,
    alm: BandedAlm,
    /// Linear term, baseline, right-hand side, row bounds, start.
    c: Vec<f64>,
    base: Vec<f64>,
    rhs: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    p: Vec<f64>,
    /// The last solution's plan `y*_0..y*_N` \[m\], and whether it is the
    /// previous tick's.
    previous: Vec<f64>,
    previous_valid: bool,
    warm_start: bool,
    warm_used: bool,
    /// Whether `base`, `lo` and `hi` hold this tick's data (set by a
    /// solve, read by the `accept_plan` right after it).
    tick_data: bool,
}

/// The box's initial σ on warm solves. Its stage sets are intervals, on
/// which the semismooth Newton step is exact while the active set holds,
/// so a stiffer penalty costs no extra steps there and each multiplier
/// update gains tenfold more: on the corner bench at N = 200, 7.28 → 6.57
/// Newton steps per solve against the cone's 1e4 (1e6: the same steps,
/// and the first tick fell to the interior point).
const BOX_SIGMA: f64 = 1e5;

/// The Newton-step budget of a warm solve with tilt-rate rows. Their
/// solves end in the active-set polish (`alm/polish.rs`) after a few
/// steps, or not at all: on the corner bench at N = 200 a budget of 20
/// instead of 40 left the median where it was and cut what a tick that
/// falls to the interior point spends first.
const TILT_RATE_NEWTON_STEPS: usize = 20;

impl BoxAlmSolver {
    /// Builds the solver for horizon N ≥ 3, weights `(q, r, δt)` as
    /// [`FastBandedSolver::with_smoothness`](crate::optimise::FastBandedSolver::with_smoothness), the bounds and the
    /// smoothness term, and whether to warm-start.
    pub fn new(
        horizon: usize,
        weights: (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
        warm_start: bool,
    ) -> Result<Self, ControlError> {
        let tuning = AlmTuning {
            sigma: BOX_SIGMA,
            max_newton_steps: if bounds.tilt_rate.is_some() {
                TILT_RATE_NEWTON_STEPS
            } else {
                super::alm::MAX_NEWTON_STEPS
            },
            ..AlmTuning::default()
        };
        Self::with_tuning(horizon, weights, bounds, smoothness, warm_start, tuning)
    }

    /// As [`BoxAlmSolver::new`] with the augmented Lagrangian's tuning.
    pub fn with_tuning(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
        warm_start: bool,
        tuning: AlmTuning,
    ) -> Result<Self, ControlError> {
        let fast = bounds.fast_solver(horizon, (q, r, dt), smoothness)?;
        let n = horizon - 2;
        let inv_dt2 = 1.0 / (dt * dt);
        let mut blocks = Vec::new();
        if bounds.speed.is_some() {
            blocks.push(RowBlock {
                rows: (0..n).map(|g| Row::speed(g, dt, |k| k)).collect(),
                scale: inv_dt2,
                penalty: f64::INFINITY,
            });
        }
        if let Some(rate) = &bounds.tilt_rate {
            // The rows weigh three accelerations by (κ, 1 − 2κ, κ − 1): their
            // σ is scaled by the squared norm's inverse, so that an active
            // row stiffens the Newton matrix as much as an active stage.
            let k = rate.kappa;
            let norm2 = k * k + (1.0 - 2.0 * k).powi(2) + (k - 1.0).powi(2);
            blocks.push(RowBlock {
                rows: (0..n)
                    .map(|f| Row::tilt_rate(f, k, |s| s).on_outputs(inv_dt2, |k| k))
                    .collect(),
                scale: 1.0 / norm2.max(1.0),
                penalty: f64::INFINITY,
            });
        }
        let m = blocks.iter().map(|b| b.rows.len()).sum();
        let stages = StageSet::Interval(vec![[[f64::NEG_INFINITY, f64::INFINITY]; 2]; n]);
        let alm = BandedAlm::new(vec![fast], dt, stages, blocks, tuning);
        Ok(Self {
            horizon,
            dt,
            bounds,
            alm,
            c: vec![0.0; n],
            base: vec![0.0; n],
            rhs: vec![0.0; n],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            p: vec![0.0; n],
            previous: vec![0.0; horizon + 1],
            previous_valid: false,
            warm_start,
            warm_used: false,
            tick_data: false,
        })
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &AxisBounds {
        &self.bounds
    }

    /// What the active-set method did in the last solve (with rows).
    pub fn active_set_work(&self) -> super::active_set::Work {
        self.alm.active_set_work()
    }

    /// Newton steps of the last solve (with rows: the active-set
    /// method's KKT solves).
    pub fn iterations(&self) -> usize {
        self.alm.newton_steps() + self.alm.active_set_work().solves
    }

    /// Factorisations of the last solve.
    pub fn factorisations(&self) -> usize {
        self.alm.factorisations()
    }

    /// Whether the last solve started from the previous tick's solution.
    pub fn warm_started(&self) -> bool {
        self.warm_used
    }

    /// A tick that did not use this solver: the next solve starts from the
    /// plan it is given, with the multipliers aged a stage.
    pub fn skip(&mut self) {
        self.tick_data = false;
        self.previous_valid = false;
        self.alm.age();
    }

    /// Takes `plan` (`y*_0..y*_N` \[m\], another solver's solution of this
    /// tick) as the previous solution, and `duals` (its rows' multipliers
    /// `[upper, lower]` in `AxisBounds::row_bounds`' order, when it has
    /// them: the interior point's) as the multipliers: the next tick starts
    /// from them, so that one fallback does not make the next.
    pub fn accept_plan(&mut self, plan: &[f64], duals: &[[f64; 2]]) {
        if plan.len() != self.previous.len() || plan.iter().any(|v| !v.is_finite()) {
            return;
        }
        self.previous.copy_from_slice(plan);
        self.previous_valid = true;
        let n = self.horizon - 2;
        let accel_rows = if self.bounds.acceleration.is_some() {
            n
        } else {
            0
        };
        if duals.len() == accel_rows + self.lo.len()
            && duals.iter().flatten().all(|z| z.is_finite())
        {
            let (stages, rows) = duals.split_at(accel_rows);
            self.alm.set_multipliers(
                |f| stages.get(f).map_or([0.0; 2], |z| [z[0] - z[1], 0.0]),
                rows,
            );
            if self.tick_data {
                // This tick's deviations p = plan − baseline (`base`,
                // `lo`, `hi` are this tick's: this solver's attempt set
                // them before the cascade went on).
                for f in 0..n {
                    self.p[f] = plan[f + 3] - self.base[f];
                }
                let a0 = (plan[2] - 2.0 * plan[1] + plan[0]) / (self.dt * self.dt);
                self.alm
                    .keep_active_multipliers(&self.p, a0, &self.lo, &self.hi);
            }
        }
        self.tick_data = false;
    }

    /// The next solve starts from the plan it is given, keeping the
    /// multipliers as they are (tests: a solve from another method's
    /// solution and multipliers).
    #[cfg(test)]
    pub(crate) fn start_from_given(&mut self) {
        self.previous_valid = false;
    }

    /// Forgets everything carried between ticks (a controller reset).
    pub fn reset(&mut self) {
        self.previous_valid = false;
        self.alm.reset_multipliers();
    }

    /// Solves with the bounds; arguments as [`FastBandedSolver::solve_problem`](crate::optimise::FastBandedSolver::solve_problem),
    /// `plan` holding the start on entry (the fast path's plan). On an
    /// error `plan` is unchanged. Errors: wrong lengths, infeasible data,
    /// and [`ControlError::Solver`] when the method does not converge.
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let (fixed, sent, reference, plan) = a.checked(self.horizon)?;
        let (dt, n, horizon) = (self.dt, self.horizon - 2, self.horizon);
        self.alm
            .axis(0)
            .right_hand_side(fixed, sent, reference, &mut self.base, &mut self.rhs);
        for f in 0..n {
            self.c[f] = -2.0 * self.rhs[f];
        }
        let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        // The rows in `row_bounds`' order: the acceleration rows (the
        // stage intervals here, absolute), then speed and tilt rate.
        let accel_rows = if self.bounds.acceleration.is_some() {
            n
        } else {
            0
        };
        let intervals = self
            .alm
            .interval_mut()
            .expect("the box's stage set is an interval");
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut i = 0;
        self.bounds.row_bounds(horizon, fixed, sent, dt, |l, h| {
            if i < accel_rows {
                intervals[i][0] = [l + a0, h + a0];
            } else {
                lo[i - accel_rows] = l;
                hi[i - accel_rows] = h;
            }
            i += 1;
        });
        self.tick_data = true;
        let warm = self.warm_start && self.previous_valid;
        self.warm_used = warm;
        self.previous_valid = false;
        for f in 0..n {
            let b = self.base[f];
            self.p[f] = if warm {
                shifted_plan(&self.previous, f, self.bounds.tilt_rate.is_some()) - b
            } else {
                plan[f + 3] - b
            };
        }
        if warm {
            self.alm.shift();
        } else if !self.warm_start {
            // Cold, as configured: no multipliers carried over.
            self.alm.reset_multipliers();
        }
        self.alm.set_start(&[&self.p]);
        if let Err(e) = self.alm.solve(&self.c, [a0, 0.0], &self.lo, &self.hi) {
            // The multipliers of a failed solve are no start for the next.
            self.alm.reset_multipliers();
            return Err(e);
        }
        for f in 0..n {
            let v = self.base[f] + self.alm.p(0, f);
            if !v.is_finite() {
                self.alm.reset_multipliers();
                return Err(SolverFault::NonFinite.into());
            }
            self.p[f] = v;
        }
        plan[..3].copy_from_slice(fixed);
        plan[3..].copy_from_slice(&self.p);
        self.previous.copy_from_slice(plan);
        self.previous_valid = true;
        Ok(())
    }
}

impl AxisSolver for BoxAlmSolver {
    fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.bounds.offset = offset;
        self.bounds.offset_slope = slope;
    }

    fn solve(&mut self, axis: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        let method = if self.alm.has_active_set() {
            SolverMethod::ActiveSet
        } else {
            SolverMethod::Alm
        };
        self.solve_problem(axis)
            .map_err(|e| SolveFailure::from_error(method, self.iterations(), e))?;
        Ok(SolveInfo {
            method,
            iterations: self.iterations(),
            factorisations: self.factorisations(),
            warm_started: self.warm_used,
            relaxed: false,
            restart: None,
        })
    }

    fn carry(&mut self, event: Carry<'_>) {
        match event {
            Carry::Accepted {
                plans: [plan],
                duals,
            } => self.accept_plan(plan, duals),
            Carry::Accepted { .. } => {}
            Carry::Skipped => self.skip(),
            Carry::Reset => self.reset(),
        }
    }

    /// None: the cascade's first solver, no solver before it to tell
    /// (its multipliers stay with its own warm start).
    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }
}
