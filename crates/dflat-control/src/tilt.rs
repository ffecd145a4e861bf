//! Tilt limits on a pitch / roll command pair (ZYX Euler angles \[rad\]).
//!
//! The paper saturates each input channel separately ([`TiltLimit::PerAxis`]):
//! with both at a 35° limit the vehicle tilts by 47.9°. An autopilot (PX4's
//! `MPC_TILTMAX_AIR`, ArduPilot's `ANGLE_MAX`) and the daemon's exit guard
//! bound the *tilt* — the angle between body z and the vertical, with
//! `cos(tilt) = cos θ · cos φ` — so a controller whose commands are then
//! cut again downstream records in its window an input that was never sent.
//! [`TiltLimit::Cone`] applies the tilt bound in the controller itself:
//! pitch and roll are scaled together (direction kept) until the tilt is
//! within the limit, and what the window records is what leaves.

use std::f64::consts::FRAC_PI_2;

use serde::{Deserialize, Serialize};

/// How a tilt limit applies to a pitch / roll pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TiltLimit {
    /// |pitch| and |roll| each clipped to the limit (the paper; the lab's
    /// plants apply the same clip). The tilt can reach 47.9° at a 35° limit.
    #[default]
    PerAxis,
    /// The tilt bounded by the limit: pitch and roll scaled by one factor
    /// (the daemon, whose exit guard bounds the tilt the same way).
    Cone,
}

/// Tilt of a pitch / roll pair: the angle between body z and the vertical
/// \[rad\], `acos(cos θ · cos φ)`, in \[0, π\].
pub fn tilt(pitch: f64, roll: f64) -> f64 {
    (pitch.cos() * roll.cos()).clamp(-1.0, 1.0).acos()
}

/// Applies the tilt limit `max` \[rad\], in (0, π/2), to `(pitch, roll)`
/// \[rad\]. Returns the limited pair and whether it changed. Non-finite
/// input is returned unchanged (the caller's finiteness check refuses it).
///
/// [`TiltLimit::Cone`]: the pair scaled by one factor s ∈ (0, 1) so the
/// tilt is at most `max` and within 1e-9 relative of it (fixed-point
/// steps s ← s·max/tilt, bisection on s when those do not settle); a
/// channel beyond ±90° (not a tilt: cos is periodic) is clipped to ±`max`
/// first. Either way |pitch|, |roll| ≤ tilt ≤ `max` afterwards.
pub fn limit_tilt(pitch: f64, roll: f64, max: f64, mode: TiltLimit) -> (f64, f64, bool) {
    match mode {
        TiltLimit::PerAxis => {
            let (p, r) = (pitch.clamp(-max, max), roll.clamp(-max, max));
            (p, r, p != pitch || r != roll)
        }
        TiltLimit::Cone => {
            if !(pitch.is_finite() && roll.is_finite()) {
                return (pitch, roll, false);
            }
            // Beyond ±90° a channel's angle is no longer a tilt in the
            // cone's sense (θ = φ = π is upright, and so is 2π): such a
            // pair is clipped per channel first, then limited as a tilt.
            let (p0, r0) = if pitch.abs() <= FRAC_PI_2 && roll.abs() <= FRAC_PI_2 {
                (pitch, roll)
            } else {
                (pitch.clamp(-max, max), roll.clamp(-max, max))
            };
            let clipped = (p0, r0) != (pitch, roll);
            if tilt(p0, r0) <= max {
                return (p0, r0, clipped);
            }
            let f = |s: f64| tilt(s * p0, s * r0);
            // Fixed point s ← s·max/tilt: two or three steps below 90°.
            let mut s = 1.0;
            for _ in 0..8 {
                let t = f(s);
                if t <= max {
                    return (s * p0, s * r0, true);
                }
                s *= max / t * (1.0 - 1e-9);
            }
            // Not settled (it should: within ±90° per channel the tilt grows
            // along the ray): bisect between s = 0 (level) and s = 1.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..64 {
                let mid = 0.5 * (lo + hi);
                if f(mid) <= max {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            (lo * p0, lo * r0, true)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    #[test]
    fn per_axis_lets_the_combined_tilt_exceed_the_limit() {
        let max = 35f64.to_radians();
        let (p, r, hit) = limit_tilt(0.9, -0.9, max, TiltLimit::PerAxis);
        assert!(hit && p == max && r == -max);
        assert!((tilt(p, r).to_degrees() - 47.855).abs() < 0.001);
        let (p, r, hit) = limit_tilt(0.9, -0.9, max, TiltLimit::Cone);
        assert!(hit && (tilt(p, r) - max).abs() < 1e-6, "{}", tilt(p, r));
        assert!((p + r).abs() < 1e-15, "direction kept");
    }

    proptest! {
        #[test]
        fn cone_bounds_the_tilt_and_keeps_the_direction(
            pitch in prop_oneof![-1.6f64..1.6, -40.0f64..40.0],
            roll in prop_oneof![-1.6f64..1.6, -40.0f64..40.0],
            max_deg in 1.0f64..89.0,
        ) {
            let max = max_deg.to_radians();
            let (p, r, hit) = limit_tilt(pitch, roll, max, TiltLimit::Cone);
            prop_assert!(tilt(p, r) <= max);
            prop_assert!(p.abs() <= max && r.abs() <= max, "{p} {r}");
            let in_range = pitch.abs() <= FRAC_PI_2 && roll.abs() <= FRAC_PI_2;
            if !hit {
                prop_assert_eq!((p, r), (pitch, roll));
            } else if in_range {
                // Same direction, on the cone's edge (to 1e-6 rad).
                prop_assert!((p * roll - r * pitch).abs() <= 1e-12 * (1.0 + pitch.abs() + roll.abs()));
                prop_assert!(p * pitch >= 0.0 && r * roll >= 0.0);
                prop_assert!(tilt(p, r) > max - 1e-6, "{} vs {}", tilt(p, r), max);
            }
        }

        #[test]
        fn multiples_of_a_turn_are_not_level(k in 1i32..8, max_deg in 1.0f64..89.0) {
            // cos is periodic: θ = φ = kπ has "tilt" 0 by the formula.
            let a = f64::from(k) * PI;
            let max = max_deg.to_radians();
            let (p, r, hit) = limit_tilt(a, -a, max, TiltLimit::Cone);
            prop_assert!(hit && p.abs() <= max && r.abs() <= max, "{p} {r}");
        }

        #[test]
        fn per_axis_is_a_clip(pitch in -3.0f64..3.0, roll in -3.0f64..3.0, max in 0.01f64..1.5) {
            let (p, r, hit) = limit_tilt(pitch, roll, max, TiltLimit::PerAxis);
            prop_assert_eq!((p, r), (pitch.clamp(-max, max), roll.clamp(-max, max)));
            prop_assert_eq!(hit, pitch.abs() > max || roll.abs() > max);
        }
    }
}
