//! The two-axis stage QP with the tilt cone ([`super::cone`]): a primal-dual
//! interior point on one KKT system holding both horizontal axes,
//! interleaved per stage so that it stays banded.
//!
//! Per free output f = 0..n−1 and axis i ∈ {x, y}: the deviation `p_{i,f}`,
//! the relative acceleration `ã_{i,f}` and the multiplier `λ_{i,f}` of
//! `Δ²p_{i,f}/δt² − ã_{i,f} = 0`, as [`StageQp`](super::interior_point::StageQp)
//! per axis. Stage order `[λ_x, λ_y, ã_x, ã_y, p_x, p_y]`: λ_f reaches back
//! to p_{f−2} (distance 8), the jerk couples ã_f with ã_{f−1} (6), the
//! smoothness term with ã_{f−2} (12), the cone ã_x with ã_y (1): the KKT
//! matrix has half-bandwidth 8 (12 with smoothness) over 6n rows.
//!
//! The cone `c_f = ½(‖u_f‖² − A²) ≤ 0`, `u_f = ã_f + a_0`, with slack s_f and
//! multiplier z_f adds `z_f·I + (z_f/s_f)·u_f·u_fᵀ` to the (ã_x, ã_y) block of
//! stage f: 2×2, inside the band. A soft speed side `h·x ≤ b + σ` (σ ≥ 0,
//! penalty ρσ; slack s, multipliers z of the row and w of σ ≥ 0) is
//! eliminated in closed form: it adds `d·hhᵀ` with
//! `d = (z/s)(w/σ)/(z/s + w/σ)` — the hard row's `z/s` in series with
//! the penalty's `w/σ`. Mehrotra's predictor-corrector, one step length.
//!
//! Always started cold: the warm path of
//! [`BandedConeSolver`](super::BandedConeSolver) is the
//! augmented Lagrangian ([`super::cone_alm`]), this its fallback.

use super::banded::SymBand;
use super::bounds::{Row, check_row_data};
use super::interior_point::BandedLdl;
use crate::ControlError;

/// Iteration limit.
pub const MAX_ITERATIONS: usize = 50;
/// Iterations without a better iterate after which the best one is taken.
const STALL_ITERATIONS: usize = 4;
/// Largest merit a stalled or last iterate may have and still be returned.
const ACCEPTABLE_MERIT: f64 = 100.0;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// Relative tolerance of the equality and primal residuals.
const TOLERANCE: f64 = 1e-10;
/// Static regularisation of the KKT matrix.
const REGULARISATION: f64 = 1e-12;
/// Variables per stage.
pub(super) const STAGE: usize = 6;

fn l_at(axis: usize, f: usize) -> usize {
    STAGE * f + axis
}
/// KKT index of ã_{axis, f}.
pub(super) fn a_at(axis: usize, f: usize) -> usize {
    STAGE * f + 2 + axis
}
/// KKT index of p_{axis, f}.
pub(super) fn p_at(axis: usize, f: usize) -> usize {
    STAGE * f + 4 + axis
}

/// One stage's cone: slack, multiplier, residual `c + s`, steps, and
/// `u = ã + a_0` at the current iterate.
#[derive(Debug, Clone, Copy, Default)]
struct ConeState {
    s: f64,
    z: f64,
    r: f64,
    ds: f64,
    dz: f64,
    u: [f64; 2],
}

/// One side `h·x − σ + s = b` of a speed row (σ = 0, w unused when hard).
#[derive(Debug, Clone, Copy, Default)]
struct Side {
    s: f64,
    z: f64,
    sig: f64,
    w: f64,
    /// Primal residual `h·x − σ + s − b`.
    r: f64,
    ds: f64,
    dz: f64,
    dsig: f64,
    dw: f64,
    /// Newton elimination: `Δz = k0 + d·hΔx`, `Δσ = (e0 + d1·hΔx)/S`.
    k0: f64,
    e0: f64,
}

/// Per-axis data of [`ConeQp::new`].
#[derive(Debug, Clone)]
pub struct ConeAxis {
    /// Tracking weight q [1/m²].
    pub q: f64,
    /// The ã block of P, `[diag, (k−1, k), (k−2, k)]` per column
    /// (as the crate-internal `smoothness::accel_block` builds it).
    pub accel: Vec<[f64; 3]>,
}

/// The two-axis cone QP's interior-point solver (module docs).
#[derive(Debug, Clone)]
pub struct ConeQp {
    n: usize,
    /// Cone radius per stage A_f [m/s²] (the nominal A unless
    /// [`ConeQp::set_radius`] set others).
    radius: Vec<f64>,
    /// Speed penalty ρ (None: no speed rows).
    penalty: Option<f64>,
    base: SymBand,
    kkt: SymBand,
    ldl: BandedLdl,
    cones: Vec<ConeState>,
    rows: Vec<Row>,
    /// `[upper, lower]` per row; upper `g·x ≤ hi`, lower `−g·x ≤ −lo`.
    sides: Vec<[Side; 2]>,
    /// Iterate, linear term, residual, step, right-hand side, best iterate.
    v: Vec<f64>,
    c: Vec<f64>,
    r: Vec<f64>,
    dv: Vec<f64>,
    rhs: Vec<f64>,
    best: Vec<f64>,
    /// Iterations of the last solve.
    iterations: usize,
}

impl ConeQp {
    /// A solver for n ≥ 1 free outputs per axis at step δt, cone radius
    /// `limit` = A [m/s²], and speed rows with exact penalty ρ when
    /// `speed_penalty` is given (soft: `Some`; `f64::INFINITY`: hard).
    pub fn new(
        n: usize,
        dt: f64,
        axes: [&ConeAxis; 2],
        limit: f64,
        speed_penalty: Option<f64>,
    ) -> Self {
        let size = STAGE * n;
        let smooth = axes.iter().any(|a| a.accel.iter().any(|c| c[2] != 0.0));
        let bandwidth = if smooth { 12 } else { 8 };
        let mut base = SymBand::zeros(size, bandwidth);
        let inv_dt2 = 1.0 / (dt * dt);
        for (i, ax) in axes.iter().enumerate() {
            for (f, &[d0, d1, d2]) in ax.accel.iter().enumerate().take(n) {
                base.add(p_at(i, f), p_at(i, f), 2.0 * ax.q);
                base.add(a_at(i, f), a_at(i, f), d0);
                if f >= 1 {
                    base.add(a_at(i, f - 1), a_at(i, f), d1);
                }
                if f >= 2 && d2 != 0.0 {
                    base.add(a_at(i, f - 2), a_at(i, f), d2);
                }
                base.add(l_at(i, f), p_at(i, f), inv_dt2);
                if f >= 1 {
                    base.add(l_at(i, f), p_at(i, f - 1), -2.0 * inv_dt2);
                }
                if f >= 2 {
                    base.add(l_at(i, f), p_at(i, f - 2), inv_dt2);
                }
                base.add(l_at(i, f), a_at(i, f), -1.0);
            }
        }
        for f in 0..n {
            for i in 0..2 {
                base.add(p_at(i, f), p_at(i, f), REGULARISATION);
                base.add(a_at(i, f), a_at(i, f), REGULARISATION);
                base.add(l_at(i, f), l_at(i, f), -REGULARISATION);
            }
        }
        let rows = if speed_penalty.is_some() {
            Row::speed_pair(n, dt, p_at)
        } else {
            Vec::new()
        };
        let m = rows.len();
        Self {
            n,
            radius: vec![limit; n],
            penalty: speed_penalty,
            kkt: base.clone(),
            base,
            ldl: BandedLdl::new(size, bandwidth),
            cones: vec![ConeState::default(); n],
            rows,
            sides: vec![[Side::default(); 2]; m],
            v: vec![0.0; size],
            c: vec![0.0; size],
            r: vec![0.0; size],
            dv: vec![0.0; size],
            rhs: vec![0.0; size],
            best: vec![0.0; size],
            iterations: 0,
        }
    }

    /// Iterations of the last solve (converged or not).
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// Number of speed rows (n per axis, or none).
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    fn soft(&self) -> bool {
        self.penalty.is_some_and(f64::is_finite)
    }

    /// The deviation `p_{axis, f}` of the current iterate.
    pub fn p(&self, axis: usize, f: usize) -> f64 {
        self.v[p_at(axis, f)]
    }

    /// Sets the primal start from `p` (per axis, length n): ã from the
    /// equality, λ = 0.
    pub fn set_start(&mut self, p: [&[f64]; 2], dt: f64) {
        let inv_dt2 = 1.0 / (dt * dt);
        for (i, p) in p.iter().enumerate() {
            for f in 0..self.n {
                let pm1 = if f >= 1 { p[f - 1] } else { 0.0 };
                let pm2 = if f >= 2 { p[f - 2] } else { 0.0 };
                self.v[p_at(i, f)] = p[f];
                self.v[a_at(i, f)] = (p[f] - 2.0 * pm1 + pm2) * inv_dt2;
                self.v[l_at(i, f)] = 0.0;
            }
        }
    }

    /// Sets the cone's radius per stage A_f [m/s²] (n entries, finite and
    /// > 0) for the next solves.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.n)?;
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// Cold-start slacks and multipliers for the current primal iterate.
    fn cold_duals(&mut self, lo: &[f64], hi: &[f64], b_scale: f64) {
        for (c, r) in self.cones.iter_mut().zip(&self.radius) {
            let a2 = 0.5 * r * r;
            c.s = a2;
            c.z = 1.0 / a2;
        }
        let rho = self.penalty.unwrap_or(f64::INFINITY);
        let soft = rho.is_finite();
        for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
            let g = row.dot(&self.v);
            let floor = (0.1 * (hi[k] - lo[k])).max(1e-3 * b_scale);
            for (j, sd) in side.iter_mut().enumerate() {
                // Distance to the bound along this side's direction.
                let room = if j == 0 { hi[k] - g } else { g - lo[k] };
                *sd = Side {
                    s: room.max(floor),
                    z: 1.0,
                    ..Side::default()
                };
                if soft {
                    sd.w = (rho - 1.0).max(1.0);
                    sd.sig = (-room).max(0.0) + floor / sd.w;
                }
            }
        }
    }

    /// Solves for the linear term `c` (full KKT length: on p and ã; zero on
    /// λ), relative fixed accelerations `a0` [m/s²] (u = ã + a0) and speed
    /// row bounds `lo ≤ g·x ≤ hi`. The primal start must be set
    /// ([`ConeQp::set_start`]); slacks and multipliers start cold. Returns
    /// the iterations.
    pub fn solve(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<usize, ControlError> {
        let n = self.n;
        let m = self.rows.len();
        check_row_data(
            "cone QP",
            c.len() == STAGE * n && lo.len() == m && hi.len() == m,
            "c needs 6n entries, lo and hi one per row",
            &[c, &self.v, &a0],
            lo,
            hi,
        )?;
        self.c.copy_from_slice(c);
        let norm = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let c_scale = 1.0 + norm(c);
        let b_scale = 1.0 + norm(lo).max(norm(hi));
        let cone_scale = 1.0 + self.radius.iter().fold(0.0f64, |a, r| a.max(r * r));
        let rho = self.penalty.unwrap_or(f64::INFINITY);
        let soft = self.soft();
        self.cold_duals(lo, hi, b_scale);
        let pairs = (n + m * if soft { 4 } else { 2 }).max(1) as f64;

        let mut best = (f64::INFINITY, 0usize);
        for iteration in 0..MAX_ITERATIONS {
            self.iterations = iteration;
            // Dual residual r = M·v + c + Σ z_f·u_f + Σ hᵀz; primal ones.
            self.base.mul_vec(&self.v, &mut self.r);
            for (r, c) in self.r.iter_mut().zip(&self.c) {
                *r += c;
            }
            let mut gap = 0.0;
            let mut rp_cone: f64 = 0.0;
            for (f, cs) in self.cones.iter_mut().enumerate() {
                cs.u = [self.v[a_at(0, f)] + a0[0], self.v[a_at(1, f)] + a0[1]];
                let a2 = self.radius[f] * self.radius[f];
                let cf = 0.5 * (cs.u[0] * cs.u[0] + cs.u[1] * cs.u[1] - a2);
                cs.r = cf + cs.s;
                rp_cone = rp_cone.max(cs.r.abs());
                self.r[a_at(0, f)] += cs.z * cs.u[0];
                self.r[a_at(1, f)] += cs.z * cs.u[1];
                gap += cs.s * cs.z;
            }
            let mut rp: f64 = 0.0;
            let mut rsig: f64 = 0.0;
            for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
                let g = row.dot(&self.v);
                let [up, low] = side;
                row.axpy(up.z - low.z, &mut self.r);
                up.r = g - up.sig + up.s - hi[k];
                low.r = -g - low.sig + low.s + lo[k];
                rp = rp.max(up.r.abs()).max(low.r.abs());
                gap += up.s * up.z + low.s * low.z;
                if soft {
                    gap += up.sig * up.w + low.sig * low.w;
                    rsig = rsig
                        .max((rho - up.z - up.w).abs())
                        .max((rho - low.z - low.w).abs());
                }
            }
            let mut rd: f64 = 0.0;
            let mut req: f64 = 0.0;
            for f in 0..n {
                for i in 0..2 {
                    rd = rd
                        .max(self.r[p_at(i, f)].abs())
                        .max(self.r[a_at(i, f)].abs());
                    req = req.max(self.r[l_at(i, f)].abs());
                }
            }
            let objective: f64 = (0..STAGE * n)
                .map(|k| 0.5 * self.c[k] * self.v[k])
                .sum::<f64>();
            if !(gap.is_finite() && rd.is_finite() && req.is_finite() && rp_cone.is_finite()) {
                return Err(ControlError::Solver("cone QP: non-finite iterate".into()));
            }
            let a_scale = 1.0
                + (0..n).fold(0.0f64, |a, f| {
                    a.max(self.v[a_at(0, f)].abs())
                        .max(self.v[a_at(1, f)].abs())
                });
            let merit = (rd / (1e-8 * c_scale))
                .max(rsig / (1e-8 * (1.0 + if soft { rho } else { 0.0 })))
                .max(req / (TOLERANCE * a_scale))
                .max(rp / (TOLERANCE * b_scale))
                .max(rp_cone / (TOLERANCE * cone_scale))
                .max(gap / (1e-9 * (1.0 + objective.abs())));
            if merit < best.0 {
                best = (merit, iteration);
                self.best.copy_from_slice(&self.v);
            }
            let stalled = best.0 <= ACCEPTABLE_MERIT && iteration >= best.1 + STALL_ITERATIONS;
            if merit <= 1.0 || stalled || iteration + 1 == MAX_ITERATIONS {
                if best.0 > ACCEPTABLE_MERIT {
                    break;
                }
                self.v.copy_from_slice(&self.best);
                return Ok(iteration);
            }
            let mu = gap / pairs;

            // K = M + cone blocks + Σ d·hhᵀ (M holds the regularisation).
            self.kkt.clone_from(&self.base);
            for (f, cs) in self.cones.iter().enumerate() {
                let d = cs.z / cs.s;
                let [ux, uy] = cs.u;
                let (ix, iy) = (a_at(0, f), a_at(1, f));
                self.kkt.add(ix, ix, cs.z + d * ux * ux);
                self.kkt.add(iy, iy, cs.z + d * uy * uy);
                self.kkt.add(iy, ix, d * ux * uy);
            }
            for (row, side) in self.rows.iter().zip(&self.sides) {
                let d: f64 = side.iter().map(|sd| Self::side_weight(sd, soft)).sum();
                for a in 0..row.len {
                    for b in 0..=a {
                        self.kkt
                            .add(row.idx[a], row.idx[b], d * row.coef[a] * row.coef[b]);
                    }
                }
            }
            if self.ldl.factor(&self.kkt).is_err() {
                // The end game's barrier terms (z/s up to ~1e20) can make
                // the KKT matrix numerically singular: an acceptable best
                // iterate is the answer then, as when stalled.
                if best.0 <= ACCEPTABLE_MERIT {
                    self.v.copy_from_slice(&self.best);
                    return Ok(iteration);
                }
                return Err(ControlError::Solver("cone QP: factorisation failed".into()));
            }

            // Predictor (affine), then Mehrotra's corrector.
            self.direction(rho, soft, |s, z, _| s * z);
            let alpha = self.step_length();
            let mut gap_aff = 0.0;
            for cs in &self.cones {
                gap_aff += (cs.s + alpha * cs.ds) * (cs.z + alpha * cs.dz);
            }
            for sd in self.sides.iter().flatten() {
                gap_aff += (sd.s + alpha * sd.ds) * (sd.z + alpha * sd.dz);
                if soft {
                    gap_aff += (sd.sig + alpha * sd.dsig) * (sd.w + alpha * sd.dw);
                }
            }
            let sigma = (gap_aff / gap).clamp(0.0, 1.0).powi(3);
            let target = sigma * mu;
            self.direction(rho, soft, |s, z, dsdz| s * z + dsdz - target);
            let alpha = (STEP_FRACTION * self.step_length()).min(1.0);
            for (v, dv) in self.v.iter_mut().zip(&self.dv) {
                *v += alpha * dv;
            }
            for cs in &mut self.cones {
                cs.s += alpha * cs.ds;
                cs.z += alpha * cs.dz;
            }
            for sd in self.sides.iter_mut().flatten() {
                sd.s += alpha * sd.ds;
                sd.z += alpha * sd.dz;
                if soft {
                    sd.sig += alpha * sd.dsig;
                    sd.w += alpha * sd.dw;
                }
            }
        }
        Err(ControlError::Solver(format!(
            "cone QP: no convergence (best merit {:.1e})",
            best.0
        )))
    }

    /// The weight `d` a side adds to `hhᵀ` in the KKT matrix.
    fn side_weight(sd: &Side, soft: bool) -> f64 {
        if soft {
            // z/s in series with w/σ, in the form that stays finite when
            // either ratio is huge.
            1.0 / (sd.s / sd.z + sd.sig / sd.w)
        } else {
            sd.z / sd.s
        }
    }

    /// The Newton step for complementarity targets `rc(s, z, Δs·Δz)` (the
    /// last argument is the predictor's product, 0 in the predictor).
    fn direction(&mut self, rho: f64, soft: bool, rc: impl Fn(f64, f64, f64) -> f64) {
        for (o, r) in self.rhs.iter_mut().zip(&self.r) {
            *o = -r;
        }
        // Cones: rhs −= u·(z·r − rc)/s on (ã_x, ã_y).
        for (f, cs) in self.cones.iter().enumerate() {
            let rcs = rc(cs.s, cs.z, cs.ds * cs.dz);
            let e = (cs.z * cs.r - rcs) / cs.s;
            self.rhs[a_at(0, f)] -= cs.u[0] * e;
            self.rhs[a_at(1, f)] -= cs.u[1] * e;
        }
        // Sides: Δz = k0 + d·hΔx, rhs −= hᵀk0 (h = ±g).
        for (row, side) in self.rows.iter().zip(self.sides.iter_mut()) {
            let mut e = 0.0;
            for (j, sd) in side.iter_mut().enumerate() {
                let rcs = rc(sd.s, sd.z, sd.ds * sd.dz);
                let d1 = sd.z / sd.s;
                if soft {
                    let rcw = rc(sd.sig, sd.w, sd.dsig * sd.dw);
                    let d2 = sd.w / sd.sig;
                    let rs = rho - sd.z - sd.w;
                    sd.e0 = -rs - rcs / sd.s - rcw / sd.sig + d1 * sd.r;
                    sd.k0 = -rcs / sd.s + d1 * sd.r - d1 * sd.e0 / (d1 + d2);
                } else {
                    sd.k0 = -rcs / sd.s + d1 * sd.r;
                }
                e += if j == 0 { sd.k0 } else { -sd.k0 };
            }
            row.axpy(-e, &mut self.rhs);
        }
        self.dv.copy_from_slice(&self.rhs);
        self.ldl.solve(&mut self.dv);
        for cs in &mut self.cones.iter_mut().enumerate() {
            let (f, cs) = cs;
            let du = cs.u[0] * self.dv[a_at(0, f)] + cs.u[1] * self.dv[a_at(1, f)];
            let rcs = rc(cs.s, cs.z, cs.ds * cs.dz);
            cs.ds = -cs.r - du;
            cs.dz = -(rcs + cs.z * cs.ds) / cs.s;
        }
        for (row, side) in self.rows.iter().zip(self.sides.iter_mut()) {
            let gdx = row.dot(&self.dv);
            for (j, sd) in side.iter_mut().enumerate() {
                let hdx = if j == 0 { gdx } else { -gdx };
                let rcs = rc(sd.s, sd.z, sd.ds * sd.dz);
                if soft {
                    let rcw = rc(sd.sig, sd.w, sd.dsig * sd.dw);
                    let (d1, d2) = (sd.z / sd.s, sd.w / sd.sig);
                    let dsig = (sd.e0 + d1 * hdx) / (d1 + d2);
                    sd.ds = -sd.r - hdx + dsig;
                    sd.dz = -(rcs + sd.z * sd.ds) / sd.s;
                    sd.dw = -(rcw + sd.w * dsig) / sd.sig;
                    sd.dsig = dsig;
                } else {
                    sd.ds = -sd.r - hdx;
                    sd.dz = -(rcs + sd.z * sd.ds) / sd.s;
                }
            }
        }
    }

    fn step_length(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        let mut limit = |v: f64, dv: f64| {
            if dv < 0.0 {
                alpha = alpha.min(-v / dv);
            }
        };
        for cs in &self.cones {
            limit(cs.s, cs.ds);
            limit(cs.z, cs.dz);
        }
        for sd in self.sides.iter().flatten() {
            limit(sd.s, sd.ds);
            limit(sd.z, sd.dz);
            limit(sd.sig, sd.dsig);
            limit(sd.w, sd.dw);
        }
        alpha
    }
}
