//! A straight stop at constant deceleration ([`super::Reference::braking`]).

use nalgebra::Vector3;

use super::is_finite3;

/// A straight stop at constant deceleration, with its monotone progress.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Brake {
    /// Where the braking starts, NED \[m\].
    pub(super) start: Vector3<f64>,
    /// Unit direction of the motion.
    pub(super) dir: Vector3<f64>,
    /// Speed at the start [m/s] (> 0).
    pub(super) speed: f64,
    /// Deceleration [m/s²] (> 0).
    pub(super) decel: f64,
    /// Distance coasted at the initial speed before the deceleration
    /// starts (`speed · lag`: the attitude loop's response) \[m\].
    pub(super) coast: f64,
    /// Stopping distance `coast + speed² / (2·decel)` \[m\]; moves on with
    /// a vehicle that overshoots it (never back), up to [`Self::max_length`].
    pub(super) length: f64,
    /// The farthest the stop may move on: twice the nominal stopping
    /// distance \[m\]. Beyond it the vehicle is flown back, so a drift
    /// along the braking direction (a thrust or wind offset the disturbance
    /// estimator has not learnt yet) cannot carry the stop with it.
    pub(super) max_length: f64,
    /// Distance of the current closest point from the start \[m\].
    pub(super) progress: f64,
}

impl Brake {
    pub(super) fn point(&self, s: f64) -> Vector3<f64> {
        self.start + self.dir * s.clamp(0.0, self.length)
    }

    /// Speed on the braking profile at distance `s` [m/s].
    pub(super) fn speed_at(&self, s: f64) -> f64 {
        if s < self.coast {
            return self.speed;
        }
        (self.speed * self.speed - 2.0 * self.decel * (s - self.coast))
            .max(0.0)
            .sqrt()
    }

    /// Distance along the profile `tau` \[s\] after passing `s`.
    pub(super) fn advance(&self, s: f64, tau: f64) -> f64 {
        let coast_left = if self.speed > 0.0 {
            ((self.coast - s) / self.speed).max(0.0)
        } else {
            0.0
        };
        if tau <= coast_left {
            return s + self.speed * tau;
        }
        let s0 = s.max(self.coast);
        let v = self.speed_at(s0);
        let t = (tau - coast_left).min(v / self.decel);
        (s0 + v * t - 0.5 * self.decel * t * t).min(self.length)
    }

    pub(super) fn update(&mut self, q: &Vector3<f64>) {
        if is_finite3(q) {
            let s = (q - self.start).dot(&self.dir);
            // Past the stop point: the stop moves on with the vehicle,
            // by at most one more stopping distance.
            self.length = self.length.max(s.min(self.max_length));
            self.progress = s.clamp(self.progress, self.length);
        }
    }
}
