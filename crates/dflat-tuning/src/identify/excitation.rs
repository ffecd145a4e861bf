//! Which parameters a flight excited: `identify` recommends only those.
//!
//! A parameter is *excited* when both hold:
//!
//! * **its regressor moved**: the signal that carries the parameter varied
//!   enough for the fit to see it. For the thrust time constant τ_T that is
//!   the commanded vertical specific thrust `g/h·c·cosφ·cosθ` [m/s²] (a
//!   level flight's thrust only compensates its tilt, so the vertical
//!   acceleration, and with it τ_T, stays unseen); for the attitude axes the
//!   command's spread, checked before any fit ([`super::MIN_ANGLE_STD_DEG`]);
//!   for the drag the speed's spread, checked by the drag fit;
//! * **its interval is small against its value**: the 95 % half-width is at
//!   most [`MAX_RELATIVE_CI`] of the value, or below the field's absolute
//!   floor (a delay of 0 ± 3 ms is determined, though 3 ms is not a fifth of
//!   0).
//!
//! A parameter that fails is kept at the value flown and said to be
//! unexcited, with the reason; it is never changed to a number with a
//! 30 % interval.

use serde::Serialize;

/// Largest 95 % half-width relative to the value for a parameter to be
/// recommended (0.2: a fifth of the value).
pub const MAX_RELATIVE_CI: f64 = 0.2;
/// Least standard deviation of the commanded vertical specific thrust
/// \[m/s²\] for τ_T to be recommended: climbs and descents, not a level
/// flight's tilt compensation.
pub const MIN_VERTICAL_ACCEL_STD: f64 = 0.3;

/// Whether a flight excited a parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Excitation {
    /// Excited and determined: it may be recommended.
    Excited,
    /// Not excited, or not determined: kept at the value flown; the reason
    /// in words.
    Unexcited(String),
}

impl Excitation {
    /// True for [`Excitation::Excited`].
    pub fn is_excited(&self) -> bool {
        matches!(self, Self::Excited)
    }
}

/// What a parameter's regressor did in the flight, against what it needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Regressor {
    /// What moved, in words (e.g. "vertical specific thrust std").
    pub what: &'static str,
    /// How much it moved (in `unit`).
    pub value: f64,
    /// The least it must move (in `unit`).
    pub needed: f64,
    /// Its unit, for the report.
    pub unit: &'static str,
}

/// The check of one `[vehicle]` field.
///
/// `value` and `ci` are as configured (e.g. the delay in ms); `floor` is the
/// absolute half-width below which the value counts as determined whatever
/// its size (0: none).
pub fn check(value: f64, ci: f64, floor: f64, regressor: Option<Regressor>) -> Excitation {
    if let Some(r) = regressor
        && !(r.value.is_finite() && r.value >= r.needed)
    {
        return Excitation::Unexcited(format!(
            "{} {:.3} {} < {} {}: the flight did not excite it",
            r.what, r.value, r.unit, r.needed, r.unit
        ));
    }
    if !(value.is_finite() && ci.is_finite()) {
        return Excitation::Unexcited("not determined by this flight".into());
    }
    if ci <= floor || ci <= MAX_RELATIVE_CI * value.abs() {
        Excitation::Excited
    } else {
        Excitation::Unexcited(format!(
            "interval ± {ci:.3} is {:.0} % of the value (at most {:.0} %)",
            100.0 * ci / value.abs().max(f64::MIN_POSITIVE),
            100.0 * MAX_RELATIVE_CI
        ))
    }
}

/// Standard deviation \[m/s²\] of the commanded vertical specific thrust
/// `g/h·c(t)·cosφ·cosθ` over the commands in `commands` (time \[s\],
/// normalised thrust), with `tilt_cos` (time \[s\], cosφ·cosθ of the
/// measured attitude, time-ordered) taken at the latest sample at or before
/// each command (the first one before it), hover thrust `hover` and gravity
/// `g` \[m/s²\]. 0 with fewer than two commands or without attitude.
pub fn vertical_accel_std(
    commands: &[(f64, f64)],
    tilt_cos: &[(f64, f64)],
    hover: f64,
    g: f64,
) -> f64 {
    if commands.len() < 2 || tilt_cos.is_empty() || hover.is_nan() || hover <= 0.0 {
        return 0.0;
    }
    let a: Vec<f64> = commands
        .iter()
        .map(|&(t, c)| {
            let i = tilt_cos.partition_point(|(s, _)| *s <= t);
            let cos = tilt_cos[i.saturating_sub(1)].1;
            g / hover * c * cos
        })
        .filter(|a| a.is_finite())
        .collect();
    if a.len() < 2 {
        return 0.0;
    }
    let n = a.len() as f64;
    let mean = a.iter().sum::<f64>() / n;
    (a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn needs(value: f64) -> Option<Regressor> {
        Some(Regressor {
            what: "vertical specific thrust std",
            value,
            needed: MIN_VERTICAL_ACCEL_STD,
            unit: "m/s²",
        })
    }

    /// The level flight of an independent vehicle: τ_T 0.456 ± 0.136 s
    /// (30 %) from a flight that never climbed is not recommended, for
    /// either reason alone.
    #[test]
    fn a_thirty_percent_interval_or_a_level_flight_is_unexcited() {
        assert!(!check(0.456, 0.136, 0.0, None).is_excited());
        assert!(!check(0.456, 0.01, 0.0, needs(0.05)).is_excited());
        assert!(check(0.456, 0.05, 0.0, needs(1.0)).is_excited());
    }

    #[test]
    fn a_small_value_is_determined_below_its_floor() {
        assert!(check(0.0, 3.0, 5.0, None).is_excited());
        assert!(!check(0.0, 8.0, 5.0, None).is_excited());
        assert!(!check(1.0, f64::INFINITY, 5.0, None).is_excited());
        assert!(!check(f64::NAN, 0.1, 5.0, None).is_excited());
    }

    proptest! {
        /// A level flight: the thrust holds the altitude through any tilt
        /// (`c = h/(cosφ·cosθ)`), so the vertical specific thrust is g
        /// throughout and τ_T is unexcited.
        #[test]
        fn level_flight_leaves_the_vertical_unexcited(
            h in 0.2f64..0.8, amp in 0.0f64..0.6, w in 0.2f64..3.0,
        ) {
            let tilt: Vec<(f64, f64)> = (0..500)
                .map(|i| { let t = i as f64 * 0.02; (t, (amp * (w * t).sin()).cos()) })
                .collect();
            let commands: Vec<(f64, f64)> = tilt.iter().map(|&(t, c)| (t, h / c)).collect();
            let std = vertical_accel_std(&commands, &tilt, h, 9.81);
            prop_assert!(std < 1e-9, "{std}");
        }

        /// Climbs: a thrust that swings by ±s of hover gives a std of
        /// g·s/√2 for a sine.
        #[test]
        fn climbs_excite_the_vertical(h in 0.2f64..0.8, s in 0.05f64..0.3) {
            let tilt = vec![(0.0, 1.0)];
            let commands: Vec<(f64, f64)> = (0..1000)
                .map(|i| { let t = i as f64 * 0.02; (t, h * (1.0 + s * (std::f64::consts::PI * t).sin())) })
                .collect();
            let std = vertical_accel_std(&commands, &tilt, h, 9.81);
            let want = 9.81 * s / 2f64.sqrt();
            prop_assert!((std - want).abs() < 0.02 * want, "{std} vs {want}");
            prop_assert!(std > MIN_VERTICAL_ACCEL_STD);
        }
    }
}
