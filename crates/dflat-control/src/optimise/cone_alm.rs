//! The tilt-cone problem ([`super::cone`]) by an augmented Lagrangian on
//! the free outputs alone, each subproblem minimised by semismooth Newton
//! on a banded positive-definite matrix: the fast path's matrix plus one
//! block per stage outside the cone, so that a tick whose active set
//! barely moved costs a few banded factorisations.
//!
//! Unknowns: `x = (p_{x,0}, p_{y,0}, p_{x,1}, p_{y,1}, …)`, the deviations of
//! the free outputs from the zero-jerk baseline (2n, n = N − 2), objective
//! `½xᵀPx + cᵀx` with P = 2·H per axis (H: [`FastBandedSolver`]'s Hessian;
//! half-bandwidth 7 interleaved, 9 with the smoothness term). Stage f's
//! acceleration `u_f = G_f·x + a_0`, `G_f·x = (p_f − 2p_{f−1} + p_{f−2})/δt²`
//! per axis (indices 2(f−2)..2f+1, inside the band).
//!
//! With multipliers y_f ∈ ℝ² and penalty σ, the augmented Lagrangian
//!
//! ```text
//! L(x) = ½xᵀPx + cᵀx + Σ_f [σ/2·dist²(u_f + y_f/σ, D) − ‖y_f‖²/(2σ)] + speed terms
//! ```
//!
//! (D the disc of radius A) is convex, once differentiable, piecewise
//! twice: its generalised Hessian is `P + σ·Σ G_fᵀ(I − ∂Π_D)G_f`, where
//! `I − ∂Π_D(w) = (1 − A/‖w‖)·I + (A/‖w‖)·ŵŵᵀ` outside the disc and 0 inside.
//! Newton with an Armijo line search minimises it; then `y_f ← σ(w_f −
//! Π_D(w_f))`, and σ grows tenfold when the constraint residual did not
//! fall tenfold (below). A soft speed side `h·x ≤ b` with exact penalty ρ has its
//! multiplier clamped to [0, ρ] (∞ when hard): `v ← clamp(v + σ_s·t, 0, ρ)`.
//!
//! Each inner solve stops when the gradient is below 1e-8 of the linear
//! term's scale or the Newton decrement `−gᵀd` below 1e-13 of the
//! objective's (the rounding floor of P·x, whose entries reach 1e10) —
//! or, while the multipliers are far off, below σ·(0.1·residual)², the
//! change the next update makes (inexact inner solves). The solve stops
//! when the constraint residual (the multipliers' change in the update,
//! over σ) is below 1e-8 of the radius and what the residuals can cost,
//! `Σ‖y_f‖·residual_f`, is below 3e-9 of the objective's scale (a stage
//! strictly inside the disc where the optimum is on it costs ‖y_f‖ per
//! m/s²: with many active stages the residual test alone left the cost
//! 1e-7 above the optimum). σ grows tenfold only while the residual is
//! above its tolerance and did not fall tenfold. The factor is reused while the
//! last step was full, its decrement small and the active set (stages
//! outside the disc, speed sides in their quadratic range) the one
//! factored; once a reused factor stops converging tenfold per step, the
//! next step refactors. `P·x` is evaluated by differencing
//! (`FastBandedSolver::apply_hessian`) and then updated by `α·P·d`.
//!
//! Warm start ([`ConeAlm::shift`]): the multipliers one stage on, σ from
//! its initial value (1e4).

use super::FastBandedSolver;
use super::banded::{BandedCholesky, SymBand};
use super::bounds::{Row, check_row_data};
use crate::ControlError;

/// Newton steps per solve, over all outer iterations.
pub const MAX_NEWTON_STEPS: usize = 40;
/// Outer (multiplier) updates per solve.
const MAX_OUTER: usize = 20;
/// Step halvings of the line search.
const MAX_HALVINGS: usize = 30;
/// Armijo's sufficient-decrease fraction.
const ARMIJO: f64 = 1e-4;
/// Relative tolerance of the Lagrangian's gradient.
const DUAL_TOLERANCE: f64 = 1e-8;
/// Tolerance of the Newton decrement `−gᵀd` (the predicted decrease of
/// L) relative to the objective's scale `|c|·|x|`.
const DECREMENT_TOLERANCE: f64 = 1e-13;
/// Decrement (relative, as [`DECREMENT_TOLERANCE`]) below which a full
/// step counts as the local phase, where the next step reuses the factor.
const REUSE_DECREMENT: f64 = 1e-7;

/// Decrement (relative, as [`DECREMENT_TOLERANCE`]) after whose full step
/// the inner loop stops without a confirming step.
const LOCAL_STOP: f64 = 1e-11;
/// Relative tolerance of the constraint residual.
const PRIMAL_TOLERANCE: f64 = 1e-8;
/// Tolerance of the residuals' cost (`residual_cost`) relative to the objective's
/// scale `|c|·|x|`: with many active stages and large multipliers the
/// residual tolerance alone left the cost 1e-7 above the optimum.
const GAP_TOLERANCE: f64 = 3e-9;
/// Fraction of the constraint residual within which an inner solve is
/// accurate enough for the next multiplier update.
const INEXACT: f64 = 0.1;
/// Growth of σ when the constraint residual stalls.
const SIGMA_GROWTH: f64 = 10.0;

/// Index of `p_{axis, f}` in x.
pub(super) fn at(axis: usize, f: usize) -> usize {
    2 * f + axis
}

/// The second difference `(1, −2, 1)` on p_f, p_{f−1}, p_{f−2}.
const D2: [f64; 3] = [1.0, -2.0, 1.0];

/// Tuning of [`ConeAlm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlmTuning {
    /// Initial penalty σ on the cone, per (m/s²)² of violation.
    pub sigma: f64,
    /// Largest σ.
    pub sigma_max: f64,
}

impl Default for AlmTuning {
    fn default() -> Self {
        Self {
            sigma: 1e4,
            sigma_max: 1e8,
        }
    }
}

/// The augmented-Lagrangian solver of the two-axis cone problem (module
/// docs). Allocates at construction only.
#[derive(Debug, Clone)]
pub struct ConeAlm {
    n: usize,
    inv_dt2: f64,
    /// Nominal cone radius A [m/s²], and the radius per stage (A unless
    /// [`ConeAlm::set_radius`] set others).
    limit: f64,
    radius: Vec<f64>,
    /// Speed penalty ρ (None: no speed rows; ∞: hard).
    penalty: Option<f64>,
    tuning: AlmTuning,
    sigma: f64,
    axes: [FastBandedSolver; 2],
    base: SymBand,
    kkt: SymBand,
    chol: BandedCholesky,
    rows: Vec<Row>,
    /// Cone multipliers y_f [cost per m/s²], and their update
    /// `σ·(w_f − Π(w_f))` at x (set by `gradient`).
    y: Vec<[f64; 2]>,
    y_next: Vec<[f64; 2]>,
    /// Speed multipliers `[upper, lower]` per row.
    v: Vec<[f64; 2]>,
    /// Iterate, linear term, gradient, direction, P·direction, scratch.
    x: Vec<f64>,
    c: Vec<f64>,
    g: Vec<f64>,
    d: Vec<f64>,
    pd: Vec<f64>,
    px: Vec<f64>,
    /// Per-stage u_f and G_f·d.
    u: Vec<[f64; 2]>,
    du: Vec<[f64; 2]>,
    /// Per-row h·x and h·d.
    hx: Vec<f64>,
    hd: Vec<f64>,
    axis_in: Vec<f64>,
    axis_out: Vec<f64>,
    newton_steps: usize,
    /// Factorisations of the last solve.
    factorisations: usize,
    /// Whether `px` holds P·x for the current x.
    px_current: bool,
    /// Largest diagonal entry of P.
    diag_max: f64,
    /// The Lagrangian's non-quadratic part at x (set by `gradient`).
    penalty_value: f64,
    /// Which stages lie outside the disc and which speed sides are in
    /// their penalty's quadratic range, at x (set by `gradient`) and at
    /// the last factorisation.
    active: Vec<bool>,
    factored_active: Vec<bool>,
}

impl ConeAlm {
    /// A solver for the axes' weights (`axes[i]`'s horizon N, n = N − 2
    /// free outputs per axis) at step δt \[s\], cone radius `limit` = A
    /// [m/s²], speed rows with exact penalty ρ when `speed_penalty` is
    /// given (`f64::INFINITY`: hard).
    pub fn new(
        axes: [FastBandedSolver; 2],
        dt: f64,
        limit: f64,
        speed_penalty: Option<f64>,
        tuning: AlmTuning,
    ) -> Self {
        let n = axes[0].horizon() - 2;
        assert_eq!(axes[1].horizon() - 2, n, "axes of one horizon");
        let size = 2 * n;
        let axis_b = axes
            .iter()
            .map(|a| a.hessian_band().bandwidth())
            .max()
            .unwrap_or(3);
        let bandwidth = 2 * axis_b + 1;
        let mut base = SymBand::zeros(size, bandwidth);
        for (i, ax) in axes.iter().enumerate() {
            let h = ax.hessian_band();
            for f in 0..n {
                for g in f.saturating_sub(h.bandwidth())..=f {
                    base.add(at(i, f), at(i, g), 2.0 * h.get(f, g));
                }
            }
        }
        let diag_max = (0..size).fold(0.0f64, |a, i| a.max(base.get(i, i)));
        let rows = if speed_penalty.is_some() {
            Row::speed_pair(n, dt, at)
        } else {
            Vec::new()
        };
        let m = rows.len();
        Self {
            n,
            inv_dt2: 1.0 / (dt * dt),
            limit,
            radius: vec![limit; n],
            penalty: speed_penalty,
            tuning,
            sigma: tuning.sigma,
            axes,
            kkt: base.clone(),
            base,
            chol: BandedCholesky::new(size, bandwidth),
            rows,
            y: vec![[0.0; 2]; n],
            y_next: vec![[0.0; 2]; n],
            v: vec![[0.0; 2]; m],
            x: vec![0.0; size],
            c: vec![0.0; size],
            g: vec![0.0; size],
            d: vec![0.0; size],
            pd: vec![0.0; size],
            px: vec![0.0; size],
            u: vec![[0.0; 2]; n],
            du: vec![[0.0; 2]; n],
            hx: vec![0.0; m],
            hd: vec![0.0; m],
            axis_in: vec![0.0; n],
            axis_out: vec![0.0; n],
            newton_steps: 0,
            factorisations: 0,
            px_current: false,
            diag_max,
            penalty_value: 0.0,
            active: vec![false; n + 2 * m],
            factored_active: vec![false; n + 2 * m],
        }
    }

    /// The weights of axis i (0: x, 1: y).
    pub fn axis(&self, i: usize) -> &FastBandedSolver {
        &self.axes[i]
    }

    /// Newton steps of the last solve.
    pub fn newton_steps(&self) -> usize {
        self.newton_steps
    }

    /// Factorisations of the last solve (Newton steps in the local phase
    /// reuse the last factor).
    pub fn factorisations(&self) -> usize {
        self.factorisations
    }

    /// The deviation `p_{axis, f}` of the current iterate.
    pub fn p(&self, axis: usize, f: usize) -> f64 {
        self.x[at(axis, f)]
    }

    /// Sets the primal start from `p` (per axis, length n).
    pub fn set_start(&mut self, p: [&[f64]; 2]) {
        self.px_current = false;
        for (i, p) in p.iter().enumerate() {
            for (f, &v) in p.iter().enumerate().take(self.n) {
                self.x[at(i, f)] = v;
            }
        }
    }

    /// Forgets the multipliers and σ (a cold start).
    pub fn reset_multipliers(&mut self) {
        self.y.iter_mut().for_each(|y| *y = [0.0; 2]);
        self.v.iter_mut().for_each(|v| *v = [0.0; 2]);
        self.sigma = self.tuning.sigma;
    }

    /// Moves the multipliers one stage earlier (the last stage keeps its
    /// own) and restarts σ from its initial value: the warm start of the
    /// next tick. (A σ grown on a hard tick and kept makes the next ticks'
    /// subproblems stiff: their semismooth Newton then zigzags.)
    pub fn shift(&mut self) {
        self.sigma = self.tuning.sigma;
        let n = self.n;
        if n >= 2 {
            self.y.copy_within(1..n, 0);
        }
        let m = self.rows.len();
        for r in [0..m / 2, m / 2..m] {
            if r.len() >= 2 {
                self.v.copy_within(r.start + 1..r.end, r.start);
            }
        }
    }

    /// σ on the speed rows: the cone's σ in acceleration-like units
    /// (rows scaled by 1/δt).
    fn sigma_speed(&self) -> f64 {
        self.sigma * self.inv_dt2
    }

    /// `out[f] = G_f·v` per axis for every stage (outputs before the
    /// horizon are 0), without a_0.
    fn accelerations(inv_dt2: f64, v: &[f64], out: &mut [[f64; 2]]) {
        let (mut p1, mut p2) = ([0.0; 2], [0.0; 2]);
        for (f, o) in out.iter_mut().enumerate() {
            let p0 = [v[at(0, f)], v[at(1, f)]];
            *o = [
                (p0[0] - 2.0 * p1[0] + p2[0]) * inv_dt2,
                (p0[1] - 2.0 * p1[1] + p2[1]) * inv_dt2,
            ];
            p2 = p1;
            p1 = p0;
        }
    }

    /// `out += Σ_f G_fᵀ·e_f`.
    fn add_transposed(inv_dt2: f64, e: &[[f64; 2]], out: &mut [f64]) {
        let n = e.len();
        let (mut e1, mut e2) = ([0.0; 2], [0.0; 2]);
        for f in (0..n).rev() {
            let e0 = e[f];
            for i in 0..2 {
                out[at(i, f)] += (e0[i] - 2.0 * e1[i] + e2[i]) * inv_dt2;
            }
            e2 = e1;
            e1 = e0;
        }
    }

    /// `out = P·v` by differencing.
    fn apply_p(&mut self, which: Vector) {
        for i in 0..2 {
            let src = match which {
                Vector::X => &self.x,
                Vector::D => &self.d,
            };
            for f in 0..self.n {
                self.axis_in[f] = src[at(i, f)];
            }
            self.axes[i].apply_hessian(&self.axis_in, &mut self.axis_out);
            let dst = match which {
                Vector::X => &mut self.px,
                Vector::D => &mut self.pd,
            };
            for f in 0..self.n {
                dst[at(i, f)] = 2.0 * self.axis_out[f];
            }
        }
    }

    /// `(‖w‖, A_f)` when `w` lies outside stage f's disc of radius A_f
    /// (then `w − Π(w) = (1 − A_f/‖w‖)·w`).
    fn radial(&self, w: [f64; 2], f: usize) -> Option<(f64, f64)> {
        let n2 = w[0] * w[0] + w[1] * w[1];
        let r = self.radius[f];
        (n2 > r * r).then(|| (n2.sqrt(), r))
    }

    /// The cone's radius per stage `A_f` [m/s²] (the nominal A unless set).
    pub fn radius(&self) -> &[f64] {
        &self.radius
    }

    /// Sets the cone's radius per stage `A_f` [m/s²] (n entries, finite
    /// and > 0; stage f bounds the acceleration of output f + 2), for the
    /// next solves — the spatial model's tilt cone, whose radius follows
    /// the planned vertical acceleration.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.n)?;
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// A speed side's updated multiplier `clamp(v + σ_s·t, 0, ρ)`.
    fn side_multiplier(&self, v: f64, t: f64) -> f64 {
        let rho = self.penalty.unwrap_or(f64::INFINITY);
        (v + self.sigma_speed() * t).clamp(0.0, rho)
    }

    /// The Lagrangian's non-quadratic part at `x + α·d` (`u`, `du`, `hx`,
    /// `hd` current), without its constant `−Σ‖y_f‖²/(2σ)`.
    fn penalty_terms(&self, alpha: f64, lo: &[f64], hi: &[f64]) -> f64 {
        let s = self.sigma;
        let ss = self.sigma_speed();
        let mut value = 0.0;
        for f in 0..self.n {
            let w = [
                self.u[f][0] + alpha * self.du[f][0] + self.y[f][0] / s,
                self.u[f][1] + alpha * self.du[f][1] + self.y[f][1] / s,
            ];
            if let Some((norm, r)) = self.radial(w, f) {
                value += 0.5 * s * (norm - r) * (norm - r);
            }
        }
        for (k, v) in self.v.iter().enumerate() {
            let h = self.hx[k] + alpha * self.hd[k];
            for (j, &vj) in v.iter().enumerate() {
                let t = if j == 0 { h - hi[k] } else { lo[k] - h };
                let vn = self.side_multiplier(vj, t);
                value += vn * t - (vn - vj) * (vn - vj) / (2.0 * ss);
            }
        }
        value
    }

    /// u, h·x and the gradient `g = P·x + c + Σ G_fᵀy'_f + Σ ±h·v'` at x,
    /// with the updated cone multipliers y' (`y_next`), the penalty part of
    /// L (`penalty_value`) and the active set (`active`); returns
    /// `(‖g‖∞, cone residual, speed residual)`, the residuals being the
    /// largest multiplier change `‖y' − y‖/σ` (cone, m/s²) and `|v' − v|/σ_s`
    /// (speed rows) the update would make.
    fn gradient(&mut self, a0: [f64; 2], lo: &[f64], hi: &[f64]) -> (f64, f64, f64) {
        if !self.px_current {
            self.apply_p(Vector::X);
            self.px_current = true;
        }
        for ((g, p), c) in self.g.iter_mut().zip(&self.px).zip(&self.c) {
            *g = p + c;
        }
        let s = self.sigma;
        Self::accelerations(self.inv_dt2, &self.x, &mut self.u);
        let mut res2: f64 = 0.0;
        let mut value = 0.0;
        for f in 0..self.n {
            let u = [self.u[f][0] + a0[0], self.u[f][1] + a0[1]];
            self.u[f] = u;
            let y = self.y[f];
            let w = [u[0] + y[0] / s, u[1] + y[1] / s];
            let yn = match self.radial(w, f) {
                Some((norm, r)) => {
                    value += 0.5 * s * (norm - r) * (norm - r);
                    let k = s * (1.0 - r / norm);
                    [k * w[0], k * w[1]]
                }
                None => [0.0; 2],
            };
            self.active[f] = yn != [0.0; 2];
            let (ex, ey) = (yn[0] - y[0], yn[1] - y[1]);
            res2 = res2.max(ex * ex + ey * ey);
            self.y_next[f] = yn;
        }
        let cone_res = res2.sqrt() / s;
        Self::add_transposed(self.inv_dt2, &self.y_next, &mut self.g);
        let ss = self.sigma_speed();
        let rho = self.penalty.unwrap_or(f64::INFINITY);
        let mut speed_res: f64 = 0.0;
        for k in 0..self.rows.len() {
            let h = self.rows[k].dot(&self.x);
            self.hx[k] = h;
            let mut e = 0.0;
            for j in 0..2 {
                let t = if j == 0 { h - hi[k] } else { lo[k] - h };
                let vn = self.side_multiplier(self.v[k][j], t);
                let raw = self.v[k][j] + ss * t;
                self.active[self.n + 2 * k + j] = raw > 0.0 && raw < rho;
                value += vn * t - (vn - self.v[k][j]) * (vn - self.v[k][j]) / (2.0 * ss);
                speed_res = speed_res.max((vn - self.v[k][j]).abs() / ss);
                e += if j == 0 { vn } else { -vn };
            }
            if e != 0.0 {
                self.rows[k].axpy(e, &mut self.g);
            }
        }
        self.penalty_value = value;
        let gn = self.g.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        (gn, cone_res, speed_res)
    }

    /// What the constraints' residuals can cost at x (`y_next`, `hx`
    /// current, the multipliers not yet updated):
    /// `Σ ‖y'_f‖·‖y'_f − y_f‖/σ + Σ v'·|v' − v|/σ_s` — a stage inside the
    /// disc by δ where the optimum is on it costs ‖y‖·δ. Only the stop
    /// needs it, once per multiplier update.
    fn residual_cost(&self, lo: &[f64], hi: &[f64]) -> f64 {
        let s = self.sigma;
        let mut gap = 0.0;
        for (yn, y) in self.y_next.iter().zip(&self.y) {
            let (ex, ey) = (yn[0] - y[0], yn[1] - y[1]);
            let e2 = ex * ex + ey * ey;
            if e2 > 0.0 {
                gap += (yn[0] * yn[0] + yn[1] * yn[1]).sqrt() * e2.sqrt() / s;
            }
        }
        let ss = self.sigma_speed();
        for (k, v) in self.v.iter().enumerate() {
            let h = self.hx[k];
            for (j, &vj) in v.iter().enumerate() {
                let t = if j == 0 { h - hi[k] } else { lo[k] - h };
                let vn = self.side_multiplier(vj, t);
                gap += vn * (vn - vj).abs() / ss;
            }
        }
        gap
    }

    /// The generalised Hessian `P + σ·Σ G_fᵀ J_f G_f + σ_s·Σ hhᵀ` at x.
    fn assemble(&mut self, lo: &[f64], hi: &[f64]) {
        self.kkt.clone_from(&self.base);
        let s = self.sigma;
        let k2 = self.inv_dt2 * self.inv_dt2;
        for f in 0..self.n {
            let w = [
                self.u[f][0] + self.y[f][0] / s,
                self.u[f][1] + self.y[f][1] / s,
            ];
            let Some((norm, r)) = self.radial(w, f) else {
                continue;
            };
            let (wx, wy) = (w[0] / norm, w[1] / norm);
            let t = r / norm;
            let j = [
                [1.0 - t + t * wx * wx, t * wx * wy],
                [t * wx * wy, 1.0 - t + t * wy * wy],
            ];
            // G_fᵀ(σ·k2·J)G_f into the band: entry (at(i, f − ka),
            // at(jj, f − kb)) at row·w + (row − col), lower triangle only.
            let w = self.kkt.bandwidth() + 1;
            let lower = self.kkt.lower_mut();
            for (ka, &ca) in D2.iter().enumerate() {
                let Some(ga) = f.checked_sub(ka) else {
                    continue;
                };
                for (kb, &cb) in D2.iter().enumerate() {
                    let Some(gb) = f.checked_sub(kb) else {
                        continue;
                    };
                    let scale = s * k2 * ca * cb;
                    for (i, ji) in j.iter().enumerate() {
                        for (jj, &jv) in ji.iter().enumerate() {
                            let (r, c) = (at(i, ga), at(jj, gb));
                            if r >= c {
                                lower[r * w + (r - c)] += scale * jv;
                            }
                        }
                    }
                }
            }
        }
        let ss = self.sigma_speed();
        let rho = self.penalty.unwrap_or(f64::INFINITY);
        for k in 0..self.rows.len() {
            let h = self.hx[k];
            let mut active = 0.0;
            for j in 0..2 {
                let t = if j == 0 { h - hi[k] } else { lo[k] - h };
                let raw = self.v[k][j] + ss * t;
                if raw > 0.0 && raw < rho {
                    active += ss;
                }
            }
            if active == 0.0 {
                continue;
            }
            let row = self.rows[k];
            for a in 0..row.len {
                for b in 0..=a {
                    self.kkt
                        .add(row.idx[a], row.idx[b], active * row.coef[a] * row.coef[b]);
                }
            }
        }
    }

    /// Solves for the linear term `c` (2n, interleaved), fixed relative
    /// accelerations `a0` [m/s²] and speed row bounds `lo ≤ h·x ≤ hi` from
    /// the primal start ([`ConeAlm::set_start`]) and the multipliers held
    /// (zero, or shifted from the last solve). Returns the Newton steps;
    /// errors when it does not converge within [`MAX_NEWTON_STEPS`].
    pub fn solve(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<usize, ControlError> {
        let m = self.rows.len();
        check_row_data(
            "cone ALM",
            c.len() == 2 * self.n && lo.len() == m && hi.len() == m,
            "c needs 2n entries, lo and hi one per row",
            &[c, &self.x, &a0],
            lo,
            hi,
        )?;
        self.c.copy_from_slice(c);
        self.px_current = false;
        let c_scale = 1.0 + c.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        // P·x has entries ~1e10 even by differencing: its rounding floor,
        // ε·max|P_ii|·|x| (1e-5 at δt = 0.02 s, r = 0.01), bounds how
        // small the gradient can be made.
        let x_scale = 1.0 + self.x.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let floor = 16.0 * f64::EPSILON * self.diag_max * x_scale;
        let dual_tol = (DUAL_TOLERANCE * c_scale).max(floor);
        let decrement_tol = DECREMENT_TOLERANCE * c_scale * x_scale;
        self.factorisations = 0;
        let (mut last_full, mut last_decrement) = (false, f64::INFINITY);
        let mut reuse_allowed = true;
        let mut compare_decrement = f64::INFINITY;
        // Whether the factor is of this solve's matrix at the current σ.
        let mut factor_current = false;
        let inner_tol = decrement_tol;
        let cone_tol = PRIMAL_TOLERANCE * (1.0 + self.limit);
        let gap_tol = GAP_TOLERANCE * c_scale * x_scale;
        let b_scale = 1.0 + lo.iter().chain(hi).fold(0.0f64, |a, b| a.max(b.abs()));
        // A soft side's violation costs ρ per m/s: its tolerance is ρ
        // times tighter so that the cost is as accurate as the cone's.
        let rho = self.penalty.filter(|r| r.is_finite()).unwrap_or(1.0);
        let speed_tol = PRIMAL_TOLERANCE * b_scale / rho.max(1.0);
        self.newton_steps = 0;
        let mut previous_res = f64::INFINITY;
        for _outer in 0..MAX_OUTER {
            // Inner: minimise L(·; y, v, σ) by semismooth Newton, until
            // the gradient or the Newton decrement −gᵀd is negligible.
            let (mut cone_res, mut speed_res);
            loop {
                let gn;
                (gn, cone_res, speed_res) = self.gradient(a0, lo, hi);
                if gn <= dual_tol {
                    break;
                }
                if self.newton_steps == MAX_NEWTON_STEPS {
                    return Err(ControlError::Solver(format!(
                        "cone ALM: no convergence in {MAX_NEWTON_STEPS} Newton steps \
                         (gradient {gn:.1e}, residual {:.1e})",
                        cone_res.max(speed_res)
                    )));
                }
                self.newton_steps += 1;
                // In the local phase (last step full, its decrement small,
                // the active set the one factored) the matrix changes only
                // in the active stages' curvature: its factor is reused.
                let reuse = reuse_allowed
                    && last_full
                    && factor_current
                    && last_decrement <= REUSE_DECREMENT * c_scale * x_scale
                    && self.active == self.factored_active;
                reuse_allowed = true;
                if !reuse {
                    self.assemble(lo, hi);
                    self.chol.factor_taking(&mut self.kkt)?;
                    self.factorisations += 1;
                    self.factored_active.clone_from(&self.active);
                    factor_current = true;
                }
                for (d, g) in self.d.iter_mut().zip(&self.g) {
                    *d = -g;
                }
                self.chol.solve_in_place(&mut self.d)?;
                let decrement: f64 = -self.g.iter().zip(&self.d).map(|(g, d)| g * d).sum::<f64>();
                if (decrement.is_nan() || decrement <= 0.0) && reuse {
                    // The old factor no longer gives a descent direction.
                    last_full = false;
                    continue;
                }
                if reuse && decrement > 0.1 * compare_decrement {
                    // The old factor converges slowly here: refactor next.
                    reuse_allowed = false;
                }
                last_decrement = decrement;
                compare_decrement = decrement;
                // Inexact inner solves while the multipliers are far off:
                // the subproblem's error (≈ decrement/2) need only be small
                // against the change the next update will make, σ·res².
                let loose = self.sigma * (INEXACT * cone_res).powi(2)
                    + self.sigma_speed() * (INEXACT * speed_res).powi(2);
                if decrement <= inner_tol.max(loose) {
                    // Converged to rounding (or enough for this update):
                    // the full step, and done.
                    for (x, d) in self.x.iter_mut().zip(&self.d) {
                        *x += d;
                    }
                    self.px_current = false;
                    (_, cone_res, speed_res) = self.gradient(a0, lo, hi);
                    break;
                }
                last_full = self.line_search(lo, hi)?;
                if last_full && !reuse && decrement <= LOCAL_STOP * c_scale * x_scale {
                    // A full step from a small decrement: the next one is
                    // of its square (Newton's local rate), below tolerance.
                    (_, cone_res, speed_res) = self.gradient(a0, lo, hi);
                    break;
                }
            }
            let gap = self.residual_cost(lo, hi);
            // Multiplier update (the gradient above is the Lagrangian's
            // with the updated multipliers: stationarity holds).
            self.y.copy_from_slice(&self.y_next);
            for k in 0..m {
                let h = self.hx[k];
                for j in 0..2 {
                    let t = if j == 0 { h - hi[k] } else { lo[k] - h };
                    self.v[k][j] = self.side_multiplier(self.v[k][j], t);
                }
            }
            if cone_res <= cone_tol && speed_res <= speed_tol && gap <= gap_tol {
                if self.x.iter().any(|v| !v.is_finite()) {
                    return Err(ControlError::Solver("cone ALM: non-finite iterate".into()));
                }
                return Ok(self.newton_steps);
            }
            let res = (cone_res / cone_tol).max(speed_res / speed_tol);
            if res > 1.0 && res > 0.1 * previous_res && self.sigma < self.tuning.sigma_max {
                self.sigma = (self.sigma * SIGMA_GROWTH).min(self.tuning.sigma_max);
                factor_current = false;
            }
            // The multipliers moved: the next decrement is not comparable.
            compare_decrement = f64::INFINITY;
            previous_res = res;
        }
        Err(ControlError::Solver(
            "cone ALM: no convergence in the multiplier updates".into(),
        ))
    }

    /// Armijo backtracking on L along d from x (u, hx, g current); moves x.
    /// Returns whether the full step was taken.
    fn line_search(&mut self, lo: &[f64], hi: &[f64]) -> Result<bool, ControlError> {
        self.apply_p(Vector::D);
        let slope: f64 = self.g.iter().zip(&self.d).map(|(g, d)| g * d).sum();
        if slope.is_nan() || slope >= 0.0 {
            // Not a descent direction: the factor is too inexact to go on.
            return Err(ControlError::Solver(format!(
                "cone ALM: no descent (slope {slope:.1e})"
            )));
        }
        // Quadratic part along d: α·(Px + c)·d + ½α²·dᵀPd.
        let lin: f64 = self
            .px
            .iter()
            .zip(&self.c)
            .zip(&self.d)
            .map(|((p, c), d)| (p + c) * d)
            .sum();
        let curv: f64 = self.pd.iter().zip(&self.d).map(|(p, d)| p * d).sum();
        Self::accelerations(self.inv_dt2, &self.d, &mut self.du);
        for k in 0..self.rows.len() {
            self.hd[k] = self.rows[k].dot(&self.d);
        }
        let base = self.penalty_value;
        let mut alpha = 1.0;
        for _ in 0..MAX_HALVINGS {
            let value =
                alpha * lin + 0.5 * alpha * alpha * curv + self.penalty_terms(alpha, lo, hi);
            if value <= base + ARMIJO * alpha * slope {
                self.step(alpha);
                return Ok(alpha == 1.0);
            }
            alpha *= 0.5;
        }
        // No decrease measurable: the merit is flat to rounding here, where
        // the full Newton step is the best guess.
        self.step(1.0);
        Ok(true)
    }

    /// `x += α·d`, and `P·x` with it from `P·d` (both by differencing,
    /// so the sum keeps their accuracy).
    fn step(&mut self, alpha: f64) {
        for (x, d) in self.x.iter_mut().zip(&self.d) {
            *x += alpha * d;
        }
        for (p, d) in self.px.iter_mut().zip(&self.pd) {
            *p += alpha * d;
        }
    }
}

/// Which vector [`ConeAlm::apply_p`] multiplies.
#[derive(Debug, Clone, Copy)]
enum Vector {
    X,
    D,
}
