//! Pose-to-tick phase study (issue 15, item 4): what locking the control
//! ticks to the pose stream buys, against an arbitrary phase.
//!
//! Set-up (as [`super::vision_rate`] unless stated):
//!
//! * The L path ([`paths::l`](dflat_control::reference::paths::l) at z = −10 m) at 5 and 9 m/s, start at rest
//!   at the path start, end 2 s after first coming within 1 m of the path
//!   end (or length/speed + 20 s; diverged beyond 15 m of path error).
//! * Planar plant, RK4 at 200 Hz, τ = 0.2 s, k̃ = 1, ±35° attitude
//!   saturation; 50 Hz control.
//! * Poses at 50 Hz ([`VisionOptions`]), an EKF-grade stream (the
//!   autopilot's LOCAL_POSITION_NED rather than raw vision): 20 ms
//!   capture-to-arrival latency, σ = 2 mm per axis, no capture jitter, no
//!   dropouts (`--latency`, `--sigma` change both). The sample grid is
//!   shifted so that every pose arrives a fixed offset
//!   ([`VisionOptions::arrival_lead`]) before the control tick that first
//!   uses it: 0 (ticks locked to the stream), 5, 10 and 19 ms.
//! * Windows ([`PhaseConfig::default`]):
//!   - `classic` — the paper's DF-MPC (`df-paper` of the vision-rate study:
//!     N = 100, q = 1, r = 0.0003, 35° command clip) on the per-tick stream,
//!     the newest pose extrapolated with constant velocity to the tick
//!     time: the offset adds to the delay it extrapolates across;
//!   - `classic-hold` — the same, the newest pose held and stamped with the
//!     tick time (the daemon's classic mode with a 50 Hz stream): the
//!     offset is a delay it does not know about;
//!   - `multi-rate` — the shipped tuning (`df-mr-smooth`: r = 0.003,
//!     s = 50 [1/rad²], 30° plan-tilt bound) on multi-rate windows
//!     ([`MultiRateWindow`](dflat_control::window::MultiRateWindow)) fed
//!     the poses at their capture times: the offset is known and
//!     predicted across.
//!
//!   The shipped tuning on the classic window is not a useful row: with a
//!   50 Hz stream it chatters at full tilt (mean |Δu| 53–73°/tick, 78–99 %
//!   saturated, 1 trial per cell during set-up) whatever the offset; the
//!   smoothness weight and plan bound were tuned for multi-rate windows.
//! * Seeds: trial t at speed index j has seed `seed_base + 1000·j + t`,
//!   shared by every offset and window (same noise).
//!
//! Metrics per (window, offset, speed): the path error of the TRUE
//! position to the L polyline per 50 Hz tick, pooled over the trials
//! (median, p95), the mean |Δu| per tick and the saturated share.

use std::path::PathBuf;

use dflat_control::window::MultiRateSettings;
use serde::{Deserialize, Serialize};

use super::trial::TrialSetup;
use super::vision_rate::{VisionController, finite_path_errors};
use super::{ExperimentError, invalid, mean, write_json};
use crate::harness::{ErrorStats, StopReason, TrialSpec, run_trials};
use dflat_sim::sensing::{SensorSpec, VisionMode, VisionOptions};

/// One window of the study: a name and the DF-MPC it flies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseWindow {
    /// The short name used in the JSON and the table (`classic`, `multi-rate`).
    pub name: String,
    /// The controller.
    pub controller: VisionController,
    /// How the pose stream is turned into the per-tick measurement
    /// ([`VisionMode::Raw`] for the multi-rate window).
    pub mode: VisionMode,
}

/// Configuration of the study. [`Default`] is the full study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseConfig {
    /// Desired speeds [m/s].
    pub speeds: Vec<f64>,
    /// Pose arrival before the tick that uses it \[ms\].
    pub offsets_ms: Vec<f64>,
    /// Trials per (window, offset, speed).
    pub trials: usize,
    /// Pose rate \[Hz\] (the control rate is 50 Hz).
    pub rate_hz: f64,
    /// Capture-to-arrival latency \[s\].
    pub latency: f64,
    /// Pose noise per axis \[m\].
    pub sigma: f64,
    /// The L path, when a trial ends, the divergence bound and the plant's
    /// saturation (the path studies' shared set-up; flat in the JSON).
    #[serde(flatten)]
    pub setup: TrialSetup,
    /// Base of the seed rule.
    pub seed_base: u64,
    /// The windows, in table order.
    pub windows: Vec<PhaseWindow>,
}

impl Default for PhaseConfig {
    /// 5 and 9 m/s; 0, 5, 10, 19 ms; 10 trials; 50 Hz poses, 20 ms, 2 mm;
    /// the paper's DF-MPC on the classic window (extrapolated and held)
    /// and the shipped tuning on the multi-rate window (module docs).
    fn default() -> Self {
        let tilt = 35.0;
        let paper = VisionController::DfMpc {
            horizon: 100,
            q: 1.0,
            r: 0.0003,
            smoothness: 0.0,
            multi_rate: None,
            plan_tilt_deg: None,
            max_tilt_deg: tilt,
        };
        let shipped = VisionController::DfMpc {
            horizon: 100,
            q: 1.0,
            r: 0.003,
            smoothness: 50.0,
            multi_rate: Some(MultiRateSettings::default()),
            plan_tilt_deg: Some(30.0),
            max_tilt_deg: tilt,
        };
        Self {
            speeds: vec![5.0, 9.0],
            offsets_ms: vec![0.0, 5.0, 10.0, 19.0],
            trials: 10,
            rate_hz: 50.0,
            latency: 0.02,
            sigma: 0.002,
            setup: TrialSetup {
                tilt_limit_deg: tilt,
                ..TrialSetup::default()
            },
            seed_base: 0,
            windows: vec![
                PhaseWindow {
                    name: "classic".to_string(),
                    controller: paper,
                    mode: VisionMode::Extrapolate,
                },
                PhaseWindow {
                    name: "classic-hold".to_string(),
                    controller: paper,
                    mode: VisionMode::Hold,
                },
                PhaseWindow {
                    name: "multi-rate".to_string(),
                    controller: shipped,
                    mode: VisionMode::Raw,
                },
            ],
        }
    }
}

impl PhaseConfig {
    /// Checks the options (the lab and the controllers check their own).
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let positive = |s: &[f64]| !s.is_empty() && s.iter().all(|v| v.is_finite() && *v > 0.0);
        if !positive(&self.speeds) {
            return Err(invalid("speeds", "at least one, each finite and > 0 m/s"));
        }
        if self.offsets_ms.is_empty() {
            return Err(invalid("offsets_ms", "at least one"));
        }
        if !(1..=1000).contains(&self.trials) {
            return Err(invalid("trials", "1 ..= 1000"));
        }
        if self.windows.is_empty() {
            return Err(invalid("windows", "at least one"));
        }
        self.setup.validate()?;
        for &o in &self.offsets_ms {
            self.vision(o, VisionMode::Raw).validate()?;
        }
        Ok(())
    }

    /// The seed of trial `trial` at speed index `speed`.
    pub fn seed(&self, speed: usize, trial: usize) -> u64 {
        self.seed_base + 1000 * speed as u64 + trial as u64
    }

    /// The pose stream at `offset_ms` in `mode`.
    pub fn vision(&self, offset_ms: f64, mode: VisionMode) -> VisionOptions {
        VisionOptions {
            rate_hz: self.rate_hz,
            latency: self.latency,
            sigma: self.sigma,
            timing_jitter: 0.0,
            arrival_lead: offset_ms * 1e-3,
            mode,
            ..VisionOptions::default()
        }
    }

    fn trial(
        &self,
        window: &PhaseWindow,
        offset_ms: f64,
        speed: f64,
    ) -> Result<TrialSpec, ExperimentError> {
        self.setup.l_trial(
            format!("{} L {speed} m/s {offset_ms} ms", window.name),
            window.controller.factory()?,
            SensorSpec::Vision(self.vision(offset_ms, window.mode)),
            speed,
        )
    }
}

/// One (window, offset, speed) aggregated over its trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseRow {
    /// The window's name.
    pub window: String,
    /// Pose arrival before the tick \[ms\].
    pub offset_ms: f64,
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
    /// Trials that diverged.
    pub diverged: usize,
    /// Trials that never reached the path end in time.
    pub not_arrived: usize,
    /// Controller errors summed over the trials.
    pub controller_errors: usize,
}

/// Everything the study produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseResult {
    /// "phase".
    pub experiment: String,
    /// The configuration flown.
    pub config: PhaseConfig,
    /// One row per (window, offset, speed), in config order.
    pub rows: Vec<PhaseRow>,
}

impl PhaseResult {
    /// The row of `window` at `offset_ms` and `speed`.
    pub fn row(&self, window: &str, offset_ms: f64, speed: f64) -> Option<&PhaseRow> {
        self.rows
            .iter()
            .find(|r| r.window == window && r.offset_ms == offset_ms && r.speed == speed)
    }

    /// The results as a markdown table (offset × window × speed).
    pub fn table(&self) -> String {
        let c = &self.config;
        let mut s = format!(
            "\n**Pose-to-tick phase** ({} Hz poses, {} ms latency, σ {} mm; 50 Hz control; {} trials per cell)\n\n",
            c.rate_hz,
            1e3 * c.latency,
            1e3 * c.sigma,
            c.trials
        );
        s += "| speed [m/s] | offset [ms] | window | median [m] | p95 [m] | mean \\|Δu\\| [°/tick] | saturated [%] | diverged |\n";
        s += "|---:|---:|:---|---:|---:|---:|---:|---:|\n";
        for &speed in &c.speeds {
            for &offset in &c.offsets_ms {
                for w in &c.windows {
                    let Some(r) = self.row(&w.name, offset, speed) else {
                        continue;
                    };
                    let (med, p95) = r
                        .path_error
                        .map_or((f64::NAN, f64::NAN), |e| (e.median, e.p95));
                    s += &format!(
                        "| {speed} | {offset} | {} | {med:.3} | {p95:.3} | {:.2} | {:.1} | {}/{} |\n",
                        r.window,
                        r.smoothness_deg,
                        100.0 * r.saturation_share,
                        r.diverged,
                        r.trials
                    );
                }
            }
        }
        s
    }
}

/// Flies the study: every (window, offset, speed, trial) in parallel.
pub fn run_phase(config: &PhaseConfig, progress: bool) -> Result<PhaseResult, ExperimentError> {
    config.validate()?;
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for (wi, w) in config.windows.iter().enumerate() {
        for (oi, &offset) in config.offsets_ms.iter().enumerate() {
            for (j, &speed) in config.speeds.iter().enumerate() {
                let t = config.trial(w, offset, speed)?;
                for k in 0..config.trials {
                    specs.push((t.clone(), config.seed(j, k)));
                    keys.push((wi, oi, j));
                }
            }
        }
    }
    let results = run_trials(&specs, progress);
    let mut rows: Vec<PhaseRow> = Vec::new();
    // Per row: the pooled path errors and per trial (|Δu|, saturated).
    type Pooled = (Vec<f64>, Vec<(f64, f64)>);
    let mut pooled: Vec<Pooled> = Vec::new();
    let mut index = std::collections::HashMap::new();
    for ((wi, oi, j), r) in keys.into_iter().zip(results) {
        let r = r?;
        let idx = *index.entry((wi, oi, j)).or_insert_with(|| {
            rows.push(PhaseRow {
                window: config.windows[wi].name.clone(),
                offset_ms: config.offsets_ms[oi],
                speed: config.speeds[j],
                trials: 0,
                path_error: None,
                smoothness_deg: f64::NAN,
                saturation_share: f64::NAN,
                diverged: 0,
                not_arrived: 0,
                controller_errors: 0,
            });
            pooled.push((Vec::new(), Vec::new()));
            rows.len() - 1
        });
        let row = &mut rows[idx];
        let (errors, per_trial) = &mut pooled[idx];
        row.trials += 1;
        errors.extend(finite_path_errors(&r));
        let m = &r.metrics;
        per_trial.push((m.smoothness_deg, m.saturation_share));
        row.diverged += usize::from(m.diverged);
        row.not_arrived += usize::from(r.stop_reason != StopReason::PathEnd);
        row.controller_errors += m.controller_errors;
    }
    for (row, (errors, per_trial)) in rows.iter_mut().zip(pooled) {
        row.path_error = ErrorStats::from_values(errors);
        row.smoothness_deg = mean(per_trial.iter().map(|p| p.0));
        row.saturation_share = mean(per_trial.iter().map(|p| p.1));
    }
    Ok(PhaseResult {
        experiment: "phase".to_string(),
        config: config.clone(),
        rows,
    })
}

/// Writes the JSON to `json`. Returns the files written.
pub fn write_phase(
    result: &PhaseResult,
    json: &std::path::Path,
) -> Result<Vec<PathBuf>, ExperimentError> {
    write_json(json, result)?;
    Ok(vec![json.to_path_buf()])
}
