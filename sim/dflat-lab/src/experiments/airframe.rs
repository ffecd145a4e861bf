//! Drag and delay in the model: what each model term buys on an
//! airframe that has them. Part of `dflat experiment mismatch`; the
//! mismatch study's own metric (the steady state of a hover step) cannot
//! see drag, which acts only in motion, so this part flies the L path.
//!
//! Set-up: the paths study's L at [`AirframeConfig::speeds`] under its
//! vision-like sensing (15 Hz, 60 ms, σ = 2 cm) on the planar plant
//! (τ = 0.2 s) with linear drag [`AirframeConfig::drag`] on the horizontal
//! axes and a pure command delay [`AirframeConfig::delay_ms`] (a whole
//! number of 20 ms ticks), flown by:
//!
//! * the product's DF-MPC (`df-mr-smooth`: N = 100, q = 1, r = 0.003,
//!   smoothness 50, multi-rate window M = 25, plan tilt ≤ 30°, combined
//!   command tilt ≤ 35°) without model terms, with the drag term, with the
//!   delay term, and with both (`vehicle.drag_h`, `vehicle.delay_ms`);
//! * the paper's DF-MPC (N = 100, q = 1, r = 0.0003 on the extrapolated
//!   stream, the paths study's weights) without and with both terms;
//! * Flatness MPC and PD fed by their state estimator (the paths study's
//!   fair weights; their models have no drag or delay term);
//!
//! and, as the anchor measured in the same run, both DF-MPC forms without
//! model terms on the same plant *without* drag and delay (the matched
//! airframe). Seeds: trial k at speed index i uses `seed_base + 100·i + k`
//! for every controller and both plants (same noise).
//!
//! Metric per cell (pooled ticks): path error of the true position (mean,
//! p95, max), mean command step ‖Δ(pitch, roll)‖ per tick, share of ticks
//! with a saturated command, trials diverged.

use std::sync::Arc;

use dflat_control::dfmpc::DfMpc;
use dflat_control::{ControlModel, TiltLimit};
use dflat_model::{PlanarModel, PlanarParams};
use serde::{Deserialize, Serialize};

use super::paths::PathsConfig;
use super::{ControllerSpec, ExperimentError, fair, invalid, percentile};
use crate::harness::{ControllerFactory, StopReason, TrialResult, TrialSpec, run_trials};
use dflat_sim::plant::PlantOptions;
use dflat_sim::sensing::VisionMode;

/// Control step of the lab \[s\].
const DT: f64 = 0.02;

/// Options of the airframe part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct AirframeConfig {
    /// Path speeds [m/s].
    pub speeds: Vec<f64>,
    /// Trials (noise seeds) per cell.
    pub trials: usize,
    /// The airframe's linear drag on the horizontal axes \[1/s\] (plant and,
    /// where modelled, `drag_h`).
    pub drag: f64,
    /// The airframe's pure command delay \[ms\], a whole number of 20 ms
    /// ticks (plant and, where modelled, `delay_ms`).
    pub delay_ms: f64,
    /// Hard cap on a trial's length \[s\] (None: the path's time plus the
    /// paths study's margin; tests shorten runs).
    pub max_duration: Option<f64>,
    /// First seed.
    pub seed_base: u64,
}

impl Default for AirframeConfig {
    fn default() -> Self {
        Self {
            speeds: vec![5.0, 7.0],
            trials: 10,
            drag: 0.3,
            delay_ms: 40.0,
            max_duration: None,
            seed_base: 0,
        }
    }
}

impl AirframeConfig {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        if self.speeds.is_empty() || self.speeds.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(invalid(
                "airframe.speeds",
                "at least one, each finite and > 0 m/s",
            ));
        }
        if !(1..=1000).contains(&self.trials) {
            return Err(invalid("airframe.trials", "1 ..= 1000"));
        }
        if !(self.drag.is_finite() && (0.0..=2.0).contains(&self.drag)) {
            return Err(invalid("airframe.drag", "0 ..= 2 1/s"));
        }
        let ticks = self.delay_ms / (1000.0 * DT);
        if !(ticks.is_finite() && (0.0..=25.0).contains(&ticks) && ticks.fract() == 0.0) {
            return Err(invalid(
                "airframe.delay_ms",
                "a whole number of 20 ms ticks, 0 ..= 500 ms",
            ));
        }
        if let Some(m) = self.max_duration
            && !(m.is_finite() && m > 0.0)
        {
            return Err(invalid("airframe.max_duration", "finite and > 0 s"));
        }
        Ok(())
    }

    fn delay_ticks(&self) -> usize {
        (self.delay_ms / (1000.0 * DT)).round() as usize
    }
}

/// Which DF-MPC form.
#[derive(Debug, Clone, Copy, PartialEq)]
enum DfForm {
    /// `df-mr-smooth`, as the daemon ships it.
    Shipped,
    /// The paper's, on the extrapolated stream.
    Paper,
}

/// What flies a cell.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Flier {
    Df {
        form: DfForm,
        drag: bool,
        delay: bool,
    },
    Baseline(ControllerSpec),
}

impl Flier {
    fn name(&self) -> String {
        match self {
            Self::Df { form, drag, delay } => {
                let base = match form {
                    DfForm::Shipped => "df-mr-smooth",
                    DfForm::Paper => "df-paper",
                };
                let terms = match (drag, delay) {
                    (false, false) => "no model terms",
                    (true, false) => "drag",
                    (false, true) => "delay",
                    (true, true) => "drag + delay",
                };
                format!("{base}, {terms}")
            }
            Self::Baseline(c) => c.name().to_string(),
        }
    }

    fn factory(&self, config: &AirframeConfig) -> Result<ControllerFactory, ExperimentError> {
        let (form, drag, delay) = match *self {
            Self::Baseline(c) => return c.factory(),
            Self::Df { form, drag, delay } => (form, drag, delay),
        };
        let params = PlanarParams {
            drag_h: if drag { config.drag } else { 0.0 },
            ..PlanarParams::default()
        };
        let wrap = |source| ExperimentError::Controller {
            controller: "df-mpc",
            source,
        };
        let model = PlanarModel::new(params).map_err(|e| wrap(e.into()))?;
        // The lab's own specs of the two forms, with the model's terms.
        let specs = match form {
            DfForm::Shipped => fair::fair_controllers(35.0),
            DfForm::Paper => PathsConfig::untuned().controllers,
        };
        let mut settings = specs
            .iter()
            .find(|c| match form {
                DfForm::Shipped => matches!(c, ControllerSpec::DfMrSmooth { .. }),
                DfForm::Paper => matches!(c, ControllerSpec::DfMpc { .. }),
            })
            .and_then(ControllerSpec::df_settings)
            .ok_or_else(|| invalid("airframe", "the lab has no such DF-MPC spec"))?;
        if form == DfForm::Shipped {
            // Limited as the daemon limits it: the combined tilt.
            if let Some(s) = &mut settings.saturation {
                s.tilt_limit = TiltLimit::Cone;
            }
        }
        settings.delay_ticks = if delay { config.delay_ticks() } else { 0 };
        DfMpc::new(ControlModel::Planar(model), settings).map_err(wrap)?;
        Ok(Arc::new(move || {
            Box::new(
                DfMpc::new(ControlModel::Planar(model), settings).expect("settings checked above"),
            ) as Box<_>
        }))
    }

    /// Multi-rate controllers take the raw samples; the others the
    /// constant-velocity extrapolated stream (the paths study's sensing).
    fn multi_rate(&self) -> bool {
        matches!(
            self,
            Self::Df {
                form: DfForm::Shipped,
                ..
            }
        )
    }
}

/// One (plant, controller, speed) cell, pooled over its trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AirframeRow {
    /// "matched" (no drag, no delay) or "airframe" (drag and delay).
    pub plant: String,
    /// The controller and its model terms, e.g. "df-mr-smooth, drag".
    pub controller: String,
    /// Path speed [m/s].
    pub speed: f64,
    /// Path error of the true position, mean \[m\].
    pub path_error_mean: f64,
    /// p95 path error \[m\].
    pub path_error_p95: f64,
    /// Largest path error \[m\].
    pub path_error_max: f64,
    /// Mean command step ‖Δ(pitch, roll)‖ per tick \[deg\].
    pub mean_step_deg: f64,
    /// Share of ticks whose command was saturated.
    pub saturated_share: f64,
    /// Trials that diverged (path error past the paths study's bound).
    pub diverged: usize,
    /// Trials flown.
    pub trials: usize,
    /// Controller errors over the trials.
    pub controller_errors: usize,
}

/// The airframe part's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AirframeResult {
    /// The options.
    pub config: AirframeConfig,
    /// One row per (speed, plant, controller).
    pub rows: Vec<AirframeRow>,
}

impl AirframeResult {
    /// The row of `controller` on `plant` at `speed`.
    pub fn row(&self, plant: &str, controller: &str, speed: f64) -> Option<&AirframeRow> {
        self.rows
            .iter()
            .find(|r| r.plant == plant && r.controller == controller && r.speed == speed)
    }

    /// The rows as a markdown table.
    pub fn table(&self) -> String {
        let c = &self.config;
        let mut s = format!(
            "**Drag and delay in the model** (L path, vision 15 Hz / 60 ms / 2 cm; airframe: \
             drag {} /s, delay {} ms; {} trials per cell)\n\n\
             | m/s | plant | controller | path error mean / p95 / max (m) | mean step (°/tick) | saturated | diverged |\n\
             |---:|:---|:---|---|---:|---:|---:|\n",
            c.drag, c.delay_ms, c.trials
        );
        for r in &self.rows {
            s.push_str(&format!(
                "| {} | {} | {} | {:.3} / {:.3} / {:.3} | {:.2} | {:.1} % | {}/{} |\n",
                r.speed,
                r.plant,
                r.controller,
                r.path_error_mean,
                r.path_error_p95,
                r.path_error_max,
                r.mean_step_deg,
                100.0 * r.saturated_share,
                r.diverged,
                r.trials,
            ));
        }
        s
    }
}

fn trial(
    config: &AirframeConfig,
    flier: &Flier,
    plant: PlantOptions,
    speed: f64,
) -> Result<TrialSpec, ExperimentError> {
    let mut lab = PathsConfig::untuned();
    lab.setup.max_duration = config.max_duration;
    if flier.multi_rate() {
        lab.vision.mode = VisionMode::Raw;
    }
    let w = lab.setup.l_path();
    let stop = lab.path_end_stop(&w, speed);
    lab.path_trial(
        format!("{} L {speed} m/s", flier.name()),
        flier.factory(config)?,
        plant,
        &w,
        speed,
        stop,
    )
}

fn row(plant: &str, controller: String, speed: f64, results: &[TrialResult]) -> AirframeRow {
    let (mut errors, mut steps) = (Vec::new(), Vec::new());
    let (mut ticks, mut saturated, mut failures, mut diverged) = (0, 0, 0, 0);
    for r in results {
        failures += r.errors.len();
        diverged += usize::from(r.stop_reason == StopReason::Diverged);
        for w in r.ticks.windows(2) {
            let (a, b) = (&w[0].command, &w[1].command);
            steps.push((b.pitch - a.pitch).hypot(b.roll - a.roll).to_degrees());
        }
        for t in &r.ticks {
            errors.push(t.path_error);
            ticks += 1;
            saturated += usize::from(t.ctrl_saturated);
        }
    }
    let finite: Vec<f64> = errors.iter().copied().filter(|e| e.is_finite()).collect();
    let steps: Vec<f64> = steps.into_iter().filter(|s| s.is_finite()).collect();
    AirframeRow {
        plant: plant.to_string(),
        controller,
        speed,
        path_error_mean: finite.iter().sum::<f64>() / finite.len().max(1) as f64,
        path_error_p95: percentile(errors.clone(), 95.0),
        path_error_max: percentile(errors, 100.0),
        mean_step_deg: steps.iter().sum::<f64>() / steps.len().max(1) as f64,
        saturated_share: saturated as f64 / ticks.max(1) as f64,
        diverged,
        trials: results.len(),
        controller_errors: failures,
    }
}

/// Flies the airframe part (trials in parallel; results independent of
/// the thread count).
pub fn run_airframe(
    config: &AirframeConfig,
    progress: bool,
) -> Result<AirframeResult, ExperimentError> {
    config.validate()?;
    let lab = PathsConfig::untuned();
    let matched = lab.plant_options();
    let airframe = PlantOptions {
        drag: config.drag,
        command_delay: config.delay_ms / 1000.0,
        ..matched.clone()
    };
    let df = |form, drag, delay| Flier::Df { form, drag, delay };
    let fair = fair::fair_controllers(35.0);
    let cells: Vec<(&str, PlantOptions, Flier)> = vec![
        (
            "matched",
            matched.clone(),
            df(DfForm::Shipped, false, false),
        ),
        ("matched", matched, df(DfForm::Paper, false, false)),
        (
            "airframe",
            airframe.clone(),
            df(DfForm::Shipped, false, false),
        ),
        (
            "airframe",
            airframe.clone(),
            df(DfForm::Shipped, true, false),
        ),
        (
            "airframe",
            airframe.clone(),
            df(DfForm::Shipped, false, true),
        ),
        (
            "airframe",
            airframe.clone(),
            df(DfForm::Shipped, true, true),
        ),
        (
            "airframe",
            airframe.clone(),
            df(DfForm::Paper, false, false),
        ),
        ("airframe", airframe.clone(), df(DfForm::Paper, true, true)),
        ("airframe", airframe.clone(), Flier::Baseline(fair[1])),
        ("airframe", airframe, Flier::Baseline(fair[2])),
    ];
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for (si, &speed) in config.speeds.iter().enumerate() {
        for (plant_name, plant, flier) in &cells {
            let t = trial(config, flier, plant.clone(), speed)?;
            for k in 0..config.trials {
                specs.push((t.clone(), config.seed_base + 100 * si as u64 + k as u64));
            }
            keys.push((*plant_name, flier.name(), speed));
        }
    }
    let mut results = run_trials(&specs, progress).into_iter();
    let mut rows = Vec::new();
    for (plant, controller, speed) in keys {
        let mut cell = Vec::with_capacity(config.trials);
        for _ in 0..config.trials {
            let r = results
                .next()
                .ok_or_else(|| invalid("airframe.trials", "missing trial result"))??;
            cell.push(r);
        }
        rows.push(row(plant, controller, speed, &cell));
    }
    Ok(AirframeResult {
        config: config.clone(),
        rows,
    })
}
