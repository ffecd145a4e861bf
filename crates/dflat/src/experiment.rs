//! `dflat experiment` — the paper's studies in the simulation lab.
//!
//! Argument parsing only: the studies live in `dflat_lab::experiments`
//! (pure runs returning results, and writers for the JSON and plots).
// The doc comments below are clap's --help text: `[m]`, `[s]`, `[link]`
// are units and TOML sections there, `<out>` a placeholder: not rustdoc
// links or HTML.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use dflat_control::dfmpc::{PlanTiltBound, QpSolver};
use dflat_lab::experiments::OutputPaths;
use dflat_lab::experiments::learned::{
    AeroPlant, LearnedConfig, LearnedShape, run_learned, write_learned,
};
use dflat_lab::experiments::mismatch::{MismatchConfig, run_mismatch, write_mismatch};
use dflat_lab::experiments::noise_sweep::{NoiseSweepConfig, run_noise_sweep, write_noise_sweep};
use dflat_lab::experiments::paths::{PathsConfig, run_paths, write_paths};
use dflat_lab::experiments::phase::{PhaseConfig, run_phase, write_phase};
use dflat_lab::experiments::preview::{PreviewConfig, run_preview, write_preview};
use dflat_lab::experiments::tilt_cone::{TiltConeConfig, run_tilt_cone, write_tilt_cone};
use dflat_lab::experiments::vision_rate::{VisionRateConfig, run_vision_rate, write_vision_rate};

/// Which study to run.
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// The paper's Fig. "simcom_noise": 1-D step to 10 m with Gaussian
    /// x-noise σ ∈ {0 … 1e-2} m; DF-MPC (N = 200, r = 0.08) vs Flatness MPC
    /// (N = 200, r = 0.1) vs PD; mean output error per σ. Plant tilt limit
    /// raised to 60°.
    NoiseSweep(NoiseSweepArgs),
    /// The paper's Figs. "boxplot_control_compare" / "control_compare": the
    /// L path at 3–9 m/s with vision-like sensing (15 Hz, 60 ms, 2 cm,
    /// extrapolated), DF-MPC (2 s) vs Flatness MPC (1.5 s) vs PD after a
    /// small weight search; plus the DSL demonstration (DF-MPC).
    Paths(PathsArgs),
    /// The L path at 3–9 m/s with vision at 10/15/30 Hz (60 ms,
    /// 2 cm): DF-MPC extrapolated (paper) vs multi-rate windows vs
    /// multi-rate + command smoothness vs Flatness MPC vs PD; path error,
    /// mean |Δu|, saturated share; budgets at 15 Hz. Markdown table on
    /// stdout, JSON + plots.
    VisionRate(VisionRateArgs),
    /// Steady-state error of a 10 m step under model mismatch
    /// (wind with drag, mass +20 %, hover thrust 0.4 vs 0.5, k̃ 0.8, τ 0.3 s;
    /// σ = 1 cm) on the spatial plant; DF-MPC with and without the
    /// disturbance estimator vs Flatness MPC vs PD; plus the noise check
    /// (noise-sweep error of DF with / without the estimator).
    Mismatch(MismatchArgs),
    /// The plan's tilt bound as the cone vs a box per axis
    /// (DF-MPC, plan 30°, command 35° on the combined tilt) on the L path
    /// and the DSL letters at 7–9 m/s, vision-like sensing: planned and
    /// flown tilt, path error, saturated share. Markdown table on stdout,
    /// JSON.
    TiltCone(TiltConeArgs),
    /// The L path at 5 and 9 m/s with 50 Hz poses (20 ms, 2 mm)
    /// arriving a fixed offset (0, 5, 10, 19 ms) before the 50 Hz tick that
    /// uses them; the paper's DF-MPC on the classic window (extrapolated,
    /// held) vs the shipped tuning on the multi-rate window: median / p95
    /// path error. Markdown table on stdout, JSON.
    Phase(PhaseArgs),
    /// A planner's trajectories (circle, figure eight, racing line,
    /// lemniscate) at 4, 6 and 8 m/s from its stream: 20 Hz p, p/v, p/v/a,
    /// 50 Hz p/v/a, and p/v/a with 1.5 s sent ahead, under 50 and 15 Hz
    /// vision poses; DF-MPC vs Flatness MPC (estimator): p95 and the
    /// largest command step. Table on stdout, JSON.
    Preview(PreviewArgs),
    /// The flat maps' residual learned from flight records and flown: the
    /// planar, spatial and rigid plants with parasitic (0.03 |v|v) and
    /// rotor drag (0.2 /s), the L, a figure eight and a racing line at 5, 7
    /// and 9 m/s under 50 and 15 Hz vision poses; the matched plant, stock,
    /// identify, learned (window 3), learned (window from data) and the
    /// plant's exact aerodynamics as the residual (what a perfect learn
    /// flies); and the seconds of records the learning needs. Tables on
    /// stdout, JSON.
    Learned(LearnedArgs),
}

/// Options of `experiment learned`.
#[derive(Debug, Args)]
pub struct LearnedArgs {
    /// Plants (planar, spatial, rigid), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "planar,spatial,rigid")]
    plants: Vec<String>,
    /// Paths and streams (l, eight, racing-line), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "l,eight,racing-line")]
    shapes: Vec<String>,
    /// Speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "5,7,9")]
    speeds: Vec<f64>,
    /// Vision pose rates [Hz], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "50,15")]
    vision: Vec<f64>,
    /// The vision poses' noise, standard deviation per axis [m] (0: exact
    /// poses, still at the rate and 60 ms latency).
    #[arg(long, default_value_t = 0.02)]
    vision_sigma: f64,
    /// Length of each stream flight (figure eight, racing line) [s], its
    /// speed ramp included (3 s up to 4 m/s, 3 s × speed/4 above; judged
    /// from 2 s after it, so at least 5 s more than that at the fastest
    /// speed): with the L's, the records one plant and pose rate learn
    /// from (60 s: about 13 minutes).
    #[arg(long, default_value_t = 60.0)]
    stream_s: f64,
    /// The aerodynamic plants' parasitic drag, quadratic in speed [1/m].
    #[arg(long, default_value_t = 0.03)]
    quadratic_drag: f64,
    /// The aerodynamic plants' rotor drag in the body plane [1/s].
    #[arg(long, default_value_t = 0.2)]
    rotor_drag: f64,
    /// DF-MPC's command-smoothness weight on x and y [1/rad²] for every
    /// flight (the shipped df-mr-smooth's: 50).
    #[arg(long, default_value_t = 50.0)]
    smoothness: f64,
    /// The plan's tilt bound of every flight: `box` (per axis, the shipped
    /// configs') or `cone` (on the combined tilt).
    #[arg(long, default_value = "box", value_parser = parse_plan_tilt_bound)]
    plan_tilt_bound: PlanTiltBound,
    /// Seconds of records the learning is given in the seconds study,
    /// comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "20,40,80,160,320,600")]
    seconds: Vec<f64>,
    /// No seconds study.
    #[arg(long)]
    no_seconds: bool,
    /// The noise seed of every flight (the plants' and the poses' noise,
    /// and so the records learned from): the study's tables fly 1.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The share of the plants' aerodynamics the *exact* flights' residual
    /// gives the controller (0 ..= 2; 1: the exact aerodynamics, below 1 a
    /// drag the model under-predicts; the plants and the other flights do
    /// not change): the study's sensitivity to the sign of a model error.
    #[arg(long, default_value_t = 1.0)]
    exact_scale: f64,
    /// JSON results file.
    #[arg(long, default_value = "docs/figures/learned.json")]
    json: PathBuf,
    /// No progress bar.
    #[arg(long)]
    no_progress: bool,
}

/// `box` or `cone` (`--plan-tilt-bound`).
fn parse_plan_tilt_bound(s: &str) -> Result<PlanTiltBound, String> {
    match s.trim() {
        "box" => Ok(PlanTiltBound::Box),
        "cone" => Ok(PlanTiltBound::Cone),
        other => Err(format!("unknown plan tilt bound `{other}` (box, cone)")),
    }
}

fn parse_plant(s: &str) -> Result<AeroPlant> {
    Ok(match s.trim() {
        "planar" => AeroPlant::Planar,
        "spatial" => AeroPlant::Spatial,
        "rigid" => AeroPlant::Rigid,
        other => anyhow::bail!("--plants: {other:?} is none of planar, spatial, rigid"),
    })
}

fn parse_shape(s: &str) -> Result<LearnedShape> {
    Ok(match s.trim() {
        "l" | "L" => LearnedShape::L,
        "eight" => LearnedShape::Eight,
        "racing-line" => LearnedShape::RacingLine,
        other => anyhow::bail!("--shapes: {other:?} is none of l, eight, racing-line"),
    })
}

/// Options of `experiment preview`.
#[derive(Debug, Args)]
pub struct PreviewArgs {
    /// Cruise speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "4,6,8")]
    speeds: Vec<f64>,
    /// Vision pose rates [Hz], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "50,15")]
    vision: Vec<f64>,
    /// JSON results file.
    #[arg(long, default_value = "docs/figures/preview.json")]
    json: PathBuf,
    /// No progress bar.
    #[arg(long)]
    no_progress: bool,
}

/// Options of `experiment phase`.
#[derive(Debug, Args)]
pub struct PhaseArgs {
    /// Trials per window, offset and speed.
    #[arg(long, default_value_t = 10)]
    trials: usize,
    /// Desired speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "5,9")]
    speeds: Vec<f64>,
    /// Pose arrival before the tick that uses it [ms], comma-separated
    /// (each 0 ..< 20).
    #[arg(long, value_delimiter = ',', default_value = "0,5,10,19")]
    offsets: Vec<f64>,
    /// Capture-to-arrival latency of the poses [ms].
    #[arg(long, default_value_t = 20.0)]
    latency: f64,
    /// Pose noise per axis [m].
    #[arg(long, default_value_t = 0.002)]
    sigma: f64,
    /// JSON results file.
    #[arg(long, default_value = "docs/figures/phase.json")]
    json: PathBuf,
    #[command(flatten)]
    run: RunArgs,
}

/// Options of `experiment tilt-cone`.
#[derive(Debug, Args)]
pub struct TiltConeArgs {
    /// Trials (noise seeds) per path, speed and bound.
    #[arg(long, default_value_t = 3)]
    trials: usize,
    /// Desired speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "7,8,9")]
    speeds: Vec<f64>,
    /// JSON results file.
    #[arg(long, default_value = "docs/figures/tilt_cone.json")]
    json: PathBuf,
    /// Solve the constrained plans with clarabel alone instead of the
    /// banded solvers (the same problems: tells the problem's behaviour
    /// from the solver's).
    #[arg(long)]
    clarabel: bool,
    #[command(flatten)]
    run: RunArgs,
}

/// How a study runs: its seeds and its progress bar.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Base of the seed rule.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bar.
    #[arg(long)]
    no_progress: bool,
}

/// Options shared by both studies.
#[derive(Debug, Args)]
pub struct CommonArgs {
    /// Trials per controller and condition.
    #[arg(long, default_value_t = 10)]
    trials: usize,
    /// JSON results file [default: <out>/<study>.json].
    #[arg(long)]
    json: Option<PathBuf>,
    /// Plot prefix: plots go to <prefix>[_name].svg/.png [default: <out>/<study>].
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "docs/figures")]
    out: PathBuf,
    /// Base of the seed rule (see the study's docs).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bar.
    #[arg(long)]
    no_progress: bool,
}

/// Options of `experiment noise-sweep`.
#[derive(Debug, Args)]
pub struct NoiseSweepArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// Noise levels σ [m], comma-separated [default: the paper's eight].
    #[arg(long, value_delimiter = ',')]
    sigmas: Option<Vec<f64>>,
    /// Simulated time per trial [s].
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
}

/// Options of `experiment paths`.
#[derive(Debug, Args)]
pub struct PathsArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// Desired speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "3,5,7,9")]
    speeds: Vec<f64>,
    /// Skip the weight search and fly the documented weights.
    #[arg(long)]
    no_tune: bool,
    /// Skip the DSL demonstration.
    #[arg(long)]
    no_dsl: bool,
}

/// Options of `experiment mismatch`.
#[derive(Debug, Args)]
pub struct MismatchArgs {
    #[command(flatten)]
    common: CommonArgs,
    /// Skip the noise check (the noise-sweep set-up flown by DF-MPC with
    /// and without the estimator).
    #[arg(long)]
    no_noise_check: bool,
    /// Position noise levels σ per axis [m], comma-separated
    /// [default: 0, 1e-4, 1e-3, 1e-2].
    #[arg(long, value_delimiter = ',')]
    sigmas: Option<Vec<f64>>,
    /// DF-MPC weights `N,q,r` (horizon [ticks], tracking [1/m²], jerk [s⁶/m²]).
    #[arg(long, value_delimiter = ',')]
    df_weights: Option<Vec<f64>>,
    /// Estimator bandwidth [Hz] and fit window [ticks], `f_c,L`.
    #[arg(long, value_delimiter = ',')]
    estimator: Option<Vec<f64>>,
    /// Skip the airframe part (the L path on a plant with drag and delay,
    /// flown with and without the model's drag and delay terms).
    #[arg(long)]
    no_airframe: bool,
}

/// Options of `experiment vision-rate`.
#[derive(Debug, Args)]
pub struct VisionRateArgs {
    /// Trials per controller, rate and speed (about 15 s in release on
    /// two cores at the default 10).
    #[arg(long, default_value_t = 10)]
    trials: usize,
    /// Desired speeds [m/s], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "3,5,7,9")]
    speeds: Vec<f64>,
    /// Vision rates [Hz], comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "10,15,30")]
    rates: Vec<f64>,
    /// JSON results file [default: <out>/vision_rate.json].
    #[arg(long)]
    json: Option<PathBuf>,
    /// Plot prefix: plots go to <prefix>_<metric>_<rate>hz.svg/.png
    /// [default: <out>/vision_rate].
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Output directory.
    #[arg(long, default_value = "docs/figures")]
    out: PathBuf,
    #[command(flatten)]
    run: RunArgs,
}

/// Runs one study, prints its table (stdout) and the files written and the
/// wall time (stderr).
pub fn run(command: ExperimentCommand) -> Result<()> {
    let start = Instant::now();
    let files = match command {
        ExperimentCommand::NoiseSweep(a) => {
            let mut config = NoiseSweepConfig {
                trials: a.common.trials,
                duration: a.duration,
                seed_base: a.common.seed,
                ..NoiseSweepConfig::default()
            };
            if let Some(s) = a.sigmas {
                config.sigmas = s;
            }
            let out =
                OutputPaths::resolve(&a.common.out, "noise_sweep", a.common.json, a.common.plot);
            let result = run_noise_sweep(&config, !a.common.no_progress).context("noise sweep")?;
            out!("{}", result.table());
            write_noise_sweep(&result, &out).context("writing the noise sweep's outputs")?
        }
        ExperimentCommand::Mismatch(a) => {
            let mut config = MismatchConfig {
                trials: a.common.trials,
                seed_base: a.common.seed,
                noise_check: !a.no_noise_check,
                ..MismatchConfig::default()
            };
            if a.no_airframe {
                config.airframe = None;
            } else if let Some(af) = &mut config.airframe {
                af.trials = a.common.trials;
                af.seed_base = a.common.seed;
            }
            if let Some(s) = a.sigmas {
                config.sigmas = s;
            }
            if let Some(w) = a.df_weights {
                anyhow::ensure!(w.len() == 3, "--df-weights takes N,q,r");
                config.df_weights = (w[0] as usize, w[1], w[2]);
            }
            if let Some(e) = a.estimator {
                anyhow::ensure!(e.len() == 2, "--estimator takes f_c,L");
                config.estimator.bandwidth_hz = e[0];
                config.estimator.fit_span = e[1] as usize;
            }
            let out = OutputPaths::resolve(&a.common.out, "mismatch", a.common.json, a.common.plot);
            let result = run_mismatch(&config, !a.common.no_progress).context("mismatch study")?;
            out!("{}", result.table());
            write_mismatch(&result, &out).context("writing the mismatch study's outputs")?
        }
        ExperimentCommand::VisionRate(a) => {
            let config = VisionRateConfig {
                speeds: a.speeds,
                rates: a.rates,
                trials: a.trials,
                seed_base: a.run.seed,
                ..VisionRateConfig::default()
            };
            let out = OutputPaths::resolve(&a.out, "vision_rate", a.json, a.plot);
            let result =
                run_vision_rate(&config, !a.run.no_progress).context("vision-rate study")?;
            out!("{}", result.table());
            write_vision_rate(&result, &out).context("writing the vision-rate study's outputs")?
        }
        ExperimentCommand::Paths(a) => {
            let mut config = if a.no_tune {
                PathsConfig::untuned()
            } else {
                PathsConfig::default()
            };
            config.speeds = a.speeds;
            config.trials = a.common.trials;
            config.seed_base = a.common.seed;
            config.dsl = !a.no_dsl;
            let out = OutputPaths::resolve(&a.common.out, "paths", a.common.json, a.common.plot);
            let result = run_paths(&config, !a.common.no_progress).context("paths comparison")?;
            out!("{}", result.table());
            write_paths(&result, &out).context("writing the paths comparison's outputs")?
        }
        ExperimentCommand::TiltCone(a) => {
            let config = TiltConeConfig {
                speeds: a.speeds,
                trials: a.trials,
                seed_base: a.run.seed,
                qp_solver: if a.clarabel {
                    QpSolver::Clarabel
                } else {
                    QpSolver::Banded
                },
                ..TiltConeConfig::default()
            };
            let result = run_tilt_cone(&config, !a.run.no_progress).context("tilt-cone study")?;
            out!("{}", result.table());
            write_tilt_cone(&result, &a.json).context("writing the tilt-cone study")?;
            vec![a.json]
        }
        ExperimentCommand::Preview(a) => {
            let config = PreviewConfig {
                speeds: a.speeds,
                vision_rates: a.vision,
                ..PreviewConfig::default()
            };
            let result = run_preview(&config, !a.no_progress).context("preview study")?;
            out!("{}", result.table());
            write_preview(&result, &a.json).context("writing the preview study")?
        }
        ExperimentCommand::Learned(a) => {
            let config = LearnedConfig {
                plants: a
                    .plants
                    .iter()
                    .map(|p| parse_plant(p))
                    .collect::<Result<_>>()?,
                shapes: a
                    .shapes
                    .iter()
                    .map(|p| parse_shape(p))
                    .collect::<Result<_>>()?,
                speeds: a.speeds,
                vision_rates: a.vision,
                vision_sigma: a.vision_sigma,
                seconds: if a.no_seconds { Vec::new() } else { a.seconds },
                stream_s: a.stream_s,
                quadratic_drag: a.quadratic_drag,
                rotor_drag: a.rotor_drag,
                smoothness: a.smoothness,
                plan_tilt_bound: a.plan_tilt_bound,
                seed: a.seed,
                exact_scale: a.exact_scale,
            };
            let result = run_learned(&config, !a.no_progress).context("learned study")?;
            out!("{}", result.table());
            write_learned(&result, &a.json).context("writing the learned study")?
        }
        ExperimentCommand::Phase(a) => {
            let config = PhaseConfig {
                speeds: a.speeds,
                offsets_ms: a.offsets,
                trials: a.trials,
                latency: a.latency * 1e-3,
                sigma: a.sigma,
                seed_base: a.run.seed,
                ..PhaseConfig::default()
            };
            let result = run_phase(&config, !a.run.no_progress).context("phase study")?;
            out!("{}", result.table());
            write_phase(&result, &a.json).context("writing the phase study")?
        }
    };
    for f in &files {
        errln!("wrote {}", f.display());
    }
    errln!("wall time {:.1} s", start.elapsed().as_secs_f64());
    Ok(())
}
