//! The anchor: a PD position controller with velocity and acceleration
//! feed-forward, what PX4's multicopter position loop is in effect
//! (`PositionControl`: position P → velocity PID → acceleration, with the
//! setpoint's velocity and acceleration fed forward). Pure: the caller
//! hands it the reference and the vehicle's state each tick.
//!
//! `a = a_ref + kp·(p_ref − p) + kd·(v_ref − v)` (horizontal), limited to
//! the tilt `max_tilt`, then mapped to attitude at yaw ψ (NED, FRD):
//! with the acceleration in the heading frame `(a_f, a_r)`,
//! `θ = −atan(a_f/g)`, `φ = atan(a_r·cos θ/g)` (ẍ = −g·tanθ,
//! ÿ = g·tanφ/cosθ at ψ = 0). Thrust is hover `g` (the planar plant holds
//! altitude). Issue 26 puts it in the SITL's OFFBOARD position mode.

use nalgebra::Vector3;

/// Gains and limits of the anchor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdFfGains {
    /// Position gain [1/s²].
    pub kp: f64,
    /// Velocity gain [1/s].
    pub kd: f64,
    /// Tilt limit \[rad\] (0 < · < π/2).
    pub max_tilt: f64,
    /// Gravity [m/s²].
    pub g: f64,
}

impl Default for PdFfGains {
    /// kp = 4 /s², kd = 3.5 /s (stable with a 0.2 s attitude lag:
    /// kp < kd/τ), 35° tilt, g = 9.81.
    fn default() -> Self {
        Self {
            kp: 4.0,
            kd: 3.5,
            max_tilt: 35f64.to_radians(),
            g: 9.81,
        }
    }
}

/// The reference the anchor tracks at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdFfReference {
    /// Position, NED \[m\].
    pub position: Vector3<f64>,
    /// Velocity, NED [m/s] (feed-forward).
    pub velocity: Vector3<f64>,
    /// Acceleration, NED [m/s²] (feed-forward).
    pub acceleration: Vector3<f64>,
}

/// The anchor's command: pitch, roll \[rad\] (ZYX, FRD) and the
/// horizontal acceleration it asked for [m/s²] (after the tilt limit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdFfCommand {
    /// Pitch θ \[rad\].
    pub pitch: f64,
    /// Roll φ \[rad\].
    pub roll: f64,
    /// The commanded horizontal acceleration, NED [m/s²].
    pub acceleration: Vector3<f64>,
}

/// One tick of the anchor: reference, the vehicle's position and velocity
/// (NED), its heading `yaw` \[rad\]. Non-finite inputs give a level command.
pub fn pd_ff(
    gains: &PdFfGains,
    reference: &PdFfReference,
    position: &Vector3<f64>,
    velocity: &Vector3<f64>,
    yaw: f64,
) -> PdFfCommand {
    let mut a = reference.acceleration
        + (reference.position - position) * gains.kp
        + (reference.velocity - velocity) * gains.kd;
    a.z = 0.0;
    if !a.iter().all(|x| x.is_finite()) || !yaw.is_finite() {
        return PdFfCommand {
            pitch: 0.0,
            roll: 0.0,
            acceleration: Vector3::zeros(),
        };
    }
    let a_max = gains.g * gains.max_tilt.tan();
    let n = a.norm();
    if n > a_max {
        a *= a_max / n;
    }
    let (c, s) = (yaw.cos(), yaw.sin());
    let fwd = c * a.x + s * a.y;
    let right = -s * a.x + c * a.y;
    let pitch = -(fwd / gains.g).atan();
    let roll = (right * pitch.cos() / gains.g).atan();
    PdFfCommand {
        pitch,
        roll,
        acceleration: a,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feed_forward_alone_gives_the_reference_acceleration() {
        let g = PdFfGains::default();
        let r = PdFfReference {
            position: Vector3::new(1.0, 2.0, -5.0),
            velocity: Vector3::new(3.0, 0.0, 0.0),
            acceleration: Vector3::new(1.0, -2.0, 0.0),
        };
        let c = pd_ff(&g, &r, &r.position, &r.velocity, 0.0);
        // ẍ = −g tanθ, ÿ = g tanφ / cosθ.
        let ax = -g.g * c.pitch.tan();
        let ay = g.g * c.roll.tan() / c.pitch.cos();
        assert!((ax - 1.0).abs() < 1e-12 && (ay + 2.0).abs() < 1e-12);
        // The tilt limit binds on a far reference.
        let far = PdFfReference {
            position: Vector3::new(100.0, 0.0, 0.0),
            ..r
        };
        let c = pd_ff(&g, &far, &Vector3::zeros(), &Vector3::zeros(), 0.3);
        let tilt = (c.pitch.cos() * c.roll.cos()).acos();
        assert!(tilt <= g.max_tilt + 1e-9);
        let nan = pd_ff(&g, &r, &Vector3::new(f64::NAN, 0.0, 0.0), &r.velocity, 0.0);
        assert_eq!((nan.pitch, nan.roll), (0.0, 0.0));
    }
}
