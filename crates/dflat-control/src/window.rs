//! The window of past data the DF-MPC needs (paper §IV-C, *input-to-output
//! map*): the last r = 3 measured outputs `y^m_{k−2}, y^m_{k−1}, y^m_k` and
//! the last r − 1 = 2 sent inputs `u_{k−2}, u_{k−1}`.
//!
//! Both are fixed-size ring buffers (kept oldest first; with three and two
//! entries a shift is as cheap as index arithmetic). No allocation.
//!
//! Start-up padding, before enough history exists:
//! * outputs: the first measurement fills every slot, i.e. the vehicle is
//!   taken to have been at rest there (`y^m_{k−2} = y^m_{k−1} = y^m_0`);
//! * inputs: every slot holds the hover input given at construction (level
//!   attitude; hover thrust g for the spatial model).
//!
//! So at the first tick the prediction F⁻¹ from the window is "at rest,
//! hovering" and the predicted outputs equal the first measurement.

use nalgebra::Vector3;

/// Measured outputs kept: r = 3.
pub const OUTPUTS: usize = 3;
/// Sent inputs kept: r − 1 = 2.
pub const INPUTS: usize = 2;

/// The last r measured outputs and r − 1 sent inputs, with start-up padding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// `[y^m_{k−2}, y^m_{k−1}, y^m_k]`, positions [m] in the model frame.
    outputs: [Vector3<f64>; OUTPUTS],
    /// `[u_{k−2}, u_{k−1}]`, inputs `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s²).
    inputs: [Vector3<f64>; INPUTS],
    /// Input used for padding.
    hover: Vector3<f64>,
    /// Measurements pushed since construction or reset (saturating).
    measurements: usize,
}

impl Window {
    /// An empty window padded with `hover` as the past inputs
    /// (`[0, 0, g]`: level attitude, hover specific thrust).
    pub fn new(hover: Vector3<f64>) -> Self {
        Self {
            outputs: [Vector3::zeros(); OUTPUTS],
            inputs: [hover; INPUTS],
            hover,
            measurements: 0,
        }
    }

    /// Pushes the newest measured output `y^m_k` [m]. The first one after
    /// construction or [`Window::reset`] fills every output slot.
    pub fn push_measurement(&mut self, y: Vector3<f64>) {
        if self.measurements == 0 {
            self.outputs = [y; OUTPUTS];
        } else {
            self.outputs.rotate_left(1);
            self.outputs[OUTPUTS - 1] = y;
        }
        self.measurements = self.measurements.saturating_add(1);
    }

    /// Pushes the input `u_k` actually sent at the newest tick.
    pub fn push_input(&mut self, u: Vector3<f64>) {
        self.inputs.rotate_left(1);
        self.inputs[INPUTS - 1] = u;
    }

    /// Forgets all history: the next measurement starts the padding again.
    pub fn reset(&mut self) {
        self.outputs = [Vector3::zeros(); OUTPUTS];
        self.inputs = [self.hover; INPUTS];
        self.measurements = 0;
    }

    /// Measured outputs `[y^m_{k−2}, y^m_{k−1}, y^m_k]`, oldest first.
    pub fn outputs(&self) -> &[Vector3<f64>; OUTPUTS] {
        &self.outputs
    }

    /// Sent inputs `[u_{k−2}, u_{k−1}]`, oldest first.
    pub fn inputs(&self) -> &[Vector3<f64>; INPUTS] {
        &self.inputs
    }

    /// Newest measured output `y^m_k`.
    pub fn latest(&self) -> &Vector3<f64> {
        &self.outputs[OUTPUTS - 1]
    }

    /// Number of measurements pushed since construction or reset (saturates).
    pub fn measurements(&self) -> usize {
        self.measurements
    }

    /// True until the first measurement.
    pub fn is_empty(&self) -> bool {
        self.measurements == 0
    }

    /// True once r real measurements fill the output slots (no padding left).
    pub fn is_full(&self) -> bool {
        self.measurements >= OUTPUTS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64) -> Vector3<f64> {
        Vector3::new(x, 0.0, 0.0)
    }

    #[test]
    fn pads_then_shifts() {
        let hover = Vector3::new(0.0, 0.0, 9.81);
        let mut w = Window::new(hover);
        assert!(w.is_empty());
        w.push_measurement(v(1.0));
        assert_eq!(w.outputs(), &[v(1.0), v(1.0), v(1.0)]);
        assert_eq!(w.inputs(), &[hover, hover]);
        w.push_input(v(0.1));
        w.push_measurement(v(2.0));
        assert_eq!(w.outputs(), &[v(1.0), v(1.0), v(2.0)]);
        assert_eq!(w.inputs(), &[hover, v(0.1)]);
        assert!(!w.is_full());
        w.push_input(v(0.2));
        w.push_measurement(v(3.0));
        w.push_input(v(0.3));
        assert!(w.is_full());
        assert_eq!(w.outputs(), &[v(1.0), v(2.0), v(3.0)]);
        assert_eq!(w.inputs(), &[v(0.2), v(0.3)]);
        assert_eq!(w.latest(), &v(3.0));
        w.reset();
        assert!(w.is_empty());
        w.push_measurement(v(5.0));
        assert_eq!(w.outputs(), &[v(5.0); 3]);
        assert_eq!(w.inputs(), &[hover, hover]);
    }
}
