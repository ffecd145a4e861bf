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
use super::kkt::Con;
use super::{ActiveSet, Problem, Side};
use crate::ControlError;

/// Iterations at most; a guess not reached by then is none.
const MAX_ITERATIONS: usize = 40;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// The start's slacks are floored at this fraction of the largest gap
/// (and its multipliers centred on them): on the corner bench at N = 200
/// 1e-2 took 23–34 iterations from rest, 0.3 took 10–21; 0.3–0.6 give
/// the same times within the machine's noise.
const START_FLOOR: f64 = 0.5;
/// The iteration ends when the mean complementarity is below this
/// fraction of the start's and the primal residuals below
/// [`PRIMAL_TOLERANCE`] of their bounds' scale: on the corner bench at
/// N = 200 the active-set method then ends in 3 KKT solves from every
/// first tick (1e-12: 2–3, 3 iterations more; 1e-6: up to 80).
const GAP_REDUCTION: f64 = 1e-8;
/// The reduction the iteration is carried on to when the active-set
/// method does not end from the first guess within `COLD_SOLVES`
/// ([`ActiveSet::interior_tighten`]): near a degenerate vertex (the
/// command's ramp up and down from the horizon's start meeting the tilt
/// box) the sides at 1e-8 name an ill-conditioned set, at 1e-13 the
/// optimum's (on the learned bench's tick 7: 40 KKT solves without an
/// end, against 17 more iterations and one KKT solve).
const TIGHT_GAP_REDUCTION: f64 = 1e-13;
/// Primal residual, relative to the largest scaled bound, accepted.
const PRIMAL_TOLERANCE: f64 = 1e-8;
/// A side is in the working set when its barrier term `(z/s)·w²aaᵀ`,
/// relative to P's largest diagonal entry, exceeds this.
const ACTIVE_RATIO: f64 = 1.0;
/// Entries past the last output in the iterate's vectors: every
/// constraint is read as five coefficients (zero past its own), so the
/// loops have a fixed length.
const PAD: usize = 4;

/// Per constraint, a value for each of its two sides (upper, lower).
type Pairs = Vec<[f64; 2]>;

/// Upper and lower side's sign on `w·a`.
const SIGN: [f64; 2] = [1.0, -1.0];

/// Storage of the condensed interior point (allocated with the active
/// set).
#[derive(Debug, Clone)]
pub(super) struct Interior {
    /// The Newton matrix and its factor (half-bandwidth: P's and the
    /// constraints' reach).
    m: SymBand,
    chol: BandedCholesky,
    /// Per constraint and side (upper, lower; each vector apart, so that a
    /// pass reads only what it uses): 1 where the bound is finite, else 0
    /// (a side off has every term multiplied by it: no branches); β (the
    /// scaled bound), slack, multiplier, their inverses (0 where off),
    /// primal residual, complementarity right-hand side, steps.
    on: Pairs,
    beta: Pairs,
    s: Pairs,
    z: Pairs,
    inv_s: Pairs,
    inv_z: Pairs,
    r: Pairs,
    rc: Pairs,
    ds: Pairs,
    dz: Pairs,
    /// The iterate and its step (n + [`PAD`], the padding always 0), the
    /// dual residual and P·p (n).
    p: Vec<f64>,
    dp: Vec<f64>,
    rd: Vec<f64>,
    px: Vec<f64>,
    /// Per constraint, the scalar `Aᵀt` multiplies its row by.
    t: Vec<f64>,
    /// The constraints as stencils: families of n, the constraint f of
    /// each ending at output f (stage intervals, tilt-rate and speed rows,
    /// as `ActiveSet::new` builds them). Entry `(family·5 + d)·n + f` is
    /// `w·a` of that constraint on output `f − 4 + d` (0 outside it); `Aᵀt`
    /// is then five shifted vector multiply-adds per family into `pad`
    /// (n + 4, its first four entries before output 0; scattering each
    /// constraint's five entries instead makes overlapping vector stores,
    /// and their loads stall). Empty when the constraints are not so
    /// aligned: there is then no guess.
    stencil: Vec<f64>,
    pad: Vec<f64>,
    /// Finite sides.
    finite: usize,
    /// The start's mean complementarity and the primal residuals'
    /// tolerance of the last guess.
    mu0: f64,
    primal_tol: f64,
}

impl Interior {
    /// Storage for n outputs, the constraints and the Newton matrix's
    /// half-bandwidth `band`.
    pub(super) fn new(n: usize, cons: &[Con], band: usize) -> Self {
        let m = cons.len();
        let aligned = n > 0
            && m.is_multiple_of(n)
            && cons.iter().enumerate().all(|(id, c)| c.last() == id % n);
        let mut stencil = Vec::new();
        if aligned {
            stencil = vec![0.0; 5 * m];
            for (id, c) in cons.iter().enumerate() {
                let (family, f) = (id / n, id % n);
                for k in 0..c.len {
                    let d = k + 5 - c.len;
                    stencil[(family * 5 + d) * n + f] = c.w * c.coef[k];
                }
            }
        }
        Self {
            m: SymBand::zeros(n, band),
            chol: BandedCholesky::new(n, band),
            on: vec![[0.0; 2]; m],
            beta: vec![[0.0; 2]; m],
            s: vec![[0.0; 2]; m],
            z: vec![[0.0; 2]; m],
            inv_s: vec![[0.0; 2]; m],
            inv_z: vec![[0.0; 2]; m],
            r: vec![[0.0; 2]; m],
            rc: vec![[0.0; 2]; m],
            ds: vec![[0.0; 2]; m],
            dz: vec![[0.0; 2]; m],
            p: vec![0.0; n + PAD],
            dp: vec![0.0; n + PAD],
            rd: vec![0.0; n],
            px: vec![0.0; n],
            t: vec![0.0; m],
            stencil,
            pad: vec![0.0; n + 4],
            finite: 0,
            mu0: 0.0,
            primal_tol: 0.0,
        }
    }

    /// The start from the gaps `s = β − ã·p` held in `s`: floored at
    /// θ = [`START_FLOOR`] of the largest, multipliers `θ²/s` (centred);
    /// returns μ = θ².
    fn start(&mut self) -> f64 {
        let largest = self.s.iter().zip(&self.on).fold(0.0f64, |a, (s, on)| {
            a.max(on[0] * s[0].abs()).max(on[1] * s[1].abs())
        });
        let theta = (START_FLOOR * largest).max(1e-12);
        for ((s, z), on) in self.s.iter_mut().zip(&mut self.z).zip(&self.on) {
            for j in 0..2 {
                s[j] = if on[j] > 0.0 { s[j].max(theta) } else { 1.0 };
                z[j] = on[j] * theta * theta / s[j];
            }
        }
        theta * theta
    }

    /// The largest step in (0, 1] that keeps every slack and multiplier
    /// positive, times `fraction`.
    fn step_to_boundary(&self, fraction: f64) -> f64 {
        let mut worst = [1.0f64; 2];
        for (((ds, dz), inv_s), inv_z) in self
            .ds
            .iter()
            .zip(&self.dz)
            .zip(&self.inv_s)
            .zip(&self.inv_z)
        {
            for j in 0..2 {
                worst[j] = fmax(fmax(worst[j], -ds[j] * inv_s[j]), -dz[j] * inv_z[j]);
            }
        }
        (fraction / worst[0].max(worst[1])).min(1.0)
    }
}

/// `out_f += Σ_id w·a_{id,f}·t_id` for every output f < n (`Aᵀt`) by the
/// stencils ([`Interior::stencil`]), `pad` (n + 4) the scratch.
fn add_transpose(stencil: &[f64], t: &[f64], pad: &mut [f64], out: &mut [f64]) {
    let n = pad.len() - 4;
    pad.fill(0.0);
    for (family, t) in t.chunks_exact(n).enumerate() {
        for d in 0..5 {
            let cd = &stencil[(family * 5 + d) * n..(family * 5 + d + 1) * n];
            for ((o, c), t) in pad[d..d + n].iter_mut().zip(cd).zip(t) {
                *o += c * t;
            }
        }
    }
    for (o, p) in out[..n].iter_mut().zip(&pad[4..]) {
        *o += p;
    }
}

/// The larger of a and b, for finite values (one `maxsd`: `f64::max`'s
/// NaN handling costs three instructions on a dependency chain).
#[inline(always)]
fn fmax(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// `a·p` over a constraint's five coefficients (p padded).
#[inline(always)]
fn dot5(c: &Con, p: &[f64]) -> f64 {
    let p = &p[c.first..c.first + 5];
    c.coef[0] * p[0] + c.coef[1] * p[1] + c.coef[2] * p[2] + c.coef[3] * p[3] + c.coef[4] * p[4]
}

impl ActiveSet {
    /// Sets the working set of a cold solve from the condensed interior
    /// point started at the plan in `x` (module docs); returns false
    /// (nothing set) when it does not converge.
    pub(super) fn interior_guess(&mut self, prob: &Problem<'_>) -> Result<bool, ControlError> {
        let ip = &mut self.interior;
        if ip.stencil.is_empty() {
            return Ok(false);
        }
        ip.p[..self.n].copy_from_slice(&self.x);
        ip.finite = 0;
        let mut beta_scale = 0.0f64;
        for (id, (c, bound)) in self.cons.iter().zip(&self.bound).enumerate() {
            let v = c.w * dot5(c, &ip.p);
            // The upper side holds w·a·p ≤ w·hi, the lower −w·a·p ≤ −w·lo.
            for j in 0..2 {
                let b = bound[1 - j];
                if b.is_finite() {
                    ip.on[id][j] = 1.0;
                    ip.beta[id][j] = SIGN[j] * c.w * b;
                    beta_scale = beta_scale.max(ip.beta[id][j].abs());
                    ip.s[id][j] = ip.beta[id][j] - SIGN[j] * v;
                    ip.finite += 1;
                } else {
                    ip.on[id][j] = 0.0;
                    ip.beta[id][j] = 0.0;
                }
            }
        }
        if ip.finite == 0 {
            return Ok(false);
        }
        ip.mu0 = ip.start();
        ip.primal_tol = PRIMAL_TOLERANCE * beta_scale.max(1.0);
        self.interior_iterate(prob, GAP_REDUCTION)
    }

    /// Sets the working set again from the condensed interior point of the
    /// last [`ActiveSet::interior_guess`], carried on from where it stopped
    /// to [`TIGHT_GAP_REDUCTION`]; returns false (nothing set) when it
    /// does not converge.
    pub(super) fn interior_tighten(&mut self, prob: &Problem<'_>) -> Result<bool, ControlError> {
        if self.interior.stencil.is_empty() || self.interior.finite == 0 {
            return Ok(false);
        }
        self.interior_iterate(prob, TIGHT_GAP_REDUCTION)
    }

    /// Iterates the condensed interior point until its mean
    /// complementarity is below `gap` of the start's (and its primal
    /// residuals within tolerance), then sets the working set from it;
    /// returns false (nothing set) when it does not converge within
    /// [`MAX_ITERATIONS`].
    fn interior_iterate(&mut self, prob: &Problem<'_>, gap: f64) -> Result<bool, ControlError> {
        let (mu0, primal_tol) = (self.interior.mu0, self.interior.primal_tol);
        let mut converged = false;
        for _ in 0..MAX_ITERATIONS {
            self.work.interior += 1;
            let (mu, primal) = self.interior_residuals(prob);
            if !(mu.is_finite() && primal.is_finite()) {
                // Rounding took a slack or multiplier to 0: no guess.
                return Ok(false);
            }
            if mu <= gap * mu0 && primal <= primal_tol {
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
        for (id, (z, inv_s)) in ip.z.iter().zip(&ip.inv_s).enumerate() {
            let (u, l) = (z[0] * inv_s[0], z[1] * inv_s[1]);
            self.side[id] = if u.max(l) <= ACTIVE_RATIO {
                Side::Free
            } else if u >= l {
                Side::Upper
            } else {
                Side::Lower
            };
            self.lam[id] = 0.0;
        }
        self.set_replaced();
        Ok(true)
    }

    /// The dual residual `rd = P·p + c + Σ w·a·(z_u − z_l)`, the sides'
    /// primal residuals `r = ã·p + s − β` and the inverses of s and z;
    /// returns the mean complementarity and the largest primal residual.
    fn interior_residuals(&mut self, prob: &Problem<'_>) -> (f64, f64) {
        let n = self.n;
        let ip = &mut self.interior;
        prob.p.mul_vec(&ip.p[..n], &mut ip.px);
        for ((rd, px), c) in ip.rd.iter_mut().zip(&ip.px).zip(prob.c) {
            *rd = px + c;
        }
        let (mut gap, mut primal) = ([0.0; 2], [0.0f64; 2]);
        let sides = ip.s.iter().zip(&ip.z).zip(&ip.on).zip(&ip.beta);
        let out = ip.r.iter_mut().zip(&mut ip.inv_s).zip(&mut ip.inv_z);
        for (((c, t), (((s, z), on), beta)), ((r, inv_s), inv_z)) in
            self.cons.iter().zip(&mut ip.t).zip(sides).zip(out)
        {
            let v = c.w * dot5(c, &ip.p);
            *t = z[0] - z[1];
            for j in 0..2 {
                r[j] = on[j] * (SIGN[j] * v + s[j] - beta[j]);
                primal[j] = fmax(primal[j], r[j].abs());
                gap[j] += s[j] * z[j];
                inv_s[j] = on[j] / s[j];
                inv_z[j] = on[j] / (z[j] + (1.0 - on[j]));
            }
        }
        add_transpose(&ip.stencil, &ip.t, &mut ip.pad, &mut ip.rd);
        (
            (gap[0] + gap[1]) / ip.finite as f64,
            primal[0].max(primal[1]),
        )
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
            for ((rc, s), z) in ip.rc.iter_mut().zip(&ip.s).zip(&ip.z) {
                for j in 0..2 {
                    rc[j] = -s[j] * z[j];
                }
            }
        }
        self.interior_direction()?;
        let ip = &mut self.interior;
        let alpha = ip.step_to_boundary(1.0);
        let mut mu_aff = [0.0; 2];
        for (((s, z), ds), dz) in ip.s.iter().zip(&ip.z).zip(&ip.ds).zip(&ip.dz) {
            for j in 0..2 {
                mu_aff[j] += (s[j] + alpha * ds[j]) * (z[j] + alpha * dz[j]);
            }
        }
        let mu_aff = (mu_aff[0] + mu_aff[1]) / ip.finite as f64;
        let sigma = (mu_aff / mu).clamp(0.0, 1.0).powi(3);
        // The corrector: rc = σμ − s·z − Δs_aff·Δz_aff.
        let sides = ip.s.iter().zip(&ip.z).zip(&ip.ds).zip(&ip.dz);
        for ((rc, on), (((s, z), ds), dz)) in ip.rc.iter_mut().zip(&ip.on).zip(sides) {
            for j in 0..2 {
                rc[j] = on[j] * (sigma * mu - s[j] * z[j] - ds[j] * dz[j]);
            }
        }
        self.interior_direction()?;
        let ip = &mut self.interior;
        let alpha = ip.step_to_boundary(STEP_FRACTION);
        for (p, dp) in ip.p.iter_mut().zip(&ip.dp) {
            *p += alpha * dp;
        }
        for (s, ds) in ip.s.iter_mut().zip(&ip.ds) {
            for j in 0..2 {
                s[j] += alpha * ds[j];
            }
        }
        for (z, dz) in ip.z.iter_mut().zip(&ip.dz) {
            for j in 0..2 {
                z[j] += alpha * dz[j];
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
        for ((c, z), inv_s) in self.cons.iter().zip(&ip.z).zip(&ip.inv_s) {
            let d = (z[0] * inv_s[0] + z[1] * inv_s[1]) * c.w * c.w;
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
        let n = self.n;
        let ip = &mut self.interior;
        for (d, r) in ip.dp.iter_mut().zip(&ip.rd) {
            *d = -r;
        }
        let sides = ip.rc.iter().zip(&ip.z).zip(&ip.r).zip(&ip.inv_s);
        for (t, (((rc, z), r), inv_s)) in ip.t.iter_mut().zip(sides) {
            *t = (rc[1] + z[1] * r[1]) * inv_s[1] - (rc[0] + z[0] * r[0]) * inv_s[0];
        }
        add_transpose(&ip.stencil, &ip.t, &mut ip.pad, &mut ip.dp);
        ip.chol.solve_in_place(&mut ip.dp[..n])?;
        let sides = ip
            .on
            .iter()
            .zip(&ip.r)
            .zip(&ip.rc)
            .zip(&ip.z)
            .zip(&ip.inv_s);
        let out = ip.ds.iter_mut().zip(&mut ip.dz);
        for ((c, ((((on, r), rc), z), inv_s)), (ds, dz)) in self.cons.iter().zip(sides).zip(out) {
            let t = c.w * dot5(c, &ip.dp);
            for j in 0..2 {
                let a_dp = SIGN[j] * t;
                ds[j] = on[j] * (-r[j] - a_dp);
                dz[j] = (rc[j] + z[j] * (r[j] + a_dp)) * inv_s[j];
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::bounds::Row;
    use super::*;

    /// The stage intervals and tilt-rate rows of n outputs at δt = 0.02,
    /// as `ActiveSet::new` builds them.
    fn constraints(n: usize) -> Vec<Con> {
        let inv_dt2 = 2500.0;
        let mut cons: Vec<Con> = (0..n).map(|f| Con::stage(f, inv_dt2, 3.0)).collect();
        cons.extend((0..n).map(|f| {
            Con::row(
                &Row::tilt_rate(f, 7.5, |s| s).on_outputs(inv_dt2, |k| k),
                3.0,
            )
        }));
        cons
    }

    /// `Aᵀt` by the stencils is the definition `Σ_id w·a_id·t_id`.
    #[test]
    fn the_stencils_give_the_transpose() {
        let n = 23;
        let cons = constraints(n);
        let mut ip = Interior::new(n, &cons, 4);
        assert!(!ip.stencil.is_empty(), "aligned families");
        let t: Vec<f64> = (0..cons.len())
            .map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.3)
            .collect();
        let mut want = vec![0.5; n + PAD];
        for (c, t) in cons.iter().zip(&t) {
            for k in 0..c.len {
                want[c.first + k] += c.w * c.coef[k] * t;
            }
        }
        let mut out = vec![0.5; n];
        add_transpose(&ip.stencil, &t, &mut ip.pad, &mut out);
        for f in 0..n {
            assert!(
                (out[f] - want[f]).abs() <= 1e-9 * want[f].abs().max(1.0),
                "output {f}: {} vs {}",
                out[f],
                want[f]
            );
        }
    }

    /// Constraints that are not families of n aligned on their last
    /// output are not read as stencils (the interior point then gives no
    /// guess: the rollout's set is the cold start).
    #[test]
    fn unaligned_constraints_are_not_stencils() {
        let n = 10;
        let mut cons = constraints(n);
        cons.swap(3, 4);
        assert!(Interior::new(n, &cons, 4).stencil.is_empty());
    }
}
