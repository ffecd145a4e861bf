//! [`BandedConeSolver`]: both horizontal axes with the tilt cone
//! ([`super::cone`]), solved by the augmented Lagrangian of
//! [`super::cone_alm`] (warm-started across ticks), with the banded
//! interior point of [`super::cone_qp`] as its fallback.

use super::cone_alm::{self, AlmTuning, ConeAlm};
use super::cone_qp::{ConeAxis, ConeQp, STAGE, a_at, p_at};
use super::smoothness::{accel_block, sent_linear_term};
use super::{AxisProblem, ConeBounds, FastBandedSolver, Smoothness, baseline, check_lengths};
use crate::ControlError;

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
/// ([`ConeBounds`]): the augmented Lagrangian ([`ConeAlm`], O(N) per
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
    qp: ConeQp,
    alm: ConeAlm,
    /// ALM linear term (2n, interleaved) and scratch.
    c_alm: Vec<f64>,
    base: Vec<f64>,
    rhs: Vec<f64>,
    c: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Start deviations per axis (cold), then the warm guess.
    p: [Vec<f64>; 2],
    warm: [Vec<f64>; 2],
    /// The last solution's plans `y*_0..y*_N` per axis \[m\].
    previous: [Vec<f64>; 2],
    /// Warm starts enabled, and whether `previous` is last tick's.
    warm_start: bool,
    previous_valid: bool,
    iterations: usize,
    warm_used: bool,
    /// Which method gave the last solution.
    method: ConeMethod,
}

/// Which method of [`BandedConeSolver`] solved a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConeMethod {
    /// The augmented Lagrangian ([`ConeAlm`]).
    Alm,
    /// The stage interior point ([`ConeQp`]), after the ALM failed.
    InteriorPoint,
}

impl BandedConeSolver {
    /// Builds the solver for horizon N ≥ 3, step δt > 0 \[s\], per-axis
    /// weights (x, y), the bounds, and whether to warm-start.
    pub fn new(
        horizon: usize,
        dt: f64,
        weights: [AxisWeights; 2],
        bounds: ConeBounds,
        warm_start: bool,
    ) -> Result<Self, ControlError> {
        for w in &weights {
            FastBandedSolver::check_args(horizon, w.q, w.r, dt)?;
            w.smoothness.check()?;
        }
        bounds.check()?;
        let n = horizon - 2;
        let axes = weights.map(|w| ConeAxis {
            q: w.q,
            accel: accel_block(n, w.r, dt, &w.smoothness),
        });
        let penalty = bounds.speed.map(|_| bounds.speed_penalty);
        let qp = ConeQp::new(n, dt, [&axes[0], &axes[1]], bounds.acceleration, penalty);
        let fast = |w: &AxisWeights| {
            FastBandedSolver::with_smoothness(horizon, w.q, w.r, dt, w.smoothness)
        };
        let alm = ConeAlm::new(
            [fast(&weights[0])?, fast(&weights[1])?],
            dt,
            bounds.acceleration,
            penalty,
            AlmTuning::default(),
        );
        let m = qp.rows();
        Ok(Self {
            horizon,
            dt,
            weights,
            bounds,
            qp,
            alm,
            c_alm: vec![0.0; 2 * n],
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
            warm_used: false,
            method: ConeMethod::Alm,
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
    /// one per Newton step: the local phase reuses the factor).
    pub fn factorisations(&self) -> usize {
        self.alm.factorisations()
    }

    /// Sets the cone's radius per stage A_f [m/s²] (N − 2 entries, finite
    /// and > 0; stage f bounds the acceleration of output f + 2) for the
    /// next solves, instead of the bounds' constant A: the spatial
    /// model's tilt cone `‖a_h‖ ≤ tan(tilt)·(g ∓ a_z)` with the planned
    /// vertical acceleration.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        self.alm.set_radius(radius)?;
        self.qp.set_radius(radius)
    }

    /// Which method gave the last solution.
    pub fn method(&self) -> ConeMethod {
        self.method
    }

    /// Whether the last successful solve was warm-started.
    pub fn warm_started(&self) -> bool {
        self.warm_used
    }

    /// Forgets the previous solution: the next solve starts cold. Call it
    /// when a tick did not use this solver (its plan is then not the one
    /// the next tick continues) and on a controller reset.
    pub fn forget(&mut self) {
        self.previous_valid = false;
    }

    /// Solves both axes with the cone. `x.plan` and `y.plan` hold the
    /// cold start on entry (any plan, e.g. the unconstrained optimum of
    /// the fast path) and the solution on exit; `fixed`, `sent`,
    /// `reference` as [`FastBandedSolver::solve_problem`]. With warm
    /// starts on and a solution from the previous tick, that solution
    /// shifted by one step is the start instead; should it fail, the cold
    /// start is tried with the interior point. Errors: wrong lengths, and
    /// [`ControlError::Solver`] when neither converges.
    pub fn solve_pair(
        &mut self,
        x: AxisProblem<'_>,
        y: AxisProblem<'_>,
    ) -> Result<(), ControlError> {
        check_lengths(self.horizon, x.reference, x.plan)?;
        check_lengths(self.horizon, y.reference, y.plan)?;
        let (dt, n) = (self.dt, self.horizon - 2);
        let fixed = [x.fixed, y.fixed];
        self.c.fill(0.0);
        let mut a0 = [0.0; 2];
        for (i, a) in [&x, &y].into_iter().enumerate() {
            let q = self.weights[i].q;
            self.alm.axis(i).right_hand_side(
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
                let j = f + 4;
                let prev = &self.previous[i];
                let guess = if j <= self.horizon {
                    prev[j]
                } else {
                    2.0 * prev[self.horizon] - prev[self.horizon - 1]
                };
                self.warm[i][f] = guess - b;
            }
            self.c[a_at(i, 0)] = sent_linear_term(&self.weights[i].smoothness, a.fixed, a.sent, dt);
            for f in 0..n {
                // ½xᵀ(2H)x − 2·rhsᵀx: the fast path's objective, doubled.
                self.c_alm[cone_alm::at(i, f)] = -2.0 * self.rhs[f];
            }
            a0[i] = (a.fixed[2] - 2.0 * a.fixed[1] + a.fixed[0]) / (dt * dt);
        }
        let axis = self.bounds.axis_within(self.alm.radius());
        let mut k = 0;
        for fx in fixed {
            let (lo, hi) = (&mut self.lo, &mut self.hi);
            axis.speed_rows(self.horizon, fx, dt, |l, h| {
                lo[k] = l;
                hi[k] = h;
                k += 1;
            });
        }
        self.iterations = 0;
        let warm = self.warm_start && self.previous_valid;
        self.warm_used = warm;
        self.previous_valid = false;
        // First the augmented Lagrangian (warm: last tick's plan and
        // multipliers one step on), then the interior point from the cold
        // start should it fail.
        if warm {
            self.alm.shift();
            self.alm.set_start([&self.warm[0], &self.warm[1]]);
        } else {
            self.alm.reset_multipliers();
            self.alm.set_start([&self.p[0], &self.p[1]]);
        }
        let alm = self.alm.solve(&self.c_alm, a0, &self.lo, &self.hi);
        self.iterations = self.alm.newton_steps();
        if alm.is_ok() {
            self.method = ConeMethod::Alm;
        } else {
            self.alm.reset_multipliers();
            self.warm_used = false;
            self.method = ConeMethod::InteriorPoint;
            self.qp.set_start([&self.p[0], &self.p[1]], dt);
            self.qp.solve(&self.c, a0, &self.lo, &self.hi)?;
            self.iterations += self.qp.iterations();
        }
        let solution = |i: usize, f: usize| match self.method {
            ConeMethod::Alm => self.alm.p(i, f),
            ConeMethod::InteriorPoint => self.qp.p(i, f),
        };
        for (i, (plan, fx)) in [x.plan, y.plan].into_iter().zip(fixed).enumerate() {
            plan[..3].copy_from_slice(fx);
            for f in 0..n {
                plan[f + 3] = baseline(fx, f + 3) + solution(i, f);
            }
            if plan.iter().any(|v| !v.is_finite()) {
                return Err(ControlError::Solver("non-finite solution".to_string()));
            }
            self.previous[i].copy_from_slice(plan);
        }
        self.previous_valid = true;
        Ok(())
    }
}
