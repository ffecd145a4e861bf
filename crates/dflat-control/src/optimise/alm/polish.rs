//! The active-set polish of one axis's box with rows: the QP solved by
//! the active-set method of [`crate::optimise::active_set`] from the
//! working set the multipliers name (stage y_f ≠ 0, row sides v > 0;
//! those below 1e-6 of the largest count as 0: an interior point's,
//! handed over after a fallback, are positive on every row).

use super::super::active_set::{ActiveSet, Problem, Side};
use super::BandedAlm;
use crate::ControlError;

impl BandedAlm {
    /// Storage of the polish for this solver's one axis and rows.
    pub(super) fn new_polish(&self) -> ActiveSet {
        ActiveSet::new(&self.base, &self.rows, &self.blocks, self.inv_dt2)
    }

    /// Tries the polish from the active set of the current multipliers:
    /// on success the iterate and the multipliers are the QP's optimum and
    /// it returns true; else nothing changed. One axis with intervals and
    /// rows only; `stage_tol`, `row_tol` the solve's residual tolerances.
    pub(super) fn polish(
        &mut self,
        a0: f64,
        (lo, hi): (&[f64], &[f64]),
        (stage_tol, row_tol): (f64, f64),
    ) -> Result<bool, ControlError> {
        let Some(mut set) = self.polish.take() else {
            return Ok(false);
        };
        let big = |m: f64, v: f64| v.abs() > 1e-6 * m;
        let ymax = self.warm.y.iter().fold(0.0f64, |a, y| a.max(y[0].abs()));
        let vmax = self.warm.v.iter().flatten().fold(0.0f64, |a, v| a.max(*v));
        let n = self.n;
        let (y, v) = (&self.warm.y, &self.warm.v);
        let guess = |id: usize| {
            if id < n {
                let y = y[id][0];
                if !big(ymax, y) {
                    Side::Free
                } else if y > 0.0 {
                    Side::Upper
                } else {
                    Side::Lower
                }
            } else {
                let [up, low] = v[id - n];
                match (big(vmax, up), big(vmax, low)) {
                    (true, _) if up >= low => Side::Upper,
                    (_, true) => Side::Lower,
                    (true, false) => Side::Upper,
                    _ => Side::Free,
                }
            }
        };
        let prob = Problem {
            p: &self.base,
            c: &self.ws.c,
            stages: match &self.stages {
                super::StageSet::Interval(b) => b,
                super::StageSet::Disc(_) => &[],
            },
            a0,
            row_lo: lo,
            row_hi: hi,
            stage_tol,
            row_tol,
        };
        let axis = &self.axes[0];
        let work = &mut self.ws.p_work;
        let result = set.solve(&prob, (guess, self.tuning.max_kkt_solves), |x, out| {
            axis.apply_hessian_strided(x, 1, 0, 2.0, 0, work, out)
        });
        let done = result.is_ok();
        self.ws.active_set_work = set.work();
        self.ws.factorisations = set.work().solves;
        if done {
            self.ws.x.copy_from_slice(set.x());
            for f in 0..n {
                self.warm.y[f] = [set.stage_multiplier(f), 0.0];
            }
            for r in 0..self.rows.len() {
                let lam = set.row_multiplier(r);
                self.warm.v[r] = [lam.max(0.0), (-lam).max(0.0)];
            }
            self.ws.px_current = false;
        }
        self.polish = Some(set);
        Ok(done)
    }
}
