//! The heading of the first-order plants (planar, spatial): the autopilot's
//! yaw loop, a first-order response to the command's yaw with a rate limit,
//!
//! ```text
//! ψ̇ = clamp(wrap(ψ_cmd − ψ) / τ_ψ, −r_max, r_max)
//! ```
//!
//! while pitch and roll keep acting in the body frame at the *actual*
//! heading: a command whose pitch and roll were meant for another heading
//! accelerates the vehicle the wrong way. With `max_yaw_rate = 0` (the
//! lab's default, the paper's set-up) the heading stays at its reset value.

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
}
