//! # dflat-sim — dflat's simulation lab
//!
//! Plants, sensor models, a closed-loop harness and plot helpers for the
//! controllers of `dflat-control`, and the SITL. Everything but [`sitl`] is pure and deterministic
//! from seeds: no wall clock, no global RNG. Time is simulated time \[s\].
//!
//! * [`plant`] — vehicle stand-ins integrated with RK4 at 200 Hz (default),
//!   the command held between 50 Hz controller ticks: a planar plant with
//!   first-order attitude (paper §IV-B), a spatial plant that adds altitude
//!   through collective thrust, and a 12-state rigid body with an inner
//!   attitude/rate autopilot. Options cover command saturation, drag, wind
//!   and gusts, and model mismatch ([`plant::PlantOptions`]).
//! * [`sensing`] — what the controller sees: Gaussian position noise at the
//!   control rate, or a vision stand-in (15 Hz, latency, noise, dropouts,
//!   jitter; paper §VII-B) extrapolated, held or passed raw.
//! * [`harness`] — [`harness::run_trial`] / [`harness::run_trials`]: one or
//!   many closed loops (rayon, results in input order, bit-identical for a
//!   seed regardless of thread count), per-tick logs (CSV) and metrics.
//! * [`plot`] — plotters wrappers (SVG + PNG, vendored font): line plots,
//!   x-y path plots, grouped box plots, in the paper's colours.
//! * [`sitl`] — the SITL autopilot stand-in: a real-time plant behind a
//!   MAVLink link (std threads, the wall clock), the plant process of
//!   `dflat sitl` and `dflat demo`. The one part of the lab that does I/O.
//! * [`trajectory`] — a planner's circle and figure eight (p, v, a, yaw).
//!   The anchor the goal tests compare with — a PD position loop with
//!   velocity and acceleration feed-forward, PX4's in effect — is the
//!   SITL's own OFFBOARD position loop ([`sitl::position_control`], pure).
//! * [`experiments`] — the paper's studies (noise sweep, L-path comparison,
//!   DSL demonstration): pure runs returning results, JSON and plot writers.
//!
//! Conventions (`docs/ARCHITECTURE.md`, the README): local NED \[m\], body FRD, ZYX Euler angles
//! \[rad\], specific thrust [m/s²] (thrust / mass), SI units throughout.

pub mod experiments;
pub mod flightlog;
pub mod harness;
pub mod identify;
pub mod plant;
pub mod plot;
pub mod sensing;
pub mod sitl;
pub mod trajectory;

mod error;
mod rng;

pub use error::SimError;
