//! The augmented Lagrangian's line search (module docs of [`super`]):
//! the full Newton step where it passes Armijo's test, else L's minimiser
//! along the direction; the full step evaluated by the gradient's own
//! stage pass so that the next gradient can take it.

use super::super::cascade::SolverFault;
use super::lagrangian::Vector;
use super::lagrangian::{centred, disc_excess, interval_excess};
use super::{ARMIJO, BandedAlm, StageSet};
use crate::ControlError;

impl BandedAlm {
    /// The full step along d from x (u, hx, g current) where it passes
    /// Armijo's test, else L's minimiser along d on (0, 1)
    /// ([`BandedAlm::exact_step`]); moves x. Returns whether the full step
    /// was taken (Armijo's), and the step taken (1: full).
    pub(super) fn line_search(
        &mut self,
        decrement: f64,
        lo: &[f64],
        hi: &[f64],
    ) -> Result<(bool, f64), ControlError> {
        self.apply_p(Vector::D);
        // gᵀd = −(Newton decrement).
        let slope = -decrement;
        if slope.is_nan() || slope >= 0.0 {
            // Not a descent direction: the factor is too inexact to go on.
            return Err(SolverFault::NoDescent { slope }.into());
        }
        // Quadratic part along d: α·(Px + c)·d + ½α²·dᵀPd (on the window:
        // the eliminated head's (Px + c) and (P·d) are 0).
        let (mut lin, mut curv) = (0.0, 0.0);
        let j0 = self.window_unknown();
        let window = self.ws.px[j0..]
            .iter()
            .zip(&self.ws.c[j0..])
            .zip(&self.ws.d[j0..])
            .zip(&self.ws.pd[j0..]);
        for (((p, c), d), pd) in window {
            lin += (p + c) * d;
            curv += pd * d;
        }
        Self::accelerations(
            self.k,
            self.inv_dt2,
            &self.ws.d,
            &mut self.ws.du,
            self.ws.window,
        );
        self.row_products(super::lagrangian::Vector::D);
        let base = self.ws.penalty_value;
        let (full, done) = self.full_step_terms(lo, hi);
        if lin + 0.5 * curv + full <= base + ARMIJO * slope {
            self.step(1.0);
            self.accept_full_step(done);
            return Ok((true, 1.0));
        }
        // L along d is convex (piecewise quadratic for intervals): its
        // minimiser on (0, 1) where the full step fails Armijo.
        let alpha = self.exact_step(lin, curv, slope, lo, hi);
        self.step(alpha);
        Ok((false, alpha))
    }

    /// After the full step: its accelerations (`u_trial`) become u, and
    /// the next gradient takes its stage pass (`done`: the largest `‖y' −
    /// y‖²` and the stages' penalty; `y_next`, `jac`, `active` set by
    /// [`BandedAlm::full_step_terms`]).
    fn accept_full_step(&mut self, done: (f64, f64)) {
        std::mem::swap(&mut self.ws.u, &mut self.ws.u_trial);
        self.ws.full_step = Some(done);
    }

    /// `x += α·d`, and `P·x` with it from `P·d` (both by differencing,
    /// so the sum keeps their accuracy; on the window only, the head's
    /// P·d being 0).
    fn step(&mut self, alpha: f64) {
        self.move_x(alpha);
        let j0 = self.window_unknown();
        for (p, pd) in self.ws.px[j0..].iter_mut().zip(&self.ws.pd[j0..]) {
            *p += alpha * pd;
        }
    }
}

/// Iterations of the exact line search's root finding.
const EXACT_ITERATIONS: usize = 12;

impl BandedAlm {
    /// The minimiser on (0, 1) of L along d (convex, its derivative
    /// `lin + α·curv + Σ y'_f(α)·du_f + Σ (v'_up(α) − v'_lo(α))·hd_r`
    /// increasing: piecewise linear for intervals, smooth between the
    /// kinks for discs), by Newton's method on the derivative kept inside
    /// the bracket `[0, 1]` (bisection where it leaves it), to 1e-3 of
    /// the slope at 0.
    fn exact_step(&self, lin: f64, curv: f64, slope: f64, lo: &[f64], hi: &[f64]) -> f64 {
        let (mut a_lo, mut a_hi) = (0.0, 1.0);
        let mut alpha = 1.0;
        let (mut d1, mut d2) = self.derivatives(alpha, lin, curv, lo, hi);
        for _ in 0..EXACT_ITERATIONS {
            if d1.abs() <= 1e-3 * slope.abs() {
                break;
            }
            if d1 > 0.0 {
                a_hi = alpha;
            } else {
                a_lo = alpha;
            }
            let newton = alpha - d1 / d2;
            alpha = if d2 > 0.0 && newton > a_lo && newton < a_hi {
                newton
            } else {
                0.5 * (a_lo + a_hi)
            };
            (d1, d2) = self.derivatives(alpha, lin, curv, lo, hi);
        }
        alpha.max(1e-6)
    }

    /// L's first and second derivatives along d at `x + α·d`.
    fn derivatives(&self, alpha: f64, lin: f64, curv: f64, lo: &[f64], hi: &[f64]) -> (f64, f64) {
        let s = self.sigma;
        let inv_s = 1.0 / s;
        let (mut d1, mut d2) = (lin + alpha * curv, curv);
        for f in self.ws.window..self.n {
            let (u, du, y) = (self.ws.u[f], self.ws.du[f], self.warm.y[f]);
            let w = [
                u[0] + alpha * du[0] + y[0] * inv_s,
                u[1] + alpha * du[1] + y[1] * inv_s,
            ];
            let ex = match &self.stages {
                StageSet::Disc(r) => disc_excess(centred(w, self.centre[f]), r[f]),
                StageSet::Interval(b) if self.k == 1 => interval_excess::<1>(w, &b[f]),
                StageSet::Interval(b) => interval_excess::<2>(w, &b[f]),
            };
            if let Some((e, j)) = ex {
                d1 += s * (e[0] * du[0] + e[1] * du[1]);
                let jd = [
                    j[0][0] * du[0] + j[0][1] * du[1],
                    j[1][0] * du[0] + j[1][1] * du[1],
                ];
                d2 += s * (du[0] * jd[0] + du[1] * jd[1]);
            }
        }
        for (r, v) in self.warm.v.iter().enumerate() {
            if !self.row_in_window(r) {
                continue;
            }
            let h = self.ws.hx[r] + alpha * self.ws.hd[r];
            let ss = self.sigma_row(r);
            let rho = self.row_penalty[r];
            for (j, &vj) in v.iter().enumerate() {
                let t = Self::side(j, h, lo[r], hi[r]);
                let vn = self.side_multiplier(r, vj, t);
                let sign = if j == 0 { 1.0 } else { -1.0 };
                d1 += sign * vn * self.ws.hd[r];
                let raw = vj + ss * t;
                if raw > 0.0 && raw < rho {
                    d2 += ss * self.ws.hd[r] * self.ws.hd[r];
                }
            }
        }
        (d1, d2)
    }
}
