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
//! # Inequality families ([`Constraints`])
//!
//! * [`Intervals`]: rows `lo ≤ g·x ≤ hi` (a few entries each, [`Row`]),
//!   one slack and multiplier per side, adding `(z_u/s_u + z_l/s_l)·ggᵀ`.
//!   A soft side `h·x ≤ b + σ` (σ ≥ 0, exact penalty ρσ; slack s,
//!   multipliers z of the row and w of σ ≥ 0) is eliminated in closed
//!   form: it adds `d·hhᵀ` with `d = (z/s)(w/σ)/(z/s + w/σ)` — the hard
//!   row's `z/s` in series with the penalty's `w/σ`.
//! * [`Discs`]: per stage the disc `c_f = ½(‖u_f‖² − A_f²) ≤ 0`,
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
//! defaults: 1e-8 for both), and the best iterate is kept in case they
//! are never met together; it is taken when it is acceptable (merit ≤
//! 100) and not improved on for a few iterations, at the iteration limit,
//! or when the end game's barrier terms make the KKT matrix numerically
//! singular.
//!
//! All storage is allocated in [`BandedIp::new`].

mod discs;
mod intervals;

pub use super::banded::BandedLdl;
use super::banded::SymBand;
use crate::ControlError;
pub use discs::Discs;
pub use intervals::Intervals;

/// Iterations without a better iterate after which the best one is taken.
const STALL_ITERATIONS: usize = 4;
/// Largest merit (residuals over their tolerances) a stalled or last
/// iterate may have and still be returned: residuals ≤ 100× the targets
/// (dual residual 1e-6, gap 1e-7 relative).
const ACCEPTABLE_MERIT: f64 = 100.0;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// Relative tolerance of the equality and primal residuals.
const TOLERANCE: f64 = 1e-10;
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

/// The complementarity target of a Newton step: `s·z` (the affine
/// predictor) or `s·z + Δs·Δz − σμ` (the corrector, with the predictor's
/// steps).
#[derive(Debug, Clone, Copy)]
pub enum Centring {
    /// The predictor.
    Affine,
    /// The corrector with target σμ.
    Corrector(f64),
}

impl Centring {
    /// The complementarity residual of a pair `(s, z)` whose predictor
    /// steps multiply to `dsdz`.
    fn rc(self, s: f64, z: f64, dsdz: f64) -> f64 {
        match self {
            Self::Affine => s * z,
            Self::Corrector(target) => s * z + dsdz - target,
        }
    }
}

/// `limit` shortened to the step that keeps `v + α·dv` ≥ 0.
fn limit(alpha: &mut f64, v: f64, dv: f64) {
    if dv < 0.0 {
        *alpha = alpha.min(-v / dv);
    }
}

/// A family of inequality constraints of [`BandedIp`]: its slacks and
/// multipliers, their residuals, and their Newton elimination into the
/// KKT system.
pub trait Constraints {
    /// Its complementarity pairs (μ is the gap over all pairs).
    fn pairs(&self) -> usize;
    /// Cold-start slacks and multipliers for the primal iterate `v`.
    fn start(&mut self, v: &[f64]);
    /// At the iterate `v`: adds its multipliers' term to the dual residual
    /// `r` and its complementarity to `gap`, and stores its primal
    /// residuals. Returns its merit: its largest residual over its
    /// tolerance.
    fn residuals(&mut self, v: &[f64], r: &mut [f64], gap: &mut f64) -> f64;
    /// Adds its barrier terms to the KKT matrix.
    fn assemble(&self, kkt: &mut SymBand);
    /// Adds its eliminated part of the Newton right-hand side for the
    /// complementarity target `rc`.
    fn eliminate(&mut self, rc: Centring, rhs: &mut [f64]);
    /// Its slack and multiplier steps from the primal step `dv`.
    fn recover(&mut self, dv: &[f64], rc: Centring);
    /// Shortens `alpha` to the step to its boundary.
    fn limit(&self, alpha: &mut f64);
    /// Adds its complementarity after a step `alpha` to `gap`.
    fn gap_after(&self, alpha: f64, gap: &mut f64);
    /// Takes the step `alpha`.
    fn step(&mut self, alpha: f64);
}

/// The families of [`BandedIp`], in the order they are visited: discs
/// first.
fn families<'a>(discs: &'a mut Discs, rows: &'a mut Intervals) -> [&'a mut dyn Constraints; 2] {
    [discs, rows]
}

/// The banded primal-dual interior point (module docs): the KKT system of
/// the cost and equality rows of [`Stages`], and two constraint families,
/// [`Intervals`] and [`Discs`] (either may be empty).
#[derive(Debug, Clone)]
pub struct BandedIp {
    /// Name in its errors.
    name: &'static str,
    stages: Stages,
    /// Stages (free outputs per axis).
    n: usize,
    max_iterations: usize,
    /// KKT matrix of the cost and equality rows (the residuals' M).
    base: SymBand,
    kkt: SymBand,
    ldl: BandedLdl,
    /// The interval rows.
    pub(in crate::optimise) intervals: Intervals,
    /// The per-stage discs.
    pub(in crate::optimise) discs: Discs,
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
    /// The interior point `name` (its errors say it) for n ≥ 1 stages of
    /// `costs.len()` axes at step δt, with the constraint families, at
    /// most `max_iterations` iterations.
    pub(in crate::optimise) fn new(
        name: &'static str,
        n: usize,
        dt: f64,
        costs: &[&AxisCost],
        intervals: Intervals,
        discs: Discs,
        max_iterations: usize,
    ) -> Self {
        let stages = Stages { axes: costs.len() };
        let size = stages.width() * n;
        let smooth = costs.iter().any(|a| a.accel.iter().any(|c| c[2] != 0.0));
        let bandwidth = (4 * stages.axes)
            .max(if smooth { 6 * stages.axes } else { 0 })
            .max(intervals.span());
        let mut base = SymBand::zeros(size, bandwidth);
        let inv_dt2 = 1.0 / (dt * dt);
        let (l_at, a_at, p_at) = (
            |i, f| stages.lambda(i, f),
            |i, f| stages.accel(i, f),
            |i, f| stages.output(i, f),
        );
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
        Self {
            name,
            stages,
            n,
            max_iterations,
            kkt: base.clone(),
            base,
            ldl: BandedLdl::new(size, bandwidth),
            intervals,
            discs,
            v: vec![0.0; size],
            c: vec![0.0; size],
            r: vec![0.0; size],
            dv: vec![0.0; size],
            rhs: vec![0.0; size],
            best: vec![0.0; size],
            iterations: 0,
        }
    }

    /// The stage order of its KKT vector.
    pub fn stages(&self) -> Stages {
        self.stages
    }

    /// Iterations of the last solve (converged or not).
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// The deviation `p_{axis, f}` of the current iterate (the solution
    /// after a successful solve).
    pub fn p(&self, axis: usize, f: usize) -> f64 {
        self.v[self.stages.output(axis, f)]
    }

    /// Stages n (free outputs per axis).
    pub fn n(&self) -> usize {
        self.n
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

    /// Solves from the primal start ([`BandedIp::set_start`]), the linear
    /// term ([`BandedIp::linear_mut`]) and the families' data; slacks and
    /// multipliers start cold. On success the iterate is the solution and
    /// the result its iteration; [`ControlError::Solver`] when it does not
    /// converge.
    pub fn solve(&mut self) -> Result<usize, ControlError> {
        let c_scale = 1.0 + norm(&self.c);
        let v = &self.v;
        let mut pairs = 0;
        for family in families(&mut self.discs, &mut self.intervals) {
            family.start(v);
            pairs += family.pairs();
        }
        let pairs = pairs.max(1) as f64;
        let (s, n) = (self.stages, self.n);

        // (lowest merit, its iteration); the iterate is in `best`.
        let mut best = (f64::INFINITY, 0usize);
        for iteration in 0..self.max_iterations {
            self.iterations = iteration;
            // r = M·v + c + the families' terms: the dual residual on p, ã;
            // the equality residual A·x on λ.
            self.base.mul_vec(&self.v, &mut self.r);
            for (r, c) in self.r.iter_mut().zip(&self.c) {
                *r += c;
            }
            let mut gap = 0.0;
            let mut primal: f64 = 0.0;
            for family in families(&mut self.discs, &mut self.intervals) {
                primal = primal.max(family.residuals(&self.v, &mut self.r, &mut gap));
            }
            let (mut rd, mut req, mut a_max): (f64, f64, f64) = (0.0, 0.0, 0.0);
            for f in 0..n {
                for i in 0..s.axes {
                    rd = rd
                        .max(self.r[s.output(i, f)].abs())
                        .max(self.r[s.accel(i, f)].abs());
                    req = req.max(self.r[s.lambda(i, f)].abs());
                    a_max = a_max.max(self.v[s.accel(i, f)].abs());
                }
            }
            // ½xᵀPx + cᵀx = ½xᵀ(r − Aᵀλ − Gᵀz) + ½cᵀx (approximately, at
            // near-feasibility; only its size is used).
            let (c, v) = (&self.c, &self.v);
            let objective: f64 = (0..n)
                .map(|f| {
                    (0..s.axes)
                        .map(|i| {
                            let (a, p) = (s.accel(i, f), s.output(i, f));
                            0.5 * (c[p] * v[p] + c[a] * v[a])
                        })
                        .sum::<f64>()
                })
                .sum();
            if !(gap.is_finite() && rd.is_finite() && req.is_finite() && primal.is_finite()) {
                return Err(self.error("non-finite iterate"));
            }
            // Each residual over its tolerance; converged at ≤ 1.
            let merit = (rd / (1e-8 * c_scale))
                .max(req / (TOLERANCE * (1.0 + a_max)))
                .max(primal)
                .max(gap / (1e-9 * (1.0 + objective.abs())));
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
            let mu = gap / pairs;

            // K = M + the families' barrier terms ± ε.
            self.kkt.clone_from(&self.base);
            self.discs.assemble(&mut self.kkt);
            self.intervals.assemble(&mut self.kkt);
            for f in 0..n {
                for i in 0..s.axes {
                    self.kkt.add(s.output(i, f), s.output(i, f), REGULARISATION);
                    self.kkt.add(s.accel(i, f), s.accel(i, f), REGULARISATION);
                    self.kkt
                        .add(s.lambda(i, f), s.lambda(i, f), -REGULARISATION);
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
                return Err(self.error("factorisation failed"));
            }

            // Predictor (affine), then Mehrotra's corrector.
            self.direction(Centring::Affine);
            let alpha = self.step_length();
            let mut gap_aff = 0.0;
            for family in families(&mut self.discs, &mut self.intervals) {
                family.gap_after(alpha, &mut gap_aff);
            }
            let sigma = (gap_aff / gap).clamp(0.0, 1.0).powi(3);
            self.direction(Centring::Corrector(sigma * mu));
            let alpha = (STEP_FRACTION * self.step_length()).min(1.0);
            for (v, dv) in self.v.iter_mut().zip(&self.dv) {
                *v += alpha * dv;
            }
            for family in families(&mut self.discs, &mut self.intervals) {
                family.step(alpha);
            }
        }
        Err(self.error(&format!("no convergence (best merit {:.1e})", best.0)))
    }

    /// [`ControlError::Solver`] naming this solver.
    fn error(&self, what: &str) -> ControlError {
        ControlError::Solver(format!("{}: {what}", self.name))
    }

    /// The Newton step for the complementarity target `rc`.
    fn direction(&mut self, rc: Centring) {
        for (o, r) in self.rhs.iter_mut().zip(&self.r) {
            *o = -r;
        }
        for family in families(&mut self.discs, &mut self.intervals) {
            family.eliminate(rc, &mut self.rhs);
        }
        self.dv.copy_from_slice(&self.rhs);
        self.ldl.solve(&mut self.dv);
        for family in families(&mut self.discs, &mut self.intervals) {
            family.recover(&self.dv, rc);
        }
    }

    /// The step to the families' boundary (at most 1).
    fn step_length(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        self.discs.limit(&mut alpha);
        self.intervals.limit(&mut alpha);
        alpha
    }
}
