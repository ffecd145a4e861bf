//! An active-set method for one axis's QP with stage intervals and rows
//! (`ActiveSet`): the tilt-rate bound's problem (and the box with speed
//! rows). The equality-constrained QP on a working set is solved exactly
//! through its compact KKT system (`kkt.rs`); the set is corrected in
//! blocks while that converges, then by the dual method, which cannot
//! cycle (`dual.rs`).
//!
//! The problem, in the deviations p of the n free outputs:
//!
//! ```text
//! min ½pᵀPp + cᵀp   s.t.   lo_f ≤ G_f·p + a_0 ≤ hi_f (stages),   lo_r ≤ h_r·p ≤ hi_r (rows)
//! ```
//!
//! G_f·p = (p_f − 2p_{f−1} + p_{f−2})/δt², the rows on at most five
//! consecutive outputs (speed, tilt rate). P is positive definite and
//! banded.
//!
//! **Chains.** Where the plan is rate-limited, tens of consecutive
//! tilt-rate rows are active (a ramp of the command), and their
//! multipliers are a triple sum along the chain: when a chain's end is a
//! stage off — the warm start's usual error — every multiplier of the
//! chain comes out on the wrong side. Freeing them all (the primal-dual
//! active set's rule) breaks them all again next step, and the method
//! cycles.
//!
//! **Block steps** (`BLOCK_STEPS`). From a guessed working set (the last
//! tick's, shifted; or none), each step solves the KKT system of the set,
//! then frees the wrong-signed constraints at the *ends* of their chains
//! (a same-family neighbour outside the set or on the other side; the
//! horizon's first row counts as an end) and binds every constraint the
//! solution breaks. A set whose multipliers all have their signs and that
//! breaks nothing is the optimum. From a warm start this ends in one to
//! three KKT solves.
//!
//! **A burst's first tick** (`rollout.rs`). Without a guess, when the
//! unconstrained plan breaks at most `COLD_FEW` (40) constraints — a
//! corner entering the horizon's end — the methods start from the set of
//! that plan's rollout (below), as a warm start within `WARM_SOLVES`; on
//! the corner bench's course of corners at N = 200 this took the box with
//! the tilt rate's bursts' first ticks from ~390 to ~210 µs (median).
//!
//! **Cold starts** (`interior.rs`). Without a guess (a burst's first
//! tick that breaks more, or whose start above did not end), or when a warm start has not ended within `warm_solves` (8 at N = 50, 10 at N = 100, 14 from N = 200) KKT
//! solves or its KKT point misprices or breaks more than `WARM_DISTANCE`
//! (40) constraints at once (and on the next solve after such a warm
//! start), the working set is read off a condensed
//! interior point: Mehrotra's
//! predictor-corrector on the QP in the outputs alone, whose Newton
//! matrix keeps P's band (half-bandwidth 4), run until the mean
//! complementarity has fallen 1e-8; a constraint whose barrier term
//! outweighs P is in the set. From there the methods below end in two or
//! three KKT solves on the corner bench at N = 200, where the set of the
//! unconstrained plan's rollout (`rollout.rs`: output by output, the value
//! that keeps the plan's acceleration, clamped into the constraints that
//! end at it) took up to 2179 from rest with the box, and warm starts
//! shifted from the last tick took more than 400 on the ticks where the
//! replayed state left the last plan. The rollout's set remains the start
//! when the interior point does not converge. (Before, a start from rest
//! with the box went to the stage interior point by rule, ~2.2 ms.)
//! Should the methods not end from the interior point's set within
//! `COLD_SOLVES` (16) KKT solves, the interior point is carried on from
//! where it stopped to a gap of 1e-13 and names the set again: near a
//! degenerate vertex the sides at 1e-8 name an ill-conditioned set.
//!
//! **The dual method** (`dual.rs`). Then every wrong-signed constraint
//! is freed until none is left (a dual-feasible point), and the broken
//! ones are added, all at once, along the segment on which the KKT
//! point's multipliers change linearly; where a multiplier of the set
//! reaches zero the segment stops and that constraint leaves (Goldfarb &
//! Idnani 1983, with the constraints added in a block; the objective
//! rises at every step, so no set repeats). A block whose every
//! constraint would leave at once falls back to one constraint: the
//! broken one of the latest stage (the factorisation restarts at the
//! first stage the set changed, so the latest is the cheapest).
//!
//! **Dependent constraints.** A chain of tilt-rate rows from the horizon's
//! start fixes every acceleration along it, so a stage interval there,
//! active too, is a combination of the rows: the KKT matrix is singular
//! (regularised: its multipliers huge and of any sign). The factorisation
//! finds such a constraint by its pivot (at the regularisation's level,
//! `kkt.rs`) and decouples it (multiplier 0); the methods then take it out
//! of the set, and a dependent constraint the dual method must add moves
//! the others' multipliers instead (`ActiveSet::pure_dual_step`).

mod dual;
mod interior;
mod kkt;
mod rollout;
mod system;

use kkt::{Con, Kkt};

use super::banded::SymBand;
use super::bounds::Row;
use super::cascade::SolverFault;
use crate::ControlError;

/// Block steps before the dual method.
const BLOCK_STEPS: usize = 2;
/// KKT solves per solve, over both methods (the default budget): beyond
/// it the solve fails (the cascade's next solver takes the tick).
pub const MAX_SOLVES: usize = 40;
/// KKT solves a warm start (a guessed working set) may take before the
/// solve starts again cold, from the interior point's set
/// (`interior.rs`). A cold solve costs the interior point's 10–19
/// iterations (~20 µs each at N = 200) and 1–4 KKT solves (~20 µs each),
/// so a warm start that ends within ~14 is still the cheaper one. With
/// box and tilt rate at N = 200, constrained p99 µs in three interleaved
/// runs each (docs/performance-log.md, "Longer warm starts"): 8 → 14, the
/// corner bench 460–468 → 446–448, the learned bench's L with drag
/// 508–517 → 427–433 with the residual and 496–544 → 378–383 without;
/// 16 gave 447–452 and 450–474; 40 leaves the cold start no budget
/// (`MAX_SOLVES`) and sends 15 solves of the corner to the stage interior
/// point (p99 626). (On 2026-11-28, with dearer KKT solves and no
/// `WARM_DISTANCE`, 8 was best: 6 / 8 / 12 / 20 / 40 gave 779 / 733 /
/// 834 / 1030 / 2719 µs.) The guesses fail in streaks (ticks 194–199 of
/// the corner replay): after one fails, the axis's next solve starts
/// cold (p99 of 8 interleaved runs each, median: 481 → 466 µs; the
/// median 108 → 110 µs). A burst's first tick from its rollout's set
/// (`rollout.rs`) has this budget at every horizon; a guess has
/// [`warm_solves`]'s, fewer at shorter horizons.
const WARM_SOLVES: usize = 14;

/// KKT solves a guess may take before the solve starts again cold, for
/// n free outputs: `6 + (n + 12)/25` within 8 ..= [`WARM_SOLVES`] — 8 at
/// N = 50, 10 at N = 100 (the shipped horizon), 14 from N = 200. Measured
/// on the corner bench with box and tilt rate, constrained p99 µs,
/// interleaved runs (docs/performance-log.md, "The warm start's budget by
/// horizon"): N = 100, 8 / 10 / 12 / 14 gave 430–435 / 411–424 / 450 /
/// 472–479 (the course of corners' other ticks 464–479 with 10 against
/// 622–639 with 14); N = 50, 8 against 14: 237 against 287–341; N = 200,
/// 10 against 14: 522–596 against 455–542; N = 400, 14 and 22 the same.
fn warm_solves(n: usize) -> usize {
    (6 + (n + 12) / 25).clamp(8, WARM_SOLVES)
}
/// A warm start whose KKT point, in a block step or while it is made dual
/// feasible, misprices (wrong-signed multipliers) or breaks more
/// constraints than this at once starts again cold at once: its set is
/// far from the optimum's. On the corner bench at N = 200 with box and
/// tilt rate, the warm solves that end within `WARM_SOLVES` show at most
/// 28; 25 of the 75 that do not show more than 40 within their first four
/// KKT solves (the constrained ticks' p99 ~525 → ~490 µs).
const WARM_DISTANCE: usize = 40;
/// A cold solve whose unconstrained plan breaks at most this many
/// constraints starts the methods from the set it breaks (as a warm
/// start, within `WARM_SOLVES`) before the condensed interior point: a
/// burst that begins where a corner enters the horizon's end breaks a
/// few stages there, a start from rest most of the horizon.
const COLD_FEW: usize = 40;
/// KKT solves a cold solve may take from the condensed interior point's
/// set before the interior point is carried on to a smaller gap and names
/// the set again (`interior.rs`, `TIGHT_GAP_REDUCTION`). From its set the
/// method ends in 1–4 KKT solves on the corner bench's cold solves and in
/// 1–14 in the learned bench's closed-loop flights (where 8 sent the
/// 10–14 to the interior point's extra iterations, which cost more:
/// p99 ~515 → ~560 µs); the one that did not end (its tick 7, at a
/// degenerate vertex) ran out of all 40 and fell to the stage interior
/// point (2.6–4.4 ms): now ~0.7–1 ms.
const COLD_SOLVES: usize = 16;

/// Which side of its interval a constraint of the working set holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Side {
    /// Not in the working set.
    Free,
    /// At its upper bound.
    Upper,
    /// At its lower bound.
    Lower,
}

/// The data of one solve: P and the linear term, the stage intervals and
/// the rows' bounds.
#[derive(Debug, Clone, Copy)]
pub(super) struct Problem<'a> {
    /// P (n × n, banded).
    pub(super) p: &'a SymBand,
    /// The linear term c (n).
    pub(super) c: &'a [f64],
    /// The stage intervals `[lo, hi]` of `u_f = G_f·p + a_0` [m/s²]
    /// (the first axis's of each pair).
    pub(super) stages: &'a [[[f64; 2]; 2]],
    /// a_0 [m/s²].
    pub(super) a0: f64,
    /// The rows' bounds.
    pub(super) row_lo: &'a [f64],
    pub(super) row_hi: &'a [f64],
    /// Tolerances on a stage's and a row's violation.
    pub(super) stage_tol: f64,
    pub(super) row_tol: f64,
}

/// What the last solve did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Work {
    /// KKT solves (factorisations).
    pub solves: usize,
    /// Of those, the dual method's.
    pub dual: usize,
    /// Iterations of the condensed interior point that guessed a cold
    /// start's working set (0: none ran).
    pub interior: usize,
}

/// The active-set method's storage (module docs); built for one axis.
/// Allocates at construction only.
#[derive(Debug, Clone)]
pub(super) struct ActiveSet {
    n: usize,
    /// Constraints: the n stages, then the rows; per stage the ids whose
    /// last output is p_f (the stage first), flattened; per constraint its
    /// family (0: stages, 1 + block: rows) for the chains.
    cons: Vec<Con>,
    by_stage: Vec<usize>,
    stage_start: Vec<usize>,
    family: Vec<usize>,
    kkt: Kkt,
    /// Per constraint: its side, its bounds `[lo, hi]` on `a·p` this
    /// solve, its multiplier (signed: > 0 at the upper bound) and the
    /// dual method's segment end; whether a block is adding it.
    side: Vec<Side>,
    bound: Vec<[f64; 2]>,
    lam: Vec<f64>,
    lam_next: Vec<f64>,
    adding: Vec<bool>,
    /// The primal iterate and the segment's end.
    x: Vec<f64>,
    /// A cold solve's unconstrained plan, kept while the methods try the
    /// set it breaks (`COLD_FEW`).
    unconstrained: Vec<f64>,
    x_next: Vec<f64>,
    /// The KKT right-hand side, solution and residual by slot; P·x.
    rhs: Vec<f64>,
    sol: Vec<f64>,
    res: Vec<f64>,
    px: Vec<f64>,
    /// The first stage whose constraints changed side since the last
    /// factorisation.
    changed_from: usize,
    work: Work,
    /// The KKT solves' budget of the current solve.
    budget: usize,
    /// Whether the current run is a warm start's.
    warm: bool,
    /// Whether the last solve's warm start did not end (this one's guess
    /// is then not tried).
    warm_failed: bool,
    /// Whether the cold solve's working set is the condensed interior
    /// point's.
    from_interior: bool,
    /// The condensed interior point of a cold solve's guess.
    interior: interior::Interior,
}

impl ActiveSet {
    /// Storage for P (n × n, banded), the rows (on the outputs, in the
    /// rows' order) in `blocks` at 1/δt² = `inv_dt2`.
    pub(super) fn new(
        p: &SymBand,
        rows: &[Row],
        blocks: &[std::ops::Range<usize>],
        inv_dt2: f64,
    ) -> Self {
        let n = p.n();
        let p_max = (0..n).fold(0.0f64, |a, i| a.max(p.get(i, i)));
        let root = p_max.max(1.0).sqrt();
        let mut cons: Vec<Con> = (0..n).map(|f| Con::stage(f, inv_dt2, root)).collect();
        let mut family = vec![0; n];
        for (b, range) in blocks.iter().enumerate() {
            for row in &rows[range.clone()] {
                cons.push(Con::row(row, root));
                family.push(1 + b);
            }
        }
        let span = cons
            .iter()
            .map(|c| c.len - 1)
            .fold(p.bandwidth().max(2), usize::max);
        let mut lists = vec![Vec::new(); n];
        for (id, c) in cons.iter().enumerate() {
            lists[c.last()].push(id);
        }
        let per_stage = lists.iter().map(Vec::len).max().unwrap_or(1);
        let mut by_stage = Vec::with_capacity(cons.len());
        let mut stage_start = Vec::with_capacity(n + 1);
        for l in &lists {
            stage_start.push(by_stage.len());
            by_stage.extend_from_slice(l);
        }
        stage_start.push(by_stage.len());
        let m = cons.len();
        let slots = n + m;
        Self {
            n,
            kkt: Kkt::new(n, m, span, per_stage),
            interior: interior::Interior::new(n, &cons, span),
            cons,
            by_stage,
            stage_start,
            family,
            side: vec![Side::Free; m],
            bound: vec![[0.0; 2]; m],
            lam: vec![0.0; m],
            lam_next: vec![0.0; m],
            adding: vec![false; m],
            x: vec![0.0; n],
            unconstrained: vec![0.0; n],
            x_next: vec![0.0; n],
            rhs: vec![0.0; slots],
            sol: vec![0.0; slots],
            res: vec![0.0; slots],
            px: vec![0.0; n],
            changed_from: 0,
            work: Work::default(),
            budget: MAX_SOLVES,
            warm: false,
            warm_failed: false,
            from_interior: false,
        }
    }

    /// What the last solve did.
    pub(super) fn work(&self) -> Work {
        self.work
    }

    /// The solution's outputs p (after a successful solve).
    pub(super) fn x(&self) -> &[f64] {
        &self.x
    }

    /// The multiplier of stage f's interval (signed: > 0 at its upper
    /// bound), per m/s² of u_f.
    pub(super) fn stage_multiplier(&self, f: usize) -> f64 {
        self.lam[f]
    }

    /// Row r's multiplier (signed as [`ActiveSet::stage_multiplier`]).
    pub(super) fn row_multiplier(&self, r: usize) -> f64 {
        self.lam[self.n + r]
    }

    /// Solves from the working set `guess(id)` (stages 0..n, then rows;
    /// [`Side::Free`] for none); `p_times(x, out)` sets `out = P·x` by
    /// differencing (the refinement's residual). Errors when the method
    /// does not end within `budget` KKT solves or a factorisation
    /// fails.
    pub(super) fn solve(
        &mut self,
        prob: &Problem<'_>,
        (guess, budget): (impl Fn(usize) -> Side, usize),
        mut p_times: impl FnMut(&[f64], &mut [f64]),
    ) -> Result<Work, ControlError> {
        self.work = Work::default();
        self.budget = budget;
        self.set_bounds(prob);
        // After a warm start that did not end, this one starts cold: the
        // guesses fail in streaks (`WARM_SOLVES`).
        let forced_cold = std::mem::take(&mut self.warm_failed);
        if forced_cold {
            self.forget_set();
        } else {
            for id in 0..self.cons.len() {
                // A side whose bound is infinite cannot hold.
                self.side[id] = match guess(id) {
                    Side::Upper if self.bound[id][1].is_finite() => Side::Upper,
                    Side::Lower if self.bound[id][0].is_finite() => Side::Lower,
                    _ => Side::Free,
                };
            }
            self.set_replaced();
        }
        let guessed = self.set_members().next().is_some();
        // A burst's first tick: no guess (not a start made cold above).
        let first = !forced_cold && !guessed;
        if guessed {
            // Warm: the guess's set, within warm_solves(n); else cold.
            self.budget = budget.min(warm_solves(self.n));
            self.warm = true;
            let warm = self.run(prob, &mut p_times);
            self.warm = false;
            match warm {
                Ok(()) => return Ok(self.work),
                Err(_) if budget > self.work.solves => {
                    self.warm_failed = true;
                    self.budget = budget;
                    self.forget_set();
                }
                Err(e) => return Err(e),
            }
        }
        if self.cold_start(prob, &mut p_times, first)? {
            return Ok(self.work);
        }
        if self.from_interior {
            // From the interior point's set, within COLD_SOLVES; else
            // again from its iterate carried on to a smaller gap.
            self.budget = budget.min(self.work.solves + COLD_SOLVES);
            match self.run(prob, &mut p_times) {
                Ok(()) => return Ok(self.work),
                Err(_) if budget > self.work.solves => {
                    self.budget = budget;
                    self.lam.fill(0.0);
                    if !self.interior_tighten(prob)? {
                        self.set_replaced();
                    }
                }
                Err(e) => return Err(e),
            }
        }
        self.run(prob, &mut p_times)?;
        Ok(self.work)
    }

    /// Empties the working set (multipliers 0) for a cold start.
    fn forget_set(&mut self) {
        self.side.fill(Side::Free);
        self.lam.fill(0.0);
        self.set_replaced();
    }

    /// Notes that the working set was replaced as a whole (a guess, a
    /// restart): no constraint is being added, and the KKT factor is
    /// rebuilt from the first stage.
    fn set_replaced(&mut self) {
        self.adding.fill(false);
        self.changed_from = 0;
        self.kkt.invalidate();
    }

    /// The methods from the current working set: block steps, then the
    /// dual method (module docs).
    fn run(
        &mut self,
        prob: &Problem<'_>,
        p_times: &mut impl FnMut(&[f64], &mut [f64]),
    ) -> Result<(), ControlError> {
        for _ in 0..BLOCK_STEPS {
            if self.block_step(prob, p_times)? {
                return Ok(());
            }
        }
        self.dual_feasible(prob)?;
        self.dual_method(prob, p_times)
    }

    /// One block step (module docs); returns whether the set solved.
    fn block_step(
        &mut self,
        prob: &Problem<'_>,
        p_times: &mut impl FnMut(&[f64], &mut [f64]),
    ) -> Result<bool, ControlError> {
        self.kkt_solve(prob)?;
        self.take_solution(false);
        let tol = self.lam_noise();
        let dependent = self.free_dependent();
        let (freed, wrong) = self.free_chain_ends(tol);
        let bound = self.bind_broken(prob);
        self.check_distance(wrong + bound)?;
        if dependent || freed || bound > 0 || self.free_wrong_signed(tol) > 0 {
            return Ok(false);
        }
        self.refine(prob, p_times)?;
        Ok(true)
    }

    /// Frees wrong-signed (and dependent) constraints until the set's KKT
    /// point is dual feasible.
    fn dual_feasible(&mut self, prob: &Problem<'_>) -> Result<(), ControlError> {
        loop {
            self.kkt_solve(prob)?;
            self.take_solution(false);
            let tol = self.lam_noise();
            let dependent = self.free_dependent();
            let wrong = self.free_wrong_signed(tol);
            self.check_distance(wrong)?;
            if !(wrong > 0 || dependent) {
                return Ok(());
            }
        }
    }

    /// The per-constraint bounds on `a·p` of this solve.
    fn set_bounds(&mut self, prob: &Problem<'_>) {
        for f in 0..self.n {
            let [lo, hi] = prob.stages[f][0];
            self.bound[f] = [lo - prob.a0, hi - prob.a0];
        }
        for r in 0..prob.row_lo.len() {
            self.bound[self.n + r] = [prob.row_lo[r], prob.row_hi[r]];
        }
    }

    /// Sets a constraint's side, noting the first stage changed.
    fn set_side(&mut self, id: usize, side: Side) {
        if self.side[id] != side {
            self.side[id] = side;
            self.changed_from = self.changed_from.min(self.cons[id].last());
        }
    }

    /// Takes constraint `id` out of the set (multiplier 0).
    fn release(&mut self, id: usize) {
        self.lam[id] = 0.0;
        self.set_side(id, Side::Free);
        self.adding[id] = false;
    }

    /// The constraints in the working set.
    fn set_members(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.cons.len()).filter(|&id| self.side[id] != Side::Free)
    }

    /// Whether multiplier `l` is on the wrong side for constraint `id`'s
    /// side.
    fn wrong(&self, id: usize, l: f64) -> bool {
        match self.side[id] {
            Side::Upper => l < 0.0,
            Side::Lower => l > 0.0,
            Side::Free => false,
        }
    }

    /// The multipliers' noise level: 1e-12 of the largest.
    fn lam_noise(&self) -> f64 {
        1e-12 * self.lam.iter().fold(0.0f64, |a, b| a.max(b.abs()))
    }

    /// Whether member `id`'s multiplier is wrong-signed beyond `tol`.
    fn wrong_beyond(&self, id: usize, tol: f64) -> bool {
        match self.side[id] {
            Side::Upper => self.lam[id] < -tol,
            Side::Lower => self.lam[id] > tol,
            Side::Free => false,
        }
    }

    /// Frees the wrong-signed constraints at the ends of their chains
    /// (module docs); returns whether any, and how many members are
    /// wrong-signed.
    fn free_chain_ends(&mut self, tol: f64) -> (bool, usize) {
        let m = self.cons.len();
        let (mut any, mut wrong) = (false, 0);
        for id in 0..m {
            if !self.wrong_beyond(id, tol) {
                continue;
            }
            wrong += 1;
            let fam = self.family[id];
            let first_row = fam > 0 && (id == 0 || self.family[id - 1] != fam);
            let end = first_row
                || [id.wrapping_sub(1), id + 1]
                    .into_iter()
                    .any(|j| j < m && self.family[j] == fam && self.side[j] != self.side[id]);
            if end {
                // Later members see this one as it was: mark, free after.
                self.adding[id] = true;
                any = true;
            }
        }
        for id in 0..m {
            if self.adding[id] {
                self.release(id);
            }
        }
        (any, wrong)
    }

    /// Frees every constraint whose multiplier is wrong-signed beyond
    /// `tol`; returns how many.
    fn free_wrong_signed(&mut self, tol: f64) -> usize {
        let mut freed = 0;
        for id in 0..self.cons.len() {
            if self.wrong_beyond(id, tol) {
                self.release(id);
                freed += 1;
            }
        }
        freed
    }

    /// Ends a warm start whose KKT point misprices or breaks more than
    /// [`WARM_DISTANCE`] constraints (`far`): its set is far from the
    /// optimum's, and the cold start's is nearer.
    fn check_distance(&self, far: usize) -> Result<(), ControlError> {
        if self.warm && far > WARM_DISTANCE {
            return Err(SolverFault::WarmSetFar.into());
        }
        Ok(())
    }

    /// How far constraint `id` (outside the set) is broken at x beyond its
    /// tolerance, scaled by w (0: not), and the side it breaks.
    fn broken(&self, prob: &Problem<'_>, id: usize) -> (f64, Side) {
        let c = &self.cons[id];
        let v = c.dot(&self.x);
        let tol = if id < self.n {
            prob.stage_tol
        } else {
            prob.row_tol
        };
        let [lo, hi] = self.bound[id];
        if v > hi + tol {
            (c.w * (v - hi), Side::Upper)
        } else if v < lo - tol {
            (c.w * (lo - v), Side::Lower)
        } else {
            (0.0, Side::Free)
        }
    }

    /// Keeps a gap between opposite chains: binding `id` at `side` next
    /// to a member of its family at the other side (not itself broken)
    /// frees that member. A chain's junction a stage off is the warm
    /// start's usual error, and opposite chains side by side make every
    /// multiplier of both wrong-signed (on the corner bench at N = 200
    /// the rate alone's KKT solves per solve: 3.43 → 3.07).
    fn keep_gap(&mut self, prob: &Problem<'_>, id: usize, side: Side) {
        let opposite = match side {
            Side::Upper => Side::Lower,
            Side::Lower => Side::Upper,
            Side::Free => return,
        };
        for j in [id.wrapping_sub(1), id + 1] {
            if j < self.cons.len()
                && self.family[j] == self.family[id]
                && self.side[j] == opposite
                && self.broken(prob, j).0 == 0.0
            {
                self.release(j);
            }
        }
    }

    /// Binds every constraint outside the set broken at x (keeping gaps,
    /// [`ActiveSet::keep_gap`]); returns how many.
    fn bind_broken(&mut self, prob: &Problem<'_>) -> usize {
        let mut bound = 0;
        self.for_each_broken(prob, |set, id, side| {
            set.lam[id] = 0.0;
            set.set_side(id, side);
            set.keep_gap(prob, id, side);
            bound += 1;
        });
        bound
    }

    /// Calls `f(self, id, side)` for each constraint outside the set that
    /// x breaks (in order; f sees the changes of the earlier calls).
    fn for_each_broken(&mut self, prob: &Problem<'_>, mut f: impl FnMut(&mut Self, usize, Side)) {
        for id in 0..self.cons.len() {
            if self.side[id] != Side::Free {
                continue;
            }
            let (amount, side) = self.broken(prob, id);
            if amount > 0.0 {
                f(self, id, side);
            }
        }
    }
}
