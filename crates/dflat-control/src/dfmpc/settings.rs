//! DF-MPC's settings: weights, horizon, saturation, constraints, solver
//! choice, multi-rate window and disturbance estimator; one `validate`.

use serde::{Deserialize, Serialize};

use crate::disturbance::DisturbanceSettings;
use crate::optimise::{check_problem, invalid};
use crate::window::MultiRateSettings;
use crate::{ControlError, Limit, TiltLimit};

// ---------------------------------------------------------------------------
// Settings
// ---------------------------------------------------------------------------

/// Input saturation applied to the command after the output-to-input map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputSaturation {
    /// Tilt limit of the pitch / roll command \[rad\], applied as
    /// `tilt_limit` says. Default 35° (the DJI SDK limit).
    pub max_tilt: f64,
    /// How `max_tilt` applies: each channel clipped (default, the paper) or
    /// the combined tilt bounded ([`TiltLimit::Cone`], the daemon).
    pub tilt_limit: TiltLimit,
    /// Smallest specific thrust command [m/s²] (spatial model only). Default 2.
    pub thrust_min: f64,
    /// Largest specific thrust command [m/s²] (spatial model only). Default 20.
    pub thrust_max: f64,
}

impl Default for InputSaturation {
    fn default() -> Self {
        Self {
            max_tilt: 35f64.to_radians(),
            tilt_limit: TiltLimit::PerAxis,
            thrust_min: 2.0,
            thrust_max: 20.0,
        }
    }
}

/// How the plan's tilt bound ([`OutputConstraints::max_tilt`]) bounds the
/// horizontal acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PlanTiltBound {
    /// Each axis separately, `|Δ²y/δt²| ≤ g·tan(max_tilt)`: the combined
    /// planned tilt can reach `atan(√2·tan(max_tilt))` (39° at 30°). Each
    /// axis is its own QP ([`BandedInteriorPointSolver`](crate::optimise::BandedInteriorPointSolver)).
    /// Default (the first round's behaviour). At the same bound the cone
    /// tracks slightly worse on L-shaped paths (it flies the bound where
    /// the box flies up to the command limit); at the command limit it
    /// tracks better, with larger command steps at corners:
    /// `docs/results.md`.
    #[default]
    Box,
    /// The tilt cone `‖(ẍ, ÿ)‖ ≤ g·tan(max_tilt)` per stage — the vehicle's
    /// limit — with both horizontal axes in one QP
    /// ([`BandedConeSolver`](crate::optimise::BandedConeSolver),
    /// warm-started; speed bounds soft with an exact penalty).
    Cone,
}

/// Optional inequality constraints on the planned outputs (solved when the
/// unconstrained plan violates them).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConstraints {
    /// Max tilt \[rad\] as a bound on the planned horizontal acceleration
    /// `g·tan(max_tilt)`, as [`DfMpcSettings::plan_tilt_bound`] says
    /// (a box per axis by default). Default none.
    pub max_tilt: Option<f64>,
    /// Max speed per axis `|Δy/δt|` [m/s]; when the window is already
    /// faster, the plan brakes to it at 90 % of the acceleration bound
    /// ([`AxisBounds::speed`](crate::optimise::AxisBounds::speed); with the
    /// cone, at 90 % of `g·tan(max_tilt)/√2` per axis — with the spatial
    /// model, of its narrowest stage's radius — and the horizontal speed
    /// rows are soft: [`ConeBounds`](crate::optimise::ConeBounds)). Default
    /// none.
    pub max_speed: Option<f64>,
    /// Bounds `[a_min, a_max]` on the vertical acceleration `Δ²z/δt²`
    /// [m/s²] in the model frame (NED: positive down); spatial model only.
    /// Default none.
    pub vertical_acceleration: Option<[f64; 2]>,
    /// Max tilt rate of the command \[rad/s\]: the plan's pitch and roll
    /// commands change by at most `max_tilt_rate·δt` per tick, the first
    /// against the command sent at the previous tick
    /// ([`TiltRate`](crate::optimise::TiltRate): exact in the per-axis
    /// tilt for the first command, linearised about hover after it).
    /// With either plan tilt bound: per axis with the box, as rows of
    /// the pair's QP with the cone ([`PlanTiltBound`]). Default none.
    pub max_tilt_rate: Option<f64>,
}

impl OutputConstraints {
    /// True when at least one constraint is configured.
    pub fn any(&self) -> bool {
        self.max_tilt.is_some()
            || self.max_speed.is_some()
            || self.vertical_acceleration.is_some()
            || self.max_tilt_rate.is_some()
    }
}

/// Which solver handles an axis whose fast plan violates a bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QpSolver {
    /// The banded interior-point method ([`BandedInteriorPointSolver`](crate::optimise::BandedInteriorPointSolver), O(N) per
    /// iteration), with clarabel as the fallback when it does not
    /// converge. Default.
    #[default]
    Banded,
    /// Clarabel alone ([`ClarabelSolver`](crate::optimise::ClarabelSolver)).
    Clarabel,
}

/// Settings of [`DfMpc`](super::DfMpc), checked by [`DfMpcSettings::validate`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DfMpcSettings {
    /// Horizon N [control steps]: outputs y_k..y_{k+N}
    /// ([`DfMpcSettings::HORIZON`]: 10–2000). Default 100 (2 s at 50 Hz).
    pub horizon: usize,
    /// Tracking weight q per axis `[x, y, z]` [1/m²]. Default 5.
    pub tracking_weight: [f64; 3],
    /// Jerk weight r per axis `[x, y, z]` [s⁶/m²] on `(Δ³y/δt³)²`.
    /// Default 0.01. Only r/q shapes the plan: the default 0.002 s⁶ settles
    /// a 10 m step to 1 cm in ~6 s at 35° saturation; the paper's (q = 1,
    /// r = 0.08, N = 200) is slower, with ~5 % overshoot.
    pub jerk_weight: [f64; 3],
    /// Input saturation; `None` sends F's output unclipped. Default on.
    pub saturation: Option<InputSaturation>,
    /// Optional inequality constraints on the plan. Default none.
    pub constraints: OutputConstraints,
    /// The solver for a plan that violates a constraint. Default
    /// [`QpSolver::Banded`].
    pub qp_solver: QpSolver,
    /// How [`OutputConstraints::max_tilt`] applies: a box per axis
    /// (default) or the tilt cone.
    pub plan_tilt_bound: PlanTiltBound,
    /// Warm-start the cone QP from the previous tick's solution, shifted
    /// one step ([`BandedConeSolver`](crate::optimise::BandedConeSolver)).
    /// Default true.
    pub warm_start: bool,
    /// Wall-time limit for one clarabel solve \[s\] (`f64::INFINITY` for
    /// none). Default 0.01.
    pub solver_time_limit: f64,
    /// Command-smoothness weight s per axis `[x, y, z]` [1/rad²] on the
    /// squared change of the (linearised) command between ticks,
    /// `s·((c_j − c_{j−1})/g)²` (see the module docs). Default 0 (off: the
    /// paper's cost). Useful values are O(0.1–10) with q = 1.
    pub smoothness_weight: [f64; 3],
    /// Multi-rate windows: timestamped samples through
    /// [`Controller::observe`](crate::Controller::observe) instead of one measurement per tick
    /// ([`MultiRateWindow`](crate::window::MultiRateWindow)). `None` (default): the paper's window.
    pub multi_rate: Option<MultiRateSettings>,
    /// Disturbance estimation for offset-free tracking
    /// ([`crate::disturbance`]): acceleration offset and thrust scale, used
    /// in F⁻¹ and F. `None` (default) runs the paper's DF-MPC unchanged.
    pub disturbance: Option<DisturbanceSettings>,
    /// Pure input delay d \[ticks\] between sending an input and the
    /// vehicle applying it (0–25, default 0): the controller predicts across
    /// the d inputs sent and not yet in effect and plans from there
    /// (`dfmpc/delay.rs`).
    pub delay_ticks: usize,
}

impl Default for DfMpcSettings {
    fn default() -> Self {
        Self {
            horizon: 100,
            tracking_weight: [5.0; 3],
            jerk_weight: [0.01; 3],
            saturation: Some(InputSaturation::default()),
            constraints: OutputConstraints::default(),
            qp_solver: QpSolver::Banded,
            plan_tilt_bound: PlanTiltBound::Box,
            warm_start: true,
            solver_time_limit: 0.01,
            smoothness_weight: [0.0; 3],
            multi_rate: None,
            disturbance: None,
            delay_ticks: 0,
        }
    }
}

fn tilt_ok(v: f64) -> bool {
    v.is_finite() && v > 0.0 && v < std::f64::consts::FRAC_PI_2
}

impl OutputConstraints {
    /// `max_tilt`, stated in degrees (the daemon's
    /// `controller.constraint_tilt_deg`; 0 there = none).
    pub const MAX_TILT_DEG: Limit = Limit::closed(1.0, 60.0, "deg");
    /// `max_speed` [m/s] (the daemon's `controller.dfmpc.constraint_speed`;
    /// 0 there = none).
    pub const MAX_SPEED: Limit = Limit::above(0.0, 50.0, "m/s");
    /// `max_tilt_rate`, stated in deg/s (the daemon's
    /// `controller.dfmpc.max_tilt_rate_deg_s`; 0 there = none).
    pub const MAX_TILT_RATE_DEG_S: Limit = Limit::closed(10.0, 1000.0, "deg/s");
}

impl DfMpcSettings {
    /// `horizon` [control steps]: at least 10 (a plan fallback of a few
    /// steps), at most 2000 (40 s at 50 Hz; the onboard sanity bound the
    /// daemon had, now the library's too).
    pub const HORIZON: Limit = Limit::closed(10.0, 2000.0, "ticks");
    /// Each `tracking_weight` \[1/m²\].
    pub const TRACKING_WEIGHT: Limit = Limit::positive("1/m²");
    /// Each `jerk_weight` \[s⁶/m²\].
    pub const JERK_WEIGHT: Limit = Limit::positive("s⁶/m²");
    /// Each `smoothness_weight` \[1/rad²\].
    pub const SMOOTHNESS_WEIGHT: Limit = Limit::closed(0.0, 1e4, "1/rad²");

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        Self::HORIZON.check("horizon", self.horizon as f64)?;
        Self::TRACKING_WEIGHT.check_all("tracking_weight", &self.tracking_weight)?;
        Self::JERK_WEIGHT.check_all("jerk_weight", &self.jerk_weight)?;
        Self::SMOOTHNESS_WEIGHT.check_all("smoothness_weight", &self.smoothness_weight)?;
        // The solvers' own structural checks (horizon ≥ 3, finite weights).
        check_problem(
            self.horizon,
            &self.tracking_weight,
            &self.jerk_weight,
            &self.smoothness_weight,
            None,
        )?;
        if let Some(s) = &self.saturation {
            if !tilt_ok(s.max_tilt) {
                return Err(invalid("saturation.max_tilt", "in (0, π/2) rad"));
            }
            if !(s.thrust_min.is_finite() && s.thrust_min >= 0.0) {
                return Err(invalid("saturation.thrust_min", "finite and >= 0 (m/s²)"));
            }
            if !(s.thrust_max.is_finite() && s.thrust_max > s.thrust_min) {
                return Err(invalid(
                    "saturation.thrust_max",
                    "finite and > thrust_min (m/s²)",
                ));
            }
        }
        let c = &self.constraints;
        if let Some(t) = c.max_tilt {
            OutputConstraints::MAX_TILT_DEG.check_radians("constraints.max_tilt", t)?;
        }
        if let Some(v) = c.max_speed {
            OutputConstraints::MAX_SPEED.check("constraints.max_speed", v)?;
        }
        if let Some([lo, hi]) = c.vertical_acceleration
            && !(lo.is_finite() && hi.is_finite() && lo < 0.0 && hi > 0.0)
        {
            return Err(invalid(
                "constraints.vertical_acceleration",
                "[a_min, a_max] finite with a_min < 0 < a_max (m/s²)",
            ));
        }
        if let Some(w) = c.max_tilt_rate {
            OutputConstraints::MAX_TILT_RATE_DEG_S.check_radians("constraints.max_tilt_rate", w)?;
        }
        if self.solver_time_limit.is_nan() || self.solver_time_limit <= 0.0 {
            return Err(invalid("solver_time_limit", "> 0 s (or infinity)"));
        }
        if let Some(m) = &self.multi_rate {
            m.validate()?;
        }
        if let Some(d) = &self.disturbance {
            d.validate()?;
        }
        if self.delay_ticks > super::delay::MAX_DELAY_TICKS {
            return Err(invalid("delay_ticks", "0–25 ticks"));
        }
        Ok(())
    }
}
