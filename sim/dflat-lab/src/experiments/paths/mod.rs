//! The paper's §VII-C controller comparison (Figs. "boxplot_control_compare"
//! and "control_compare") and the §VII-D DSL demonstration, in the lab.
//!
//! Set-up:
//!
//! * The L path (x, y) = (−20, −30) → (0, −30) → (0, 0) m (NED, north/east)
//!   at z = −10 m ([`paths::l`]), flown at 3, 5, 7 and 9 m/s; start at rest
//!   at the path start; the trial ends 2 s after the vehicle first comes
//!   within 1 m of the path end (or at length/speed + 20 s; or when the path
//!   error exceeds 15 m: *diverged*).
//! * Planar plant, RK4 at 200 Hz, τ = 0.2 s, k̃ = 1, the lab's default ±35°
//!   attitude saturation (the DJI SDK's); every controller also clips its
//!   command at 35°.
//! * Vision-like sensing ([`VisionOptions::default`]): poses captured at
//!   15 Hz (±5 ms jitter), 60 ms latency, σ = 2 cm per axis, extrapolated to
//!   the 50 Hz ticks with a constant-velocity model on the last two samples
//!   (the paper used STEAM).
//! * DF-MPC with N = 100 (2 s lookahead), Flatness MPC with N = 75 (1.5 s),
//!   PD (non-predictive: closest point + desired velocity), reference as in
//!   §VII-C (`dflat_control::reference::Reference`).
//! * Seeds: trial t at speed index i has seed `seed_base + 1000·i + t`,
//!   shared by the three controllers.
//!
//! # Weights: a small documented search
//!
//! The paper: "we tune the weights for all controllers to maximize stable
//! performance". With [`PathsConfig::tuning`] set (the default), each
//! controller's candidates ([`Tuning::default`]; q = 1, only r varies for
//! the MPCs, (k_p, k_d) for PD) are flown at 5 and 9 m/s, 3 trials each, on
//! seeds disjoint from the evaluation (`seed_base + 100000 + 1000·i + t`).
//! A candidate's score is the mean over those trials of the per-trial mean
//! path error; a candidate with a diverged trial, a controller error or a
//! trial that never reached the path end is *unstable* and excluded. The
//! lowest score wins, and one set of weights is then used at every speed
//! (no per-speed picking). The whole search is in the JSON (`tuning`).
//!
//! The outcome on this set-up (seed_base 0), which is also the fallback
//! without tuning ([`PathsConfig::untuned`]): DF-MPC r = 0.0003 (scores
//! 0.65 / 0.74 / 0.94 / 1.45 m for r = 0.0003 / 0.001 / 0.003 / 0.01),
//! Flatness MPC r = 0.01 (2.63 / 2.18 / 2.26 / 2.65 m for r = 0.003 / 0.01
//! / 0.03 / 0.1), PD k_p = 3, k_d = 3 (2.45 / 2.25 / 2.13 / 2.14 m); none
//! unstable. DF's best r is the smallest tried: smaller r tracks harder, and
//! its commands chatter at every vision sample anyway (see
//! `docs/figures/paths.json`).
//!
//! # Metrics
//!
//! Path error: per 50 Hz tick, the horizontal distance of the TRUE position
//! to the L polyline; the box plot pools the ticks of all trials of a
//! (controller, speed). Command smoothness: per trial, the mean over ticks
//! of |Δu| = √(Δθ_cmd² + Δφ_cmd²) [deg per tick], and the share of ticks
//! at which the controller or the autopilot clipped the command.
//!
//! # DSL demonstration
//!
//! DF-MPC only (the tuned weights), one flight each of the D at 10 m/s, the
//! S at 3 m/s and the L at 8 m/s ([`paths::d`], [`paths::s`],
//! [`paths::dsl_l`]; letters reconstructed from the paper's figure) at
//! z = −20 m, same sensing; each flight lasts length/speed + 4 s (the D ends
//! where it starts, so "arrival" cannot end it). Plotted coloured by the
//! true horizontal speed, and as speed vs distance flown.

use std::path::PathBuf;

use dflat_control::reference::paths;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::figures::speed_series;
use super::trial::{TrialSetup, path_length};
use super::{ControllerSpec, ExperimentError, OutputPaths, invalid, mean, write_json};
use crate::harness::{
    ControllerFactory, ErrorStats, Metrics, StopCondition, StopReason, TrialResult, TrialSpec,
    quantile, run_trials,
};
use crate::plot::{
    BoxPlot, BoxSeries, LinePlot, PathPlot, RGBColor, Series, controller_color, north_up,
    write_box_plot, write_line_plot, write_path_plot,
};
use dflat_sim::plant::PlantOptions;
use dflat_sim::sensing::{SensorSpec, VisionOptions};

mod output;

pub use output::write_paths;

/// Seed offset of the tuning trials.
pub const TUNING_SEED_OFFSET: u64 = 100_000;
/// Seed offset of the DSL flights.
pub const DSL_SEED_OFFSET: u64 = 200_000;

/// The small weight search (see the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tuning {
    /// Speeds flown \[m/s\].
    pub speeds: Vec<f64>,
    /// Trials per candidate and speed.
    pub trials: usize,
    /// The candidates; each replaces the configured controller of the same
    /// name if it wins.
    pub candidates: Vec<ControllerSpec>,
}

impl Default for Tuning {
    /// 5 and 9 m/s, 3 trials; DF-MPC (N = 100, q = 1) r ∈ {0.0003, 0.001,
    /// 0.003, 0.01}; Flatness MPC (N = 75, q = 1) r ∈ {0.003, 0.01, 0.03,
    /// 0.1}; PD (k_p, k_d) ∈ {(1, 1.6), (2, 2.5), (3, 3), (4, 4)}.
    fn default() -> Self {
        let tilt = 35.0;
        let mut candidates = Vec::new();
        for r in [0.0003, 0.001, 0.003, 0.01] {
            candidates.push(ControllerSpec::DfMpc {
                horizon: 100,
                q: 1.0,
                r,
                max_tilt_deg: tilt,
            });
        }
        for r in [0.003, 0.01, 0.03, 0.1] {
            candidates.push(ControllerSpec::Fmpc {
                horizon: 75,
                q: 1.0,
                r,
                max_tilt_deg: tilt,
                estimator: None,
            });
        }
        for (kp, kd) in [(1.0, 1.6), (2.0, 2.5), (3.0, 3.0), (4.0, 4.0)] {
            candidates.push(ControllerSpec::Pd {
                kp,
                kd,
                max_tilt_deg: tilt,
                estimator: None,
            });
        }
        candidates.extend(super::fair::estimator_candidates(tilt));
        Self {
            speeds: vec![5.0, 9.0],
            trials: 3,
            candidates,
        }
    }
}

/// Configuration of the comparison. [`Default`] is the full study with the
/// weight search; [`PathsConfig::untuned`] skips the search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathsConfig {
    /// Desired speeds \[m/s\].
    pub speeds: Vec<f64>,
    /// Trials per controller and speed.
    pub trials: usize,
    /// The L path, when a trial ends, the divergence bound and the plant's
    /// saturation (the path studies' shared set-up; flat in the JSON).
    #[serde(flatten)]
    pub setup: TrialSetup,
    /// The vision-like sensing.
    pub vision: VisionOptions,
    /// Base of the seed rules.
    pub seed_base: u64,
    /// The controllers (weights used where the search has no candidate, or
    /// without the search), in plotting order.
    pub controllers: Vec<ControllerSpec>,
    /// The weight search (None: use `controllers` as given).
    pub tuning: Option<Tuning>,
    /// Fly the DSL demonstration too.
    pub dsl: bool,
    /// Altitude of the DSL letters, NED z \[m\].
    pub dsl_altitude: f64,
}

impl Default for PathsConfig {
    fn default() -> Self {
        Self {
            tuning: Some(Tuning::default()),
            ..Self::untuned()
        }
    }
}

impl PathsConfig {
    /// The study without the weight search, with the weights it chose on
    /// this set-up (see the module docs).
    pub fn untuned() -> Self {
        let tilt = 35.0;
        Self {
            speeds: paths::L_SPEEDS.to_vec(),
            trials: 10,
            setup: TrialSetup {
                tilt_limit_deg: tilt,
                ..TrialSetup::default()
            },
            vision: VisionOptions::default(),
            seed_base: 0,
            controllers: vec![
                ControllerSpec::DfMpc {
                    horizon: 100,
                    q: 1.0,
                    r: 0.0003,
                    max_tilt_deg: tilt,
                },
                ControllerSpec::Fmpc {
                    horizon: 75,
                    q: 1.0,
                    r: 0.01,
                    max_tilt_deg: tilt,
                    estimator: None,
                },
                ControllerSpec::Pd {
                    kp: 3.0,
                    kd: 3.0,
                    max_tilt_deg: tilt,
                    estimator: None,
                },
            ]
            .into_iter()
            .chain(super::fair::fair_controllers(tilt))
            .collect(),
            tuning: None,
            dsl: true,
            dsl_altitude: -20.0,
        }
    }

    /// Checks the options (the lab and the controllers check their own).
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let speeds_ok = |s: &[f64]| !s.is_empty() && s.iter().all(|v| v.is_finite() && *v > 0.0);
        if !speeds_ok(&self.speeds) {
            return Err(invalid("speeds", "at least one, each finite and > 0 m/s"));
        }
        if !(1..=10_000).contains(&self.trials) {
            return Err(invalid("trials", "1 ..= 10000"));
        }
        self.setup.validate()?;
        if !self.dsl_altitude.is_finite() {
            return Err(invalid("dsl_altitude", "finite m"));
        }
        if self.controllers.is_empty() {
            return Err(invalid("controllers", "at least one"));
        }
        if let Some(t) = &self.tuning {
            if !speeds_ok(&t.speeds) {
                return Err(invalid(
                    "tuning.speeds",
                    "at least one, each finite and > 0 m/s",
                ));
            }
            if !(1..=1000).contains(&t.trials) {
                return Err(invalid("tuning.trials", "1 ..= 1000"));
            }
        }
        self.vision.validate()?;
        Ok(())
    }

    /// The seed of evaluation trial `trial` at speed index `speed_index`.
    pub fn seed(&self, speed_index: usize, trial: usize) -> u64 {
        self.seed_base + 1000 * speed_index as u64 + trial as u64
    }

    /// The plant options: lab defaults with the configured tilt limit.
    pub fn plant_options(&self) -> PlantOptions {
        self.setup.plant_options()
    }
}

/// One evaluation trial on the L path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathTrial {
    /// The controller's name.
    pub controller: String,
    /// Desired speed \[m/s\].
    pub speed: f64,
    /// Index of the speed in the configuration.
    pub speed_index: usize,
    /// Trial number within (controller, speed).
    pub trial: usize,
    /// The seed.
    pub seed: u64,
    /// Why the trial ended.
    pub stop_reason: StopReason,
    /// The harness's metrics (path error statistics over the ticks).
    pub metrics: Metrics,
}

/// Aggregate of one (controller, speed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathSummary {
    /// The controller's name.
    pub controller: String,
    /// Desired speed \[m/s\].
    pub speed: f64,
    /// Trials aggregated.
    pub trials: usize,
    /// Path error over the pooled ticks of all trials \[m\].
    pub path_error: Option<ErrorStats>,
    /// Mean over trials of the mean |Δu| per tick \[deg\].
    pub smoothness_deg: f64,
    /// Mean over trials of the mean per-axis max |Δu| per tick \[deg\].
    pub smoothness_axis_max_deg: f64,
    /// Mean over trials of the share of saturated ticks [0, 1].
    pub saturation_share: f64,
    /// Largest tilt over the trials \[deg\].
    pub max_tilt_deg: f64,
    /// Mean flight time \[s\].
    pub mean_duration: f64,
    /// Trials that diverged (path error beyond the bound).
    pub diverged: usize,
    /// Trials that never reached the path end in time.
    pub not_arrived: usize,
    /// Controller errors summed over the trials.
    pub controller_errors: usize,
}

/// One candidate of the weight search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TuningCandidate {
    /// The candidate.
    pub spec: ControllerSpec,
    /// Mean path error per tuning speed: mean over trials of each trial's
    /// mean path error \[m\].
    pub mean_path_error: Vec<f64>,
    /// The score: mean of `mean_path_error` \[m\] (null when unstable).
    pub score: Option<f64>,
    /// Diverged, failing or unfinished trials (any makes it unstable).
    pub failed_trials: usize,
    /// This candidate won for its controller.
    pub chosen: bool,
}

/// The weight search and its outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TuningResult {
    /// The search flown.
    pub tuning: Tuning,
    /// Every candidate with its score.
    pub candidates: Vec<TuningCandidate>,
}

/// One DSL flight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DslFlight {
    /// "D", "S" or "L".
    pub letter: String,
    /// Desired speed \[m/s\].
    pub speed: f64,
    /// The seed.
    pub seed: u64,
    /// Why the flight ended.
    pub stop_reason: StopReason,
    /// Largest true horizontal speed \[m/s\].
    pub max_speed: f64,
    /// The harness's metrics.
    pub metrics: Metrics,
    /// Waypoints, NED \[m\].
    #[serde(skip)]
    pub waypoints: Vec<Vector3<f64>>,
    /// True position per tick, NED \[m\].
    #[serde(skip)]
    pub positions: Vec<Vector3<f64>>,
    /// True horizontal speed per tick \[m/s\].
    #[serde(skip)]
    pub speeds: Vec<f64>,
}

/// A flown path kept for the plots (one trial per controller and speed).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FlownPath {
    /// The controller's name.
    pub controller: String,
    /// Desired speed \[m/s\].
    pub speed: f64,
    /// True position per tick, NED \[m\].
    pub positions: Vec<Vector3<f64>>,
}

/// Everything the comparison produced (serialised as its JSON; the per-tick
/// data behind the plots is not serialised).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PathsResult {
    /// "paths".
    pub experiment: String,
    /// The configuration flown.
    pub config: PathsConfig,
    /// The plant options flown.
    pub plant: PlantOptions,
    /// The weight search (None when not run).
    pub tuning: Option<TuningResult>,
    /// The controllers flown in the evaluation (after the search).
    pub controllers: Vec<ControllerSpec>,
    /// One row per (controller, speed).
    pub summary: Vec<PathSummary>,
    /// Every evaluation trial.
    pub trials: Vec<PathTrial>,
    /// The DSL flights (empty when not flown).
    pub dsl: Vec<DslFlight>,
    /// Per (controller, speed): the pooled per-tick path errors \[m\].
    #[serde(skip)]
    pub pooled_errors: Vec<(String, f64, Vec<f64>)>,
    /// Trial 0 of each (controller, speed).
    #[serde(skip)]
    pub flown: Vec<FlownPath>,
}

impl PathsResult {
    /// The summary row of `controller` at `speed`.
    pub fn row(&self, controller: &str, speed: f64) -> Option<&PathSummary> {
        self.summary
            .iter()
            .find(|r| r.controller == controller && r.speed == speed)
    }

    /// A plain-text table: speed → median / p95 path error, mean |Δu| and
    /// saturated share per controller.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:>6} | {:<12} | {:>7} {:>7} {:>7} {:>7} | {:>9} | {:>6} | {:>5}\n",
            "speed", "ctrl", "mean", "median", "p95", "max", "|du| deg", "sat %", "div"
        );
        for &speed in &self.config.speeds {
            for c in &self.controllers {
                let Some(r) = self.row(c.name(), speed) else {
                    continue;
                };
                let (mean, med, p95, max) = r
                    .path_error
                    .map_or((f64::NAN, f64::NAN, f64::NAN, f64::NAN), |e| {
                        (e.mean, e.median, e.p95, e.max)
                    });
                s += &format!(
                    "{speed:>6.1} | {:<12} | {mean:>7.3} {med:>7.3} {p95:>7.3} {max:>7.3} | {:>9.3} | {:>6.1} | {:>2}/{:<2}\n",
                    c.name(),
                    r.smoothness_deg,
                    100.0 * r.saturation_share,
                    r.diverged,
                    r.trials
                );
            }
        }
        if let Some(t) = &self.tuning {
            s += &format!(
                "weight search (score = mean path error [m] over {:?} m/s, {} trials):\n",
                t.tuning.speeds, t.tuning.trials
            );
            for c in &t.candidates {
                s += &format!(
                    "  {:<12} {:<40} {:>8} {}\n",
                    c.spec.name(),
                    c.spec.describe(),
                    c.score
                        .map_or("unstable".to_string(), |v| format!("{v:.3}")),
                    if c.chosen { "<- chosen" } else { "" }
                );
            }
        }
        for f in &self.dsl {
            let e = f.metrics.path_error;
            s += &format!(
                "DSL {} at {} m/s: median {:.3} m, p95 {:.3} m, max speed {:.2} m/s, |du| {:.3} deg\n",
                f.letter,
                f.speed,
                e.map_or(f64::NAN, |e| e.median),
                e.map_or(f64::NAN, |e| e.p95),
                f.max_speed,
                f.metrics.smoothness_deg
            );
        }
        s
    }
}

impl PathsConfig {
    /// The stop at the end of `waypoints` flown at `speed`
    /// ([`TrialSetup::end_stop`]).
    pub(crate) fn path_end_stop(&self, waypoints: &[Vector3<f64>], speed: f64) -> StopCondition {
        self.setup.end_stop(waypoints, speed)
    }

    /// A trial of `controller` on `waypoints` at `speed` on `plant`, under
    /// this lab's vision ([`TrialSetup::trial`]).
    pub(crate) fn path_trial(
        &self,
        name: String,
        controller: ControllerFactory,
        plant: PlantOptions,
        waypoints: &[Vector3<f64>],
        speed: f64,
        stop: StopCondition,
    ) -> Result<TrialSpec, ExperimentError> {
        self.setup.trial(
            name,
            controller,
            plant,
            SensorSpec::Vision(self.vision.clone()),
            waypoints,
            speed,
            stop,
        )
    }
}

/// A trial on `waypoints` at `speed` with `spec`'s controller on the lab's
/// plant.
fn path_trial(
    config: &PathsConfig,
    spec: &ControllerSpec,
    waypoints: &[Vector3<f64>],
    speed: f64,
    stop: StopCondition,
    name: String,
) -> Result<TrialSpec, ExperimentError> {
    config.path_trial(
        name,
        spec.factory()?,
        config.plant_options(),
        waypoints,
        speed,
        stop,
    )
}

/// A trial on the L path at `speed`, ending at arrival + settle.
fn l_trial(
    config: &PathsConfig,
    spec: &ControllerSpec,
    speed: f64,
) -> Result<TrialSpec, ExperimentError> {
    let w = config.setup.l_path();
    let stop = config.path_end_stop(&w, speed);
    path_trial(
        config,
        spec,
        &w,
        speed,
        stop,
        format!("{} L {speed} m/s", spec.name()),
    )
}

/// A failed trial for the search: diverged, controller errors, or never
/// arrived.
fn failed(r: &TrialResult) -> bool {
    r.metrics.diverged || r.metrics.controller_errors > 0 || r.stop_reason != StopReason::PathEnd
}

fn trial_mean_error(r: &TrialResult) -> f64 {
    r.metrics.path_error.map_or(f64::NAN, |e| e.mean)
}

/// Runs the weight search; returns the candidates' scores and the
/// controllers with the winners substituted.
fn tune(
    config: &PathsConfig,
    tuning: &Tuning,
    progress: bool,
) -> Result<(TuningResult, Vec<ControllerSpec>), ExperimentError> {
    let mut specs = Vec::new();
    for c in &tuning.candidates {
        for (i, &speed) in tuning.speeds.iter().enumerate() {
            let t = l_trial(config, c, speed)?;
            for k in 0..tuning.trials {
                let seed = config.seed_base + TUNING_SEED_OFFSET + 1000 * i as u64 + k as u64;
                specs.push((t.clone(), seed));
            }
        }
    }
    let results = run_trials(&specs, progress);
    let mut results = results.into_iter();
    let mut candidates = Vec::new();
    for c in &tuning.candidates {
        let mut per_speed = Vec::new();
        let mut failed_trials = 0;
        for _ in &tuning.speeds {
            let mut errs = Vec::new();
            for _ in 0..tuning.trials {
                let r = results
                    .next()
                    .ok_or_else(|| invalid("tuning", "missing trial result"))??;
                if failed(&r) {
                    failed_trials += 1;
                }
                errs.push(trial_mean_error(&r));
            }
            per_speed.push(mean(errs));
        }
        let score = mean(per_speed.iter().copied());
        candidates.push(TuningCandidate {
            spec: *c,
            mean_path_error: per_speed,
            score: (failed_trials == 0 && score.is_finite()).then_some(score),
            failed_trials,
            chosen: false,
        });
    }
    let mut controllers = config.controllers.clone();
    for slot in controllers.iter_mut() {
        let best = candidates
            .iter()
            .enumerate()
            .filter(|(_, c)| c.spec.name() == slot.name())
            .filter_map(|(i, c)| c.score.map(|s| (i, s)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, _)) = best {
            candidates[i].chosen = true;
            *slot = candidates[i].spec;
        }
    }
    Ok((
        TuningResult {
            tuning: tuning.clone(),
            candidates,
        },
        controllers,
    ))
}

fn horizontal_speed(v: &Vector3<f64>) -> f64 {
    v.x.hypot(v.y)
}

/// Flies the comparison: the weight search (if configured), then every
/// (controller, speed, trial) and the DSL flights in parallel, with
/// indicatif bars when `progress`.
pub fn run_paths(config: &PathsConfig, progress: bool) -> Result<PathsResult, ExperimentError> {
    config.validate()?;
    let (tuning, controllers) = match &config.tuning {
        Some(t) => {
            let (r, c) = tune(config, t, progress)?;
            (Some(r), c)
        }
        None => (None, config.controllers.clone()),
    };

    // Evaluation trials, then the DSL flights, in one parallel batch.
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for c in &controllers {
        for (i, &speed) in config.speeds.iter().enumerate() {
            let t = l_trial(config, c, speed)?;
            for k in 0..config.trials {
                specs.push((t.clone(), config.seed(i, k)));
                keys.push((c.name(), i, speed, k));
            }
        }
    }
    let n_eval = specs.len();
    let letters: [(&str, &[[f64; 2]], f64); 3] = [
        ("D", &paths::D_XY, paths::D_SPEED),
        ("S", &paths::S_XY, paths::S_SPEED),
        ("L", &paths::DSL_L_XY, paths::DSL_L_SPEED),
    ];
    let df = controllers
        .iter()
        .find(|c| matches!(c, ControllerSpec::DfMpc { .. }))
        .copied();
    let mut dsl_keys = Vec::new();
    if config.dsl
        && let Some(df) = df
    {
        for (j, (letter, xy, speed)) in letters.iter().enumerate() {
            let w = paths::waypoints(xy, config.dsl_altitude);
            let mut duration = path_length(&w) / speed + 4.0;
            if let Some(cap) = config.setup.max_duration {
                duration = duration.min(cap);
            }
            let t = path_trial(
                config,
                &df,
                &w,
                *speed,
                StopCondition::Duration(duration),
                format!("DSL {letter}"),
            )?;
            specs.push((t, config.seed_base + DSL_SEED_OFFSET + j as u64));
            dsl_keys.push((*letter, *speed, w));
        }
    }
    let results = run_trials(&specs, progress);

    let mut trials = Vec::with_capacity(n_eval);
    let mut pooled: Vec<(String, f64, Vec<f64>)> = Vec::new();
    let mut flown = Vec::new();
    let mut dsl = Vec::new();
    let mut results = results.into_iter();
    for (name, i, speed, k) in keys {
        let r = results
            .next()
            .ok_or_else(|| invalid("trials", "missing trial result"))??;
        let errors = r
            .ticks
            .iter()
            .map(|t| t.path_error)
            .filter(|e| e.is_finite());
        match pooled.iter_mut().find(|p| p.0 == name && p.1 == speed) {
            Some(p) => p.2.extend(errors),
            None => pooled.push((name.to_string(), speed, errors.collect())),
        }
        if k == 0 {
            flown.push(FlownPath {
                controller: name.to_string(),
                speed,
                positions: r.ticks.iter().map(|t| t.truth.position).collect(),
            });
        }
        trials.push(PathTrial {
            controller: name.to_string(),
            speed,
            speed_index: i,
            trial: k,
            seed: r.seed,
            stop_reason: r.stop_reason,
            metrics: r.metrics,
        });
    }
    for (letter, speed, waypoints) in dsl_keys {
        let r = results
            .next()
            .ok_or_else(|| invalid("dsl", "missing trial result"))??;
        let speeds: Vec<f64> = r
            .ticks
            .iter()
            .map(|t| horizontal_speed(&t.truth.velocity))
            .collect();
        dsl.push(DslFlight {
            letter: letter.to_string(),
            speed,
            seed: r.seed,
            stop_reason: r.stop_reason,
            max_speed: speeds.iter().copied().fold(0.0, f64::max),
            metrics: r.metrics,
            waypoints,
            positions: r.ticks.iter().map(|t| t.truth.position).collect(),
            speeds,
        });
    }

    let mut summary = Vec::new();
    for c in &controllers {
        for &speed in &config.speeds {
            let rows: Vec<&PathTrial> = trials
                .iter()
                .filter(|t| t.controller == c.name() && t.speed == speed)
                .collect();
            let errors = pooled
                .iter()
                .find(|p| p.0 == c.name() && p.1 == speed)
                .map(|p| p.2.clone())
                .unwrap_or_default();
            summary.push(PathSummary {
                controller: c.name().to_string(),
                speed,
                trials: rows.len(),
                path_error: ErrorStats::from_values(errors),
                smoothness_deg: mean(rows.iter().map(|t| t.metrics.smoothness_deg)),
                smoothness_axis_max_deg: mean(
                    rows.iter().map(|t| t.metrics.smoothness_axis_max_deg),
                ),
                saturation_share: mean(rows.iter().map(|t| t.metrics.saturation_share)),
                max_tilt_deg: rows
                    .iter()
                    .map(|t| t.metrics.max_tilt_deg)
                    .fold(0.0, f64::max),
                mean_duration: mean(rows.iter().map(|t| t.metrics.duration)),
                diverged: rows.iter().filter(|t| t.metrics.diverged).count(),
                not_arrived: rows
                    .iter()
                    .filter(|t| t.stop_reason != StopReason::PathEnd)
                    .count(),
                controller_errors: rows.iter().map(|t| t.metrics.controller_errors).sum(),
            });
        }
    }

    Ok(PathsResult {
        experiment: "paths".to_string(),
        config: config.clone(),
        plant: config.plant_options(),
        tuning,
        controllers,
        summary,
        trials,
        dsl,
        pooled_errors: pooled,
        flown,
    })
}
