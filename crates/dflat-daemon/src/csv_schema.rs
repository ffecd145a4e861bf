//! The per-tick flight CSV's columns: the schema of `dflat-records`
//! ([`dflat_records::schema`]), which the offline tools read by too.

pub use dflat_records::schema::*;
