//! The flight envelope's box as the reference sees it: every position a
//! reference hands the controller is clamped into it.
//!
//! A reference that would leave the box (a stream's prediction running
//! past the fence, its stop point beyond it) is flown along the box's
//! face instead: the clamp is per axis, so motion along the face goes on
//! and motion out of it stops at the face. The clamped horizon has a kink
//! where it meets the face, so a clamped horizon is not "flyable" as it
//! is (no feed-forward of its jerk).

use nalgebra::Vector3;

use crate::ControlError;

/// An axis-aligned box in local NED \[m\]: `min ≤ p ≤ max` per axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounds {
    /// The smallest x, y, z \[m\] (NED: z's smallest is the ceiling).
    pub min: Vector3<f64>,
    /// The largest x, y, z \[m\] (NED: z's largest is the floor).
    pub max: Vector3<f64>,
}

impl Bounds {
    /// The box `min ≤ p ≤ max`. Errors unless every bound is finite and
    /// `min ≤ max` per axis.
    pub fn new(min: Vector3<f64>, max: Vector3<f64>) -> Result<Self, ControlError> {
        let ok = min.iter().chain(max.iter()).all(|v| v.is_finite())
            && min.iter().zip(max.iter()).all(|(a, b)| a <= b);
        if !ok {
            return Err(ControlError::InvalidSetting {
                field: "bounds",
                reason: "finite, min ≤ max on every axis".into(),
            });
        }
        Ok(Self { min, max })
    }

    /// True when `p` lies in the box (its faces included).
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }

    /// `p` clamped into the box per axis, and whether it moved. A NaN
    /// component stays NaN (the controller refuses a non-finite reference).
    pub fn clamp(&self, p: &Vector3<f64>) -> (Vector3<f64>, bool) {
        let mut q = *p;
        let mut moved = false;
        for i in 0..3 {
            if q[i] < self.min[i] {
                q[i] = self.min[i];
                moved = true;
            } else if q[i] > self.max[i] {
                q[i] = self.max[i];
                moved = true;
            }
        }
        (q, moved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn unit() -> Bounds {
        Bounds::new(
            Vector3::new(-30.0, -30.0, -100.0),
            Vector3::new(30.0, 30.0, 5.0),
        )
        .unwrap()
    }

    #[test]
    fn refuses_inverted_or_infinite_bounds() {
        assert!(Bounds::new(Vector3::new(1.0, 0.0, 0.0), Vector3::zeros()).is_err());
        assert!(Bounds::new(Vector3::zeros(), Vector3::new(f64::INFINITY, 1.0, 1.0)).is_err());
        assert!(Bounds::new(Vector3::zeros(), Vector3::zeros()).is_ok());
    }

    proptest! {
        /// The clamp lands inside, leaves inside points alone, and moves a
        /// point only on the axes where it was outside.
        #[test]
        fn clamp_lands_inside_and_keeps_inside_points(
            x in -1e3f64..1e3, y in -1e3f64..1e3, z in -1e3f64..1e3
        ) {
            let b = unit();
            let p = Vector3::new(x, y, z);
            let (q, moved) = b.clamp(&p);
            prop_assert!(b.contains(&q));
            prop_assert_eq!(moved, !b.contains(&p));
            for i in 0..3 {
                if p[i] >= b.min[i] && p[i] <= b.max[i] {
                    prop_assert_eq!(q[i], p[i]);
                }
            }
        }
    }
}
