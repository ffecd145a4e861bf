//! The command line: parsing and dispatch of `dflat`'s subcommands.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Discrete-flatness MPC flight control for multirotors (MAVLink).
#[derive(Debug, Parser)]
#[command(name = "dflat", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Validate a configuration file and print the effective configuration.
    CheckConfig {
        /// The TOML file.
        file: PathBuf,
        /// Instead: print FILE with the keys of the old flat `[controller]`
        /// table moved into its sub-tables (`[controller.dfmpc]`, ...;
        /// comments kept) on stdout, and what moved on stderr; the file
        /// itself is not written. Fails if the result does not validate.
        #[arg(long)]
        migrate: bool,
    },
    /// Run one of the paper's studies in the simulation lab (JSON + plots).
    #[cfg(feature = "lab")]
    Experiment {
        /// The study.
        #[command(subcommand)]
        which: crate::experiment::ExperimentCommand,
    },
    /// The autopilot stand-in: a real-time plant behind MAVLink (udpin);
    /// SIGUSR1 / SIGUSR2 pause / resume its pose stream.
    #[cfg(feature = "sitl")]
    Sitl(crate::sitl_demo::SitlArgs),
    /// Fly the L path with the SITL and the daemon on loopback (shipped
    /// defaults); print the summary and draw the flown path.
    #[cfg(feature = "lab")]
    Demo(crate::sitl_demo::DemoArgs),
    /// Identify the vehicle from a flight's .tlog: attitude τ, k̃ and delay,
    /// hover thrust and τ_T, with intervals; writes a `[vehicle]` snippet.
    #[cfg(feature = "tuning")]
    Identify(crate::tools::IdentifyArgs),
    /// Learn the flat maps' residual over the parametric model from one or
    /// more flights' CSVs; reports held-out errors, writes a model file.
    #[cfg(feature = "tuning")]
    Learn(crate::tools::LearnArgs),
    /// A flight's report as one self-contained HTML page (inline SVG).
    #[cfg(feature = "tuning")]
    Review(crate::tools::review::ReviewArgs),
    /// Re-run the controller offline on a flight's logged poses, setpoints
    /// and timing, with its own or another configuration.
    #[cfg(feature = "tuning")]
    Replay(crate::tools::replay::ReplayArgs),
    /// The flight-control daemon (systemd runs this): pose and setpoints in,
    /// attitude commands out, until SIGINT / SIGTERM; prints a summary.
    Daemon(DaemonArgs),
}

/// Arguments of `dflat daemon`.
#[derive(Debug, clap::Args)]
struct DaemonArgs {
    /// The TOML configuration file.
    #[arg(long)]
    config: PathBuf,
    /// Connection string replacing `link.url` (`udpout:HOST:PORT`,
    /// `udpin:HOST:PORT`, `tcpout:HOST:PORT`, `serial:PATH:BAUD`).
    #[arg(long)]
    link: Option<String>,
    /// Also write the shutdown summary as JSON to this file.
    #[arg(long)]
    summary_json: Option<PathBuf>,
    /// Log JSON lines on stderr (overrides `logging.format`).
    #[arg(long)]
    log_json: bool,
}

/// `dflat`'s `main`: parses the command line, runs the subcommand, prints
/// an error and exits with 2 when it fails.
pub fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            errln!("error: {}", error_text(&e));
            std::process::ExitCode::from(2)
        }
    }
}

/// The error and its causes on one line, `outer: cause: …`, each cause said
/// once: a cause whose text the message before it already contains (most of
/// our errors print their source in their own message) is not repeated.
pub fn error_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::CheckConfig {
            file,
            migrate: true,
        } => migrate_config(&file),
        Command::CheckConfig { file, .. } => {
            #[allow(unused_mut)]
            let mut cfg = dflat_daemon::config::Config::load(&file)?;
            // What a start checks beyond the ranges (one validation).
            dflat_daemon::daemon::preflight(&cfg, None)
                .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
            #[cfg(feature = "sitl")]
            {
                // The [sitl] table is the SITL's: validate it and print it
                // with its defaults filled in.
                let sitl = dflat_sitl::SitlSettings::load(&file)?;
                cfg.sitl = None;
                out!("{}\n{}", cfg.to_toml(), sitl.to_toml());
            }
            #[cfg(not(feature = "sitl"))]
            out!("{}", cfg.to_toml());
            Ok(())
        }
        #[cfg(feature = "lab")]
        Command::Experiment { which } => crate::experiment::run(which),
        #[cfg(feature = "sitl")]
        Command::Sitl(args) => crate::sitl_demo::run_sitl(args),
        #[cfg(feature = "lab")]
        Command::Demo(args) => crate::sitl_demo::run_demo(args),
        #[cfg(feature = "tuning")]
        Command::Identify(args) => crate::tools::run_identify(args),
        #[cfg(feature = "tuning")]
        Command::Learn(args) => crate::tools::run_learn(args),
        #[cfg(feature = "tuning")]
        Command::Review(args) => crate::tools::review::run(args),
        #[cfg(feature = "tuning")]
        Command::Replay(args) => crate::tools::replay::run(args),
        Command::Daemon(args) => run_daemon(args),
    }
}

/// `dflat check-config --migrate FILE`: the migrated text on stdout, each
/// move on stderr, then the result validated as `check-config` would.
fn migrate_config(file: &std::path::Path) -> Result<()> {
    use anyhow::Context as _;
    let text = std::fs::read_to_string(file)
        .with_context(|| format!("{}: cannot read", file.display()))?;
    let migrated = dflat_daemon::config::migrate::migrate(&text)
        .with_context(|| format!("{}: cannot migrate", file.display()))?;
    out!("{}", migrated.text);
    if migrated.moved.is_empty() {
        errln!("{}: no key to move", file.display());
    }
    for m in &migrated.moved {
        errln!("{}: {m}", file.display());
    }
    dflat_daemon::config::Config::parse(&migrated.text, file)?;
    #[cfg(feature = "sitl")]
    dflat_sitl::SitlSettings::parse(&migrated.text, file)?;
    Ok(())
}

/// Installs the tracing subscriber on stderr: filter from `RUST_LOG`
/// (default `default_filter`, e.g. `info`), text or JSON lines. A second
/// call is a no-op.
fn init_logging(default_filter: &str, json: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default_filter));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr);
    // Err only if a subscriber is already installed.
    let _ = if json {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// `dflat daemon`: runs until SIGINT / SIGTERM, prints the summary.
fn run_daemon(args: DaemonArgs) -> Result<()> {
    use anyhow::Context as _;
    use dflat_daemon::config::{Config, LogFormat};

    let cfg = Config::load(&args.config)?;
    init_logging(
        "info",
        args.log_json || cfg.logging.format == LogFormat::Json,
    );
    // `[realtime]`: the link threads one priority below the control thread
    // (a refusal is reported by the control thread, which stops the start).
    let link_rt = cfg.realtime.link_threads();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("dflat-io")
        .on_thread_start(move || {
            if link_rt.is_enabled() {
                let _ = dflat_daemon::realtime::apply_to_current_thread(&link_rt);
            }
        })
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let summary = runtime.block_on(dflat_daemon::run(
        cfg,
        args.link,
        dflat_daemon::daemon_signals(),
    ))?;
    // The file first: it must not depend on stdout being there.
    if let Some(path) = args.summary_json {
        let json = serde_json::to_string_pretty(&summary).context("summary as JSON")?;
        std::fs::write(&path, json + "\n")
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    outln!("{summary}");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::error_text;
    use clap::Parser as _;

    /// `dflat identify --manoeuvre --at 0,0,-10` (docs/tuning.md): a NED
    /// altitude is negative, and `--at` takes it.
    #[cfg(feature = "tuning")]
    #[test]
    fn at_takes_a_negative_z() {
        for at in [
            ["--at", "0,0,-10"],
            ["--at=-1,2,-10", ""],
            ["--at", "-1,2,-10"],
        ] {
            let args = ["dflat", "identify", "--manoeuvre"]
                .into_iter()
                .chain(at.into_iter().filter(|a| !a.is_empty()));
            let cli = super::Cli::try_parse_from(args).expect("parses");
            let super::Command::Identify(a) = cli.command else {
                panic!("not identify: {cli:?}");
            };
            assert!(a.manoeuvre);
            assert_eq!(a.at[2], -10.0);
        }
        let default =
            super::Cli::try_parse_from(["dflat", "identify", "--manoeuvre"]).expect("parses");
        let super::Command::Identify(a) = default.command else {
            panic!("not identify");
        };
        assert_eq!(a.at, [0.0, 0.0, -10.0]);
        for bad in ["0,0", "0,0,x", "0,0,-10,1"] {
            let r = super::Cli::try_parse_from(["dflat", "identify", "--manoeuvre", "--at", bad]);
            assert!(r.is_err(), "{bad}");
        }
    }

    /// `dflat sitl --gcs udpin:0.0.0.0:14550` (README): no `--config`
    /// needed, the built-in defaults fly.
    #[cfg(feature = "sitl")]
    #[test]
    fn sitl_runs_without_a_config() {
        let cli = super::Cli::try_parse_from(["dflat", "sitl", "--gcs", "udpin:0.0.0.0:14550"]);
        assert!(cli.is_ok(), "{cli:?}");
    }

    #[derive(Debug, thiserror::Error)]
    #[error("cfg.toml: cannot read: {source}")]
    struct Read {
        source: std::io::Error,
    }

    #[test]
    fn a_cause_already_in_the_message_is_said_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "No such file or directory");
        let e = anyhow::Error::new(Read { source: io });
        assert_eq!(
            error_text(&e),
            "cfg.toml: cannot read: No such file or directory"
        );
    }

    #[test]
    fn a_context_and_a_new_cause_are_both_said() {
        let e = anyhow::anyhow!("bad port").context("--link udpout:x");
        assert_eq!(error_text(&e), "--link udpout:x: bad port");
    }
}
