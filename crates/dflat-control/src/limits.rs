//! The allowed range of a numeric setting, stated once.
//!
//! Each settings type owns one [`Limit`] per numeric field (associated
//! constants such as [`crate::dfmpc::DfMpcSettings::HORIZON`]). Its
//! `validate` checks the field against it, and a shell that reads the
//! setting from a file (the daemon's `[controller.*]` tables) checks the
//! file's value against the same constant under its own name for the
//! field. There is no second range.

use std::fmt;

use crate::ControlError;

/// The allowed values of one numeric setting: `min ≤ x ≤ max` (or
/// `min < x` when `min_open`), finite, in `unit`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limit {
    /// Lower bound, in `unit`.
    pub min: f64,
    /// Upper bound, in `unit` (`f64::INFINITY`: none).
    pub max: f64,
    /// True when `min` itself is not allowed (`x > min`).
    pub min_open: bool,
    /// Unit of the bounds, as written after them (e.g. `"ticks"`, `"deg"`).
    pub unit: &'static str,
}

/// Relative slack on a bound for values converted between units (a limit
/// in degrees checked on a value in radians).
const CONVERSION_SLACK: f64 = 1e-12;

impl Limit {
    /// `min ≤ x ≤ max` \[`unit`\].
    pub const fn closed(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: false,
            unit,
        }
    }

    /// `min < x ≤ max` \[`unit`\].
    pub const fn above(min: f64, max: f64, unit: &'static str) -> Self {
        Self {
            min,
            max,
            min_open: true,
            unit,
        }
    }

    /// `0 < x < ∞` \[`unit`\].
    pub const fn positive(unit: &'static str) -> Self {
        Self::above(0.0, f64::INFINITY, unit)
    }

    /// True when `x` is finite and inside the limit.
    pub fn contains(&self, x: f64) -> bool {
        x.is_finite()
            && if self.min_open {
                x > self.min
            } else {
                x >= self.min
            }
            && x <= self.max
    }

    /// [`Limit::contains`] for a value `x` converted from another unit (a
    /// relative slack of 1e-12 on the bounds absorbs the rounding, so
    /// 60° → rad → deg is still at most 60°).
    pub fn contains_converted(&self, x: f64) -> bool {
        let slack = |b: f64| CONVERSION_SLACK * b.abs().max(1.0);
        x.is_finite()
            && if self.min_open {
                x > self.min
            } else {
                x >= self.min - slack(self.min)
            }
            && x <= self.max + slack(self.max)
    }

    /// `Ok` when `x` is inside, else [`ControlError::InvalidSetting`]
    /// naming `field` with the value and the allowed range.
    pub fn check(&self, field: &'static str, x: f64) -> Result<(), ControlError> {
        if self.contains(x) {
            Ok(())
        } else {
            Err(self.error(field, x))
        }
    }

    /// `check` for every element of `xs`.
    pub fn check_all(&self, field: &'static str, xs: &[f64]) -> Result<(), ControlError> {
        xs.iter().try_for_each(|x| self.check(field, *x))
    }

    /// `check` on a value in radians against a limit in degrees.
    pub fn check_radians(&self, field: &'static str, rad: f64) -> Result<(), ControlError> {
        let deg = rad.to_degrees();
        if self.contains_converted(deg) {
            Ok(())
        } else {
            Err(self.error(field, deg))
        }
    }

    /// The [`ControlError::InvalidSetting`] for `x` out of this limit.
    pub fn error(&self, field: &'static str, x: f64) -> ControlError {
        ControlError::InvalidSetting {
            field,
            reason: format!("{x}: allowed {self}"),
        }
    }
}

impl fmt::Display for Limit {
    /// `"10 to 2000 ticks"`, `"> 0 to 50 m/s"`, `"finite and > 0 1/m²"`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        match (self.min_open, self.max.is_finite()) {
            (true, false) => write!(f, "finite and > {}{unit}", self.min),
            (false, false) => write!(f, "finite and >= {}{unit}", self.min),
            (true, true) => write!(f, "> {} to {}{unit}", self.min, self.max),
            (false, true) => write!(f, "{} to {}{unit}", self.min, self.max),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_messages() {
        let h = Limit::closed(10.0, 2000.0, "ticks");
        assert!(h.contains(10.0) && h.contains(2000.0));
        assert!(!h.contains(9.0) && !h.contains(2001.0) && !h.contains(f64::NAN));
        assert_eq!(h.to_string(), "10 to 2000 ticks");
        let e = h.check("horizon", 5.0).unwrap_err().to_string();
        assert_eq!(e, "invalid setting horizon: 5: allowed 10 to 2000 ticks");
        let p = Limit::positive("1/m²");
        assert!(!p.contains(0.0) && p.contains(1e-300) && !p.contains(f64::INFINITY));
        assert_eq!(p.to_string(), "finite and > 0 1/m²");
        let s = Limit::above(0.0, 50.0, "m/s");
        assert!(!s.contains(0.0) && s.contains(50.0) && !s.contains(50.1));
        assert_eq!(s.to_string(), "> 0 to 50 m/s");
        assert!(s.check_all("v", &[1.0, 0.0]).is_err());
    }

    #[test]
    fn degrees_round_trip_through_radians() {
        let tilt = Limit::closed(1.0, 60.0, "deg");
        assert!(tilt.check_radians("t", 60f64.to_radians()).is_ok());
        assert!(tilt.check_radians("t", 1f64.to_radians()).is_ok());
        assert!(tilt.check_radians("t", 60.001f64.to_radians()).is_err());
        assert!(tilt.check_radians("t", 0.5f64.to_radians()).is_err());
    }
}
