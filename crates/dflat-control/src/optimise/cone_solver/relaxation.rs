//! The pair without its tilt-rate rows, solved first on a warm tick
//! ([`BandedConeSolver::try_relaxation`]).
//!
//! Dropping the hard tilt-rate rows (the speed rows, soft, and the discs
//! at the funnel's radius kept) leaves a relaxation of the cone with the
//! tilt rate: where the relaxation's optimum keeps every tilt-rate row, it
//! is the optimum of the pair with them, the problem being strictly
//! convex. On most constrained ticks no tilt-rate row binds at the
//! optimum (on the corner bench at N = 200, 1625 of the 1905 solves), and
//! the relaxation is the plain cone's problem: no rows to walk a chain
//! of, no multipliers of rows to find. Where a row does bind, the
//! relaxation's solve is spent, so it is tried only when the last tick's
//! solution bound none (`rows_bound`): a tick whose rows bound is mostly
//! followed by another. On the corner bench the cone with the tilt rate's
//! constrained median fell by a third to two fifths at N = 50 … 800 and
//! its p99 did not move (docs/performance-log.md, "The relaxation without
//! the tilt-rate rows").

use super::BandedConeSolver;

impl BandedConeSolver {
    /// The relaxation's attempt on a warm tick: its multipliers shifted a
    /// stage, started from the warm guess, solved with the speed rows'
    /// bounds. Returns whether its optimum keeps every tilt-rate row (to
    /// the hard rows' tolerance) and so is the pair's: the augmented
    /// Lagrangian with the rows then holds it as its iterate, with its
    /// stage and speed-row multipliers and the tilt-rate rows' at 0 (the
    /// next tick's warm start). Otherwise the augmented Lagrangian's
    /// iterate and multipliers are as they were.
    pub(super) fn try_relaxation(&mut self, a0: [f64; 2]) -> bool {
        let (Some(relaxed), Some(alm)) = (&mut self.relaxed, &mut self.alm) else {
            return false;
        };
        relaxed.shift();
        relaxed.set_start(&[&self.warm[0], &self.warm[1]]);
        let speed = self.speed_rows;
        let solved = relaxed.solve(&self.c_alm, a0, &self.lo[..speed], &self.hi[..speed]);
        self.relaxation_steps = relaxed.newton_steps();
        self.relaxation_factorisations = relaxed.factorisations();
        if solved.is_err() {
            // Its multipliers are no start for the next solve.
            relaxed.reset_multipliers();
            return false;
        }
        let n = self.horizon - 2;
        for (axis, plan) in self.relaxed_plan.iter_mut().enumerate() {
            for (f, p) in plan.iter_mut().enumerate().take(n) {
                *p = relaxed.p(axis, f);
            }
        }
        alm.set_start(&[&self.relaxed_plan[0], &self.relaxed_plan[1]]);
        if !alm.hard_rows_hold(&self.lo, &self.hi) {
            return false;
        }
        let rows = &mut self.relaxed_rows;
        rows.fill([0.0; 2]);
        rows[..speed].copy_from_slice(relaxed.row_multipliers());
        alm.set_multipliers(|f| relaxed.stage_multiplier(f), rows);
        true
    }

    /// Whether the last solve was the relaxation's: its optimum kept the
    /// tilt-rate rows (module docs of `relaxation.rs`).
    pub fn relaxation_held(&self) -> bool {
        self.relaxation_held
    }

    /// Turns the relaxation on or off (tests: the augmented Lagrangian
    /// with the rows on every tick).
    #[cfg(test)]
    pub(crate) fn set_relaxation(&mut self, on: bool) {
        self.relaxation_on = on;
    }
}
