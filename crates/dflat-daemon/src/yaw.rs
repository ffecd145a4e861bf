//! Yaw, flown (pure): the commanded heading, rate-limited towards the
//! goal's yaw, and the change of heading of a tilt.
//!
//! **The window stays heading-independent.** The controller's model flies
//! at the fixed reference heading ψ⋆ (`vehicle.yaw_deg`): its pitch and
//! roll are a *world-frame tilt* — the direction of the thrust axis, seen
//! at ψ⋆ — and that is what its window records (sent inputs, and in
//! standby the inputs that explain the measured attitude). Only at the
//! exit is the tilt expressed at the commanded heading ψ
//! ([`tilt_at_heading`]: the same thrust axis, so the same acceleration),
//! and a measured attitude is brought back to ψ⋆ before the window sees
//! it. A heading change therefore changes the command's quaternion, never
//! the window's prediction.

use dflat_link::math::wrap_pi;
use dflat_model::attitude::{pitch_roll_from_ratios, ratios_from_pitch_roll};

/// The pitch and roll \[rad\] (ZYX) at heading `to_yaw` whose thrust axis
/// is that of `(pitch, roll)` at heading `from_yaw` \[rad\]. At or beyond
/// 90° of tilt (no thrust direction to keep) the angles are returned
/// unchanged.
pub fn tilt_at_heading(pitch: f64, roll: f64, from_yaw: f64, to_yaw: f64) -> (f64, f64) {
    match ratios_from_pitch_roll(pitch, roll, from_yaw) {
        Ok((a, b)) => pitch_roll_from_ratios(a, b, to_yaw),
        Err(_) => (pitch, roll),
    }
}

/// The commanded heading: follows a target yaw at no more than the
/// configured yaw rate, along the shorter way round.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YawCommand {
    /// Largest yaw rate \[rad/s\] (> 0).
    max_rate: f64,
    /// The heading commanded at the previous tick \[rad\], and its time \[s\].
    last: Option<(f64, f64)>,
}

impl YawCommand {
    /// A command limited to `max_rate` \[rad/s\], starting from the first
    /// heading it is given.
    pub fn new(max_rate: f64) -> Self {
        Self {
            max_rate,
            last: None,
        }
    }

    /// The heading commanded last, if any \[rad\].
    pub fn current(&self) -> Option<f64> {
        self.last.map(|(y, _)| y)
    }

    /// Starts again from `heading` \[rad\] at `t` \[s\] (standby: the
    /// vehicle's own heading, so an engagement does not turn it).
    pub fn follow(&mut self, t: f64, heading: f64) {
        if heading.is_finite() {
            self.last = Some((wrap_pi(heading), t));
        }
    }

    /// The heading at `t` \[s\]: one step towards `target` (`None`, or not
    /// finite: keep the heading), at most `max_rate · (t − t_previous)`;
    /// the first call starts at `start` \[rad\].
    pub fn step(&mut self, t: f64, target: Option<f64>, start: f64) -> f64 {
        let (yaw, since) = self.last.unwrap_or((wrap_pi(start), t));
        let dt = (t - since).clamp(0.0, 0.1);
        let next = match target.filter(|y| y.is_finite()) {
            Some(goal) => {
                let error = wrap_pi(goal - yaw);
                let limit = self.max_rate * dt;
                wrap_pi(yaw + error.clamp(-limit, limit))
            }
            None => yaw,
        };
        self.last = Some((next, t));
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_model::attitude::thrust_axis;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn a_tilt_keeps_its_thrust_axis_at_any_heading(
            pitch in -0.6f64..0.6,
            roll in -0.6f64..0.6,
            from in -3.1f64..3.1,
            to in -3.1f64..3.1,
        ) {
            let (p, r) = tilt_at_heading(pitch, roll, from, to);
            let a = thrust_axis(pitch, roll, from);
            let b = thrust_axis(p, r, to);
            for (x, y) in a.iter().zip(&b) {
                prop_assert!((x - y).abs() < 1e-9, "{a:?} vs {b:?}");
            }
            // And back.
            let (p2, r2) = tilt_at_heading(p, r, to, from);
            prop_assert!((p2 - pitch).abs() < 1e-9 && (r2 - roll).abs() < 1e-9);
        }
    }

    #[test]
    fn a_quarter_turn_swaps_pitch_and_roll() {
        // Nose down facing north accelerates north; facing east, north is
        // the body's left (−y): the same thrust axis is a roll to the left.
        let (p, r) = tilt_at_heading(-0.2, 0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(p.abs() < 1e-12, "{p}");
        assert!((r - (-0.2)).abs() < 1e-12, "{r}");
    }

    #[test]
    fn the_heading_turns_at_the_rate_limit_the_short_way() {
        let mut y = YawCommand::new(1.0);
        assert_eq!(y.step(0.0, Some(3.0), 0.0), 0.0);
        let h = y.step(0.1, Some(3.0), 0.0);
        assert!((h - 0.1).abs() < 1e-12, "{h}");
        // After a gap, at most 0.1 s worth of turn.
        let h = y.step(1.0, Some(3.0), 0.0);
        assert!((h - 0.2).abs() < 1e-12, "{h}");
        // From 3.0 to −3.0 is 0.28 rad the short way (through ±π).
        y.follow(2.0, 3.0);
        let h = y.step(2.1, Some(-3.0), 0.0);
        assert!((wrap_pi(h - 3.1)).abs() < 1e-12, "{h}");
        let h = y.step(2.2, Some(-3.0), 0.0);
        assert!((wrap_pi(h - 3.2)).abs() < 1e-12, "{h}");
        let h = y.step(2.3, Some(-3.0), 0.0);
        assert!((h - -3.0).abs() < 1e-12, "{h}");
        // No target: kept; a NaN target is no target.
        assert_eq!(y.step(3.0, None, 0.0), h);
        assert_eq!(y.step(4.0, Some(f64::NAN), 0.0), h);
    }
}
