//! The augmented Lagrangian's terms (module docs of [`super`]): the
//! stage sets' projections, the row sides' clamped multipliers, the
//! gradient and its residuals, the line search's merit and the generalised
//! Hessian.

use super::{BandedAlm, ROW_TOLERANCE, StageSet};

impl BandedAlm {
    /// The stage bounds' scale [m/s²] for the residual's tolerance.
    pub(super) fn stage_scale(&self) -> f64 {
        match &self.stages {
            StageSet::Disc(r) => r.iter().fold(0.0f64, |a, b| a.max(*b)),
            StageSet::Interval(b) => b
                .iter()
                .flat_map(|s| s.iter().take(self.k).flatten())
                .filter(|v| v.is_finite())
                .fold(0.0f64, |a, b| a.max(b.abs())),
        }
    }

    /// σ on row k, in its units.
    pub(super) fn sigma_row(&self, k: usize) -> f64 {
        self.sigma * self.row_scale[k]
    }

    /// Row k's side multiplier after the update, `clamp(v + σ_h·t, 0, ρ)`.
    pub(super) fn side_multiplier(&self, k: usize, v: f64, t: f64) -> f64 {
        (v + self.sigma_row(k) * t).clamp(0.0, self.row_penalty[k])
    }

    /// `out[f] = G_f·v` per axis for the stages f ≥ `from` (outputs
    /// before the horizon are 0), without a_0.
    #[inline]
    pub(super) fn accelerations(
        k: usize,
        inv_dt2: f64,
        v: &[f64],
        out: &mut [[f64; 2]],
        from: usize,
    ) {
        match k {
            1 => accelerations_k::<1>(inv_dt2, v, out, from),
            _ => accelerations_k::<2>(inv_dt2, v, out, from),
        }
    }

    /// `out += Σ_f G_fᵀ·e_f` on the outputs f ≥ `from` (the stages' e
    /// before `from + 2` must be 0 for the rest to be whole).
    pub(super) fn add_transposed(
        k: usize,
        inv_dt2: f64,
        e: &[[f64; 2]],
        out: &mut [f64],
        from: usize,
    ) {
        match k {
            1 => add_transposed_k::<1>(inv_dt2, e, out, from),
            _ => add_transposed_k::<2>(inv_dt2, e, out, from),
        }
    }

    /// `out = P·v` by differencing, per axis on the interleaved vectors,
    /// on the unknowns of the outputs f ≥ `from` (the window's, below).
    pub(super) fn apply_p(&mut self, which: Vector) {
        let k = self.k;
        let from = self.window_output();
        let (src, dst) = match which {
            Vector::X => (&self.ws.x, &mut self.ws.px),
            Vector::D => (&self.ws.d, &mut self.ws.pd),
        };
        for (i, axis) in self.axes.iter().enumerate() {
            axis.apply_hessian_strided(src, k, i, 2.0, from, &mut self.ws.p_work, dst);
        }
    }

    /// The first output of the window (`window − 2`, 0 for the whole
    /// horizon): the unknowns from `k·window_output()` on are iterated,
    /// those before are the eliminated head's (module docs of [`super`]).
    #[inline]
    pub(super) fn window_output(&self) -> usize {
        self.ws.window.saturating_sub(2)
    }

    /// The first unknown of the window.
    #[inline]
    pub(super) fn window_unknown(&self) -> usize {
        self.k * self.window_output()
    }

    /// Whether row r lies in the window (all of it without one); the
    /// eliminated head's rows are not iterated: should one bind, the
    /// whole horizon's check as the window closes finds it.
    #[inline]
    pub(super) fn row_in_window(&self, r: usize) -> bool {
        self.row_first[r] >= self.window_unknown()
    }

    /// `h_r·v` for the rows in the window (`row_in_window`), v the
    /// iterate (into `hx`) or the direction (into `hd`).
    pub(super) fn row_products(&mut self, v: Vector) {
        let j0 = self.window_unknown();
        let (src, out) = match v {
            Vector::X => (&self.ws.x, &mut self.ws.hx),
            _ => (&self.ws.d, &mut self.ws.hd),
        };
        for run in &self.row_runs {
            let mut from = run.start;
            while from < run.end && self.row_first[from] < j0 {
                from += 1;
            }
            run.products(src, from, out);
        }
    }

    /// Whether a row with multipliers `v` at `h` is inside its interval
    /// `[lo, hi]` with no multiplier: both sides' updates are then 0, and
    /// so are its terms in L and its gradient (bit for bit), which the
    /// row passes skip.
    #[inline]
    pub(super) fn row_idle(v: [f64; 2], h: f64, lo: f64, hi: f64) -> bool {
        v == [0.0; 2] && lo <= h && h <= hi
    }

    /// The side `t` of row k at h (upper side j = 0: h − hi, lower: lo − h).
    #[inline]
    pub(super) fn side(j: usize, h: f64, lo: f64, hi: f64) -> f64 {
        if j == 0 { h - hi } else { lo - h }
    }

    /// The rows' part of the Lagrangian's non-quadratic part at `x + α·d`
    /// (`hx`, `hd` current).
    pub(super) fn row_terms(&self, alpha: f64, lo: &[f64], hi: &[f64]) -> f64 {
        let mut value = 0.0;
        for (k, v) in self.warm.v.iter().enumerate() {
            if !self.row_in_window(k) {
                continue;
            }
            let h = self.ws.hx[k] + alpha * self.ws.hd[k];
            if Self::row_idle(*v, h, lo[k], hi[k]) {
                continue;
            }
            let ss = self.sigma_row(k);
            for (j, &vj) in v.iter().enumerate() {
                let t = Self::side(j, h, lo[k], hi[k]);
                let vn = self.side_multiplier(k, vj, t);
                value += vn * t - (vn - vj) * (vn - vj) / (2.0 * ss);
            }
        }
        value
    }

    /// u, h·x and the gradient `g = P·x + c + Σ G_fᵀy'_f + Σ ±h·v'` at x,
    /// with the updated stage multipliers y' (`y_next`), the penalty part
    /// of L (`penalty_value`) and the active set (`active`); returns
    /// `(‖g‖∞, stage residual, row residual)`, the residuals being the
    /// largest multiplier change `‖y' − y‖/σ` (stages, m/s²) and `|v' −
    /// v|/σ_h` (rows, their units) the update would make.
    pub(super) fn gradient(&mut self, a0: [f64; 2], lo: &[f64], hi: &[f64]) -> (f64, f64, f64) {
        if !self.ws.px_current {
            self.apply_p(Vector::X);
            self.ws.px_current = true;
        }
        let j0 = self.window_unknown();
        for ((g, p), c) in self.ws.g[j0..]
            .iter_mut()
            .zip(&self.ws.px[j0..])
            .zip(&self.ws.c[j0..])
        {
            *g = p + c;
        }
        let s = self.sigma;
        let k = self.k;
        let (res2, mut value) = match self.ws.full_step.take() {
            // The line search's full step left u, y', I − ∂Π and the
            // active stages at this x.
            Some(done) => done,
            None => {
                Self::accelerations(k, self.inv_dt2, &self.ws.x, &mut self.ws.u, self.ws.window);
                let a0 = if k == 1 { [a0[0], 0.0] } else { a0 };
                self.stage_values(false, |_| a0)
            }
        };
        let stage_res = res2.sqrt() / s;
        let from = self.window_output();
        Self::add_transposed(k, self.inv_dt2, &self.ws.y_next, &mut self.ws.g, from);
        let mut row_res: f64 = 0.0;
        self.row_products(Vector::X);
        for r in 0..self.rows.len() {
            if !self.row_in_window(r) {
                continue;
            }
            let h = self.ws.hx[r];
            if Self::row_idle(self.warm.v[r], h, lo[r], hi[r]) {
                self.ws.active[self.n + 2 * r] = 0;
                self.ws.active[self.n + 2 * r + 1] = 0;
                continue;
            }
            let ss = self.sigma_row(r);
            let rho = self.row_penalty[r];
            let weight = if rho.is_infinite() {
                self.hard_row_weight
            } else {
                1.0
            };
            let mut e = 0.0;
            for j in 0..2 {
                let vj = self.warm.v[r][j];
                let t = Self::side(j, h, lo[r], hi[r]);
                let vn = self.side_multiplier(r, vj, t);
                let raw = vj + ss * t;
                self.ws.active[self.n + 2 * r + j] = u8::from(raw > 0.0 && raw < rho);
                value += vn * t - (vn - vj) * (vn - vj) / (2.0 * ss);
                row_res = row_res.max(weight * (vn - vj).abs() / ss);
                e += if j == 0 { vn } else { -vn };
            }
            if e != 0.0 {
                self.rows[r].axpy(e, &mut self.ws.g);
            }
        }
        self.ws.penalty_value = value;
        let gn = self.ws.g[j0..].iter().fold(0.0f64, |a, b| a.max(b.abs()));
        (gn, stage_res, row_res)
    }

    /// The stage pass ([`stage_pass`]) over `u` (`trial`: `u_trial`) moved
    /// by `delta(f)`, one pass per kind of set so that the projection
    /// inlines; returns the largest `‖y' − y‖²` and the stages' penalty.
    fn stage_values(&mut self, trial: bool, delta: impl Fn(usize) -> [f64; 2]) -> (f64, f64) {
        let s = self.sigma;
        let u = if trial {
            &mut self.ws.u_trial
        } else {
            &mut self.ws.u
        };
        let from = self.ws.window;
        macro_rules! pass {
            ($k:literal, $excess:expr) => {
                stage_pass::<$k>(
                    from,
                    u,
                    &delta,
                    &self.warm.y,
                    &mut self.ws.y_next,
                    &mut self.ws.jac,
                    &mut self.ws.active,
                    s,
                    $excess,
                )
            };
        }
        match (&self.stages, self.k) {
            (StageSet::Disc(radius), _) => {
                let centre = &self.centre;
                pass!(2, |f, w| disc_excess(centred(w, centre[f]), radius[f]))
            }
            (StageSet::Interval(bounds), 1) => pass!(1, |f, w| interval_excess::<1>(w, &bounds[f])),
            (StageSet::Interval(bounds), _) => pass!(2, |f, w| interval_excess::<2>(w, &bounds[f])),
        }
    }

    /// The Lagrangian's non-quadratic part at the full step `x + d` (`u`,
    /// `du`, `hx`, `hd` current; without its constant `−Σ‖y_f‖²/(2σ)`),
    /// by the gradient's stage pass into `u_trial`, `y_next`, `jac` and
    /// `active`: should the line search take the full step, the next
    /// gradient starts from them ([`BandedAlm::accept_full_step`]).
    pub(super) fn full_step_terms(&mut self, lo: &[f64], hi: &[f64]) -> (f64, (f64, f64)) {
        let from = self.ws.window;
        self.ws.u_trial[from..].copy_from_slice(&self.ws.u[from..]);
        let du = std::mem::take(&mut self.ws.du);
        let done = self.stage_values(true, |f| du[f]);
        self.ws.du = du;
        (done.1 + self.row_terms(1.0, lo, hi), done)
    }

    /// Whether the iterate held keeps every hard row `lo ≤ h·x ≤ hi` to
    /// the solve's tolerance of hard rows ([`ROW_TOLERANCE`] of their
    /// bounds' scale); soft rows are not judged (their violation is
    /// priced).
    pub(crate) fn hard_rows_hold(&self, lo: &[f64], hi: &[f64]) -> bool {
        let tol = ROW_TOLERANCE * self.hard_row_scale(lo, hi);
        (0..self.rows.len())
            .filter(|&r| self.row_penalty[r].is_infinite())
            .all(|r| {
                let h = self.rows[r].dot(&self.ws.x);
                h <= hi[r] + tol && h >= lo[r] - tol
            })
    }

    /// The hard rows' bounds' scale, `1 + max |lo_r|, |hi_r|` over the
    /// rows without a penalty, in their units.
    pub(super) fn hard_row_scale(&self, lo: &[f64], hi: &[f64]) -> f64 {
        1.0 + (0..lo.len())
            .filter(|&r| self.row_penalty[r].is_infinite())
            .fold(0.0f64, |a, r| a.max(lo[r].abs()).max(hi[r].abs()))
    }

    /// What the constraints' residuals can cost at x (`y_next`, `hx`
    /// current, the multipliers not yet updated):
    /// `Σ ‖y'_f‖·‖y'_f − y_f‖/σ + Σ v'·|v' − v|/σ_h` — a stage inside its
    /// set by δ where the optimum is on its boundary costs ‖y‖·δ. Only the
    /// stop needs it, once per multiplier update.
    pub(super) fn residual_cost(&self, lo: &[f64], hi: &[f64]) -> f64 {
        let s = self.sigma;
        let mut gap = 0.0;
        for (yn, y) in self.ws.y_next.iter().zip(&self.warm.y) {
            let (ex, ey) = (yn[0] - y[0], yn[1] - y[1]);
            let e2 = ex * ex + ey * ey;
            if e2 > 0.0 {
                gap += (yn[0] * yn[0] + yn[1] * yn[1]).sqrt() * e2.sqrt() / s;
            }
        }
        for (r, v) in self.warm.v.iter().enumerate() {
            let h = self.ws.hx[r];
            let ss = self.sigma_row(r);
            for (j, &vj) in v.iter().enumerate() {
                let t = Self::side(j, h, lo[r], hi[r]);
                let vn = self.side_multiplier(r, vj, t);
                gap += vn * (vn - vj).abs() / ss;
            }
        }
        gap
    }

    /// The generalised Hessian `P + σ·Σ G_fᵀ J_f G_f + σ_h·Σ hhᵀ` at x,
    /// its rows `from` and after (a multiple of K; 0: all, the others
    /// left unspecified).
    #[inline]
    pub(super) fn assemble(&mut self, lo: &[f64], hi: &[f64], from: usize) {
        let w = self.kkt.bandwidth() + 1;
        if from == 0 {
            self.kkt.clone_from(&self.base);
        } else {
            self.kkt.lower_mut()[from * w..].copy_from_slice(&self.base.lower()[from * w..]);
        }
        let sc = self.sigma * self.inv_dt2 * self.inv_dt2;
        let lower = self.kkt.lower_mut();
        let position = from / self.k;
        match self.k {
            1 => add_stage_blocks::<1>(&self.ws.jac, sc, w, lower, position),
            _ => add_stage_blocks::<2>(&self.ws.jac, sc, w, lower, position),
        }
        for r in 0..self.rows.len() {
            if !self.row_in_window(r) {
                continue;
            }
            let h = self.ws.hx[r];
            let ss = self.sigma_row(r);
            let rho = self.row_penalty[r];
            let mut active = 0.0;
            for j in 0..2 {
                let raw = self.warm.v[r][j] + ss * Self::side(j, h, lo[r], hi[r]);
                if raw > 0.0 && raw < rho {
                    active += ss;
                }
            }
            if active == 0.0 {
                continue;
            }
            let row = self.rows[r];
            for a in 0..row.len {
                for b in 0..row.len {
                    if row.idx[a] >= row.idx[b] {
                        self.kkt
                            .add(row.idx[a], row.idx[b], active * row.coef[a] * row.coef[b]);
                    }
                }
            }
        }
    }
}

/// [`BandedAlm::accelerations`] for K axes (1 or 2).
#[inline(always)]
fn accelerations_k<const K: usize>(inv_dt2: f64, v: &[f64], out: &mut [[f64; 2]], from: usize) {
    let (mut p1, mut p2) = ([0.0; K], [0.0; K]);
    for i in 0..K {
        if from >= 1 {
            p1[i] = v[K * (from - 1) + i];
        }
        if from >= 2 {
            p2[i] = v[K * (from - 2) + i];
        }
    }
    for (o, p) in out[from..].iter_mut().zip(v[K * from..].chunks_exact(K)) {
        let mut p0 = [0.0; K];
        for i in 0..K {
            p0[i] = p[i];
            o[i] = (p0[i] - 2.0 * p1[i] + p2[i]) * inv_dt2;
        }
        p2 = p1;
        p1 = p0;
    }
}

/// [`BandedAlm::add_transposed`] for K axes (1 or 2).
#[inline(always)]
fn add_transposed_k<const K: usize>(inv_dt2: f64, e: &[[f64; 2]], out: &mut [f64], from: usize) {
    let (mut e1, mut e2) = ([0.0; 2], [0.0; 2]);
    for (e0, o) in e[from..]
        .iter()
        .zip(out[K * from..].chunks_exact_mut(K))
        .rev()
    {
        for i in 0..K {
            o[i] += (e0[i] - 2.0 * e1[i] + e2[i]) * inv_dt2;
        }
        e2 = e1;
        e1 = *e0;
    }
}

/// The gradient's pass over the stages: `u_f += delta(f)` (u holds G_f·x
/// and delta gives a_0, or u the last iterate's accelerations and delta
/// the step's), `w_f = u_f + y_f/σ`, the updated multipliers `y'_f = σ·(w_f −
/// Π_f(w_f))`, `I − ∂Π_f` of the stages outside their set (`jac`) and
/// which they are (`active`, first n entries); returns the largest
/// `‖y' − y‖²` and the penalty `Σ σ/2·‖w_f − Π_f(w_f)‖²`. Generic over
/// the projection so that it inlines.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn stage_pass<const K: usize>(
    from: usize,
    u: &mut [[f64; 2]],
    delta: impl Fn(usize) -> [f64; 2],
    y: &[[f64; 2]],
    y_next: &mut [[f64; 2]],
    jac: &mut [[[f64; 2]; 2]],
    active: &mut [u8],
    s: f64,
    excess: impl Fn(usize, [f64; 2]) -> Option<([f64; 2], [[f64; 2]; 2])>,
) -> (f64, f64) {
    let inv_s = 1.0 / s;
    let (mut res2, mut value) = (0.0f64, 0.0);
    let stages = u[from..]
        .iter_mut()
        .zip(&y[from..])
        .zip(&mut y_next[from..]);
    for (f, ((uf, yf), ynf)) in stages.enumerate().map(|(i, s)| (i + from, s)) {
        let du = delta(f);
        let uu = [uf[0] + du[0], uf[1] + du[1]];
        *uf = uu;
        let w = [uu[0] + yf[0] * inv_s, uu[1] + yf[1] * inv_s];
        let yn = match excess(f, w) {
            Some((e, j)) => {
                value += 0.5 * s * (e[0] * e[0] + e[1] * e[1]);
                jac[f] = j;
                [s * e[0], s * e[1]]
            }
            None => {
                jac[f] = [[0.0; 2]; 2];
                [0.0; 2]
            }
        };
        active[f] = u8::from(yn[0] != 0.0) | (u8::from(yn[1] != 0.0) << 1);
        let (ex, ey) = (yn[0] - yf[0], yn[1] - yf[1]);
        res2 = res2.max(ex * ex + ey * ey);
        *ynf = yn;
    }
    (res2, value)
}

/// `w − o`: `w` relative to the disc's centre `o`.
#[inline(always)]
pub(super) fn centred(w: [f64; 2], o: [f64; 2]) -> [f64; 2] {
    [w[0] - o[0], w[1] - o[1]]
}

/// `w − Π(w)` and `I − ∂Π(w)` for the disc of radius `r` when `w` lies
/// outside it (`(1 − r/‖w‖)·w`, `(1 − t)·I + t·ŵŵᵀ` with t = r/‖w‖).
#[inline(always)]
pub(super) fn disc_excess(w: [f64; 2], r: f64) -> Option<([f64; 2], [[f64; 2]; 2])> {
    let n2 = w[0] * w[0] + w[1] * w[1];
    if n2 <= r * r {
        return None;
    }
    let inv = 1.0 / n2.sqrt();
    let t = r * inv;
    let (wx, wy) = (w[0] * inv, w[1] * inv);
    let k = 1.0 - t;
    let off = t * wx * wy;
    Some((
        [k * w[0], k * w[1]],
        [[k + t * wx * wx, off], [off, k + t * wy * wy]],
    ))
}

/// `w − Π(w)` and `I − ∂Π(w)` for the first `K` axes' intervals
/// `[lo, hi]` when `w` lies outside one of them.
#[inline(always)]
pub(super) fn interval_excess<const K: usize>(
    w: [f64; 2],
    b: &[[f64; 2]; 2],
) -> Option<([f64; 2], [[f64; 2]; 2])> {
    let mut e = [0.0; 2];
    let mut j = [[0.0; 2]; 2];
    let mut any = false;
    for i in 0..K {
        let [lo, hi] = b[i];
        let out = w[i] - w[i].clamp(lo, hi);
        if out != 0.0 {
            e[i] = out;
            j[i][i] = 1.0;
            any = true;
        }
    }
    any.then_some((e, j))
}

/// `lower += σ·k2·Σ_f G_fᵀ J_f G_f` (`sc` = σ/δt⁴, `w` the band's row
/// stride) for K axes, gathered by rows: the block of stages g and g − e
/// is `S_e = Σ_a D2[a]·D2[a+e]·J_{g+a}` (D2 = (1, −2, 1), the second
/// difference's coefficients of p_f, p_{f−1}, p_{f−2}), i.e. `S_0 = J_g +
/// 4J_{g+1} + J_{g+2}`, `S_1 = −2(J_g + J_{g+1})`, `S_2 = J_g` — each
/// entry written once, in order. `jac` is 0 at the stages inside their
/// set.
#[inline(always)]
pub(super) fn add_stage_blocks<const K: usize>(
    jac: &[[[f64; 2]; 2]],
    sc: f64,
    w: usize,
    lower: &mut [f64],
    from: usize,
) {
    let n = jac.len();
    let at = |f: usize| if f < n { jac[f] } else { [[0.0; 2]; 2] };
    // sc·Σ c·J over the terms given.
    let sum = |terms: &[(f64, [[f64; 2]; 2])]| {
        let mut m = [[0.0; 2]; 2];
        for i in 0..K {
            for j in 0..K {
                m[i][j] = sc * terms.iter().map(|(c, a)| c * a[i][j]).sum::<f64>();
            }
        }
        m
    };
    for (g, rows) in lower.chunks_exact_mut(K * w).enumerate().take(n) {
        if g < from {
            continue;
        }
        let (j0, j1, j2) = (at(g), at(g + 1), at(g + 2));
        let s = [
            sum(&[(1.0, j0), (4.0, j1), (1.0, j2)]),
            sum(&[(-2.0, j0), (-2.0, j1)]),
            sum(&[(1.0, j0)]),
        ];
        // Row K·g + i, column K·(g − e) + j: slot K·e + i − j.
        for (e, se) in s.iter().enumerate().take(g.min(2) + 1) {
            for i in 0..K {
                let row = &mut rows[i * w..(i + 1) * w];
                for j in 0..K {
                    if e > 0 || j <= i {
                        row[K * e + i - j] += se[i][j];
                    }
                }
            }
        }
    }
}

/// Which vector [`BandedAlm::apply_p`] multiplies.
#[derive(Debug, Clone, Copy)]
pub(super) enum Vector {
    X,
    D,
}
