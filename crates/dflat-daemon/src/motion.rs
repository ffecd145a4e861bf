//! The vehicle's motion from its recent poses, for engagement only: where
//! it is and how fast it moves.
//!
//! DF-MPC itself needs no velocity (its window holds outputs and inputs);
//! the shell needs the motion at the moment the pilot engages — the stop it
//! brakes along (`dflat_control::reference::Reference::braking`) — and, in
//! standby, the same stop for the command it streams. A least-squares line
//! through the poses of the last [`MOTION_SPAN`] seconds (by capture time)
//! gives position and velocity with the pose noise averaged: at σ = 1 cm
//! and 50 Hz, about 4 cm/s of velocity noise.
//!
//! Positions local NED \[m\], velocities \[m/s\], times \[s\] on the daemon's
//! clock. Pure: no clock, no I/O.

use std::collections::VecDeque;

/// Poses older than this before the newest are not used \[s\].
pub const MOTION_SPAN: f64 = 0.25;
/// Most poses kept (a 200 Hz stream over the span, with margin).
const CAPACITY: usize = 64;

/// Position and velocity at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Time \[s\] (the newest pose's capture time).
    pub t: f64,
    /// Position, local NED \[m\] (the fitted line at `t`).
    pub position: [f64; 3],
    /// Velocity, local NED \[m/s\].
    pub velocity: [f64; 3],
}

impl Motion {
    /// Speed \[m/s\] (3-D).
    pub fn speed(&self) -> f64 {
        norm(self.velocity)
    }
}

/// Least-squares position and velocity over the last [`MOTION_SPAN`].
#[derive(Debug, Clone, Default)]
pub struct MotionEstimator {
    samples: VecDeque<(f64, [f64; 3])>,
}

impl MotionEstimator {
    /// An empty estimator.
    pub fn new() -> Self {
        Self {
            samples: VecDeque::with_capacity(CAPACITY),
        }
    }

    /// A pose captured at `t` \[s\]. Non-finite poses and poses not newer
    /// than the newest are ignored; a pose more than a span newer than the
    /// others starts afresh.
    pub fn push(&mut self, t: f64, position: [f64; 3]) {
        if !t.is_finite() || !position.iter().all(|v| v.is_finite()) {
            return;
        }
        if let Some(&(last, _)) = self.samples.back()
            && t <= last
        {
            return;
        }
        while let Some(&(first, _)) = self.samples.front() {
            if first < t - MOTION_SPAN || self.samples.len() >= CAPACITY {
                self.samples.pop_front();
            } else {
                break;
            }
        }
        self.samples.push_back((t, position));
    }

    /// Forgets every pose (a pose jump: the old ones are another frame).
    pub fn reset(&mut self) {
        self.samples.clear();
    }

    /// The fitted motion at the newest pose; `None` with fewer than three
    /// poses or no spread in time. One pose alone gives no velocity.
    pub fn estimate(&self) -> Option<Motion> {
        let n = self.samples.len();
        let &(t_last, _) = self.samples.back()?;
        if n < 3 {
            return None;
        }
        let nf = n as f64;
        let mean_t = self.samples.iter().map(|(t, _)| t - t_last).sum::<f64>() / nf;
        let stt: f64 = self
            .samples
            .iter()
            .map(|(t, _)| (t - t_last - mean_t).powi(2))
            .sum();
        if stt < 1e-12 {
            return None;
        }
        let mut position = [0.0; 3];
        let mut velocity = [0.0; 3];
        for i in 0..3 {
            let mean_p = self.samples.iter().map(|(_, p)| p[i]).sum::<f64>() / nf;
            let stp: f64 = self
                .samples
                .iter()
                .map(|(t, p)| (t - t_last - mean_t) * (p[i] - mean_p))
                .sum();
            velocity[i] = stp / stt;
            position[i] = mean_p - velocity[i] * mean_t;
        }
        Some(Motion {
            t: t_last,
            position,
            velocity,
        })
    }
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn too_few_poses_give_no_motion() {
        let mut m = MotionEstimator::new();
        assert!(m.estimate().is_none());
        m.push(0.0, [0.0; 3]);
        m.push(0.02, [0.0; 3]);
        assert!(m.estimate().is_none());
        m.push(0.04, [0.0; 3]);
        assert_eq!(m.estimate().unwrap().velocity, [0.0; 3]);
        m.reset();
        assert!(m.estimate().is_none());
    }

    #[test]
    fn old_and_bad_poses_are_not_used() {
        let mut m = MotionEstimator::new();
        // Moving at 1 m/s long ago, then standing still.
        for k in 0..50 {
            m.push(k as f64 * 0.02, [k as f64 * 0.02, 0.0, 0.0]);
        }
        for k in 50..70 {
            m.push(k as f64 * 0.02, [1.0, 0.0, 0.0]);
        }
        m.push(f64::NAN, [5.0; 3]);
        m.push(2.0, [f64::NAN; 3]);
        m.push(0.5, [9.0; 3]);
        let e = m.estimate().unwrap();
        assert!(e.speed() < 1e-9, "{e:?}");
        assert!((e.position[0] - 1.0).abs() < 1e-9);
    }

    proptest! {
        /// A straight line at constant velocity is recovered exactly,
        /// whatever the (increasing) sample times.
        #[test]
        fn a_line_is_recovered(
            p0 in prop::array::uniform3(-100.0f64..100.0),
            v in prop::array::uniform3(-10.0f64..10.0),
            gaps in prop::collection::vec(0.005f64..0.05, 3..40),
        ) {
            let mut m = MotionEstimator::new();
            let mut t = 10.0;
            for g in &gaps {
                t += g;
                m.push(t, [p0[0] + v[0] * t, p0[1] + v[1] * t, p0[2] + v[2] * t]);
            }
            // At least three poses within the span (gaps ≤ 50 ms).
            let e = m.estimate().unwrap();
            for i in 0..3 {
                prop_assert!((e.velocity[i] - v[i]).abs() < 1e-6);
                prop_assert!((e.position[i] - (p0[i] + v[i] * t)).abs() < 1e-6);
            }
        }
    }
}
