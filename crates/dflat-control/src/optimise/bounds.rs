//! Inequality bounds on one axis's planned outputs: acceleration (the tilt
//! bound, or the vertical acceleration), speed, the braking funnel, and the
//! tilt-rate bound on the command's change per tick ([`TiltRate`], its
//! maths in [`super::tilt_rate`]).

pub use super::tilt_rate::TiltRate;

/// Inequality bounds on one axis's planned outputs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AxisBounds {
    /// `[lo, hi]` on the acceleration `Δ²y_j/δt²` [m/s²], j = 1..N−2.
    pub acceleration: Option<[f64; 2]>,
    /// `v` with `|Δy_j/δt| ≤ v` [m/s], j = 2..N−1. With an acceleration
    /// bound too, a window already faster than v gets a funnel instead of
    /// an infeasible problem: the bound at step j is
    /// `max(v, |v_1| − 0.9·a·(j − 1)·δt)`, v_1 the window's speed, a the
    /// braking bound (the plan slows at 90 % of it).
    pub speed: Option<f64>,
    /// The tilt-rate bound on this axis's command (horizontal axes): rows
    /// on the change of the command per tick, stage 0 against the command
    /// sent at the previous tick ([`TiltRate`]). With it, the acceleration
    /// rows widen where the rate bound cannot reach them in time (a
    /// funnel, [`TiltRate`]), so the problem stays feasible.
    pub tilt_rate: Option<TiltRate>,
    /// The model's linear drag D on this axis \[1/s\] (0: none). The tilt
    /// holds the thrust's acceleration, the plan's plus `D·v`, so the
    /// acceleration bound applies to `Δ²y/δt² + D·v_1`, v_1 the window's
    /// speed `(y_2 − y_1)/δt`: `[lo − D·v_1, hi − D·v_1]` on the plan's
    /// first free acceleration, moved along the horizon by
    /// [`AxisBounds::offset_slope`].
    pub drag: f64,
    /// This tick's offset of the plan's acceleration from the thrust's on
    /// this axis [m/s²], `Δ²y/δt² − a_thrust` at the window's speed: what
    /// the model adds to the thrust's (the drag `−D·v_1`, a learned
    /// residual `ρ`). `None`: `−D·v_1` from [`AxisBounds::drag`]. Set per
    /// tick by the controller when a learned residual is flown: a residual
    /// that takes the drag back (`dflat learn` over an identified
    /// `drag_h`) moves the bound with it.
    pub offset: Option<f64>,
    /// How the offset changes per stage along the horizon [m/s² per
    /// stage], from the window's two model steps (`o_1 − o_0`: the drag's
    /// `−D·a·δt`, and a learned residual's change). Where the offset
    /// shrinks towards 0 (the vehicle slows), stage j's bound is moved by
    /// `o_j = o_1 + slope·(j − 1)`, not past 0, instead of `o_1`: a
    /// braking plan does not count on the drag of its start speed to its
    /// stop. Where it would grow (speeding up), every stage keeps `o_1`.
    /// 0: the start's offset for every stage.
    pub offset_slope: f64,
}

impl AxisBounds {
    /// The acceleration bound on the plan's `Δ²y/δt²` for a window whose
    /// last outputs are `fixed` ([`AxisBounds::drag`]): `[lo, hi]` plus the
    /// offset ([`AxisBounds::offset`], else `−D·v_1`).
    pub(crate) fn acceleration_at(&self, fixed: &[f64; 3], dt: f64) -> Option<[f64; 2]> {
        let [lo, hi] = self.acceleration?;
        let offset = self.start_offset(fixed, dt);
        Some([lo + offset, hi + offset])
    }

    /// The offset at the plan's start \[m/s²\]: [`AxisBounds::offset`]
    /// when finite, else the drag's `−D·v_1` (0 without drag).
    fn start_offset(&self, fixed: &[f64; 3], dt: f64) -> f64 {
        match self.offset {
            Some(o) if o.is_finite() => o,
            _ if self.drag == 0.0 => 0.0,
            _ => -self.drag * (fixed[2] - fixed[1]) / dt,
        }
    }

    /// For the window `fixed`: stage j's offset (j = 1 the first free
    /// acceleration) less stage 1's \[m/s²\] as a function of j
    /// ([`AxisBounds::offset_slope`]): the slope's while the offset shrinks
    /// towards 0, never past it; 0 where it would grow, and without a
    /// slope or an acceleration bound.
    pub(crate) fn stage_shifts(&self, fixed: &[f64; 3], dt: f64) -> impl Fn(usize) -> f64 {
        let o1 = self.start_offset(fixed, dt);
        let along = self.stage_offsets(fixed, dt);
        let bounded = self.acceleration.is_some();
        move |j| {
            let shift = along(j) - o1;
            if bounded && shift.is_finite() {
                shift
            } else {
                0.0
            }
        }
    }

    /// For the window `fixed`: stage j's offset o_j [m/s²] (j = 1 the
    /// first free acceleration; [`AxisBounds::offset`], else `−D·v_1`),
    /// moved along the horizon by [`AxisBounds::offset_slope`] while it
    /// shrinks towards 0, never past it; the start's where it would grow.
    /// The tilt cone's centre ([`super::BandedConeSolver::set_centre`]) is
    /// the pair's.
    pub(crate) fn stage_offsets(&self, fixed: &[f64; 3], dt: f64) -> impl Fn(usize) -> f64 {
        let o1 = self.start_offset(fixed, dt);
        let slope = self.offset_slope;
        // Only towards 0 (NaN: nowhere).
        let shrinking = o1 * slope < 0.0;
        move |j| {
            if !shrinking || j <= 1 {
                return o1;
            }
            let oj = o1 + slope * (j - 1) as f64;
            let oj = if oj * o1 < 0.0 { 0.0 } else { oj };
            if oj.is_finite() { oj } else { o1 }
        }
    }

    /// The speed funnel for a window moving faster than the speed bound:
    /// `(|v_1|, a)` with v_1 = (y_2 − y_1)/δt [m/s] and a [m/s²] 90 % of
    /// the acceleration bound that slows it down; the bound at step j is
    /// then `max(v, |v_1| − a·(j − 1)·δt)`. `None` (the plain bound) when
    /// there is no acceleration bound — the first free output can then
    /// meet any speed — or the window is within the bound.
    pub(crate) fn speed_funnel(&self, fixed: &[f64; 3], dt: f64) -> Option<(f64, f64)> {
        let v = self.speed?;
        let [lo, hi] = self.acceleration_at(fixed, dt)?;
        let v1 = (fixed[2] - fixed[1]) / dt;
        let brake = if v1 > 0.0 { -lo } else { hi };
        (v1.abs() > v).then_some((v1.abs(), 0.9 * brake))
    }

    /// The bounds `(lo, hi)` of each constraint row for this window, in row
    /// order — the acceleration rows `Δ²p_j/δt²`, j = 1..N−2, then the speed
    /// rows `Δp_j/δt`, j = 2..N−1, on the deviation p from the baseline
    /// (so the baseline's own acceleration and speed are subtracted), then
    /// the tilt-rate rows ([`TiltRate::rows`]; `sent` the acceleration the
    /// command sent at k−1 asks for [m/s²]). With a tilt-rate bound the
    /// acceleration rows follow its funnel ([`TiltRate::funnel`]).
    pub(crate) fn row_bounds(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        sent: Option<f64>,
        dt: f64,
        mut out: impl FnMut(f64, f64),
    ) {
        let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
        let a_base = d2 / (dt * dt);
        if let Some([lo, hi]) = self.acceleration_at(fixed, dt) {
            let shift = self.stage_shifts(fixed, dt);
            match &self.tilt_rate {
                Some(rate) => {
                    let mut j = 0;
                    rate.funnel(horizon, fixed, sent, [lo, hi], dt, |a| {
                        j += 1;
                        let sh = shift(j);
                        out((lo + sh).min(a) - a_base, (hi + sh).max(a) - a_base)
                    })
                }
                None => {
                    for j in 1..=horizon - 2 {
                        let sh = shift(j);
                        out(lo + sh - a_base, hi + sh - a_base);
                    }
                }
            }
        }
        self.speed_rows(horizon, fixed, dt, &mut out);
        if let Some(rate) = &self.tilt_rate {
            rate.rows(horizon, fixed, sent, dt, out);
        }
    }

    /// The speed rows of [`AxisBounds::row_bounds`] alone: `(lo, hi)` on
    /// `Δp_j/δt`, j = 2..N−1, funnel included (nothing without a speed
    /// bound).
    pub(crate) fn speed_rows(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        dt: f64,
        mut out: impl FnMut(f64, f64),
    ) {
        let d1 = fixed[1] - fixed[0];
        let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
        if let Some(v) = self.speed {
            let funnel = self.speed_funnel(fixed, dt);
            for j in 2..=horizon - 1 {
                let s_base = (d1 + j as f64 * d2) / dt;
                let limit = funnel.map_or(v, |(v1, a)| v.max(v1 - a * (j - 1) as f64 * dt));
                out(-limit - s_base, limit - s_base);
            }
        }
    }

    /// The fast path's solver for horizon N, weights `(q, r, δt)` and the
    /// smoothness term (the box's solvers build on it), the tilt-rate
    /// bound checked.
    pub(crate) fn fast_solver(
        &self,
        horizon: usize,
        (q, r, dt): (f64, f64, f64),
        smoothness: super::smoothness::Smoothness,
    ) -> Result<super::fast_banded::FastBandedSolver, crate::ControlError> {
        if let Some(t) = &self.tilt_rate {
            t.check()?;
        }
        super::fast_banded::FastBandedSolver::with_smoothness(horizon, q, r, dt, smoothness)
    }

    /// True when no bound is set.
    pub fn is_empty(&self) -> bool {
        self.acceleration.is_none() && self.speed.is_none() && self.tilt_rate.is_none()
    }

    /// [`AxisBounds::violated_by`], or the tilt-rate bound violated
    /// ([`TiltRate::violated_by`], `sent` as in `AxisBounds::row_bounds`):
    /// the check of the fast plan.
    pub fn violated(&self, plan: &[f64], sent: Option<f64>, dt: f64) -> bool {
        self.violated_by(plan, dt)
            || self
                .tilt_rate
                .is_some_and(|r| r.violated_by(plan, sent, dt))
    }

    /// True when `plan` (`y_0..y_N` \[m\], step δt \[s\]; its first three
    /// the window's fixed outputs) violates a bound by more than a relative
    /// 1e-6 (absolute 1e-9 near zero bounds).
    pub fn violated_by(&self, plan: &[f64], dt: f64) -> bool {
        let tol = |b: f64| 1e-6 * b.abs() + 1e-9;
        let n = plan.len();
        let fixed = match plan {
            [a, b, c, ..] => [*a, *b, *c],
            _ => return false,
        };
        if let Some([lo, hi]) = self.acceleration_at(&fixed, dt) {
            let dt2 = dt * dt;
            let shift = self.stage_shifts(&fixed, dt);
            for j in 1..n.saturating_sub(2) {
                let a = (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / dt2;
                let sh = shift(j);
                let (lo, hi) = (lo + sh, hi + sh);
                if a > hi + tol(hi) || a < lo - tol(lo) {
                    return true;
                }
            }
        }
        if let Some(v) = self.speed {
            for j in 2..n.saturating_sub(1) {
                let s = (plan[j + 1] - plan[j]) / dt;
                if s.abs() > v + tol(v) {
                    return true;
                }
            }
        }
        false
    }
}

/// Most entries of a [`Row`]: a tilt-rate row on three stage
/// accelerations spans five free outputs.
const ROW_ENTRIES: usize = 5;

/// A bound row `g·v` over at most five indices of a solver's unknowns
/// (the banded interior points' and the augmented Lagrangian's speed,
/// acceleration and tilt-rate rows).
#[derive(Debug, Clone, Copy)]
pub(super) struct Row {
    pub(super) idx: [usize; ROW_ENTRIES],
    pub(super) coef: [f64; ROW_ENTRIES],
    pub(super) len: usize,
}

impl Row {
    /// A row from its entries (at most [`ROW_ENTRIES`], distinct indices).
    fn from_entries(entries: &[(usize, f64)]) -> Self {
        let mut row = Self {
            idx: [0; ROW_ENTRIES],
            coef: [0.0; ROW_ENTRIES],
            len: entries.len(),
        };
        for (k, &(i, c)) in entries.iter().enumerate() {
            row.idx[k] = i;
            row.coef[k] = c;
        }
        row
    }

    /// The row `v[index]` (coefficient 1).
    pub(super) fn single(index: usize) -> Self {
        Self::from_entries(&[(index, 1.0)])
    }

    /// This row over the free outputs p instead of the stage accelerations
    /// ã: each `ã_s = (p_s − 2p_{s−1} + p_{s−2})/δt²` (p before the
    /// horizon 0) expanded, `stage(k)` the stage of entry k of `self`
    /// (whose `idx` are stage numbers), p_s at `index(s)`.
    pub(super) fn on_outputs(&self, inv_dt2: f64, index: impl Fn(usize) -> usize) -> Self {
        let top = self.idx[..self.len].iter().copied().max().unwrap_or(0);
        // Entry o holds p_{top − o}.
        let mut coef = [0.0; ROW_ENTRIES];
        for k in 0..self.len {
            let s = self.idx[k];
            for (m, d) in [1.0, -2.0, 1.0].into_iter().enumerate() {
                if s >= m {
                    coef[top - (s - m)] += self.coef[k] * d * inv_dt2;
                }
            }
        }
        let mut entries = [(0, 0.0); ROW_ENTRIES];
        let mut len = 0;
        for (o, &c) in coef.iter().enumerate() {
            if c != 0.0 && o <= top {
                entries[len] = (index(top - o), c);
                len += 1;
            }
        }
        Self::from_entries(&entries[..len])
    }

    /// The largest distance between two of its indices (the band it
    /// needs).
    pub(super) fn span(&self) -> usize {
        let idx = &self.idx[..self.len];
        match (idx.iter().max(), idx.iter().min()) {
            (Some(a), Some(b)) => a - b,
            _ => 0,
        }
    }

    /// Tilt-rate row f = 0..n−1 ([`TiltRate::rows`]) on the planned
    /// accelerations ã at `index(k)`: ã_0 alone for f = 0, else
    /// `κ·ã_f + (1 − 2κ)·ã_{f−1} − (1 − κ)·ã_{f−2}` (ã_{−1} = 0).
    pub(super) fn tilt_rate(f: usize, kappa: f64, index: impl Fn(usize) -> usize) -> Self {
        match f {
            0 => Self::single(index(0)),
            1 => Self::from_entries(&[(index(1), kappa), (index(0), 1.0 - 2.0 * kappa)]),
            _ => Self::from_entries(&[
                (index(f), kappa),
                (index(f - 1), 1.0 - 2.0 * kappa),
                (index(f - 2), kappa - 1.0),
            ]),
        }
    }

    /// Speed row g = 0..n−1 per axis, `(p_g − p_{g−1})/δt` with p_{−1} = 0
    /// (the output after the fixed ones starts from the baseline), p_k at
    /// `index(k)`.
    pub(super) fn speed(g: usize, dt: f64, index: impl Fn(usize) -> usize) -> Self {
        if g == 0 {
            Self::from_entries(&[(index(0), 1.0 / dt)])
        } else {
            Self::from_entries(&[(index(g - 1), -1.0 / dt), (index(g), 1.0 / dt)])
        }
    }

    /// The speed rows g = 0..n−1 of both horizontal axes, axis 0's first
    /// (the order in which the cone solvers shift their multipliers),
    /// p_{axis, k} at `index(axis, k)`.
    pub(super) fn speed_pair(
        n: usize,
        dt: f64,
        index: impl Fn(usize, usize) -> usize,
    ) -> Vec<Self> {
        (0..2)
            .flat_map(|axis| (0..n).map(move |g| (axis, g)))
            .map(|(axis, g)| Self::speed(g, dt, |k| index(axis, k)))
            .collect()
    }

    /// `g·v`.
    pub(super) fn dot(&self, v: &[f64]) -> f64 {
        self.dot_shifted(v, 0)
    }

    /// The row moved `shift` unknowns on, times v: `Σ g_k·v[idx_k +
    /// shift]`, summed in order (a [`RowRun`]'s rows past its first).
    #[inline(always)]
    fn dot_shifted(&self, v: &[f64], shift: usize) -> f64 {
        let mut s = 0.0;
        for k in 0..self.len {
            s += self.coef[k] * v[self.idx[k] + shift];
        }
        s
    }

    /// `out += a·g`.
    pub(super) fn axpy(&self, a: f64, out: &mut [f64]) {
        for k in 0..self.len {
            out[self.idx[k]] += a * self.coef[k];
        }
    }
}

/// A run of consecutive rows that are one row shifted by `stride`
/// unknowns per row (a block's rows past its truncated first ones): their
/// products with a vector in one pass, the first row's indices and
/// coefficients held ([`RowRun::products`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct RowRun {
    /// The rows `start..end`.
    pub(super) start: usize,
    pub(super) end: usize,
    row: Row,
    stride: usize,
}

impl RowRun {
    /// The maximal runs of `rows`, in order (a row shifted from none of
    /// its neighbours is a run of one).
    pub(super) fn runs(rows: &[Row]) -> Vec<Self> {
        let mut runs: Vec<Self> = Vec::new();
        for (r, row) in rows.iter().enumerate() {
            if let Some(run) = runs.last_mut()
                && run.end == r
                && run.extends(row)
            {
                run.end += 1;
                continue;
            }
            runs.push(Self {
                start: r,
                end: r + 1,
                row: *row,
                stride: 0,
            });
        }
        runs
    }

    /// Whether `next` (the row after the run's last) extends the run: the
    /// same coefficients, every index moved by one stride (> 0).
    fn extends(&mut self, next: &Row) -> bool {
        let (first, len) = (&self.row, self.row.len);
        if next.len != len || len == 0 || next.coef[..len] != first.coef[..len] {
            return false;
        }
        let count = self.end - self.start;
        let Some(step) = next.idx[0].checked_sub(first.idx[0]) else {
            return false;
        };
        let stride = if count == 1 { step } else { self.stride };
        if stride == 0 || step != stride * count {
            return false;
        }
        let shifted = (0..len).all(|k| next.idx[k] == first.idx[k] + stride * count);
        if shifted {
            self.stride = stride;
        }
        shifted
    }

    /// `out[r] = h_r·v` for the run's rows r from `from` on: the first
    /// row shifted ([`Row::dot`]'s own sum).
    pub(super) fn products(&self, v: &[f64], from: usize, out: &mut [f64]) {
        let first = from.max(self.start);
        for (r, o) in out[first..self.end].iter_mut().enumerate() {
            *o = self
                .row
                .dot_shifted(v, self.stride * (first - self.start + r));
        }
    }
}

/// The data check of the banded solvers over rows (the stage interior
/// point, the cone's interior point and augmented Lagrangian): `shape_ok`
/// (else the error says `shape`, the lengths expected), every entry of
/// `data` and of the row bounds finite, and `lo ≤ hi` row by row.
/// [`check_row_data`] for a solve's data: the linear term `c` of `len`
/// entries, one `lo`/`hi` pair per row (`rows` of them), finite data
/// (`c`, the iterate `x`, `a0`) with lo ≤ hi; `shape` says what is
/// expected.
#[allow(clippy::too_many_arguments)] // the solve's data, as the solvers take it
pub(super) fn check_solve_data(
    field: &'static str,
    (c, len): (&[f64], usize),
    rows: usize,
    x: &[f64],
    a0: &[f64; 2],
    (lo, hi): (&[f64], &[f64]),
    shape: &str,
) -> Result<(), crate::ControlError> {
    let shape_ok = c.len() == len && lo.len() == rows && hi.len() == rows;
    check_row_data(field, shape_ok, shape, &[c, x, a0], lo, hi)
}

pub(super) fn check_row_data(
    field: &'static str,
    shape_ok: bool,
    shape: &str,
    data: &[&[f64]],
    lo: &[f64],
    hi: &[f64],
) -> Result<(), crate::ControlError> {
    if !shape_ok {
        return Err(super::problem::invalid(field, shape));
    }
    let finite = |v: &[f64]| v.iter().all(|a| a.is_finite());
    if !(data.iter().all(|v| finite(v)) && finite(lo) && finite(hi))
        || lo.iter().zip(hi).any(|(l, h)| l > h)
    {
        return Err(super::problem::invalid(field, "finite data with lo ≤ hi"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The acceleration bound on the plan follows the thrust's: `−D·v_1`
    /// from the drag without an offset, the tick's offset when one is
    /// set (whatever the drag), nothing shifted without either; a
    /// non-finite offset falls back to the drag's.
    #[test]
    fn the_acceleration_bound_moves_with_the_models_offset() {
        let dt = 0.02;
        // Window speed v_1 = (y_2 − y_1)/δt = 5 m/s.
        let fixed = [0.0, 0.1, 0.2];
        let mut b = AxisBounds {
            acceleration: Some([-4.0, 4.0]),
            drag: 0.4,
            ..AxisBounds::default()
        };
        let near = |a: Option<[f64; 2]>, want: [f64; 2]| {
            let a = a.unwrap();
            (a[0] - want[0]).abs() < 1e-12 && (a[1] - want[1]).abs() < 1e-12
        };
        assert!(near(b.acceleration_at(&fixed, dt), [-6.0, 2.0]));
        b.offset = Some(1.5);
        assert!(near(b.acceleration_at(&fixed, dt), [-2.5, 5.5]));
        b.offset = Some(f64::NAN);
        assert!(near(b.acceleration_at(&fixed, dt), [-6.0, 2.0]));
        b.drag = 0.0;
        b.offset = None;
        assert!(near(b.acceleration_at(&fixed, dt), [-4.0, 4.0]));
        // The fast plan's check reads the same bound: a plan at 5 m/s²
        // keeps it with the offset 1.5, breaks it without.
        let plan: Vec<f64> = (0..8)
            .map(|j| 0.1 * j as f64 + 0.5 * 5.0 * (j as f64 * dt).powi(2))
            .collect();
        assert!(b.violated_by(&plan, dt));
        b.offset = Some(1.5);
        assert!(!b.violated_by(&plan, dt));
    }

    /// Along the horizon the drag's offset shrinks with a braking plan's
    /// speed, to 0 and not past it; where it would grow, every stage
    /// keeps the start's; the solvers' rows and the fast plan's check read
    /// the same stage bounds.
    #[test]
    fn a_braking_plans_bound_loses_the_drag_as_it_slows() {
        let dt = 0.02;
        // v_1 = 5 m/s, a = −2 m/s² (y_0..y_2): the drag 0.4 /s gives o_1 =
        // −2 m/s², shrinking by D·|a|·δt = 0.016 m/s² a stage.
        let fixed = [0.0, 0.1 + 2.0 * dt * dt, 0.2 + 2.0 * dt * dt];
        let o1 = -0.4 * (fixed[2] - fixed[1]) / dt;
        let b = AxisBounds {
            acceleration: Some([-4.0, 4.0]),
            drag: 0.4,
            offset_slope: 0.016,
            ..AxisBounds::default()
        };
        let shift = b.stage_shifts(&fixed, dt);
        assert_eq!(shift(1), 0.0);
        assert!((shift(11) - 0.16).abs() < 1e-12);
        // 125 stages take the offset to 0; later stages stay there.
        assert!((shift(200) + o1).abs() < 1e-12);
        let growing = AxisBounds {
            offset_slope: -0.016,
            ..b
        };
        assert_eq!(growing.stage_shifts(&fixed, dt)(50), 0.0);
        let mut rows = Vec::new();
        b.row_bounds(200, &fixed, None, dt, |l, h| rows.push((l, h)));
        let a_base = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        for (j, (l, h)) in rows.iter().enumerate().take(198) {
            let [lo, hi] = b.acceleration_at(&fixed, dt).unwrap();
            let sh = shift(j + 1);
            assert!(
                (l - (lo + sh - a_base)).abs() < 1e-12 && (h - (hi + sh - a_base)).abs() < 1e-12
            );
        }
        // A plan braking at the start's bound to the end breaks the later
        // stages' (they lose the drag's help), and not without the slope.
        let [lo, _] = b.acceleration_at(&fixed, dt).unwrap();
        let mut plan = fixed.to_vec();
        for _ in 0..40 {
            let n = plan.len();
            plan.push(2.0 * plan[n - 1] - plan[n - 2] + lo * dt * dt);
        }
        assert!(b.violated_by(&plan, dt));
        assert!(
            !AxisBounds {
                offset_slope: 0.0,
                ..b
            }
            .violated_by(&plan, dt)
        );
    }

    /// The cone's rows (speed and tilt-rate rows of both axes on the
    /// interleaved unknowns, their first rows truncated at the horizon's
    /// start) fall into one run per block past the truncated rows, and a
    /// run's products are each row's own [`Row::dot`], bit for bit; a row
    /// that is no shift of its neighbour starts a run.
    #[test]
    fn row_runs_give_each_rows_product() {
        let (n, dt) = (40, 0.02);
        let inv_dt2 = 1.0 / (dt * dt);
        let mut rows = Vec::new();
        for axis in 0..2 {
            rows.extend((0..n).map(|g| Row::speed(g, dt, |k| 2 * k + axis)));
        }
        for axis in 0..2 {
            rows.extend(
                (0..n).map(|f| Row::tilt_rate(f, 3.5, |s| s).on_outputs(inv_dt2, |k| 2 * k + axis)),
            );
        }
        // A row breaking the tilt-rate run of axis 1 at f = 20.
        let broken = 3 * n + 20;
        rows[broken].coef[0] *= 1.5;
        let runs = RowRun::runs(&rows);
        // Contiguous, in order, covering every row.
        assert_eq!(runs[0].start, 0);
        assert_eq!(runs.last().unwrap().end, rows.len());
        assert!(runs.windows(2).all(|w| w[0].end == w[1].start));
        // Few runs: each block's truncated first rows (one speed row, four
        // tilt-rate rows), then one run; the broken row splits its block's
        // in two around itself.
        let spans: Vec<_> = runs.iter().map(|r| (r.start, r.end)).collect();
        assert_eq!(runs.len(), 2 * 2 + 2 * 5 + 2, "{spans:?}");
        assert!(
            runs.iter()
                .any(|r| r.start == broken && r.end == broken + 1)
        );
        assert!(runs.iter().any(|r| r.end - r.start == n - 1));
        assert!(runs.iter().any(|r| r.end - r.start == n - 4));
        let v: Vec<f64> = (0..2 * n)
            .map(|i| ((i * 7919) % 97) as f64 * 0.013 - 0.6)
            .collect();
        let mut out = vec![f64::NAN; rows.len()];
        for run in &runs {
            run.products(&v, run.start, &mut out);
        }
        for (r, row) in rows.iter().enumerate() {
            assert_eq!(out[r].to_bits(), row.dot(&v).to_bits(), "row {r}");
        }
        // From a later row on, the earlier ones are left alone.
        let mut part = vec![f64::NAN; rows.len()];
        let run = runs.iter().find(|r| r.end - r.start >= 10).unwrap();
        run.products(&v, run.start + 5, &mut part);
        assert!(part[run.start..run.start + 5].iter().all(|p| p.is_nan()));
        assert_eq!(
            part[run.start + 5].to_bits(),
            rows[run.start + 5].dot(&v).to_bits()
        );
    }
}
