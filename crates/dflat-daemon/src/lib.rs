//! # dflat-daemon — the flight-control daemon's runtime
//!
//! The imperative shell around `dflat-control`: configuration, MAVLink link
//! tasks, the 50 Hz control loop, failsafe state machine, telemetry and the
//! SITL autopilot stand-in.

pub mod config;
