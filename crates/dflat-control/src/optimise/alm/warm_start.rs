//! The augmented Lagrangian's multipliers between solves (module docs of
//! [`super`], "Warm start"): forgotten, set from another method's, shifted
//! (and extrapolated) one stage on, or aged over a tick without a solve.
//!
//! **The first row's multiplier.** A row block's first row is the one on
//! the window and the sent command (for the tilt rate: the first stage's
//! change from the command sent). Where a chain of tilt-rate rows starts
//! there, it still starts there a tick on, and that first row's
//! multiplier carries the push of the whole chain: on the corner bench's
//! restarted ticks it was ~1e2 as shifted in from the second row and
//! ~2e4 at the optimum, and the interior point's restart spent its first
//! two to four iterations on steps of 0.7–9 % finding it. So the shift
//! leaves each block's first multiplier where it was. At N = 200 the
//! restart's iterations went from a median of 10 to 9 (N = 100 and 400:
//! 10 to 7), the box with the tilt rate's KKT solves per axis 2.68 →
//! 2.54, the tilt rate alone's 2.63 → 2.40 (docs/performance-log.md,
//! "The first row's multiplier").

use super::{BandedAlm, StageSet};

impl BandedAlm {
    /// Forgets the multipliers and σ (a cold start).
    pub fn reset_multipliers(&mut self) {
        self.warm.y_last_valid = false;
        self.warm.y.iter_mut().for_each(|y| *y = [0.0; 2]);
        self.warm.v.iter_mut().for_each(|v| *v = [0.0; 2]);
        self.sigma = self.tuning.sigma;
    }

    /// The stage multiplier y_f held (after a solve: its solution's),
    /// signed per axis, cost per m/s².
    pub(crate) fn stage_multiplier(&self, f: usize) -> [f64; 2] {
        self.warm.y[f]
    }

    /// The rows' multipliers `[upper, lower]` held (after a solve: its
    /// solution's), in row order.
    pub(crate) fn row_multipliers(&self) -> &[[f64; 2]] {
        &self.warm.v
    }

    /// Sets the multipliers from another method's: the stage multipliers
    /// per stage (`stage(f)`, signed per axis, cost per m/s²) and the rows'
    /// `[upper, lower]` in row order; σ from its initial value.
    pub fn set_multipliers(&mut self, stage: impl Fn(usize) -> [f64; 2], rows: &[[f64; 2]]) {
        self.warm.y_last_valid = false;
        self.sigma = self.tuning.sigma;
        for (f, y) in self.warm.y.iter_mut().enumerate() {
            *y = stage(f);
        }
        for (v, r) in self.warm.v.iter_mut().zip(rows) {
            *v = [r[0].max(0.0), r[1].max(0.0)];
        }
    }

    /// Keeps, of the multipliers set from another method's solution `p`
    /// (one axis, the deviations; a_0 and the rows' bounds this tick's),
    /// those of the constraints that `p` holds at a bound (within 1e-7 of
    /// the bound's scale): an interior point's multipliers are positive on
    /// every constraint, small on the inactive ones, and as the active-set
    /// method's start they name a set far from the optimum.
    pub fn keep_active_multipliers(&mut self, p: &[f64], a0: f64, lo: &[f64], hi: &[f64]) {
        if self.k != 1 || p.len() != self.n {
            return;
        }
        let near = |v: f64, b: f64| (v - b).abs() <= 1e-7 * (1.0 + b.abs());
        if let StageSet::Interval(b) = &self.stages {
            Self::accelerations(1, self.inv_dt2, p, &mut self.ws.du, 0);
            for ((y, du), b) in self.warm.y.iter_mut().zip(&self.ws.du).zip(b) {
                let a = du[0] + a0;
                let [l, h] = b[0];
                if !((y[0] > 0.0 && near(a, h)) || (y[0] < 0.0 && near(a, l))) {
                    *y = [0.0; 2];
                }
            }
        }
        for (r, row) in self.rows.iter().enumerate() {
            let h = row.dot(p);
            let [up, low] = self.warm.v[r];
            self.warm.v[r] = [
                if near(h, hi[r]) { up } else { 0.0 },
                if near(h, lo[r]) { low } else { 0.0 },
            ];
        }
    }

    /// Moves the multipliers one stage earlier (the last stage keeps its
    /// own, and so does each row block's first row) and restarts σ from
    /// its initial value: the warm start of the
    /// next tick. (A σ grown on a hard tick and kept makes the next ticks'
    /// subproblems stiff: their semismooth Newton then zigzags.) When the
    /// last tick was warm too, each stage multiplier is extrapolated
    /// linearly along the ticks, `y_f ← 2·y^k_{f+1} − y^{k−1}_{f+2}` (the
    /// same instant of the plan in the last two solutions), where both are
    /// non-zero and no axis changes sign; else it is the shifted one. On
    /// the corner bench at N = 200 the warm cone then takes 5.75 Newton
    /// steps and 3.30 factorisations per solve instead of 6.43 and 3.87.
    pub fn shift(&mut self) {
        let extrapolate = self.warm.y_last_valid;
        // y_older ← last tick's solution, y_last ← this one's (unshifted).
        std::mem::swap(&mut self.warm.y_last, &mut self.warm.y_older);
        self.warm.y_last.copy_from_slice(&self.warm.y);
        self.shift_multipliers(false);
        if extrapolate {
            let n = self.n;
            for f in 0..n.saturating_sub(2) {
                let (a, b) = (self.warm.y_last[f + 1], self.warm.y_older[f + 2]);
                if a != [0.0; 2] && b != [0.0; 2] {
                    let p = [2.0 * a[0] - b[0], 2.0 * a[1] - b[1]];
                    if p[0] * a[0] >= 0.0 && p[1] * a[1] >= 0.0 {
                        self.warm.y[f] = p;
                    }
                }
            }
        }
        self.warm.y_last_valid = true;
    }

    /// Moves the multipliers one stage earlier with nothing entering at the
    /// end: a tick that did not solve, so that the first tick of the next
    /// constrained burst starts from the last burst's multipliers where
    /// they still apply.
    pub fn age(&mut self) {
        self.warm.y_last_valid = false;
        self.shift_multipliers(true);
    }

    fn shift_multipliers(&mut self, clear_last: bool) {
        self.sigma = self.tuning.sigma;
        let n = self.n;
        if n >= 2 {
            self.warm.y.copy_within(1..n, 0);
        }
        if clear_last && n >= 1 {
            self.warm.y[n - 1] = [0.0; 2];
        }
        for r in &self.blocks {
            if r.len() >= 2 {
                // The block's first row keeps its own multiplier (module
                // docs: "The first row's multiplier").
                let first = self.warm.v[r.start];
                self.warm.v.copy_within(r.start + 1..r.end, r.start);
                self.warm.v[r.start] = first;
            }
            if clear_last && !r.is_empty() {
                self.warm.v[r.end - 1] = [0.0; 2];
            }
        }
    }
}
