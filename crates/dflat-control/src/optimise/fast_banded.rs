//! The fast path: the unconstrained per-axis QP, factored once, solved in
//! O(N) with one step of iterative refinement (module docs of
//! [`crate::optimise`]).

use super::banded::{BandedCholesky, SymBand};
use super::problem::{AxisProblem, D3, check_lengths, check_problem};
use super::smoothness::Smoothness;
use crate::ControlError;

/// Half-bandwidth of the fast-path Hessian.
const BANDWIDTH: usize = 3;

/// Per-right-hand-side workspace of [`FastBandedSolver`].
#[derive(Debug, Clone)]
struct Slot {
    /// Baseline b_3..b_N \[m\].
    base: Vec<f64>,
    /// q·(ref − b) on the free outputs.
    rhs: Vec<f64>,
    /// Deviation from the baseline.
    p: Vec<f64>,
    /// Residual, then the refinement correction.
    work: Vec<f64>,
}

/// The unconstrained 1-D DF-MPC problem on one axis, solved in O(N).
///
/// Minimises `Σ_{j=0..N} q·(y_j − ref_j)² + Σ_{j=0..N−3} r·(Δ³y_j/δt³)²`
/// (plus the smoothness term when configured, [`Smoothness`]) over
/// `y_0..y_N` with `y_0, y_1, y_2` fixed (relative indices: y_j is
/// `y_{k+j}`). The Hessian is factored once here; [`FastBandedSolver::solve`]
/// and [`FastBandedSolver::solve_pair`] allocate nothing.
#[derive(Debug, Clone)]
pub struct FastBandedSolver {
    pub(super) horizon: usize,
    pub(super) q: f64,
    /// Weight on the raw third difference, r/δt⁶.
    w: f64,
    pub(super) smoothness: Smoothness,
    /// Weight on `(δt²·Δc)²`, s/(g²·δt⁴) (0: off).
    s: f64,
    /// `s/(g²·δt²)·κ`: the sent command's gain on the first free output.
    sent_gain: f64,
    pub(super) dt: f64,
    /// `q·I + w·DᵀD (+ s·EᵀE)` on the free outputs, half-bandwidth 3 (4).
    hessian: SymBand,
    factor: BandedCholesky,
    slots: [Slot; 2],
}

impl FastBandedSolver {
    /// Builds and factors the problem for horizon N ≥ 3 \[steps\], tracking
    /// weight q ≥ 0 [1/m²], jerk weight r > 0 [s⁶/m²], step δt > 0 \[s\].
    pub fn new(horizon: usize, q: f64, r: f64, dt: f64) -> Result<Self, ControlError> {
        Self::with_smoothness(horizon, q, r, dt, Smoothness::default())
    }

    /// As [`FastBandedSolver::new`], plus the command-smoothness term (half-
    /// bandwidth 4 when its weight is > 0).
    pub fn with_smoothness(
        horizon: usize,
        q: f64,
        r: f64,
        dt: f64,
        smoothness: Smoothness,
    ) -> Result<Self, ControlError> {
        Self::check_args(horizon, q, r, dt)?;
        smoothness.check()?;
        let n = horizon - 2;
        let w = r / dt.powi(6);
        let (s, sent_gain) = if smoothness.weight > 0.0 {
            let sg = smoothness.weight / smoothness.gravity.powi(2);
            (sg / dt.powi(4), sg / (dt * dt) * smoothness.kappa)
        } else {
            (0.0, 0.0)
        };
        let hessian = Self::hessian(n, q, w, s, &smoothness);
        let bandwidth = hessian.bandwidth();
        let mut factor = BandedCholesky::new(n, bandwidth);
        factor.factor(&hessian)?;
        let slot = Slot {
            base: vec![0.0; n],
            rhs: vec![0.0; n],
            p: vec![0.0; n],
            work: vec![0.0; n],
        };
        Ok(Self {
            horizon,
            q,
            w,
            smoothness,
            s,
            sent_gain,
            dt,
            hessian,
            factor,
            slots: [slot.clone(), slot],
        })
    }

    /// The smoothness term this solver carries (weight 0: none).
    pub fn smoothness(&self) -> Smoothness {
        self.smoothness
    }

    /// The right-hand side's shift on the first free output from the sent
    /// command: `−s/(g²δt²)·κ·(a_0 − c_{−1})` (0 without smoothness or
    /// without `sent`).
    fn sent_shift(&self, fixed: &[f64; 3], sent: Option<f64>) -> f64 {
        match sent {
            Some(c) if self.s > 0.0 => {
                let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (self.dt * self.dt);
                -self.sent_gain * (a0 - c)
            }
            _ => 0.0,
        }
    }

    /// The Hessian `q·I + w·DᵀD (+ s·EᵀE)` of the deviation from the
    /// baseline on n free outputs (objective `pᵀHp − 2·rhsᵀp`).
    fn hessian(n: usize, q: f64, w: f64, s: f64, smoothness: &Smoothness) -> SymBand {
        let bandwidth = if s > 0.0 { BANDWIDTH + 1 } else { BANDWIDTH };
        let mut hessian = SymBand::zeros(n, bandwidth);
        for i in 0..n {
            hessian.add(i, i, q);
        }
        // Row i of D: Δ³ over y_i..y_{i+3}; free unknown f ↔ y_{f+3}.
        Self::add_gram(&mut hessian, n, &D3, w);
        if s > 0.0 {
            // Row i of E = T·D: δt²·Δc_i over y_{i−1}..y_{i+3}.
            Self::add_gram(&mut hessian, n, &smoothness.stencil(), s);
        }
        hessian
    }

    /// `hessian += weight·RᵀR` for the n rows of a difference stencil
    /// ending at y_{i+3} (row i's last coefficient on free unknown i,
    /// `stencil[a]` on unknown i + a − (len − 1); unknowns before the
    /// first free one are fixed and dropped).
    fn add_gram(hessian: &mut SymBand, n: usize, stencil: &[f64], weight: f64) {
        let last = stencil.len() - 1;
        for i in 0..n {
            for (a, &ca) in stencil.iter().enumerate() {
                let Some(fa) = (i + a).checked_sub(last) else {
                    continue;
                };
                for (b, &cb) in stencil.iter().enumerate().take(a + 1) {
                    let Some(fb) = (i + b).checked_sub(last) else {
                        continue;
                    };
                    hessian.add(fa, fb, weight * ca * cb);
                }
            }
        }
    }

    /// Horizon N \[steps\].
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// Tracking weight q [1/m²] and weight on the raw third difference
    /// `r/δt⁶` [1/m²].
    pub fn weights(&self) -> (f64, f64) {
        (self.q, self.w)
    }

    /// Baseline, right-hand side `q·(ref − b)` on the free outputs (plus
    /// `shift` on the first), `p = rhs`.
    fn prepare(q: f64, slot: &mut Slot, fixed: &[f64; 3], reference: &[f64], shift: f64) {
        Self::baseline_and_rhs(q, fixed, reference, shift, &mut slot.base, &mut slot.rhs);
        slot.p.copy_from_slice(&slot.rhs);
    }

    /// Baseline `b_3..b_N` and right-hand side `q·(ref − b)` (plus `shift`
    /// on the first free output).
    fn baseline_and_rhs(
        q: f64,
        fixed: &[f64; 3],
        reference: &[f64],
        shift: f64,
        base: &mut [f64],
        rhs: &mut [f64],
    ) {
        let d1 = fixed[1] - fixed[0];
        let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
        let it = base.iter_mut().zip(rhs.iter_mut());
        for (f, ((b, r), &y_ref)) in it.zip(&reference[3..]).enumerate() {
            let j = (f + 3) as f64;
            *b = fixed[0] + j * d1 + 0.5 * j * (j - 1.0) * d2;
            *r = q * (y_ref - *b);
        }
        if shift != 0.0 {
            rhs[0] += shift;
        }
    }

    /// `work = rhs − (q·I + w·DᵀD)·p`, evaluated by repeated differencing
    /// rather than with the assembled Hessian: the products of entries
    /// ~1e10 with outputs ~10 m would leave an absolute rounding error near
    /// 1e-4 in the residual, while differences of neighbouring samples are
    /// nearly exact, so the residual is accurate to ~ε·|rhs|.
    ///
    /// With smoothness (s > 0, κ) the middle factor is `w·I + s·TᵀT`,
    /// `T = κ·I + (1 − κ)·S`, applied to `d = D·p` as a two-tap filter and
    /// its transpose.
    fn residual(q: f64, w: f64, smooth: (f64, f64), slot: &mut Slot) {
        Self::residual_of(q, w, smooth, &slot.p, Some(&slot.rhs), &mut slot.work);
    }

    /// `out = rhs − H·p` as [`FastBandedSolver::residual`] (rhs = 0 when
    /// `None`).
    fn residual_of(
        q: f64,
        w: f64,
        smooth: (f64, f64),
        p: &[f64],
        rhs: Option<&[f64]>,
        out: &mut [f64],
    ) {
        let b = |k: usize| rhs.map_or(0.0, |rhs| rhs[k]);
        Self::residual_with(q, w, smooth, |k| p[k], b, out, 0, |x, k, v| x[k] = v);
    }

    /// `rhs_k − (H·p)_k` for k = n−1 … `start` handed to `put(x, k, ·)`,
    /// p and rhs read through `p(k)`, `rhs(k)`; `x` (length n) holds the
    /// middle factor's output `M·D·p` meanwhile (from `start − 1` on), and
    /// `put` may overwrite `x[k]` (read before). With `start` = 0 the
    /// whole of it; later starts compute only what rows `start` and after
    /// need (p from `start − 4` on), the same operations for them. Generic
    /// so that each caller's access inlines.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn residual_with(
        q: f64,
        w: f64,
        smooth: (f64, f64),
        p: impl Fn(usize) -> f64,
        rhs: impl Fn(usize) -> f64,
        x: &mut [f64],
        start: usize,
        mut put: impl FnMut(&mut [f64], usize, f64),
    ) {
        let (s, kappa) = smooth;
        // x = w·D·p: third backward difference by three first differences,
        // fused in one pass (p before the horizon is 0), from s0 = start − 1
        // (the smoothing filter of row `start` reads d one before it).
        let s0 = start.saturating_sub(1);
        let (mut p1, mut e1, mut f1) = (0.0, 0.0, 0.0);
        if s0 > 0 {
            let at = |k: usize| if k < s0 { p(s0 - 1 - k) } else { 0.0 };
            // p_{s0−1}, p_{s0−2}, p_{s0−3} (0 before the horizon).
            let (a, b, c) = (at(0), at(1), at(2));
            let (ea, eb) = (a - b, b - c);
            (p1, e1, f1) = (a, ea, ea - eb);
        }
        let scale = if s > 0.0 { 1.0 } else { w };
        for (i, xk) in x[s0..].iter_mut().enumerate() {
            let pk = p(s0 + i);
            let e = pk - p1;
            let f = e - e1;
            *xk = scale * (f - f1);
            (p1, e1, f1) = (pk, e, f);
        }
        if s > 0.0 {
            // x = (w·I + s·TᵀT)·d in place, backwards: g_f = (T·d)_f needs
            // d_{f−1} (not yet overwritten), (Tᵀg)_f needs g_{f+1} (carried).
            let mut g_next = 0.0;
            for f in (start..x.len()).rev() {
                let d = x[f];
                let d_prev = if f > 0 { x[f - 1] } else { 0.0 };
                let g = d_prev + kappa * (d - d_prev);
                let tg = g_next + kappa * (g - g_next);
                x[f] = w * d + s * tg;
                g_next = g;
            }
        }
        // rhs − q·p − Dᵀ·x: three forward differences (x beyond the
        // horizon is 0), fused with the combination, in one pass.
        let (mut x1, mut e1, mut f1) = (0.0, 0.0, 0.0);
        for k in (start..x.len()).rev() {
            let xv = x[k];
            let e = xv - x1;
            let f = e - e1;
            let g = f - f1;
            (x1, e1, f1) = (xv, e, f);
            put(x, k, rhs(k) - q * p(k) - g);
        }
    }

    /// `out = H·p` (the Hessian of [`FastBandedSolver::hessian`]) by
    /// differencing, accurate to ~ε·|H·p| where the assembled band is not
    /// (see [`FastBandedSolver::residual`]), on interleaved storage:
    /// `p_f = v[stride·f + axis]`, `out[stride·f + axis] = scale·(H·p)_f`
    /// for the rows f ≥ `start` (the others untouched); `work` (length n)
    /// is scratch.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn apply_hessian_strided(
        &self,
        v: &[f64],
        stride: usize,
        axis: usize,
        scale: f64,
        start: usize,
        work: &mut [f64],
        out: &mut [f64],
    ) {
        let smooth = (self.s, self.smoothness.kappa);
        // put gets rhs − H·p with rhs = 0, i.e. −(q·p + Dᵀx) exactly.
        Self::residual_with(
            self.q,
            self.w,
            smooth,
            |k| v[stride * k + axis],
            |_| 0.0,
            work,
            start,
            |_, k, r| out[stride * k + axis] = -scale * r,
        );
    }

    /// The assembled Hessian `q·I + w·DᵀD (+ s·EᵀE)` (n × n, band 3 or 4).
    pub(crate) fn hessian_band(&self) -> &SymBand {
        &self.hessian
    }

    /// The baseline `b_3..b_N` and the right-hand side `q·(ref − b)` plus
    /// the sent command's shift on the first free output (objective
    /// `pᵀHp − 2·rhsᵀp` in the deviation p = y − b). Lengths n; `reference`
    /// has N + 1 entries.
    pub(crate) fn right_hand_side(
        &self,
        fixed: &[f64; 3],
        sent: Option<f64>,
        reference: &[f64],
        base: &mut [f64],
        rhs: &mut [f64],
    ) {
        let shift = self.sent_shift(fixed, sent);
        Self::baseline_and_rhs(self.q, fixed, reference, shift, base, rhs);
    }

    /// The refined plan `y_j = b_j + (p + correction)_j` after the fixed outputs.
    fn write_plan(slot: &Slot, fixed: &[f64; 3], plan: &mut [f64]) {
        plan[..3].copy_from_slice(fixed);
        let it = plan[3..]
            .iter_mut()
            .zip(&slot.base)
            .zip(&slot.p)
            .zip(&slot.work);
        for (((y, &b), &p), &dp) in it {
            *y = b + (p + dp);
        }
    }

    /// Solves for the optimal outputs. `fixed` = `[y_0, y_1, y_2]` \[m\],
    /// `reference` = `ref_0..ref_N` \[m\] (length N + 1); writes `y*_0..y*_N`
    /// into `plan` (length N + 1). Errors name a wrong length.
    ///
    /// One banded solve for the deviation from the baseline, then one step
    /// of iterative refinement with the accurate residual: the result is
    /// within a few ulps of the exact optimum in the first outputs.
    pub fn solve(
        &mut self,
        fixed: &[f64; 3],
        reference: &[f64],
        plan: &mut [f64],
    ) -> Result<(), ControlError> {
        self.solve_problem(AxisProblem::new(fixed, reference, plan))
    }

    /// As [`FastBandedSolver::solve`], with the previously sent command
    /// ([`AxisProblem::sent`]) for the smoothness term.
    pub fn solve_problem(&mut self, a: AxisProblem<'_>) -> Result<(), ControlError> {
        check_lengths(self.horizon, a.reference, a.plan)?;
        let (q, w) = (self.q, self.w);
        let smooth = (self.s, self.smoothness.kappa);
        let shift = self.sent_shift(a.fixed, a.sent);
        let slot = &mut self.slots[0];
        Self::prepare(q, slot, a.fixed, a.reference, shift);
        self.factor.solve_in_place(&mut slot.p)?;
        Self::residual(q, w, smooth, slot);
        self.factor.solve_in_place(&mut slot.work)?;
        Self::write_plan(slot, a.fixed, a.plan);
        Ok(())
    }

    /// Solves two axes that share these weights (x and y, usually) at once;
    /// same results as two [`FastBandedSolver::solve`] calls, bit for bit, at
    /// little more than the cost of one.
    pub fn solve_pair(
        &mut self,
        a: AxisProblem<'_>,
        b: AxisProblem<'_>,
    ) -> Result<(), ControlError> {
        check_lengths(self.horizon, a.reference, a.plan)?;
        check_lengths(self.horizon, b.reference, b.plan)?;
        let (q, w) = (self.q, self.w);
        let smooth = (self.s, self.smoothness.kappa);
        let (shift_a, shift_b) = (
            self.sent_shift(a.fixed, a.sent),
            self.sent_shift(b.fixed, b.sent),
        );
        let [sa, sb] = &mut self.slots;
        Self::prepare(q, sa, a.fixed, a.reference, shift_a);
        Self::prepare(q, sb, b.fixed, b.reference, shift_b);
        self.factor.solve2_in_place(&mut sa.p, &mut sb.p)?;
        Self::residual(q, w, smooth, sa);
        Self::residual(q, w, smooth, sb);
        self.factor.solve2_in_place(&mut sa.work, &mut sb.work)?;
        Self::write_plan(sa, a.fixed, a.plan);
        Self::write_plan(sb, b.fixed, b.plan);
        Ok(())
    }
}

impl FastBandedSolver {
    /// The scalar settings of one axis, checked by [`check_problem`].
    pub(crate) fn check_args(horizon: usize, q: f64, r: f64, dt: f64) -> Result<(), ControlError> {
        check_problem(horizon, &[q], &[r], &[], Some(dt))
    }
}
