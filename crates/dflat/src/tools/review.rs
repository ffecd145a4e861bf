//! `dflat review`: a flight's report as one HTML page
//! ([`dflat_tuning::review`] draws it).

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};

use dflat_tuning::flightlog::{FlightLog, FlightLogError};
use dflat_tuning::review::{header_for, render_with};

/// Arguments of `dflat review`.
#[derive(Debug, clap::Args)]
pub struct ReviewArgs {
    /// The flight's `.csv` (its `.tlog` beside it adds the measured
    /// attitude and the STATUSTEXTs).
    pub flight: PathBuf,
    /// The HTML file to write (default `<flight>.html`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The configuration the flight was flown with: its `[vehicle]` table
    /// goes into the page's header.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// `dflat review`.
pub fn run(args: ReviewArgs) -> Result<()> {
    let given_tlog = args.flight.extension().and_then(|e| e.to_str()) == Some("tlog");
    let csv_path = if given_tlog {
        args.flight.with_extension("csv")
    } else {
        args.flight.clone()
    };
    if given_tlog && !csv_path.exists() {
        anyhow::bail!(
            "{}: review reads the flight's .csv, and {} is not there \
             (the daemon writes both with logging.csv and logging.tlog)",
            args.flight.display(),
            csv_path.display()
        );
    }
    let csv = super::read_csv(&csv_path)?;
    let log = load_tlog_beside(&csv_path)?;
    let header = header_for(&csv_path, log.as_ref(), args.config.as_deref())?;
    let html = render_with(&csv_path, &csv, log.as_ref(), None, &header);
    let out = args.out.unwrap_or_else(|| csv_path.with_extension("html"));
    std::fs::write(&out, html).with_context(|| format!("cannot write {}", out.display()))?;
    outln!("{}", out.display());
    Ok(())
}

/// The `.tlog` beside a CSV, if there is one with a complete record (an
/// empty one — the daemon killed before its first frame was whole — is
/// left out with a warning; a torn tail is dropped with one).
pub fn load_tlog_beside(csv: &Path) -> Result<Option<FlightLog>> {
    let tlog = csv.with_extension("tlog");
    if !tlog.exists() {
        return Ok(None);
    }
    match super::read_tlog(&tlog) {
        Ok(log) => Ok(Some(log)),
        Err(e) => match e.downcast_ref::<FlightLogError>() {
            Some(empty @ FlightLogError::EmptyTlog { .. }) => {
                errln!("warning: {empty}: reviewing from the CSV alone");
                Ok(None)
            }
            _ => Err(e),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `.tlog` named with no flight CSV beside it: the error says that
    /// review reads the CSV and which one it looked for, not only that a
    /// file the user never named is missing.
    #[test]
    fn a_tlog_without_its_csv_is_refused_naming_both() {
        let dir = std::env::temp_dir().join(format!("dflat-review-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let tlog = dir.join("flight.tlog");
        std::fs::write(&tlog, b"").unwrap();
        let err = run(ReviewArgs {
            flight: tlog.clone(),
            out: None,
            config: None,
        })
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("flight.tlog") && err.contains("flight.csv") && err.contains("reads"),
            "{err}"
        );
        assert!(!dir.join("flight.html").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
