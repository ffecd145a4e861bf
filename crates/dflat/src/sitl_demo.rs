//! `dflat sitl` and `dflat demo`: thin CLI shells over
//! `dflat_daemon::sitl` and `dflat_daemon::demo`.
// The doc comments below are clap's --help text: `[m]`, `[s]`, `[link]`
// are units and TOML sections there, `<out>` a placeholder: not rustdoc
// links or HTML.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use dflat_daemon::config::Config;
use dflat_daemon::{demo, sitl};

/// `dflat sitl` arguments.
#[derive(Debug, Args)]
pub struct SitlArgs {
    /// Configuration file (reads [link] ids and [sitl]).
    #[arg(long)]
    config: PathBuf,
    /// Vehicle link, overriding sitl.url: udpin:HOST:PORT (port 0 = any
    /// free port; the bound address is printed on stdout).
    #[arg(long)]
    link: Option<String>,
    /// Also listen for a ground station (udpin:HOST:PORT) and route MAVLink
    /// between it and the vehicle link, as an autopilot does.
    #[arg(long)]
    gcs: Option<String>,
    /// Write the true state (telemetry rate) to this CSV.
    #[arg(long)]
    truth: Option<PathBuf>,
}

/// `dflat demo` arguments.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Speed along the L path [m/s].
    #[arg(long, default_value_t = 5.0)]
    speed: f64,
    /// Directory for the plot, the truth CSV and the daemon's flight records.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Stop after this many seconds even if the path is not done
    /// (default: path time + 8 s).
    #[arg(long)]
    seconds: Option<f64>,
}

fn init_logs(default: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    // A second init (tests) is harmless.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

/// Runs `dflat sitl` until SIGINT / SIGTERM.
pub fn run_sitl(args: SitlArgs) -> Result<()> {
    init_logs("info");
    let cfg = Config::load(&args.config)?;
    let options = sitl::SitlOptions {
        link: args.link,
        gcs: args.gcs,
        truth_csv: args.truth,
        ..sitl::SitlOptions::default()
    };
    let report = runtime()?.block_on(sitl::run(&cfg, options, dflat_daemon::shutdown_signal()))?;
    if report.diverged {
        bail!("the SITL plant diverged (non-finite state)");
    }
    Ok(())
}

/// Runs `dflat demo`.
pub fn run_demo(args: DemoArgs) -> Result<()> {
    init_logs("warn");
    let options = demo::DemoOptions {
        speed: args.speed,
        out: args.out,
        seconds: args.seconds,
    };
    let outcome = runtime()?.block_on(demo::run(&options))?;
    print!("{}", outcome.summary_text());
    if let Some(failure) = outcome.failure() {
        bail!("demo flight failed: {failure}");
    }
    Ok(())
}
