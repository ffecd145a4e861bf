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

use super::bounds::AxisBounds;

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
}

impl ConeBounds {
    /// The cone `‖a‖ ≤ acceleration` [m/s²] with an optional soft speed
    /// bound [m/s] and the default penalty ([`DEFAULT_SPEED_PENALTY`]).
    pub fn new(acceleration: f64, speed: Option<f64>) -> Self {
        Self {
            acceleration,
            speed,
            speed_penalty: DEFAULT_SPEED_PENALTY,
        }
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
        }
    }

    /// True when the plans `x`, `y` (`y_0..y_N` \[m\], step δt \[s\]) leave
    /// the cone by more than a relative 1e-6 or break a speed bound (as
    /// [`AxisBounds::violated_by`]).
    pub fn violated_by(&self, x: &[f64], y: &[f64], dt: f64) -> bool {
        self.violated_within(x, y, dt, &[])
    }

    /// As [`ConeBounds::violated_by`] with the cone's radius per stage
    /// (`radius[j − 1]` bounds the acceleration row j = 1..N−2; the
    /// constant A where `radius` is shorter).
    pub fn violated_within(&self, x: &[f64], y: &[f64], dt: f64, radius: &[f64]) -> bool {
        let dt2 = dt * dt;
        let n = x.len().min(y.len());
        for j in 1..n.saturating_sub(2) {
            let r = radius.get(j - 1).copied().unwrap_or(self.acceleration);
            let ax = (x[j + 2] - 2.0 * x[j + 1] + x[j]) / dt2;
            let ay = (y[j + 2] - 2.0 * y[j + 1] + y[j]) / dt2;
            if ax.hypot(ay) > r * (1.0 + 1e-6) + 1e-9 {
                return true;
            }
        }
        let speed = AxisBounds {
            acceleration: None,
            speed: self.speed,
            tilt_rate: None,
            drag: 0.0,
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
