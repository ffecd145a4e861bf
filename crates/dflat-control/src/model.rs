//! The models the controllers run on, behind one enum chosen by config.
//!
//! [`ControlModel`] gives the controllers one representation for both
//! models, so the window, the prediction and the optimisation do not care
//! which one flies:
//!
//! * outputs are `Vector3` positions `[x, y, z]` [m] in the model's frame
//!   (local NED for flight; the planar model ignores z and carries it along),
//! * inputs are `Vector3` `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s² specific
//!   thrust); the planar model's thrust is always hover, `T_cmd = g`.
//!
//! Both models have window r = [`WINDOW`] = 3: `u_k = F(y_k..y_{k+3})` and
//! `y_{k+3} = F⁻¹(y_k..y_{k+2}, u_k)`. Everything here is pure and does not
//! allocate.

use dflat_model::{FlatError, FlatModel, Frame, PlanarModel, SpatialModel};
use nalgebra::{Vector2, Vector3};

use crate::AttitudeCommand;

/// Window r of both control models: the input needs r + 1 = 4 consecutive
/// outputs, the prediction r = 3 outputs and one input.
pub const WINDOW: usize = 3;

/// The controller's model of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlModel {
    /// Planar model: x, y controlled, altitude held by the autopilot.
    Planar(PlanarModel),
    /// Spatial model: x, y, z with collective thrust.
    Spatial(SpatialModel),
}

fn xy(v: &Vector3<f64>) -> Vector2<f64> {
    Vector2::new(v.x, v.y)
}

impl ControlModel {
    /// Number of controlled position axes: 2 (planar: x, y) or 3 (spatial).
    pub fn axes(&self) -> usize {
        match self {
            ControlModel::Planar(_) => 2,
            ControlModel::Spatial(_) => 3,
        }
    }

    /// Control step δt [s].
    pub fn dt(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.dt(),
            ControlModel::Spatial(m) => m.dt(),
        }
    }

    /// The model's fixed yaw ψ⋆ [rad].
    pub fn yaw(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.params().psi,
            ControlModel::Spatial(m) => m.params().psi,
        }
    }

    /// Gravity g [m/s²].
    pub fn gravity(&self) -> f64 {
        match self {
            ControlModel::Planar(m) => m.params().g,
            ControlModel::Spatial(m) => m.params().g,
        }
    }

    /// Frame convention of the outputs and attitude.
    pub fn frame(&self) -> Frame {
        match self {
            ControlModel::Planar(m) => m.params().frame,
            ControlModel::Spatial(m) => m.params().frame,
        }
    }

    /// The hover input `[0, 0, g]`: level attitude, specific thrust g [m/s²].
    pub fn hover_input(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.gravity())
    }

    /// F⁻¹, the input-to-output map: `y_{k+3}` from `y_k, y_{k+1}, y_{k+2}`
    /// (oldest first) and `u_k`. The planar model carries z of `y_{k+2}`.
    pub fn next_output(
        &self,
        y: &[Vector3<f64>; 3],
        u: &Vector3<f64>,
    ) -> Result<Vector3<f64>, FlatError> {
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2])];
                let n = m.next_output(&w, &Vector2::new(u.x, u.y))?;
                Ok(Vector3::new(n.x, n.y, y[2].z))
            }
            ControlModel::Spatial(m) => m.next_output(y, u),
        }
    }

    /// F, the output-to-input map: `u_k = [θ_cmd, φ_cmd, T_cmd]` from
    /// `y_k..y_{k+3}` (oldest first). The planar model returns `T_cmd = g`.
    pub fn input_from_outputs(&self, y: &[Vector3<f64>; 4]) -> Result<Vector3<f64>, FlatError> {
        match self {
            ControlModel::Planar(m) => {
                let w = [xy(&y[0]), xy(&y[1]), xy(&y[2]), xy(&y[3])];
                let u = m.input_from_outputs(&w)?;
                Ok(Vector3::new(u.x, u.y, m.params().g))
            }
            ControlModel::Spatial(m) => m.input_from_outputs(y),
        }
    }

    /// The autopilot command for input `u = [θ_cmd, φ_cmd, T_cmd]` at the
    /// model's yaw ψ⋆.
    pub fn command(&self, u: &Vector3<f64>) -> AttitudeCommand {
        AttitudeCommand {
            pitch: u.x,
            roll: u.y,
            yaw: self.yaw(),
            thrust: u.z,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_model::PlanarParams;

    fn planar() -> ControlModel {
        ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap())
    }

    #[test]
    fn planar_maps_are_inverse() {
        let m = planar();
        let y = [
            Vector3::new(0.0, 0.0, -2.0),
            Vector3::new(0.01, -0.02, -2.0),
            Vector3::new(0.021, -0.041, -2.0),
        ];
        let u = Vector3::new(-0.1, 0.05, 9.81);
        let y3 = m.next_output(&y, &u).unwrap();
        assert_eq!(y3.z, -2.0);
        let u2 = m.input_from_outputs(&[y[0], y[1], y[2], y3]).unwrap();
        assert!((u2 - u).norm() < 1e-9, "{u2} vs {u}");
        assert_eq!(m.axes(), 2);
        assert_eq!(m.hover_input(), Vector3::new(0.0, 0.0, 9.81));
        let c = m.command(&u);
        assert_eq!((c.pitch, c.roll, c.thrust), (-0.1, 0.05, 9.81));
    }

    #[test]
    fn nan_is_an_error() {
        let m = planar();
        let y = [Vector3::new(f64::NAN, 0.0, 0.0); 3];
        assert!(m.next_output(&y, &Vector3::zeros()).is_err());
    }
}
