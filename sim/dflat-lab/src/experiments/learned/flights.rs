//! The flights of `dflat experiment learned`: which plant, which path or
//! stream, which poses, which model; and how a flight is judged.

use std::sync::Arc;

use dflat_control::dfmpc::{DfMpc, PlanTiltBound};
use dflat_control::learned::LearnedResidual;
use dflat_control::reference::StreamSettings;
use dflat_control::{ControlModel, Controller};
use dflat_model::{PlanarModel, PlanarParams, SpatialModel, SpatialParams};
use dflat_sim::plant::{PlantKind, PlantOptions, PlantState};
use dflat_sim::sensing::{SensorSpec, VisionOptions};
use dflat_sim::trajectory::{Shape, Trajectory};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::super::controllers::Unbuildable;
use super::super::mismatch::MultiRateDf;
use super::super::preview::{self, Fields, StreamForm};
use super::super::trial::TrialSetup;
use super::super::{ExperimentError, percentile};
use super::Vehicle;
use crate::harness::{ControllerFactory, StopReason, TrialResult, TrialSpec, polyline_closest};

/// Control step of the lab \[s\].
pub const DT: f64 = 0.02;

/// The plants of the study, each with the control model that flies it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AeroPlant {
    /// The planar plant (first-order attitude, altitude held), flown by the
    /// planar model.
    Planar,
    /// The spatial plant (first-order attitude, thrust lag), flown by the
    /// spatial model.
    Spatial,
    /// The rigid body with its inner autopilot (attitude P, rate PID),
    /// flown by the spatial model.
    Rigid,
}

impl AeroPlant {
    /// Its name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Planar => "planar",
            Self::Spatial => "spatial",
            Self::Rigid => "rigid",
        }
    }

    fn kind(self) -> PlantKind {
        match self {
            Self::Planar => PlantKind::Planar,
            Self::Spatial => PlantKind::Spatial,
            Self::Rigid => PlantKind::RigidBody,
        }
    }

    /// The control model flies thrust (the spatial model).
    pub fn spatial(self) -> bool {
        self != Self::Planar
    }
}

/// The paths and streams of the study.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LearnedShape {
    /// The paths study's L (20 m then 30 m), a path at a fixed speed.
    L,
    /// A planner's figure eight, 20 Hz p/v/a.
    Eight,
    /// A planner's racing line, 20 Hz p/v/a.
    RacingLine,
}

impl LearnedShape {
    /// Its name in tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::L => "L",
            Self::Eight => "eight",
            Self::RacingLine => "racing line",
        }
    }

    /// The stream's trajectory at `speed` (None for the L): preview's
    /// sizes at 4 m/s scaled by `(v/4)²`, halved — the same accelerations
    /// at every speed, half of preview's (the drag at 9 m/s takes 25° of
    /// tilt on its own) — and its speed ramp likewise: preview's 3 s at
    /// 4 m/s, stretched by `v/4` above (`ramp_s`), so the ramp asks for
    /// the same acceleration at every speed and stays inside the tilt
    /// envelope with the aerodynamics. With 3 s at every speed the eight's
    /// ramp at 9 m/s asked 34° of the plant without them and more than the
    /// 35° it has of the plant with them: the flights with the
    /// aerodynamics fell up to 0.9 m behind in the ramp and were still
    /// catching up when the judging began, so the study measured a
    /// saturation the matched plant never met instead of the model
    /// (`the_streams_ramp_inside_the_tilt_envelope`).
    ///
    /// `speed` is the stream's top speed, as the L's legs and the racing
    /// line's sides fly it: the eight's phase rate is `speed/√2`
    /// (`EIGHT_TOP_OVER_PHASE`), so it crosses its centre at `speed`
    /// and turns through its lobes at `speed/√2`. (With its phase rate at
    /// `speed` the eight "at 9 m/s" crossed at 12.7 m/s, where the drag
    /// alone needs 37° of the plants' 35°: the study measured the tilt
    /// envelope there, not the model;
    /// `every_stream_tops_out_at_its_speed`.)
    pub fn trajectory(self, speed: f64) -> Option<Trajectory> {
        let (shape, size, top_over_phase) = match self {
            Self::L => return None,
            Self::Eight => (Shape::FigureEight, 16.0, EIGHT_TOP_OVER_PHASE),
            Self::RacingLine => (Shape::RacingLine, 24.0, 1.0),
        };
        Some(Trajectory {
            ramp_s: ramp_s(speed),
            ..preview::trajectory(shape, size * (speed / 4.0).powi(2), speed / top_over_phase)
        })
    }
}

/// The Gerono eight's top speed (through its crossing) over its
/// `Trajectory::speed` (its size times its phase rate): √2.
pub const EIGHT_TOP_OVER_PHASE: f64 = std::f64::consts::SQRT_2;

/// The streams' speed ramp at `speed` [m/s]: preview's
/// [`preview::RAMP_S`] up to 4 m/s, `RAMP_S·v/4` above \[s\]
/// ([`LearnedShape::trajectory`]).
pub fn ramp_s(speed: f64) -> f64 {
    preview::RAMP_S * (speed / 4.0).max(1.0)
}

/// When a stream's judging starts at `speed` [m/s]: after its ramp and
/// preview's [`preview::SETTLE_S`] \[s\].
pub fn judged_from(speed: f64) -> f64 {
    ramp_s(speed) + preview::SETTLE_S
}

/// One flight: where, how fast, what the controller sees, what flies it.
#[derive(Debug, Clone)]
pub struct Flight {
    /// The plant.
    pub plant: AeroPlant,
    /// With the aerodynamics (false: the matched plant).
    pub aero: bool,
    /// Its parasitic and rotor drag (1/m, 1/s).
    pub drag: (f64, f64),
    /// The path or stream.
    pub shape: LearnedShape,
    /// Speed \[m/s\].
    pub speed: f64,
    /// Vision rate \[Hz\] (60 ms latency).
    pub vision_hz: f64,
    /// The poses' noise per axis \[m\] ([`VISION_SIGMA`] in the study).
    pub vision_sigma: f64,
    /// The `[vehicle]` values flown.
    pub vehicle: Vehicle,
    /// The learned residual, when flown.
    pub learned: Option<LearnedResidual>,
    /// A stream's length \[s\].
    pub stream_s: f64,
    /// DF-MPC's command-smoothness weight on x and y \[1/rad²\].
    pub smoothness: f64,
    /// The plan's tilt bound: a box per axis (the shipped configs') or
    /// the cone on the combined tilt.
    pub plan_tilt_bound: PlanTiltBound,
}

/// The lab's vision noise per axis \[m\].
pub const VISION_SIGMA: f64 = 0.02;

/// The shipped `df-mr-smooth`'s command-smoothness weight on x and y
/// \[1/rad²\].
pub const SMOOTHNESS: f64 = 50.0;

/// The control model of `vehicle` on `plant`.
pub fn control_model(plant: AeroPlant, vehicle: &Vehicle) -> Result<ControlModel, ExperimentError> {
    let err = |source: dflat_model::FlatError| ExperimentError::Controller {
        controller: "df-mr-smooth",
        source: source.into(),
    };
    Ok(if plant.spatial() {
        ControlModel::Spatial(
            SpatialModel::new(SpatialParams {
                dt: DT,
                tau: vehicle.tau,
                k: vehicle.k,
                tau_thrust: vehicle.tau_thrust,
                drag_h: vehicle.drag_h,
                drag_rotor: vehicle.drag_rotor,
                ..SpatialParams::default()
            })
            .map_err(err)?,
        )
    } else {
        ControlModel::Planar(
            PlanarModel::new(PlanarParams {
                dt: DT,
                tau: vehicle.tau,
                k: vehicle.k,
                drag_h: vehicle.drag_h,
                ..PlanarParams::default()
            })
            .map_err(err)?,
        )
    })
}

/// The shipped DF-MPC (`df-mr-smooth`) on `vehicle`'s model, with the
/// learned residual when given and the command-smoothness weight
/// `smoothness` on x and y.
fn factory(
    plant: AeroPlant,
    vehicle: Vehicle,
    learned: Option<LearnedResidual>,
    smoothness: f64,
    plan_tilt_bound: PlanTiltBound,
) -> Result<ControllerFactory, ExperimentError> {
    let build = move || -> Result<Box<dyn Controller>, ExperimentError> {
        let model = control_model(plant, &vehicle)?;
        let mut df = MultiRateDf::default();
        df.smoothness[0] = smoothness;
        df.smoothness[1] = smoothness;
        let mut settings = df.settings(35f64.to_radians(), 2.0 * model.gravity(), None);
        settings.delay_ticks = (vehicle.delay_ms / (1e3 * DT)).round() as usize;
        settings.plan_tilt_bound = plan_tilt_bound;
        let mut mpc =
            DfMpc::new(model, settings).map_err(|source| ExperimentError::Controller {
                controller: "df-mr-smooth",
                source,
            })?;
        mpc.set_learned(learned.clone());
        Ok(Box::new(mpc))
    };
    build()?;
    Ok(Arc::new(move || {
        build().unwrap_or_else(|e| Box::new(Unbuildable::new("df-mr-smooth", &e)))
    }))
}

impl Flight {
    /// The plant options: the lab's defaults, 35° saturation, the
    /// aerodynamics when `aero`.
    fn plant_options(&self) -> PlantOptions {
        let mut o = TrialSetup::default().plant_options();
        if self.aero {
            (o.quadratic_drag, o.rotor_drag) = self.drag;
        }
        o
    }

    fn sensor(&self) -> SensorSpec {
        SensorSpec::Vision(VisionOptions {
            rate_hz: self.vision_hz,
            sigma: self.vision_sigma,
            ..VisionOptions::default()
        })
    }

    /// The trial.
    pub fn spec(&self) -> Result<TrialSpec, ExperimentError> {
        let controller = factory(
            self.plant,
            self.vehicle,
            self.learned.clone(),
            self.smoothness,
            self.plan_tilt_bound,
        )?;
        let mut spec = match self.shape.trajectory(self.speed) {
            None => {
                let setup = TrialSetup::default();
                let w = setup.l_path();
                let stop = setup.end_stop(&w, self.speed);
                setup.trial(
                    "learned".into(),
                    controller,
                    self.plant_options(),
                    self.sensor(),
                    &w,
                    self.speed,
                    stop,
                )?
            }
            Some(tr) => {
                let form = StreamForm {
                    rate_hz: 20.0,
                    fields: Fields::Pva,
                    ahead_s: 0.0,
                    yaw: false,
                };
                let mut spec = preview::spec(
                    tr,
                    form,
                    StreamSettings::default(),
                    &preview::PreviewController::Lab(preview::shipped_dfmpc()),
                    self.sensor(),
                    self.stream_s,
                )?;
                spec.controller = controller;
                spec.plant_options = self.plant_options();
                spec.divergence_bound = 15.0;
                spec
            }
        };
        spec.plant = self.plant.kind();
        spec.initial = PlantState::hover(spec.initial.position, spec.plant_options.g);
        spec.validate()?;
        Ok(spec)
    }

    /// The flight's figures.
    pub fn judge(&self, r: &TrialResult) -> Judged {
        let judged_from = match self.shape {
            LearnedShape::L => 0.0,
            _ => judged_from(self.speed),
        };
        let horizontal: Vec<f64> = match self.shape.trajectory(self.speed) {
            None => r.ticks.iter().map(|t| t.path_error).collect(),
            Some(tr) => return self.judge_stream(r, &tr, judged_from),
        };
        let axes = cross_track_per_axis(r, &TrialSetup::default().l_path());
        let (constrained, tilt_p99_deg) = bound_use(r, judged_from);
        Judged {
            p95: percentile(horizontal, 95.0),
            axis_p95: axes,
            // The trial's own arrival at the L's end (its stop).
            arrival_s: r.arrived_at.unwrap_or(f64::NAN),
            diverged: r.stop_reason == StopReason::Diverged,
            errors: r.errors.len(),
            constrained,
            tilt_p99_deg,
        }
    }

    fn judge_stream(&self, r: &TrialResult, tr: &Trajectory, from: f64) -> Judged {
        let f = preview::judge(r, tr);
        let (constrained, tilt_p99_deg) = bound_use(r, from);
        Judged {
            p95: f.p95,
            axis_p95: per_axis(r, from),
            arrival_s: f64::NAN,
            diverged: r.stop_reason == StopReason::Diverged,
            errors: r.errors.len(),
            constrained,
            tilt_p99_deg,
        }
    }
}

/// Over the ticks from `from` \[s\]: the share whose plan was constrained
/// (its tilt bound or tilt-rate rows active), and the p99 of the commanded
/// tilt `acos(cos φ·cos θ)` \[°\].
fn bound_use(r: &TrialResult, from: f64) -> (f64, f64) {
    let judged: Vec<_> = r.ticks.iter().filter(|t| t.t >= from).collect();
    let constrained =
        judged.iter().filter(|t| t.constrained).count() as f64 / judged.len().max(1) as f64;
    let tilt = judged
        .iter()
        .map(|t| {
            (t.command.roll.cos() * t.command.pitch.cos())
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        })
        .collect();
    (constrained, percentile(tilt, 99.0))
}

/// p95 of each axis (x, y, z) of the cross-track error: the true
/// position less its closest point on the path through `waypoints`
/// (horizontally closest, at the path's altitude there), over every tick.
/// The L's judged error split by axis; the error to the controller's own
/// reference (as on a stream) would hold its progress along the path too,
/// which differs from controller to controller and is not judged on the L
/// (the L's axes were read so until 2026-11-29; both readings put the
/// learned flights' y at 1.5–2.2× the stock flights' at 5 and 7 m/s, as
/// the matched plant's).
fn cross_track_per_axis(r: &TrialResult, waypoints: &[Vector3<f64>]) -> [f64; 3] {
    let offsets: Vec<Vector3<f64>> = r
        .ticks
        .iter()
        .filter_map(|t| {
            polyline_closest(waypoints, &t.truth.position, true).map(|c| t.truth.position - c)
        })
        .collect();
    std::array::from_fn(|axis| percentile(offsets.iter().map(|o| o[axis].abs()).collect(), 95.0))
}

/// p95 of |true position − y_ref,k| per axis (x, y, z) over the ticks
/// from `from` \[s\].
fn per_axis(r: &TrialResult, from: f64) -> [f64; 3] {
    std::array::from_fn(|axis| {
        percentile(
            r.ticks
                .iter()
                .filter(|t| t.t >= from)
                .map(|t| (t.truth.position[axis] - t.reference[axis]).abs())
                .collect(),
            95.0,
        )
    })
}

/// What one flight gives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Judged {
    /// Horizontal error p95 \[m\]: cross-track on the L, to the trajectory
    /// at the same time on a stream (after its ramp).
    pub p95: f64,
    /// p95 of each axis' error \[m\]: on the L the cross-track error's
    /// (to the closest point of the path), on a stream the error to the
    /// controller's reference.
    pub axis_p95: [f64; 3],
    /// On the L, the time from the start to the first tick within the
    /// arrival radius (1 m) of its end \[s\] (NaN on a stream, or when it
    /// never arrived): the progress along the path that the cross-track
    /// error does not judge.
    pub arrival_s: f64,
    /// Diverged.
    pub diverged: bool,
    /// Controller errors.
    pub errors: usize,
    /// Share of the judged ticks whose plan was constrained (the plan's
    /// tilt bound or tilt-rate rows active).
    pub constrained: f64,
    /// p99 of the commanded tilt over the judged ticks \[°\] (the plan's
    /// bound: 30°).
    pub tilt_p99_deg: f64,
}

impl Judged {
    /// A flight that was not flown (its model could not be learned).
    pub const NONE: Self = Self {
        p95: f64::NAN,
        axis_p95: [f64::NAN; 3],
        arrival_s: f64::NAN,
        diverged: false,
        errors: 0,
        constrained: f64::NAN,
        tilt_p99_deg: f64::NAN,
    };
}
