//! Trajectories a planner streams: a circle, a figure eight (Gerono), a
//! racing line and a lemniscate (Bernoulli), as pure functions of time with
//! position, velocity, acceleration, yaw and yaw rate (local NED, SI
//! units). All start at `start` at t = 0 and ramp their speed up over
//! `ramp_s` with a cosine (`ṡ = V(1 − cos(πt/T))/2`), as a planner leaving
//! hover would, so the stream itself asks for no step.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One point of a trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryPoint {
    /// Position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Velocity, local NED [m/s].
    pub velocity: Vector3<f64>,
    /// Acceleration, local NED [m/s²].
    pub acceleration: Vector3<f64>,
    /// Heading along the velocity \[rad\], NED (0 north, π/2 east); the
    /// start's heading (0) until the vehicle moves.
    pub yaw: f64,
    /// Rate of that heading [rad/s] (`(v_x a_y − v_y a_x)/|v_h|²`; 0 at
    /// rest).
    pub yaw_rate: f64,
}

/// Which shape (`sitl.planner.shape`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    /// A circle of `size` radius flown clockwise (seen from above) at
    /// `speed` along the path.
    #[default]
    Circle,
    /// A lemniscate of Gerono, `size` half-width north–south, half as wide
    /// east–west; its phase advances at `speed / size` rad/s.
    FigureEight,
    /// A racing line: an oval `size` half-length north–south and half as
    /// wide, flown fast along its sides and slowly through its ends, so
    /// the vehicle accelerates, brakes and turns: along the sides at
    /// `speed`, through the ends at about a fifth of it (phase
    /// `φ = u + ε sin 2u`, `ε` = [`RACING_EPSILON`],
    /// `u̇ = speed/(size·(1 + 2ε))`).
    RacingLine,
    /// A lemniscate of Bernoulli of half-width `size`, started at its
    /// crossing; its phase advances at `speed / size` rad/s, so it is flown
    /// at `speed` through the lobes' tips and `speed/√2` through the
    /// crossing. The heading along the velocity turns three quarters
    /// round through each lobe, one way then the other.
    Lemniscate,
}

/// The racing line's phase modulation (module docs of [`Shape::RacingLine`]).
pub const RACING_EPSILON: f64 = 0.2;

/// A trajectory: shape, size \[m\], speed [m/s], ramp \[s\], start (NED \[m\]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trajectory {
    /// The shape.
    pub shape: Shape,
    /// Radius (circle) or half-width (figure eight) \[m\] (> 0).
    pub size: f64,
    /// Cruise speed [m/s] (circle: along the path; figure eight: `size ×`
    /// the phase rate).
    pub speed: f64,
    /// Speed ramp from rest \[s\] (≥ 0; 0: at full speed from t = 0).
    pub ramp_s: f64,
    /// Where the trajectory starts, NED \[m\].
    pub start: Vector3<f64>,
}

impl Trajectory {
    /// Path coordinate (arc length for the circle, `size ×` phase for the
    /// others) and its first two derivatives at `t` \[s\] (t < 0: at rest).
    fn progress(&self, t: f64) -> (f64, f64, f64) {
        let v = self.speed;
        if t <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let tr = self.ramp_s;
        if tr <= 0.0 {
            return (v * t, v, 0.0);
        }
        let k = std::f64::consts::PI / tr;
        if t < tr {
            let s = 0.5 * v * (t - (k * t).sin() / k);
            let sd = 0.5 * v * (1.0 - (k * t).cos());
            let sdd = 0.5 * v * k * (k * t).sin();
            (s, sd, sdd)
        } else {
            (0.5 * v * tr + v * (t - tr), v, 0.0)
        }
    }

    /// The point at time `t` \[s\] since the start.
    pub fn at(&self, t: f64) -> TrajectoryPoint {
        let (s, sd, sdd) = self.progress(t);
        let r = self.size;
        let (p, v, a) = match self.shape {
            Shape::Circle => {
                // Centre west of the start: the circle leaves north-east…
                // clockwise seen from above (north → east).
                let th = s / r;
                let (c, sn) = (th.cos(), th.sin());
                let p = Vector3::new(r * sn, r * (1.0 - c), 0.0);
                let tangent = Vector3::new(c, sn, 0.0);
                let normal = Vector3::new(-sn, c, 0.0);
                (p, tangent * sd, tangent * sdd + normal * (sd * sd / r))
            }
            Shape::FigureEight => {
                let ph = s / r;
                let (c, sn) = (ph.cos(), ph.sin());
                let (c2, s2) = ((2.0 * ph).cos(), (2.0 * ph).sin());
                let p = Vector3::new(r * sn, 0.5 * r * s2, 0.0);
                let dp = Vector3::new(c, c2, 0.0); // dp/ds
                let ddp = Vector3::new(-sn / r, -2.0 * s2 / r, 0.0); // d²p/ds²
                (p, dp * sd, ddp * (sd * sd) + dp * sdd)
            }
            Shape::RacingLine => {
                // u = phase at speed/(size (1 + 2ε)); φ = u + ε sin 2u.
                let e = RACING_EPSILON;
                let k = 1.0 / (r * (1.0 + 2.0 * e));
                let (u, ud, udd) = (s * k, sd * k, sdd * k);
                let ph = u + e * (2.0 * u).sin();
                let phd = ud * (1.0 + 2.0 * e * (2.0 * u).cos());
                let phdd =
                    udd * (1.0 + 2.0 * e * (2.0 * u).cos()) - ud * ud * 4.0 * e * (2.0 * u).sin();
                let (c, sn) = (ph.cos(), ph.sin());
                let b = 0.5 * r;
                let p = Vector3::new(r * sn, b * (1.0 - c), 0.0);
                let dp = Vector3::new(r * c, b * sn, 0.0);
                let ddp = Vector3::new(-r * sn, b * c, 0.0);
                (p, dp * phd, ddp * (phd * phd) + dp * phdd)
            }
            Shape::Lemniscate => {
                let ph = s / r + std::f64::consts::FRAC_PI_2;
                let (phd, phdd) = (sd / r, sdd / r);
                let (p, dp, ddp) = bernoulli(r, ph);
                let (p0, _, _) = bernoulli(r, std::f64::consts::FRAC_PI_2);
                (p - p0, dp * phd, ddp * (phd * phd) + dp * phdd)
            }
        };
        let speed2 = v.x * v.x + v.y * v.y;
        let (yaw, yaw_rate) = if speed2 > 1e-18 {
            (v.y.atan2(v.x), (v.x * a.y - v.y * a.x) / speed2)
        } else {
            (0.0, 0.0)
        };
        TrajectoryPoint {
            position: self.start + p,
            velocity: v,
            acceleration: a,
            yaw,
            yaw_rate,
        }
    }
}

/// The lemniscate of Bernoulli of half-width `a` at phase `ph`:
/// `a·(cos φ, sin φ cos φ)/(1 + sin²φ)` and its first two derivatives in
/// `φ`.
fn bernoulli(a: f64, ph: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let (s, c) = ph.sin_cos();
    // x = a c / D, y = a s c / D, D = 1 + s².
    let d = 1.0 + s * s;
    let dd = 2.0 * s * c; // D'
    let ddd = 2.0 * (c * c - s * s); // D''
    let (fx, fxd, fxdd) = (c, -s, -c);
    let (fy, fyd, fydd) = (s * c, c * c - s * s, -4.0 * s * c);
    // (f/D)' = (f' D − f D')/D²; (f/D)'' = f''/D − 2 f' D'/D² + f (2D'² − D D'')/D³.
    let q = |f: f64, fd: f64, fdd: f64| -> (f64, f64, f64) {
        (
            f / d,
            (fd * d - f * dd) / (d * d),
            fdd / d - 2.0 * fd * dd / (d * d) + f * (2.0 * dd * dd - d * ddd) / (d * d * d),
        )
    };
    let (x, xd, xdd) = q(fx, fxd, fxdd);
    let (y, yd, ydd) = q(fy, fyd, fydd);
    (
        Vector3::new(a * x, a * y, 0.0),
        Vector3::new(a * xd, a * yd, 0.0),
        Vector3::new(a * xdd, a * ydd, 0.0),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Velocity and acceleration are the derivatives of the position
    /// (central differences), for both shapes, in and after the ramp.
    #[test]
    fn derivatives_match_finite_differences() {
        for shape in [
            Shape::Circle,
            Shape::FigureEight,
            Shape::RacingLine,
            Shape::Lemniscate,
        ] {
            let tr = Trajectory {
                shape,
                size: 6.0,
                speed: 4.0,
                ramp_s: 2.0,
                start: Vector3::new(1.0, 2.0, -10.0),
            };
            assert_eq!(tr.at(0.0).position, tr.start);
            let h = 1e-4;
            for k in 1..200 {
                // Off the ramp's end (t = ramp_s), where the jerk steps and
                // a central difference straddles it.
                let t = k as f64 * 0.05 + 0.013;
                let (a, b, c) = (tr.at(t - h), tr.at(t), tr.at(t + h));
                let v = (c.position - a.position) / (2.0 * h);
                let acc = (c.velocity - a.velocity) / (2.0 * h);
                assert!((v - b.velocity).norm() < 1e-6, "{shape:?} v at {t}");
                assert!((acc - b.acceleration).norm() < 1e-5, "{shape:?} a at {t}");
                let yaw_d = (c.yaw - a.yaw + std::f64::consts::PI)
                    .rem_euclid(2.0 * std::f64::consts::PI)
                    - std::f64::consts::PI;
                assert!(
                    (yaw_d / (2.0 * h) - b.yaw_rate).abs() < 1e-4,
                    "{shape:?} yaw rate at {t}"
                );
            }
        }
        // The circle keeps its radius and speed after the ramp.
        let c = Trajectory {
            shape: Shape::Circle,
            size: 6.0,
            speed: 4.0,
            ramp_s: 1.0,
            start: Vector3::zeros(),
        };
        let centre = Vector3::new(0.0, 6.0, 0.0);
        for k in 0..100 {
            let p = c.at(1.0 + k as f64 * 0.1);
            assert!(((p.position - centre).norm() - 6.0).abs() < 1e-9);
            assert!((p.velocity.norm() - 4.0).abs() < 1e-9);
        }
    }
}
