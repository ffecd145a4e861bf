//! Shared helpers of the end-to-end tests: spawn the real `dflat` binary
//! (SITL and daemon) on loopback, read the SITL's truth, fake a ground
//! station (`gcs.rs`), judge a flight (`judge.rs`) and inject faults into
//! a controller (`faulty.rs`).
//!
//! Ports: the SITL binds port 0 and prints the address it got
//! (`sitl listening on udpin:127.0.0.1:PORT`); the daemon is then started
//! with `--link udpout:127.0.0.1:PORT`. No port is guessed, so tests can run
//! next to anything else on the machine.

#![allow(dead_code)] // each test binary uses a subset

mod faulty;
pub mod gcs;
mod judge;

#[allow(unused_imports)] // each test binary uses a subset
pub use faulty::{Fault, Faulty};
#[allow(unused_imports)]
pub use judge::*;

use std::io::{BufRead, BufReader};
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

use dflat_daemon::config::Config;
use dflat_link::MavMessage;
use dflat_link::dialect::{MavFrame, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA};
use dflat_sitl::{self as sitl, SitlOptions, SitlReport, TapFrame};

/// Runs `dflat args`, asserting it succeeds (its stderr in the message);
/// its output.
pub fn dflat_ok(args: &[&str]) -> std::process::Output {
    let out = Command::new(bin()).args(args).output().expect("run dflat");
    assert!(
        out.status.success(),
        "dflat {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// The binary under test.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_dflat-under-test")
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("e2e-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// The scratch directory of `name` as [`scratch`] made it (not cleared).
pub fn scratch_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("e2e-{name}-{}", std::process::id()))
}

/// Writes a config file into `dir`.
pub fn write_config(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write config");
    path
}

/// A child process killed (SIGKILL) on drop unless it already exited; its
/// stderr goes to a file that is printed when a test fails.
pub struct Proc {
    /// The child.
    pub child: Child,
    /// What it is (for messages).
    pub name: &'static str,
    /// Its stderr.
    pub stderr: PathBuf,
}

impl Proc {
    /// Sends a signal by name (`INT`, `TERM`, `USR1`, …) with `kill(1)`.
    pub fn signal(&self, sig: &str) {
        let ok = Command::new("kill")
            .arg(format!("-{sig}"))
            .arg(self.child.id().to_string())
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
        assert!(ok, "kill -{sig} {} failed", self.name);
    }

    /// SIGINT, then waits up to `limit` for a clean exit; returns whether it
    /// exited successfully.
    pub fn interrupt_and_wait(&mut self, limit: Duration) -> bool {
        self.signal("INT");
        let until = Instant::now() + limit;
        while Instant::now() < until {
            if let Ok(Some(status)) = self.child.try_wait() {
                return status.success();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    /// The captured stderr so far.
    pub fn stderr_text(&self) -> String {
        std::fs::read_to_string(&self.stderr).unwrap_or_default()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        if std::thread::panicking() {
            let text = self.stderr_text();
            let tail: Vec<&str> = text.lines().rev().take(40).collect();
            eprintln!("---- {} stderr (last lines) ----", self.name);
            for l in tail.iter().rev() {
                eprintln!("{l}");
            }
        }
    }
}

/// The SITL binary, its addresses and its stdout lines.
pub struct Sitl {
    /// The process.
    pub proc: Proc,
    /// The vehicle link address.
    pub link: SocketAddr,
    /// The GCS port, if asked for.
    pub gcs: Option<SocketAddr>,
    /// stdout lines.
    pub lines: Receiver<String>,
}

impl Sitl {
    /// Waits for a stdout line containing `needle`.
    pub fn wait_for_line(&self, needle: &str, limit: Duration) -> Option<String> {
        let until = Instant::now() + limit;
        loop {
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            match self.lines.recv_timeout(left) {
                Ok(l) if l.contains(needle) => return Some(l),
                Ok(_) => {}
                Err(_) => return None,
            }
        }
    }
}

fn parse_addr(line: &str) -> Option<SocketAddr> {
    line.rsplit("udpin:").next()?.trim().parse().ok()
}

/// Starts `dflat sitl --config CONFIG --link udpin:127.0.0.1:0 [--gcs
/// udpin:127.0.0.1:0] --truth TRUTH` and reads back its addresses.
pub fn spawn_sitl(dir: &Path, config: &Path, gcs: bool, truth: &Path) -> Sitl {
    spawn_sitl_on(dir, config, "udpin:127.0.0.1:0", gcs, truth, "sitl.stderr")
}

/// [`spawn_sitl`] on a given link (`udpin:HOST:PORT`, e.g. the port of a
/// SITL that was killed), with its stderr in `dir/stderr_name`.
pub fn spawn_sitl_on(
    dir: &Path,
    config: &Path,
    link: &str,
    gcs: bool,
    truth: &Path,
    stderr_name: &str,
) -> Sitl {
    let stderr = dir.join(stderr_name);
    let mut cmd = Command::new(bin());
    cmd.arg("sitl")
        .arg("--config")
        .arg(config)
        .arg("--link")
        .arg(link)
        .arg("--truth")
        .arg(truth);
    if gcs {
        cmd.arg("--gcs").arg("udpin:127.0.0.1:0");
    }
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(&stderr).expect("stderr file"))
        .spawn()
        .expect("spawn dflat sitl");
    let stdout = child.stdout.take().expect("piped stdout");
    let (tx, lines) = channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut sitl = Sitl {
        proc: Proc {
            child,
            name: "sitl",
            stderr,
        },
        link: SocketAddr::from(([127, 0, 0, 1], 0)),
        gcs: None,
        lines,
    };
    let line = sitl
        .wait_for_line("sitl listening on", Duration::from_secs(10))
        .expect("the SITL did not print its address");
    sitl.link = parse_addr(&line).expect("SITL address");
    if gcs {
        let line = sitl
            .wait_for_line("sitl gcs on", Duration::from_secs(5))
            .expect("the SITL did not print its GCS address");
        sitl.gcs = Some(parse_addr(&line).expect("GCS address"));
    }
    sitl
}

/// Starts `dflat daemon --config CONFIG --link udpout:ADDR`.
pub fn spawn_daemon(dir: &Path, config: &Path, sitl: SocketAddr) -> Proc {
    spawn_daemon_with(dir, config, sitl, &[])
}

/// [`spawn_daemon`] with extra arguments (e.g. `--summary-json FILE`).
pub fn spawn_daemon_with(dir: &Path, config: &Path, sitl: SocketAddr, extra: &[&str]) -> Proc {
    let mut args: Vec<std::ffi::OsString> = vec![
        "--config".into(),
        config.into(),
        "--link".into(),
        format!("udpout:{sitl}").into(),
    ];
    args.extend(extra.iter().map(Into::into));
    spawn_daemon_args(dir, &args, &[])
}

/// `dflat daemon ARGS` with `env` added to its environment, its stderr in
/// `dir/daemon.stderr`.
pub fn spawn_daemon_args(dir: &Path, args: &[std::ffi::OsString], env: &[(&str, &str)]) -> Proc {
    let stderr = dir.join("daemon.stderr");
    let child = Command::new(bin())
        .arg("daemon")
        .args(args)
        .envs(env.iter().copied())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&stderr).expect("stderr file"))
        .spawn()
        .expect("spawn dflat daemon");
    Proc {
        child,
        name: "daemon",
        stderr,
    }
}

/// SET_POSITION_TARGET_LOCAL_NED to the daemon (system 1, component 191):
/// position only, LOCAL_NED.
pub fn position_setpoint(p: [f64; 3]) -> MavMessage {
    let mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms: 0,
        x: p[0] as f32,
        y: p[1] as f32,
        z: p[2] as f32,
        type_mask: mask,
        target_system: 1,
        target_component: 191,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..SET_POSITION_TARGET_LOCAL_NED_DATA::default()
    })
}

/// Sends one message from (`sys`, `comp`) over `socket` to `to`.
pub fn send(socket: &UdpSocket, to: SocketAddr, sys: u8, comp: u8, seq: u8, msg: &MavMessage) {
    let frame = dflat_link::serialize_v2(&dflat_link::header(sys, comp, seq), msg).expect("encode");
    socket.send_to(frame.as_bytes(), to).expect("send");
}

/// The daemon's summary file in a [`fly_in_process`] flight's directory
/// (`--summary-json`).
pub const SUMMARY_JSON: &str = "summary.json";

/// What [`fly_in_process`] saw.
pub struct Flight {
    /// Every frame the daemon sent, in arrival order.
    pub frames: Vec<TapFrame>,
    /// The flight's directory (its configuration and the daemon's records).
    pub dir: PathBuf,
    /// The in-process SITL's report (with its truth trace).
    pub report: SitlReport,
    /// The daemon exited cleanly on SIGINT.
    pub clean_exit: bool,
}

impl Flight {
    /// The daemon's shutdown summary (`--summary-json`), parsed; `None`
    /// when it did not write one (no clean exit).
    pub fn summary(&self) -> Option<serde_json::Value> {
        let text = std::fs::read_to_string(self.dir.join(SUMMARY_JSON)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// How long the daemon streamed, on its own clock: from its first
    /// command to its last in its records (the flight CSV's tick wake
    /// times) \[s\]; 0 without two.
    pub fn streamed_s(&self) -> f64 {
        let wakes: Vec<f64> = read_flight_csv(&self.dir)
            .iter()
            .filter(|r| field(r, "roll").is_some())
            .filter_map(|r| field(r, "t_wake"))
            .collect();
        match (wakes.first(), wakes.last()) {
            (Some(first), Some(last)) => last - first,
            _ => 0.0,
        }
    }

    /// How late the daemon's latest tick ran, from its own records (the
    /// flight CSV's `jitter_us` over the ticks that commanded) \[µs\]; 0
    /// without such ticks.
    #[allow(dead_code)]
    pub fn latest_tick_us(&self) -> f64 {
        read_flight_csv(&self.dir)
            .iter()
            .filter(|r| field(r, "roll").is_some())
            .filter_map(|r| field(r, "jitter_us"))
            .fold(0.0, f64::max)
    }

    /// Asserts, from the daemon's summary, that it entered no failsafe:
    /// no time in FAILSAFE and no level-hover ticks (no brake, no level);
    /// `what` names the flight in the message.
    #[allow(dead_code)]
    pub fn assert_no_failsafe(&self, what: &str) {
        let summary = self.summary().expect("the daemon's summary");
        let failsafe_s = summary["time_in_state_s"]["failsafe"]
            .as_f64()
            .expect("a time");
        let level_hover = summary["guards"]["level_hover"].as_u64().expect("a count");
        assert!(
            failsafe_s == 0.0 && level_hover == 0,
            "{what}: failsafe for {failsafe_s} s, {level_hover} level-hover ticks: {}",
            summary["guards"]
        );
    }

    /// The texts of the STATUSTEXT frames, in order.
    #[allow(dead_code)]
    pub fn statustexts(&self) -> impl Iterator<Item = String> + '_ {
        self.frames.iter().filter_map(|f| match &f.message {
            MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
            _ => None,
        })
    }

    /// The SET_ATTITUDE_TARGET frames.
    pub fn attitude_targets(
        &self,
    ) -> impl Iterator<Item = (&TapFrame, &dflat_link::dialect::SET_ATTITUDE_TARGET_DATA)> {
        self.frames.iter().filter_map(|f| match &f.message {
            MavMessage::SET_ATTITUDE_TARGET(d) => Some((f, d)),
            _ => None,
        })
    }
}

/// Flies the real daemon binary against the in-process SITL with
/// `config_text` (a short path mission), tapping every frame the daemon
/// sends, for `fly` after its first attitude target (at most 20 s).
pub fn fly_in_process(name: &str, config_text: &str, fly: Duration) -> Flight {
    let end = FlightEnd {
        fly,
        cap: Duration::from_secs(20),
        settle: Duration::ZERO,
    };
    fly_in_process_until(name, config_text, end, |_| false)
}

/// A tick this late in the daemon's own records \[µs\] (a quarter of its
/// 20 ms period) means the machine starved the flight
/// ([`fly_unstarved`]).
pub const STARVED_US: f64 = 5000.0;
/// A plant step this far behind its due time in the SITL's counters \[µs\]
/// (half the daemon's 20 ms period: its pose then reaches the daemon a
/// tick late) means the machine starved the flight ([`fly_unstarved`]).
/// Half a period, not a quarter as for the daemon's ticks: the in-process
/// SITL runs on the normal scheduler, and on the quiet 2-core VM its
/// plant steps lag 2–7 ms now and then while the daemon's ticks do not.
pub const SITL_STARVED_US: f64 = 10_000.0;
/// Flights at most [`fly_unstarved`] flies when the machine starves them.
pub const STARVED_ATTEMPTS: usize = 3;

/// [`fly_in_process`], flown again while the daemon's own records show a
/// tick later than [`STARVED_US`], or the SITL's counters a plant step
/// later than [`SITL_STARVED_US`] (the machine starved it: said; the
/// lateness judged is the daemon's, or half the SITL's; the daemon may run at
/// SCHED_FIFO, [`realtime_if_granted`], the in-process SITL does not), up to
/// [`STARVED_ATTEMPTS`] flights; when every one was starved, the least
/// late is returned (said). The flights run as `{name}-{attempt}`; the
/// returned one's directory becomes `name`'s ([`scratch_dir`]), where its
/// records are read.
pub fn fly_unstarved(name: &str, config_text: &str, fly: Duration) -> Flight {
    let mut flights = LeastLate::new(name);
    for attempt in 1..=STARVED_ATTEMPTS {
        let flight = fly_in_process(&format!("{name}-{attempt}"), config_text, fly);
        let (tick, step) = (
            flight.latest_tick_us(),
            flight.report.counters.step_lag_max_us as f64,
        );
        // The SITL's lag on the daemon's scale (its threshold is twice).
        let late = tick.max(step * STARVED_US / SITL_STARVED_US);
        if late > STARVED_US {
            println!(
                "{name}: flight {attempt}: the daemon's latest tick {tick:.0} µs late, the SITL's latest plant step {step:.0} µs"
            );
        }
        if flights.offer(attempt, late, flight) {
            break;
        }
    }
    let (attempt, mut flight) = flights.judged();
    let dir = scratch_dir(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::rename(scratch_dir(&format!("{name}-{attempt}")), &dir)
        .expect("the judged flight's records");
    flight.dir = dir;
    flight
}

/// The choice among flights the machine may have starved
/// ([`fly_unstarved`]): each flight is offered with how late its latest
/// tick ran in the daemon's own records \[µs\]; one on time
/// ([`STARVED_US`]) ends the flying, else the least late is judged, each
/// starved flight and that choice said under `name`.
pub struct LeastLate<T> {
    name: String,
    least: Option<(f64, usize, T)>,
}

impl<T> LeastLate<T> {
    /// No flight offered yet.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            least: None,
        }
    }

    /// Offers flight `attempt` (from 1), whose latest tick ran `late` µs
    /// late; returns whether it was on time (then fly no more).
    pub fn offer(&mut self, attempt: usize, late: f64, flight: T) -> bool {
        let on_time = late <= STARVED_US;
        if !on_time {
            println!(
                "{}: the machine starved flight {attempt} (lateness {late:.0} µs){}",
                self.name,
                if attempt < STARVED_ATTEMPTS {
                    ": flown again"
                } else {
                    ""
                }
            );
        }
        if self.least.as_ref().is_none_or(|(l, _, _)| late < *l) {
            self.least = Some((late, attempt, flight));
        }
        on_time
    }

    /// The flight to judge and its attempt: the one on time, else the
    /// least late (said). Panics when none was offered.
    pub fn judged(self) -> (usize, T) {
        let (late, attempt, flight) = self.least.expect("at least one flight");
        if late > STARVED_US {
            println!(
                "{}: every flight was starved; the least late ({late:.0} µs) is judged",
                self.name
            );
        }
        (attempt, flight)
    }
}

/// The `[realtime]` table of a flight judged to centimetres: the control
/// thread at SCHED_FIFO 50 (its link threads at 49), as the daemon is
/// deployed on a companion computer that does other work
/// (docs/deployment.md), when this machine grants it (root or
/// `CAP_SYS_NICE` with `RLIMIT_RTPRIO`); empty where it does not, and said
/// once. Without it two busy loops on two cores delay the daemon's ticks by
/// up to 50 ms (its own records' `jitter_us`), and a centimetre budget then
/// judges the scheduler, not the controller.
#[allow(dead_code)]
pub fn realtime_if_granted() -> &'static str {
    static GRANTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let granted = *GRANTED.get_or_init(|| {
        let probe = dflat_daemon::realtime::RealtimeConfig {
            fifo_priority: 1,
            ..Default::default()
        };
        let granted = std::thread::spawn(move || {
            dflat_daemon::realtime::apply_to_current_thread(&probe).is_ok()
        })
        .join()
        .unwrap_or(false);
        if !granted {
            eprintln!(
                "realtime: SCHED_FIFO not granted here; the flight runs on the normal \
                 scheduler (its figures then depend on this machine's load)"
            );
        }
        granted
    });
    if granted {
        "[realtime]\nfifo_priority = 50\n"
    } else {
        ""
    }
}

/// When [`fly_in_process_until`] ends a flight: `fly` after the daemon's
/// first attitude target, `cap` after the start, or `settle` after its
/// condition first held, whichever comes first.
#[derive(Debug, Clone, Copy)]
pub struct FlightEnd {
    pub fly: Duration,
    pub cap: Duration,
    pub settle: Duration,
}

/// As [`fly_in_process`], ending also `end.settle` after `done` first
/// holds for the SITL's true position (NED, m): a flight judged on
/// reaching its path's end flies until it does, however slowly a loaded
/// machine brought the daemon up and engaged it.
pub fn fly_in_process_until(
    name: &str,
    config_text: &str,
    end: FlightEnd,
    done: impl Fn([f64; 3]) -> bool,
) -> Flight {
    fly_in_process_with(name, config_text, end, done, |_, _| {})
}

/// As [`fly_in_process_until`], handing the SITL to `during` with the time
/// since the daemon's first command (zero before it) at every frame the
/// daemon sends: a test's faults (dropped or late poses) go in there.
pub fn fly_in_process_with(
    name: &str,
    config_text: &str,
    end: FlightEnd,
    done: impl Fn([f64; 3]) -> bool,
    mut during: impl FnMut(&sitl::SitlHandle, Duration),
) -> Flight {
    let dir = scratch(name);
    let text = config_text.replace("@DIR@", &dir.display().to_string());
    let (config, _) = write_daemon_config(&dir, &format!("{name}.toml"), &text);
    let options = TapOptions {
        record_trace: true,
        ..TapOptions::default()
    };
    let (sim, tap) = tapped_sitl(&config, options);
    let summary = dir.join(SUMMARY_JSON).display().to_string();
    let mut daemon = spawn_daemon_with(
        &dir,
        &config,
        sim.local_addr(),
        &["--summary-json", summary.as_str()],
    );
    let start = Instant::now();
    let mut frames = Vec::new();
    let mut first_target: Option<Instant> = None;
    let mut done_at: Option<Instant> = None;
    while start.elapsed() < end.cap
        && first_target.is_none_or(|t| t.elapsed() < end.fly)
        && done_at.is_none_or(|t| t.elapsed() < end.settle)
    {
        if let Ok(f) = tap.recv_timeout(Duration::from_millis(100)) {
            if matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)) {
                first_target.get_or_insert(f.at);
            }
            frames.push(f);
            during(&sim, first_target.map_or(Duration::ZERO, |t| t.elapsed()));
        }
        if done_at.is_none() && done(sim.truth().position) {
            done_at = Some(Instant::now());
        }
    }
    let clean_exit = daemon.interrupt_and_wait(Duration::from_secs(5));
    let report = sim.stop().expect("sitl stop");
    frames.extend(tap.try_iter());
    Flight {
        frames,
        dir,
        report,
        clean_exit,
    }
}

/// A flight's configuration (TOML): `tables`, then the records (CSV, no
/// tlog) in `dir` and the SITL's table, its vehicle at rest at NED
/// (0, 0, −10) m, with the further keys `sitl`.
pub fn flight_config(dir: &Path, tables: &str, sitl: &str) -> String {
    format!(
        "{tables}\n[logging]\ndir = \"{}\"\ntlog = false\n[sitl]\nstart = [0.0, 0.0, -10.0]\n{sitl}\n",
        dir.display()
    )
}

/// As [`flight_config`] for a vehicle that flies `path` (NED \[m\]) at
/// `speed` \[m/s\] from the start: `more` holds any more tables.
pub fn path_config(dir: &Path, path: &[[f64; 3]], speed: f64, more: &str, sitl: &str) -> String {
    let mission = format!("[mission]\nstart = \"path\"\npath = {path:?}\nspeed = {speed:?}");
    flight_config(dir, &format!("{mission}\n{more}"), sitl)
}

/// The tilt limit of the flights of [`hold_config`] \[deg\] (the
/// daemon's default, written out).
pub const MAX_TILT_DEG: f64 = 35.0;

/// As [`flight_config`] for a vehicle that holds where it starts, at the
/// tilt limit [`MAX_TILT_DEG`]: `mission` holds the mission table's
/// further keys and any more tables.
pub fn hold_config(dir: &Path, mission: &str, sitl: &str) -> String {
    let vehicle = format!("[vehicle]\nmax_tilt_deg = {MAX_TILT_DEG}");
    let tables = format!("[mission]\nstart = \"hold\"\n{mission}\n{vehicle}");
    flight_config(dir, &tables, sitl)
}

/// A short L (8 m north, then 6 m east, at 4 m/s) with the daemon's
/// records in `@DIR@`, for [`fly_in_process`].
pub const SHORT_L: &str = r#"
[mission]
start = "path"
path = [[0.0, 0.0, -10.0], [8.0, 0.0, -10.0], [8.0, 6.0, -10.0]]
speed = 4.0
[logging]
dir = "@DIR@"
tlog = false
"#;

/// The daemon's spatial model with normalised thrust (PX4 style), hover
/// at 0.5.
pub const SPATIAL_VEHICLE: &str = r#"[vehicle]
model = "spatial"
thrust_mode = "normalized"
hover_thrust = 0.5
"#;

/// The SITL's keys for the shipped tuning with realistic sensing: the
/// planar plant, 1 cm position noise.
pub const PLANAR_NOISY: &str = "plant = \"planar\"\nnoise_sigma = 0.01";

/// Writes the configuration `text` as `dir/file`, starts the SITL (with
/// its ground-station port if `gcs`) writing its truth to
/// `dir/truth.csv`, and the daemon against it; returns them and the truth
/// file once the daemon commands the SITL (its offboard mode, within 15 s).
pub fn start_flight(dir: &Path, file: &str, text: &str, gcs: bool) -> (Sitl, Proc, PathBuf) {
    let config = write_config(dir, file, text);
    let truth = dir.join("truth.csv");
    let sitl = spawn_sitl(dir, &config, gcs, &truth);
    let daemon = spawn_daemon(dir, &config, sitl.link);
    assert!(
        sitl.wait_for_line("sitl mode offboard", Duration::from_secs(15))
            .is_some(),
        "the daemon never commanded the SITL"
    );
    (sitl, daemon, truth)
}

/// Which ports and records the in-process SITL of [`tapped_sitl`] opens.
#[derive(Debug, Clone, Copy, Default)]
pub struct TapOptions {
    /// Open its ground-station port too (loopback, port 0).
    pub gcs: bool,
    /// Keep its truth trace for the report.
    pub record_trace: bool,
}

/// The in-process SITL with the settings of `config`, listening on
/// loopback (port 0), and the tap on which it hands over every frame the
/// daemon sends it.
pub fn tapped_sitl(config: &Path, options: TapOptions) -> (sitl::SitlHandle, Receiver<TapFrame>) {
    let (tx, tap) = channel();
    let sim = sitl::spawn(
        &dflat_sitl::SitlSettings::load(config).expect("sitl config"),
        SitlOptions {
            link: Some("udpin:127.0.0.1:0".into()),
            gcs: options.gcs.then(|| "udpin:127.0.0.1:0".into()),
            tap: Some(tx),
            record_trace: options.record_trace,
            ..SitlOptions::default()
        },
    )
    .expect("sitl");
    (sim, tap)
}

/// The in-process SITL with the settings `plant`, keeping its truth trace.
pub fn traced_sitl(plant: &dflat_sitl::SitlSettings) -> sitl::SitlHandle {
    let options = SitlOptions {
        record_trace: true,
        ..SitlOptions::default()
    };
    sitl::spawn(plant, options).expect("sitl")
}

/// Waits (at most `limit`) until the SITL's true position is within
/// `within` \[m\] of `end` (NED \[m\]), and a second more; whether it got
/// there.
pub async fn arrive_and_linger(
    sitl: &sitl::SitlHandle,
    end: [f64; 3],
    within: f64,
    limit: Duration,
) -> bool {
    let until = Instant::now() + limit;
    let mut arrived: Option<Instant> = None;
    while Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(20)).await;
        if arrived.is_none() && dist(sitl.truth().position, end) < within {
            arrived = Some(Instant::now());
        }
        if arrived.is_some_and(|t| t.elapsed() > Duration::from_secs(1)) {
            break;
        }
    }
    arrived.is_some()
}

/// Writes `text` as `dir/file` (as [`write_config`]) and loads it as the
/// daemon's configuration, which must be valid.
pub fn write_daemon_config(dir: &Path, file: &str, text: &str) -> (PathBuf, Config) {
    let config = write_config(dir, file, text);
    let cfg = Config::load(&config).expect("daemon config");
    (config, cfg)
}

/// Waits (at most 15 s) until the daemon has streamed attitude targets
/// for `hold` on the `tap` (whose frames it takes); false if it never
/// streamed.
pub fn wait_streaming(tap: &Receiver<TapFrame>, hold: Duration) -> bool {
    let until = Instant::now() + Duration::from_secs(15);
    let mut since: Option<Instant> = None;
    while Instant::now() < until {
        std::thread::sleep(Duration::from_millis(50));
        let n = tap
            .try_iter()
            .filter(|f| matches!(f.message, MavMessage::SET_ATTITUDE_TARGET(_)))
            .count();
        if n > 0 && since.get_or_insert_with(Instant::now).elapsed() > hold {
            break;
        }
    }
    since.is_some()
}

/// The daemon's local address from its log line `daemon started ... local=Some(ADDR)`.
pub fn daemon_local_addr(daemon: &Proc, limit: Duration) -> Option<SocketAddr> {
    let until = Instant::now() + limit;
    while Instant::now() < until {
        let text = daemon.stderr_text();
        if let Some(rest) = text.split("local=Some(").nth(1)
            && let Some(addr) = rest.split(')').next()
            && let Ok(a) = addr.parse()
        {
            return Some(a);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    None
}

/// The shipped SITL configuration as `dflat demo` flies it (L path at
/// 5 m/s, `mission.start = "path"`), without flight records, and with the
/// SITL's engagement `engage`: the demo plays a pilot (`Pilot`); most
/// tests want the vehicle engaged as soon as the stream runs (`Auto`).
pub fn sitl_flight(
    name: &str,
    engage: dflat_sitl::SitlEngage,
) -> (Config, dflat_sitl::SitlSettings) {
    let out = std::env::temp_dir().join(format!("dflat-{name}-{}", std::process::id()));
    let (mut cfg, mut plant) = dflat::demo::demo_config(&dflat::demo::DemoOptions {
        speed: 5.0,
        out,
        seconds: None,
    })
    .unwrap();
    cfg.logging.dir = String::new();
    plant.sitl.engage = engage;
    (cfg, plant)
}

/// Every command the daemon's ticks produced (`summary.commands`) reached
/// the SITL, accounted for on the daemon's own counters: each was sent
/// (and the SITL, `accepted`, flew exactly those sent), or replaced in
/// the send task's slot by a newer one before it went out (a link task
/// late under load: the newer command is what flies), or dropped there as
/// stale; one may still sit in the slot at shutdown.
pub fn assert_commands_delivered(summary: &dflat_daemon::FlightSummary, accepted: u64) {
    let lg = &summary.link_guard;
    let sent = summary.link_stats.sent.set_attitude_target;
    assert_eq!(accepted, sent, "the SITL flew {accepted} of {sent} sent");
    let accounted = sent + lg.commands_replaced + lg.commands_stale;
    assert!(
        accounted <= summary.commands && accounted + 1 >= summary.commands,
        "commands {}: sent {sent}, replaced {}, stale {}",
        summary.commands,
        lg.commands_replaced,
        lg.commands_stale
    );
}
