//! # dflat-lab — dflat's simulation lab
//!
//! Closed-loop trials of `dflat-control`'s controllers on `dflat-sim`'s
//! plants and sensing, the paper's studies and their plots. Pure and
//! deterministic from seeds: no wall clock, no global RNG; the only I/O is
//! writing results (JSON, CSV, SVG/PNG).
//!
//! * [`harness`] — [`harness::run_trial`] / [`harness::run_trials`]: one or
//!   many closed loops (rayon, results in input order, bit-identical for a
//!   seed regardless of thread count), per-tick logs (CSV) and metrics.
//! * [`experiments`] — the paper's studies (noise sweep, L-path comparison
//!   and the DSL demonstration, vision rate, model mismatch and the airframe
//!   terms, tilt cone, phase): pure runs returning results, JSON and plot
//!   writers.
//! * [`plot`] — plotters wrappers (SVG + PNG, the vendored font in
//!   `assets/`): line plots, x-y path plots, grouped box plots, in the
//!   paper's colours.
//!
//! Conventions as in `dflat-sim`: local NED \[m\], body FRD, ZYX Euler angles
//! \[rad\], SI units throughout.

pub mod experiments;
pub mod harness;
pub mod plot;
