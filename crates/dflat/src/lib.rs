//! # dflat — discrete-flatness MPC flight control for multirotors
//!
//! The one binary, `dflat`, and where the daemon and the lab meet:
//!
//! * [`cli`] — the command line (`daemon`, `check-config`; with the `sitl`
//!   feature `sitl`; with `lab` `demo` and `experiment`; with `tuning`
//!   `identify`, `review` and `replay`).
//! * [`demo`] (`lab`) — `dflat demo`: the SITL of `dflat-sitl` and the
//!   daemon of `dflat-daemon` on loopback.
//! * [`tools`] (`tuning`) — the shells of `identify`, `learn`, `review`
//!   and `replay` around the library `dflat-tuning`; the replay re-runs the
//!   daemon's pure tick, so it lives here, where the daemon and the tools
//!   meet.
//!
//! Features (all three default): `sitl` links `dflat-sitl` (and its plants,
//! `dflat-sim`), `lab` links `dflat-lab` (the harness, the experiments, the
//! plots; it implies `sitl` for `dflat demo`), `tuning` links
//! `dflat-tuning`. The onboard build leaves them out:
//! `cargo build --release -p dflat --no-default-features` gives a binary
//! with `daemon` and `check-config` only (what `deploy/install.sh`
//! installs).

/// `print!` that never panics: with stdout gone (`dflat … | head -1`, a
/// closed terminal) the text is lost, not the process or what follows it.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = write!(std::io::stdout(), $($t)*);
    }};
}

/// `eprintln!` that never panics (see `out!`): a closed stderr loses the text.
macro_rules! errln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

/// `println!` that never panics (see `out!`).
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}

pub mod cli;
#[cfg(feature = "lab")]
pub mod demo;
#[cfg(feature = "lab")]
mod experiment;
#[cfg(feature = "sitl")]
mod sitl_demo;
/// `dflat demo --stream`: a planner's stream flown on the SITL.
#[cfg(feature = "lab")]
pub mod stream_demo;
/// The tuning tools' library (flight logs, identification, the learned
/// residual, the review page).
#[cfg(feature = "tuning")]
pub use dflat_tuning as tuning;
/// The tuning tools' shells (`dflat identify`, `learn`, `review`,
/// `replay`) and the replay of the daemon's tick.
#[cfg(feature = "tuning")]
pub mod tools;

pub use cli::main;
