//! [`BandedConeSolver`]: both horizontal axes with the tilt cone
//! ([`super::cone`]), solved by the augmented Lagrangian of
//! [`super::alm`] (warm-started across ticks), with the banded
//! interior point of [`super::cone_qp`] as its fallback. With the
//! tilt-rate rows, a warm tick first solves the pair without them and
//! keeps that optimum where it keeps every row (`relaxation.rs`).

use super::alm::{AlmTuning, BandedAlm, RowBlock, StageSet};
use super::banded_ip::AxisCost;
use super::bounds::Row;
use super::cascade::{Carry, PairSolver, SolveFailure, SolveInfo, SolverFault, SolverMethod};
use super::cone::ConeBounds;
use super::cone_qp::{ConeQp, STAGE, a_at, p_at};
use super::fast_banded::FastBandedSolver;
use super::problem::{AxisProblem, baseline, shifted_plan};
use super::smoothness::Smoothness;
use super::smoothness::{accel_block, sent_linear_term};
use crate::ControlError;

mod interior;
mod relaxation;

/// Newton steps a warm start of the pair with tilt-rate rows is given
/// before it goes on from the condensed interior point's start: on the
/// corner bench at N = 200, 97 % of the warm solves that end by
/// themselves end within 14.
pub const WARM_STEPS_BEFORE_START: usize = 12;
/// Newton steps the first inner solve of that warm start (its multipliers
/// as shifted) gets before the interior point's restart: a tick whose
/// first inner solve has not ended by then is a chain of rate rows that
/// moved, which the warm start walks a row or two per Newton step. On the
/// corner bench (constrained p99 µs, one run per value; no limit: 235,
/// 553, 1503, 2514 at N = 50, 100, 200, 400): 5 gave 205, 452, 1370,
/// 1946; 6 203, 438, 1376, 2085; 8 202, 486, 1375, 2329; 10 219, 520,
/// 1551, 2295; 4 took the median at N = 50 and 100 from 44 and 86 to 100
/// and 202 µs (docs/performance-log.md, "The warm start's first inner
/// solve").
pub const WARM_FIRST_INNER_STEPS: usize = 6;
/// Share of the horizon before which a cold solve's start (the plan given)
/// breaks no disc or row for the cone with the tilt rate to try the
/// augmented Lagrangian first, with the warm start's budget and then the
/// interior point's restart, instead of the interior point's cold start
/// (the eliminated head's share, `alm/mod.rs`). On the course of corners
/// at N = 200 a burst's first tick went from ~650 to ~105 µs at the
/// median (docs/performance-log.md, "A burst's first tick of the cone with
/// the tilt rate").
pub const LATE_ARC_SHARE: f64 = 0.25;

/// Weights of one axis: tracking q ≥ 0 [1/m²], jerk r > 0 [s⁶/m²], and
/// the smoothness term.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisWeights {
    /// Tracking weight q [1/m²].
    pub q: f64,
    /// Jerk weight r [s⁶/m²].
    pub r: f64,
    /// Command-smoothness term (weight 0: none).
    pub smoothness: Smoothness,
}

/// The two horizontal axes with the tilt cone and soft speed bounds
/// ([`ConeBounds`]): the augmented Lagrangian ([`BandedAlm`], O(N) per
/// Newton step), warm-started from the previous tick's solution and
/// multipliers shifted by one step when the previous tick used it too;
/// should it not converge, the stage-ordered banded interior point
/// ([`ConeQp`]) from the cold start.
///
/// [`DfMpc`](crate::dfmpc::DfMpc) uses it first and falls back to
/// [`ClarabelConeSolver`](super::ClarabelConeSolver) (the same problem as
/// an SOCP) when it does not converge.
#[derive(Debug, Clone)]
pub struct BandedConeSolver {
    horizon: usize,
    dt: f64,
    weights: [AxisWeights; 2],
    bounds: ConeBounds,
    /// The interior point and the augmented Lagrangian, those this
    /// solver runs ([`BandedConeSolver::with_methods`]).
    qp: Option<ConeQp>,
    alm: Option<BandedAlm>,
    /// With tilt-rate rows, the augmented Lagrangian of the pair without
    /// them (`relaxation.rs`), its plan and the rows' multipliers it
    /// hands over, the speed rows' count (the first of `lo`, `hi`),
    /// whether it is on, whether the last solution bound a tilt-rate row,
    /// and the last solve's relaxation: its Newton steps and
    /// factorisations (0 when it did not run), whether it held.
    relaxed: Option<BandedAlm>,
    relaxed_plan: [Vec<f64>; 2],
    relaxed_rows: Vec<[f64; 2]>,
    speed_rows: usize,
    relaxation_on: bool,
    rows_bound: bool,
    relaxation_steps: usize,
    relaxation_factorisations: usize,
    relaxation_held: bool,
    /// ALM linear term (2n, interleaved) and scratch.
    c_alm: Vec<f64>,
    /// The interior point's disc and row multipliers after it solved: the
    /// augmented Lagrangian's warm start for the next tick.
    ip_stage_duals: Vec<[f64; 2]>,
    ip_row_duals: Vec<[f64; 2]>,
    base: Vec<f64>,
    rhs: Vec<f64>,
    c: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// The axes' fast paths (their right-hand sides), and the radius per
    /// stage A_f [m/s²]: the cone's, and the one enforced this tick (with
    /// a tilt-rate bound the funnel, [`ConeBounds`]).
    fast: [FastBandedSolver; 2],
    radius: Vec<f64>,
    stage_radius: Vec<f64>,
    /// The discs' centre per stage o_f [m/s²] (zeros unless set,
    /// [`BandedConeSolver::set_centre`]).
    centre: Vec<[f64; 2]>,
    /// This tick's window (fixed outputs per axis \[m\]) and the
    /// accelerations the command sent at k−1 asks for [m/s²].
    window: [[f64; 3]; 2],
    sent: [Option<f64>; 2],
    /// Start deviations per axis (cold), then the warm guess.
    p: [Vec<f64>; 2],
    warm: [Vec<f64>; 2],
    /// The last solution's plans `y*_0..y*_N` per axis \[m\].
    previous: [Vec<f64>; 2],
    /// Warm starts enabled, and whether `previous` is last tick's.
    warm_start: bool,
    previous_valid: bool,
    iterations: usize,
    /// The condensed interior point's iterations in the last solve.
    interior_iterations: usize,
    /// Whether the last solve's interior point was restarted from where
    /// its warm attempt stopped ([`BandedConeSolver::interior_restart`]).
    restarted: bool,
    /// The Newton steps of the last solve's warm attempt, when the
    /// interior point's restart followed it.
    attempt_steps: usize,
    /// The Newton steps of the augmented Lagrangian after the interior
    /// point's start or restart (0 when none ran).
    steps_after: usize,
    /// Newton steps a warm solve with tilt-rate rows gets before the
    /// interior point ([`WARM_STEPS_BEFORE_START`]; tests lower it).
    warm_steps_before_start: usize,
    warm_used: bool,
    /// Which method gave the last solution.
    method: ConeMethod,
}

/// Which method of [`BandedConeSolver`] solved a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConeMethod {
    /// The augmented Lagrangian ([`BandedAlm`]).
    Alm,
    /// The stage interior point ([`ConeQp`]), after the ALM failed.
    InteriorPoint,
}

impl BandedConeSolver {
    /// Builds the solver for horizon N ≥ 3, step δt > 0 \[s\], per-axis
    /// weights (x, y), the bounds, and whether to warm-start: the
    /// augmented Lagrangian with the interior point as its fallback.
    pub fn new(
        horizon: usize,
        dt: f64,
        weights: [AxisWeights; 2],
        bounds: ConeBounds,
        warm_start: bool,
    ) -> Result<Self, ControlError> {
        Self::with_methods(horizon, dt, weights, bounds, warm_start, [true, true])
    }

    /// As [`BandedConeSolver::new`], running only the methods chosen:
    /// `[augmented Lagrangian, interior point]` (at least one) — one entry
    /// each of the constrained plan's cascade ([`super::cascade`]).
    pub fn with_methods(
        horizon: usize,
        dt: f64,
        weights: [AxisWeights; 2],
        bounds: ConeBounds,
        warm_start: bool,
        [use_alm, use_ip]: [bool; 2],
    ) -> Result<Self, ControlError> {
        for w in &weights {
            FastBandedSolver::check_args(horizon, w.q, w.r, dt)?;
            w.smoothness.check()?;
        }
        bounds.check()?;
        if !(use_alm || use_ip) {
            return Err(super::problem::invalid(
                "cone solver",
                "at least one method",
            ));
        }
        let n = horizon - 2;
        let axes = weights.map(|w| AxisCost {
            q: w.q,
            accel: accel_block(n, w.r, dt, &w.smoothness),
        });
        let penalty = bounds.speed.map(|_| bounds.speed_penalty);
        let kappa = bounds.tilt_rate.map(|r| r.map(|r| r.kappa));
        let qp = ConeQp::new(
            n,
            dt,
            [&axes[0], &axes[1]],
            bounds.acceleration,
            penalty,
            kappa,
        );
        let fast = |w: &AxisWeights| {
            FastBandedSolver::with_smoothness(horizon, w.q, w.r, dt, w.smoothness)
        };
        let fast = [fast(&weights[0])?, fast(&weights[1])?];
        let (speed_blocks, rate_blocks) = row_blocks(n, dt, penalty, kappa);
        let speed_rows = speed_blocks.iter().map(|b| b.rows.len()).sum();
        let alm_of = |blocks: Vec<RowBlock>| {
            BandedAlm::new(
                fast.to_vec(),
                dt,
                StageSet::Disc(vec![bounds.acceleration; n]),
                blocks,
                AlmTuning::default(),
            )
        };
        // The relaxation's rows: the speed rows alone.
        let relaxed = (use_alm && kappa.is_some()).then(|| alm_of(speed_blocks.clone()));
        let alm = use_alm.then(|| alm_of([speed_blocks, rate_blocks].concat()));
        let m = bounds.rows(n);
        debug_assert_eq!(m, qp.ip.rows());
        Ok(Self {
            horizon,
            dt,
            weights,
            bounds,
            qp: use_ip.then_some(qp),
            alm,
            relaxed,
            relaxed_plan: [vec![0.0; n], vec![0.0; n]],
            relaxed_rows: vec![[0.0; 2]; m],
            speed_rows,
            relaxation_on: true,
            rows_bound: true,
            relaxation_steps: 0,
            relaxation_factorisations: 0,
            relaxation_held: false,
            fast,
            radius: vec![bounds.acceleration; n],
            stage_radius: vec![bounds.acceleration; n],
            window: [[0.0; 3]; 2],
            sent: [None; 2],
            c_alm: vec![0.0; 2 * n],
            centre: vec![[0.0; 2]; n],
            ip_stage_duals: vec![[0.0; 2]; n],
            ip_row_duals: vec![[0.0; 2]; m],
            base: vec![0.0; n],
            rhs: vec![0.0; n],
            c: vec![0.0; STAGE * n],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            p: [vec![0.0; n], vec![0.0; n]],
            warm: [vec![0.0; n], vec![0.0; n]],
            previous: [vec![0.0; horizon + 1], vec![0.0; horizon + 1]],
            warm_start,
            previous_valid: false,
            iterations: 0,
            interior_iterations: 0,
            attempt_steps: 0,
            steps_after: 0,
            restarted: false,
            warm_steps_before_start: WARM_STEPS_BEFORE_START,
            warm_used: false,
            method: if use_alm {
                ConeMethod::Alm
            } else {
                ConeMethod::InteriorPoint
            },
        })
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &ConeBounds {
        &self.bounds
    }

    /// Horizon N \[steps\].
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Iterations of the last solve: the augmented Lagrangian's Newton
    /// steps, plus the interior point's iterations when it followed.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// Factorisations of the augmented Lagrangian's last solve (at most
    /// one per Newton step: the local phase reuses the factor; 0 without
    /// it).
    pub fn factorisations(&self) -> usize {
        let alm = if self.relaxation_held {
            0
        } else {
            self.alm.as_ref().map_or(0, BandedAlm::factorisations)
        };
        alm + self.relaxation_factorisations
    }

    /// The first stage of the window the augmented Lagrangian's last solve
    /// iterated on with the horizon's head eliminated (0: none).
    pub fn eliminated_head(&self) -> usize {
        self.alm.as_ref().map_or(0, BandedAlm::last_window)
    }

    /// Turns the augmented Lagrangian's head elimination on or off (tests).
    #[cfg(test)]
    pub(crate) fn set_eliminate_head(&mut self, on: bool) {
        if let Some(alm) = &mut self.alm {
            alm.set_eliminate_head(on);
        }
    }

    /// Whether the augmented Lagrangian's last solve started from the
    /// saturated rollout ([`BandedAlm::rollout_started`]).
    pub fn rollout_started(&self) -> bool {
        self.alm.as_ref().is_some_and(BandedAlm::rollout_started)
    }

    /// Turns the augmented Lagrangian's rollout start on or off (tests).
    #[cfg(test)]
    pub(crate) fn set_rollout_start(&mut self, on: bool) {
        if let Some(alm) = &mut self.alm {
            alm.set_rollout_start(on);
        }
    }

    /// Sets the cone's radius per stage A_f [m/s²] (N − 2 entries, finite
    /// and > 0; stage f bounds the acceleration of output f + 2) for the
    /// next solves, instead of the bounds' constant A: the spatial
    /// model's tilt cone `‖a_h‖ ≤ tan(tilt)·(g ∓ a_z)` with the planned
    /// vertical acceleration.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.horizon - 2)?;
        for alm in self.alm.iter_mut().chain(&mut self.relaxed) {
            alm.set_radius(radius)?;
        }
        if let Some(qp) = &mut self.qp {
            qp.ip.set_radius(radius)?;
        }
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// Sets the discs' centre per stage o_f [m/s²] (N − 2 entries,
    /// finite; stage f as [`BandedConeSolver::set_radius`]) for the next
    /// solves: the cone then bounds `‖a_f − o_f‖ ≤ A_f`, the thrust's
    /// acceleration where the model adds o_f to it (the drag `−D·v`, a
    /// learned residual). Zeros unless set. An error (nothing changed)
    /// for a wrong length or a value that is not finite.
    pub fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        super::cone::check_centre(centre, self.horizon - 2)?;
        for alm in self.alm.iter_mut().chain(&mut self.relaxed) {
            alm.set_centre(centre)?;
        }
        if let Some(qp) = &mut self.qp {
            qp.ip.set_centre(centre)?;
        }
        self.centre.copy_from_slice(centre);
        Ok(())
    }

    /// Which method gave the last solution.
    pub fn method(&self) -> ConeMethod {
        self.method
    }

    /// Whether the last successful solve was warm-started.
    pub fn warm_started(&self) -> bool {
        self.warm_used
    }

    /// Forgets the previous solution: the next solve starts from the plan
    /// it is given. Call it when a tick did not use this solver (its plan
    /// is then not the one the next tick continues): the multipliers are
    /// aged a stage, so that the next constrained burst starts from what
    /// this one left ([`BandedAlm::age`]).
    pub fn forget(&mut self) {
        self.previous_valid = false;
        for alm in self.alm.iter_mut().chain(&mut self.relaxed) {
            alm.age();
        }
    }

    /// Takes `plans` (x, y: `y*_0..y*_N` \[m\], another solver's solution
    /// of this tick) as the previous solution: the next tick starts from
    /// it.
    pub fn accept_plans(&mut self, plans: [&[f64]; 2]) {
        let ok = |p: &[f64]| p.len() == self.horizon + 1 && p.iter().all(|v| v.is_finite());
        if plans.iter().all(|p| ok(p)) {
            for (prev, p) in self.previous.iter_mut().zip(plans) {
                prev.copy_from_slice(p);
            }
            self.previous_valid = true;
        }
    }

    /// The augmented Lagrangian, if this solver runs it (tests).
    #[cfg(test)]
    pub(super) fn alm_mut(&mut self) -> Option<&mut BandedAlm> {
        self.alm.as_mut()
    }

    /// Forgets everything carried between ticks (a controller reset).
    pub fn reset(&mut self) {
        self.previous_valid = false;
        self.rows_bound = true;
        for alm in self.alm.iter_mut().chain(&mut self.relaxed) {
            alm.reset_multipliers();
        }
    }

    /// Solves both axes with the cone. `x.plan` and `y.plan` hold the
    /// cold start on entry (any plan, e.g. the unconstrained optimum of
    /// the fast path) and the solution on exit (unchanged on an error);
    /// `fixed`, `sent`, `reference` as [`FastBandedSolver::solve_problem`].
    /// With warm starts on and a solution from the previous tick, that
    /// solution shifted by one step is the augmented Lagrangian's start
    /// instead; should it fail, the interior point starts from the plan
    /// given. Errors: wrong lengths, and [`ControlError::Solver`] when
    /// neither converges.
    pub fn solve_pair(
        &mut self,
        x: AxisProblem<'_>,
        y: AxisProblem<'_>,
    ) -> Result<(), ControlError> {
        super::problem::check_pair(self.horizon, &x, &y)?;
        let a0 = self.load(&x, &y)?;
        self.iterations = 0;
        self.interior_iterations = 0;
        self.restarted = false;
        self.attempt_steps = 0;
        self.steps_after = 0;
        let warm = self.warm_start && self.previous_valid;
        self.warm_used = false;
        self.previous_valid = false;
        // First the augmented Lagrangian (warm: last tick's plan and
        // multipliers one step on; else the plan given and the multipliers
        // the last burst left), then the interior point from the plan given
        // should it fail.
        let method = if self.try_alm(warm, a0) {
            self.warm_used = warm;
            ConeMethod::Alm
        } else {
            self.try_interior_point(a0)?;
            ConeMethod::InteriorPoint
        };
        self.method = method;
        self.store_solution(method, [x.fixed, y.fixed])?;
        x.plan.copy_from_slice(&self.previous[0]);
        y.plan.copy_from_slice(&self.previous[1]);
        self.previous_valid = true;
        Ok(())
    }

    /// The tick's data: both methods' linear terms, the plans given and
    /// the warm guesses as deviations from the baseline, the rows' bounds
    /// and, with a tilt-rate bound, the funnel's radius on both methods.
    /// Returns the axes' window accelerations a_0 [m/s²].
    fn load(&mut self, x: &AxisProblem<'_>, y: &AxisProblem<'_>) -> Result<[f64; 2], ControlError> {
        let (dt, n) = (self.dt, self.horizon - 2);
        self.c.fill(0.0);
        let mut a0 = [0.0; 2];
        let rate_rows = self.bounds.tilt_rate.is_some();
        for (i, a) in [x, y].into_iter().enumerate() {
            let q = self.weights[i].q;
            self.fast[i].right_hand_side(
                a.fixed,
                a.sent,
                a.reference,
                &mut self.base,
                &mut self.rhs,
            );
            for f in 0..n {
                let b = self.base[f];
                self.c[p_at(i, f)] = 2.0 * q * (b - a.reference[f + 3]);
                self.p[i][f] = a.plan[f + 3] - b;
                // The warm guess: the previous plan one step on.
                self.warm[i][f] = shifted_plan(&self.previous[i], f, rate_rows) - b;
                // ½xᵀ(2H)x − 2·rhsᵀx: the fast path's objective, doubled
                // (p_{i, f} at 2f + i).
                self.c_alm[2 * f + i] = -2.0 * self.rhs[f];
            }
            self.c[a_at(i, 0)] = sent_linear_term(&self.weights[i].smoothness, a.fixed, a.sent, dt);
            a0[i] = (a.fixed[2] - 2.0 * a.fixed[1] + a.fixed[0]) / (dt * dt);
        }
        self.window = [*x.fixed, *y.fixed];
        self.sent = [x.sent, y.sent];
        let (fixed, sent) = ([x.fixed, y.fixed], self.sent);
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut k = 0;
        self.bounds.row_bounds(
            self.horizon,
            fixed,
            sent,
            &self.radius,
            &self.centre,
            dt,
            |l, h| {
                lo[k] = l;
                hi[k] = h;
                k += 1;
            },
        );
        if self.bounds.tilt_rate.is_some() {
            self.bounds.funnel_radius(
                (&self.radius, &self.centre),
                fixed,
                sent,
                dt,
                &mut self.stage_radius,
            );
            for alm in self.alm.iter_mut().chain(&mut self.relaxed) {
                alm.set_radius(&self.stage_radius)?;
            }
            if let Some(qp) = &mut self.qp {
                qp.ip.set_radius(&self.stage_radius)?;
            }
        }
        Ok(a0)
    }

    /// The augmented Lagrangian's attempt (none configured: false). With
    /// the tilt-rate rows a cold solve starts from the condensed interior
    /// point's solution and multipliers (`alm/interior_start.rs`) unless
    /// its start breaks nothing before [`LATE_ARC_SHARE`] of the horizon;
    /// a warm one (or that cold one) that has not ended within
    /// [`WARM_STEPS_BEFORE_START`] Newton steps, or whose first inner
    /// solve has not within [`WARM_FIRST_INNER_STEPS`], goes on from the
    /// interior point (a chain of rate rows that moved takes the warm
    /// multipliers 40 and more): restarted from where it stopped, else
    /// started cold. A warm tick whose last solution bound no tilt-rate
    /// row first tries the pair without them (`relaxation.rs`).
    fn try_alm(&mut self, warm: bool, a0: [f64; 2]) -> bool {
        self.relaxation_steps = 0;
        self.relaxation_factorisations = 0;
        self.relaxation_held = false;
        if warm && self.relaxation_on && !self.rows_bound && self.relaxed.is_some() {
            if self.try_relaxation(a0) {
                self.relaxation_held = true;
                self.iterations = self.relaxation_steps;
                self.attempt_steps = 0;
                return true;
            }
        } else if warm && let Some(relaxed) = &mut self.relaxed {
            // Not run this tick: its multipliers a stage on, as time is.
            relaxed.age();
        }
        let Some(alm) = &mut self.alm else {
            return false;
        };
        let rate_rows = self.bounds.tilt_rate.is_some();
        if warm {
            alm.shift();
            alm.set_start(&[&self.warm[0], &self.warm[1]]);
        } else {
            if !self.warm_start {
                // Cold, as configured: no multipliers carried over.
                alm.reset_multipliers();
            }
            alm.set_start(&[&self.p[0], &self.p[1]]);
        }
        let mut started = false;
        if rate_rows && !warm && !self.breaks_late(a0) {
            started = self.interior_start(a0);
        }
        let Some(alm) = &mut self.alm else {
            return false;
        };
        let budget = alm.max_newton_steps();
        let short = rate_rows && !started;
        if short {
            alm.set_max_newton_steps(self.warm_steps_before_start.min(budget));
            alm.set_first_inner_steps(WARM_FIRST_INNER_STEPS);
        }
        let mut result = alm.solve(&self.c_alm, a0, &self.lo, &self.hi);
        alm.set_max_newton_steps(budget);
        alm.set_first_inner_steps(usize::MAX);
        self.attempt_steps = alm.newton_steps();
        self.iterations = self.attempt_steps + self.relaxation_steps;
        if result.is_err()
            && short
            && (self.interior_restart(a0) || self.interior_start(a0))
            && let Some(alm) = &mut self.alm
        {
            result = alm.solve(&self.c_alm, a0, &self.lo, &self.hi);
            self.steps_after = alm.newton_steps();
            self.iterations += self.steps_after;
        }
        if result.is_err()
            && let Some(alm) = &mut self.alm
        {
            // Its multipliers are no start for the next solve.
            alm.reset_multipliers();
        }
        // Whether a tilt-rate row bound (their multipliers follow the
        // speed rows'): the next tick then skips the relaxation.
        let speed = self.speed_rows;
        self.rows_bound = match (&result, &self.alm) {
            (Ok(_), Some(alm)) => alm.row_multipliers()[speed..]
                .iter()
                .any(|v| *v != [0.0; 2]),
            _ => true,
        };
        result.is_ok()
    }

    /// The solution of `method` into `previous` (the plans y*_0..y*_N);
    /// an error (and the multipliers forgotten) when not finite.
    fn store_solution(
        &mut self,
        method: ConeMethod,
        fixed: [&[f64; 3]; 2],
    ) -> Result<(), ControlError> {
        let n = self.horizon - 2;
        for (i, fx) in fixed.into_iter().enumerate() {
            for f in 0..n {
                let p = match method {
                    ConeMethod::Alm => self.alm.as_ref().map_or(f64::NAN, |a| a.p(i, f)),
                    ConeMethod::InteriorPoint => {
                        self.qp.as_ref().map_or(f64::NAN, |q| q.ip.p(i, f))
                    }
                };
                self.previous[i][f + 3] = baseline(fx, f + 3) + p;
            }
            self.previous[i][..3].copy_from_slice(fx);
            if self.previous[i].iter().any(|v| !v.is_finite()) {
                if let Some(alm) = &mut self.alm {
                    alm.reset_multipliers();
                }
                return Err(SolverFault::NonFinite.into());
            }
        }
        Ok(())
    }
}

/// The pair's rows for the augmented Lagrangian: the speed rows per
/// axis, axis 0's first (p_{axis, k} at 2k + axis; soft, penalty ρ), and
/// the tilt-rate rows per axis (hard, in m/s²), each none when its bound
/// is off.
fn row_blocks(
    n: usize,
    dt: f64,
    penalty: Option<f64>,
    kappa: Option<[f64; 2]>,
) -> (Vec<RowBlock>, Vec<RowBlock>) {
    let speed = penalty.map_or_else(Vec::new, |penalty| {
        (0..2)
            .map(|axis| RowBlock {
                rows: (0..n)
                    .map(|g| Row::speed(g, dt, |k| 2 * k + axis))
                    .collect(),
                scale: 1.0 / (dt * dt),
                penalty,
            })
            .collect()
    });
    let inv_dt2 = 1.0 / (dt * dt);
    let rate = kappa.map_or_else(Vec::new, |kappa| {
        (0..2)
            .map(|axis| RowBlock {
                rows: (0..n)
                    .map(|f| {
                        Row::tilt_rate(f, kappa[axis], |s| s).on_outputs(inv_dt2, |k| 2 * k + axis)
                    })
                    .collect(),
                scale: 1.0,
                penalty: f64::INFINITY,
            })
            .collect()
    });
    (speed, rate)
}

impl PairSolver for BandedConeSolver {
    fn solve(&mut self, x: AxisProblem<'_>, y: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        let result = self.solve_pair(x, y);
        let method = match self.method() {
            ConeMethod::Alm => SolverMethod::Alm,
            ConeMethod::InteriorPoint => SolverMethod::InteriorPoint,
        };
        result.map_err(|e| SolveFailure::from_error(method, self.iterations(), e))?;
        Ok(SolveInfo {
            method,
            iterations: self.iterations(),
            factorisations: self.factorisations(),
            warm_started: self.warm_started(),
            relaxed: self.relaxation_held(),
            restart: self.restart_counts(),
        })
    }

    fn carry(&mut self, event: Carry<'_>) {
        match event {
            Carry::Accepted { plans: [x, y], .. } => self.accept_plans([x, y]),
            Carry::Accepted { .. } => {}
            Carry::Skipped => self.forget(),
            Carry::Reset => self.reset(),
        }
    }

    fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        BandedConeSolver::set_radius(self, radius)
    }

    fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        BandedConeSolver::set_centre(self, centre)
    }
}
