//! The pair's start from a condensed interior point
//! ([`BandedAlm::interior_start`]): the tilt cone with hard rows (the
//! tilt rate's), whose multipliers the augmented Lagrangian's first-order
//! updates find slowly — a chain of rate rows from the sent command takes
//! it 40–680 Newton steps from zero multipliers, and 1–4 from the
//! optimum's.
//!
//! Mehrotra's predictor-corrector on the QP in the free outputs alone (the
//! unknowns x of [`BandedAlm`]), so that its Newton matrix is the
//! augmented Lagrangian's own, `P + Σ G_fᵀ J_f G_f + Σ w_r·h_r h_rᵀ`, with
//! the disc's barrier block `J_f = z_f·I + (z_f/s_f)·u_f u_fᵀ` (the disc
//! `c_f = ½(‖u_f‖² − A_f²) ≤ 0`, `u_f = G_f·x + a_0`) and the rows' `z/s`
//! per side: one banded Cholesky of 2n unknowns per iteration, against
//! the stage interior point's LDLᵀ of 6n (`super::super::cone_qp`). Soft
//! rows are held hard here (the funnel keeps every row feasible); their
//! multipliers are handed over clamped to the penalty.
//!
//! P's condition number (near 1e10) limits its directions to about six
//! digits, so its plan is not the answer: its iterate and multipliers
//! (`y_f = z_f·u_f`, the rows' `[z_upper, z_lower]`) are the augmented
//! Lagrangian's start, which ends from there in a few Newton steps.
//!
//! Each constraint is scaled to P's (`w = √P_max / ‖gradient‖`, as the box's
//! condensed interior point, `active_set/interior.rs`), so that one floor
//! and one gap serve the discs (m²/s⁴) and the rows (m/s, m/s²).
//!
//! **Two starts.** A cold solve's ([`BandedAlm::interior_start`]): from
//! the funnel's witness (the caller's iterate), its slacks the gaps
//! floored at half the largest and its multipliers centred on them. A
//! warm solve that did not end within its Newton steps restarts
//! ([`BandedAlm::interior_restart`]) from its own iterate and multipliers,
//! floored at a tenth of that floor: on the corner bench at N = 200 the
//! interior point's share of such a tick went from 839 to 513 µs on the
//! mean (17.2 to 10.2 iterations), the cone with the tilt rate's p99 from
//! ~1.75 to ~1.49 ms.

use super::super::bounds::Row;
use super::{BandedAlm, StageSet};
use crate::ControlError;

/// Entries of one row's outer product `hhᵀ` on and below the diagonal
/// (five entries at most: 15).
const PAIRS: usize = 15;

/// Iterations at most; none converged by then is no start (a tight rate
/// from rest took 41: the start's floored slacks leave the rate rows far
/// from feasible; a rate of 0.5° a tick bringing back a command 3.2 m/s²
/// outside an 8° disc took 68, the proptest's case `cc 3a4a7ba7…` of
/// `the_interior_start_hands_over_stationary_multipliers`; the corner's
/// ticks take 12–24).
const MAX_ITERATIONS: usize = 100;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// The start's slacks are floored at this fraction of the largest scaled
/// gap, the multipliers centred on them (the box's condensed interior
/// point's value).
const START_FLOOR: f64 = 0.5;
/// The restart's floor ([`BandedAlm::interior_restart`]): its slacks and
/// multipliers are floored at this fraction of the cold start's floor, so
/// that the iterate and the multipliers held keep most of what they know
/// (on the corner bench at N = 200, 0.1 and 0.2 took the restarts from
/// 839 µs to 513–523 µs on the mean; 0.05 and 0.03 to 543–548; 0.001 to
/// 780: docs/performance-log.md, "The interior point restarted from where the
/// warm solve stopped").
const RESTART_FLOOR: f64 = 0.1;
/// Ends when the mean complementarity is below this fraction of the
/// start's and the primal residuals below [`PRIMAL_TOLERANCE`] of the
/// scaled bounds'.
const GAP_REDUCTION: f64 = 1e-8;
/// Primal residual accepted, relative to the largest scaled bound.
const PRIMAL_TOLERANCE: f64 = 1e-6;
/// Should the end game's barrier terms make the Newton matrix fail to
/// factor, an iterate whose mean complementarity has fallen this far is
/// handed over all the same.
const FALLEN_ENOUGH: f64 = 1e-6;

/// Relative shift of the Newton matrix's diagonal when it does not factor
/// as assembled: in the end game the barrier terms of a chain of active
/// rate rows and discs grow to ~1e12 of P's, and rounding can take a
/// pivot below zero. Two draws of
/// `the_interior_start_hands_over_stationary_multipliers` (`cc b76fa06f…`:
/// 33.7° cone, 0.5° a tick, from 5.5 m/s; `cc 6a4b410d…`: 34.2°) failed
/// so (the first at a gap of 9.4e-6 of its start) and were no start;
/// with 1e-15, 1e-14 or 1e-13 both converge and hand over multipliers
/// stationary to 1e-9, with 1e-12 the second only to 3.4e-9.
const REGULARISATION: f64 = 1e-14;

/// Slack, multiplier, primal residual, complementarity right-hand side
/// and steps of one scaled inequality `g̃ + s = 0` (a disc, or a row's
/// side `w·(±h·x − b) + s = 0`).
#[derive(Debug, Clone, Copy, Default)]
struct Ineq {
    s: f64,
    z: f64,
    r: f64,
    rc: f64,
    ds: f64,
    dz: f64,
    /// Whether the side exists (a row's infinite bound: no).
    on: bool,
}

/// Storage of [`BandedAlm::interior_start`] (allocated with the solver).
#[derive(Debug, Clone)]
pub(super) struct InteriorStart {
    /// Per stage: the disc, its scale w_f, `u_f` and `G_f·dx`.
    discs: Vec<Ineq>,
    disc_w: Vec<f64>,
    u: Vec<[f64; 2]>,
    gdx: Vec<[f64; 2]>,
    /// Per row: its sides `[upper, lower]` and its scale w_r (fixed with
    /// the rows and P).
    sides: Vec<[Ineq; 2]>,
    row_w: Vec<f64>,
    /// Dual residual, right-hand side / step, stage scratch.
    rd: Vec<f64>,
    dx: Vec<f64>,
    e: Vec<[f64; 2]>,
    jac: Vec<[[f64; 2]; 2]>,
    /// Per row, [`PAIRS`] entries of `hhᵀ` on and below the diagonal: the
    /// index in the Newton matrix's lower band and the product of the two
    /// coefficients (0 past the row's own).
    outer: Vec<[(usize, f64); PAIRS]>,
}

impl InteriorStart {
    /// Storage for n stages, the rows and `size` unknowns, the Newton
    /// matrix's half-bandwidth `band` and P's largest diagonal entry
    /// `diag_max` (the rows' scales).
    pub(super) fn new(n: usize, rows: &[Row], size: usize, band: usize, diag_max: f64) -> Self {
        let m = rows.len();
        let root = diag_max.sqrt();
        let row_w = rows
            .iter()
            .map(|row| {
                let norm = row.coef[..row.len]
                    .iter()
                    .map(|c| c * c)
                    .sum::<f64>()
                    .sqrt();
                root / norm.max(f64::MIN_POSITIVE)
            })
            .collect();
        let w = band + 1;
        let outer = rows
            .iter()
            .map(|row| {
                let mut o = [(0usize, 0.0); PAIRS];
                let mut k = 0;
                for a in 0..row.len {
                    for b in 0..row.len {
                        let (i, j) = (row.idx[a], row.idx[b]);
                        if i >= j && i - j <= band && k < PAIRS {
                            o[k] = (i * w + (i - j), row.coef[a] * row.coef[b]);
                            k += 1;
                        }
                    }
                }
                o
            })
            .collect();
        Self {
            outer,
            discs: vec![Ineq::default(); n],
            disc_w: vec![0.0; n],
            u: vec![[0.0; 2]; n],
            gdx: vec![[0.0; 2]; n],
            sides: vec![[Ineq::default(); 2]; m],
            row_w,
            rd: vec![0.0; size],
            dx: vec![0.0; size],
            e: vec![[0.0; 2]; n],
            jac: vec![[[0.0; 2]; 2]; n],
        }
    }
}

/// Upper and lower side's sign on `h·x`.
const SIGN: [f64; 2] = [1.0, -1.0];

impl BandedAlm {
    /// The pair's start from the condensed interior point (module docs),
    /// from the iterate held ([`BandedAlm::set_start`]) for the linear term
    /// `c` (as [`BandedAlm::solve`]'s), fixed relative accelerations `a0`
    /// [m/s²] and row bounds `lo ≤ h·x ≤ hi`, its slacks and multipliers
    /// centred on the floor of its gaps: on
    /// convergence the iterate and the multipliers become its solution's
    /// and its iterations are returned; `None` (the iterate unspecified,
    /// the multipliers unchanged) when it does not converge or the problem
    /// is not the pair's discs with rows.
    pub fn interior_start(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<Option<usize>, ControlError> {
        self.interior_start_from(c, a0, lo, hi, false)
    }

    /// [`BandedAlm::interior_start`] restarted from what a solve that did
    /// not end left: the iterate held and the multipliers held (`z_f =
    /// ‖y_f‖/(w_f‖u_f‖)` per disc, `v/w_r` per row side), its slacks the
    /// gaps, each floored at `RESTART_FLOOR` (0.1) of the cold start's floor.
    /// Its stopping test is the cold start's (the same gap reduction from
    /// the cold start's complementarity).
    pub fn interior_restart(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<Option<usize>, ControlError> {
        self.interior_start_from(c, a0, lo, hi, true)
    }

    /// [`BandedAlm::interior_start`] (`restart` false) or
    /// [`BandedAlm::interior_restart`].
    fn interior_start_from(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
        restart: bool,
    ) -> Result<Option<usize>, ControlError> {
        let StageSet::Disc(radius) = &self.stages else {
            return Ok(None);
        };
        let Some(ip) = self.interior.as_mut() else {
            return Ok(None);
        };
        if lo.len() != self.rows.len() || hi.len() != self.rows.len() || c.len() != self.ws.c.len()
        {
            return Err(super::super::problem::invalid(
                "ALM interior start",
                "c with K·n entries, one bound per row",
            ));
        }
        self.ws.c.copy_from_slice(c);
        // The discs' scales: P's largest diagonal entry against the
        // gradient's norm at the edge of the radius (‖G_fᵀu‖ ≤ √6·A/δt²);
        // the rows' are fixed (`InteriorStart::new`).
        let root = self.diag_max.sqrt();
        let mut bound_scale = 0.0f64;
        for (w, a) in ip.disc_w.iter_mut().zip(radius) {
            *w = root / (6f64.sqrt() * self.inv_dt2 * a.max(1e-3));
            bound_scale = bound_scale.max(*w * 0.5 * a * a);
        }
        // The start: the gaps (the residuals with s = 0), floored at θ of
        // the largest; z = θ²/s.
        for d in &mut ip.discs {
            (d.on, d.s, d.z) = (true, 0.0, 0.0);
        }
        for (r, sides) in ip.sides.iter_mut().enumerate() {
            for (side, b) in sides.iter_mut().zip([hi[r], -lo[r]]) {
                (side.on, side.s, side.z) = (b.is_finite(), 0.0, 0.0);
                if side.on {
                    bound_scale = bound_scale.max(ip.row_w[r] * b.abs());
                }
            }
        }
        self.interior_residuals(a0, lo, hi, 1);
        let Some(ip) = self.interior.as_mut() else {
            return Ok(None);
        };
        let mut largest = 0.0f64;
        for q in ip.discs.iter_mut().chain(ip.sides.iter_mut().flatten()) {
            if q.on {
                q.s = -q.r;
                largest = largest.max(q.s.abs());
            }
        }
        let theta = (START_FLOOR * largest).max(1e-12);
        let count = ip.discs.len() + ip.sides.iter().flatten().filter(|s| s.on).count();
        if restart {
            let floor = RESTART_FLOOR * theta;
            for (f, d) in ip.discs.iter_mut().enumerate() {
                let (y, u) = (self.warm.y[f], ip.u[f]);
                let z = y[0].hypot(y[1]) / (ip.disc_w[f] * u[0].hypot(u[1]));
                d.s = d.s.max(floor);
                d.z = if z.is_finite() { z.max(floor) } else { floor };
            }
            for (sides, (v, w)) in ip.sides.iter_mut().zip(self.warm.v.iter().zip(&ip.row_w)) {
                for (q, v) in sides.iter_mut().zip(v) {
                    if q.on {
                        let z = v / w;
                        q.s = q.s.max(floor);
                        q.z = if z.is_finite() { z.max(floor) } else { floor };
                    } else {
                        (q.s, q.z) = (1.0, 0.0);
                    }
                }
            }
        } else {
            for q in ip.discs.iter_mut().chain(ip.sides.iter_mut().flatten()) {
                if q.on {
                    q.s = q.s.max(theta);
                    q.z = theta * theta / q.s;
                } else {
                    (q.s, q.z) = (1.0, 0.0);
                }
            }
        }
        // The stopping test's reference: the cold start's complementarity.
        let mu0 = theta * theta;
        let primal_tol = PRIMAL_TOLERANCE * bound_scale.max(1.0);
        for iteration in 0..MAX_ITERATIONS {
            let (mu, primal) = self.interior_residuals(a0, lo, hi, count);
            if !(mu.is_finite() && primal.is_finite()) {
                return Ok(None);
            }
            if mu <= GAP_REDUCTION * mu0 && primal <= primal_tol {
                self.interior_hand_over();
                return Ok(Some(iteration));
            }
            if !self.interior_step(mu, count)? {
                if mu <= FALLEN_ENOUGH * mu0 {
                    self.interior_hand_over();
                    return Ok(Some(iteration));
                }
                return Ok(None);
            }
        }
        Ok(None)
    }

    /// The residuals at the iterate: per disc `u_f`, `r = w·c + s`; per
    /// row side `r = w·(±h·x − b) + s`; the dual residual `rd = P·x + c +
    /// Σ w_f z_f G_fᵀu_f + Σ w_r (z_u − z_l) h_r`. Returns the mean
    /// complementarity and the largest primal residual.
    fn interior_residuals(
        &mut self,
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
        count: usize,
    ) -> (f64, f64) {
        let StageSet::Disc(radius) = &self.stages else {
            return (f64::NAN, f64::NAN);
        };
        let Some(ip) = self.interior.as_mut() else {
            return (f64::NAN, f64::NAN);
        };
        let x = &self.ws.x;
        Self::accelerations(2, self.inv_dt2, x, &mut ip.u, 0);
        let (mut gap, mut primal) = (0.0, 0.0f64);
        for (f, d) in ip.discs.iter_mut().enumerate() {
            // Relative to the disc's centre: c_f and its gradient
            // G_fᵀ(u_f − o_f).
            let u = &mut ip.u[f];
            u[0] += a0[0] - self.centre[f][0];
            u[1] += a0[1] - self.centre[f][1];
            let c = 0.5 * (u[0] * u[0] + u[1] * u[1] - radius[f] * radius[f]);
            d.r = ip.disc_w[f] * c + d.s;
            primal = primal.max(d.r.abs());
            gap += d.s * d.z;
            let wz = ip.disc_w[f] * d.z;
            ip.e[f] = [wz * u[0], wz * u[1]];
        }
        // P·x by differencing, as the augmented Lagrangian's own
        // (`BandedAlm::apply_p`): cheaper than the band's product (the
        // cone with the tilt rate's constrained p99 on the corner bench,
        // the least of 12 alternated runs: 450 → 422 µs at N = 100, 1111
        // → 1051 µs at N = 200).
        for (i, axis) in self.axes.iter().enumerate() {
            axis.apply_hessian_strided(x, 2, i, 2.0, 0, &mut self.ws.p_work, &mut ip.rd);
        }
        for (rd, c) in ip.rd.iter_mut().zip(&self.ws.c) {
            *rd += c;
        }
        Self::add_transposed(2, self.inv_dt2, &ip.e, &mut ip.rd, 0);
        for (r, row) in self.rows.iter().enumerate() {
            let hx: f64 = (0..row.len).map(|k| row.coef[k] * x[row.idx[k]]).sum();
            let b = [hi[r], -lo[r]];
            let mut t = 0.0;
            for (j, side) in ip.sides[r].iter_mut().enumerate() {
                if !side.on {
                    continue;
                }
                side.r = ip.row_w[r] * (SIGN[j] * hx - b[j]) + side.s;
                primal = primal.max(side.r.abs());
                gap += side.s * side.z;
                t += SIGN[j] * side.z;
            }
            let wt = ip.row_w[r] * t;
            for k in 0..row.len {
                ip.rd[row.idx[k]] += wt * row.coef[k];
            }
        }
        (gap / count.max(1) as f64, primal)
    }

    /// One predictor-corrector step from the residuals; false when the
    /// Newton matrix does not factor.
    fn interior_step(&mut self, mu: f64, count: usize) -> Result<bool, ControlError> {
        if !self.interior_factor(0.0) && !self.interior_factor(REGULARISATION) {
            return Ok(false);
        }
        // Predictor (affine): rc = s·z.
        self.interior_set_rc(|q| q.s * q.z);
        self.interior_direction()?;
        let alpha = self.interior_step_to_boundary(1.0);
        let Some(ip) = self.interior.as_ref() else {
            return Ok(false);
        };
        let mu_aff = ip
            .discs
            .iter()
            .chain(ip.sides.iter().flatten())
            .filter(|q| q.on)
            .map(|q| (q.s + alpha * q.ds) * (q.z + alpha * q.dz))
            .sum::<f64>()
            / count.max(1) as f64;
        let centring = (mu_aff / mu).clamp(0.0, 1.0).powi(3);
        // Corrector: rc = s·z + Δs_aff·Δz_aff − σμ.
        self.interior_set_rc(|q| q.s * q.z + q.ds * q.dz - centring * mu);
        self.interior_direction()?;
        let alpha = self.interior_step_to_boundary(STEP_FRACTION);
        let Some(ip) = self.interior.as_mut() else {
            return Ok(false);
        };
        for (x, dx) in self.ws.x.iter_mut().zip(&ip.dx) {
            *x += alpha * dx;
        }
        for q in ip.discs.iter_mut().chain(ip.sides.iter_mut().flatten()) {
            if q.on {
                q.s += alpha * q.ds;
                q.z += alpha * q.dz;
            }
        }
        Ok(true)
    }

    /// Assembles and factors `P + Σ G_fᵀ J_f G_f + Σ (z/s)·w²·hhᵀ`, its
    /// diagonal times `1 + regularise`.
    fn interior_factor(&mut self, regularise: f64) -> bool {
        let Some(ip) = self.interior.as_mut() else {
            return false;
        };
        for (f, (j, d)) in ip.jac.iter_mut().zip(&ip.discs).enumerate() {
            let w = ip.disc_w[f];
            let u = ip.u[f];
            let (a, b) = (w * d.z, w * w * d.z / d.s);
            *j = [
                [a + b * u[0] * u[0], b * u[0] * u[1]],
                [b * u[1] * u[0], a + b * u[1] * u[1]],
            ];
        }
        self.kkt.clone_from(&self.base);
        let w = self.kkt.bandwidth() + 1;
        let sc = self.inv_dt2 * self.inv_dt2;
        super::lagrangian::add_stage_blocks::<2>(&ip.jac, sc, w, self.kkt.lower_mut(), 0);
        let lower = self.kkt.lower_mut();
        for (r, outer) in ip.outer.iter().enumerate() {
            let weight: f64 = ip.sides[r]
                .iter()
                .filter(|q| q.on)
                .map(|q| q.z / q.s)
                .sum::<f64>()
                * ip.row_w[r]
                * ip.row_w[r];
            for &(k, prod) in outer {
                lower[k] += weight * prod;
            }
        }
        if regularise > 0.0 {
            for d in lower.iter_mut().step_by(w) {
                *d *= 1.0 + regularise;
            }
        }
        self.factored = super::Factored::Stale;
        self.chol.factor_taking(&mut self.kkt).is_ok()
    }

    /// Sets each inequality's complementarity right-hand side.
    fn interior_set_rc(&mut self, rc: impl Fn(&Ineq) -> f64) {
        if let Some(ip) = self.interior.as_mut() {
            for q in ip.discs.iter_mut().chain(ip.sides.iter_mut().flatten()) {
                q.rc = if q.on { rc(q) } else { 0.0 };
            }
        }
    }

    /// The Newton direction for the held right-hand sides: `M·dx = −rd −
    /// Σ ∇g̃·(z·r − rc)/s`, then per inequality `Δs = −r − ∇g̃·dx`, `Δz =
    /// (−rc − z·Δs)/s`.
    fn interior_direction(&mut self) -> Result<(), ControlError> {
        let Some(ip) = self.interior.as_mut() else {
            return Ok(());
        };
        for (dx, rd) in ip.dx.iter_mut().zip(&ip.rd) {
            *dx = -rd;
        }
        for (f, d) in ip.discs.iter().enumerate() {
            let k = -ip.disc_w[f] * (d.z * d.r - d.rc) / d.s;
            ip.e[f] = [k * ip.u[f][0], k * ip.u[f][1]];
        }
        Self::add_transposed(2, self.inv_dt2, &ip.e, &mut ip.dx, 0);
        for (r, row) in self.rows.iter().enumerate() {
            let mut t = 0.0;
            for (j, q) in ip.sides[r].iter().enumerate() {
                if q.on {
                    t -= SIGN[j] * (q.z * q.r - q.rc) / q.s;
                }
            }
            let wt = ip.row_w[r] * t;
            for k in 0..row.len {
                ip.dx[row.idx[k]] += wt * row.coef[k];
            }
        }
        self.chol.solve_in_place(&mut ip.dx)?;
        Self::accelerations(2, self.inv_dt2, &ip.dx, &mut ip.gdx, 0);
        for (f, d) in ip.discs.iter_mut().enumerate() {
            let u = ip.u[f];
            let g = ip.disc_w[f] * (u[0] * ip.gdx[f][0] + u[1] * ip.gdx[f][1]);
            d.ds = -d.r - g;
            d.dz = (-d.rc - d.z * d.ds) / d.s;
        }
        for (r, row) in self.rows.iter().enumerate() {
            let hd: f64 = (0..row.len).map(|k| row.coef[k] * ip.dx[row.idx[k]]).sum();
            for (j, q) in ip.sides[r].iter_mut().enumerate() {
                if q.on {
                    q.ds = -q.r - ip.row_w[r] * SIGN[j] * hd;
                    q.dz = (-q.rc - q.z * q.ds) / q.s;
                }
            }
        }
        Ok(())
    }

    /// The largest step in (0, 1] keeping every slack and multiplier
    /// positive, times `fraction`.
    fn interior_step_to_boundary(&self, fraction: f64) -> f64 {
        let Some(ip) = self.interior.as_ref() else {
            return 0.0;
        };
        let worst = ip
            .discs
            .iter()
            .chain(ip.sides.iter().flatten())
            .filter(|q| q.on)
            .fold(1.0f64, |a, q| a.max(-q.ds / q.s).max(-q.dz / q.z));
        (fraction / worst).min(1.0)
    }

    /// The multipliers of the converged iterate, in the augmented
    /// Lagrangian's terms: `y_f = w_f z_f u_f` per stage, `[w z_u, w z_l]`
    /// per row clamped to its penalty; σ its warm value.
    fn interior_hand_over(&mut self) {
        let Some(ip) = self.interior.as_mut() else {
            return;
        };
        // `u` holds u_f of the last residuals (the iterate's: a failed
        // step does not move it).
        for (f, (y, d)) in self.warm.y.iter_mut().zip(&ip.discs).enumerate() {
            let wz = ip.disc_w[f] * d.z;
            *y = [wz * ip.u[f][0], wz * ip.u[f][1]];
        }
        for (r, (v, sides)) in self.warm.v.iter_mut().zip(&ip.sides).enumerate() {
            let rho = self.row_penalty[r];
            *v = [0, 1].map(|j| {
                if sides[j].on {
                    (ip.row_w[r] * sides[j].z).clamp(0.0, rho)
                } else {
                    0.0
                }
            });
        }
        self.warm.y_last_valid = false;
        self.handed_over = true;
        self.sigma = self.tuning.sigma;
        self.ws.px_current = false;
    }

    /// The KKT stationarity of the iterate and the multipliers held,
    /// `max |P·x + c + Σ G_fᵀ·y_f + Σ h_r·(v_u − v_l)|` over the scale of
    /// its largest term, `max |c| + P_max·max |x|` (P·x's entries reach
    /// 1e10: its rounding is the floor) (tests: the interior start's
    /// hand-over).
    #[cfg(test)]
    pub(crate) fn stationarity(&self) -> f64 {
        let size = self.ws.x.len();
        let mut g = vec![0.0; size];
        self.base.mul_vec(&self.ws.x, &mut g);
        for (g, c) in g.iter_mut().zip(&self.ws.c) {
            *g += c;
        }
        Self::add_transposed(self.k, self.inv_dt2, &self.warm.y, &mut g, 0);
        for (row, v) in self.rows.iter().zip(&self.warm.v) {
            for k in 0..row.len {
                g[row.idx[k]] += row.coef[k] * (v[0] - v[1]);
            }
        }
        let c_scale = 1.0 + self.ws.c.iter().fold(0.0f64, |a, c| a.max(c.abs()));
        let x_scale = self.ws.x.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        g.iter().fold(0.0f64, |a, v| a.max(v.abs())) / (c_scale + self.diag_max * x_scale)
    }
}
