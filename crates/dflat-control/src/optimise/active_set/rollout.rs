//! A cold solve's start (module docs of [`super`], "Cold starts"): the
//! unconstrained plan, then the interior point's working set
//! (`interior.rs`), or, when that does not converge, the unconstrained
//! plan rolled out stage by stage into the constraints, and the
//! constraints that held it.

use super::{ActiveSet, Problem, Side};
use crate::ControlError;

impl ActiveSet {
    /// A cold solve's start (no guess): the unconstrained plan; when it
    /// breaks at most [`super::COLD_FEW`] constraints and no warm start
    /// ran this solve (`first`), the methods from the set it breaks,
    /// within `WARM_SOLVES` KKT solves; else, or when that does not end,
    /// the interior point's working set ([`ActiveSet::interior_guess`])
    /// or else its rollout's ([`ActiveSet::rollout_guess`]). Returns true
    /// when solved.
    pub(super) fn cold_start(
        &mut self,
        prob: &Problem<'_>,
        p_times: &mut impl FnMut(&[f64], &mut [f64]),
        first: bool,
    ) -> Result<bool, ControlError> {
        self.kkt_solve(prob)?;
        self.take_solution(false);
        let m = self.cons.len();
        let broken = (0..m).filter(|&id| self.broken(prob, id).0 > 0.0).count();
        if broken == 0 {
            self.refine(prob, p_times)?;
            return Ok(true);
        }
        if first && broken <= super::COLD_FEW {
            self.unconstrained.copy_from_slice(&self.x);
            let budget = self.budget;
            self.budget = budget.min(self.work.solves + super::WARM_SOLVES);
            self.warm = true;
            self.rollout_guess();
            self.trim_end_block();
            let few = self.run(prob, p_times);
            self.warm = false;
            self.budget = budget;
            match few {
                Ok(()) => return Ok(true),
                Err(_) if budget > self.work.solves => {
                    self.forget_set();
                    self.x.copy_from_slice(&self.unconstrained);
                }
                Err(e) => return Err(e),
            }
        }
        self.from_interior = self.interior_guess(prob)?;
        if !self.from_interior {
            self.rollout_guess();
        }
        Ok(false)
    }

    /// Frees the first half of the block of stage intervals in the set
    /// that reaches the horizon's last stage. Where a burst begins because
    /// a corner enters the horizon's end, the rollout's block there spans
    /// the unconstrained plan's violation, about twice the optimum's (9
    /// stages where the optimum holds 4 on the corner bench's course at
    /// N = 200: the optimum turns earlier, under the bound), and the
    /// methods freed it one stage per KKT solve from its start. From its
    /// second half they end in 6 KKT solves instead of 14 there (4 instead
    /// of 22 at N = 100); docs/performance-log.md, "The block at the horizon's
    /// end".
    fn trim_end_block(&mut self) {
        let n = self.n;
        if n == 0 || self.side[n - 1] == Side::Free {
            return;
        }
        let side = self.side[n - 1];
        let mut first = n - 1;
        while first > 0 && self.side[first - 1] == side {
            first -= 1;
        }
        for id in first..first + (n - first) / 2 {
            self.release(id);
        }
    }

    /// Sets the working set of a cold solve from the unconstrained plan
    /// in `x`: output by output, the value that keeps the plan's stage
    /// acceleration (from the rollout's earlier outputs), clamped into
    /// every constraint that ends at that output; a constraint that
    /// clamps it joins the set at the side it holds. Where the plan is
    /// rate-limited this binds the ramp's rows one after another and then
    /// the stage intervals the ramp reaches: the optimum's set but for
    /// where the ramps start and end. Uses `x_next` as scratch.
    pub(super) fn rollout_guess(&mut self) {
        for f in 0..self.n {
            // d = rollout − plan follows d_f = 2·d_{f−1} − d_{f−2}.
            let d = |k: usize| {
                if k < f {
                    self.x_next[k] - self.x[k]
                } else {
                    0.0
                }
            };
            let want = self.x[f] + 2.0 * d(f.wrapping_sub(1)) - d(f.wrapping_sub(2));
            let (mut lo, mut hi) = ((f64::NEG_INFINITY, None), (f64::INFINITY, None));
            for &id in &self.by_stage[self.stage_start[f]..self.stage_start[f + 1]] {
                let c = &self.cons[id];
                let a = c.coef[c.len - 1];
                if a == 0.0 {
                    continue;
                }
                let rest: f64 = (0..c.len - 1)
                    .map(|k| c.coef[k] * self.x_next[c.first + k])
                    .sum();
                let [b_lo, b_hi] = self.bound[id];
                let (from_lo, from_hi) = ((b_lo - rest) / a, (b_hi - rest) / a);
                // The output's limits and the side each one holds.
                let ((l, l_side), (h, h_side)) = if a > 0.0 {
                    ((from_lo, Side::Lower), (from_hi, Side::Upper))
                } else {
                    ((from_hi, Side::Upper), (from_lo, Side::Lower))
                };
                if l > lo.0 {
                    lo = (l, Some((id, l_side)));
                }
                if h < hi.0 {
                    hi = (h, Some((id, h_side)));
                }
            }
            let (value, holds) = if want < lo.0 {
                lo
            } else if want > hi.0 {
                hi
            } else {
                (want, None)
            };
            self.x_next[f] = value;
            if let Some((id, side)) = holds {
                self.lam[id] = 0.0;
                self.set_side(id, side);
            }
        }
    }
}
