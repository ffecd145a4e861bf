//! The augmented Lagrangian's line search (module docs of [`super`]):
//! Armijo backtracking on L along the Newton direction, the full step
//! evaluated by the gradient's own stage pass so that the next gradient
//! can take it.

use super::lagrangian::Vector;
use super::{ARMIJO, BandedAlm, MAX_HALVINGS};
use crate::ControlError;

impl BandedAlm {
    /// Armijo backtracking on L along d from x (u, hx, g current); moves x.
    /// Returns whether the full step was taken.
    pub(super) fn line_search(
        &mut self,
        decrement: f64,
        lo: &[f64],
        hi: &[f64],
    ) -> Result<bool, ControlError> {
        self.apply_p(Vector::D);
        // gᵀd = −(Newton decrement).
        let slope = -decrement;
        if slope.is_nan() || slope >= 0.0 {
            // Not a descent direction: the factor is too inexact to go on.
            return Err(ControlError::Solver(format!(
                "ALM: no descent (slope {slope:.1e})"
            )));
        }
        // Quadratic part along d: α·(Px + c)·d + ½α²·dᵀPd (on the window:
        // the eliminated head's (Px + c) and (P·d) are 0).
        let (mut lin, mut curv) = (0.0, 0.0);
        let j0 = self.window_unknown();
        let window = self.px[j0..]
            .iter()
            .zip(&self.c[j0..])
            .zip(&self.d[j0..])
            .zip(&self.pd[j0..]);
        for (((p, c), d), pd) in window {
            lin += (p + c) * d;
            curv += pd * d;
        }
        Self::accelerations(self.k, self.inv_dt2, &self.d, &mut self.du, self.window);
        for r in 0..self.rows.len() {
            if self.row_in_window(r) {
                self.hd[r] = self.rows[r].dot(&self.d);
            }
        }
        let base = self.penalty_value;
        let (full, done) = self.full_step_terms(lo, hi);
        let mut alpha = 1.0;
        for _ in 0..MAX_HALVINGS {
            let penalty = if alpha == 1.0 {
                full
            } else {
                self.penalty_terms(alpha, lo, hi)
            };
            let value = alpha * lin + 0.5 * alpha * alpha * curv + penalty;
            if value <= base + ARMIJO * alpha * slope {
                self.step(alpha);
                if alpha == 1.0 {
                    self.accept_full_step(done);
                }
                return Ok(alpha == 1.0);
            }
            alpha *= 0.5;
        }
        // No decrease measurable: the merit is flat to rounding here, where
        // the full Newton step is the best guess.
        self.step(1.0);
        self.accept_full_step(done);
        Ok(true)
    }

    /// After the full step: its accelerations (`u_trial`) become u, and
    /// the next gradient takes its stage pass (`done`: the largest `‖y' −
    /// y‖²` and the stages' penalty; `y_next`, `jac`, `active` set by
    /// [`BandedAlm::full_step_terms`]).
    fn accept_full_step(&mut self, done: (f64, f64)) {
        std::mem::swap(&mut self.u, &mut self.u_trial);
        self.full_step = Some(done);
    }

    /// `x += α·d`, and `P·x` with it from `P·d` (both by differencing,
    /// so the sum keeps their accuracy; on the window only, the head's
    /// P·d being 0).
    fn step(&mut self, alpha: f64) {
        self.move_x(alpha);
        let j0 = self.window_unknown();
        for (p, pd) in self.px[j0..].iter_mut().zip(&self.pd[j0..]) {
            *p += alpha * pd;
        }
    }
}
