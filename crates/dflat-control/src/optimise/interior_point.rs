//! The inequality-constrained DF-MPC axis problem by a primal-dual
//! interior-point method on its KKT system ordered by stage: banded, so one
//! iteration is O(N).
//!
//! Variables as in [`ClarabelSolver`](super::ClarabelSolver) (clarabel): per
//! free output f = 0..n−1 the deviation `p_f` from the zero-jerk baseline
//! and the planned acceleration relative to the fixed one `ã_f`, tied by
//! the equality `Δ²p_f/δt² − ã_f = 0` (multiplier `λ_f`); cost `½xᵀPx +
//! cᵀx` with `P = 2q` on p and the jerk and smoothness terms on ã. This
//! formulation is well scaled — the raw one in p alone has a Hessian with a
//! condition number near 1e10, on which an interior-point method stalls.
//! Ordered `[λ_0, ã_0, p_0, λ_1, ã_1, p_1, …]`, the KKT matrix
//!
//! ```text
//! [ P + Gᵀ·W·G   Aᵀ ]
//! [ A           −εI ]
//! ```
//!
//! has half-bandwidth 4 (λ_f reaches back to p_{f−2}), 6 with the
//! smoothness term (ã_f with ã_{f−2}); it is quasi-definite, so an LDLᵀ
//! factorisation without pivoting exists ([`BandedLdl`]); ε = 1e-12 keeps
//! it so when q = 0 (its effect on the steps is far below the tolerances:
//! a refinement step against the unregularised matrix changed no digit of
//! the first planned jerk and cost a third of the time, so there is none).
//! Bound rows: the acceleration
//! bounds act on single ã entries, the speed bounds on two p entries.
//! Mehrotra's predictor-corrector, one step length for primal and dual.
//!
//! All storage is allocated in [`StageQp::new`].

use super::banded::SymBand;
use super::bounds::{Row, check_row_data};
use super::smoothness::{accel_block, sent_linear_term};
use super::{AxisBounds, AxisProblem, FastBandedSolver, Smoothness, baseline};
use crate::ControlError;

/// Iteration limit.
pub const MAX_ITERATIONS: usize = 40;
/// Iteration limit with tilt-rate rows (long stretches of active
/// three-entry rows; random cases needed up to ~60 from the witness start).
pub const MAX_ITERATIONS_TILT_RATE: usize = 100;
/// Iterations without a better iterate after which the best one is taken.
const STALL_ITERATIONS: usize = 4;
/// Largest merit (residuals over their tolerances) a stalled or last
/// iterate may have and still be returned: residuals ≤ 100× the targets
/// (dual residual 1e-6, gap 1e-7 relative).
const ACCEPTABLE_MERIT: f64 = 100.0;
/// Fraction of the step to the boundary taken.
const STEP_FRACTION: f64 = 0.99;
/// Relative stopping tolerance of the residuals and the gap.
const TOLERANCE: f64 = 1e-10;
/// Static regularisation of the KKT matrix.
const REGULARISATION: f64 = 1e-12;

/// LDLᵀ of a symmetric banded matrix without pivoting (for quasi-definite
/// matrices), L unit lower triangular with the same band.
#[derive(Debug, Clone)]
pub struct BandedLdl {
    n: usize,
    b: usize,
    /// Strictly lower part of L by row, column-aligned: `L[i][i − b + t]`
    /// at `i·b + t`, t = 0..b (zero before column 0).
    l: Vec<f64>,
    /// The same transposed for the back substitution: `L[i + d][i]` at
    /// `i·b + d − 1`, d = 1..=b (zero past row n − 1).
    lt: Vec<f64>,
    d: Vec<f64>,
    inv_d: Vec<f64>,
    /// Row i of L times D, scratch of the factorisation.
    work: Vec<f64>,
}

impl BandedLdl {
    /// Storage for n×n matrices of half-bandwidth b ≥ 1.
    pub fn new(n: usize, b: usize) -> Self {
        Self {
            n,
            b,
            l: vec![0.0; n * b],
            lt: vec![0.0; n * b],
            d: vec![0.0; n],
            inv_d: vec![0.0; n],
            work: vec![0.0; b],
        }
    }

    /// Factors `a` (same n and b). A pivot that is not finite or whose
    /// magnitude is below 1e-300 is [`ControlError::NotPositiveDefinite`].
    ///
    /// # Panics
    /// If `a` has another shape.
    pub fn factor(&mut self, a: &SymBand) -> Result<(), ControlError> {
        let (n, b) = (self.n, self.b);
        assert!(a.n() == n && a.bandwidth() == b, "shape mismatch");
        let lower = a.lower();
        let w = b + 1;
        for i in 0..n {
            let t0 = b.saturating_sub(i);
            let (done, rest) = self.l.split_at_mut(i * b);
            let row = &mut rest[..b];
            row[..t0].fill(0.0);
            for t in t0..b {
                // Column j = i − b + t; Σ over k in [i − b, j): in row i at
                // t' = 0..t, in row j at t' + b − t.
                let j = i + t - b;
                let rj = &done[j * b..(j + 1) * b];
                let mut s = lower[i * w + (b - t)];
                for (wk, lj) in self.work[t0..t].iter().zip(&rj[t0 + b - t..]) {
                    s -= wk * lj;
                }
                self.work[t] = s;
                row[t] = s * self.inv_d[j];
            }
            let mut dii = lower[i * w];
            for (wk, li) in self.work[t0..].iter().zip(&row[t0..]) {
                dii -= wk * li;
            }
            if !(dii.is_finite() && dii.abs() > 1e-300) {
                return Err(ControlError::NotPositiveDefinite);
            }
            self.d[i] = dii;
            self.inv_d[i] = 1.0 / dii;
        }
        for i in 0..n {
            for d in 1..=b {
                self.lt[i * b + d - 1] = if i + d < n {
                    self.l[(i + d) * b + b - d]
                } else {
                    0.0
                };
            }
        }
        Ok(())
    }

    /// Solves `L·D·Lᵀ·x = rhs` in place.
    ///
    /// # Panics
    /// If `x` does not have length n.
    pub fn solve(&self, x: &mut [f64]) {
        let (n, b) = (self.n, self.b);
        assert!(x.len() == n, "length mismatch");
        for i in 0..n {
            let t0 = b.saturating_sub(i);
            let row = &self.l[i * b + t0..(i + 1) * b];
            let s: f64 = row.iter().zip(&x[i + t0 - b..i]).map(|(l, v)| l * v).sum();
            x[i] -= s;
        }
        for (xi, di) in x.iter_mut().zip(&self.inv_d) {
            *xi *= di;
        }
        for i in (0..n).rev() {
            let m = b.min(n - 1 - i);
            let col = &self.lt[i * b..i * b + m];
            let s: f64 = col
                .iter()
                .zip(&x[i + 1..i + 1 + m])
                .map(|(l, v)| l * v)
                .sum();
            x[i] -= s;
        }
    }
}

/// Slacks, multipliers, primal residuals and steps of one bound row.
#[derive(Debug, Clone, Copy, Default)]
struct RowState {
    su: f64,
    sl: f64,
    zu: f64,
    zl: f64,
    ru: f64,
    rl: f64,
    dsu: f64,
    dsl: f64,
    dzu: f64,
    dzl: f64,
}

/// The axis problem's interior-point solver (see the module docs).
#[derive(Debug, Clone)]
pub struct StageQp {
    n: usize,
    dt: f64,
    /// KKT matrix without barrier and regularisation.
    base: SymBand,
    kkt: SymBand,
    ldl: BandedLdl,
    rows: Vec<Row>,
    state: Vec<RowState>,
    /// Iterate `[λ_0, ã_0, p_0, …]`, linear term, residual, step, its
    /// right-hand side.
    v: Vec<f64>,
    c: Vec<f64>,
    r: Vec<f64>,
    dv: Vec<f64>,
    rhs: Vec<f64>,
    /// The best iterate's p.
    best: Vec<f64>,
    /// Iteration limit ([`MAX_ITERATIONS`], with tilt-rate rows
    /// [`MAX_ITERATIONS_TILT_RATE`]).
    max_iterations: usize,
}

// Stage order λ_f, ã_f, p_f: λ_f reaches back to p_{f−2} (distance 4),
// the smoothness term couples ã_f with ã_{f−2} (distance 6).
fn l_at(f: usize) -> usize {
    3 * f
}
fn a_at(f: usize) -> usize {
    3 * f + 1
}
fn p_at(f: usize) -> usize {
    3 * f + 2
}

impl StageQp {
    /// A solver for n ≥ 1 free outputs at step δt: tracking weight q, the
    /// ã block of P (`[diag, (k−1, k), (k−2, k)]` per column, as
    /// clarabel's), and bound rows on ã_f for `acceleration` and on
    /// `(p_{f} − p_{f−1})/δt`, f = −1..n−2 (p_{−1} = 0), for `speed`, and
    /// with `tilt_rate = Some(κ)` the tilt-rate rows on ã
    /// ([`Row::tilt_rate`]).
    pub fn new(
        n: usize,
        q: f64,
        dt: f64,
        accel: &[[f64; 3]],
        acceleration: bool,
        speed: bool,
        tilt_rate: Option<f64>,
    ) -> Self {
        let size = 3 * n;
        // Half-bandwidth: 6 with the smoothness term or the tilt-rate rows
        // (ã_f–ã_{f−2}), else 4.
        let bandwidth = if tilt_rate.is_some() || accel.iter().any(|c| c[2] != 0.0) {
            6
        } else {
            4
        };
        let mut base = SymBand::zeros(size, bandwidth);
        let inv_dt2 = 1.0 / (dt * dt);
        for (f, &[d0, d1, d2]) in accel.iter().enumerate().take(n) {
            base.add(p_at(f), p_at(f), 2.0 * q);
            base.add(a_at(f), a_at(f), d0);
            if f >= 1 {
                base.add(a_at(f - 1), a_at(f), d1);
            }
            if f >= 2 && d2 != 0.0 {
                base.add(a_at(f - 2), a_at(f), d2);
            }
            // Δ²p_f/δt² − ã_f = 0 (p before the horizon is 0).
            base.add(l_at(f), p_at(f), inv_dt2);
            if f >= 1 {
                base.add(l_at(f), p_at(f - 1), -2.0 * inv_dt2);
            }
            if f >= 2 {
                base.add(l_at(f), p_at(f - 2), inv_dt2);
            }
            base.add(l_at(f), a_at(f), -1.0);
        }
        let mut rows = Vec::new();
        if acceleration {
            rows.extend((0..n).map(|f| Row::single(a_at(f))));
        }
        if speed {
            // Speed rows j = 2..N−1 on y_j, y_{j+1}: p_{j−3}, p_{j−2}.
            rows.extend((0..n).map(|g| Row::speed(g, dt, p_at)));
        }
        if let Some(kappa) = tilt_rate {
            rows.extend((0..n).map(|f| Row::tilt_rate(f, kappa, a_at)));
        }
        let m = rows.len();
        Self {
            n,
            dt,
            kkt: base.clone(),
            base,
            ldl: BandedLdl::new(size, bandwidth),
            rows,
            state: vec![RowState::default(); m],
            v: vec![0.0; size],
            c: vec![0.0; size],
            r: vec![0.0; size],
            dv: vec![0.0; size],
            rhs: vec![0.0; size],
            best: vec![0.0; n],
            max_iterations: if tilt_rate.is_some() {
                MAX_ITERATIONS_TILT_RATE
            } else {
                MAX_ITERATIONS
            },
        }
    }

    /// Number of bound rows.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// The rows' multipliers `[upper, lower]` of the last iterate (≥ 0;
    /// the Lagrangian's `z_u·(g·x − hi) + z_l·(lo − g·x)`), in row order.
    pub fn duals(&self, out: &mut [[f64; 2]]) {
        for (o, st) in out.iter_mut().zip(&self.state) {
            *o = [st.zu, st.zl];
        }
    }

    /// Solves for the linear terms `c_p` (on p, length n) and `c_a0` (on
    /// ã_0) and the row bounds `lo ≤ g·x ≤ hi` (one pair per row, in row
    /// order); `p` holds the start on entry (the unconstrained optimum is a
    /// good one) and the solution on exit. Returns the iterations.
    pub fn solve(
        &mut self,
        c_p: &[f64],
        c_a0: f64,
        lo: &[f64],
        hi: &[f64],
        p: &mut [f64],
    ) -> Result<usize, ControlError> {
        let n = self.n;
        let m = self.rows.len();
        check_row_data(
            "stage QP",
            c_p.len() == n && p.len() == n && lo.len() == m && hi.len() == m,
            "c_p and p need n entries, lo and hi one per row",
            &[c_p, p, &[c_a0]],
            lo,
            hi,
        )?;
        let norm = |v: &[f64]| v.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        // Linear term and start: p given, ã from the equality, λ = 0.
        self.c.fill(0.0);
        let inv_dt2 = 1.0 / (self.dt * self.dt);
        for f in 0..n {
            self.c[p_at(f)] = c_p[f];
            self.v[p_at(f)] = p[f];
            let pm1 = if f >= 1 { p[f - 1] } else { 0.0 };
            let pm2 = if f >= 2 { p[f - 2] } else { 0.0 };
            self.v[a_at(f)] = (p[f] - 2.0 * pm1 + pm2) * inv_dt2;
            self.v[l_at(f)] = 0.0;
        }
        self.c[a_at(0)] = c_a0;
        let c_scale = 1.0 + norm(&self.c);
        let b_scale = 1.0 + norm(lo).max(norm(hi));
        for (st, (row, (&l, &h))) in self
            .state
            .iter_mut()
            .zip(self.rows.iter().zip(lo.iter().zip(hi)))
        {
            let g = row.dot(&self.v);
            let floor = (0.1 * (h - l)).max(1e-3 * b_scale);
            *st = RowState {
                su: (h - g).max(floor),
                sl: (g - l).max(floor),
                zu: 1.0,
                zl: 1.0,
                ..RowState::default()
            };
        }

        // (lowest merit, its iteration); the iterate is in `best`.
        let mut best = (f64::INFINITY, 0usize);
        let max_iterations = self.max_iterations;
        for iteration in 0..max_iterations {
            // r = M·v + c + Gᵀ(z_u − z_l): dual residual on p, ã; the
            // equality residual A·x on λ.
            self.base.mul_vec(&self.v, &mut self.r);
            for (r, c) in self.r.iter_mut().zip(&self.c) {
                *r += c;
            }
            let mut gap = 0.0;
            let mut rp: f64 = 0.0;
            for (i, (row, st)) in self.rows.iter().zip(self.state.iter_mut()).enumerate() {
                row.axpy(st.zu - st.zl, &mut self.r);
                let g = row.dot(&self.v);
                st.ru = g + st.su - hi[i];
                st.rl = -g + st.sl + lo[i];
                rp = rp.max(st.ru.abs()).max(st.rl.abs());
                gap += st.su * st.zu + st.sl * st.zl;
            }
            let mut rd: f64 = 0.0;
            let mut req: f64 = 0.0;
            for f in 0..n {
                rd = rd.max(self.r[p_at(f)].abs()).max(self.r[a_at(f)].abs());
                req = req.max(self.r[l_at(f)].abs());
            }
            // ½xᵀPx + cᵀx = ½xᵀ(r − Aᵀλ − Gᵀz) + ½cᵀx (approximately, at
            // near-feasibility; only its size is used).
            let objective: f64 = (0..n)
                .map(|f| {
                    0.5 * (self.c[p_at(f)] * self.v[p_at(f)] + self.c[a_at(f)] * self.v[a_at(f)])
                })
                .sum::<f64>();
            if !(gap.is_finite() && rd.is_finite() && req.is_finite()) {
                return Err(ControlError::Solver("stage QP: non-finite iterate".into()));
            }
            let a_scale = 1.0 + (0..n).fold(0.0f64, |a, f| a.max(self.v[a_at(f)].abs()));
            // Each residual over its tolerance; converged at ≤ 1. The dual
            // residual cannot get much below ~1e-10 relative (rounding in
            // K, whose barrier terms grow without bound as the gap closes)
            // and grows again as they do: the targets are a gap of 1e-9
            // with the dual residual at 1e-8 (clarabel's defaults: 1e-8
            // for both), and the best iterate is kept in case they are
            // never met together.
            let merit = (rd / (1e-8 * c_scale))
                .max(req / (TOLERANCE * a_scale))
                .max(rp / (TOLERANCE * b_scale))
                .max(gap / (1e-9 * (1.0 + objective.abs())));
            if merit < best.0 {
                best = (merit, iteration);
                for (f, bp) in self.best.iter_mut().enumerate() {
                    *bp = self.v[p_at(f)];
                }
            }
            // Stalled: an acceptable best iterate not improved on for a few
            // iterations (far from the solution progress is not monotone).
            let stalled = best.0 <= ACCEPTABLE_MERIT && iteration >= best.1 + STALL_ITERATIONS;
            if merit <= 1.0 || stalled || iteration + 1 == max_iterations {
                if best.0 > ACCEPTABLE_MERIT {
                    break;
                }
                p.copy_from_slice(&self.best);
                return Ok(iteration);
            }
            let mu = gap / (2 * m).max(1) as f64;

            // K = M + Gᵀ·diag(z_u/s_u + z_l/s_l)·G ± ε.
            self.kkt.clone_from(&self.base);
            for (row, st) in self.rows.iter().zip(&self.state) {
                let d = st.zu / st.su + st.zl / st.sl;
                for a in 0..row.len {
                    for b in 0..=a {
                        self.kkt
                            .add(row.idx[a], row.idx[b], d * row.coef[a] * row.coef[b]);
                    }
                }
            }
            for f in 0..n {
                self.kkt.add(p_at(f), p_at(f), REGULARISATION);
                self.kkt.add(a_at(f), a_at(f), REGULARISATION);
                self.kkt.add(l_at(f), l_at(f), -REGULARISATION);
            }
            self.ldl
                .factor(&self.kkt)
                .map_err(|_| ControlError::Solver("stage QP: factorisation failed".into()))?;

            self.direction(|st| (st.su * st.zu, st.sl * st.zl));
            let alpha = self.step_length();
            let mut gap_aff = 0.0;
            for st in &self.state {
                gap_aff += (st.su + alpha * st.dsu) * (st.zu + alpha * st.dzu)
                    + (st.sl + alpha * st.dsl) * (st.zl + alpha * st.dzl);
            }
            let sigma = (gap_aff / gap).clamp(0.0, 1.0).powi(3);
            let target = sigma * mu;
            self.direction(|st| {
                (
                    st.su * st.zu + st.dsu * st.dzu - target,
                    st.sl * st.zl + st.dsl * st.dzl - target,
                )
            });
            let alpha = (STEP_FRACTION * self.step_length()).min(1.0);
            for (v, dv) in self.v.iter_mut().zip(&self.dv) {
                *v += alpha * dv;
            }
            for st in &mut self.state {
                st.su += alpha * st.dsu;
                st.sl += alpha * st.dsl;
                st.zu += alpha * st.dzu;
                st.zl += alpha * st.dzl;
            }
        }
        Err(ControlError::Solver(format!(
            "stage QP: no convergence (best merit {:.1e})",
            best.0
        )))
    }

    /// The Newton step for complementarity residuals `rc(row)`.
    fn direction(&mut self, rc: impl Fn(&RowState) -> (f64, f64)) {
        // rhs = −r − Gᵀe, e = (z_u r_u − rc_u)/s_u − (z_l r_l − rc_l)/s_l.
        for (o, r) in self.rhs.iter_mut().zip(&self.r) {
            *o = -r;
        }
        for (row, st) in self.rows.iter().zip(&self.state) {
            let (rcu, rcl) = rc(st);
            let e = (st.zu * st.ru - rcu) / st.su - (st.zl * st.rl - rcl) / st.sl;
            row.axpy(-e, &mut self.rhs);
        }
        self.dv.copy_from_slice(&self.rhs);
        self.ldl.solve(&mut self.dv);
        for (row, st) in self.rows.iter().zip(self.state.iter_mut()) {
            let (rcu, rcl) = rc(st);
            let gdx = row.dot(&self.dv);
            st.dsu = -st.ru - gdx;
            st.dsl = -st.rl + gdx;
            st.dzu = -(rcu + st.zu * st.dsu) / st.su;
            st.dzl = -(rcl + st.zl * st.dsl) / st.sl;
        }
    }

    fn step_length(&self) -> f64 {
        let mut alpha: f64 = 1.0;
        let mut limit = |v: f64, dv: f64| {
            if dv < 0.0 {
                alpha = alpha.min(-v / dv);
            }
        };
        for st in &self.state {
            limit(st.su, st.dsu);
            limit(st.sl, st.dsl);
            limit(st.zu, st.dzu);
            limit(st.zl, st.dzl);
        }
        alpha
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ldl_solves_a_quasi_definite_band() {
        // [[4, 1, 2], [1, 3, 0], [2, 0, −5]] (half-bandwidth 2).
        let mut a = SymBand::zeros(3, 2);
        a.set(0, 0, 4.0);
        a.set(1, 0, 1.0);
        a.set(2, 0, 2.0);
        a.set(1, 1, 3.0);
        a.set(2, 2, -5.0);
        let mut ldl = BandedLdl::new(3, 2);
        ldl.factor(&a).unwrap();
        let want = [1.0, -2.0, 0.5];
        let mut x = [0.0; 3];
        a.mul_vec(&want, &mut x);
        ldl.solve(&mut x);
        for (g, w) in x.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{x:?}");
        }
        let mut singular = SymBand::zeros(2, 1);
        singular.set(0, 0, 1.0);
        singular.set(1, 0, 1.0);
        singular.set(1, 1, 1.0);
        assert!(BandedLdl::new(2, 1).factor(&singular).is_err());
    }
}

/// The 1-D DF-MPC problem with inequality bounds, solved by the banded
/// interior-point method of [`StageQp`]: clarabel's variables and
/// cost ([`ClarabelSolver`](super::ClarabelSolver)), the KKT system ordered by stage, so
/// O(N) per iteration. It starts from the unconstrained optimum (computed
/// here with the fast path). [`DfMpc`](crate::dfmpc::DfMpc) uses it first and falls back to
/// clarabel when it does not converge.
#[derive(Debug, Clone)]
pub struct BandedInteriorPointSolver {
    fast: FastBandedSolver,
    bounds: AxisBounds,
    qp: StageQp,
    c_p: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    p: Vec<f64>,
    iterations: usize,
    /// The rows' multipliers of the last solve ([`StageQp::duals`]).
    duals: Vec<[f64; 2]>,
}

impl BandedInteriorPointSolver {
    /// Builds the solver for horizon N, weights `(q, r, δt)` as
    /// [`FastBandedSolver::with_smoothness`], the bounds and the smoothness term.
    pub fn new(
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        bounds: AxisBounds,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        let fast = FastBandedSolver::with_smoothness(horizon, q, r, dt, smoothness)?;
        if let Some(t) = &bounds.tilt_rate {
            t.check()?;
        }
        let n = horizon - 2;
        let accel = accel_block(n, r, dt, &smoothness);
        let qp = StageQp::new(
            n,
            q,
            dt,
            &accel,
            bounds.acceleration.is_some(),
            bounds.speed.is_some(),
            bounds.tilt_rate.map(|t| t.kappa),
        );
        let m = qp.rows();
        Ok(Self {
            fast,
            bounds,
            qp,
            c_p: vec![0.0; n],
            lo: vec![0.0; m],
            hi: vec![0.0; m],
            p: vec![0.0; n],
            iterations: 0,
            duals: vec![[0.0; 2]; m],
        })
    }

    /// The bounds this solver enforces.
    pub fn bounds(&self) -> &AxisBounds {
        &self.bounds
    }

    /// Interior-point iterations of the last solve.
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// The rows' multipliers `[upper, lower]` of the last solve, in the
    /// order of [`AxisBounds::row_bounds`] (acceleration, speed, tilt
    /// rate): a warm start for the augmented Lagrangian.
    pub fn row_duals(&self) -> &[[f64; 2]] {
        &self.duals
    }

    /// Solves with the bounds; arguments as [`FastBandedSolver::solve_problem`].
    /// Errors: those of the fast path, and [`ControlError::Solver`] when
    /// the interior-point method does not converge (infeasible bounds,
    /// numerical trouble).
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        let AxisProblem {
            fixed,
            sent,
            reference,
            plan,
        } = a;
        self.fast.solve_problem(AxisProblem {
            fixed,
            sent,
            reference,
            plan: &mut *plan,
        })?;
        let dt = self.fast.dt;
        let q = self.fast.q;
        let n = self.p.len();
        for f in 0..n {
            let b = baseline(fixed, f + 3);
            self.c_p[f] = 2.0 * q * (b - reference[f + 3]);
            self.p[f] = plan[f + 3] - b;
        }
        if let Some(rate) = &self.bounds.tilt_rate {
            // With the tilt-rate rows the start is the witness trajectory
            // at half the rate (strictly inside the rate rows): the
            // unconstrained plan breaks those narrow rows by many times
            // their width and the iterates then crawl (40 iterations were
            // not enough on random cases). p from ã: Δ²p_f = ã_f·δt².
            let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            let (mut pm2, mut pm1, mut f) = (0.0, 0.0, 0);
            let p = &mut self.p;
            rate.witness(
                self.fast.horizon,
                fixed,
                sent,
                self.bounds.acceleration_at(fixed, dt),
                dt,
                0.5,
                |a| {
                    let pf = 2.0 * pm1 - pm2 + (a - a0) * dt * dt;
                    p[f] = pf;
                    (pm2, pm1, f) = (pm1, pf, f + 1);
                },
            );
        }
        let sm = self.fast.smoothness;
        let c_a0 = sent_linear_term(&sm, fixed, sent, dt);
        let (lo, hi) = (&mut self.lo, &mut self.hi);
        let mut i = 0;
        self.bounds
            .row_bounds(self.fast.horizon, fixed, sent, dt, |l, h| {
                lo[i] = l;
                hi[i] = h;
                i += 1;
            });
        self.iterations = self
            .qp
            .solve(&self.c_p, c_a0, &self.lo, &self.hi, &mut self.p)?;
        self.qp.duals(&mut self.duals);
        for f in 0..n {
            plan[f + 3] = baseline(fixed, f + 3) + self.p[f];
        }
        if plan.iter().any(|v| !v.is_finite()) {
            return Err(ControlError::Solver("non-finite solution".to_string()));
        }
        Ok(())
    }
}
