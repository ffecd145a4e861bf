//! `dflat experiment preview`: a planner's trajectories of four shapes
//! (circle, figure eight, racing line, lemniscate) at three speeds, flown
//! from its stream — position only, p/v, p/v/a at 20 and 50 Hz, and p/v/a
//! with 1.5 s of the trajectory sent ahead — under 50 Hz and 15 Hz vision
//! poses (60 ms latency, 2 cm noise): DF-MPC against the autopilot's
//! position loop (PD with velocity and acceleration feed-forward, the
//! SITL's gains, on the lab's state estimator) and Flatness MPC fed by the
//! same estimator, on the planar plant. `tests/e2e_preview.rs` flies the
//! SITL's own loop (on its true state) beside the daemon.

mod feed;

pub use feed::{Fields, StreamFeed, StreamForm};

use std::sync::Arc;

use dflat_control::estimator::StateSource;
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::reference::StreamSettings;
use dflat_sim::plant::{PlantKind, PlantState};
use dflat_sim::sensing::{SensorSpec, VisionOptions};
use dflat_sim::trajectory::{Shape, Trajectory};
use nalgebra::Vector3;
use serde::Serialize;

use super::{ControllerSpec, ExperimentError};
use crate::harness::{StopCondition, TrialResult, TrialSpec, quantile, run_trial, run_trials};

/// The speed ramp of every shape \[s\].
pub const RAMP_S: f64 = 3.0;
/// Judged from this long after the ramp \[s\].
pub const SETTLE_S: f64 = 2.0;

/// One flight's figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Flown {
    /// Horizontal error to the trajectory at the same time, p95 \[m\].
    pub p95: f64,
    /// Median of the same \[m\].
    pub median: f64,
    /// Largest command step between ticks (pitch or roll) \[deg\].
    pub max_step_deg: f64,
    /// Ticks whose controller update failed (the command held).
    pub errors: u64,
}

/// The shipped DF-MPC (`df-mr-smooth`) at the shipped 35° tilt limit.
pub fn shipped_dfmpc() -> ControllerSpec {
    ControllerSpec::shipped_dfmpc(35.0)
}

/// Flatness MPC fed by the lab's state estimator (the fair baseline).
pub fn fmpc_estimator() -> ControllerSpec {
    ControllerSpec::Fmpc {
        horizon: 75,
        q: 1.0,
        r: 0.01,
        max_tilt_deg: 35.0,
        estimator: Some(super::fair::lab_estimator()),
    }
}

/// A controller of the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PreviewController {
    /// One of the lab's ([`ControllerSpec`]).
    Lab(ControllerSpec),
    /// The autopilot's position loop as the SITL flies it: PD (k_p 3, k_d
    /// 3, the SITL's OFFBOARD gains) with velocity and acceleration
    /// feed-forward from the stream, on the lab's state estimator, its
    /// tilt limited to 30°.
    PdFeedForward,
}

impl PreviewController {
    fn factory(&self) -> Result<crate::harness::ControllerFactory, ExperimentError> {
        match self {
            Self::Lab(spec) => spec.factory(),
            Self::PdFeedForward => {
                let build = || -> Result<Box<dyn dflat_control::Controller>, ExperimentError> {
                    let model = super::controllers::planar_model().map_err(|source| {
                        ExperimentError::Controller {
                            controller: "pd-ff",
                            source,
                        }
                    })?;
                    let tilt = 30f64.to_radians();
                    let pd = Pd::new(
                        model,
                        PdSettings {
                            kp: [3.0; 3],
                            kd: [3.0; 3],
                            max_horizontal_acceleration: 9.81 * tilt.tan(),
                            max_tilt: tilt,
                            state: StateSource::Estimator(super::fair::lab_estimator()),
                            acceleration_feed_forward: true,
                            ..PdSettings::default()
                        },
                    )
                    .map_err(|source| ExperimentError::Controller {
                        controller: "pd-ff",
                        source,
                    })?;
                    Ok(Box::new(pd))
                };
                build()?;
                // As the lab's own factories: a later failure is an
                // unbuildable controller that errs every tick, not a panic.
                Ok(Arc::new(move || {
                    build().unwrap_or_else(|e| {
                        Box::new(super::controllers::Unbuildable::new("pd-ff", &e))
                    })
                }))
            }
        }
    }
}

/// The trial that flies `trajectory` from its stream in `form` with
/// `controller` on the planar plant for `duration` \[s\] with `sensor`.
pub fn spec(
    trajectory: Trajectory,
    form: StreamForm,
    settings: StreamSettings,
    controller: &PreviewController,
    sensor: SensorSpec,
    duration: f64,
) -> Result<TrialSpec, ExperimentError> {
    let mut spec = TrialSpec::new(
        "preview",
        controller.factory()?,
        Arc::new(move || Box::new(StreamFeed::new(trajectory, form, settings))),
    );
    spec.plant = PlantKind::Planar;
    spec.initial = PlantState {
        position: trajectory.start,
        ..PlantState::default()
    };
    spec.sensor = sensor;
    spec.stop = StopCondition::Duration(duration);
    Ok(spec)
}

/// The figures of a flight of `trajectory` (from its ramp plus
/// [`SETTLE_S`] on: [`RAMP_S`] + [`SETTLE_S`] for the study's own).
pub fn judge(result: &TrialResult, trajectory: &Trajectory) -> Flown {
    let mut errors: Vec<f64> = result
        .trace
        .iter()
        .filter(|s| s.t >= trajectory.ramp_s + SETTLE_S)
        .map(|s| (s.position - trajectory.at(s.t).position).xy().norm())
        .collect();
    errors.sort_by(f64::total_cmp);
    let max_step = result
        .ticks
        .windows(2)
        .map(|w| {
            let (a, b) = (&w[0].applied, &w[1].applied);
            (b.pitch - a.pitch).abs().max((b.roll - a.roll).abs())
        })
        .fold(0.0, f64::max)
        .to_degrees();
    Flown {
        p95: quantile(&errors, 0.95),
        median: quantile(&errors, 0.5),
        max_step_deg: max_step,
        errors: result.errors.len() as u64,
    }
}

/// Flies `spec` (one trial of `trajectory`, see [`spec`]) and judges it.
pub fn fly(spec: &TrialSpec, trajectory: &Trajectory) -> Result<Flown, ExperimentError> {
    Ok(judge(&run_trial(spec, 1)?, trajectory))
}

/// The trajectory of `shape` at `size` \[m\] and `speed` \[m/s\] from hover
/// at 10 m.
pub fn trajectory(shape: Shape, size: f64, speed: f64) -> Trajectory {
    Trajectory {
        shape,
        size,
        speed,
        ramp_s: RAMP_S,
        start: Vector3::new(0.0, 0.0, -10.0),
    }
}

/// The study's shapes at 4 m/s, `(name, shape, size)`; at speed `v` each
/// is scaled by `(v/4)²`, so every speed asks for the same accelerations.
pub const SHAPES: [(&str, Shape, f64); 4] = [
    ("circle", Shape::Circle, 6.0),
    ("eight", Shape::FigureEight, 8.0),
    ("racing line", Shape::RacingLine, 12.0),
    ("lemniscate", Shape::Lemniscate, 12.0),
];

/// The forms the planner sends: `(label, form)`.
pub fn forms() -> Vec<(&'static str, StreamForm)> {
    let f = |rate_hz, fields, ahead_s| StreamForm {
        rate_hz,
        fields,
        ahead_s,
        yaw: true,
    };
    vec![
        ("20 Hz p", f(20.0, Fields::P, 0.0)),
        ("20 Hz p/v", f(20.0, Fields::Pv, 0.0)),
        ("20 Hz p/v/a", f(20.0, Fields::Pva, 0.0)),
        ("50 Hz p/v/a", f(50.0, Fields::Pva, 0.0)),
        ("20 Hz p/v/a, 1.5 s ahead", f(20.0, Fields::Pva, 1.5)),
    ]
}

/// `dflat experiment preview`'s settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PreviewConfig {
    /// Cruise speeds \[m/s\].
    pub speeds: Vec<f64>,
    /// Vision pose rates \[Hz\] (60 ms latency, 2 cm noise).
    pub vision_rates: Vec<f64>,
    /// Flight length \[s\].
    pub duration: f64,
}

impl Default for PreviewConfig {
    fn default() -> Self {
        Self {
            speeds: vec![4.0, 6.0, 8.0],
            vision_rates: vec![50.0, 15.0],
            duration: 20.0,
        }
    }
}

/// One row of the study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PreviewRow {
    /// The shape's name.
    pub shape: &'static str,
    /// Cruise speed \[m/s\].
    pub speed: f64,
    /// What the planner sends.
    pub form: &'static str,
    /// Vision rate \[Hz\].
    pub vision_hz: f64,
    /// DF-MPC's figures.
    pub dfmpc: Flown,
    /// The PD with velocity and acceleration feed-forward's figures.
    pub pd_feed_forward: Flown,
    /// Flatness MPC's (estimator) figures.
    pub fmpc_estimator: Flown,
}

/// The study's rows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PreviewResult {
    /// The settings flown.
    pub config: PreviewConfig,
    /// Shape × speed × form × vision rate.
    pub rows: Vec<PreviewRow>,
}

impl PreviewResult {
    /// The table (p95 \[m\], DF-MPC / Flatness MPC (estimator)).
    pub fn table(&self) -> String {
        let mut t = String::from(
            "shape        speed  vision  form                       DF-MPC p95  PD+FF p95  FMPC-est p95  DF step\n",
        );
        for r in &self.rows {
            t += &format!(
                "{:12} {:5.1}  {:4.0} Hz  {:26} {:9.3} m  {:7.3} m  {:10.3} m  {:5.2}°\n",
                r.shape,
                r.speed,
                r.vision_hz,
                r.form,
                r.dfmpc.p95,
                r.pd_feed_forward.p95,
                r.fmpc_estimator.p95,
                r.dfmpc.max_step_deg
            );
        }
        t
    }
}

/// Flies the study (in parallel; deterministic from its seed).
pub fn run_preview(
    config: &PreviewConfig,
    progress: bool,
) -> Result<PreviewResult, ExperimentError> {
    let settings = StreamSettings::default();
    let controllers = [
        PreviewController::Lab(shipped_dfmpc()),
        PreviewController::PdFeedForward,
        PreviewController::Lab(fmpc_estimator()),
    ];
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for &(name, shape, size) in &SHAPES {
        for &speed in &config.speeds {
            let tr = trajectory(shape, size * (speed / 4.0f64).powi(2), speed);
            for (label, form) in forms() {
                // Positions alone imply their velocity (as the daemon's
                // `stream.implied_velocity`).
                let settings = StreamSettings {
                    implied_velocity: form.fields == Fields::P,
                    ..settings
                };
                for &rate in &config.vision_rates {
                    let sensor = SensorSpec::Vision(VisionOptions {
                        rate_hz: rate,
                        ..VisionOptions::default()
                    });
                    for c in &controllers {
                        specs.push((
                            spec(tr, form, settings, c, sensor.clone(), config.duration)?,
                            1,
                        ));
                    }
                    keys.push((name, speed, label, rate, tr));
                }
            }
        }
    }
    let mut results = run_trials(&specs, progress).into_iter();
    let mut rows = Vec::new();
    for (shape, speed, form, vision_hz, tr) in keys {
        let mut judged = || -> Result<Flown, ExperimentError> {
            let r = results.next().expect("one result per trial")?;
            Ok(judge(&r, &tr))
        };
        let dfmpc = judged()?;
        let pd_feed_forward = judged()?;
        let fmpc_estimator = judged()?;
        rows.push(PreviewRow {
            shape,
            speed,
            form,
            vision_hz,
            dfmpc,
            pd_feed_forward,
            fmpc_estimator,
        });
    }
    Ok(PreviewResult {
        config: config.clone(),
        rows,
    })
}

/// Writes the study's JSON to `json`.
pub fn write_preview(
    result: &PreviewResult,
    json: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, ExperimentError> {
    super::write_json(json, result)?;
    Ok(vec![json.to_path_buf()])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eight(form: StreamForm, jerk: f64) -> Flown {
        let settings = StreamSettings {
            jerk_horizon_s: jerk,
            ..StreamSettings::default()
        };
        let trajectory = trajectory(Shape::FigureEight, 8.0, 4.0);
        let controller = PreviewController::Lab(shipped_dfmpc());
        let spec = spec(
            trajectory,
            form,
            settings,
            &controller,
            SensorSpec::Perfect,
            16.0,
        );
        fly(&spec.unwrap(), &trajectory).unwrap()
    }

    /// On the figure eight, the stream's own jerk cuts the error from
    /// 20 Hz p/v/a samples several times over, and the trajectory sent
    /// 1 s ahead halves it again; every flight is smooth and no update
    /// fails.
    #[test]
    fn the_jerk_and_the_future_sent_ahead_each_buy_precision() {
        let samples = StreamForm {
            rate_hz: 20.0,
            fields: Fields::Pva,
            ahead_s: 0.0,
            yaw: false,
        };
        let ahead = StreamForm {
            ahead_s: 1.0,
            ..samples
        };
        let turn = eight(samples, 0.0);
        let jerk = eight(samples, 0.25);
        let sent = eight(ahead, 0.25);
        assert!(jerk.p95 < 0.25 * turn.p95, "{jerk:?} vs {turn:?}");
        assert!(sent.p95 < 0.6 * jerk.p95, "{sent:?} vs {jerk:?}");
        for f in [turn, jerk, sent] {
            assert_eq!(f.errors, 0);
            assert!(f.max_step_deg < 5.0, "{f:?}");
        }
    }

    /// The autopilot's loop with the stream's acceleration fed forward
    /// tracks the circle (a PD alone lags it by metres) and DF-MPC cuts its
    /// error on the eight several times over.
    #[test]
    fn the_pd_with_feed_forward_is_a_fair_anchor() {
        let form = StreamForm {
            rate_hz: 20.0,
            fields: Fields::Pva,
            ahead_s: 0.0,
            yaw: false,
        };
        let fly_with = |shape, size, c: &PreviewController| {
            let tr = trajectory(shape, size, 4.0);
            let settings = StreamSettings::default();
            let spec = spec(tr, form, settings, c, SensorSpec::Perfect, 16.0);
            fly(&spec.unwrap(), &tr).unwrap()
        };
        let pd = PreviewController::PdFeedForward;
        let df = PreviewController::Lab(shipped_dfmpc());
        let circle = fly_with(Shape::Circle, 6.0, &pd);
        assert!(circle.p95 < 0.2, "{circle:?}");
        let (pd8, df8) = (
            fly_with(Shape::FigureEight, 8.0, &pd),
            fly_with(Shape::FigureEight, 8.0, &df),
        );
        assert!(df8.p95 < 0.5 * pd8.p95, "{df8:?} vs {pd8:?}");
    }
}
