//! ZYX attitude helpers shared by the models.
//!
//! Body→world rotation `R = Rz(ψ)·Ry(θ)·Rx(φ)`. The thrust axis in the world
//! frame is the third column `R·e3 = [cψ·sθ·cφ + sψ·sφ, sψ·sθ·cφ − cψ·sφ, cθ·cφ]`.

use crate::FlatError;

/// Sign convention of the vertical axis and thrust.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Frame {
    /// MAVLink local NED with body FRD: thrust along −z body, gravity +z.
    /// `a = g·e3 − T·R·e3`; at ψ = 0 a nose-down pitch (θ < 0) accelerates
    /// north: `ẍ = −g·tanθ`.
    #[default]
    Ned,
    /// The paper's convention, z up: thrust along +z body, gravity −z.
    /// `a = T·R·e3 − g·e3`; at ψ = 0, `ẍ = g·tanθ`.
    Zup,
}

impl Frame {
    /// Sign s with `ẍ = s·g·R13/R33`, `ÿ = s·g·R23/R33` at constant altitude.
    pub fn horizontal_sign(self) -> f64 {
        match self {
            Frame::Ned => -1.0,
            Frame::Zup => 1.0,
        }
    }

    /// Specific-thrust vector `t = T·R·e3` [m/s²] that produces the
    /// world-frame acceleration `a` [m/s²] against gravity `g` [m/s²].
    pub fn thrust_vector(self, a: [f64; 3], g: f64) -> [f64; 3] {
        match self {
            Frame::Ned => [-a[0], -a[1], g - a[2]],
            Frame::Zup => [a[0], a[1], a[2] + g],
        }
    }

    /// World-frame acceleration [m/s²] from the specific-thrust vector
    /// `t = T·R·e3` [m/s²]: the inverse of [`Frame::thrust_vector`].
    pub fn acceleration(self, t: [f64; 3], g: f64) -> [f64; 3] {
        match self {
            Frame::Ned => [-t[0], -t[1], g - t[2]],
            Frame::Zup => [t[0], t[1], t[2] - g],
        }
    }
}

/// Pitch θ and roll φ [rad] from the ratios `a = R13/R33`, `b = R23/R33` at
/// yaw ψ [rad] (paper eqs. (pitch), (roll)): `θ = atan(a·cψ + b·sψ)`,
/// `φ = atan((a·sψ − b·cψ)·cθ)`. Both lie in (−π/2, π/2).
pub fn pitch_roll_from_ratios(a: f64, b: f64, psi: f64) -> (f64, f64) {
    let (s, c) = psi.sin_cos();
    let theta = (a * c + b * s).atan();
    let phi = ((a * s - b * c) * theta.cos()).atan();
    (theta, phi)
}

/// The ratios `(R13/R33, R23/R33)` of the ZYX attitude (θ, φ, ψ) [rad]:
/// `R13/R33 = cψ·tanθ + sψ·tanφ/cθ`, `R23/R33 = sψ·tanθ − cψ·tanφ/cθ`.
///
/// Errors with [`FlatError::Singular`] when |θ| or |φ| reaches 90°.
pub fn ratios_from_pitch_roll(theta: f64, phi: f64, psi: f64) -> Result<(f64, f64), FlatError> {
    let ct = theta.cos();
    let cp = phi.cos();
    if !(ct > 1e-9 && cp > 1e-9) {
        return Err(FlatError::Singular);
    }
    let (s, c) = psi.sin_cos();
    let tt = theta.tan();
    let tp_over_ct = phi.tan() / ct;
    Ok((c * tt + s * tp_over_ct, s * tt - c * tp_over_ct))
}

/// Thrust magnitude [m/s²] and ZYX pitch, roll [rad] from a specific-thrust
/// vector `t = T·R·e3` and yaw ψ. Errors with [`FlatError::FreeFall`] when
/// the vector does not point up through the body (t_z ≤ 0 in thrust-vector
/// coordinates, see [`Frame::thrust_vector`]).
pub fn thrust_pitch_roll(t: [f64; 3], psi: f64) -> Result<(f64, f64, f64), FlatError> {
    let norm = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    if !norm.is_finite() {
        return Err(FlatError::NonFinite("thrust vector"));
    }
    if !(t[2] > 1e-9 * norm.max(1e-300)) || norm < 1e-12 {
        return Err(FlatError::FreeFall);
    }
    let (theta, phi) = pitch_roll_from_ratios(t[0] / t[2], t[1] / t[2], psi);
    Ok((norm, theta, phi))
}

/// Unit thrust axis `R·e3` of the ZYX attitude (θ, φ, ψ) [rad].
pub fn thrust_axis(theta: f64, phi: f64, psi: f64) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    let (ss, cs) = psi.sin_cos();
    [cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratios_round_trip() {
        for &(th, ph, ps) in &[(0.3, -0.2, 0.7), (-0.5, 0.4, -2.0), (0.0, 0.0, 0.0)] {
            let (a, b) = ratios_from_pitch_roll(th, ph, ps).unwrap();
            let (t2, p2) = pitch_roll_from_ratios(a, b, ps);
            assert!((t2 - th).abs() < 1e-14 && (p2 - ph).abs() < 1e-14);
            let ax = thrust_axis(th, ph, ps);
            assert!((ax[0] / ax[2] - a).abs() < 1e-14 && (ax[1] / ax[2] - b).abs() < 1e-14);
        }
    }

    #[test]
    fn ned_nose_down_accelerates_north() {
        // θ < 0 at ψ = 0, hover thrust: ẍ = −g·tanθ > 0.
        let theta: f64 = -0.2;
        let axis = thrust_axis(theta, 0.0, 0.0);
        let thrust = 9.81 / axis[2];
        let a = Frame::Ned.acceleration(axis.map(|c| c * thrust), 9.81);
        assert!((a[0] - (-9.81 * theta.tan())).abs() < 1e-12);
        assert!(a[2].abs() < 1e-12);
    }

    #[test]
    fn free_fall_is_an_error() {
        let t = Frame::Ned.thrust_vector([0.0, 0.0, 9.81], 9.81);
        assert_eq!(thrust_pitch_roll(t, 0.0), Err(FlatError::FreeFall));
        assert_eq!(ratios_from_pitch_roll(std::f64::consts::FRAC_PI_2, 0.0, 0.0), Err(FlatError::Singular));
    }
}
