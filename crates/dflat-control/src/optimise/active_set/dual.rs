//! The dual method of the active-set solver (module docs of [`super`]):
//! from a dual-feasible KKT point, the broken constraints added in a
//! block along the segment on which the multipliers change linearly, one
//! at a time when a block cannot, and the step without a primal move for
//! a constraint the set's others determine.

use super::super::cascade::SolverFault;
use super::kkt::Con;
use super::{ActiveSet, Problem, Side};
use crate::ControlError;

impl ActiveSet {
    /// Adds broken constraints until none is left (the optimum).
    pub(super) fn dual_method(
        &mut self,
        prob: &Problem<'_>,
        p_times: &mut impl FnMut(&[f64], &mut [f64]),
    ) -> Result<(), ControlError> {
        loop {
            let Some((add, side)) = self.latest_broken(prob) else {
                // (x, lam) are the last KKT solve's (a whole segment).
                return self.refine(prob, p_times);
            };
            if !self.add_block(prob)? {
                self.add_one(prob, add, side)?;
            }
        }
    }

    /// Adds every broken constraint at once (module docs of [`super`]):
    /// the members whose multiplier would start on the wrong side, or
    /// that the others determine, leave at once; along the segment, the
    /// first multiplier to reach zero stops it and leaves. Returns false
    /// (nothing added) when every constraint added leaves at once.
    fn add_block(&mut self, prob: &Problem<'_>) -> Result<bool, ControlError> {
        self.adding.fill(false);
        let mut count = 0;
        self.for_each_broken(prob, |set, id, side| {
            set.lam[id] = 0.0;
            set.set_side(id, side);
            set.adding[id] = true;
            count += 1;
        });
        loop {
            self.kkt_solve(prob)?;
            self.work.dual += 1;
            self.take_solution(true);
            let (left, changed) = self.drop_at_start();
            if changed {
                count -= left;
                if count == 0 {
                    return Ok(false);
                }
                continue;
            }
            match self.segment_step(None) {
                None => return Ok(true),
                Some(id) => {
                    if self.adding[id] {
                        count -= 1;
                    }
                    self.release(id);
                }
            }
        }
    }

    /// Releases the members the others determine or, when there are
    /// none, those being added whose multiplier starts on the wrong side;
    /// returns how many being added left, and whether the set changed.
    /// A member that was in the set before the block and that the block
    /// made dependent stays; the members being added near it (the
    /// dependence is local: constraints on overlapping outputs) leave,
    /// or every one being added when none is near.
    fn drop_at_start(&mut self) -> (usize, bool) {
        let (mut left, mut changed) = (0, false);
        let (mut old_dependent, mut near_left) = (false, false);
        let mut from = 0;
        while let Some(id) = self.dependent_member(from) {
            from = id + 1;
            if self.adding[id] {
                left += 1;
                self.release(id);
                changed = true;
            } else if self.side[id] != Side::Free {
                old_dependent = true;
                let k = self.cons[id];
                let gone = self.release_adding(|c| near(c, &k));
                left += gone;
                near_left |= gone > 0;
            }
        }
        if old_dependent && !near_left {
            left += self.release_adding(|_| true);
        }
        changed |= old_dependent;
        if changed {
            // The factor no longer matches the set: solve again first.
            return (left, true);
        }
        for id in 0..self.cons.len() {
            if self.adding[id] && self.lam[id] == 0.0 && self.wrong(id, self.lam_next[id]) {
                self.release(id);
                left += 1;
                changed = true;
            }
        }
        (left, changed)
    }

    /// Releases the constraints being added that `pick` chooses; returns
    /// how many.
    fn release_adding(&mut self, pick: impl Fn(&Con) -> bool) -> usize {
        let mut gone = 0;
        for id in 0..self.cons.len() {
            if self.adding[id] && pick(&self.cons[id]) {
                self.release(id);
                gone += 1;
            }
        }
        gone
    }

    /// Moves (x, λ) along the segment to the KKT solution just solved
    /// (`x_next`, `lam_next`) as far as every member's multiplier keeps
    /// its side (`except`: a member not checked); returns the member that
    /// stopped it (None: the whole segment).
    fn segment_step(&mut self, except: Option<usize>) -> Option<usize> {
        let mut t_max = 1.0;
        let mut block = None;
        for id in self.set_members() {
            let (l0, l1) = (self.lam[id], self.lam_next[id]);
            if Some(id) != except && self.wrong(id, l1) {
                let sign = if self.side[id] == Side::Upper {
                    1.0
                } else {
                    -1.0
                };
                let t = (sign * l0).max(0.0) / (sign * (l0 - l1));
                if t < t_max {
                    t_max = t;
                    block = Some(id);
                }
            }
        }
        for (x, xn) in self.x.iter_mut().zip(&self.x_next) {
            *x += t_max * (xn - *x);
        }
        for id in 0..self.cons.len() {
            if self.side[id] != Side::Free {
                self.lam[id] += t_max * (self.lam_next[id] - self.lam[id]);
            }
        }
        block
    }

    /// Adds constraint `add` at `side` alone (Goldfarb & Idnani), from
    /// the current KKT point (x, lam).
    fn add_one(&mut self, prob: &Problem<'_>, add: usize, side: Side) -> Result<(), ControlError> {
        self.adding.fill(false);
        self.lam[add] = 0.0;
        self.set_side(add, side);
        loop {
            self.kkt_solve(prob)?;
            self.work.dual += 1;
            self.take_solution(true);
            if self.dependent_member(0).is_some()
                || (self.lam[add] == 0.0 && self.wrong(add, self.lam_next[add]))
            {
                // Determined (or nearly) by the set: the set's factor
                // without it, and the others' multipliers move for it.
                // Found at its own slot alone (the usual case: a chain's
                // row at the horizon's start), the factor held is that
                // one already: its row is decoupled, and no later row
                // refers to it. Found elsewhere, or nearly dependent, the
                // set without it is factored again.
                let own_slot_alone = self.dependent_member(0) == Some(add)
                    && self.dependent_member(add + 1).is_none();
                self.set_side(add, Side::Free);
                if !own_slot_alone {
                    self.kkt_solve(prob)?;
                }
                if self.dependent_member(0).is_some_and(|id| id != add)
                    || !self.pure_dual_step(add, side)
                {
                    return Err(SolverFault::DependentConstraint.into());
                }
                continue;
            }
            match self.segment_step(Some(add)) {
                None => return Ok(()),
                Some(id) => self.release(id),
            }
        }
    }

    /// The dual method's step for a constraint `p` (at `side`, outside the
    /// set whose factor is held) that the set determines (`a_p = Σ
    /// r_k·a_k`): x stays, p's multiplier grows and the others' change
    /// along −r until the first reaches zero; that one leaves and p joins
    /// the set. Returns false when none can.
    fn pure_dual_step(&mut self, p: usize, side: Side) -> bool {
        let m = self.kkt.len();
        self.res[..m].fill(0.0);
        let c = self.cons[p];
        for k in 0..c.len {
            self.res[self.kkt.slot_p(c.first + k)] = c.w * c.coef[k];
        }
        self.kkt.solve(&mut self.res);
        let sign_p = if side == Side::Upper { 1.0 } else { -1.0 };
        let r_of = |s: &Self, id: usize| {
            s.kkt
                .slot_con(id)
                .filter(|&slot| id != p && !s.kkt.is_dependent(slot))
                .map(|slot| s.res[slot])
        };
        let mut best: Option<(f64, usize)> = None;
        for id in self.set_members() {
            let Some(r) = r_of(self, id) else {
                continue;
            };
            // λ_k/w − sign_p·τ·r keeps its side while τ < λ_k/(w·sign_p·r).
            let rate = sign_p * r;
            let tau = self.lam[id] / self.cons[id].w / rate;
            if rate != 0.0 && tau >= 0.0 && best.is_none_or(|b| tau < b.0) {
                best = Some((tau, id));
            }
        }
        let Some((tau, drop)) = best else {
            return false;
        };
        for id in 0..self.cons.len() {
            if self.side[id] == Side::Free {
                continue;
            }
            if let Some(r) = r_of(self, id) {
                self.lam[id] -= sign_p * tau * r * self.cons[id].w;
            }
        }
        self.lam[p] = sign_p * tau * self.cons[p].w;
        self.release(drop);
        self.set_side(p, side);
        true
    }

    /// The broken constraint of the latest stage (ties: the most broken).
    fn latest_broken(&self, prob: &Problem<'_>) -> Option<(usize, Side)> {
        for f in (0..self.n).rev() {
            let ids = &self.by_stage[self.stage_start[f]..self.stage_start[f + 1]];
            let mut best: Option<(f64, usize, Side)> = None;
            for &id in ids {
                if self.side[id] != Side::Free {
                    continue;
                }
                let (amount, side) = self.broken(prob, id);
                if amount > 0.0 && best.is_none_or(|b| amount > b.0) {
                    best = Some((amount, id, side));
                }
            }
            if let Some((_, id, side)) = best {
                return Some((id, side));
            }
        }
        None
    }
}

/// Whether two constraints' outputs are within four stages of each other.
fn near(a: &Con, b: &Con) -> bool {
    a.first <= b.last() + 4 && b.first <= a.last() + 4
}
