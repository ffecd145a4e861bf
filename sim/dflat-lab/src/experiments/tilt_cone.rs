//! The tilt cone in the plan against the box: DF-MPC with a
//! planned tilt bound applied as the cone `‖(ẍ, ÿ)‖ ≤ g·tan(bound)` or per
//! axis, on the L path and the three DSL letters at 7–9 m/s, under the
//! paths study's vision-like sensing. Three bounds per cell: the box and
//! the cone at [`TiltConeConfig::plan_tilt_deg`], and the cone at the
//! command limit [`TiltConeConfig::command_tilt_deg`] (the box's combined
//! tilt reaches it: the like-for-like comparison).
//!
//! Controller: DF-MPC as the daemon ships it (`df-mr-smooth`: N = 100,
//! q = 1, r = 0.003, smoothness 50 on x and y, multi-rate window M = 25,
//! σ = 2 cm), the command limited as the daemon does (35° on the
//! combined tilt, [`TiltLimit::Cone`]). Per (path, speed, bound):
//! the planned tilt (the first free planned acceleration `Δ²y_{k+1}/δt²` as
//! a tilt, max and p95 over ticks), the flown tilt (plant trace), the path
//! error (pooled ticks: mean, p95, max), the command's smoothness (RMS of
//! its attitude rate), the share of ticks whose command was saturated and
//! the share that solved a constrained QP. Seeds: trial
//! k of path p at speed i uses `seed_base + 1000·p + 100·i + k`, the same
//! for both bounds (same noise).

use std::sync::Arc;

use dflat_control::dfmpc::{
    DfMpc, DfMpcSettings, InputSaturation, OutputConstraints, PlanTiltBound, QpSolver,
};
use dflat_control::reference::paths;
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, TiltLimit};
use dflat_model::{PlanarModel, PlanarParams};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::paths::PathsConfig;
use super::{ExperimentError, percentile, write_json};
use crate::harness::{ControllerFactory, TrialResult, TrialSpec, run_trials};

/// Options of the study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TiltConeConfig {
    /// Path speeds [m/s].
    pub speeds: Vec<f64>,
    /// Trials (noise seeds) per path, speed and bound.
    pub trials: usize,
    /// The plan's tilt bound \[deg\].
    pub plan_tilt_deg: f64,
    /// The command's tilt limit \[deg\] (combined tilt, as the daemon).
    pub command_tilt_deg: f64,
    /// First seed.
    pub seed_base: u64,
    /// The constrained solver (box and cone): the banded solvers, or
    /// clarabel alone — the same problems, to tell the problem's behaviour
    /// from the solver's.
    pub qp_solver: QpSolver,
}

impl Default for TiltConeConfig {
    fn default() -> Self {
        Self {
            speeds: vec![7.0, 8.0, 9.0],
            trials: 3,
            plan_tilt_deg: 30.0,
            command_tilt_deg: 35.0,
            seed_base: 0,
            qp_solver: QpSolver::Banded,
        }
    }
}

/// One (path, speed, bound) cell, pooled over its trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TiltConeRow {
    /// "L", "DSL D", "DSL S" or "DSL L".
    pub path: String,
    /// Path speed [m/s].
    pub speed: f64,
    /// The plan's tilt bound: "box 30°", "cone 30°" (the plan bound) or
    /// "cone 35°" (the cone at the command limit).
    pub bound: String,
    /// Largest / p95 planned tilt \[deg\].
    pub planned_tilt_max_deg: f64,
    /// p95 planned tilt \[deg\].
    pub planned_tilt_p95_deg: f64,
    /// Largest / p95 flown tilt \[deg\].
    pub flown_tilt_max_deg: f64,
    /// p95 flown tilt \[deg\].
    pub flown_tilt_p95_deg: f64,
    /// Path error: mean, p95, max \[m\].
    pub path_error_mean: f64,
    /// p95 path error \[m\].
    pub path_error_p95: f64,
    /// Largest path error \[m\].
    pub path_error_max: f64,
    /// RMS of the commanded attitude's rate `‖Δ(pitch, roll)‖/δt` over
    /// ticks \[deg/s\]: the command's smoothness.
    pub command_rate_rms_dps: f64,
    /// p95 of the commanded attitude's rate \[deg/s\].
    pub command_rate_p95_dps: f64,
    /// Largest commanded attitude rate \[deg/s\].
    pub command_rate_max_dps: f64,
    /// Share of ticks with a saturated command.
    pub saturated_share: f64,
    /// Share of ticks that solved a constrained QP.
    pub constrained_share: f64,
    /// Controller errors over the trials.
    pub controller_errors: usize,
}

/// The study's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TiltConeResult {
    /// The options.
    pub config: TiltConeConfig,
    /// One row per (path, speed, bound).
    pub rows: Vec<TiltConeRow>,
}

impl TiltConeResult {
    /// The rows as a markdown table.
    pub fn table(&self) -> String {
        let mut s = String::from(
            "| path | m/s | plan bound | planned tilt max / p95 (deg) | flown tilt max / p95 (deg) | path error mean / p95 / max (m) | command rate RMS / p95 / max (deg/s) | saturated | constrained |\n|---|---|---|---|---|---|---|---|---|\n",
        );
        for r in &self.rows {
            s.push_str(&format!(
                "| {} | {} | {} | {:.1} / {:.1} | {:.1} / {:.1} | {:.3} / {:.3} / {:.3} | {:.1} / {:.0} / {:.0} | {:.1} % | {:.1} % |\n",
                r.path,
                r.speed,
                r.bound,
                r.planned_tilt_max_deg,
                r.planned_tilt_p95_deg,
                r.flown_tilt_max_deg,
                r.flown_tilt_p95_deg,
                r.path_error_mean,
                r.path_error_p95,
                r.path_error_max,
                r.command_rate_rms_dps,
                r.command_rate_p95_dps,
                r.command_rate_max_dps,
                100.0 * r.saturated_share,
                100.0 * r.constrained_share,
            ));
        }
        s
    }
}

fn factory(
    config: &TiltConeConfig,
    bound: PlanTiltBound,
    plan_tilt_deg: f64,
) -> Result<ControllerFactory, ExperimentError> {
    let settings = DfMpcSettings {
        horizon: 100,
        tracking_weight: [1.0; 3],
        jerk_weight: [0.003; 3],
        smoothness_weight: [50.0, 50.0, 0.0],
        multi_rate: Some(MultiRateSettings {
            fit_span: 25,
            sample_sigma: 0.02,
            ..MultiRateSettings::default()
        }),
        saturation: Some(InputSaturation {
            max_tilt: config.command_tilt_deg.to_radians(),
            tilt_limit: TiltLimit::Cone,
            ..InputSaturation::default()
        }),
        constraints: OutputConstraints {
            max_tilt: Some(plan_tilt_deg.to_radians()),
            ..OutputConstraints::default()
        },
        plan_tilt_bound: bound,
        qp_solver: config.qp_solver,
        ..DfMpcSettings::default()
    };
    let model = || -> Result<ControlModel, ExperimentError> {
        let m = PlanarModel::new(PlanarParams::default())
            .map_err(|e| ExperimentError::Reference(e.into()))?;
        Ok(ControlModel::Planar(m))
    };
    let wrap = |source| ExperimentError::Controller {
        controller: "df-mpc",
        source,
    };
    DfMpc::new(model()?, settings).map_err(wrap)?;
    let m = model()?;
    Ok(Arc::new(move || {
        Box::new(DfMpc::new(m, settings).expect("checked above")) as Box<_>
    }))
}

fn trial(
    name: String,
    controller: ControllerFactory,
    waypoints: &[Vector3<f64>],
    speed: f64,
) -> Result<TrialSpec, ExperimentError> {
    let lab = PathsConfig::untuned();
    let stop = lab.path_end_stop(waypoints, speed);
    lab.path_trial(
        name,
        controller,
        lab.plant_options(),
        waypoints,
        speed,
        stop,
    )
}

fn row(path: &str, speed: f64, bound: &str, dt: f64, results: &[TrialResult]) -> TiltConeRow {
    let g = PlanarParams::default().g;
    let (mut planned, mut flown, mut errors) = (Vec::new(), Vec::new(), Vec::new());
    let (mut ticks, mut saturated, mut constrained, mut failures) = (0, 0, 0, 0);
    let mut rates = Vec::new();
    for r in results {
        failures += r.errors.len();
        for w in r.ticks.windows(2) {
            let (a, b) = (&w[0].command, &w[1].command);
            let rate = (b.pitch - a.pitch).hypot(b.roll - a.roll).to_degrees() / dt;
            if rate.is_finite() {
                rates.push(rate);
            }
        }
        for t in &r.ticks {
            let p = &t.plan;
            let a = (p[3] - 2.0 * p[2] + p[1]) / (dt * dt);
            planned.push(a.xy().norm().atan2(g).to_degrees());
            errors.push(t.path_error);
            ticks += 1;
            saturated += usize::from(t.ctrl_saturated);
            constrained += usize::from(t.constrained);
        }
        flown.extend(r.trace.iter().map(|s| s.tilt().to_degrees()));
    }
    let share = |k: usize| k as f64 / ticks.max(1) as f64;
    let finite_errors: Vec<f64> = errors.iter().copied().filter(|e| e.is_finite()).collect();
    TiltConeRow {
        path: path.to_string(),
        speed,
        bound: bound.to_string(),
        planned_tilt_max_deg: percentile(planned.clone(), 100.0),
        planned_tilt_p95_deg: percentile(planned, 95.0),
        flown_tilt_max_deg: percentile(flown.clone(), 100.0),
        flown_tilt_p95_deg: percentile(flown, 95.0),
        path_error_mean: finite_errors.iter().sum::<f64>() / finite_errors.len().max(1) as f64,
        path_error_p95: percentile(errors.clone(), 95.0),
        path_error_max: percentile(errors, 100.0),
        command_rate_rms_dps: (rates.iter().map(|r| r * r).sum::<f64>()
            / rates.len().max(1) as f64)
            .sqrt(),
        command_rate_p95_dps: percentile(rates.clone(), 95.0),
        command_rate_max_dps: percentile(rates, 100.0),
        saturated_share: share(saturated),
        constrained_share: share(constrained),
        controller_errors: failures,
    }
}

/// Flies the study (trials in parallel; results independent of the thread
/// count).
pub fn run_tilt_cone(
    config: &TiltConeConfig,
    progress: bool,
) -> Result<TiltConeResult, ExperimentError> {
    if config.speeds.is_empty() || config.speeds.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(super::invalid(
            "speeds",
            "at least one, each finite and > 0 m/s",
        ));
    }
    if !(1..=1000).contains(&config.trials) {
        return Err(super::invalid("trials", "1 ..= 1000"));
    }
    let tilts_ok = |d: f64| d > 0.0 && d < 80.0;
    if !(tilts_ok(config.plan_tilt_deg) && tilts_ok(config.command_tilt_deg)) {
        return Err(super::invalid(
            "plan_tilt_deg / command_tilt_deg",
            "(0, 80) deg",
        ));
    }
    let lab = PathsConfig::untuned();
    let path_list: [(&str, Vec<Vector3<f64>>); 4] = [
        ("L", lab.setup.l_path()),
        ("DSL D", paths::waypoints(&paths::D_XY, lab.dsl_altitude)),
        ("DSL S", paths::waypoints(&paths::S_XY, lab.dsl_altitude)),
        (
            "DSL L",
            paths::waypoints(&paths::DSL_L_XY, lab.dsl_altitude),
        ),
    ];
    // The box and the cone at the plan bound, and the cone at the command
    // limit: the like-for-like comparison with the box, whose combined
    // tilt the command limit alone caps.
    let (plan, command) = (config.plan_tilt_deg, config.command_tilt_deg);
    let bounds = [
        (format!("box {plan:.0}°"), PlanTiltBound::Box, plan),
        (format!("cone {plan:.0}°"), PlanTiltBound::Cone, plan),
        (format!("cone {command:.0}°"), PlanTiltBound::Cone, command),
    ];
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for (pi, (name, w)) in path_list.iter().enumerate() {
        for (si, &speed) in config.speeds.iter().enumerate() {
            for (bname, bound, tilt) in &bounds {
                let f = factory(config, *bound, *tilt)?;
                let t = trial(format!("{bname} {name} {speed} m/s"), f, w, speed)?;
                for k in 0..config.trials {
                    let seed = config.seed_base + 1000 * pi as u64 + 100 * si as u64 + k as u64;
                    specs.push((t.clone(), seed));
                }
                keys.push((*name, speed, bname.as_str()));
            }
        }
    }
    let results = run_trials(&specs, progress);
    let mut results = results.into_iter();
    let mut rows = Vec::new();
    for (name, speed, bname) in keys {
        let mut cell = Vec::new();
        for _ in 0..config.trials {
            let r = results
                .next()
                .ok_or_else(|| super::invalid("trials", "missing trial result"))??;
            cell.push(r);
        }
        rows.push(row(name, speed, bname, 0.02, &cell));
    }
    Ok(TiltConeResult {
        config: config.clone(),
        rows,
    })
}

/// Writes the result as JSON to `path`.
pub fn write_tilt_cone(
    result: &TiltConeResult,
    path: &std::path::Path,
) -> Result<(), ExperimentError> {
    write_json(path, result)
}
