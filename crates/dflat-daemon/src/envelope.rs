//! The flight envelope: one fence (with a ceiling and a floor) and one
//! speed limit that bound every goal before it becomes a reference.
//!
//! * **Positions.** The fence is a box around the local origin (NED):
//!   `|x| ≤ mission.geofence[0]`, `|y| ≤ mission.geofence[1]`, up to
//!   `mission.geofence[2]` above the origin (`z ≥ −geofence[2]`) and at most
//!   `mission.geofence_down_m` below it (`z ≤ geofence_down_m`: the floor).
//!   A setpoint, a configured path's or an uploaded mission's waypoint, or
//!   a stream sample outside it is refused in words; every reference the
//!   controller flies is clamped into it ([`Envelope::bounds`], applied in
//!   the tick), so neither a stream's prediction nor the point where a
//!   lost stream stops can leave it.
//! * **Speed and acceleration.** A stream sample whose velocity exceeds
//!   `safety.max_speed_mps`, or whose horizontal acceleration needs more
//!   tilt than `vehicle.max_tilt_deg` (`|a_xy| > g·tan(max_tilt)`), is a
//!   trajectory the vehicle cannot have: refused in words. Paths and
//!   routes fly at `mission.speed`, validated at or below the limit; a
//!   DO_CHANGE_SPEED above it is refused. A vehicle measured faster than
//!   the limit while engaged is braked (`tick/overspeed.rs`).

use dflat_control::reference::Bounds;
use nalgebra::Vector3;

use crate::config::Config;

/// Why a goal is outside the envelope.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Breach {
    /// A position outside the fence's box.
    Fence,
    /// A speed above the limit \[m/s\].
    Speed(f64),
    /// A horizontal acceleration beyond the tilt limit's \[m/s²\].
    Acceleration(f64),
}

/// The flight envelope (see the module docs). All positions local NED \[m\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// The fence's box.
    pub bounds: Bounds,
    /// The speed limit [m/s] (`safety.max_speed_mps`).
    pub max_speed: f64,
    /// The largest horizontal acceleration \[m/s²\] the tilt limit allows,
    /// `g·tan(vehicle.max_tilt_deg)`.
    pub max_acceleration: f64,
}

impl Envelope {
    /// The envelope of a configuration. Its fields are validated; an
    /// unvalidated fence that cannot make a box gives the empty box at the
    /// origin (everything refused), never an unbounded one.
    pub fn from_config(cfg: &Config) -> Self {
        let g = cfg.mission.geofence;
        let min = Vector3::new(-g[0], -g[1], -g[2]);
        let max = Vector3::new(g[0], g[1], cfg.mission.geofence_down_m);
        let bounds = Bounds::new(min, max).unwrap_or_else(|_| {
            Bounds::new(Vector3::zeros(), Vector3::zeros()).expect("the empty box is a box")
        });
        Self {
            bounds,
            max_speed: cfg.safety.max_speed_mps,
            max_acceleration: cfg.vehicle.gravity * cfg.vehicle.max_tilt_deg.to_radians().tan(),
        }
    }

    /// True when `p` is finite and inside the fence.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        p.iter().all(|v| v.is_finite()) && self.bounds.contains(&Vector3::from(p))
    }

    /// Whether a stream sample's velocity and acceleration (local NED,
    /// [m/s], [m/s²]) are ones the vehicle can have.
    pub fn check_motion(
        &self,
        velocity: Option<[f64; 3]>,
        acceleration: Option<[f64; 3]>,
    ) -> Result<(), Breach> {
        if let Some(v) = velocity {
            let speed = Vector3::from(v).norm();
            if speed.is_nan() || speed > self.max_speed {
                return Err(Breach::Speed(speed));
            }
        }
        if let Some(a) = acceleration {
            let horizontal = a[0].hypot(a[1]);
            if horizontal.is_nan() || horizontal > self.max_acceleration {
                return Err(Breach::Acceleration(horizontal));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn envelope() -> Envelope {
        let mut cfg = Config::default();
        cfg.mission.geofence = [30.0, 30.0, 100.0];
        cfg.mission.geofence_down_m = 5.0;
        cfg.safety.max_speed_mps = 15.0;
        Envelope::from_config(&cfg)
    }

    #[test]
    fn the_fence_has_a_floor_apart_from_its_ceiling() {
        let e = envelope();
        assert!(e.contains([0.0, 0.0, -99.0]));
        assert!(!e.contains([0.0, 0.0, -101.0]));
        assert!(e.contains([0.0, 0.0, 4.9]));
        // 150 m below the origin: refused although |z| < 200 would pass a
        // symmetric fence.
        assert!(!e.contains([0.0, 0.0, 6.0]));
        assert!(!e.contains([31.0, 0.0, 0.0]));
        assert!(!e.contains([0.0, f64::NAN, 0.0]));
    }

    #[test]
    fn motion_beyond_the_speed_or_tilt_limit_is_refused() {
        let e = envelope();
        assert_eq!(e.check_motion(Some([14.0, 0.0, 0.0]), None), Ok(()));
        assert_eq!(
            e.check_motion(Some([20.0, 0.0, 0.0]), None),
            Err(Breach::Speed(20.0))
        );
        assert!(matches!(
            e.check_motion(Some([1000.0, 0.0, 0.0]), None),
            Err(Breach::Speed(_))
        ));
        assert!(matches!(
            e.check_motion(Some([f64::NAN, 0.0, 0.0]), None),
            Err(Breach::Speed(_))
        ));
        // 35°: g·tan(35°) = 6.87 m/s².
        assert_eq!(e.check_motion(None, Some([6.0, 0.0, 3.0])), Ok(()));
        assert!(matches!(
            e.check_motion(None, Some([6.0, 4.0, 0.0])),
            Err(Breach::Acceleration(_))
        ));
    }
}
