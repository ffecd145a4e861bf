//! The tuning tools' command-line shells — `dflat identify`, `learn`,
//! `review` and `replay` — around the library `dflat-tuning` (which reads
//! the records through `dflat-records` and links no daemon): the
//! arguments, the configuration files read through the daemon's `Config`,
//! the files written and the words printed. The replay is here because it
//! re-runs the daemon's pure tick (`dflat_daemon::tick`) on a flight.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use dflat_tuning::flightlog::{FlightCsv, FlightLog};
use dflat_tuning::identify::{self, FlownVehicle};

pub mod learn;
pub mod replay;
pub mod review;

pub use learn::{LearnArgs, read_model, run_learn, write_model};

/// Arguments of `dflat identify`.
#[derive(Debug, clap::Args)]
pub struct IdentifyArgs {
    /// The flight's `.tlog` (a `.csv` of the same flight names its `.tlog`).
    #[arg(required_unless_present = "manoeuvre")]
    pub flight: Option<PathBuf>,
    /// The configuration the flight was flown with: the report says what
    /// it would change.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where to write the `[vehicle]` snippet (default: next to the log,
    /// `<flight>.vehicle.toml`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write the identification as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Print a `[mission]` for a short identification flight and exit.
    #[arg(long)]
    pub manoeuvre: bool,
    /// Start of the manoeuvre, local NED `X,Y,Z` \[m\] (z negative: up;
    /// `--at 0,0,-10`, also `--at -5,0,-10`).
    #[arg(long, value_name = "X,Y,Z", default_value = "0,0,-10", allow_hyphen_values = true, value_parser = parse_xyz)]
    pub at: [f64; 3],
}

/// `X,Y,Z` \[m\]: three finite numbers, comma-separated.
fn parse_xyz(text: &str) -> std::result::Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, z] = parts.as_slice() else {
        return Err(format!("`{text}`: expected X,Y,Z (three numbers)"));
    };
    let num = |s: &str| match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{s}` is not a finite number")),
    };
    Ok([num(x)?, num(y)?, num(z)?])
}

/// The `.tlog` of a flight given as its `.tlog` or `.csv`.
pub fn tlog_of(flight: &Path) -> Result<PathBuf> {
    let Some(tlog) = dflat_records::names::tlog_beside(flight) else {
        bail!(
            "{}: expected the flight's .tlog or .csv (flight-YYYYmmdd-HHMMSS.tlog)",
            flight.display()
        );
    };
    if !tlog.exists() {
        bail!(
            "{}: no such file (identification reads the .tlog: set logging.tlog = true)",
            tlog.display()
        );
    }
    Ok(tlog)
}

/// Reads a flight CSV; a torn tail (a crash mid-write) is dropped with a
/// warning on stderr and the complete rows are used.
pub fn read_csv(path: &Path) -> Result<FlightCsv> {
    let csv = FlightCsv::read(path)?;
    if let Some(torn) = &csv.torn_tail {
        errln!(
            "warning: {}: {torn} dropped (the daemon was stopped mid-write); using the {} complete rows",
            path.display(),
            csv.rows.len()
        );
    }
    Ok(csv)
}

/// Reads a flight `.tlog`; a torn last record is dropped with a warning
/// on stderr and the complete records are used.
pub fn read_tlog(path: &Path) -> Result<FlightLog> {
    let log = FlightLog::read_tlog(path)?;
    if log.torn_tail {
        errln!(
            "warning: {}: a torn last record dropped (the daemon was stopped mid-write); using the {} complete records",
            path.display(),
            log.records
        );
    }
    Ok(log)
}

/// The `[vehicle]` values of a configuration file.
pub fn flown_vehicle(config: &Path) -> Result<FlownVehicle> {
    let cfg = dflat_daemon::config::Config::load(config)?;
    let v = &cfg.vehicle;
    Ok(FlownVehicle {
        tau: v.tau,
        k: v.k,
        tau_thrust: v.tau_thrust,
        hover_thrust: v.hover_thrust,
        spatial: v.model == dflat_daemon::config::ModelKind::Spatial,
        delay_ms: v.delay_ms,
        drag_h: v.drag_h,
        drag_rotor: v.drag_rotor,
    })
}

/// `dflat identify`.
pub fn run_identify(args: IdentifyArgs) -> Result<()> {
    if args.manoeuvre {
        out!("{}", identify::manoeuvre_mission(args.at));
        return Ok(());
    }
    let Some(flight) = args.flight else {
        bail!("no flight given");
    };
    let tlog = tlog_of(&flight)?;
    let log = read_tlog(&tlog)?;
    let flown = args.config.as_deref().map(flown_vehicle).transpose()?;
    let found = identify::identify(&log).with_context(|| format!("{}", tlog.display()))?;
    let name = tlog.display().to_string();
    out!("{}", found.report(&name, flown.as_ref()));
    let snippet = found.vehicle_snippet(&name, flown.as_ref());
    let out = args
        .out
        .unwrap_or_else(|| tlog.with_extension("vehicle.toml"));
    std::fs::write(&out, &snippet).with_context(|| format!("cannot write {}", out.display()))?;
    outln!("\n{snippet}\n(written to {})", out.display());
    if let Some(json) = args.json {
        let text = serde_json::to_string_pretty(&found).context("identification as JSON")?;
        std::fs::write(&json, text + "\n")
            .with_context(|| format!("cannot write {}", json.display()))?;
    }
    Ok(())
}
