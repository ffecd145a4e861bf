//! Trajectories a planner streams: a circle and a figure eight, as pure
//! functions of time with position, velocity, acceleration and yaw (local
//! NED, SI units). Both start at `start` at t = 0 and ramp their speed up
//! over `ramp_s` with a cosine (`ṡ = V(1 − cos(πt/T))/2`), as a planner
//! leaving hover would, so the stream itself asks for no step.

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
}

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
    /// eight) and its first two derivatives at `t` \[s\] (t < 0: at rest).
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
        };
        let yaw = if v.x.hypot(v.y) > 1e-9 {
            v.y.atan2(v.x)
        } else {
            0.0
        };
        TrajectoryPoint {
            position: self.start + p,
            velocity: v,
            acceleration: a,
            yaw,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Velocity and acceleration are the derivatives of the position
    /// (central differences), for both shapes, in and after the ramp.
    #[test]
    fn derivatives_match_finite_differences() {
        for shape in [Shape::Circle, Shape::FigureEight] {
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
