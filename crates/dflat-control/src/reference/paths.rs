//! The paths flown in the paper, as NED waypoints at a caller-given
//! altitude z (NED, so z = −10 is 10 m above the origin).
//!
//! Waypoints are `(x, y)` = (north, east) \[m\]. The paper gives the
//! coordinates of the L path only; the DSL letters are our reconstruction
//! of Fig. 8 (sizes 20–30 m, placed side by side along east so that they
//! read "DSL").

use nalgebra::Vector3;

use super::Reference;
use crate::ControlError;

/// The L-shaped teach path of the controller comparison (§VII-C,
/// Figs. 6–7): (x, y) = (−20, −30) → (0, −30) → (0, 0) \[m\].
pub const L_XY: [[f64; 2]; 3] = [[-20.0, -30.0], [0.0, -30.0], [0.0, 0.0]];
/// Speeds of the controller comparison on the L path [m/s].
pub const L_SPEEDS: [f64; 4] = [3.0, 5.0, 7.0, 9.0];

/// "D" of the DSL demonstration: a 30 m stem north, then a bowl of
/// radius 15 m bulging east (polyline, 30° steps), closed back at the
/// start.
pub const D_XY: [[f64; 2]; 10] = [
    [0.0, 0.0],
    [30.0, 0.0],
    [30.0, 5.0],
    [27.990_381_056_766_58, 12.5],
    [22.5, 17.990_381_056_766_58],
    [15.0, 20.0],
    [7.5, 17.990_381_056_766_58],
    [2.009_618_943_233_42, 12.5],
    [0.0, 5.0],
    [0.0, 0.0],
];
/// Speed of the "D" flight [m/s].
pub const D_SPEED: f64 = 10.0;

/// "S" of the DSL demonstration: 20 m wide, 30 m tall, drawn from the
/// top right to the bottom left in three east–west legs.
pub const S_XY: [[f64; 2]; 6] = [
    [30.0, 50.0],
    [30.0, 30.0],
    [15.0, 30.0],
    [15.0, 50.0],
    [0.0, 50.0],
    [0.0, 30.0],
];
/// Speed of the "S" flight [m/s].
pub const S_SPEED: f64 = 3.0;

/// "L" of the DSL demonstration: 30 m south along the stem, then 20 m
/// east.
pub const DSL_L_XY: [[f64; 2]; 3] = [[30.0, 60.0], [0.0, 60.0], [0.0, 80.0]];
/// Speed of the DSL "L" flight [m/s].
pub const DSL_L_SPEED: f64 = 8.0;

/// NED waypoints `(x, y, z)` \[m\] from `(x, y)` pairs at altitude `z`.
pub fn waypoints(xy: &[[f64; 2]], z: f64) -> Vec<Vector3<f64>> {
    xy.iter().map(|p| Vector3::new(p[0], p[1], z)).collect()
}

/// The comparison's L path at altitude `z` (NED \[m\]) flown at `speed` [m/s].
pub fn l(z: f64, speed: f64) -> Result<Reference, ControlError> {
    Reference::path(&waypoints(&L_XY, z), speed)
}

/// The DSL "D" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
/// (the paper: [`D_SPEED`]).
pub fn d(z: f64, speed: f64) -> Result<Reference, ControlError> {
    Reference::path(&waypoints(&D_XY, z), speed)
}

/// The DSL "S" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
/// (the paper: [`S_SPEED`]).
pub fn s(z: f64, speed: f64) -> Result<Reference, ControlError> {
    Reference::path(&waypoints(&S_XY, z), speed)
}

/// The DSL "L" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
/// (the paper: [`DSL_L_SPEED`]).
pub fn dsl_l(z: f64, speed: f64) -> Result<Reference, ControlError> {
    Reference::path(&waypoints(&DSL_L_XY, z), speed)
}
