//! # dflat-sim — dflat's simulated vehicles
//!
//! Plants, sensor models and trajectories for the controllers of
//! `dflat-control`: pure and deterministic from seeds (no wall clock, no
//! global RNG, no I/O). Time is simulated time \[s\]. The SITL
//! (`dflat-sitl`) runs these plants in real time behind MAVLink; the lab
//! (`dflat-lab`) flies them in closed-loop trials.
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
//! * [`trajectory`] — a planner's circle and figure eight (p, v, a, yaw).
//!   The anchor the goal tests compare with — a PD position loop with
//!   velocity and acceleration feed-forward, PX4's in effect — is the
//!   SITL's own OFFBOARD position loop (`dflat_sitl::position_control`,
//!   pure).
//! * [`error`] — [`SimError`] and the option range checks the simulation
//!   crates share.
//!
//! Conventions (`docs/ARCHITECTURE.md`, the README): local NED \[m\], body
//! FRD, ZYX Euler angles \[rad\], specific thrust [m/s²] (thrust / mass), SI
//! units throughout.

pub mod error;
pub mod plant;
pub mod sensing;
pub mod trajectory;

mod rng;

pub use error::SimError;
