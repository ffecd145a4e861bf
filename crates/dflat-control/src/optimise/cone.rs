//! The tilt cone on the horizontal plan: bounds of the two-axis problem
//! solved by [`BandedConeSolver`](super::BandedConeSolver)
//! and [`ClarabelConeSolver`](super::ClarabelConeSolver).
//!
//! # The problem
//!
//! Both horizontal axes (x, y), each as in [`ClarabelSolver`](super::ClarabelSolver)
//! (deviation `p` of the free outputs from the zero-jerk baseline,
//! planned acceleration `ã` relative to the fixed one, jerk and
//! smoothness costs), and per stage f = 0..N−3 (acceleration row j = f + 1)
//! the **tilt cone**
//!
//! ```text
//! ‖(a_x,f, a_y,f)‖ ≤ g·tan(tilt_max),    a_f = Δ²y_{f+1}/δt² = a_0 + ã_f
//! ```
//!
//! (a second-order cone in `(g·tan, a_x, a_y)`; the interior point treats it
//! as the convex quadratic constraint `½(‖a_f‖² − A²) ≤ 0`, the same set).
//! The radius may differ per stage (`set_radius` on the solvers): the
//! spatial model plans thrust, and its tilt is `atan(‖a_h‖/(g − a_z))`
//! (NED; `g + a_z` z up), so the DF-MPC solves the vertical axis first and
//! bounds each stage by `A_f = tan(tilt_max)·(g − a_z,f)` from that plan
//! (the thrust's vertical part floored at 0.2·g) — exact for the planned
//! thrust, though not jointly optimal over the three axes.
//! Optionally per axis the **speed** rows `|Δy_j/δt| ≤ v`, j = 2..N−1, as
//! in [`AxisBounds`]: *soft* — each side `g·x ≤ h + σ`, `σ ≥ 0`, with the
//! exact (L1) penalty `ρ·σ` in the cost — so that no combination of
//! bounds makes the tick infeasible: the cone alone always is feasible (every
//! stage has its own free acceleration), speed and cone together are not
//! (a window faster than the bound cannot brake at more than the cone).
//! With ρ above the largest multiplier of the hard speed rows the soft
//! problem has the hard problem's solution whenever that one exists. The
//! braking funnel ([`AxisBounds::speed`]) brakes each axis at 90 % of
//! `A/√2`, a rate both axes can keep at once inside the cone.
//!
//! Optionally per axis the **tilt-rate** rows of [`TiltRate`] (hard, on
//! the stage accelerations ã, after the speed rows: axis x's, then y's).
//! With them the cone's radius of each stage widens to a **funnel**
//! (`ConeBounds::funnel_radius`) as the box's acceleration rows do: a
//! witness trajectory — each axis's command moved from the sent one at
//! 90 % of the rate bound towards the sent command's projection onto the
//! narrowest disc (with a speed bound: braking at the speed funnel's rate
//! while faster than the bound, else 0), the accelerations its
//! first-order response — keeps every tilt-rate row by construction;
//! stage f's radius is at least the witness's `‖a_f‖`, and with a speed
//! bound each speed row's bound at least the witness's speed, so that
//! disc, speed and rate rows together stay feasible when the window's
//! attitude or the sent command lies outside the cone (a radius that
//! shrank, a command saturated elsewhere) or the window is faster than
//! the speed bound (the braking the rate rows allow is slower than the
//! plain funnel's).

use super::bounds::{AxisBounds, TiltRate};

/// Share of the rate bound the funnel's witness moves at (module docs):
/// below 1, so that the plans that keep the funnel (disc and speed rows)
/// and the rate rows have an interior — at 1 the witness's speed would be
/// the only one the speed rows allow while it brakes, and the interior
/// points stall on the set's empty interior (clarabel: `InsufficientProgress`).
pub(crate) const FUNNEL_RATE: f64 = 0.9;

/// Default exact penalty ρ of a soft speed row, per m/s of violation
/// (cost units of `q·m²`): far above the multipliers the speed rows take
/// with the weights of this crate (< 10 on the property tests' instances).
pub const DEFAULT_SPEED_PENALTY: f64 = 1e4;

/// Bounds of the two-axis (horizontal) problem: the tilt cone and, per
/// axis, soft speed bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeBounds {
    /// `A = g·tan(tilt_max)` [m/s²]: the largest horizontal acceleration
    /// magnitude (> 0).
    pub acceleration: f64,
    /// Speed bound per axis `|Δy/δt| ≤ v` [m/s], soft. `None`: none.
    pub speed: Option<f64>,
    /// Exact penalty ρ of the soft speed rows, per m/s of violation (> 0).
    pub speed_penalty: f64,
    /// The tilt-rate bound per axis (x, y), hard (module docs). `None`:
    /// none.
    pub tilt_rate: Option<[TiltRate; 2]>,
}

impl ConeBounds {
    /// The cone `‖a‖ ≤ acceleration` [m/s²] with an optional soft speed
    /// bound [m/s] and the default penalty ([`DEFAULT_SPEED_PENALTY`]).
    pub fn new(acceleration: f64, speed: Option<f64>) -> Self {
        Self {
            acceleration,
            speed,
            speed_penalty: DEFAULT_SPEED_PENALTY,
            tilt_rate: None,
        }
    }

    /// These bounds with the tilt-rate bound per axis (x, y).
    pub fn with_tilt_rate(self, tilt_rate: [TiltRate; 2]) -> Self {
        Self {
            tilt_rate: Some(tilt_rate),
            ..self
        }
    }

    /// Number of bound rows of `n` stages per axis: the speed rows (n per
    /// axis with a speed bound), then the tilt-rate rows (n per axis).
    pub(crate) fn rows(&self, n: usize) -> usize {
        let per_axis = usize::from(self.speed.is_some()) + usize::from(self.tilt_rate.is_some());
        2 * n * per_axis
    }

    /// The rows' bounds `(lo, hi)` in row order ([`ConeBounds::rows`]):
    /// the speed rows per axis with the funnel of the narrowest of
    /// `radius` ([`ConeBounds::axis_within`]), then the tilt-rate rows per
    /// axis ([`TiltRate::rows`]; `sent` the accelerations the command sent
    /// at k−1 asks for [m/s²]), on the deviations from the baseline.
    /// `centre`: the discs' centres ([`centre_at`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn row_bounds(
        &self,
        horizon: usize,
        fixed: [&[f64; 3]; 2],
        sent: [Option<f64>; 2],
        radius: &[f64],
        centre: &[[f64; 2]],
        dt: f64,
        mut out: impl FnMut(f64, f64),
    ) {
        match (self.speed, &self.tilt_rate) {
            (Some(limit), Some(_)) => {
                // The speed funnel of the rate-limited witness (module docs):
                // row j = f + 2 bounds |v_j| by max(v, the witness's), v_j =
                // v_{j−1} + a_{j−1}·δt from the window's v_1.
                let mut v = 0.0;
                self.witness(
                    (radius, centre),
                    fixed,
                    sent,
                    dt,
                    FUNNEL_RATE,
                    |axis, f, a| {
                        let fx = fixed[axis];
                        if f == 0 {
                            v = (fx[2] - fx[1]) / dt;
                        }
                        v += a * dt;
                        let (d1, d2) = (fx[1] - fx[0], fx[2] - 2.0 * fx[1] + fx[0]);
                        let s_base = (d1 + (f + 2) as f64 * d2) / dt;
                        let l = limit.max(v.abs());
                        out(-l - s_base, l - s_base);
                    },
                );
            }
            _ => {
                let axis = self.axis_within(radius);
                for fx in fixed {
                    axis.speed_rows(horizon, fx, dt, &mut out);
                }
            }
        }
        if let Some(rates) = &self.tilt_rate {
            for ((rate, fx), s) in rates.iter().zip(fixed).zip(sent) {
                rate.rows(horizon, fx, s, dt, &mut out);
            }
        }
    }

    /// The radius per stage the solvers enforce: `radius` (the cone's,
    /// one per stage f = 0..n−1 [m/s²]), widened with a tilt-rate bound to
    /// the witness's `‖a_f − o_f‖` (module docs: the funnel; o_f the
    /// disc's centre, [`centre_at`]); `radius` itself without one. `fixed`
    /// and `sent` per axis as [`ConeBounds::row_bounds`].
    pub(crate) fn funnel_radius(
        &self,
        (radius, centre): (&[f64], &[[f64; 2]]),
        fixed: [&[f64; 3]; 2],
        sent: [Option<f64>; 2],
        dt: f64,
        out: &mut [f64],
    ) {
        out.copy_from_slice(radius);
        // Axis x's witness into `out`, then the norm with axis y's.
        self.witness(
            (radius, centre),
            fixed,
            sent,
            dt,
            FUNNEL_RATE,
            |axis, f, a| {
                let o = centre_at(centre, f);
                out[f] = if axis == 0 {
                    a - o[0]
                } else {
                    radius[f].max(out[f].hypot(a - o[1]))
                };
            },
        );
    }

    /// The witness at `shrink`·B per tick as deviations `p` per axis from
    /// the baseline (n each; `Δ²p_f = ã_f·δt²`): strictly inside the rate
    /// rows for `shrink` < 1, the interior point's start. No effect
    /// without a tilt-rate bound.
    pub(crate) fn witness_start(
        &self,
        disc: (&[f64], &[[f64; 2]]),
        fixed: [&[f64; 3]; 2],
        sent: [Option<f64>; 2],
        dt: f64,
        shrink: f64,
        [px, py]: [&mut [f64]; 2],
    ) {
        let a0 = fixed.map(|f| (f[2] - 2.0 * f[1] + f[0]) / (dt * dt));
        let dt2 = dt * dt;
        self.witness(disc, fixed, sent, dt, shrink, |axis, f, a| {
            let p = if axis == 0 { &mut *px } else { &mut *py };
            let at = |k: usize| if f >= k { p[f - k] } else { 0.0 };
            p[f] = 2.0 * at(1) - at(2) + (a - a0[axis]) * dt2;
        });
    }

    /// The witness trajectory of the funnel (module docs) at `shrink`·B
    /// per tick: `out(axis, f, a_f)` for axis x's stages f = 0..n−1, then
    /// axis y's [m/s²]. Nothing without a tilt-rate bound. Each axis's
    /// command moves towards, with a speed bound v, `∓b` while the
    /// witness is faster than v and 0 otherwise (b = 0.9·A_min/√2, the
    /// speed funnel's braking: a point inside every disc), without one
    /// the sent command's projection onto the narrowest disc — each
    /// relative to the first stage's centre o_0 ([`centre_at`]).
    fn witness(
        &self,
        (radius, centre): (&[f64], &[[f64; 2]]),
        fixed: [&[f64; 3]; 2],
        sent: [Option<f64>; 2],
        dt: f64,
        shrink: f64,
        mut out: impl FnMut(usize, usize, f64),
    ) {
        let Some(rates) = &self.tilt_rate else {
            return;
        };
        let horizon = radius.len() + 2;
        let a0 = fixed.map(|f| (f[2] - 2.0 * f[1] + f[0]) / (dt * dt));
        let o = centre_at(centre, 0);
        let c = [0, 1].map(|i| sent[i].unwrap_or(a0[i]) - o[i]);
        let narrowest = radius.iter().copied().fold(f64::INFINITY, f64::min);
        let norm = c[0].hypot(c[1]);
        let scale = if norm > narrowest {
            narrowest / norm
        } else {
            1.0
        };
        let brake = 0.9 * narrowest / std::f64::consts::SQRT_2;
        for axis in 0..2 {
            let projected = c[axis] * scale;
            let target = |v: f64| {
                o[axis]
                    + match self.speed {
                        Some(limit) if v > limit => -brake,
                        Some(limit) if v < -limit => brake,
                        Some(_) => 0.0,
                        None => projected,
                    }
            };
            let mut f = 0;
            rates[axis].witness_toward(horizon, fixed[axis], sent[axis], dt, shrink, target, |a| {
                out(axis, f, a);
                f += 1;
            });
        }
    }

    /// True when a tilt-rate row of either axis is broken by the plans
    /// ([`TiltRate::violated_by`]; `sent` per axis: the accelerations the
    /// command sent at k−1 asks for [m/s²]).
    pub fn rate_violated_by(&self, plans: [&[f64]; 2], sent: [Option<f64>; 2], dt: f64) -> bool {
        self.tilt_rate
            .is_some_and(|rates| (0..2).any(|i| rates[i].violated_by(plans[i], sent[i], dt)))
    }

    /// The per-axis view used for the speed rows: the speed bound with the
    /// box `±A/√2` that sets the braking funnel's rate — with the cone's
    /// radius per stage (`radius`; empty: A), the narrowest stage's
    /// `A_f/√2`, a rate every stage allows on both axes at once (the
    /// spatial model's cone narrows where the plan descends).
    pub(crate) fn axis_within(&self, radius: &[f64]) -> AxisBounds {
        let narrowest = radius.iter().copied().fold(self.acceleration, f64::min);
        let a = narrowest / std::f64::consts::SQRT_2;
        AxisBounds {
            acceleration: Some([-a, a]),
            speed: self.speed,
            tilt_rate: None,
            drag: 0.0,
            offset: None,
            offset_slope: 0.0,
        }
    }

    /// True when the plans `x`, `y` (`y_0..y_N` \[m\], step δt \[s\]) leave
    /// the cone by more than a relative 1e-6 or break a speed bound (as
    /// [`AxisBounds::violated_by`]).
    pub fn violated_by(&self, x: &[f64], y: &[f64], dt: f64) -> bool {
        self.violated_within(x, y, dt, (&[], &[]))
    }

    /// As [`ConeBounds::violated_by`] with the cone's radius per stage
    /// (`radius[j − 1]` bounds the acceleration row j = 1..N−2; the
    /// constant A where `radius` is shorter) and its centre per stage
    /// ([`centre_at`]: the disc bounds `a − o`).
    pub fn violated_within(
        &self,
        x: &[f64],
        y: &[f64],
        dt: f64,
        (radius, centre): (&[f64], &[[f64; 2]]),
    ) -> bool {
        let dt2 = dt * dt;
        let n = x.len().min(y.len());
        for j in 1..n.saturating_sub(2) {
            let r = radius.get(j - 1).copied().unwrap_or(self.acceleration);
            let o = centre_at(centre, j - 1);
            let ax = (x[j + 2] - 2.0 * x[j + 1] + x[j]) / dt2 - o[0];
            let ay = (y[j + 2] - 2.0 * y[j + 1] + y[j]) / dt2 - o[1];
            if ax.hypot(ay) > r * (1.0 + 1e-6) + 1e-9 {
                return true;
            }
        }
        let speed = AxisBounds {
            acceleration: None,
            speed: self.speed,
            tilt_rate: None,
            drag: 0.0,
            offset: None,
            offset_slope: 0.0,
        };
        speed.violated_by(x, dt) || speed.violated_by(y, dt)
    }

    /// Largest planned horizontal acceleration magnitude [m/s²] of the
    /// plans `x`, `y` over the acceleration rows j = 1..N−2.
    pub fn peak_acceleration(x: &[f64], y: &[f64], dt: f64) -> f64 {
        let dt2 = dt * dt;
        let n = x.len().min(y.len());
        (1..n.saturating_sub(2))
            .map(|j| {
                let ax = (x[j + 2] - 2.0 * x[j + 1] + x[j]) / dt2;
                let ay = (y[j + 2] - 2.0 * y[j + 1] + y[j]) / dt2;
                ax.hypot(ay)
            })
            .fold(0.0, f64::max)
    }

    pub(crate) fn check(&self) -> Result<(), crate::ControlError> {
        if !(self.acceleration.is_finite() && self.acceleration > 0.0) {
            return Err(super::problem::invalid(
                "constraints.max_tilt",
                "a cone acceleration g·tan(tilt) finite and > 0 (m/s²)",
            ));
        }
        if self.speed.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
            return Err(super::problem::invalid(
                "constraints.max_speed",
                "finite and > 0 (m/s)",
            ));
        }
        if !(self.speed_penalty.is_finite() && self.speed_penalty > 0.0) {
            return Err(super::problem::invalid(
                "constraints.speed_penalty",
                "finite and > 0 (per m/s)",
            ));
        }
        if let Some(rates) = &self.tilt_rate {
            rates.iter().try_for_each(TiltRate::check)?;
        }
        Ok(())
    }
}

/// Checks a cone radius per stage for a solver of `n` stages: n entries,
/// each finite and > 0 [m/s²].
pub(crate) fn check_radius(radius: &[f64], n: usize) -> Result<(), crate::ControlError> {
    if radius.len() != n || radius.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(super::problem::invalid(
            "cone radius",
            "one finite radius > 0 per stage",
        ));
    }
    Ok(())
}

/// Stage f's disc centre o_f [m/s²] of `centre` (per stage f = 0..n−1:
/// the plan's acceleration less the thrust's, the drag and a learned
/// residual); 0 where `centre` is shorter (empty: every disc about 0).
pub fn centre_at(centre: &[[f64; 2]], f: usize) -> [f64; 2] {
    centre.get(f).copied().unwrap_or([0.0; 2])
}

/// Checks a cone's centre per stage for a solver of `n` stages: n
/// entries, each finite [m/s²].
pub(crate) fn check_centre(centre: &[[f64; 2]], n: usize) -> Result<(), crate::ControlError> {
    if centre.len() != n || centre.iter().flatten().any(|c| !c.is_finite()) {
        return Err(super::problem::invalid(
            "cone centre",
            "one finite centre per stage",
        ));
    }
    Ok(())
}
