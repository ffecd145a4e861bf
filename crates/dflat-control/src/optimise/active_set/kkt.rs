//! The KKT system of one axis's QP on a working set, compact and in
//! profile (skyline) form ([`Kkt`]).
//!
//! Unknowns in stage order: per stage f the free output p_f, then the
//! multiplier of each constraint of the working set whose last output is
//! p_f (the stage's own interval first, then the rows in row order). The
//! constraints outside the working set have no slot. Row i of the lower
//! triangle is non-zero from its first column `first[i]` on: for p_f the
//! slot of p_{f−b} (b: P's half-bandwidth), for a constraint the slot of
//! its first output. The LDLᵀ factor keeps that profile (no fill outside
//! it), so its cost follows the working set: a stage with no constraint
//! of the set costs P's band alone (about b²/2 multiply-adds), where the
//! fixed-stride band of every constraint's slot cost (stride·reach)²/2.
//!
//! A constraint `a·p = β` enters scaled by `w = √P_max/|a|` (entries of
//! P's size) with `−δ` on its diagonal (δ = [`REGULARISATION`]): the
//! matrix is quasi-definite, so the factor needs no pivoting; the
//! solution holds its multiplier divided by w. A constraint whose pivot
//! comes out at the regularisation's level (above −[`DEPENDENT`]) lies in
//! the span of the set's others: its row is decoupled and its multiplier
//! held at 0 ([`Kkt::is_dependent`]).
//!
//! When a working set changes only from stage f on, the slots before
//! p_f's and their factor rows are the same: the factorisation restarts
//! there ([`Kkt::build_from`]).

use super::super::banded::{SymBand, dot};
use super::super::bounds::Row;
use crate::ControlError;

/// The multipliers' diagonal in the scaled KKT matrix.
pub(super) const REGULARISATION: f64 = 1e-10;
/// A constraint's pivot above −DEPENDENT (the scaled matrix's pivots of
/// independent constraints are of order −1 or below): its row lies in the
/// span of the set's others.
const DEPENDENT: f64 = 1e-9;

/// What a slot holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Slot {
    /// The free output p_f.
    Output(usize),
    /// The multiplier of constraint `id`.
    Multiplier(usize),
}

/// One constraint `lo ≤ a·p ≤ hi` on consecutive outputs: `coef[k]` on
/// `p_{first + k}`, k < len, and its scale `w = √P_max/|a|`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Con {
    pub(super) first: usize,
    pub(super) len: usize,
    pub(super) coef: [f64; 5],
    pub(super) w: f64,
}

impl Con {
    /// Stage f's acceleration `(p_f − 2p_{f−1} + p_{f−2})/δt²` (outputs
    /// before the horizon 0), scaled to `root` = √P_max.
    pub(super) fn stage(f: usize, inv_dt2: f64, root: f64) -> Self {
        let first = f.saturating_sub(2);
        let len = f - first + 1;
        let full = [1.0, -2.0, 1.0];
        let mut coef = [0.0; 5];
        for k in 0..len {
            coef[k] = full[3 - len + k] * inv_dt2;
        }
        Self::scaled(first, len, coef, root)
    }

    /// A row (on the outputs), scaled to `root` = √P_max.
    pub(super) fn row(row: &Row, root: f64) -> Self {
        let idx = &row.idx[..row.len];
        let first = idx.iter().copied().min().unwrap_or(0);
        let last = idx.iter().copied().max().unwrap_or(0);
        let mut coef = [0.0; 5];
        for k in 0..row.len {
            coef[row.idx[k] - first] += row.coef[k];
        }
        Self::scaled(first, last - first + 1, coef, root)
    }

    fn scaled(first: usize, len: usize, coef: [f64; 5], root: f64) -> Self {
        let norm = coef[..len].iter().map(|v| v * v).sum::<f64>().sqrt();
        Self {
            first,
            len,
            coef,
            w: root / norm.max(f64::MIN_POSITIVE),
        }
    }

    /// `a·p`.
    #[inline]
    pub(super) fn dot(&self, p: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..self.len {
            s += self.coef[k] * p[self.first + k];
        }
        s
    }

    /// The last output's index.
    #[inline]
    pub(super) fn last(&self) -> usize {
        self.first + self.len - 1
    }
}

/// `a·b` summed in order, for the factor's rows: they are a few slots
/// long (3.6 on average on the corner's working sets), where the
/// four-way [`dot`]'s set-up costs more than its lanes save.
#[inline(always)]
fn short_dot(a: &[f64], b: &[f64]) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        s += x * y;
    }
    s
}

/// The compact KKT matrix of a working set and its LDLᵀ factor in profile
/// form (module docs). Storage is allocated once for the largest working
/// set (every constraint in it).
#[derive(Debug, Clone)]
pub(super) struct Kkt {
    /// Slots in use.
    m: usize,
    /// Per slot: what it holds, its row's first column and the offset of
    /// that row in `l`.
    what: Vec<Slot>,
    first: Vec<usize>,
    off: Vec<usize>,
    /// Per stage the slot of p_f; per constraint its slot (`usize::MAX`:
    /// not in the working set).
    slot_p: Vec<usize>,
    slot_con: Vec<usize>,
    /// The matrix's lower profile (assembled), then its factor's L, row by
    /// row from `first[i]`; the diagonal, then D and 1/D.
    l: Vec<f64>,
    diag: Vec<f64>,
    inv_d: Vec<f64>,
    /// Scratch of the factorisation: row i of L times D.
    work: Vec<f64>,
    /// Whether the factor is of the matrix held.
    factored: bool,
    /// Per slot: a constraint dependent on the set's others (decoupled).
    dependent: Vec<bool>,
}

impl Kkt {
    /// Storage for n outputs and `cons` constraints, at most `span`
    /// outputs reached back by a row of the lower triangle (P's
    /// half-bandwidth or a constraint's span) and at most `per_stage`
    /// constraints per stage.
    pub(super) fn new(n: usize, cons: usize, span: usize, per_stage: usize) -> Self {
        let slots = n + cons;
        let width = (span + 1) * (1 + per_stage);
        Self {
            m: 0,
            what: vec![Slot::Output(0); slots],
            first: vec![0; slots],
            off: vec![0; slots + 1],
            slot_p: vec![0; n],
            slot_con: vec![usize::MAX; cons],
            l: vec![0.0; slots * width],
            diag: vec![0.0; slots],
            inv_d: vec![0.0; slots],
            work: vec![0.0; width],
            factored: false,
            dependent: vec![false; slots],
        }
    }

    /// Whether slot i is a constraint dependent on the set's others (its
    /// multiplier 0, its row decoupled).
    pub(super) fn is_dependent(&self, i: usize) -> bool {
        self.dependent[i]
    }

    /// Forgets the factor (the next build starts at stage 0).
    pub(super) fn invalidate(&mut self) {
        self.factored = false;
    }

    /// Slots in use.
    pub(super) fn len(&self) -> usize {
        self.m
    }

    /// The slot of p_f.
    #[inline]
    pub(super) fn slot_p(&self, f: usize) -> usize {
        self.slot_p[f]
    }

    /// The slot of constraint `id` (`None` outside the working set).
    #[inline]
    pub(super) fn slot_con(&self, id: usize) -> Option<usize> {
        let s = self.slot_con[id];
        (s != usize::MAX).then_some(s)
    }

    /// Lays out the slots from stage `from` on (those before kept) for the
    /// working set `in_set(id)`, the constraints of stage f being
    /// `by_stage(f)` in order, assembles their rows and factors them.
    pub(super) fn build_from<'a>(
        &mut self,
        from: usize,
        p: &SymBand,
        cons: &[Con],
        by_stage: impl Fn(usize) -> &'a [usize],
        in_set: impl Fn(usize) -> bool,
    ) -> Result<(), ControlError> {
        let n = self.slot_p.len();
        let p_band = p.bandwidth();
        let from = if self.factored { from.min(n) } else { 0 };
        if from == n {
            return Ok(());
        }
        // Constraints of the stages from `from` on leave their slots.
        for f in from..n {
            for &id in by_stage(f) {
                self.slot_con[id] = usize::MAX;
            }
        }
        let mut m = if from == 0 { 0 } else { self.slot_p[from] };
        let start = m;
        for f in from..n {
            self.slot_p[f] = m;
            self.what[m] = Slot::Output(f);
            self.first[m] = self.slot_p[f.saturating_sub(p_band)];
            m += 1;
            for &id in by_stage(f) {
                if in_set(id) {
                    self.slot_con[id] = m;
                    self.what[m] = Slot::Multiplier(id);
                    self.first[m] = self.slot_p[cons[id].first];
                    m += 1;
                }
            }
        }
        self.m = m;
        for i in start..m {
            self.off[i + 1] = self.off[i] + (i - self.first[i]);
        }
        // Assemble rows start..m.
        for i in start..m {
            let (fi, oi) = (self.first[i], self.off[i]);
            self.l[oi..self.off[i + 1]].fill(0.0);
            match self.what[i] {
                Slot::Output(f) => {
                    // P[f][f − d] for d = 1..=b (before output 0: none).
                    let band = p.lower_row(f);
                    for (d, &v) in band.iter().enumerate().take(f + 1).skip(1) {
                        self.l[oi + self.slot_p[f - d] - fi] = v;
                    }
                    self.diag[i] = band[0];
                }
                Slot::Multiplier(id) => {
                    let c = &cons[id];
                    for k in 0..c.len {
                        let s = self.slot_p[c.first + k];
                        self.l[oi + s - fi] = c.w * c.coef[k];
                    }
                    self.diag[i] = -REGULARISATION;
                }
            }
        }
        self.factored = false;
        self.factor(start)?;
        self.factored = true;
        Ok(())
    }

    /// LDLᵀ of rows `start..m` in place (rows before factored already).
    // t indexes the row, the scratch and (through j) the earlier rows.
    #[allow(clippy::needless_range_loop)]
    fn factor(&mut self, start: usize) -> Result<(), ControlError> {
        let Self {
            m,
            what,
            first,
            off,
            l,
            diag,
            inv_d,
            work,
            dependent,
            ..
        } = self;
        for i in start..*m {
            let (fi, oi) = (first[i], off[i]);
            let width = i - fi;
            let (done, rest) = l.split_at_mut(oi);
            let row = &mut rest[..width];
            let work = &mut work[..width];
            let firsts = &first[fi..i];
            let offs = &off[fi..i];
            let invs = &inv_d[fi..i];
            for t in 0..width {
                let j = fi + t;
                let (fj, oj) = (firsts[t], offs[t]);
                let lo = fi.max(fj);
                // s = A_ij − Σ_{k ∈ [lo, j)} (L_ik·D_k)·L_jk.
                let s = row[t] - short_dot(&work[lo - fi..t], &done[oj + lo - fj..oj + j - fj]);
                work[t] = s;
                row[t] = s * invs[t];
            }
            let d = diag[i] - short_dot(work, row);
            let output = matches!(what[i], Slot::Output(_));
            dependent[i] = false;
            if !output && d.is_finite() && d > -DEPENDENT {
                // A constraint the set's others determine: its row
                // decoupled, its multiplier 0 (`Kkt::solve`).
                row.fill(0.0);
                dependent[i] = true;
                diag[i] = -1.0;
                inv_d[i] = 0.0;
                continue;
            }
            if !(d.is_finite() && (d > 0.0) == output && d != 0.0) {
                return Err(ControlError::NotPositiveDefinite);
            }
            diag[i] = d;
            inv_d[i] = 1.0 / d;
        }
        Ok(())
    }

    /// Solves `K·x = rhs` in place (rhs by slot, length ≥ m).
    pub(super) fn solve(&self, x: &mut [f64]) {
        let m = self.m;
        for i in 0..m {
            let (fi, oi) = (self.first[i], self.off[i]);
            // (The four-way `dot`, not `short_dot`: the rounding of these
            // substitutions decides the cold solves' paths on the corner
            // bench — with `short_dot` the tilt rate alone's first tick
            // took 37 KKT solves instead of 8.)
            let s = dot(&self.l[oi..self.off[i + 1]], &x[fi..i]);
            x[i] -= s;
        }
        for (xi, d) in x[..m].iter_mut().zip(&self.inv_d) {
            *xi *= d;
        }
        for i in (0..m).rev() {
            let (fi, oi) = (self.first[i], self.off[i]);
            let xi = x[i];
            if xi != 0.0 {
                for (xk, l) in x[fi..i].iter_mut().zip(&self.l[oi..self.off[i + 1]]) {
                    *xk -= l * xi;
                }
            }
        }
    }
}
