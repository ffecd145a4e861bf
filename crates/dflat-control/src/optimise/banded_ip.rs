//! The banded primal-dual interior point shared by the box's and the
//! cone's fallbacks ([`BandedIp`]): one Mehrotra predictor-corrector loop
//! on a KKT system ordered by stage, so that it is banded and one
//! iteration is O(N). The two problems are data over it: the stage QP of
//! one axis ([`StageQp`](super::interior_point::StageQp)) and the
//! two-axis cone QP ([`ConeQp`](super::cone_qp::ConeQp)).
//!
//! # Variables and equality rows
//!
//! Variables as in [`ClarabelSolver`](super::ClarabelSolver) (clarabel):
//! per free output f = 0..n−1 and axis i the deviation `p_{i,f}` from the
//! zero-jerk baseline and the planned acceleration relative to the fixed
//! one `ã_{i,f}`, tied by the equality `Δ²p_{i,f}/δt² − ã_{i,f} = 0`
//! (multiplier `λ_{i,f}`); cost `½xᵀPx + cᵀx` with `P = 2q` on p and the
//! jerk and smoothness terms on ã ([`AxisCost`]). This formulation is well
//! scaled — the raw one in p alone has a Hessian with a condition number
//! near 1e10, on which an interior-point method stalls. With k axes the
//! stage is `[λ_0..λ_{k−1}, ã_0..ã_{k−1}, p_0..p_{k−1}]` ([`Stages`]): λ_f
//! reaches back to p_{f−2} (distance 4k), the jerk couples ã_f with
//! ã_{f−1} (3k), the smoothness term with ã_{f−2} (6k). The KKT matrix
//!
//! ```text
//! [ P + Σ barrier terms   Aᵀ ]
//! [ A                    −εI ]
//! ```
//!
//! is quasi-definite, so an LDLᵀ factorisation without pivoting exists
//! ([`BandedLdl`]); ε = 1e-12 (on the primal diagonal too) keeps it so
//! when q = 0 (its effect on the steps is far below the tolerances: a
//! refinement step against the unregularised matrix changed no digit of
//! the first planned jerk and cost a third of the time, so there is none).
//!
//! # Inequality families (data of [`BandedIp`])
//!
//! * Interval rows `lo ≤ g·x ≤ hi` (a few entries each, `Row`),
//!   one slack and multiplier per side, adding `(z_u/s_u + z_l/s_l)·ggᵀ`.
//!   A soft side `h·x ≤ b + σ` (σ ≥ 0, exact penalty ρσ; slack s,
//!   multipliers z of the row and w of σ ≥ 0) is eliminated in closed
//!   form: it adds `d·hhᵀ` with `d = (z/s)(w/σ)/(z/s + w/σ)` — the hard
//!   row's `z/s` in series with the penalty's `w/σ`.
//! * Discs: per stage the disc `c_f = ½(‖u_f‖² − A_f²) ≤ 0`,
//!   `u_f = ã_f + a_0` on the two axes' accelerations, with slack s_f and
//!   multiplier z_f, adding `z_f·I + (z_f/s_f)·u_f·u_fᵀ` to the (ã_x, ã_y)
//!   block of stage f: 2×2, inside the band.
//!
//! # The loop
//!
//! Mehrotra's predictor-corrector with one step length for primal and
//! dual, 99 % of the step to the boundary. Converged when every residual
//! is within its tolerance (the merit ≤ 1). The dual residual cannot get
//! much below ~1e-10 relative (rounding in K, whose barrier terms grow
//! without bound as the gap closes) and grows again as they do: the
//! targets are a gap of 1e-9 with the dual residual at 1e-8 (clarabel's
//! defaults: 1e-8 for both), the centring target is floored at a tenth
//! of the gap's tolerance so that the barrier terms stop growing once
//! the gap is met, and the best iterate is kept in case they
//! are never met together; it is taken when it is acceptable (merit ≤
//! 100) and not improved on for a few iterations, at the iteration limit,
//! or when the end game's barrier terms make the KKT matrix numerically
//! singular.
//!
//! All storage is allocated in `BandedIp::new`.

use super::banded::SymBand;
use super::bounds::Row;
use super::cascade::SolverFault;
use crate::ControlError;

pub use super::banded::BandedLdl;

/// Iterations without a better iterate after which the best one is taken.
const STALL_ITERATIONS: usize = 4;
/// Largest merit (residuals over their tolerances) a stalled or last
/// iterate may have and still be returned: residuals ≤ 100× the targets
/// (dual residual 1e-6, gap 1e-7 relative).
const ACCEPTABLE_MERIT: f64 = 100.0;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// Floor of the centring target `σμ`, as a fraction of the gap's
/// tolerance per complementarity pair: once the gap is within a tenth of
/// its tolerance, the barrier terms stop growing and the steps go on
/// reducing the dual residual (module docs, "The loop"). Without it a
/// draw of `constrained_solvers_match_clarabel_defaults` (N = 194, a
/// window faster than the speed bound) took the gap to 1e-25 of its
/// tolerance while the dual residual grew from 58 to 1e10 times its own,
/// and failed; with it, it converges at iteration 23.
const GAP_FLOOR: f64 = 0.1;
/// Relative tolerance of the equality and primal residuals.
const TOLERANCE: f64 = 1e-10;
/// Tolerance of the gap, relative to `1 + |objective|`.
const GAP_TOLERANCE: f64 = 1e-9;
/// Static regularisation of the KKT matrix.
const REGULARISATION: f64 = 1e-12;

/// `max |v_k|`.
fn norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, b| a.max(b.abs()))
}

/// The stage order of the KKT vector with `axes` axes: stage f holds
/// `[λ_{0,f}.., ã_{0,f}.., p_{0,f}..]`, one entry per axis each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stages {
    /// Number of axes (1: the stage QP, 2: the cone QP).
    pub axes: usize,
}

impl Stages {
    /// KKT entries per stage.
    pub const fn width(self) -> usize {
        3 * self.axes
    }
    /// KKT index of the multiplier λ_{axis, f}.
    pub const fn lambda(self, axis: usize, f: usize) -> usize {
        self.width() * f + axis
    }
    /// KKT index of ã_{axis, f}.
    pub const fn accel(self, axis: usize, f: usize) -> usize {
        self.width() * f + self.axes + axis
    }
    /// KKT index of p_{axis, f}.
    pub const fn output(self, axis: usize, f: usize) -> usize {
        self.width() * f + 2 * self.axes + axis
    }
}

/// One axis's cost: tracking weight and the ã block of P.
#[derive(Debug, Clone)]
pub struct AxisCost {
    /// Tracking weight q [1/m²].
    pub q: f64,
    /// The ã block of P, `[diag, (k−1, k), (k−2, k)]` per column
    /// (as the crate-internal `smoothness::accel_block` builds it).
    pub accel: Vec<[f64; 3]>,
}

/// One stage's disc: slack, multiplier, residual `c + s`, steps, and
/// `u = ã + a_0` at the current iterate.
#[derive(Debug, Clone, Copy, Default)]
struct Disc {
    s: f64,
    z: f64,
    r: f64,
    ds: f64,
    dz: f64,
    u: [f64; 2],
}

/// One side `h·x − σ + s = b` of a row (σ = 0, w unused when hard).
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

/// The residuals of an iterate (`BandedIp::residuals`).
#[derive(Debug, Clone, Copy, Default)]
struct Residuals {
    gap: f64,
    rp_cone: f64,
    rp: f64,
    rsig: f64,
    rd: f64,
    req: f64,
    a_max: f64,
    objective: f64,
}

/// The banded primal-dual interior point (module docs): the KKT system of
/// the cost and equality rows of [`Stages`], interval rows and per-stage
/// discs (either may be absent).
#[derive(Debug, Clone)]
pub struct BandedIp {
    stages: Stages,
    /// Stages (free outputs per axis).
    n: usize,
    max_iterations: usize,
    /// KKT matrix of the cost and equality rows (the residuals' M).
    base: SymBand,
    kkt: SymBand,
    ldl: BandedLdl,
    /// Disc radius per stage A_f [m/s²] (empty: no discs), the discs, and
    /// the fixed accelerations a_0 [m/s²] (u = ã + a_0).
    radius: Vec<f64>,
    discs: Vec<Disc>,
    a0: [f64; 2],
    /// The discs' centre per stage o_f [m/s²] (zeros unless set): the
    /// disc bounds `u_f − o_f`.
    centre: Vec<[f64; 2]>,
    rows: Vec<Row>,
    /// `[upper, lower]` per row; upper `g·x ≤ hi`, lower `−g·x ≤ −lo`.
    sides: Vec<[Side; 2]>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// The exact penalty ρ per row (`f64::INFINITY`: a hard row), and
    /// the largest finite one (0: none soft).
    penalty: Vec<f64>,
    rho_max: f64,
    /// Iterate, linear term, residual, step, right-hand side, best
    /// iterate.
    v: Vec<f64>,
    c: Vec<f64>,
    r: Vec<f64>,
    dv: Vec<f64>,
    rhs: Vec<f64>,
    best: Vec<f64>,
    /// Iterations of the last solve.
    iterations: usize,
}

impl BandedIp {
    /// The interior point for n ≥ 1 stages of
    /// `costs.len()` axes at step δt: the bound `rows`, each soft with the
    /// exact penalty ρ where its entry of `penalty` is finite (one per
    /// row; `f64::INFINITY`: hard), and discs of radius
    /// `disc` on the first two axes' accelerations; at most
    /// `max_iterations` iterations.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::optimise) fn new(
        n: usize,
        dt: f64,
        costs: &[&AxisCost],
        rows: Vec<Row>,
        penalty: Vec<f64>,
        disc: Option<f64>,
        max_iterations: usize,
    ) -> Self {
        let stages = Stages { axes: costs.len() };
        let size = stages.width() * n;
        let smooth = costs.iter().any(|a| a.accel.iter().any(|c| c[2] != 0.0));
        let bandwidth = (4 * stages.axes)
            .max(if smooth { 6 * stages.axes } else { 0 })
            .max(rows.iter().map(Row::span).max().unwrap_or(0));
        let mut base = SymBand::zeros(size, bandwidth);
        let inv_dt2 = 1.0 / (dt * dt);
        let (a_at, p_at) = (|i, f| stages.accel(i, f), |i, f| stages.output(i, f));
        for (i, ax) in costs.iter().enumerate() {
            for (f, &[d0, d1, d2]) in ax.accel.iter().enumerate().take(n) {
                base.add(p_at(i, f), p_at(i, f), 2.0 * ax.q);
                base.add(a_at(i, f), a_at(i, f), d0);
                if f >= 1 {
                    base.add(a_at(i, f - 1), a_at(i, f), d1);
                }
                if f >= 2 && d2 != 0.0 {
                    base.add(a_at(i, f - 2), a_at(i, f), d2);
                }
                // Δ²p_f/δt² − ã_f = 0 (p before the horizon is 0).
                let l = stages.lambda(i, f);
                for (back, w) in [1.0, -2.0, 1.0].into_iter().enumerate().take(f + 1) {
                    base.add(l, p_at(i, f - back), w * inv_dt2);
                }
                base.add(l, a_at(i, f), -1.0);
            }
        }
        let m = rows.len();
        assert_eq!(penalty.len(), m, "a penalty per row");
        let discs = if disc.is_some() { n } else { 0 };
        let rho_max = penalty
            .iter()
            .copied()
            .filter(|p| p.is_finite())
            .fold(0.0, f64::max);
        Self {
            stages,
            n,
            max_iterations,
            kkt: base.clone(),
            base,
            ldl: BandedLdl::new(size, bandwidth),
            radius: vec![disc.unwrap_or(0.0); discs],
            discs: vec![Disc::default(); discs],
            a0: [0.0; 2],
            centre: vec![[0.0; 2]; discs],
            rows,
            sides: vec![[Side::default(); 2]; m],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            penalty,
            rho_max,
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

    /// Stages n (free outputs per axis).
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of bound rows.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// The deviation `p_{axis, f}` of the current iterate (the solution
    /// after a successful solve).
    pub fn p(&self, axis: usize, f: usize) -> f64 {
        self.v[self.stages.output(axis, f)]
    }

    /// The current iterate (KKT order).
    pub fn iterate(&self) -> &[f64] {
        &self.v
    }

    /// The linear term of the cost (KKT length; zero on λ), to be set
    /// before a solve.
    pub fn linear_mut(&mut self) -> &mut [f64] {
        &mut self.c
    }

    /// The rows' multipliers `[upper, lower]` of the last iterate (≥ 0;
    /// the Lagrangian's `z_u·(g·x − hi) + z_l·(lo − g·x)`), in row order.
    pub fn duals(&self, out: &mut [[f64; 2]]) {
        for (o, [up, low]) in out.iter_mut().zip(&self.sides) {
            *o = [up.z, low.z];
        }
    }

    /// The discs' multipliers of the last iterate as stage multipliers
    /// on the accelerations, `z_f·(u_f − o_f)` per stage (`u_f = ã_f +
    /// a_0` [m/s²], o_f the centre; the gradient of `c_f`): the augmented
    /// Lagrangian's `y_f` at the same optimum. No effect without discs.
    pub fn disc_duals(&self, out: &mut [[f64; 2]]) {
        let s = self.stages;
        for (f, (o, d)) in out.iter_mut().zip(&self.discs).enumerate() {
            let c = self.centre[f];
            let u = [
                self.v[s.accel(0, f)] + self.a0[0] - c[0],
                self.v[s.accel(1, f)] + self.a0[1] - c[1],
            ];
            *o = [d.z * u[0], d.z * u[1]];
        }
    }

    /// Sets the primal start from `p` (per axis, length n): ã from the
    /// equality, λ = 0.
    pub fn set_start(&mut self, p: &[&[f64]], dt: f64) {
        let inv_dt2 = 1.0 / (dt * dt);
        let s = self.stages;
        for (i, p) in p.iter().enumerate() {
            for f in 0..self.n {
                let pm1 = if f >= 1 { p[f - 1] } else { 0.0 };
                let pm2 = if f >= 2 { p[f - 2] } else { 0.0 };
                self.v[s.output(i, f)] = p[f];
                self.v[s.accel(i, f)] = (p[f] - 2.0 * pm1 + pm2) * inv_dt2;
                self.v[s.lambda(i, f)] = 0.0;
            }
        }
    }

    /// Sets the discs' radius per stage A_f [m/s²] (n entries, finite and
    /// > 0) for the next solves.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.radius.len())?;
        self.radius.copy_from_slice(radius);
        Ok(())
    }

    /// Sets the discs' centre per stage o_f [m/s²] (n entries, finite):
    /// the discs then bound `‖u_f − o_f‖ ≤ A_f`.
    pub fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        super::cone::check_centre(centre, self.centre.len())?;
        self.centre.copy_from_slice(centre);
        Ok(())
    }

    /// Sets the rows' bounds (one pair per row, checked by the caller)
    /// and the discs' fixed accelerations a_0 [m/s²] for the next solve.
    pub fn set_bounds(&mut self, lo: &[f64], hi: &[f64], a0: [f64; 2]) {
        self.lo.copy_from_slice(lo);
        self.hi.copy_from_slice(hi);
        self.a0 = a0;
    }

    /// Cold-start slacks and multipliers for the current primal iterate.
    fn cold_duals(&mut self, b_scale: f64) {
        for (c, r) in self.discs.iter_mut().zip(&self.radius) {
            let a2 = 0.5 * r * r;
            c.s = a2;
            c.z = 1.0 / a2;
        }
        for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
            let g = row.dot(&self.v);
            let floor = (0.1 * (self.hi[k] - self.lo[k])).max(1e-3 * b_scale);
            for (j, sd) in side.iter_mut().enumerate() {
                // Distance to the bound along this side's direction.
                let room = if j == 0 {
                    self.hi[k] - g
                } else {
                    g - self.lo[k]
                };
                *sd = Side {
                    s: room.max(floor),
                    z: 1.0,
                    ..Side::default()
                };
                let rho = self.penalty[k];
                if rho.is_finite() {
                    sd.w = (rho - 1.0).max(1.0);
                    sd.sig = (-room).max(0.0) + floor / sd.w;
                }
            }
        }
    }

    /// Solves from the primal start ([`BandedIp::set_start`]), the linear
    /// term ([`BandedIp::linear_mut`]) and the bounds
    /// ([`BandedIp::set_bounds`]); slacks and multipliers start cold. On
    /// success the iterate is the solution and the result its iteration;
    /// [`ControlError::Solver`] when it does not converge.
    pub fn solve(&mut self) -> Result<usize, ControlError> {
        let c_scale = 1.0 + norm(&self.c);
        let b_scale = 1.0 + norm(&self.lo).max(norm(&self.hi));
        let cone_scale = 1.0 + self.radius.iter().fold(0.0f64, |a, r| a.max(r * r));
        let rho = self.rho_max;
        self.cold_duals(b_scale);
        let soft_rows = self.penalty.iter().filter(|p| p.is_finite()).count();
        let pairs = (self.discs.len() + 2 * self.rows.len() + 2 * soft_rows).max(1) as f64;

        // (lowest merit, its iteration); the iterate is in `best`.
        let mut best = (f64::INFINITY, 0usize);
        for iteration in 0..self.max_iterations {
            self.iterations = iteration;
            let r = self.residuals();
            if !(r.gap.is_finite()
                && r.rd.is_finite()
                && r.req.is_finite()
                && r.rp_cone.is_finite())
            {
                return Err(SolverFault::NonFinite.into());
            }
            // Each residual over its tolerance; converged at ≤ 1.
            let gap_target = GAP_TOLERANCE * (1.0 + r.objective.abs());
            let merit = (r.rd / (1e-8 * c_scale))
                .max(r.rsig / (1e-8 * (1.0 + rho)))
                .max(r.req / (TOLERANCE * (1.0 + r.a_max)))
                .max(r.rp / (TOLERANCE * b_scale))
                .max(r.rp_cone / (TOLERANCE * cone_scale))
                .max(r.gap / gap_target);
            if merit < best.0 {
                best = (merit, iteration);
                self.best.copy_from_slice(&self.v);
            }
            // Stalled: an acceptable best iterate not improved on for a few
            // iterations (far from the solution progress is not monotone).
            let stalled = best.0 <= ACCEPTABLE_MERIT && iteration >= best.1 + STALL_ITERATIONS;
            if merit <= 1.0 || stalled || iteration + 1 == self.max_iterations {
                if best.0 > ACCEPTABLE_MERIT {
                    break;
                }
                self.v.copy_from_slice(&self.best);
                return Ok(iteration);
            }
            self.assemble_kkt();
            if self.ldl.factor(&self.kkt).is_err() {
                // The end game's barrier terms (z/s up to ~1e20) can make
                // the KKT matrix numerically singular: an acceptable best
                // iterate is the answer then, as when stalled.
                if best.0 <= ACCEPTABLE_MERIT {
                    self.v.copy_from_slice(&self.best);
                    return Ok(iteration);
                }
                return Err(SolverFault::Factorisation.into());
            }
            self.mehrotra_step(r.gap, r.gap / pairs, GAP_FLOOR * gap_target / pairs);
        }
        Err(SolverFault::NotConverged {
            iterations: self.max_iterations,
        }
        .into())
    }

    /// The residuals at the iterate: `r = M·v + c + Σ z_f·u_f + Σ hᵀz`
    /// (the dual residual on p, ã; the equality residual A·x on λ), the
    /// discs' and rows' primal residuals, the gap, and the objective's
    /// size.
    fn residuals(&mut self) -> Residuals {
        let (s, n) = (self.stages, self.n);
        self.base.mul_vec(&self.v, &mut self.r);
        for (r, c) in self.r.iter_mut().zip(&self.c) {
            *r += c;
        }
        let mut out = Residuals::default();
        for (f, cs) in self.discs.iter_mut().enumerate() {
            let (ix, iy) = (s.accel(0, f), s.accel(1, f));
            // Relative to the centre: c_f's gradient on ã_f.
            let o = self.centre[f];
            cs.u = [
                self.v[ix] + self.a0[0] - o[0],
                self.v[iy] + self.a0[1] - o[1],
            ];
            let a2 = self.radius[f] * self.radius[f];
            cs.r = 0.5 * (cs.u[0] * cs.u[0] + cs.u[1] * cs.u[1] - a2) + cs.s;
            out.rp_cone = out.rp_cone.max(cs.r.abs());
            self.r[ix] += cs.z * cs.u[0];
            self.r[iy] += cs.z * cs.u[1];
            out.gap += cs.s * cs.z;
        }
        for (k, (row, side)) in self.rows.iter().zip(self.sides.iter_mut()).enumerate() {
            let g = row.dot(&self.v);
            let [up, low] = side;
            row.axpy(up.z - low.z, &mut self.r);
            up.r = g - up.sig + up.s - self.hi[k];
            low.r = -g - low.sig + low.s + self.lo[k];
            out.rp = out.rp.max(up.r.abs()).max(low.r.abs());
            out.gap += up.s * up.z + low.s * low.z;
            let rho = self.penalty[k];
            if rho.is_finite() {
                out.gap += up.sig * up.w + low.sig * low.w;
                out.rsig = out
                    .rsig
                    .max((rho - up.z - up.w).abs())
                    .max((rho - low.z - low.w).abs());
            }
        }
        for f in 0..n {
            for i in 0..s.axes {
                out.rd = out
                    .rd
                    .max(self.r[s.output(i, f)].abs())
                    .max(self.r[s.accel(i, f)].abs());
                out.req = out.req.max(self.r[s.lambda(i, f)].abs());
                out.a_max = out.a_max.max(self.v[s.accel(i, f)].abs());
            }
        }
        // ½xᵀPx + cᵀx = ½xᵀ(r − Aᵀλ − Gᵀz) + ½cᵀx (approximately, at
        // near-feasibility; only its size is used).
        let (c, v) = (&self.c, &self.v);
        out.objective = (0..n)
            .map(|f| {
                (0..s.axes)
                    .map(|i| {
                        let (a, p) = (s.accel(i, f), s.output(i, f));
                        0.5 * (c[p] * v[p] + c[a] * v[a])
                    })
                    .sum::<f64>()
            })
            .sum();
        out
    }

    /// K = M + the discs' 2×2 blocks + Σ d·hhᵀ ± ε.
    fn assemble_kkt(&mut self) {
        let (s, n) = (self.stages, self.n);
        self.kkt.clone_from(&self.base);
        for (f, cs) in self.discs.iter().enumerate() {
            let d = cs.z / cs.s;
            let [ux, uy] = cs.u;
            let (ix, iy) = (s.accel(0, f), s.accel(1, f));
            self.kkt.add(ix, ix, cs.z + d * ux * ux);
            self.kkt.add(iy, iy, cs.z + d * uy * uy);
            self.kkt.add(iy, ix, d * ux * uy);
        }
        for ((row, side), rho) in self.rows.iter().zip(&self.sides).zip(&self.penalty) {
            let soft = rho.is_finite();
            let d: f64 = side.iter().map(|sd| Self::side_weight(sd, soft)).sum();
            for a in 0..row.len {
                for b in 0..=a {
                    self.kkt
                        .add(row.idx[a], row.idx[b], d * row.coef[a] * row.coef[b]);
                }
            }
        }
        for k in 0..s.width() * n {
            let sign = if k % s.width() < s.axes { -1.0 } else { 1.0 };
            self.kkt.add(k, k, sign * REGULARISATION);
        }
    }

    /// The predictor (affine) direction, Mehrotra's corrector towards
    /// σ·μ (`mu` the mean complementarity, `gap` the total; the target
    /// floored at `mu_floor`, [`GAP_FLOOR`]), and the step along it, on
    /// the factor held.
    fn mehrotra_step(&mut self, gap: f64, mu: f64, mu_floor: f64) {
        self.direction(|s, z, _| s * z);
        let alpha = self.step_length();
        let mut gap_aff = 0.0;
        for cs in &self.discs {
            gap_aff += (cs.s + alpha * cs.ds) * (cs.z + alpha * cs.dz);
        }
        // A hard side's σ, w and their steps are 0.
        let after = |sd: &Side| {
            (sd.s + alpha * sd.ds) * (sd.z + alpha * sd.dz)
                + (sd.sig + alpha * sd.dsig) * (sd.w + alpha * sd.dw)
        };
        for [up, low] in &self.sides {
            gap_aff += after(up) + after(low);
        }
        let sigma = (gap_aff / gap).clamp(0.0, 1.0).powi(3);
        let target = (sigma * mu).max(mu_floor);
        self.direction(|s, z, dsdz| s * z + dsdz - target);
        let alpha = (STEP_FRACTION * self.step_length()).min(1.0);
        for (v, dv) in self.v.iter_mut().zip(&self.dv) {
            *v += alpha * dv;
        }
        for cs in &mut self.discs {
            cs.s += alpha * cs.ds;
            cs.z += alpha * cs.dz;
        }
        for sd in self.sides.iter_mut().flatten() {
            sd.s += alpha * sd.ds;
            sd.z += alpha * sd.dz;
            sd.sig += alpha * sd.dsig;
            sd.w += alpha * sd.dw;
        }
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
    /// last argument is the predictor's product, unused by the predictor).
    fn direction(&mut self, rc: impl Fn(f64, f64, f64) -> f64) {
        let s = self.stages;
        for (o, r) in self.rhs.iter_mut().zip(&self.r) {
            *o = -r;
        }
        // Discs: rhs −= u·(z·r − rc)/s on (ã_x, ã_y).
        for (f, cs) in self.discs.iter().enumerate() {
            let e = (cs.z * cs.r - rc(cs.s, cs.z, cs.ds * cs.dz)) / cs.s;
            self.rhs[s.accel(0, f)] -= cs.u[0] * e;
            self.rhs[s.accel(1, f)] -= cs.u[1] * e;
        }
        // Sides: Δz = k0 + d·hΔx, rhs −= hᵀk0 (h = ±g).
        for ((row, side), &rho) in self
            .rows
            .iter()
            .zip(self.sides.iter_mut())
            .zip(&self.penalty)
        {
            let soft = rho.is_finite();
            for sd in side.iter_mut() {
                let rcs = rc(sd.s, sd.z, sd.ds * sd.dz);
                sd.k0 = if soft {
                    let rcw = rc(sd.sig, sd.w, sd.dsig * sd.dw);
                    let (d1, d2) = (sd.z / sd.s, sd.w / sd.sig);
                    let rs = rho - sd.z - sd.w;
                    sd.e0 = -rs - rcs / sd.s - rcw / sd.sig + d1 * sd.r;
                    -rcs / sd.s + d1 * sd.r - d1 * sd.e0 / (d1 + d2)
                } else {
                    (sd.z * sd.r - rcs) / sd.s
                };
            }
            row.axpy(-(side[0].k0 - side[1].k0), &mut self.rhs);
        }
        self.dv.copy_from_slice(&self.rhs);
        self.ldl.solve(&mut self.dv);
        for (f, cs) in self.discs.iter_mut().enumerate() {
            let du = cs.u[0] * self.dv[s.accel(0, f)] + cs.u[1] * self.dv[s.accel(1, f)];
            let rcs = rc(cs.s, cs.z, cs.ds * cs.dz);
            cs.ds = -cs.r - du;
            cs.dz = -(rcs + cs.z * cs.ds) / cs.s;
        }
        for ((row, side), rho) in self
            .rows
            .iter()
            .zip(self.sides.iter_mut())
            .zip(&self.penalty)
        {
            let soft = rho.is_finite();
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

    /// The step to the boundary of the slacks and multipliers (at most 1).
    fn step_length(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        let mut limit = |v: f64, dv: f64| {
            if dv < 0.0 {
                alpha = alpha.min(-v / dv);
            }
        };
        for cs in &self.discs {
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
