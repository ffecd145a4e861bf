//! The paper's studies, reproduced in the lab: pure functions that fly the
//! trials and return result structs, and writers for their JSON and plots.
//!
//! * [`noise_sweep`] — §VI, Fig. "simcom_noise": 1-D step to 10 m with
//!   Gaussian x-noise, DF-MPC vs Flatness MPC (and PD), mean output error
//!   per noise level σ.
//! * [`paths`] — §VII-C, Figs. "boxplot_control_compare" and
//!   "control_compare": the L path at 3–9 m/s under vision-like sensing
//!   (15 Hz, 60 ms latency, 2 cm noise, constant-velocity extrapolation),
//!   DF-MPC vs Flatness MPC vs PD, after a small documented weight search;
//!   plus the DSL demonstration (§VII-D, Fig. "dsl_visual").
//!
//! Every trial is reproducible from its seed (see each study's seed rule),
//! all controllers of a study see the same noise for the same seed, trials
//! run in parallel with rayon through [`crate::harness::run_trials`], and the
//! results (hence the JSON) are bit-identical whatever the thread count. No
//! wall-clock value enters a result.
//!
//! The `dflat experiment` subcommands only parse arguments and call
//! [`noise_sweep::run_noise_sweep`] / [`noise_sweep::write_noise_sweep`] and
//! [`paths::run_paths`] / [`paths::write_paths`].

pub mod airframe;
mod controllers;
mod fair;
mod figures;
pub mod learned;
pub mod mismatch;
pub mod noise_sweep;
pub mod paths;
pub mod phase;
pub mod preview;
pub mod tilt_cone;
mod trial;
pub mod vision_rate;

pub use controllers::ControllerSpec;
pub use trial::TrialSetup;

use std::path::{Path, PathBuf};

use dflat_control::ControlError;
use serde::Serialize;
use thiserror::Error;

use dflat_sim::SimError;

/// Why an experiment could not run or write its outputs. What happens
/// inside a trial (controller errors, divergence) is a result, not an error.
#[derive(Debug, Error)]
pub enum ExperimentError {
    /// A lab set-up was invalid, or a plot could not be written.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A controller could not be built from its settings.
    #[error("controller {controller}: {source}")]
    Controller {
        /// The controller's name.
        controller: &'static str,
        /// Why it could not be built.
        source: ControlError,
    },
    /// A reference path could not be built.
    #[error("reference: {0}")]
    Reference(ControlError),
    /// An experiment option is out of range.
    #[error("invalid experiment option {field}: {reason}")]
    Invalid {
        /// The option's name.
        field: &'static str,
        /// What is allowed.
        reason: String,
    },
    /// Serialising the results failed.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// Writing a file failed.
    #[error("writing {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

pub(crate) fn invalid(field: &'static str, reason: impl Into<String>) -> ExperimentError {
    ExperimentError::Invalid {
        field,
        reason: reason.into(),
    }
}

/// Where an experiment writes its outputs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputPaths {
    /// The JSON results file.
    pub json: PathBuf,
    /// The plot stem prefix: plots are `<prefix>_<name>.svg/.png` (the main
    /// plot of the noise sweep is `<prefix>.svg/.png`).
    pub plot_prefix: PathBuf,
}

impl OutputPaths {
    /// `<dir>/<stem>.json` and plots under `<dir>/<stem>`, unless `json` or
    /// `plot_prefix` override them.
    pub fn resolve(
        dir: &Path,
        stem: &str,
        json: Option<PathBuf>,
        plot_prefix: Option<PathBuf>,
    ) -> Self {
        Self {
            json: json.unwrap_or_else(|| dir.join(format!("{stem}.json"))),
            plot_prefix: plot_prefix.unwrap_or_else(|| dir.join(stem)),
        }
    }

    /// The stem `<prefix>_<name>` for one plot.
    pub fn plot(&self, name: &str) -> PathBuf {
        let mut s = self.plot_prefix.clone().into_os_string();
        if !name.is_empty() {
            s.push("_");
            s.push(name);
        }
        PathBuf::from(s)
    }
}

/// Serialises `value` as pretty JSON (with a trailing newline) into `path`,
/// creating the parent directory.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), ExperimentError> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    let io = |source| ExperimentError::Io {
        path: path.display().to_string(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    std::fs::write(path, text).map_err(io)
}

/// Mean of the finite values (NaN when there are none).
pub(crate) fn mean(values: impl IntoIterator<Item = f64>) -> f64 {
    let (s, n) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// Sample standard deviation of the finite values (NaN with fewer than two).
pub(crate) fn std_dev(values: impl IntoIterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.into_iter().filter(|v| v.is_finite()).collect();
    if v.len() < 2 {
        return f64::NAN;
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// The `p`-th percentile (0–100, nearest rank) of the finite values in `v`;
/// NaN when there are none.
pub(crate) fn percentile(mut v: Vec<f64>, p: f64) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((p / 100.0) * (v.len() - 1) as f64).round() as usize]
}
