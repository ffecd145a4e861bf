//! The closed-loop harness: controller at the control rate, plant at the
//! plant rate, a sensor in between.
//!
//! [`run_trial`] flies one [`TrialSpec`] with one seed; [`run_trials`] flies
//! many in parallel (rayon). Everything is deterministic from the seed: the
//! plant's gusts and the sensor's noise come from independent ChaCha8
//! streams of it, no clock is read, and each trial owns its controller,
//! reference, plant and sensor, so results are bit-identical whatever the
//! thread count and are returned in input order.
//!
//! One tick k at `t_k = k·δt`:
//!
//! 1. the sensor gives the measurement for `t_k` (`None` before the first
//!    sample: the held command stays); every sample that arrived since the
//!    last tick is handed to the controller first, with its measurement
//!    time ([`Controller::observe`]; ignored by classic controllers);
//! 2. the controller updates (an error is recorded and counted, and the
//!    previous command is held — as is a non-finite command). A multi-rate
//!    controller ([`Controller::multi_rate`]) gets the measurement stamped
//!    with the tick time `t_k` (its poses came through `observe`); the
//!    others get the sensor's measurement as it is;
//! 3. the command is applied to the plant (which saturates it) and held for
//!    `δt / plant_dt` plant steps; after each step the sensor observes the
//!    true state.
//!
//! The tick record holds the true state at `t_k` (before the command acts).
//! The plant trace holds the true state at the start of every plant step,
//! i.e. at `t ∈ [0, T)` at the plant rate (the reference trace's `mae`).

mod csv;
pub use csv::{SAMPLES_HEADER, TICKS_HEADER, TRACE_HEADER};
mod metrics;

pub use metrics::{
    ErrorStats, Metrics, command_smoothness, fixed_target_error, max_tilt_deg, path_error_stats,
    quantile, saturation_share,
};

use std::sync::Arc;

use dflat_control::{AttitudeCommand, Controller, Measurement, ReferenceSource, TickOutput};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::Vector3;
use rayon::prelude::*;

use dflat_sim::SimError;
use dflat_sim::error::{check_positive, check_range};
use dflat_sim::plant::{PlantKind, PlantOptions, PlantState, build_plant};
use dflat_sim::sensing::{PoseSample, SensorSpec, build_sensor};

/// Builds a fresh controller for a trial (called once per trial).
pub type ControllerFactory = Arc<dyn Fn() -> Box<dyn Controller> + Send + Sync>;
/// Builds a fresh reference source for a trial (called once per trial).
pub type ReferenceFactory = Arc<dyn Fn() -> Box<dyn ReferenceSource + Send> + Send + Sync>;
/// Distance \[m\] of a position (local NED \[m\]) to the reference path.
pub type PathDistance = Arc<dyn Fn(&Vector3<f64>) -> f64 + Send + Sync>;

/// When a trial ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StopCondition {
    /// After this many seconds of simulated time: ticks at `t ∈ [0, T)`.
    Duration(f64),
    /// `settle` seconds after the true position first comes within `radius`
    /// \[m\] of `end` (local NED \[m\], all three axes), or at `max_duration` \[s\].
    PathEnd {
        /// The path's last point, local NED \[m\].
        end: Vector3<f64>,
        /// Arrival radius \[m\].
        radius: f64,
        /// Time flown after arrival \[s\].
        settle: f64,
        /// Upper bound on the trial length \[s\].
        max_duration: f64,
    },
}

/// A fixed reference point for the output-error metrics (paper §VI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedTarget {
    /// The reference position, local NED \[m\].
    pub target: Vector3<f64>,
    /// Which NED axes count (the paper's 1-D set-up: x only).
    pub axes: [bool; 3],
    /// Start of the late window for `mae_after` \[s\] (the reference trace: 5 s).
    pub after: f64,
}

impl FixedTarget {
    /// Error vector `(p − target)` with the unused axes zeroed.
    pub fn error(&self, p: &Vector3<f64>) -> Vector3<f64> {
        let e = p - self.target;
        Vector3::from_fn(|i, _| if self.axes[i] { e[i] } else { 0.0 })
    }
}

/// Everything one closed-loop trial needs except the seed.
#[derive(Clone)]
pub struct TrialSpec {
    /// Label for logs, plots and CSV file names.
    pub name: String,
    /// The controller under test.
    pub controller: ControllerFactory,
    /// The reference the controller tracks.
    pub reference: ReferenceFactory,
    /// Which plant flies.
    pub plant: PlantKind,
    /// Plant options (rate, saturation, drag, wind, mismatch).
    pub plant_options: PlantOptions,
    /// Initial true state (time 0).
    pub initial: PlantState,
    /// What the controller sees.
    pub sensor: SensorSpec,
    /// Control step δt \[s\]; a multiple of `plant_options.plant_dt`.
    pub ctrl_dt: f64,
    /// When the trial ends.
    pub stop: StopCondition,
    /// Fixed reference for mae/rms (None: not computed).
    pub target: Option<FixedTarget>,
    /// Distance to the reference path, for the path error (None: not computed).
    pub path_distance: Option<PathDistance>,
    /// Divergence bound \[m\] on the position error (path distance if given,
    /// else the fixed-target error, else the distance to y_ref,k).
    pub divergence_bound: f64,
    /// End the trial at the first diverged tick.
    pub stop_on_divergence: bool,
    /// Command held until the controller's first success (None: level, yaw
    /// of the initial state, thrust g).
    pub initial_command: Option<AttitudeCommand>,
}

impl std::fmt::Debug for TrialSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrialSpec")
            .field("name", &self.name)
            .field("plant", &self.plant)
            .field("plant_options", &self.plant_options)
            .field("initial", &self.initial)
            .field("sensor", &self.sensor)
            .field("ctrl_dt", &self.ctrl_dt)
            .field("stop", &self.stop)
            .field("target", &self.target)
            .field("path_distance", &self.path_distance.is_some())
            .field("divergence_bound", &self.divergence_bound)
            .finish_non_exhaustive()
    }
}

impl TrialSpec {
    /// A spec with the lab defaults: planar plant with default options, hover
    /// at the origin, perfect sensing, δt = 0.02 s, 10 s, no metrics
    /// targets, divergence bound 50 m (stopping the trial).
    pub fn new(
        name: impl Into<String>,
        controller: ControllerFactory,
        reference: ReferenceFactory,
    ) -> Self {
        Self {
            name: name.into(),
            controller,
            reference,
            plant: PlantKind::Planar,
            plant_options: PlantOptions::default(),
            initial: PlantState::default(),
            sensor: SensorSpec::Perfect,
            ctrl_dt: 0.02,
            stop: StopCondition::Duration(10.0),
            target: None,
            path_distance: None,
            divergence_bound: 50.0,
            stop_on_divergence: true,
            initial_command: None,
        }
    }

    /// Checks the options; returns the number of plant steps per tick.
    pub fn validate(&self) -> Result<usize, SimError> {
        self.plant_options.validate()?;
        self.sensor.validate()?;
        check_range("ctrl_dt", self.ctrl_dt, 1e-4, 10.0, "1e-4 ..= 10 s")?;
        let ratio = self.ctrl_dt / self.plant_options.plant_dt;
        let n = ratio.round();
        if n < 1.0 || (ratio - n).abs() > 1e-6 {
            return Err(SimError::InvalidOption {
                field: "ctrl_dt",
                value: self.ctrl_dt,
                allowed: "a whole multiple of plant_dt",
            });
        }
        match self.stop {
            StopCondition::Duration(d) => check_range("stop.duration", d, 0.0, 1e6, "0 ..= 1e6 s")?,
            StopCondition::PathEnd {
                end,
                radius,
                settle,
                max_duration,
            } => {
                if !end.iter().all(|v| v.is_finite()) {
                    return Err(SimError::InvalidOption {
                        field: "stop.end",
                        value: f64::NAN,
                        allowed: "finite",
                    });
                }
                check_positive("stop.radius", radius)?;
                check_range("stop.settle", settle, 0.0, 1e6, "0 ..= 1e6 s")?;
                check_range("stop.max_duration", max_duration, 0.0, 1e6, "0 ..= 1e6 s")?;
            }
        }
        check_positive("divergence_bound", self.divergence_bound)?;
        if !self.initial.is_finite() {
            return Err(SimError::InvalidOption {
                field: "initial",
                value: f64::NAN,
                allowed: "finite state",
            });
        }
        Ok(n as usize)
    }
}

/// What happened at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TickStatus {
    /// The controller produced the command.
    Ok,
    /// The controller failed (or returned a non-finite command): the
    /// previous command was held.
    ControllerError,
    /// No measurement yet: the previous (initial) command was held.
    NoMeasurement,
}

impl TickStatus {
    /// Short name for CSV ("ok", "error", "no_measurement").
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::ControllerError => "error",
            Self::NoMeasurement => "no_measurement",
        }
    }
}

/// The log of one control tick. Positions local NED \[m\], angles ZYX \[rad\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickRecord {
    /// Tick index k.
    pub k: usize,
    /// Tick time `k·δt` \[s\].
    pub t: f64,
    /// True state at the tick, before the command acts.
    pub truth: PlantState,
    /// The measurement given to the controller (None before the first sample).
    pub measurement: Option<Measurement>,
    /// Number of sensor samples that arrived at this tick.
    pub new_samples: usize,
    /// y_ref,k from the controller (held from the last success on error;
    /// NaN before any success).
    pub reference: Vector3<f64>,
    /// Planned outputs y*_k … y*_{k+3} (held / NaN as `reference`).
    pub plan: [Vector3<f64>; 4],
    /// The command sent to the plant (the controller's, or the held one).
    pub command: AttitudeCommand,
    /// The command after the plant's saturation.
    pub applied: AttitudeCommand,
    /// The controller clipped its command.
    pub ctrl_saturated: bool,
    /// The plant (autopilot) clipped the command.
    pub plant_saturated: bool,
    /// The controller solved its inequality-constrained QP.
    pub constrained: bool,
    /// Outcome of the controller update.
    pub status: TickStatus,
    /// Distance of the true position to the reference path \[m\] (NaN without
    /// [`TrialSpec::path_distance`]).
    pub path_error: f64,
}

/// The true state at the start of one plant step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantSample {
    /// Time \[s\].
    pub t: f64,
    /// Position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Velocity, local NED [m/s].
    pub velocity: Vector3<f64>,
    /// Roll φ \[rad\].
    pub roll: f64,
    /// Pitch θ \[rad\].
    pub pitch: f64,
}

impl PlantSample {
    /// Tilt of the thrust axis from vertical \[rad\].
    pub fn tilt(&self) -> f64 {
        dflat_control::tilt::tilt(self.pitch, self.roll)
    }
}

/// Why a trial ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The configured duration elapsed.
    Duration,
    /// The path end was reached and the settle time flown.
    PathEnd,
    /// `max_duration` elapsed before the path end was reached (+ settle).
    MaxDuration,
    /// The position error exceeded the bound or the state went non-finite.
    Diverged,
}

/// Everything one trial produced.
#[derive(Debug, Clone)]
pub struct TrialResult {
    /// The spec's name.
    pub name: String,
    /// The controller's name.
    pub controller: String,
    /// The seed.
    pub seed: u64,
    /// Control step δt \[s\].
    pub ctrl_dt: f64,
    /// One record per control tick.
    pub ticks: Vec<TickRecord>,
    /// True state at the plant rate, t ∈ [0, T).
    pub trace: Vec<PlantSample>,
    /// Every sensor sample delivered to the controller, in arrival order.
    pub samples: Vec<PoseSample>,
    /// Controller errors: (tick index, message).
    pub errors: Vec<(usize, String)>,
    /// Why the trial ended.
    pub stop_reason: StopReason,
    /// With a [`StopCondition::PathEnd`] stop: the time \[s\] of the first
    /// tick whose true position was within its radius of its end (the
    /// settle counts from it); `None` when it never came, or for another
    /// stop.
    pub arrived_at: Option<f64>,
    /// Summary metrics.
    pub metrics: Metrics,
}

/// Flies one trial. Errors only for an invalid spec; controller failures
/// and divergence are part of the result.
pub fn run_trial(spec: &TrialSpec, seed: u64) -> Result<TrialResult, SimError> {
    let n_sub = spec.validate()?;
    let o = &spec.plant_options;
    let plant_dt = spec.ctrl_dt / n_sub as f64;
    let mut plant = build_plant(spec.plant, o, seed)?;
    plant.reset(&spec.initial);
    let mut sensor = build_sensor(&spec.sensor, seed)?;
    sensor.reset(0.0, &plant.true_state());
    let mut controller = (spec.controller)();
    controller.reset();
    let mut reference = (spec.reference)();

    let max_ticks = match spec.stop {
        StopCondition::Duration(d) => (d / spec.ctrl_dt - 1e-9).ceil().max(0.0) as usize,
        StopCondition::PathEnd { max_duration, .. } => {
            (max_duration / spec.ctrl_dt - 1e-9).ceil().max(0.0) as usize
        }
    };
    let mut command = spec.initial_command.unwrap_or(AttitudeCommand {
        pitch: 0.0,
        roll: 0.0,
        yaw: spec.initial.yaw,
        thrust: o.g,
    });
    let nan3 = Vector3::repeat(f64::NAN);
    let mut last_out: Option<TickOutput> = None;
    let mut ticks = Vec::with_capacity(max_ticks);
    let mut trace = Vec::with_capacity(max_ticks * n_sub);
    let mut samples = Vec::new();
    let mut errors = Vec::new();
    let mut stop_reason = match spec.stop {
        StopCondition::Duration(_) => StopReason::Duration,
        StopCondition::PathEnd { .. } => StopReason::MaxDuration,
    };
    let mut arrived_at: Option<f64> = None;
    let mut diverged_at = None;

    for k in 0..max_ticks {
        let t = k as f64 * spec.ctrl_dt;
        let truth = plant.true_state();
        let measurement = sensor.measure(t);
        let new = sensor.new_samples();
        for s in new {
            controller.observe(&Measurement {
                t: s.t_measured,
                position: s.position,
                yaw: s.yaw,
            });
        }
        samples.extend_from_slice(new);
        let new_samples = new.len();
        let multi_rate = controller.multi_rate();

        let status = match &measurement {
            None => TickStatus::NoMeasurement,
            Some(m) => match controller.update(
                &if multi_rate {
                    Measurement { t, ..*m }
                } else {
                    *m
                },
                reference.as_mut(),
            ) {
                Ok(out) if out.command.is_finite() => {
                    command = out.command;
                    last_out = Some(out);
                    TickStatus::Ok
                }
                Ok(_) => {
                    errors.push((k, "non-finite command".to_string()));
                    TickStatus::ControllerError
                }
                Err(e) => {
                    errors.push((k, e.to_string()));
                    TickStatus::ControllerError
                }
            },
        };
        plant.apply(&command);
        let fresh = status == TickStatus::Ok;
        let reference_k = last_out.map_or(nan3, |o| o.reference);
        let path_error = spec
            .path_distance
            .as_ref()
            .map_or(f64::NAN, |d| d(&truth.position));
        ticks.push(TickRecord {
            k,
            t,
            truth,
            measurement,
            new_samples,
            reference: reference_k,
            plan: last_out.map_or([nan3; 4], |o| o.plan),
            command,
            applied: plant.applied_command(),
            ctrl_saturated: fresh && last_out.is_some_and(|o| o.saturated),
            plant_saturated: plant.saturated(),
            constrained: fresh && last_out.is_some_and(|o| o.constrained),
            status,
            path_error,
        });

        // Divergence.
        let err = if spec.path_distance.is_some() {
            path_error
        } else if let Some(target) = &spec.target {
            target.error(&truth.position).norm()
        } else if reference_k.iter().all(|v| v.is_finite()) {
            (truth.position - reference_k).norm()
        } else {
            0.0
        };
        if !truth.is_finite() || !err.is_finite() || err > spec.divergence_bound {
            diverged_at.get_or_insert(t);
            if spec.stop_on_divergence {
                stop_reason = StopReason::Diverged;
                break;
            }
        }

        // Plant steps under the held command.
        for i in 0..n_sub {
            let s = plant.true_state();
            trace.push(PlantSample {
                t: (k * n_sub + i) as f64 * plant_dt,
                position: s.position,
                velocity: s.velocity,
                roll: s.roll,
                pitch: s.pitch,
            });
            plant.advance(plant_dt);
            sensor.observe((k * n_sub + i + 1) as f64 * plant_dt, &plant.true_state());
        }

        if let StopCondition::PathEnd {
            end,
            radius,
            settle,
            ..
        } = spec.stop
        {
            if arrived_at.is_none() && (truth.position - end).norm() <= radius {
                arrived_at = Some(t);
            }
            if arrived_at.is_some_and(|ta| t + spec.ctrl_dt >= ta + settle - 1e-9) {
                stop_reason = StopReason::PathEnd;
                break;
            }
        }
    }

    let metrics = Metrics::compute(
        &ticks,
        &trace,
        spec.target.as_ref(),
        spec.ctrl_dt,
        errors.len(),
        diverged_at,
    );
    Ok(TrialResult {
        name: spec.name.clone(),
        controller: controller.name().to_string(),
        seed,
        ctrl_dt: spec.ctrl_dt,
        ticks,
        trace,
        samples,
        errors,
        stop_reason,
        arrived_at,
        metrics,
    })
}

/// Flies every `(spec, seed)` pair in parallel (rayon's global pool, or the
/// pool the call is `install`ed in). Results are in input order and, for a
/// given pair, bit-identical to [`run_trial`] whatever the thread count.
/// With `progress`, an indicatif bar on stderr counts finished trials.
pub fn run_trials(
    trials: &[(TrialSpec, u64)],
    progress: bool,
) -> Vec<Result<TrialResult, SimError>> {
    let bar = if progress {
        let bar = ProgressBar::new(trials.len() as u64);
        if let Ok(style) =
            ProgressStyle::with_template("{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} ({eta})")
        {
            bar.set_style(style);
        }
        bar.set_message("trials");
        bar
    } else {
        ProgressBar::hidden()
    };
    let out = trials
        .par_iter()
        .map(|(spec, seed)| {
            let r = run_trial(spec, *seed);
            bar.inc(1);
            r
        })
        .collect();
    bar.finish();
    out
}

/// Distance \[m\] from `p` to the polyline through `vertices` (local NED \[m\]);
/// with `horizontal` only north/east count. A single vertex is a point;
/// no vertices give NaN.
pub fn polyline_distance(vertices: &[Vector3<f64>], p: &Vector3<f64>, horizontal: bool) -> f64 {
    match vertices {
        [] => f64::NAN,
        [a] => (flatten(p, horizontal) - flatten(a, horizontal)).norm(),
        _ => segment_projections(vertices, p, horizontal)
            .map(|(d, _)| d)
            .fold(f64::INFINITY, f64::min),
    }
}

/// The point of the polyline through `vertices` closest to `p` (local NED
/// \[m\]): with `horizontal`, closest in north/east, at the path's own
/// altitude there. A single vertex is a point; None without vertices.
pub fn polyline_closest(
    vertices: &[Vector3<f64>],
    p: &Vector3<f64>,
    horizontal: bool,
) -> Option<Vector3<f64>> {
    match vertices {
        [] => None,
        [a] => Some(*a),
        _ => segment_projections(vertices, p, horizontal)
            // The nearest segment's point (the first of equals; a NaN
            // distance never replaces one).
            .fold(
                None,
                |best: Option<(f64, Vector3<f64>)>, (d, c)| match best {
                    Some((bd, _)) if d.partial_cmp(&bd) != Some(std::cmp::Ordering::Less) => best,
                    _ => Some((d, c)),
                },
            )
            .map(|(_, c)| c),
    }
}

/// `v` with its vertical dropped when `horizontal`.
fn flatten(v: &Vector3<f64>, horizontal: bool) -> Vector3<f64> {
    if horizontal {
        Vector3::new(v.x, v.y, 0.0)
    } else {
        *v
    }
}

/// Per segment of the polyline through `vertices` (two or more): the
/// distance from `p` to its closest point (north/east only with
/// `horizontal`) and that point on the segment itself (its altitude kept).
fn segment_projections<'a>(
    vertices: &'a [Vector3<f64>],
    p: &Vector3<f64>,
    horizontal: bool,
) -> impl Iterator<Item = (f64, Vector3<f64>)> + 'a {
    let q = flatten(p, horizontal);
    vertices.windows(2).map(move |w| {
        let (a, b) = (flatten(&w[0], horizontal), flatten(&w[1], horizontal));
        let ab = b - a;
        let len2 = ab.norm_squared();
        let s = if len2 > 0.0 {
            ((q - a).dot(&ab) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        ((q - (a + ab * s)).norm(), w[0] + (w[1] - w[0]) * s)
    })
}

/// A [`PathDistance`] to the polyline through `vertices` (see
/// [`polyline_distance`]).
pub fn polyline_path_distance(vertices: Vec<Vector3<f64>>, horizontal: bool) -> PathDistance {
    Arc::new(move |p| polyline_distance(&vertices, p, horizontal))
}
