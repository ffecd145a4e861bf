//! The models the controllers run on, behind one enum chosen by config.
//!
//! TODO(control helper).

use dflat_model::{PlanarModel, SpatialModel};

/// The controller's model of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlModel {
    /// Planar model: x, y controlled, altitude held by the autopilot.
    Planar(PlanarModel),
    /// Spatial model: x, y, z with collective thrust.
    Spatial(SpatialModel),
}
