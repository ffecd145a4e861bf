//! The active-set polish of one axis's box with rows ([`Polish`]): the
//! equality-constrained QP on a guessed active set solved exactly, by a
//! banded LDLᵀ of its KKT matrix ordered by stage, then corrected
//! (primal-dual active set) until its multipliers have their signs and no
//! inactive bound is broken.
//!
//! Why: a chain of active tilt-rate rows pins the commands to a ramp over
//! tens of stages, and the multipliers along it are a triple sum of the
//! cost's gradient; in the augmented Lagrangian their slow modes fall only
//! a few times per multiplier update, and each rise of σ reshuffles the
//! chain's rows one Newton step at a time. The active set itself is found
//! early — the warm start's, or the first update's — and on it the KKT
//! system gives the plan and the multipliers at once.
//!
//! Unknowns per stage f, stride s = 2 + (row blocks): `[p_f, y_f, λ_{b,f}
//! …]`, y_f the stage's multiplier, λ_{b,f} that of block b's row whose
//! last free output is p_f (speed row g and tilt-rate row f end there).
//! An active constraint `a·x = β` enters scaled by `√P_max/|a|` (entries
//! of P's size), with `−δ` on its diagonal (δ = [`REGULARISATION`]: the
//! matrix is quasi-definite, so LDLᵀ needs no pivoting); an inactive one
//! is the row `−λ = 0`. One step of iterative refinement on the
//! unregularised system removes δ's error. A correction refactors
//! from the first slot whose side changed ([`BandedLdl::factor_from`]).

// The passes index several per-stage arrays (KKT slots, intervals,
// multipliers) by the stage.
#![allow(clippy::needless_range_loop)]

use super::super::banded::{BandedLdl, SymBand};
use super::BandedAlm;
use crate::ControlError;

/// The multipliers' diagonal in the scaled KKT matrix.
const REGULARISATION: f64 = 1e-10;
/// Steps of iterative refinement per KKT solve.
const REFINEMENTS: usize = 1;
/// Active-set corrections per polish.
const MAX_CORRECTIONS: usize = 8;

/// Which side of a constraint the guess holds at its bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    Free,
    Upper,
    Lower,
}

/// The polish's storage (module docs); built for one axis with rows.
#[derive(Debug, Clone)]
pub(super) struct Polish {
    /// Stride per stage and the rows' slots.
    stride: usize,
    row_slot: Vec<usize>,
    /// Per row `√P_max/|h|`, per stage `√P_max/|G|`.
    row_scale: Vec<f64>,
    stage_scale: f64,
    kkt: SymBand,
    ldl: BandedLdl,
    sol: Vec<f64>,
    res: Vec<f64>,
    stage_side: Vec<Side>,
    row_side: Vec<Side>,
    /// Scratch: P·x and the candidate's accelerations.
    px: Vec<f64>,
    work: Vec<f64>,
    /// The iterate before the polish (restored when it fails).
    saved: Vec<f64>,
    /// The first KKT slot whose side the last correction changed.
    first_change: usize,
    /// Attempts and successes (tests, benches).
    pub(super) tried: usize,
    pub(super) solved: usize,
}

impl Polish {
    /// Storage for n stages, P's half-bandwidth `p_band`, its largest
    /// diagonal entry, the rows (their last free output is their stage)
    /// in `blocks` row blocks, at 1/δt² = `inv_dt2`.
    pub(super) fn new(
        n: usize,
        p_band: usize,
        diag_max: f64,
        rows: &[super::super::bounds::Row],
        blocks: &[std::ops::Range<usize>],
        inv_dt2: f64,
    ) -> Self {
        let stride = 2 + blocks.len();
        let mut row_slot = vec![0; rows.len()];
        let mut span = 2;
        for (b, range) in blocks.iter().enumerate() {
            for r in range.clone() {
                let idx = &rows[r].idx[..rows[r].len];
                let top = idx.iter().copied().max().unwrap_or(0);
                span = span.max(top - idx.iter().copied().min().unwrap_or(0));
                row_slot[r] = stride * top + 2 + b;
            }
        }
        let bandwidth = (stride * p_band).max(stride * span + stride - 1);
        let root = diag_max.max(1.0).sqrt();
        let row_scale = rows
            .iter()
            .map(|r| {
                let norm = r.coef[..r.len].iter().map(|c| c * c).sum::<f64>().sqrt();
                root / norm.max(f64::MIN_POSITIVE)
            })
            .collect();
        let size = stride * n;
        Self {
            stride,
            row_slot,
            row_scale,
            stage_scale: root / (6f64.sqrt() * inv_dt2),
            kkt: SymBand::zeros(size, bandwidth),
            ldl: BandedLdl::new(size, bandwidth),
            sol: vec![0.0; size],
            res: vec![0.0; size],
            stage_side: vec![Side::Free; n],
            row_side: vec![Side::Free; rows.len()],
            px: vec![0.0; n],
            work: vec![0.0; n],
            saved: vec![0.0; n],
            first_change: 0,
            tried: 0,
            solved: 0,
        }
    }
}

impl BandedAlm {
    /// Tries the polish (module docs) from the active set of the current
    /// multipliers (stage y_f ≠ 0, row sides v > 0): on success the
    /// iterate and the multipliers are the KKT point's and it returns
    /// true; else nothing changed. One axis with intervals and rows only;
    /// `stage_tol`, `row_tol` the solve's residual tolerances.
    pub(super) fn polish(
        &mut self,
        a0: f64,
        (lo, hi): (&[f64], &[f64]),
        (stage_tol, row_tol): (f64, f64),
    ) -> Result<bool, ControlError> {
        let Some(mut pol) = self.polish.take() else {
            return Ok(false);
        };
        pol.tried += 1;
        pol.saved.copy_from_slice(&self.x);
        // Multipliers below 1e-6 of the largest count as 0: an interior
        // point's (handed over after a fallback) are positive on every
        // row.
        let big = |m: f64, v: f64| if v.abs() > 1e-6 * m { v } else { 0.0 };
        let ymax = self.y.iter().fold(0.0f64, |a, y| a.max(y[0].abs()));
        for (side, y) in pol.stage_side.iter_mut().zip(&self.y) {
            *side = side_of(big(ymax, y[0]), 0.0);
        }
        let vmax = self.v.iter().flatten().fold(0.0f64, |a, v| a.max(*v));
        for (side, v) in pol.row_side.iter_mut().zip(&self.v) {
            *side = side_of(big(vmax, v[0]), big(vmax, v[1]));
        }
        let mut done = false;
        pol.first_change = 0;
        for _ in 0..MAX_CORRECTIONS {
            self.polish_assemble(&mut pol, lo, hi, a0);
            if pol.ldl.factor_from(&pol.kkt, pol.first_change).is_err() {
                break;
            }
            pol.first_change = usize::MAX;
            pol.sol.copy_from_slice(&pol.res);
            pol.ldl.solve(&mut pol.sol);
            // Iterative refinement on the unregularised system.
            for _ in 0..REFINEMENTS {
                self.polish_residual(&mut pol, lo, hi, a0);
                pol.ldl.solve(&mut pol.res);
                for (s, r) in pol.sol.iter_mut().zip(&pol.res) {
                    *s += r;
                }
            }
            if !pol.sol.iter().all(|v| v.is_finite()) {
                break;
            }
            if !self.polish_correct(&mut pol, lo, hi, a0, (stage_tol, row_tol)) {
                done = true;
                break;
            }
        }
        if done {
            self.polish_accept(&pol);
            pol.solved += 1;
        } else {
            self.x.copy_from_slice(&pol.saved);
        }
        self.polish = Some(pol);
        Ok(done)
    }

    /// The KKT matrix of the guessed active set, and in `res` its
    /// right-hand side `[−c; β]` (scaled).
    fn polish_assemble(&self, pol: &mut Polish, lo: &[f64], hi: &[f64], a0: f64) {
        let (s, n) = (pol.stride, self.n);
        pol.kkt.fill_zero();
        pol.res.fill(0.0);
        let pb = self.base.bandwidth();
        for f in 0..n {
            for g in f.saturating_sub(pb)..=f {
                pol.kkt.set(s * f, s * g, self.base.get(f, g));
            }
            pol.res[s * f] = -self.c[f];
        }
        let intervals = self.intervals();
        let sc = pol.stage_scale * self.inv_dt2;
        for f in 0..n {
            let slot = s * f + 1;
            let bound = match pol.stage_side[f] {
                Side::Free => {
                    pol.kkt.set(slot, slot, -1.0);
                    continue;
                }
                Side::Upper => intervals[f][0][1],
                Side::Lower => intervals[f][0][0],
            };
            for (k, d) in [1.0, -2.0, 1.0].into_iter().enumerate().take(f + 1) {
                pol.kkt.set(slot, s * (f - k), sc * d);
            }
            pol.kkt.set(slot, slot, -REGULARISATION);
            pol.res[slot] = pol.stage_scale * (bound - a0);
        }
        for (r, row) in self.rows.iter().enumerate() {
            let slot = pol.row_slot[r];
            let bound = match pol.row_side[r] {
                Side::Free => {
                    pol.kkt.set(slot, slot, -1.0);
                    continue;
                }
                Side::Upper => hi[r],
                Side::Lower => lo[r],
            };
            let w = pol.row_scale[r];
            for k in 0..row.len {
                pol.kkt.add(slot, pol.stride * row.idx[k], w * row.coef[k]);
            }
            pol.kkt.set(slot, slot, -REGULARISATION);
            pol.res[slot] = w * bound;
        }
    }

    /// `res` = the unregularised KKT residual at `sol`: `−c − P·x − Aᵀλ`
    /// on the outputs (P·x by differencing), `β − a·x` (scaled) on the
    /// active constraints, 0 on the inactive.
    fn polish_residual(&mut self, pol: &mut Polish, lo: &[f64], hi: &[f64], a0: f64) {
        let (s, n) = (pol.stride, self.n);
        for f in 0..n {
            self.x[f] = pol.sol[s * f];
        }
        let mut px = std::mem::take(&mut pol.px);
        self.axes[0].apply_hessian_strided(&self.x, 1, 0, 2.0, 0, &mut pol.work, &mut px);
        pol.res.fill(0.0);
        for f in 0..n {
            pol.res[s * f] = -self.c[f] - px[f];
        }
        pol.px = px;
        let intervals = self.intervals();
        let sc = pol.stage_scale * self.inv_dt2;
        for f in 0..n {
            let bound = match pol.stage_side[f] {
                Side::Free => continue,
                Side::Upper => intervals[f][0][1],
                Side::Lower => intervals[f][0][0],
            };
            let lam = pol.sol[s * f + 1];
            let mut ax = 0.0;
            for (k, d) in [1.0, -2.0, 1.0].into_iter().enumerate().take(f + 1) {
                ax += sc * d * self.x[f - k];
                pol.res[s * (f - k)] -= sc * d * lam;
            }
            pol.res[s * f + 1] = pol.stage_scale * (bound - a0) - ax;
        }
        for (r, row) in self.rows.iter().enumerate() {
            let bound = match pol.row_side[r] {
                Side::Free => continue,
                Side::Upper => hi[r],
                Side::Lower => lo[r],
            };
            let (w, slot) = (pol.row_scale[r], pol.row_slot[r]);
            let lam = pol.sol[slot];
            for k in 0..row.len {
                pol.res[s * row.idx[k]] -= w * row.coef[k] * lam;
            }
            pol.res[slot] = w * (bound - row.dot(&self.x));
        }
    }

    /// The primal-dual active-set correction at `sol`: frees the
    /// constraints whose multiplier has the wrong sign; when there are
    /// none, binds the inactive ones broken beyond their tolerance (both
    /// at once cycle on a chain of rows). Returns whether the guess
    /// changed.
    fn polish_correct(
        &mut self,
        pol: &mut Polish,
        lo: &[f64],
        hi: &[f64],
        a0: f64,
        tols: (f64, f64),
    ) -> bool {
        let (s, n) = (pol.stride, self.n);
        for f in 0..n {
            self.x[f] = pol.sol[s * f];
        }
        let lam_max = pol.sol.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let eps = 1e-12 * lam_max;
        self.polish_sides(pol, lo, hi, a0, tols, Some(eps), None)
            || self.polish_sides(pol, lo, hi, a0, tols, None, Some(()))
    }

    /// One pass of [`BandedAlm::polish_correct`]: `free` (the multipliers'
    /// noise level) frees, `bind` binds.
    #[allow(clippy::too_many_arguments)]
    fn polish_sides(
        &self,
        pol: &mut Polish,
        lo: &[f64],
        hi: &[f64],
        a0: f64,
        (stage_tol, row_tol): (f64, f64),
        free: Option<f64>,
        bind: Option<()>,
    ) -> bool {
        let s = pol.stride;
        let step = |side: Side, lam: f64, value: f64, l: f64, h: f64, tol: f64| match side {
            Side::Upper if free.is_some_and(|e| lam < -e) => Side::Free,
            Side::Lower if free.is_some_and(|e| lam > e) => Side::Free,
            Side::Free if bind.is_some() && value > h + tol => Side::Upper,
            Side::Free if bind.is_some() && value < l - tol => Side::Lower,
            other => other,
        };
        let mut changed = false;
        let intervals = self.intervals();
        for f in 0..self.n {
            let uf = stage_acceleration(&self.x, f, self.inv_dt2) + a0;
            let [l, h] = intervals[f][0];
            let next = step(pol.stage_side[f], pol.sol[s * f + 1], uf, l, h, stage_tol);
            if next != pol.stage_side[f] {
                pol.first_change = pol.first_change.min(s * f + 1);
            }
            changed |= next != pol.stage_side[f];
            pol.stage_side[f] = next;
        }
        for (r, row) in self.rows.iter().enumerate() {
            let hx = row.dot(&self.x);
            let lam = pol.sol[pol.row_slot[r]];
            let next = step(pol.row_side[r], lam, hx, lo[r], hi[r], row_tol);
            if next != pol.row_side[r] {
                pol.first_change = pol.first_change.min(pol.row_slot[r]);
            }
            changed |= next != pol.row_side[r];
            pol.row_side[r] = next;
        }
        changed
    }

    /// Takes the KKT point: x, the stage multipliers y_f and the rows'
    /// `[upper, lower]` (unscaled).
    fn polish_accept(&mut self, pol: &Polish) {
        let (s, n) = (pol.stride, self.n);
        for f in 0..n {
            self.x[f] = pol.sol[s * f];
            let lam = match pol.stage_side[f] {
                Side::Free => 0.0,
                _ => pol.sol[s * f + 1] * pol.stage_scale,
            };
            self.y[f] = [lam, 0.0];
        }
        for r in 0..self.rows.len() {
            let lam = match pol.row_side[r] {
                Side::Free => 0.0,
                _ => pol.sol[pol.row_slot[r]] * pol.row_scale[r],
            };
            self.v[r] = [lam.max(0.0), (-lam).max(0.0)];
        }
        self.px_current = false;
    }
}

impl BandedAlm {
    /// The stage intervals (empty for a disc).
    fn intervals(&self) -> &[[[f64; 2]; 2]] {
        match &self.stages {
            super::StageSet::Interval(b) => b,
            super::StageSet::Disc(_) => &[],
        }
    }
}

/// The side a multiplier pair says is bound.
fn side_of(upper: f64, lower: f64) -> Side {
    if upper > 0.0 && upper >= lower {
        Side::Upper
    } else if lower > 0.0 || upper < 0.0 {
        Side::Lower
    } else {
        Side::Free
    }
}

/// `G_f·x` = `(p_f − 2p_{f−1} + p_{f−2})/δt²` (outputs before 0 are 0).
fn stage_acceleration(x: &[f64], f: usize, inv_dt2: f64) -> f64 {
    let at = |k: usize| if f >= k { x[f - k] } else { 0.0 };
    (at(0) - 2.0 * at(1) + at(2)) * inv_dt2
}
