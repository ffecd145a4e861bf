//! The heading of the first-order plants (planar, spatial): the autopilot's
//! yaw loop, a first-order response to the command's yaw with a rate limit,
//!
//! ```text
//! ψ̇ = clamp(wrap(ψ_cmd − ψ) / τ_ψ, −r_max, r_max)
//! ```
//!
//! and the thrust axis tracks the *command's* thrust axis — the one of its
//! whole attitude (pitch and roll at the command's yaw) — whatever the
//! heading is meanwhile, as PX4's and ArduPilot's attitude controllers do
//! (reduced attitude first, yaw second). The plants keep their tilt state
//! at the reset heading ψ_ref (a world frame): the command is expressed
//! there ([`tilt_between`]) and the reported body angles at the actual
//! heading. With `max_yaw_rate = 0` (the lab's default, the paper's
//! set-up) the heading stays at ψ_ref and the command is taken at it, as
//! before.

use dflat_model::attitude::{pitch_roll_from_ratios, ratios_from_pitch_roll};

use super::PlantOptions;

/// `a` wrapped to (−π, π].
fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// The yaw rate ψ̇ \[rad/s\] at heading `yaw` towards the commanded `command`
/// \[rad\] (see the module docs); 0 when the yaw loop is off or the command
/// is not finite.
pub(crate) fn yaw_rate(options: &PlantOptions, yaw: f64, command: f64) -> f64 {
    let max = options.max_yaw_rate;
    if !(max > 0.0 && command.is_finite() && yaw.is_finite()) {
        return 0.0;
    }
    (wrap(command - yaw) / options.yaw_tau).clamp(-max, max)
}

/// The pitch and roll \[rad\] at heading `to` whose thrust axis is that of
/// `(pitch, roll)` at heading `from` (unchanged at or beyond 90° of tilt).
pub(crate) fn tilt_between(pitch: f64, roll: f64, from: f64, to: f64) -> (f64, f64) {
    if from == to {
        return (pitch, roll);
    }
    match ratios_from_pitch_roll(pitch, roll, from) {
        Ok((a, b)) => pitch_roll_from_ratios(a, b, to),
        Err(_) => (pitch, roll),
    }
}

/// The commanded (pitch, roll) \[rad\] at the plant's reference heading
/// `yaw_ref`: the command's thrust axis, its angles taken at its own yaw
/// when the yaw loop is on, else at the (fixed) actual heading `yaw`.
pub(crate) fn command_tilt(
    options: &PlantOptions,
    command: &dflat_control::AttitudeCommand,
    yaw: f64,
    yaw_ref: f64,
) -> (f64, f64) {
    let at = if options.max_yaw_rate > 0.0 && command.yaw.is_finite() {
        command.yaw
    } else {
        yaw
    };
    tilt_between(command.pitch, command.roll, at, yaw_ref)
}

/// One step `h` \[s\] of the heading (Euler; the rate is bounded, and the
/// step is the plant's small integration step), wrapped.
pub(crate) fn step_yaw(options: &PlantOptions, yaw: f64, command: f64, h: f64) -> f64 {
    wrap(yaw + h * yaw_rate(options, yaw, command))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heading_turns_at_most_at_the_rate_limit_the_short_way() {
        let o = PlantOptions {
            max_yaw_rate: 1.0,
            yaw_tau: 0.1,
            ..PlantOptions::default()
        };
        // Far from the command: the rate limit, the short way through ±π.
        assert_eq!(yaw_rate(&o, 3.0, -3.0), 1.0);
        assert_eq!(yaw_rate(&o, 0.0, -2.0), -1.0);
        // Close: first order.
        assert!((yaw_rate(&o, 0.0, 0.05) - 0.5).abs() < 1e-12);
        let mut y = 0.0;
        for _ in 0..400 {
            y = step_yaw(&o, y, 1.0, 0.005);
        }
        assert!((y - 1.0).abs() < 1e-3, "{y}");
        // Off (the lab's default), or a NaN command: no turn.
        assert_eq!(yaw_rate(&PlantOptions::default(), 0.0, 1.0), 0.0);
        assert_eq!(yaw_rate(&o, 0.0, f64::NAN), 0.0);
    }

    /// While the heading turns, a command's thrust axis is flown as the
    /// command means it (pitch and roll at its own yaw): the planar plant
    /// accelerates the same way at any heading the yaw loop is at, and
    /// reports the body angles at its actual heading.
    #[test]
    fn the_thrust_axis_is_the_commands_whatever_the_heading() {
        use crate::plant::{PlanarPlant, Plant, PlantState};
        use nalgebra::Vector3;
        let o = PlantOptions {
            max_yaw_rate: 1.0,
            yaw_tau: 0.1,
            ..PlantOptions::default()
        };
        let mut turning = PlanarPlant::new(o, 1).unwrap();
        let mut still = PlanarPlant::new(PlantOptions::default(), 1).unwrap();
        let hover = PlantState::hover(Vector3::zeros(), 9.81);
        turning.reset(&hover);
        still.reset(&hover);
        // 0.1 rad of pitch north, commanded at a heading of 1 rad for the
        // turning plant (its angles then say north as well) and 0 for the
        // other: the same thrust axis.
        let (p, r) = tilt_between(-0.1, 0.0, 0.0, 1.0);
        let north_at_1 = dflat_control::AttitudeCommand {
            roll: r,
            pitch: p,
            yaw: 1.0,
            thrust: 0.5,
        };
        let north_at_0 = dflat_control::AttitudeCommand {
            roll: 0.0,
            pitch: -0.1,
            yaw: 0.0,
            thrust: 0.5,
        };
        turning.apply(&north_at_1);
        still.apply(&north_at_0);
        for _ in 0..200 {
            turning.advance(0.01);
            still.advance(0.01);
        }
        let (a, b) = (turning.true_state(), still.true_state());
        assert!(
            (a.velocity - b.velocity).norm() < 1e-9,
            "{:?} vs {:?}",
            a.velocity,
            b.velocity
        );
        assert!(
            a.velocity.x > 0.5 && a.velocity.y.abs() < 1e-9,
            "{:?}",
            a.velocity
        );
        // Turned towards 1 rad, reporting the body angles there.
        assert!((a.yaw - 1.0).abs() < 0.01, "{}", a.yaw);
        let (p0, r0) = tilt_between(a.pitch, a.roll, a.yaw, 0.0);
        assert!((p0 - b.pitch).abs() < 1e-9 && (r0 - b.roll).abs() < 1e-9);
    }
}
