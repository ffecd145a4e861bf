//! Attitude and thrust conversions for the MAVLink contract.
//!
//! Quaternions are `[w, x, y, z]` (MAVLink order) and rotate body FRD into
//! local NED. Euler angles are ZYX: `q = qz(ψ)·qy(θ)·qx(φ)`, i.e. the
//! rotation matrix `R = Rz(ψ)·Ry(θ)·Rx(φ)`, angles in radians.

use crate::LinkError;

/// Unit quaternion `[w, x, y, z]` (body FRD → local NED) from ZYX Euler
/// angles roll φ, pitch θ, yaw ψ \[rad\]: `q = qz(ψ)·qy(θ)·qx(φ)`, normalized.
///
/// Non-finite angles give a non-finite quaternion; the message builders
/// check their inputs before calling this.
pub fn quaternion_from_euler(roll: f64, pitch: f64, yaw: f64) -> [f64; 4] {
    let (sr, cr) = (0.5 * roll).sin_cos();
    let (sp, cp) = (0.5 * pitch).sin_cos();
    let (sy, cy) = (0.5 * yaw).sin_cos();
    let q = [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ];
    normalize_quaternion(q).unwrap_or(q)
}

/// ZYX Euler angles `[roll, pitch, yaw]` \[rad\] of the rotation `q = [w, x, y, z]`.
///
/// `q` need not be unit (it is normalized first). Roll and yaw are in
/// (−π, π], pitch in [−π/2, π/2]. Pitch uses `atan2` rather than `asin`, so
/// it keeps full precision near ±90°. A zero or non-finite quaternion gives
/// non-finite or zero angles, never a panic.
pub fn euler_from_quaternion(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = normalize_quaternion(q).unwrap_or(q);
    // Rotation matrix entries of R = Rz·Ry·Rx.
    let r11 = 1.0 - 2.0 * (y * y + z * z);
    let r21 = 2.0 * (x * y + w * z);
    let r31 = 2.0 * (x * z - w * y);
    let r32 = 2.0 * (y * z + w * x);
    let r33 = 1.0 - 2.0 * (x * x + y * y);
    let roll = r32.atan2(r33);
    let pitch = (-r31).atan2(r32.hypot(r33));
    let yaw = r21.atan2(r11);
    [roll, pitch, yaw]
}

/// Yaw ψ \[rad\] (heading of body x from north, about NED z) of `q = [w, x, y, z]`.
pub fn yaw_from_quaternion(q: [f64; 4]) -> f64 {
    euler_from_quaternion(q)[2]
}

/// `q / |q|`, or `None` if `q` is non-finite or its norm is below 1e-9.
pub fn normalize_quaternion(q: [f64; 4]) -> Option<[f64; 4]> {
    let norm = quaternion_norm(q);
    if !norm.is_finite() || norm < 1e-9 {
        return None;
    }
    Some([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm])
}

/// Euclidean norm of a quaternion.
pub fn quaternion_norm(q: [f64; 4]) -> f64 {
    (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt()
}

/// Wraps an angle \[rad\] into (−π, π].
pub fn wrap_pi(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let a = angle.rem_euclid(TAU); // [0, 2π)
    if a > PI { a - TAU } else { a }
}

/// How the controller's thrust becomes SET_ATTITUDE_TARGET's normalized
/// `thrust` in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ThrustMapping {
    /// Collective specific thrust T \[m/s²\] (thrust per unit mass, along −z
    /// body) → `T / gravity · hover_thrust`, clamped to [0, 1].
    ///
    /// `hover_thrust` ∈ (0, 1] is the normalized thrust that balances
    /// gravity (PX4's `MPC_THR_HOVER`), so full thrust is `gravity /
    /// hover_thrust` m/s². For the spatial model against PX4 offboard
    /// attitude control.
    Normalized {
        /// Normalized thrust at hover, in (0, 1].
        hover_thrust: f64,
        /// Gravitational acceleration g \[m/s²\], > 0.
        gravity: f64,
    },
    /// A constant value in [0, 1], whatever the controller asks.
    ///
    /// For the planar model with an autopilot that holds altitude itself:
    /// ArduPilot GUIDED_NOGPS reads `thrust` as a climb-rate demand where
    /// 0.5 means "hold climb rate 0" (GUID_OPTIONS bit 3 clear); with a PX4
    /// altitude-holding setup use the configured hover value.
    Fixed(f64),
}

impl ThrustMapping {
    /// Checks the parameters: `hover_thrust` ∈ (0, 1], `gravity` > 0 and
    /// finite, a fixed value ∈ [0, 1].
    pub fn validate(&self) -> Result<(), LinkError> {
        match *self {
            ThrustMapping::Normalized {
                hover_thrust,
                gravity,
            } => {
                if !(hover_thrust > 0.0 && hover_thrust <= 1.0) {
                    return Err(LinkError::OutOfRange {
                        name: "hover_thrust",
                        value: hover_thrust,
                        allowed: "(0, 1]",
                    });
                }
                if !(gravity.is_finite() && gravity > 0.0) {
                    return Err(LinkError::OutOfRange {
                        name: "gravity",
                        value: gravity,
                        allowed: "finite and > 0 m/s²",
                    });
                }
                Ok(())
            }
            ThrustMapping::Fixed(value) => {
                if (0.0..=1.0).contains(&value) {
                    Ok(())
                } else {
                    Err(LinkError::OutOfRange {
                        name: "fixed thrust",
                        value,
                        allowed: "[0, 1]",
                    })
                }
            }
        }
    }

    /// Normalized thrust in [0, 1] for specific thrust `specific_thrust`
    /// \[m/s²\]. Errors on a non-finite input or invalid parameters.
    pub fn normalized(&self, specific_thrust: f64) -> Result<f64, LinkError> {
        self.validate()?;
        if !specific_thrust.is_finite() {
            return Err(LinkError::NonFinite {
                message: "ThrustMapping",
                field: "specific_thrust",
            });
        }
        Ok(match *self {
            ThrustMapping::Normalized {
                hover_thrust,
                gravity,
            } => (specific_thrust / gravity * hover_thrust).clamp(0.0, 1.0),
            ThrustMapping::Fixed(value) => value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn identity_and_pure_yaw() {
        assert_eq!(quaternion_from_euler(0.0, 0.0, 0.0), [1.0, 0.0, 0.0, 0.0]);
        let q = quaternion_from_euler(0.0, 0.0, FRAC_PI_2);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!((q[0] - h).abs() < 1e-15 && (q[3] - h).abs() < 1e-15);
        assert!((yaw_from_quaternion(q) - FRAC_PI_2).abs() < 1e-15);
    }

    #[test]
    fn nose_down_pitch_tilts_thrust_north() {
        // Thrust along −z body; at θ < 0 its world x component must be > 0.
        let [w, x, y, z] = quaternion_from_euler(0.0, -0.2, 0.0);
        // Third column of R (body z in world), negated.
        let thrust_x = -(2.0 * (x * z + w * y));
        assert!(thrust_x > 0.0);
    }

    #[test]
    fn thrust_mapping() {
        let m = ThrustMapping::Normalized {
            hover_thrust: 0.5,
            gravity: 9.81,
        };
        assert!((m.normalized(9.81).unwrap() - 0.5).abs() < 1e-15);
        assert_eq!(m.normalized(100.0).unwrap(), 1.0);
        assert_eq!(m.normalized(-1.0).unwrap(), 0.0);
        assert!(m.normalized(f64::NAN).is_err());
        assert_eq!(ThrustMapping::Fixed(0.5).normalized(3.0).unwrap(), 0.5);
        assert!(ThrustMapping::Fixed(1.5).validate().is_err());
        assert!(
            ThrustMapping::Normalized {
                hover_thrust: 0.0,
                gravity: 9.81
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn wrap() {
        assert!((wrap_pi(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
        assert!((wrap_pi(-0.5) + 0.5).abs() < 1e-15);
    }
}
