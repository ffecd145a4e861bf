//! Vision-rate study (issue 6): DF-MPC on 10–30 Hz delayed poses, with and
//! without multi-rate windows and the command-smoothness weight, against the
//! paper's extrapolated DF-MPC and the two baselines.
//!
//! Set-up (as [`super::paths`] unless stated):
//!
//! * The L path ([`paths::l`] at z = −10 m) at 3, 5, 7 and 9 m/s, start at
//!   rest at the path start, end 2 s after first coming within 1 m of the
//!   path end (or length/speed + 20 s; diverged beyond 15 m of path error).
//! * Planar plant, RK4 at 200 Hz, τ = 0.2 s, k̃ = 1, ±35° attitude
//!   saturation; every controller clips its command at 35° too.
//! * Vision stand-in ([`VisionOptions`]) at 10, 15 and 30 Hz: 60 ms
//!   latency, σ = 2 cm per axis, ±5 ms capture jitter (±3 ms at 30 Hz is not
//!   needed: 5 ms is below half the period at every rate), no dropouts.
//! * Controllers ([`VisionRateConfig::default`]):
//!   - `df-paper` — DF-MPC of the paper on the 50 Hz stream extrapolated
//!     with constant velocity (the weights of the paths study: N = 100,
//!     q = 1, r = 0.0003);
//!   - `df-multirate` — the same weights on multi-rate windows
//!     ([`MultiRateWindow`](dflat_control::window::MultiRateWindow)): raw
//!     samples at their capture times, no extrapolation;
//!   - `df-mr-smooth` — the recommended set-up: multi-rate windows, the
//!     command-smoothness weight s = 50 [1/rad²], a larger jerk weight
//!     r = 0.003 and a 30° tilt bound on the plan (clarabel when it binds;
//!     no wall-clock limit in the lab, so runs stay deterministic);
//!   - `fmpc-est` (N = 75, q = 1, r = 0.01) and `pd-est` (k_p = 6,
//!     k_d = 5): the baselines fed by their state estimator, as the paper
//!     flew them outdoors (the paths study's fair weights; the estimator's
//!     default rule at each cell's rate and σ, every pose at its capture
//!     time).
//!
//!   The ladder separates the ingredients: `df-paper` → `df-multirate`
//!   changes only the window; `df-multirate` → `df-mr-smooth` adds the
//!   weights and the bound.
//! * Seeds: trial t at rate index i and speed index j has seed
//!   `seed_base + 10000·i + 1000·j + t`, shared by all controllers (same
//!   noise, same capture times).
//!
//! # What each ingredient does (15 Hz, 2 trials per speed, during tuning)
//!
//! * The multi-rate window alone takes the mean |Δu| from 22–30°/tick to
//!   ~1°/tick and the p95 path error down by a third or more (the
//!   extrapolated stream's jumps were the chatter). It does not change the
//!   saturated share at 7–9 m/s (30–60 %): that comes from the L reference
//!   itself (it starts at full speed, turns the corner with a velocity step
//!   and stops dead), which an unconstrained plan meets at full tilt.
//! * The 30° plan bound with r = 0.003 takes the saturated share to ≤ 6 %
//!   at every speed and the p95 at 9 m/s from 2.3 m to 0.65 m (the plan
//!   brakes for the corner within what the vehicle can do).
//! * The smoothness weight then takes another ~10 % off |Δu| at s = 50
//!   (0.35 → 0.30°/tick at 3 m/s), ~20 % at s = 200 with a slightly larger
//!   p95; its large effect is where the window itself is smooth but the
//!   plan is not (50 Hz motion-capture-grade poses: −68 %, see
//!   `dflat-control/tests/df_smooth.rs`).
//! * Window length M ∈ {10, 15, 25, 40} and process noise from
//!   `[0.0005, 0.002, 0.02]` to `[0.002, 0.05, 1]` change the results by a
//!   few per cent (the arrival cost keeps what older samples said).
//!
//! * Seeds: trial t at rate index i and speed index j has seed
//!   `seed_base + 10000·i + 1000·j + t`, shared by all controllers (same
//!   noise, same capture times).
//!
//! Metrics per (controller, rate, speed): the path error (distance of the
//! TRUE position to the L polyline, per 50 Hz tick, pooled over the trials:
//! median and p95), the command smoothness (per trial the mean over ticks
//! of `|Δu| = √(Δθ_cmd² + Δφ_cmd²)` [deg per tick], averaged over trials)
//! and the share of ticks where the controller or the autopilot clipped the
//! command.
//!
//! Budgets (issue 6), checked at 15 Hz for `df-mr-smooth` at every speed:
//! mean |Δu| ≤ 5°/tick, ≤ 10 % saturated ticks, p95 path error ≤ 1.1× the
//! `df-paper` p95 at the same speed ([`VisionRateResult::budgets`]).

use std::path::PathBuf;
use std::sync::Arc;

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::estimator::EstimatorSettings;
use dflat_control::reference::paths;
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller};
use dflat_model::{PlanarModel, PlanarParams};
use serde::{Deserialize, Serialize};

use super::trial::TrialSetup;
use super::{ControllerSpec, ExperimentError, OutputPaths, fair, invalid, mean, write_json};
use crate::harness::{
    ControllerFactory, ErrorStats, StopReason, TrialResult, TrialSpec, run_trials,
};
use crate::plot::{LinePlot, RGBColor, Series, write_line_plot};
use dflat_sim::plant::PlantOptions;
use dflat_sim::sensing::{SensorSpec, VisionMode, VisionOptions};

/// One controller of the study.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum VisionController {
    /// DF-MPC ([`DfMpc`]), command clipped at ±`max_tilt_deg`.
    DfMpc {
        /// Horizon N \[steps\].
        horizon: usize,
        /// Tracking weight q (x and y) [1/m²].
        q: f64,
        /// Jerk weight r (x and y) [s⁶/m²].
        r: f64,
        /// Command-smoothness weight s (x and y) [1/rad²]; 0 = off.
        smoothness: f64,
        /// Multi-rate windows (raw samples); `None`: the extrapolated stream.
        multi_rate: Option<MultiRateSettings>,
        /// Tilt constraint on the plan \[deg\] (`|Δ²y/δt²| ≤ g·tan` per
        /// axis, clarabel when it binds); `None`: unconstrained.
        plan_tilt_deg: Option<f64>,
        /// Command saturation \[deg\].
        max_tilt_deg: f64,
    },
    /// A baseline of the paths study (Flatness MPC or PD), extrapolated stream.
    Baseline(ControllerSpec),
}

impl VisionController {
    /// The short key used in the JSON and the table.
    /// `df-paper` (extrapolated, no smoothness), `df-smooth` (extrapolated
    /// with smoothness), `df-multirate`, `df-mr-smooth`; `fmpc`, `pd`.
    pub fn key(&self) -> &'static str {
        match self {
            Self::DfMpc {
                multi_rate,
                smoothness,
                ..
            } => match (multi_rate.is_some(), *smoothness > 0.0) {
                (false, false) => "df-paper",
                (false, true) => "df-smooth",
                (true, false) => "df-multirate",
                (true, true) => "df-mr-smooth",
            },
            Self::Baseline(c) => c.name(),
        }
    }

    /// Legend label, with the weights that differ between the DF variants.
    pub fn label(&self) -> String {
        match self {
            Self::DfMpc {
                r,
                smoothness,
                plan_tilt_deg,
                ..
            } => {
                let base = match self.key() {
                    "df-paper" => "DF-MPC, extrapolated (paper)",
                    "df-smooth" => "DF-MPC, extrapolated + smoothness",
                    "df-multirate" => "DF-MPC, multi-rate window",
                    _ => "DF-MPC, multi-rate + smoothness",
                };
                let mut s = format!("{base}: r = {r}");
                if *smoothness > 0.0 {
                    s += &format!(", s = {smoothness}");
                }
                if let Some(t) = plan_tilt_deg {
                    s += &format!(", plan tilt ≤ {t}°");
                }
                s
            }
            Self::Baseline(c) => c.label().to_string(),
        }
    }

    /// The sensing mode it flies with: raw samples for multi-rate windows,
    /// constant-velocity extrapolation otherwise.
    pub fn vision_mode(&self) -> VisionMode {
        match self {
            Self::DfMpc {
                multi_rate: Some(_),
                ..
            } => VisionMode::Raw,
            _ => VisionMode::Extrapolate,
        }
    }

    fn color(&self, index: usize) -> RGBColor {
        match self.key() {
            "df-paper" => RGBColor(214, 39, 40),
            "df-multirate" => RGBColor(255, 127, 14),
            "df-mr-smooth" => RGBColor(148, 103, 189),
            "df-smooth" => RGBColor(140, 86, 75),
            "fmpc" | "fmpc-est" => RGBColor(31, 119, 180),
            "pd" | "pd-est" => RGBColor(44, 160, 44),
            _ => crate::plot::controller_color(self.key(), index),
        }
    }

    /// Builds the controller.
    pub fn build(&self) -> Result<Box<dyn Controller>, ExperimentError> {
        match *self {
            Self::DfMpc {
                horizon,
                q,
                r,
                smoothness,
                multi_rate,
                plan_tilt_deg,
                max_tilt_deg,
            } => {
                let wrap = |source| ExperimentError::Controller {
                    controller: "df-mpc",
                    source,
                };
                let model = ControlModel::Planar(
                    PlanarModel::new(PlanarParams::default()).map_err(|e| wrap(e.into()))?,
                );
                let settings = super::controllers::smooth_dfmpc_settings(
                    (horizon, q, r, smoothness),
                    multi_rate,
                    plan_tilt_deg,
                    max_tilt_deg,
                );
                Ok(Box::new(DfMpc::new(model, settings).map_err(wrap)?))
            }
            Self::Baseline(c) => c.build(),
        }
    }

    /// A factory for the harness (the controller is built once here to check
    /// the settings; a later failure cannot happen for the same settings).
    pub fn factory(&self) -> Result<ControllerFactory, ExperimentError> {
        if let Self::Baseline(c) = self {
            return c.factory();
        }
        self.build()?;
        let spec = *self;
        Ok(Arc::new(move || match spec.build() {
            Ok(c) => c,
            // Unreachable for settings that built once; keep the trial alive.
            Err(_) => Box::new(
                DfMpc::new(
                    ControlModel::Planar(
                        PlanarModel::new(PlanarParams::default()).expect("default planar model"),
                    ),
                    DfMpcSettings::default(),
                )
                .expect("default DF-MPC settings"),
            ),
        }))
    }
}

/// The finite path errors of `r`'s ticks \[m\] (the pooled samples of the
/// vision-rate and phase studies' rows).
pub(super) fn finite_path_errors(r: &TrialResult) -> impl Iterator<Item = f64> + '_ {
    r.ticks
        .iter()
        .map(|t| t.path_error)
        .filter(|e| e.is_finite())
}

/// Configuration of the study. [`Default`] is the full study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VisionRateConfig {
    /// Desired speeds [m/s].
    pub speeds: Vec<f64>,
    /// Vision rates \[Hz\].
    pub rates: Vec<f64>,
    /// Trials per (controller, rate, speed).
    pub trials: usize,
    /// Vision latency \[s\].
    pub latency: f64,
    /// Vision noise per axis \[m\].
    pub sigma: f64,
    /// Capture-time jitter (uniform ±) \[s\].
    pub timing_jitter: f64,
    /// The L path, when a trial ends, the divergence bound and the plant's
    /// saturation (the path studies' shared set-up; flat in the JSON).
    #[serde(flatten)]
    pub setup: TrialSetup,
    /// Base of the seed rule.
    pub seed_base: u64,
    /// The controllers, in table and legend order.
    pub controllers: Vec<VisionController>,
}

impl Default for VisionRateConfig {
    /// 3/5/7/9 m/s, 10/15/30 Hz, 10 trials, 60 ms, 2 cm, ±5 ms; the five
    /// controllers (module docs). Multi-rate windows: the
    /// [`MultiRateSettings`] defaults (M = 25 steps = 0.5 s, sample σ 2 cm,
    /// process noise 1 mm, 0.01 m/s, 0.1 m/s² per step). `df-mr-smooth`:
    /// s = 50 [1/rad²], r = 0.003, 30° plan-tilt bound.
    fn default() -> Self {
        let tilt = 35.0;
        let df = |r: f64, smoothness: f64, multi_rate, plan_tilt_deg| VisionController::DfMpc {
            horizon: 100,
            q: 1.0,
            r,
            smoothness,
            multi_rate,
            plan_tilt_deg,
            max_tilt_deg: tilt,
        };
        let mr = Some(MultiRateSettings::default());
        Self {
            speeds: paths::L_SPEEDS.to_vec(),
            rates: vec![10.0, 15.0, 30.0],
            trials: 10,
            latency: 0.06,
            sigma: 0.02,
            timing_jitter: 0.005,
            setup: TrialSetup {
                tilt_limit_deg: tilt,
                ..TrialSetup::default()
            },
            seed_base: 0,
            controllers: [
                df(0.0003, 0.0, None, None),
                df(0.0003, 0.0, mr, None),
                df(0.003, 50.0, mr, Some(30.0)),
            ]
            .into_iter()
            // The baselines fed by their state estimator (the paths study's
            // weights; its settings are re-derived per rate,
            // [`VisionRateConfig::trial`]).
            .chain(
                fair::fair_controllers(tilt)
                    .into_iter()
                    .filter(|c| c.df_settings().is_none())
                    .map(VisionController::Baseline),
            )
            .collect(),
        }
    }
}

impl VisionRateConfig {
    /// Checks the options (the lab and the controllers check their own).
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let positive = |s: &[f64]| !s.is_empty() && s.iter().all(|v| v.is_finite() && *v > 0.0);
        if !positive(&self.speeds) {
            return Err(invalid("speeds", "at least one, each finite and > 0 m/s"));
        }
        if !positive(&self.rates) {
            return Err(invalid("rates", "at least one, each finite and > 0 Hz"));
        }
        if !(1..=1000).contains(&self.trials) {
            return Err(invalid("trials", "1 ..= 1000"));
        }
        if self.controllers.is_empty() {
            return Err(invalid("controllers", "at least one"));
        }
        self.setup.validate()?;
        for r in &self.rates {
            self.vision(*r, VisionMode::Raw).validate()?;
        }
        Ok(())
    }

    /// The seed of trial `trial` at rate index `rate` and speed index `speed`.
    pub fn seed(&self, rate: usize, speed: usize, trial: usize) -> u64 {
        self.seed_base + 10_000 * rate as u64 + 1000 * speed as u64 + trial as u64
    }

    /// The vision options at `rate_hz` in `mode`.
    pub fn vision(&self, rate_hz: f64, mode: VisionMode) -> VisionOptions {
        VisionOptions {
            rate_hz,
            latency: self.latency,
            sigma: self.sigma,
            timing_jitter: self.timing_jitter,
            mode,
            ..VisionOptions::default()
        }
    }

    /// The plant options: lab defaults with the configured tilt limit.
    pub fn plant_options(&self) -> PlantOptions {
        self.setup.plant_options()
    }

    fn trial(
        &self,
        controller: &VisionController,
        rate: f64,
        speed: f64,
    ) -> Result<TrialSpec, ExperimentError> {
        // An estimator-fed baseline gets the default rule at this rate.
        let controller = &match *controller {
            VisionController::Baseline(spec) => VisionController::Baseline(
                spec.with_estimator(EstimatorSettings::for_sensor(self.sigma, rate)),
            ),
            c => c,
        };
        self.setup.l_trial(
            format!("{} L {speed} m/s {rate} Hz", controller.key()),
            controller.factory()?,
            SensorSpec::Vision(self.vision(rate, controller.vision_mode())),
            speed,
        )
    }
}

/// One (controller, rate, speed) aggregated over its trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VisionRateRow {
    /// The controller's key ([`VisionController::key`]).
    pub controller: String,
    /// Vision rate \[Hz\].
    pub rate: f64,
    /// Desired speed [m/s].
    pub speed: f64,
    /// Trials aggregated.
    pub trials: usize,
    /// Path error over the pooled ticks of all trials \[m\].
    pub path_error: Option<ErrorStats>,
    /// Mean over trials of the mean |Δu| per tick \[deg\].
    pub smoothness_deg: f64,
    /// Mean over trials of the share of saturated ticks [0, 1].
    pub saturation_share: f64,
    /// Largest tilt over the trials \[deg\].
    pub max_tilt_deg: f64,
    /// Trials that diverged.
    pub diverged: usize,
    /// Trials that never reached the path end in time.
    pub not_arrived: usize,
    /// Controller errors summed over the trials.
    pub controller_errors: usize,
}

/// The budgets of issue 6 at one speed (15 Hz, `df-mr-smooth` vs `df-paper`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BudgetCheck {
    /// Desired speed [m/s].
    pub speed: f64,
    /// Mean |Δu| [deg/tick] (budget ≤ 5).
    pub smoothness_deg: f64,
    /// Saturated share [0, 1] (budget ≤ 0.10).
    pub saturation_share: f64,
    /// p95 path error \[m\].
    pub p95: f64,
    /// The paper DF's p95 at the same speed \[m\] (budget: p95 ≤ 1.1× this).
    pub paper_p95: f64,
    /// All three budgets hold.
    pub met: bool,
}

/// Everything the study produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VisionRateResult {
    /// "vision-rate".
    pub experiment: String,
    /// The configuration flown.
    pub config: VisionRateConfig,
    /// One row per (controller, rate, speed), in config order.
    pub rows: Vec<VisionRateRow>,
    /// The budgets at 15 Hz (empty when 15 Hz or a DF variant is not flown).
    pub budgets: Vec<BudgetCheck>,
}

/// The rate at which the budgets are checked \[Hz\].
pub const BUDGET_RATE: f64 = 15.0;

impl VisionRateResult {
    /// The row of `controller` (key) at `rate` and `speed`.
    pub fn row(&self, controller: &str, rate: f64, speed: f64) -> Option<&VisionRateRow> {
        self.rows
            .iter()
            .find(|r| r.controller == controller && r.rate == rate && r.speed == speed)
    }

    /// The results as a markdown table (one per rate) plus the budgets.
    pub fn table(&self) -> String {
        let mut s = String::new();
        for &rate in &self.config.rates {
            s += &format!(
                "\n**Vision at {rate} Hz** (60 ms latency, σ 2 cm; {} trials per cell)\n\n",
                self.config.trials
            );
            s += "| speed [m/s] | controller | median [m] | p95 [m] | mean \\|Δu\\| [°/tick] | saturated [%] | diverged |\n";
            s += "|---:|:---|---:|---:|---:|---:|---:|\n";
            for &speed in &self.config.speeds {
                for c in &self.config.controllers {
                    let Some(r) = self.row(c.key(), rate, speed) else {
                        continue;
                    };
                    let (med, p95) = r
                        .path_error
                        .map_or((f64::NAN, f64::NAN), |e| (e.median, e.p95));
                    s += &format!(
                        "| {speed} | {} | {med:.3} | {p95:.3} | {:.2} | {:.1} | {}/{} |\n",
                        r.controller,
                        r.smoothness_deg,
                        100.0 * r.saturation_share,
                        r.diverged,
                        r.trials
                    );
                }
            }
        }
        if !self.budgets.is_empty() {
            s += &format!(
                "\n**Budgets at {BUDGET_RATE} Hz** (df-mr-smooth: mean |Δu| ≤ 5°/tick, ≤ 10 % saturated, p95 ≤ 1.1× df-paper)\n\n"
            );
            s += "| speed [m/s] | mean \\|Δu\\| [°/tick] | saturated [%] | p95 [m] | 1.1× df-paper p95 [m] | met |\n";
            s += "|---:|---:|---:|---:|---:|:---:|\n";
            for b in &self.budgets {
                s += &format!(
                    "| {} | {:.2} | {:.1} | {:.3} | {:.3} | {} |\n",
                    b.speed,
                    b.smoothness_deg,
                    100.0 * b.saturation_share,
                    b.p95,
                    1.1 * b.paper_p95,
                    if b.met { "yes" } else { "NO" }
                );
            }
        }
        s
    }
}

/// Flies the study: every (controller, rate, speed, trial) in parallel.
pub fn run_vision_rate(
    config: &VisionRateConfig,
    progress: bool,
) -> Result<VisionRateResult, ExperimentError> {
    config.validate()?;
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for c in &config.controllers {
        for (i, &rate) in config.rates.iter().enumerate() {
            for (j, &speed) in config.speeds.iter().enumerate() {
                let t = config.trial(c, rate, speed)?;
                for k in 0..config.trials {
                    specs.push((t.clone(), config.seed(i, j, k)));
                    keys.push((c.key(), rate, speed));
                }
            }
        }
    }
    let results = run_trials(&specs, progress);
    // Per row: the pooled path errors and per trial (|Δu|, saturated, tilt).
    type Pooled = (VisionRateRow, Vec<f64>, Vec<(f64, f64, f64)>);
    let mut rows: Vec<Pooled> = Vec::new();
    for ((key, rate, speed), r) in keys.into_iter().zip(results) {
        let r = r?;
        let idx = match rows
            .iter()
            .position(|(row, ..)| row.controller == key && row.rate == rate && row.speed == speed)
        {
            Some(i) => i,
            None => {
                rows.push((
                    VisionRateRow {
                        controller: key.to_string(),
                        rate,
                        speed,
                        trials: 0,
                        path_error: None,
                        smoothness_deg: f64::NAN,
                        saturation_share: f64::NAN,
                        max_tilt_deg: 0.0,
                        diverged: 0,
                        not_arrived: 0,
                        controller_errors: 0,
                    },
                    Vec::new(),
                    Vec::new(),
                ));
                rows.len() - 1
            }
        };
        let (row, errors, per_trial) = &mut rows[idx];
        row.trials += 1;
        errors.extend(finite_path_errors(&r));
        let m = &r.metrics;
        per_trial.push((m.smoothness_deg, m.saturation_share, m.max_tilt_deg));
        row.diverged += usize::from(m.diverged);
        row.not_arrived += usize::from(r.stop_reason != StopReason::PathEnd);
        row.controller_errors += m.controller_errors;
    }
    let rows: Vec<VisionRateRow> = rows
        .into_iter()
        .map(|(mut row, errors, per_trial)| {
            row.path_error = ErrorStats::from_values(errors);
            row.smoothness_deg = mean(per_trial.iter().map(|p| p.0));
            row.saturation_share = mean(per_trial.iter().map(|p| p.1));
            row.max_tilt_deg = per_trial.iter().map(|p| p.2).fold(0.0, f64::max);
            row
        })
        .collect();

    let mut result = VisionRateResult {
        experiment: "vision-rate".to_string(),
        config: config.clone(),
        rows,
        budgets: Vec::new(),
    };
    for &speed in &config.speeds {
        let (Some(smooth), Some(paper)) = (
            result.row("df-mr-smooth", BUDGET_RATE, speed),
            result.row("df-paper", BUDGET_RATE, speed),
        ) else {
            continue;
        };
        let p95 = smooth.path_error.map_or(f64::NAN, |e| e.p95);
        let paper_p95 = paper.path_error.map_or(f64::NAN, |e| e.p95);
        let check = BudgetCheck {
            speed,
            smoothness_deg: smooth.smoothness_deg,
            saturation_share: smooth.saturation_share,
            p95,
            paper_p95,
            met: smooth.smoothness_deg <= 5.0
                && smooth.saturation_share <= 0.10
                && p95 <= 1.1 * paper_p95,
        };
        result.budgets.push(check);
    }
    Ok(result)
}

/// Writes the JSON and the plots: per rate, `<prefix>_p95_<r>hz`,
/// `<prefix>_smoothness_<r>hz` (log scale) and `<prefix>_saturation_<r>hz`
/// (metric vs desired speed, one line per controller). Returns the files
/// written.
pub fn write_vision_rate(
    result: &VisionRateResult,
    out: &OutputPaths,
) -> Result<Vec<PathBuf>, ExperimentError> {
    write_json(&out.json, result)?;
    let mut files = vec![out.json.clone()];
    type Metric = fn(&VisionRateRow) -> f64;
    let metrics: [(&str, &str, Metric); 3] = [
        ("p95", "p95 path error [m]", |r| {
            r.path_error.map_or(f64::NAN, |e| e.p95)
        }),
        ("smoothness", "mean |Δu| per tick [deg]", |r| {
            r.smoothness_deg
        }),
        ("saturation", "ticks at saturation [%]", |r| {
            100.0 * r.saturation_share
        }),
    ];
    for &rate in &result.config.rates {
        for (name, label, f) in metrics {
            let mut lp = LinePlot::new(
                format!("L path, vision at {rate} Hz (60 ms, 2 cm): {label}"),
                "desired speed [m/s]",
                label,
            );
            lp.size = (900, 600);
            // |Δu| and p95 span two decades between the controllers.
            lp.log_y = name != "saturation";
            for (k, c) in result.config.controllers.iter().enumerate() {
                let points: Vec<(f64, f64)> = result
                    .config
                    .speeds
                    .iter()
                    .filter_map(|&v| result.row(c.key(), rate, v).map(|r| (v, f(r))))
                    .filter(|p| p.1.is_finite())
                    .collect();
                let mut s = Series::new(c.label(), c.color(k), points);
                s.markers = true;
                lp.series.push(s);
            }
            let stem = out.plot(&format!("{name}_{rate}hz"));
            files.extend(write_line_plot(&stem, &lp)?);
        }
    }
    Ok(files)
}
