//! # dflat — discrete-flatness MPC flight control for multirotors
//!
//! The one binary, `dflat`, and where the daemon and the lab meet:
//!
//! * [`cli`] — the command line (`daemon`, `check-config`, and with the `lab`
//!   feature `sitl`, `demo`, `experiment`).
//! * [`demo`] (`lab`) — `dflat demo`: the SITL of `dflat-sim` and the daemon
//!   of `dflat-daemon` on loopback.
//!
//! Features: `lab` (default) links the simulation lab, the SITL and the
//! plotting. The onboard build leaves it out:
//! `cargo build --release -p dflat --no-default-features` gives a binary
//! with `daemon` and `check-config` only (what `deploy/install.sh`
//! installs).

pub mod cli;
#[cfg(feature = "lab")]
pub mod demo;
#[cfg(feature = "lab")]
mod experiment;
#[cfg(feature = "lab")]
mod sitl_demo;
/// `dflat demo --stream`: a planner's stream flown on the SITL.
#[cfg(feature = "lab")]
pub mod stream_demo;
#[cfg(feature = "lab")]
pub mod tuning;

pub use cli::main;
