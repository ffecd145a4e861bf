//! `[controller]` and its sub-tables, one per settings type of the core:
//! `[controller.dfmpc]` → [`DfMpcSettings`], `[controller.fmpc]` →
//! [`FmpcSettings`], `[controller.pd]` → [`PdSettings`],
//! `[controller.disturbance]` → [`DisturbanceSettings`],
//! `[controller.estimator]` → [`EstimatorSettings`]
//! ([`super::EstimatorConfig`]).
//!
//! Every range is the core's ([`dflat_control::Limit`] constants on those
//! types); [`ControllerConfig::validate`] checks each field against its
//! limit under the field's full TOML path.
//!
//! [`EstimatorSettings`]: dflat_control::estimator::EstimatorSettings

use dflat_control::dfmpc::{DfMpcSettings, OutputConstraints, PlanTiltBound, QpSolver};
use dflat_control::disturbance::DisturbanceSettings;
use dflat_control::fmpc::FmpcSettings;
use dflat_control::pd::{CornerSlowdown, PdSettings};
use dflat_control::window::MultiRateSettings;
use serde::{Deserialize, Serialize};

use super::ConfigError;
use super::EstimatorConfig;
use super::validate::Validator;

/// What places the control ticks (`controller.tick`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TickMode {
    /// Ticks locked to the pose stream, the deadline as the fallback.
    #[default]
    Pose,
    /// The loop's own clock at `rate_hz`.
    Clock,
}

/// Which controller runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ControllerKind {
    /// The discrete-flatness MPC (the product).
    #[default]
    DfMpc,
    /// The Flatness MPC baseline.
    Fmpc,
    /// The PD baseline.
    Pd,
}

/// `[controller]`: the choice, the timing, what every controller shares,
/// and one sub-table per controller.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// `df-mpc`, `fmpc` or `pd`.
    pub kind: ControllerKind,
    /// Control rate \[Hz\] (10–200); the model step is its inverse.
    pub rate_hz: f64,
    /// What places the ticks: "pose" (default) — a tick runs the moment a
    /// pose arrives, on a grid phase-locked to the pose stream, with the
    /// period's deadline as the fallback — or "clock" (the loop's own
    /// 50 Hz clock; a pose waits for the next tick). See
    /// [`crate::schedule::TickPlanner`].
    pub tick: TickMode,
    /// How long past its nominal time a tick waits for an expected pose
    /// before it runs on the previous one (the deadline fallback) \[ms\]
    /// (0–10; a longer wait than half a period is cut to it). Default 3.
    pub pose_wait_ms: f64,
    /// Standard deviation of one pose sample per axis \[m\] (1e-4 to 1,
    /// [`MultiRateSettings::SAMPLE_SIGMA`]): the pose noise that DF-MPC's
    /// multi-rate fit and the baselines' estimator both assume. Default 0.02.
    pub sample_sigma: f64,
    /// Bound on the planned horizontal acceleration, as a tilt \[deg\] (0 =
    /// off; else 1–60, [`OutputConstraints::MAX_TILT_DEG`]), on each
    /// horizontal axis separately with `dfmpc.plan_tilt_bound = "box"` (the
    /// combined planned tilt can exceed it by up to √2 in tan). DF-MPC's
    /// constrained QP (`dfmpc.qp_solver`) runs only on ticks whose plan
    /// violates it. It also sets the braking deceleration at engagement for
    /// every controller kind (`mission.brake_fraction`). Default 30
    /// (`df-mr-smooth`; below the 35° command limit).
    pub constraint_tilt_deg: f64,
    /// `[controller.dfmpc]`: the discrete-flatness MPC.
    pub dfmpc: DfMpcConfig,
    /// `[controller.disturbance]`: DF-MPC's disturbance estimator.
    pub disturbance: DisturbanceConfig,
    /// `[controller.fmpc]`: the Flatness MPC baseline.
    pub fmpc: FmpcConfig,
    /// `[controller.pd]`: the PD baseline.
    pub pd: PdConfig,
    /// `[controller.estimator]`: the baselines' state source
    /// ([`EstimatorConfig`]; fmpc and pd only).
    pub estimator: EstimatorConfig,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            kind: ControllerKind::DfMpc,
            rate_hz: 50.0,
            tick: TickMode::Pose,
            pose_wait_ms: 3.0,
            sample_sigma: 0.02,
            constraint_tilt_deg: 30.0,
            dfmpc: DfMpcConfig::default(),
            disturbance: DisturbanceConfig::default(),
            fmpc: FmpcConfig::default(),
            pd: PdConfig::default(),
            estimator: EstimatorConfig::default(),
        }
    }
}

/// `[controller.dfmpc]`: the discrete-flatness MPC ([`DfMpcSettings`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DfMpcConfig {
    /// Horizon N \[ticks\] (10–2000, [`DfMpcSettings::HORIZON`]). Default 100.
    pub horizon: usize,
    /// Tracking weight per axis x, y, z [1/m²] (> 0). Default 1 (the lab's
    /// recommended `df-mr-smooth` set-up, `dflat experiment vision-rate`).
    pub q: [f64; 3],
    /// Jerk weight per axis x, y, z [s⁶/m²] (> 0): cost r·(Δ³y/δt³)².
    /// Default 0.003 (`df-mr-smooth`; the paper's is 0.08).
    pub r_jerk: [f64; 3],
    /// Command-smoothness weight per axis x, y, z [1/rad²] (0–10000) on the
    /// squared change of the linearised command between ticks. Default
    /// [50, 50, 0] (`df-mr-smooth` on x, y; 0 = the paper's cost).
    pub smoothness_weight: [f64; 3],
    /// Multi-rate windows: every pose is fitted at its own capture time
    /// through the inputs sent, instead of one pose per tick. Default true
    /// (`df-mr-smooth`).
    pub multi_rate: bool,
    /// Multi-rate window M \[ticks\] (2–250, [`MultiRateSettings::WINDOW`]).
    /// Default 25 (0.5 s at 50 Hz).
    pub multi_rate_window: usize,
    /// Bound on the planned speed per axis [m/s] (0 = off; else up to 50,
    /// [`OutputConstraints::MAX_SPEED`]). When the vehicle is already
    /// faster (a gust, pose noise), the plan brakes to it at 90 % of the
    /// tilt bound's acceleration rather than making the QP infeasible.
    /// Default 0.
    pub constraint_speed: f64,
    /// Tilt-rate bound in the plan \[deg/s\] (0 = off, else 10–1000,
    /// [`OutputConstraints::MAX_TILT_RATE_DEG_S`]): the planned pitch and
    /// roll commands change by at most this times δt per tick, the first
    /// one against the command sent at the previous tick, so no goal change
    /// makes the command jump (docs/controllers.md, "The tilt-rate bound").
    /// Default 150 (3° per tick at 50 Hz on each NED axis; pitch and roll
    /// measured ≤ 4.5° per tick after 10 and 20 m diagonal steps, inside the
    /// 5°/tick budget). With either plan-tilt bound: with the cone the
    /// rate rows join the pair's problem, the cone's radius widening into
    /// a funnel where the rate cannot reach it in time.
    pub max_tilt_rate_deg_s: f64,
    /// Solver of the constrained QP: "banded" — O(N) per iteration: an
    /// augmented Lagrangian (an active-set method for the box's rows) with
    /// a banded interior point as its fallback, for the box and the cone;
    /// clarabel as the last fallback of both — or
    /// "clarabel" alone. Default "banded".
    pub qp_solver: QpSolver,
    /// How `controller.constraint_tilt_deg` bounds the plan: "box" (each
    /// horizontal axis separately; the combined planned tilt can reach 39°
    /// at 30°) or "cone" (the combined tilt, both axes in one problem — the
    /// vehicle's real limit — solved warm by a banded augmented Lagrangian;
    /// docs/results.md, docs/performance.md). Default "box".
    pub plan_tilt_bound: PlanTiltBound,
    /// A residual of the flat maps learned by `dflat learn` (its model
    /// file, TOML); empty (the default): the parametric model alone. The
    /// file is validated and refused unless it was learned with this
    /// `[vehicle]` table; DF-MPC adds the residual to its maps'
    /// acceleration offset, faded outside its data's support and when its
    /// running prediction error grows (docs/controllers.md, "The learned
    /// residual").
    pub learned_model: String,
}

impl Default for DfMpcConfig {
    fn default() -> Self {
        Self {
            horizon: 100,
            q: [1.0, 1.0, 1.0],
            r_jerk: [0.003, 0.003, 0.003],
            smoothness_weight: [50.0, 50.0, 0.0],
            multi_rate: true,
            multi_rate_window: 25,
            constraint_speed: 0.0,
            max_tilt_rate_deg_s: 150.0,
            qp_solver: QpSolver::Banded,
            plan_tilt_bound: PlanTiltBound::Box,
            learned_model: String::new(),
        }
    }
}

/// `[controller.disturbance]`: DF-MPC's disturbance estimator
/// ([`DisturbanceSettings`]; offset-free tracking).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DisturbanceConfig {
    /// Estimate acceleration offsets (wind, drag) and, for the spatial
    /// model, the thrust scale (hover thrust, mass). Default false.
    pub enabled: bool,
    /// Estimator bandwidth \[Hz\] (0.001 to rate_hz/10,
    /// [`DisturbanceSettings::bandwidth_limit`]). Default 0.1.
    pub bandwidth_hz: f64,
    /// Fit window \[ticks\] (10–2000, [`DisturbanceSettings::WINDOW`]).
    /// Default 50 (1 s at 50 Hz).
    pub window: usize,
    /// Clamp on each acceleration-offset component [m/s²] (0–10). Default 3.
    pub max_acceleration: f64,
    /// Bounds on the thrust scale (actual / model thrust), [min, max] with
    /// 0.1 ≤ min ≤ 1 ≤ max ≤ 10. Default [0.5, 2].
    pub thrust_scale_range: [f64; 2],
    /// A pose step between ticks larger than this \[m\] resets the estimate
    /// (0.01–100). Default 1.
    pub max_step: f64,
}

impl Default for DisturbanceConfig {
    /// Off, with the core's defaults ([`DisturbanceSettings::default`]).
    fn default() -> Self {
        let d = DisturbanceSettings::default();
        Self {
            enabled: false,
            bandwidth_hz: d.bandwidth_hz,
            window: d.fit_span,
            max_acceleration: d.max_acceleration,
            thrust_scale_range: d.thrust_scale_range,
            max_step: d.max_step,
        }
    }
}

impl DisturbanceConfig {
    /// The core's settings, `None` when `enabled` is false.
    pub fn settings(&self) -> Option<DisturbanceSettings> {
        self.enabled.then_some(DisturbanceSettings {
            bandwidth_hz: self.bandwidth_hz,
            fit_span: self.window,
            max_acceleration: self.max_acceleration,
            thrust_scale_range: self.thrust_scale_range,
            max_step: self.max_step,
        })
    }
}

/// `[controller.fmpc]`: the Flatness MPC baseline ([`FmpcSettings`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FmpcConfig {
    /// Horizon N \[ticks\] (10–2000, [`FmpcSettings::HORIZON`]). Default 75
    /// (1.5 s at 50 Hz, the paper's).
    pub horizon: usize,
    /// Tracking weight per axis x, y, z [1/m²] (> 0). Default 1.
    pub q: [f64; 3],
    /// Jerk weight per axis x, y, z [s⁶/m²] (> 0). Default 0.01 (the
    /// library's tuned value, `FmpcSettings`: the paper's 0.1 oscillates at
    /// N = 75).
    pub r_jerk: [f64; 3],
}

impl Default for FmpcConfig {
    fn default() -> Self {
        Self {
            horizon: 75,
            q: [1.0, 1.0, 1.0],
            r_jerk: [0.01, 0.01, 0.01],
        }
    }
}

/// `[controller.pd]`: the PD baseline ([`PdSettings`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PdConfig {
    /// Proportional gain [1/s²] (> 0), every axis. Default 2 (the library's
    /// tuned value, `PdSettings`: settles a 10 m step in ~4.5 s, no
    /// overshoot).
    pub kp: f64,
    /// Derivative gain [1/s] (> 0), every axis. Default 2.5 (`PdSettings`).
    pub kd: f64,
    /// On a path PD slows for each corner so that it turns on an arc whose
    /// tangent points lie this far from the waypoint \[m\], and stops at the
    /// end, as PX4's mission mode does (0 = the paper's PD, every corner at
    /// the path speed; else up to 50, [`CornerSlowdown::RADIUS`]). Default 1.
    pub corner_radius: f64,
    /// Braking and turning acceleration for those corners [m/s²] (0.1–20,
    /// [`CornerSlowdown::ACCELERATION`]). Default 3.
    pub corner_acceleration: f64,
}

impl Default for PdConfig {
    fn default() -> Self {
        Self {
            kp: 2.0,
            kd: 2.5,
            corner_radius: 1.0,
            corner_acceleration: 3.0,
        }
    }
}

impl PdConfig {
    /// The core's corner slowdown, `None` when `corner_radius` is 0.
    pub fn corners(&self) -> Option<CornerSlowdown> {
        (self.corner_radius > 0.0).then_some(CornerSlowdown {
            radius: self.corner_radius,
            acceleration: self.corner_acceleration,
        })
    }
}

impl ControllerConfig {
    /// DF-MPC's output constraints (tilt and tilt rate in radians; 0 = off).
    pub fn output_constraints(&self) -> OutputConstraints {
        let d = &self.dfmpc;
        OutputConstraints {
            max_tilt: (self.constraint_tilt_deg > 0.0)
                .then(|| self.constraint_tilt_deg.to_radians()),
            max_speed: (d.constraint_speed > 0.0).then_some(d.constraint_speed),
            vertical_acceleration: None,
            max_tilt_rate: (d.max_tilt_rate_deg_s > 0.0)
                .then(|| d.max_tilt_rate_deg_s.to_radians()),
        }
    }

    /// DF-MPC's multi-rate window, `None` when `dfmpc.multi_rate` is false.
    pub fn multi_rate(&self) -> Option<MultiRateSettings> {
        self.dfmpc.multi_rate.then(|| MultiRateSettings {
            fit_span: self.dfmpc.multi_rate_window,
            sample_sigma: self.sample_sigma,
            ..MultiRateSettings::default()
        })
    }

    /// Checks every field against the core's limit, naming it by its TOML
    /// path (`controller.dfmpc.horizon`).
    pub(super) fn validate(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        v.range("controller.rate_hz", self.rate_hz, 10.0, 200.0)?;
        v.range("controller.pose_wait_ms", self.pose_wait_ms, 0.0, 10.0)?;
        v.limit(
            "controller.sample_sigma",
            self.sample_sigma,
            MultiRateSettings::SAMPLE_SIGMA,
        )?;
        v.limit_or_off(
            "controller.constraint_tilt_deg",
            self.constraint_tilt_deg,
            OutputConstraints::MAX_TILT_DEG,
        )?;
        let d = &self.dfmpc;
        v.limit(
            "controller.dfmpc.horizon",
            d.horizon as f64,
            DfMpcSettings::HORIZON,
        )?;
        v.limits("controller.dfmpc.q", &d.q, DfMpcSettings::TRACKING_WEIGHT)?;
        v.limits(
            "controller.dfmpc.r_jerk",
            &d.r_jerk,
            DfMpcSettings::JERK_WEIGHT,
        )?;
        v.limits(
            "controller.dfmpc.smoothness_weight",
            &d.smoothness_weight,
            DfMpcSettings::SMOOTHNESS_WEIGHT,
        )?;
        v.limit(
            "controller.dfmpc.multi_rate_window",
            d.multi_rate_window as f64,
            MultiRateSettings::WINDOW,
        )?;
        v.limit_or_off(
            "controller.dfmpc.constraint_speed",
            d.constraint_speed,
            OutputConstraints::MAX_SPEED,
        )?;
        v.limit_or_off(
            "controller.dfmpc.max_tilt_rate_deg_s",
            d.max_tilt_rate_deg_s,
            OutputConstraints::MAX_TILT_RATE_DEG_S,
        )?;
        let s = &self.disturbance;
        v.limit(
            "controller.disturbance.bandwidth_hz",
            s.bandwidth_hz,
            DisturbanceSettings::bandwidth_limit(1.0 / self.rate_hz),
        )?;
        v.limit(
            "controller.disturbance.window",
            s.window as f64,
            DisturbanceSettings::WINDOW,
        )?;
        v.limit(
            "controller.disturbance.max_acceleration",
            s.max_acceleration,
            DisturbanceSettings::MAX_ACCELERATION,
        )?;
        v.limit(
            "controller.disturbance.thrust_scale_range[0]",
            s.thrust_scale_range[0],
            DisturbanceSettings::THRUST_SCALE_MIN,
        )?;
        v.limit(
            "controller.disturbance.thrust_scale_range[1]",
            s.thrust_scale_range[1],
            DisturbanceSettings::THRUST_SCALE_MAX,
        )?;
        v.limit(
            "controller.disturbance.max_step",
            s.max_step,
            DisturbanceSettings::MAX_STEP,
        )?;
        let f = &self.fmpc;
        v.limit(
            "controller.fmpc.horizon",
            f.horizon as f64,
            FmpcSettings::HORIZON,
        )?;
        v.limits("controller.fmpc.q", &f.q, FmpcSettings::Q)?;
        v.limits("controller.fmpc.r_jerk", &f.r_jerk, FmpcSettings::R)?;
        let p = &self.pd;
        v.limit("controller.pd.kp", p.kp, PdSettings::KP)?;
        v.limit("controller.pd.kd", p.kd, PdSettings::KD)?;
        v.limit_or_off(
            "controller.pd.corner_radius",
            p.corner_radius,
            CornerSlowdown::RADIUS,
        )?;
        v.limit(
            "controller.pd.corner_acceleration",
            p.corner_acceleration,
            CornerSlowdown::ACCELERATION,
        )?;
        self.estimator.validate(v)
    }
}
