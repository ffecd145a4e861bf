//! `dflat sitl` and `dflat demo`: thin CLI shells over
//! `dflat_sitl` and [`crate::demo`].
// The doc comments below are clap's --help text: `[m]`, `[s]`, `[link]`
// are units and TOML sections there, `<out>` a placeholder: not rustdoc
// links or HTML.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;
use std::io::Write as _;
use std::time::Duration;

use dflat_sitl::{self as sitl, SitlSettings};

#[cfg(feature = "lab")]
use crate::demo;

/// `dflat sitl` arguments.
#[derive(Debug, Args)]
pub struct SitlArgs {
    /// Configuration file (reads [link] ids and [sitl]); without it the
    /// built-in defaults (those of config/default.toml: the vehicle link
    /// udpin:127.0.0.1:14540, where the daemon's default link sends).
    #[arg(long)]
    config: Option<PathBuf>,
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
#[cfg(feature = "lab")]
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Speed along the L path [m/s] (default 5), or of the streamed
    /// circle with --stream (default 4: the heading then turns at 38°/s,
    /// within vehicle.max_yaw_rate_deg_s).
    #[arg(long)]
    speed: Option<f64>,
    /// Directory for the plot, the truth CSV and the daemon's flight records.
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// Stop after this many seconds even if the path is not done
    /// (default: path time + 8 s).
    #[arg(long)]
    seconds: Option<f64>,
    /// Fly a planner's stream instead of the L path: the SITL streams a
    /// 6 m circle at --speed (p, v, a, yaw at 20 Hz) to the daemon.
    #[arg(long)]
    stream: bool,
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
    // The daemon's tables are not the SITL's business, but a file both read
    // must be valid for both.
    let cfg = match &args.config {
        Some(path) => {
            dflat_daemon::config::Config::load(path)?;
            SitlSettings::load(path)?
        }
        None => SitlSettings::default(),
    };
    let options = sitl::SitlOptions {
        link: args.link,
        gcs: args.gcs,
        truth_csv: args.truth,
        ..sitl::SitlOptions::default()
    };
    let report = runtime()?.block_on(run_until(&cfg, options, dflat_daemon::shutdown_signal()))?;
    if report.diverged {
        bail!("the SITL plant diverged (non-finite state)");
    }
    Ok(())
}

/// Runs `dflat demo`.
#[cfg(feature = "lab")]
pub fn run_demo(args: DemoArgs) -> Result<()> {
    init_logs("warn");
    let default_speed = if args.stream { 4.0 } else { 5.0 };
    let options = demo::DemoOptions {
        speed: args.speed.unwrap_or(default_speed),
        out: args.out,
        seconds: args.seconds,
    };
    if args.stream {
        let outcome = runtime()?.block_on(crate::stream_demo::run(&options))?;
        out!("{}", outcome.summary_text());
        if let Some(failure) = outcome.failure() {
            bail!("stream demo failed: {failure}");
        }
        return Ok(());
    }
    let outcome = runtime()?.block_on(demo::run(&options))?;
    out!("{}", outcome.summary_text());
    if let Some(failure) = outcome.failure() {
        bail!("demo flight failed: {failure}");
    }
    Ok(())
}

/// Runs the SITL until `shutdown` resolves.
///
/// Prints `sitl listening on udpin:ADDR` (and `sitl gcs on udpin:ADDR`)
/// first, then one line per mode change (`sitl mode offboard` / `sitl mode
/// hold`) and per pose pause / resume, flushing stdout each time so a parent
/// process can follow. On Unix, SIGUSR1 pauses the pose stream and SIGUSR2
/// resumes it.
async fn run_until(
    cfg: &SitlSettings,
    options: sitl::SitlOptions,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<sitl::SitlReport, sitl::SitlError> {
    let handle = sitl::spawn(cfg, options)?;
    say(&format!("sitl listening on udpin:{}", handle.local_addr()));
    if let Some(g) = handle.gcs_addr() {
        say(&format!("sitl gcs on udpin:{g}"));
    }
    let mut signals = PoseSignals::new();
    let mut tick = tokio::time::interval(Duration::from_millis(20));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut mode = handle.mode();
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            () = &mut shutdown => break,
            pause = signals.next() => {
                if pause {
                    handle.pause_pose();
                    say("sitl pose paused");
                } else {
                    handle.resume_pose();
                    say("sitl pose resumed");
                }
            }
            _ = tick.tick() => {
                let m = handle.mode();
                if m != mode {
                    mode = m;
                    say(&format!("sitl mode {}", m.as_str()));
                }
            }
        }
    }
    let report = handle.stop()?;
    let c = &report.counters;
    let g = &c.to_gcs;
    say(&format!(
        "sitl stopped: commands {} accepted, {} ignored, {} rejected, {} unauthenticated; \
         to vehicle hb {} pos {} att {} status {}; to gcs hb {} pos {} att {} status {} replies {} routed {}; \
         acked {} commands, params set {} refused {}; late steps {} (the latest {:.1} ms behind)",
        c.commands_accepted,
        c.commands_ignored,
        c.commands_rejected,
        c.commands_unauthenticated,
        c.heartbeats_sent,
        c.positions_sent,
        c.attitudes_sent,
        c.sys_status_sent,
        g.heartbeats,
        g.positions,
        g.attitudes,
        g.sys_status,
        g.replies,
        c.gcs_frames_routed,
        c.commands_acked,
        c.params_set,
        c.params_refused,
        c.late_steps,
        c.step_lag_max_us as f64 / 1000.0
    ));
    let l = &c.pose_latency;
    say(&format!(
        "sitl pose→command: p50 {} µs, p99 {} µs, max {} µs ({} matched, {} without a new pose); command interval p50 {} µs, jitter p99 {} µs, max interval {} µs",
        l.p50_us,
        l.p99_us,
        l.max_us,
        l.matched,
        l.unmatched,
        l.interval_p50_us,
        l.jitter_p99_us,
        l.interval_max_us
    ));
    Ok(report)
}

fn say(line: &str) {
    let mut out = std::io::stdout().lock();
    // stdout closed: nobody is listening, which is not the SITL's problem.
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

/// SIGUSR1 (pause → `true`) and SIGUSR2 (resume → `false`); never fires
/// where they do not exist.
struct PoseSignals {
    #[cfg(unix)]
    usr1: Option<tokio::signal::unix::Signal>,
    #[cfg(unix)]
    usr2: Option<tokio::signal::unix::Signal>,
}

impl PoseSignals {
    fn new() -> Self {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            Self {
                usr1: signal(SignalKind::user_defined1()).ok(),
                usr2: signal(SignalKind::user_defined2()).ok(),
            }
        }
        #[cfg(not(unix))]
        Self {}
    }

    async fn next(&mut self) -> bool {
        #[cfg(unix)]
        {
            async fn recv(s: &mut Option<tokio::signal::unix::Signal>) {
                match s {
                    Some(s) => {
                        if s.recv().await.is_none() {
                            std::future::pending::<()>().await;
                        }
                    }
                    None => std::future::pending::<()>().await,
                }
            }
            tokio::select! {
                () = recv(&mut self.usr1) => true,
                () = recv(&mut self.usr2) => false,
            }
        }
        #[cfg(not(unix))]
        std::future::pending::<bool>().await
    }
}
