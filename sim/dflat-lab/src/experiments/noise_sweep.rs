//! The paper's §VI simulation, Fig. "simcom_noise": robustness to output
//! noise of DF-MPC vs Flatness MPC (and PD).
//!
//! Set-up (paper §VI, `reference/README.md`):
//!
//! * 1-D motion in x (north) on the planar plant (NED, ψ = 0), RK4 at
//!   200 Hz, τ = 0.2 s, k̃ = 1; start at rest at the origin; fixed
//!   reference x = 10 m; 10 s; controllers at 50 Hz with zero-order hold.
//! * The plant's (and every controller's) tilt limit is raised from the
//!   lab's default 35° to **60°**: the paper's weights command up to ~40° in
//!   this step, and the paper's simulation has no saturation.
//! * Measurement: true position plus Gaussian noise of standard deviation σ
//!   on x only, at every 50 Hz tick; σ ∈ {0, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3,
//!   5e-3, 1e-2} m.
//! * Controllers: DF-MPC N = 200, q = 1, r = 0.08 (the paper's R = 1.25e9 on
//!   the raw third difference); Flatness MPC N = 200, q = 1, r = 0.1; PD
//!   kp = 2, kd = 2.5 (the lab's default gains).
//! * Seeds: trial t at noise level i has seed `seed_base + 1000·i + t`,
//!   shared by all controllers (same noise sequence).
//!
//! Metric (the paper's "average output error"): per trial, the mean of
//! |x − 10| of the TRUE x over the plant-rate trace t ∈ [0, 10 s); averaged
//! over the trials per σ. Also reported: the same mean over t ≥ 5 s (the
//! steady part), command smoothness (mean |Δθ_cmd| per tick \[deg\]), the
//! share of saturated ticks and the largest tilt.

use std::path::PathBuf;

use dflat_control::reference::Reference;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{ControllerSpec, ExperimentError, OutputPaths, invalid, mean, std_dev, write_json};
use crate::harness::{FixedTarget, Metrics, StopCondition, StopReason, TrialSpec, run_trials};
use crate::plot::{LinePlot, RGBColor, Series, controller_color, write_line_plot};
use dflat_sim::plant::{PlantOptions, PlantState};
use dflat_sim::sensing::{GaussianOptions, SensorSpec};

/// The paper's noise levels σ \[m\].
pub const PAPER_SIGMAS: [f64; 8] = [0.0, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2];

/// Configuration of the noise sweep. [`Default`] is the paper's set-up (see
/// the module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseSweepConfig {
    /// Noise standard deviations σ on x \[m\].
    pub sigmas: Vec<f64>,
    /// Trials per σ and controller.
    pub trials: usize,
    /// Simulated time per trial \[s\].
    pub duration: f64,
    /// The fixed reference x \[m\] (north; y = 0).
    pub target: f64,
    /// Start of the late window of `mean_error_after` \[s\].
    pub after: f64,
    /// Tilt limit of the plant and the controllers \[deg\].
    pub tilt_limit_deg: f64,
    /// Base of the seed rule `seed_base + 1000·σ_index + trial`.
    pub seed_base: u64,
    /// The controllers, in plotting order.
    pub controllers: Vec<ControllerSpec>,
}

impl Default for NoiseSweepConfig {
    fn default() -> Self {
        let tilt = 60.0;
        Self {
            sigmas: PAPER_SIGMAS.to_vec(),
            trials: 10,
            duration: 10.0,
            target: 10.0,
            after: 5.0,
            tilt_limit_deg: tilt,
            seed_base: 0,
            controllers: vec![
                ControllerSpec::DfMpc {
                    horizon: 200,
                    q: 1.0,
                    r: 0.08,
                    max_tilt_deg: tilt,
                },
                ControllerSpec::Fmpc {
                    horizon: 200,
                    q: 1.0,
                    r: 0.1,
                    max_tilt_deg: tilt,
                    estimator: None,
                },
                ControllerSpec::Pd {
                    kp: 2.0,
                    kd: 2.5,
                    max_tilt_deg: tilt,
                    estimator: None,
                },
            ],
        }
    }
}

impl NoiseSweepConfig {
    /// Checks the options (the lab and the controllers check their own).
    pub fn validate(&self) -> Result<(), ExperimentError> {
        if self.sigmas.is_empty() || !self.sigmas.iter().all(|s| s.is_finite() && *s >= 0.0) {
            return Err(invalid("sigmas", "at least one, each finite and >= 0 m"));
        }
        if !(1..=10_000).contains(&self.trials) {
            return Err(invalid("trials", "1 ..= 10000"));
        }
        if !(self.duration.is_finite() && self.duration > 0.0 && self.duration <= 3600.0) {
            return Err(invalid("duration", "(0, 3600] s"));
        }
        if !self.target.is_finite() || !self.after.is_finite() {
            return Err(invalid("target/after", "finite"));
        }
        if !(self.tilt_limit_deg > 0.0 && self.tilt_limit_deg <= 80.0) {
            return Err(invalid("tilt_limit_deg", "(0, 80] deg"));
        }
        if self.controllers.is_empty() {
            return Err(invalid("controllers", "at least one"));
        }
        Ok(())
    }

    /// The seed of trial `trial` at noise level `sigma_index`.
    pub fn seed(&self, sigma_index: usize, trial: usize) -> u64 {
        self.seed_base + 1000 * sigma_index as u64 + trial as u64
    }

    /// The plant options: lab defaults (RK4 200 Hz, τ = 0.2 s, k̃ = 1) with
    /// the tilt limit raised to `tilt_limit_deg`.
    pub fn plant_options(&self) -> PlantOptions {
        PlantOptions {
            tilt_limit: self.tilt_limit_deg.to_radians(),
            ..PlantOptions::default()
        }
    }
}

/// One trial's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseTrial {
    /// The controller's name.
    pub controller: String,
    /// Index of σ in the configuration.
    pub sigma_index: usize,
    /// Noise standard deviation \[m\].
    pub sigma: f64,
    /// Trial number within (σ, controller).
    pub trial: usize,
    /// The seed.
    pub seed: u64,
    /// Why the trial ended.
    pub stop_reason: StopReason,
    /// The harness's metrics (mae = mean |x − target| \[m\]).
    pub metrics: Metrics,
}

/// Aggregate over the trials of one (σ, controller).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseSummary {
    /// The controller's name.
    pub controller: String,
    /// Noise standard deviation \[m\].
    pub sigma: f64,
    /// Trials aggregated.
    pub trials: usize,
    /// Mean over trials of the mean output error \[m\] (the paper's metric).
    pub mean_error: f64,
    /// Standard deviation over trials of the mean output error \[m\].
    pub std_error: f64,
    /// Smallest and largest trial mean output error \[m\].
    pub min_error: f64,
    /// Largest trial mean output error \[m\].
    pub max_error: f64,
    /// Mean over trials of the mean output error after `after` \[m\].
    pub mean_error_after: f64,
    /// Mean over trials of the mean |Δu| per tick \[deg\].
    pub smoothness_deg: f64,
    /// Mean over trials of the share of saturated ticks [0, 1].
    pub saturation_share: f64,
    /// Largest tilt over all trials \[deg\].
    pub max_tilt_deg: f64,
    /// Trials that diverged (error beyond 50 m).
    pub diverged: usize,
    /// Controller errors summed over the trials.
    pub controller_errors: usize,
}

/// Everything the noise sweep produced (serialised as its JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseSweepResult {
    /// "noise-sweep".
    pub experiment: String,
    /// The configuration flown.
    pub config: NoiseSweepConfig,
    /// The plant options flown.
    pub plant: PlantOptions,
    /// One row per (controller, σ), controllers in configuration order.
    pub summary: Vec<NoiseSummary>,
    /// Every trial, ordered by controller, σ, trial.
    pub trials: Vec<NoiseTrial>,
}

impl NoiseSweepResult {
    /// The summary row of `controller` at `sigma_index`.
    pub fn row(&self, controller: &str, sigma_index: usize) -> Option<&NoiseSummary> {
        let sigma = *self.config.sigmas.get(sigma_index)?;
        self.summary
            .iter()
            .find(|r| r.controller == controller && r.sigma == sigma)
    }

    /// A plain-text table: σ → mean output error per controller.
    pub fn table(&self) -> String {
        let mut s = format!("{:>9}", "sigma [m]");
        for c in &self.config.controllers {
            s += &format!(" | {:>26}", format!("{} err/late/|du| [m,m,deg]", c.name()));
        }
        s.push('\n');
        for (i, sigma) in self.config.sigmas.iter().enumerate() {
            s += &format!("{sigma:>9.0e}");
            for c in &self.config.controllers {
                match self.row(c.name(), i) {
                    Some(r) => {
                        s += &format!(
                            " | {:>8.4} {:>8.4} {:>7.3}",
                            r.mean_error, r.mean_error_after, r.smoothness_deg
                        )
                    }
                    None => s += &format!(" | {:>26}", "-"),
                }
            }
            s.push('\n');
        }
        s
    }
}

/// Flies the sweep: every (controller, σ, trial) in parallel, with an
/// indicatif bar when `progress`.
pub fn run_noise_sweep(
    config: &NoiseSweepConfig,
    progress: bool,
) -> Result<NoiseSweepResult, ExperimentError> {
    config.validate()?;
    let target = Vector3::new(config.target, 0.0, 0.0);
    let reference = Reference::setpoint(target).map_err(ExperimentError::Reference)?;
    let plant = config.plant_options();
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for c in &config.controllers {
        let factory = c.factory()?;
        for (i, &sigma) in config.sigmas.iter().enumerate() {
            let r = reference.clone();
            let mut spec = TrialSpec::new(
                format!("{} sigma={sigma}", c.name()),
                factory.clone(),
                std::sync::Arc::new(move || Box::new(r.clone())),
            );
            spec.plant_options = plant.clone();
            spec.initial = PlantState::hover(Vector3::zeros(), plant.g);
            spec.sensor = SensorSpec::Gaussian(GaussianOptions::x_only(sigma));
            spec.stop = StopCondition::Duration(config.duration);
            spec.target = Some(FixedTarget {
                target,
                axes: [true, false, false],
                after: config.after,
            });
            // Record divergence (> 50 m) but fly the full duration so every
            // trial's mean covers the same window.
            spec.stop_on_divergence = false;
            spec.validate()?;
            for t in 0..config.trials {
                specs.push((spec.clone(), config.seed(i, t)));
                keys.push((c.name(), i, sigma, t));
            }
        }
    }
    let results = run_trials(&specs, progress);
    let mut trials = Vec::with_capacity(results.len());
    for (r, (name, i, sigma, t)) in results.into_iter().zip(keys) {
        let r = r?;
        trials.push(NoiseTrial {
            controller: name.to_string(),
            sigma_index: i,
            sigma,
            trial: t,
            seed: r.seed,
            stop_reason: r.stop_reason,
            metrics: r.metrics,
        });
    }
    let mut summary = Vec::new();
    for c in &config.controllers {
        for &sigma in &config.sigmas {
            let rows: Vec<&NoiseTrial> = trials
                .iter()
                .filter(|t| t.controller == c.name() && t.sigma == sigma)
                .collect();
            let err = |t: &&NoiseTrial| t.metrics.mae.unwrap_or(f64::NAN);
            summary.push(NoiseSummary {
                controller: c.name().to_string(),
                sigma,
                trials: rows.len(),
                mean_error: mean(rows.iter().map(err)),
                std_error: std_dev(rows.iter().map(err)),
                min_error: rows.iter().map(err).fold(f64::INFINITY, f64::min),
                max_error: rows.iter().map(err).fold(f64::NEG_INFINITY, f64::max),
                mean_error_after: mean(
                    rows.iter().map(|t| t.metrics.mae_after.unwrap_or(f64::NAN)),
                ),
                smoothness_deg: mean(rows.iter().map(|t| t.metrics.smoothness_deg)),
                saturation_share: mean(rows.iter().map(|t| t.metrics.saturation_share)),
                max_tilt_deg: rows
                    .iter()
                    .map(|t| t.metrics.max_tilt_deg)
                    .fold(0.0, f64::max),
                diverged: rows.iter().filter(|t| t.metrics.diverged).count(),
                controller_errors: rows.iter().map(|t| t.metrics.controller_errors).sum(),
            });
        }
    }
    Ok(NoiseSweepResult {
        experiment: "noise-sweep".to_string(),
        config: config.clone(),
        plant,
        summary,
        trials,
    })
}

/// One figure of the sweep: a summary column against σ.
struct Figure {
    name: &'static str,
    title: &'static str,
    y_label: &'static str,
    value: fn(&NoiseSummary) -> f64,
    log_y: bool,
}

/// Writes the JSON and the plots: `<prefix>` (mean output error vs σ, log
/// x; the paper's figure), `<prefix>_late` (error after 5 s) and
/// `<prefix>_smoothness` (mean |Δu| per tick). σ = 0 cannot sit on a log
/// axis: it is in the JSON and the table, not in the plots. Returns the
/// files written.
pub fn write_noise_sweep(
    result: &NoiseSweepResult,
    out: &OutputPaths,
) -> Result<Vec<PathBuf>, ExperimentError> {
    write_json(&out.json, result)?;
    let mut files = vec![out.json.clone()];
    let plots = [
        Figure {
            name: "",
            title: "Output error vs. measurement noise (1-D step to 10 m, tilt limit 60°)",
            y_label: "mean output error |x − 10| [m]",
            value: |r| r.mean_error,
            log_y: false,
        },
        Figure {
            name: "late",
            title: "Output error after 5 s vs. measurement noise",
            y_label: "mean |x − 10| for t ≥ 5 s [m] (log)",
            value: |r| r.mean_error_after,
            log_y: true,
        },
        Figure {
            name: "smoothness",
            title: "Command smoothness vs. measurement noise",
            y_label: "mean |Δθ_cmd| per tick [deg] (log)",
            value: |r| r.smoothness_deg,
            log_y: true,
        },
    ];
    for Figure {
        name,
        title,
        y_label,
        value,
        log_y,
    } in plots
    {
        let mut plot = LinePlot::new(
            title,
            "output noise σ on x [m] (log; σ = 0 in the JSON)",
            y_label,
        );
        plot.log_x = true;
        plot.log_y = log_y;
        plot.size = (1000, 700);
        for (k, c) in result.config.controllers.iter().enumerate() {
            let points = result
                .summary
                .iter()
                .filter(|r| r.controller == c.name() && r.sigma > 0.0)
                .map(|r| (r.sigma, value(r)))
                .collect();
            plot.series.push(Series {
                markers: true,
                ..Series::new(c.label(), controller_color(c.name(), k), points)
            });
        }
        // Head room for the legend (upper right): an invisible point above
        // the data.
        let (x_max, y_max) = plot
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite() && p.1 > 0.0)
            .fold((f64::NAN, f64::NAN), |(x, y), p| (p.0.max(x), p.1.max(y)));
        if x_max.is_finite() && y_max.is_finite() {
            let top = if log_y { y_max * 4.0 } else { y_max * 1.3 };
            plot.series
                .push(Series::new("", RGBColor(255, 255, 255), vec![(x_max, top)]));
        }
        let [svg, png] = write_line_plot(&out.plot(name), &plot)?;
        files.push(svg);
        files.push(png);
    }
    Ok(files)
}
