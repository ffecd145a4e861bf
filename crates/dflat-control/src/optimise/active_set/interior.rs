//! The working set of a cold solve from a condensed interior point (module
//! docs of [`super`], "Cold starts"): Mehrotra's predictor-corrector on
//! the QP in the outputs p alone, every constraint an interval row on at
//! most five consecutive outputs, so that its Newton matrix
//! `P + Σ (z/s)·w²·aaᵀ` keeps P's band (half-bandwidth 4) and one
//! iteration is a banded Cholesky of n × 4 and two substitutions: a few
//! microseconds at N = 200, against ~110 µs for the stage interior point's
//! KKT system of 3n unknowns and half-bandwidth 14
//! ([`crate::optimise::banded_ip`]).
//!
//! P's condition number (near 1e10: the jerk term at 1/δt⁶) limits what
//! the Newton directions resolve to about six digits, which is why the
//! plan is not taken from here: the iterate names the working set (a
//! constraint whose barrier term `(z/s)·w²` outweighs P's largest
//! diagonal entry is in it) and the active-set method solves that set's
//! KKT system exactly, checks its multipliers' signs and its bounds, and
//! corrects the set where the guess was wrong.
//!
//! In scaled units (`w = √P_max/|a|`, as the KKT system's): each finite
//! side of constraint `lo ≤ a·p ≤ hi` is `ã·p + s = β` (upper: `ã = w·a`,
//! `β = w·hi`; lower: `ã = −w·a`, `β = −w·lo`), slack s ≥ 0 and
//! multiplier z ≥ 0.

use super::super::banded::{BandedCholesky, SymBand};
use super::{ActiveSet, Problem, Side};
use crate::ControlError;

/// Iterations at most; a guess not reached by then is none.
const MAX_ITERATIONS: usize = 40;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// The start's slacks are floored at this fraction of the largest gap
/// (and its multipliers centred on them): on the corner bench at N = 200
/// 1e-2 took 23–34 iterations from rest, 0.3 took 10–21.
const START_FLOOR: f64 = 0.3;
/// The iteration ends when the mean complementarity is below this
/// fraction of the start's and the primal residuals below
/// [`PRIMAL_TOLERANCE`] of their bounds' scale: on the corner bench at
/// N = 200 the active-set method then ends in 3 KKT solves from every
/// first tick (1e-12: 2–3, 3 iterations more; 1e-6: up to 80).
const GAP_REDUCTION: f64 = 1e-8;
/// Primal residual, relative to the largest scaled bound, accepted.
const PRIMAL_TOLERANCE: f64 = 1e-8;
/// A side is in the working set when its barrier term `(z/s)·w²aaᵀ`,
/// relative to P's largest diagonal entry, exceeds this.
const ACTIVE_RATIO: f64 = 1.0;

/// Storage of the condensed interior point (allocated with the active
/// set). Per constraint `id`, its sides at `2·id` (upper) and `2·id + 1`
/// (lower).
#[derive(Debug, Clone)]
pub(super) struct Interior {
    /// The Newton matrix and its factor (half-bandwidth: P's and the
    /// constraints' reach).
    m: SymBand,
    chol: BandedCholesky,
    /// Per side: whether it is finite, β, slack, multiplier, their
    /// inverses, primal residual, complementarity right-hand side and
    /// steps.
    on: Vec<bool>,
    beta: Vec<f64>,
    s: Vec<f64>,
    z: Vec<f64>,
    inv_s: Vec<f64>,
    inv_z: Vec<f64>,
    r: Vec<f64>,
    rc: Vec<f64>,
    ds: Vec<f64>,
    dz: Vec<f64>,
    /// The iterate, its step, the dual residual and P·p.
    p: Vec<f64>,
    dp: Vec<f64>,
    rd: Vec<f64>,
    px: Vec<f64>,
    /// Finite sides.
    sides: usize,
    /// Iterations of the last guess.
    iterations: usize,
}

impl Interior {
    /// Storage for n outputs, `m` constraints and the Newton matrix's
    /// half-bandwidth `band`.
    pub(super) fn new(n: usize, m: usize, band: usize) -> Self {
        let per_side = || vec![0.0; 2 * m];
        Self {
            m: SymBand::zeros(n, band),
            chol: BandedCholesky::new(n, band),
            on: vec![false; 2 * m],
            beta: per_side(),
            s: per_side(),
            z: per_side(),
            inv_s: per_side(),
            inv_z: per_side(),
            r: per_side(),
            rc: per_side(),
            ds: per_side(),
            dz: per_side(),
            p: vec![0.0; n],
            dp: vec![0.0; n],
            rd: vec![0.0; n],
            px: vec![0.0; n],
            sides: 0,
            iterations: 0,
        }
    }

    /// Iterations of the last guess.
    pub(super) fn iterations(&self) -> usize {
        self.iterations
    }

    /// The start from the gaps `s = β − ã·p` held in `s`: floored at
    /// θ = [`START_FLOOR`] of the largest, multipliers `θ²/s` (centred);
    /// returns μ = θ².
    fn start(&mut self) -> f64 {
        let largest = self
            .s
            .iter()
            .zip(&self.on)
            .filter(|(_, on)| **on)
            .fold(0.0f64, |a, (g, _)| a.max(g.abs()));
        let theta = (START_FLOOR * largest).max(1e-12);
        for k in 0..self.s.len() {
            if self.on[k] {
                self.s[k] = self.s[k].max(theta);
                self.z[k] = theta * theta / self.s[k];
            } else {
                self.s[k] = 1.0;
                self.z[k] = 0.0;
            }
        }
        theta * theta
    }

    /// The largest step in (0, 1] that keeps every slack and multiplier
    /// positive, times `fraction`.
    fn step_to_boundary(&self, fraction: f64) -> f64 {
        let mut worst = 1.0f64;
        for k in 0..self.s.len() {
            worst = worst
                .max(-self.ds[k] * self.inv_s[k])
                .max(-self.dz[k] * self.inv_z[k]);
        }
        (fraction / worst).min(1.0)
    }
}

impl ActiveSet {
    /// Sets the working set of a cold solve from the condensed interior
    /// point started at the plan in `x` (module docs); returns false
    /// (nothing set) when it does not converge.
    pub(super) fn interior_guess(&mut self, prob: &Problem<'_>) -> Result<bool, ControlError> {
        let ip = &mut self.interior;
        ip.p.copy_from_slice(&self.x);
        ip.iterations = 0;
        ip.sides = 0;
        let mut beta_scale = 0.0f64;
        for (id, c) in self.cons.iter().enumerate() {
            let v = c.w * c.dot(&ip.p);
            for side in 0..2 {
                let k = 2 * id + side;
                let b = self.bound[id][1 - side];
                ip.on[k] = b.is_finite();
                if ip.on[k] {
                    ip.beta[k] = SIGN[side] * c.w * b;
                    beta_scale = beta_scale.max(ip.beta[k].abs());
                    ip.s[k] = ip.beta[k] - SIGN[side] * v;
                    ip.sides += 1;
                } else {
                    ip.beta[k] = 0.0;
                }
            }
        }
        if ip.sides == 0 {
            return Ok(false);
        }
        let mu0 = ip.start();
        let primal_tol = PRIMAL_TOLERANCE * beta_scale.max(1.0);
        let mut converged = false;
        for it in 0..MAX_ITERATIONS {
            self.interior.iterations = it + 1;
            let (mu, primal) = self.interior_residuals(prob);
            if mu <= GAP_REDUCTION * mu0 && primal <= primal_tol {
                converged = true;
                break;
            }
            if !self.interior_step(prob, mu)? {
                return Ok(false);
            }
        }
        if !converged {
            return Ok(false);
        }
        // The working set: the sides whose barrier outweighs P.
        let ip = &self.interior;
        for id in 0..self.cons.len() {
            let ratio = |k: usize| if ip.on[k] { ip.z[k] * ip.inv_s[k] } else { 0.0 };
            let (u, l) = (ratio(2 * id), ratio(2 * id + 1));
            self.side[id] = if u.max(l) <= ACTIVE_RATIO {
                Side::Free
            } else if u >= l {
                Side::Upper
            } else {
                Side::Lower
            };
            self.lam[id] = 0.0;
        }
        self.changed_from = 0;
        self.kkt.invalidate();
        Ok(true)
    }

    /// The dual residual `rd = P·p + c + Σ w·a·(z_u − z_l)`, the sides'
    /// primal residuals `r = ã·p + s − β` and the inverses of s and z;
    /// returns the mean complementarity and the largest primal residual.
    fn interior_residuals(&mut self, prob: &Problem<'_>) -> (f64, f64) {
        let ip = &mut self.interior;
        prob.p.mul_vec(&ip.p, &mut ip.px);
        for ((rd, px), c) in ip.rd.iter_mut().zip(&ip.px).zip(prob.c) {
            *rd = px + c;
        }
        let (mut gap, mut primal) = (0.0, 0.0f64);
        for (id, c) in self.cons.iter().enumerate() {
            let (u, l) = (2 * id, 2 * id + 1);
            let v = c.w * c.dot(&ip.p);
            let zz = c.w * (ip.z[u] - ip.z[l]);
            for k in 0..c.len {
                ip.rd[c.first + k] += c.coef[k] * zz;
            }
            for (k, sign) in [(u, 1.0), (l, -1.0)] {
                if ip.on[k] {
                    let r = sign * v + ip.s[k] - ip.beta[k];
                    ip.r[k] = r;
                    primal = primal.max(r.abs());
                    gap += ip.s[k] * ip.z[k];
                    ip.inv_s[k] = 1.0 / ip.s[k];
                    ip.inv_z[k] = 1.0 / ip.z[k];
                } else {
                    ip.r[k] = 0.0;
                    ip.inv_s[k] = 0.0;
                    ip.inv_z[k] = 0.0;
                }
            }
        }
        (gap / ip.sides as f64, primal)
    }

    /// One predictor-corrector step from the residuals of
    /// [`ActiveSet::interior_residuals`]; returns false when the Newton
    /// matrix is not positive definite.
    fn interior_step(&mut self, prob: &Problem<'_>, mu: f64) -> Result<bool, ControlError> {
        if self.interior_factor(prob).is_err() {
            return Ok(false);
        }
        // The predictor: rc = −s·z.
        {
            let ip = &mut self.interior;
            for k in 0..ip.s.len() {
                ip.rc[k] = -ip.s[k] * ip.z[k];
            }
        }
        self.interior_direction()?;
        let ip = &mut self.interior;
        let alpha = ip.step_to_boundary(1.0);
        let mut mu_aff = 0.0;
        for k in 0..ip.s.len() {
            mu_aff += (ip.s[k] + alpha * ip.ds[k]) * (ip.z[k] + alpha * ip.dz[k]);
        }
        mu_aff /= ip.sides as f64;
        let sigma = (mu_aff / mu).clamp(0.0, 1.0).powi(3);
        // The corrector: rc = σμ − s·z − Δs_aff·Δz_aff.
        for k in 0..ip.s.len() {
            ip.rc[k] = if ip.on[k] {
                sigma * mu - ip.s[k] * ip.z[k] - ip.ds[k] * ip.dz[k]
            } else {
                0.0
            };
        }
        self.interior_direction()?;
        let ip = &mut self.interior;
        let alpha = ip.step_to_boundary(STEP_FRACTION);
        for (p, dp) in ip.p.iter_mut().zip(&ip.dp) {
            *p += alpha * dp;
        }
        for k in 0..ip.s.len() {
            if ip.on[k] {
                ip.s[k] += alpha * ip.ds[k];
                ip.z[k] += alpha * ip.dz[k];
            }
        }
        Ok(true)
    }

    /// Assembles and factors `P + Σ w²·(z_u/s_u + z_l/s_l)·aaᵀ`.
    fn interior_factor(&mut self, prob: &Problem<'_>) -> Result<(), ControlError> {
        let ip = &mut self.interior;
        let (pw, mw) = (prob.p.bandwidth() + 1, ip.m.bandwidth() + 1);
        let src = prob.p.lower();
        let dst = ip.m.lower_mut();
        if pw == mw {
            dst.copy_from_slice(src);
        } else {
            dst.fill(0.0);
            for i in 0..self.n {
                dst[i * mw..i * mw + pw].copy_from_slice(&src[i * pw..(i + 1) * pw]);
            }
        }
        for (id, c) in self.cons.iter().enumerate() {
            let (u, l) = (2 * id, 2 * id + 1);
            let d = (ip.z[u] * ip.inv_s[u] + ip.z[l] * ip.inv_s[l]) * c.w * c.w;
            for k1 in 0..c.len {
                let row = (c.first + k1) * mw;
                let a1 = d * c.coef[k1];
                for k2 in 0..=k1 {
                    dst[row + k1 - k2] += a1 * c.coef[k2];
                }
            }
        }
        ip.chol.factor(&ip.m)
    }

    /// The Newton direction (dp, ds, dz) for the held factor, the
    /// residuals and the complementarity right-hand side `rc`:
    /// `dp = M⁻¹(−rd − Σ ã·(rc + z·r)/s)`, `ds = −r − ã·dp`,
    /// `dz = (rc + z·(r + ã·dp))/s`.
    fn interior_direction(&mut self) -> Result<(), ControlError> {
        let ip = &mut self.interior;
        for (d, r) in ip.dp.iter_mut().zip(&ip.rd) {
            *d = -r;
        }
        for (id, c) in self.cons.iter().enumerate() {
            let (u, l) = (2 * id, 2 * id + 1);
            let t = (ip.rc[u] + ip.z[u] * ip.r[u]) * ip.inv_s[u]
                - (ip.rc[l] + ip.z[l] * ip.r[l]) * ip.inv_s[l];
            let t = c.w * t;
            for k in 0..c.len {
                ip.dp[c.first + k] -= c.coef[k] * t;
            }
        }
        ip.chol.solve_in_place(&mut ip.dp)?;
        for (id, c) in self.cons.iter().enumerate() {
            let t = c.w * c.dot(&ip.dp);
            for (k, a_dp) in [(2 * id, t), (2 * id + 1, -t)] {
                if ip.on[k] {
                    ip.ds[k] = -ip.r[k] - a_dp;
                    ip.dz[k] = (ip.rc[k] + ip.z[k] * (ip.r[k] + a_dp)) * ip.inv_s[k];
                } else {
                    ip.ds[k] = 0.0;
                    ip.dz[k] = 0.0;
                }
            }
        }
        Ok(())
    }
}

/// Upper and lower side's sign on `w·a`.
const SIGN: [f64; 2] = [1.0, -1.0];
