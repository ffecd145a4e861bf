//! The shell of `dflat learn`: read the records and the configuration,
//! learn, write the model file, print the report.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, Result, bail};
use dflat_control::learned::LearnedResidual;
use dflat_daemon::config::{Config, ModelKind};

use dflat_tuning::learn::parametric::Parametric;
use dflat_tuning::learn::{self, LearnOptions, Learned, VehicleTable, data::Run};

/// Arguments of `dflat learn`.
#[derive(Debug, clap::Args)]
pub struct LearnArgs {
    /// One or more flights' per-tick CSVs (the daemon's records: commands
    /// sent and poses measured).
    #[arg(required = true)]
    pub flights: Vec<PathBuf>,
    /// The configuration to fly the residual with: its `[vehicle]` table is
    /// the parametric model the residual is learned over (and the only one
    /// the model file loads against).
    #[arg(long)]
    pub config: PathBuf,
    /// Where to write the model file (default: next to the first flight,
    /// `<flight>.learned.toml`). The configuration snippet that flies it
    /// is written beside it, `<out>` with the extension `.snippet.toml`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Learn through this window \[poses\] (odd, 3–51) instead of choosing
    /// it on held-out data.
    #[arg(long)]
    pub window: Option<usize>,
}

/// The `[vehicle]` table of a configuration as [`learn`] reads it, at
/// control step `dt` \[s\]: the fields the daemon checks a model file
/// against ([`dflat_daemon::learned::vehicle_fields`]).
pub fn vehicle_table(cfg: &Config, dt: f64) -> VehicleTable {
    let v = &cfg.vehicle;
    let (model, fields) = dflat_daemon::learned::vehicle_fields(v);
    VehicleTable {
        model: model.into(),
        fields: fields.into_iter().map(|(k, x)| (k.to_owned(), x)).collect(),
        parametric: Parametric {
            spatial: v.model == ModelKind::Spatial,
            g: v.gravity,
            tau: v.tau,
            k: v.k,
            delay: v.delay_ms / 1000.0,
            tau_thrust: v.tau_thrust,
            hover_thrust: v.hover_thrust,
            drag_h: v.drag_h,
            drag_v: v.drag_v,
            drag_rotor: if v.model == ModelKind::Spatial {
                v.drag_rotor
            } else {
                0.0
            },
            dt,
        },
    }
}

/// The control step \[s\] of a record: the median spacing of its ticks.
fn tick_spacing(csv: &dflat_tuning::flightlog::FlightCsv) -> Option<f64> {
    let t: Vec<f64> = csv.numbers("t").into_iter().flatten().collect();
    let mut d: Vec<f64> = t
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    d.sort_by(f64::total_cmp);
    d.get(d.len() / 2).copied()
}

/// Reads the records' engaged runs and their common control step.
fn read_runs(flights: &[PathBuf]) -> Result<(Vec<Run>, f64)> {
    let mut runs = Vec::new();
    let mut dt: Option<f64> = None;
    for f in flights {
        let csv = super::read_csv(f)?;
        let step =
            tick_spacing(&csv).with_context(|| format!("{}: fewer than two ticks", f.display()))?;
        match dt {
            Some(d) if (d - step).abs() > 1e-4 => bail!(
                "{}: ticks every {step} s, the first record every {d} s: learn from records of one control rate",
                f.display()
            ),
            _ => dt = Some(step),
        }
        runs.extend(learn::data::runs(&csv, &f.display().to_string(), step)?);
    }
    Ok((runs, dt.unwrap_or(0.02)))
}

/// The report `dflat learn` prints.
pub fn report(learned: &Learned, out: &Path, seconds_taken: f64) -> String {
    let r = &learned.residual;
    let v = &r.validation;
    let mut s = String::new();
    let names: Vec<&str> = r.features.iter().map(|f| f.name()).collect();
    let _ = writeln!(
        s,
        "dflat learn: {:.1} s engaged; {} candidates (window × basis × λ) in {seconds_taken:.2} s",
        r.seconds, learned.candidates
    );
    let _ = writeln!(
        s,
        "chosen on held-out data: window r = {} outputs, basis [{}], λ = {:e}",
        r.window,
        names.join(", "),
        r.lambda
    );
    for (f, why) in &learned.unexcited {
        let _ = writeln!(s, "  {}: unexcited ({why}), not learned", f.name());
    }
    for (axis, why) in &learned.parametric_axes {
        let name = ["x", "y", "z"].get(*axis).copied().unwrap_or("?");
        let _ = writeln!(
            s,
            "  axis {name}: the parametric model kept ({why}), weights 0"
        );
    }
    let _ = writeln!(
        s,
        "support: speed ≤ {:.2} m/s, tilt ≤ {:.1}°, thrust {:.2} … {:.2} m/s²",
        r.support.speed_max,
        r.support.tilt_max.to_degrees(),
        r.support.thrust_min,
        r.support.thrust_max
    );
    let ratio = |l: f64, p: f64| if p > 0.0 { l / p } else { f64::NAN };
    let _ = writeln!(
        s,
        "test blocks: RMS acceleration left   parametric {:.4} m/s²   learned {:.4} m/s²   ({:.2}×)",
        v.acceleration_parametric,
        v.acceleration_learned,
        ratio(v.acceleration_learned, v.acceleration_parametric)
    );
    let _ = writeln!(
        s,
        "test blocks ({} starts), RMS prediction error from each model's window of poses (chosen on the validation blocks: parametric {:.1} s, learned {:.1} s):\n  one step     parametric {:.5} m   learned {:.5} m   ({:.2}×)\n  {:.2} s ahead  parametric {:.4} m   learned {:.4} m   ({:.2}×)",
        v.samples,
        v.start_parametric_s,
        v.start_learned_s,
        v.one_step_parametric_m,
        v.one_step_learned_m,
        ratio(v.one_step_learned_m, v.one_step_parametric_m),
        v.horizon_s,
        v.horizon_parametric_m,
        v.horizon_learned_m,
        ratio(v.horizon_learned_m, v.horizon_parametric_m)
    );
    let _ = writeln!(s, "written to {}", out.display());
    s
}

/// `dflat learn`.
pub fn run_learn(args: LearnArgs) -> Result<()> {
    let started = Instant::now();
    let cfg = Config::load(&args.config)?;
    let (runs, dt) = read_runs(&args.flights)?;
    let vehicle = vehicle_table(&cfg, dt);
    if let Some(w) = args.window
        && (!(3..=51).contains(&w) || w.is_multiple_of(2))
    {
        bail!("--window {w}: odd, 3 ..= 51 poses");
    }
    let options = LearnOptions {
        window: args.window,
    };
    let learned = learn::learn_with(&runs, &vehicle, options).context("dflat learn")?;
    learned.residual.validate().context("the learned model")?;
    let out = args
        .out
        .unwrap_or_else(|| args.flights[0].with_extension("learned.toml"));
    write_model(&learned.residual, &out)?;
    let snippet_path = out.with_extension("snippet.toml");
    let snippet = config_snippet(&out, &args.config);
    std::fs::write(&snippet_path, &snippet)
        .with_context(|| format!("cannot write {}", snippet_path.display()))?;
    let taken = started.elapsed().as_secs_f64();
    outln!("{}", report(&learned, &out, taken));
    outln!(
        "the configuration that flies it ({}), beside {}'s [vehicle] table:\n{snippet}",
        snippet_path.display(),
        args.config.display()
    );
    Ok(())
}

/// The configuration snippet that flies the model file `model` (its
/// absolute path), learned over `config`'s `[vehicle]` table.
pub fn config_snippet(model: &Path, config: &Path) -> String {
    let path = std::path::absolute(model).unwrap_or_else(|_| model.to_owned());
    format!(
        "# From `dflat learn`: the learned residual of the flat maps, flown with the\n\
         # [vehicle] table of {} (it refuses to load against another).\n\
         [controller.dfmpc]\n\
         learned_model = {:?}\n",
        config.display(),
        path.display().to_string()
    )
}

/// Writes a model file (TOML) with a header comment.
pub fn write_model(model: &LearnedResidual, out: &Path) -> Result<()> {
    let body = toml::to_string(model).context("the learned model as TOML")?;
    let text = format!(
        "# A residual of the flat maps learned by `dflat learn` (format {}, version {}).\n\
         # It loads only against the [vehicle] table below.\n{body}",
        model.format, model.version
    );
    std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))
}

/// Reads and validates a model file (as the daemon does).
pub fn read_model(path: &Path) -> Result<LearnedResidual> {
    dflat_daemon::learned::read(path).map_err(anyhow::Error::msg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_control::learned::{FORMAT, Feature, Support, VERSION, Validation};

    /// A model file round-trips through TOML, and a damaged one is refused
    /// naming its field.
    #[test]
    fn a_model_file_round_trips_and_a_bad_one_names_its_field() {
        let model = LearnedResidual {
            format: FORMAT.into(),
            version: VERSION,
            vehicle_model: "spatial".into(),
            vehicle: [("tau".to_owned(), 0.2)].into_iter().collect(),
            dt: 0.02,
            window: 3,
            features: vec![Feature::Bias, Feature::Quadratic],
            lambda: 1e-3,
            weights: [vec![0.1, -0.03, 0.0, 0.0], vec![0.0; 4], vec![0.0; 4]],
            support: Support {
                speed_max: 7.0,
                tilt_max: 0.4,
                thrust_min: 8.0,
                thrust_max: 12.0,
            },
            validation: Validation {
                one_step_parametric_m: 1e-3,
                one_step_learned_m: 2e-4,
                horizon_s: 0.5,
                horizon_parametric_m: 0.2,
                horizon_learned_m: 0.03,
                samples: 500,
                start_parametric_s: 0.4,
                start_learned_s: 1.2,
                acceleration_parametric: 1.0,
                acceleration_learned: 0.1,
            },
            seconds: 120.0,
        };
        let dir = std::env::temp_dir().join(format!("dflat-learn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("m.learned.toml");
        write_model(&model, &path).unwrap();
        assert_eq!(read_model(&path).unwrap(), model);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.replace("window = 3", "window = 1")).unwrap();
        let err = format!("{:#}", read_model(&path).unwrap_err());
        assert!(err.contains("window = 1"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
