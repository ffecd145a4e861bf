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

/// Pitch θ and roll φ \[rad\] from the ratios `a = R13/R33`, `b = R23/R33` at
/// yaw ψ \[rad\] (paper eqs. (pitch), (roll)): `θ = atan(a·cψ + b·sψ)`,
/// `φ = atan((a·sψ − b·cψ)·cθ)`. Both lie in (−π/2, π/2).
pub fn pitch_roll_from_ratios(a: f64, b: f64, psi: f64) -> (f64, f64) {
    let (s, c) = psi.sin_cos();
    let theta = (a * c + b * s).atan();
    let phi = ((a * s - b * c) * theta.cos()).atan();
    (theta, phi)
}

/// The ratios `(R13/R33, R23/R33)` of the ZYX attitude (θ, φ, ψ) \[rad\]:
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

/// Thrust magnitude [m/s²] and ZYX pitch, roll \[rad\] from a specific-thrust
/// vector `t = T·R·e3` and yaw ψ. Errors with [`FlatError::FreeFall`] when
/// the vector does not point up through the body (t_z ≤ 0 in thrust-vector
/// coordinates, see [`Frame::thrust_vector`]).
pub fn thrust_pitch_roll(t: [f64; 3], psi: f64) -> Result<(f64, f64, f64), FlatError> {
    let norm = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    if !norm.is_finite() {
        return Err(FlatError::NonFinite("thrust vector"));
    }
    // `norm` is finite here, so every component is too.
    if t[2] <= 1e-9 * norm.max(1e-300) || norm < 1e-12 {
        return Err(FlatError::FreeFall);
    }
    let (theta, phi) = pitch_roll_from_ratios(t[0] / t[2], t[1] / t[2], psi);
    Ok((norm, theta, phi))
}

/// Unit thrust axis `R·e3` of the ZYX attitude (θ, φ, ψ) \[rad\].
pub fn thrust_axis(theta: f64, phi: f64, psi: f64) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    let (ss, cs) = psi.sin_cos();
    [cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp]
}

/// Body rates `[p, q, r]` [rad/s] from ZYX Euler-angle rates
/// `[φ̇, θ̇, ψ̇]` [rad/s] at pitch θ and roll φ \[rad\].
///
/// This is `Rᵀ·W·[φ̇, θ̇, ψ̇]` with the ZYX matrix
/// `W = [[cψcθ, −sψ, 0], [sψcθ, cψ, 0], [−sθ, 0, 1]]` (world angular
/// velocity `ω = W·[φ̇, θ̇, ψ̇] = R·[p, q, r]`), multiplied out: ψ cancels,
///
/// ```text
/// p = φ̇ − sθ·ψ̇,   q = cφ·θ̇ + sφ·cθ·ψ̇,   r = −sφ·θ̇ + cφ·cθ·ψ̇.
/// ```
///
/// The same in both frames (NED/FRD and z-up): only the thrust sign differs.
pub fn body_rates(theta: f64, phi: f64, euler_rates: [f64; 3]) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    let [dphi, dtheta, dpsi] = euler_rates;
    [
        dphi - st * dpsi,
        cp * dtheta + sp * ct * dpsi,
        -sp * dtheta + cp * ct * dpsi,
    ]
}

/// ZYX Euler-angle rates `[φ̇, θ̇, ψ̇]` [rad/s] from body rates `[p, q, r]`
/// [rad/s] at pitch θ and roll φ \[rad\]: `W⁻¹·R·[p, q, r]`, the inverse of
/// [`body_rates`],
///
/// ```text
/// θ̇ = cφ·q − sφ·r,   ψ̇ = (sφ·q + cφ·r)/cθ,   φ̇ = p + sθ·ψ̇.
/// ```
///
/// Errors with [`FlatError::Singular`] at gimbal lock, |cos θ| ≤ 1e-9
/// (pitch ±90°), where `W` is singular.
pub fn euler_rates(theta: f64, phi: f64, body_rates: [f64; 3]) -> Result<[f64; 3], FlatError> {
    let (st, ct) = theta.sin_cos();
    if ct.is_nan() || ct.abs() <= 1e-9 {
        return Err(FlatError::Singular);
    }
    let (sp, cp) = phi.sin_cos();
    let [p, q, r] = body_rates;
    let dpsi = (sp * q + cp * r) / ct;
    Ok([p + st * dpsi, cp * q - sp * r, dpsi])
}

/// An angle difference \[rad\] wrapped to [−π, π]; returned unchanged (bit
/// for bit) when already inside. Yaw differences of consecutive samples go
/// through this, so yaw measurements wrapped to (−π, π] work as long as the
/// yaw rate stays below π/δt.
pub fn wrap_angle_difference(d: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if (-PI..=PI).contains(&d) {
        d
    } else {
        (d + PI).rem_euclid(TAU) - PI
    }
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
    fn euler_and_body_rates_round_trip() {
        for &(th, ph) in &[(0.3, -0.2), (-0.5, 0.4), (0.0, 0.0), (1.2, -1.1)] {
            let w = [0.4, -1.3, 2.1];
            let e = euler_rates(th, ph, w).unwrap();
            let back = body_rates(th, ph, e);
            for i in 0..3 {
                assert!((back[i] - w[i]).abs() < 1e-13);
            }
        }
        assert_eq!(
            euler_rates(std::f64::consts::FRAC_PI_2, 0.0, [0.0, 1.0, 0.0]),
            Err(FlatError::Singular)
        );
        assert_eq!(
            euler_rates(f64::NAN, 0.0, [0.0; 3]),
            Err(FlatError::Singular)
        );
    }

    #[test]
    fn body_rates_match_rt_w() {
        // Rᵀ·W·ė with R, W built explicitly (ZYX).
        let (th, ph, ps) = (0.3_f64, -0.4_f64, 2.0_f64);
        let (st, ct) = th.sin_cos();
        let (sp, cp) = ph.sin_cos();
        let (ss, cs) = ps.sin_cos();
        let r = [
            [cs * ct, cs * st * sp - ss * cp, cs * st * cp + ss * sp],
            [ss * ct, ss * st * sp + cs * cp, ss * st * cp - cs * sp],
            [-st, ct * sp, ct * cp],
        ];
        let w = [[cs * ct, -ss, 0.0], [ss * ct, cs, 0.0], [-st, 0.0, 1.0]];
        let e = [0.7, -0.2, 1.1];
        let omega: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| w[i][j] * e[j]).sum())
            .collect();
        let body: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| r[j][i] * omega[j]).sum())
            .collect();
        let got = body_rates(th, ph, e);
        for i in 0..3 {
            assert!((got[i] - body[i]).abs() < 1e-14);
        }
    }

    #[test]
    fn wraps_angle_differences() {
        use std::f64::consts::PI;
        assert_eq!(wrap_angle_difference(0.25), 0.25);
        assert!((wrap_angle_difference(2.0 * PI - 0.1) + 0.1).abs() < 1e-15);
        assert!((wrap_angle_difference(-2.0 * PI + 0.1) - 0.1).abs() < 1e-15);
    }

    #[test]
    fn free_fall_is_an_error() {
        let t = Frame::Ned.thrust_vector([0.0, 0.0, 9.81], 9.81);
        assert_eq!(thrust_pitch_roll(t, 0.0), Err(FlatError::FreeFall));
        assert_eq!(
            ratios_from_pitch_roll(std::f64::consts::FRAC_PI_2, 0.0, 0.0),
            Err(FlatError::Singular)
        );
    }
}
