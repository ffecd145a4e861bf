//! # dflat-records — the flight records' schema
//!
//! What the daemon writes and the tuning tools read, in one small crate
//! with no I/O runtime (no tokio, no MAVLink), so the tools need not link
//! the daemon to read a flight:
//!
//! * [`schema`] — the per-tick CSV's columns ([`Column`], [`CSV_HEADER`])
//!   and the check of a header ([`check_header`]).
//! * [`names`] — the flight files' names (`flight-YYYYmmdd-HHMMSS.csv` /
//!   `.tlog`).
//!
//! The `.tlog` is MAVLink's own format (`dflat_link::tlog`).

pub mod names;
pub mod schema;

pub use schema::{CSV_HEADER, Column, SchemaError, check_header};
