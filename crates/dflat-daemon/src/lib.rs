//! # dflat-daemon — the flight-control daemon's runtime
//!
//! The imperative shell around `dflat-control`: configuration, MAVLink link
//! tasks, the 50 Hz control loop, failsafe state machine and telemetry. It
//! depends on the pure core (`dflat-model`, `dflat-control`) and the link
//! (`dflat-link`) only: no lab, no plotting, no random numbers. The SITL
//! autopilot stand-in lives in `dflat-sitl`; `dflat demo` composes both in the
//! binary crate.
//!
//! * [`commands`] — the command protocol: COMMAND_ACK, REQUEST_MESSAGE (pure).
//! * [`autopilot_params`], [`stream_rates`] — what the daemon asks the
//!   autopilot at start-up: its hover thrust and tilt limit, its pose and
//!   ATTITUDE at the tick rate (pure).
//! * [`config`] — the TOML schema, defaults and validation.
//! * [`daemon`] — `dflat daemon`: [`daemon::run`], [`daemon::spawn`].
//! * [`supervisor`] — the flight state machine (pure).
//! * [`schedule`] — the control loop's absolute-deadline tick schedule (pure).
//! * [`control`] — controller, reference and thrust mapping from the config.
//! * [`clock`] — pose capture times on this computer's clock (offset
//!   estimate from the source timestamps).
//! * [`guard`] — the command exit guard, fallback, pose-jump and residual
//!   checks, the systemd watchdog cadence (pure).
//! * [`signing`] — MAVLink 2 signing: key file, persisted timestamp.
//! * [`realtime`] — SCHED_FIFO, CPU affinity and locked memory for the
//!   control thread (optional, safe APIs).
//! * [`records`] — per-flight CSV and file names.
//! * [`csv_schema`] — the per-tick CSV's columns, shared with the offline
//!   reader (`dflat-tuning`).
//! * [`summary`] — measurements and the shutdown summary.

pub mod autopilot_params;
pub mod clock;
pub mod commands;
pub mod config;
pub mod control;
pub mod csv_schema;
pub mod daemon;
pub mod envelope;
pub mod guard;
pub mod learned;
pub mod link_health;
pub mod mission;
pub mod motion;
pub mod realtime;
pub mod record_store;
pub mod records;
pub mod schedule;
pub mod signing;
pub mod stream_rates;
pub mod summary;
pub mod supervisor;
pub mod tick;
pub mod yaw;

pub use daemon::{
    DaemonError, DaemonHandle, daemon_signals, run, shutdown_signal, spawn, spawn_with_controller,
};
pub use summary::FlightSummary;
