//! The active-set solver's KKT solves (module docs of [`super`]): the
//! working set's system factored from the first stage changed, solved
//! with a step of iterative refinement on the unregularised system, and
//! the solution read back; the dependent constraints the factorisation
//! found.

use super::super::cascade::SolverFault;
use super::{ActiveSet, Problem, Side};
use crate::ControlError;

impl ActiveSet {
    /// Factors the KKT matrix of the working set (from the first stage
    /// changed) and solves it: `sol` by slot. Unrefined: the decisions
    /// the methods take from it are the same as from the refined solution
    /// (on the corner bench, the same KKT solves to the one); the accepted
    /// solution is refined ([`ActiveSet::refine`]).
    pub(super) fn kkt_solve(&mut self, prob: &Problem<'_>) -> Result<(), ControlError> {
        if self.work.solves == self.budget {
            return Err(SolverFault::NotConverged {
                iterations: self.work.solves,
            }
            .into());
        }
        self.work.solves += 1;
        let (by_stage, stage_start) = (&self.by_stage, &self.stage_start);
        let side = &self.side;
        self.kkt.build_from(
            self.changed_from,
            prob.p,
            &self.cons,
            |f| &by_stage[stage_start[f]..stage_start[f + 1]],
            |id| side[id] != Side::Free,
        )?;
        self.changed_from = self.n;
        let m = self.kkt.len();
        // Right-hand side [−c; w·β].
        for f in 0..self.n {
            self.rhs[self.kkt.slot_p(f)] = -prob.c[f];
        }
        for id in 0..self.cons.len() {
            if let Some(s) = self.kkt.slot_con(id) {
                self.rhs[s] = self.cons[id].w * self.target(id);
            }
        }
        self.sol[..m].copy_from_slice(&self.rhs[..m]);
        self.kkt.solve(&mut self.sol);
        if !self.sol[..m].iter().all(|v| v.is_finite()) {
            return Err(SolverFault::NonFinite.into());
        }
        Ok(())
    }

    /// One step of iterative refinement of the last KKT solve on the
    /// unregularised system (with P·x by differencing): the rounding of
    /// the factor (P's condition number is near 1e11) and the
    /// regularisation's error leave `sol`; into (x, lam). On a nearly
    /// singular set the step can move x by more than it corrects: should
    /// the refined x break a constraint, the solve fails rather than give
    /// an inaccurate plan (seed `cc 3210b686…` of
    /// `alm_tilt_rate_rows_match_clarabel_cold_and_warm`, a cold draw
    /// after 423 KKT solves: a rate row 5e-4 over its bound after the
    /// step, the rows of the set 2e-6 over before it).
    pub(super) fn refine(
        &mut self,
        prob: &Problem<'_>,
        p_times: &mut impl FnMut(&[f64], &mut [f64]),
    ) -> Result<(), ControlError> {
        let m = self.kkt.len();
        self.residual(p_times);
        self.kkt.solve(&mut self.res);
        for (s, r) in self.sol[..m].iter_mut().zip(&self.res[..m]) {
            *s += r;
        }
        self.take_solution(false);
        if (0..self.cons.len()).any(|id| self.broken(prob, id).0 > 0.0) {
            return Err(SolverFault::BoundBroken.into());
        }
        Ok(())
    }

    /// The bound a constraint of the working set holds.
    fn target(&self, id: usize) -> f64 {
        match self.side[id] {
            Side::Upper => self.bound[id][1],
            Side::Lower => self.bound[id][0],
            Side::Free => 0.0,
        }
    }

    /// `res` = the unregularised KKT residual at `sol` (by slot): `−c −
    /// P·x − Σ w·aᵀλ` on the outputs (P·x by differencing), `w·(β − a·x)`
    /// on the constraints (0 on the dependent ones, whose multiplier the
    /// factor holds at 0).
    fn residual(&mut self, p_times: &mut impl FnMut(&[f64], &mut [f64])) {
        for f in 0..self.n {
            self.x_next[f] = self.sol[self.kkt.slot_p(f)];
        }
        p_times(&self.x_next, &mut self.px);
        for f in 0..self.n {
            let s = self.kkt.slot_p(f);
            self.res[s] = self.rhs[s] - self.px[f];
        }
        for id in 0..self.cons.len() {
            let Some(s) = self.kkt.slot_con(id) else {
                continue;
            };
            let c = self.cons[id];
            let lam = self.sol[s];
            for k in 0..c.len {
                self.res[self.kkt.slot_p(c.first + k)] -= c.w * c.coef[k] * lam;
            }
            self.res[s] = self.rhs[s] - c.w * c.dot(&self.x_next);
        }
    }

    /// The KKT solution into `x`, `lam` (or, `next`: `x_next`,
    /// `lam_next`), multipliers unscaled; 0 outside the set.
    pub(super) fn take_solution(&mut self, next: bool) {
        let (x, lam) = if next {
            (&mut self.x_next, &mut self.lam_next)
        } else {
            (&mut self.x, &mut self.lam)
        };
        for (f, x) in x.iter_mut().enumerate() {
            *x = self.sol[self.kkt.slot_p(f)];
        }
        for (id, (lam, c)) in lam.iter_mut().zip(&self.cons).enumerate() {
            *lam = match self.kkt.slot_con(id) {
                Some(s) => self.sol[s] * c.w,
                None => 0.0,
            };
        }
    }

    /// The first member from `from` on that the set's others determine
    /// (decoupled in the factor, its multiplier 0).
    pub(super) fn dependent_member(&self, from: usize) -> Option<usize> {
        (from..self.cons.len()).find(|&id| {
            self.kkt
                .slot_con(id)
                .is_some_and(|s| self.kkt.is_dependent(s))
        })
    }

    /// Frees the members the others determine (their value is then
    /// checked as the free ones' are); returns whether any.
    pub(super) fn free_dependent(&mut self) -> bool {
        let mut any = false;
        let mut from = 0;
        while let Some(id) = self.dependent_member(from) {
            self.release(id);
            any = true;
            from = id + 1;
        }
        any
    }
}
