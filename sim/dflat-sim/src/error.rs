//! The simulation crates' error type and the option checks they share.

use thiserror::Error;

/// Why a lab operation could not run. Data problems inside a trial (a
/// controller error, a diverging plant) are *results*, not errors; these are
/// invalid set-ups and I/O failures.
#[derive(Debug, Error)]
pub enum SimError {
    /// An option is out of range; names the field and the allowed range.
    #[error("invalid option {field} = {value}: allowed {allowed}")]
    InvalidOption {
        /// The option's name, dotted for nested structs (`rigid.mass`).
        field: &'static str,
        /// The offending value.
        value: f64,
        /// What is allowed, in words.
        allowed: &'static str,
    },
    /// Writing a log or a plot failed.
    #[error("i/o: {0}")]
    Io(#[from] std::io::Error),
    /// plotters reported an error while drawing.
    #[error("plot {file}: {message}")]
    Plot {
        /// The file being drawn.
        file: String,
        /// plotters' message.
        message: String,
    },
}

/// Checks `lo <= value <= hi` (and finiteness).
pub fn check_range(
    field: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    allowed: &'static str,
) -> Result<(), SimError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(SimError::InvalidOption {
            field,
            value,
            allowed,
        })
    }
}

/// Checks `value > 0` (and finiteness).
pub fn check_positive(field: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SimError::InvalidOption {
            field,
            value,
            allowed: "finite and > 0",
        })
    }
}
