//! The 6 m circle the planner tests stream and fly.

use dflat_sim::trajectory::{Shape, Trajectory};
use nalgebra::Vector3;

/// A circle of radius 6 m from `start` (NED \[m\]) at `speed` [m/s] after a
/// `ramp_s` \[s\] ramp from rest.
pub fn circle(speed: f64, ramp_s: f64, start: [f64; 3]) -> Trajectory {
    Trajectory {
        shape: Shape::Circle,
        size: 6.0,
        speed,
        ramp_s,
        start: Vector3::from(start),
    }
}
