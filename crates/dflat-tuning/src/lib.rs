//! # dflat-tuning — from a flight log to a tuned vehicle, offline
//!
//! * [`flightlog`] — reading a flight's records back: the daemon's `.tlog`
//!   and its per-tick CSV (columns from `dflat_records`' schema).
//! * [`identify`] — system identification from a flight log (`dflat
//!   identify`): τ, k̃ and delay per axis, hover thrust and τ_T, drag.
//! * [`learn`] — the flat maps' residual over the parametric model,
//!   learned from flight records (`dflat learn`).
//! * [`review`] — a flight's report as one self-contained HTML page
//!   (`dflat review`; `dflat replay` draws its re-run into it).
//!
//! A library: errors are values (`thiserror`), nothing is printed, and it
//! links neither the daemon nor an I/O runtime (no tokio: `dflat-link`
//! without its transports). The command-line shells — the arguments, the
//! configuration files, the words printed — and the replay, which re-runs
//! the daemon's pure tick, are in the `dflat` binary (`dflat::tools`).

pub mod flightlog;
pub mod identify;
pub mod learn;
mod page;
pub mod review;
#[cfg(test)]
mod review_tests;
mod svg;
