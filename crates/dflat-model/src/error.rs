use thiserror::Error;

/// Why a flatness map could not be evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum FlatError {
    /// A window had the wrong number of samples.
    #[error("window holds {got} samples, the map needs {expected}")]
    WindowLength {
        /// Samples the map needs.
        expected: usize,
        /// Samples it was given.
        got: usize,
    },
    /// An input value was NaN or infinite.
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
    /// The thrust direction is undefined: the commanded acceleration equals
    /// gravity (free fall) or points the thrust downwards.
    #[error("free fall or inverted thrust: the attitude is undefined")]
    FreeFall,
    /// The attitude reaches or passes 90° of pitch or roll, where the ZYX
    /// Euler angles or the planar model are singular.
    #[error("tilt at or beyond 90°: the map is singular")]
    Singular,
    /// The model has no uniform input-to-output map (the full rigid body:
    /// thrust reaches the position after two steps, torques after four).
    #[error("this model has no uniform input-to-output map")]
    NoInputToOutputMap,
    /// A model parameter is outside its allowed range.
    #[error("parameter {name} = {value} is invalid: {allowed}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The allowed range, in words.
        allowed: &'static str,
    },
}
