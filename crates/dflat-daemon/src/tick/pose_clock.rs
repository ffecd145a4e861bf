//! The pose clock: when a pose was captured, on this computer's clock.
//!
//! With `link.pose_time = "source"` the source's own timestamp is mapped
//! onto this computer's clock ([`crate::clock::PoseClock`]). A source clock
//! that runs slow, or ever later than ours, shows as poses that arrive
//! later and later after their mapped capture; lagging more than
//! `safety.pose_max_latency_ms` for [`POSE_LATENCY_PERSISTENCE`] on end
//! is a pose clock fault ([`PoseLatency`]): from then on poses are stamped
//! with their arrival time (said, logged, counted).

use dflat_link::dialect::MavSeverity;
use tracing::error;

use super::ControlCore;
use crate::config::PoseTime;

/// A pose clock's lag must exceed its bound this long \[s\] to count.
pub const POSE_LATENCY_PERSISTENCE: f64 = 1.0;

/// The pose clock's lateness check (see the module docs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct PoseLatency {
    /// Since when poses have arrived later than the bound \[s\].
    late_since: Option<f64>,
    /// The source clock was found unusable: poses are stamped with their
    /// arrival time.
    faulted: bool,
}

impl PoseLatency {
    /// True once the source clock was found unusable.
    pub(super) fn faulted(&self) -> bool {
        self.faulted
    }

    /// A pose arrived at `arrival` \[s\] with its mapped `capture` time
    /// \[s\]; `max_latency` \[s\] is the bound. True when this pose makes
    /// the lag a fault (once).
    pub(super) fn check(&mut self, arrival: f64, capture: f64, max_latency: f64) -> bool {
        if self.faulted {
            return false;
        }
        let late = arrival - capture > max_latency;
        if !late {
            self.late_since = None;
            return false;
        }
        let since = *self.late_since.get_or_insert(arrival);
        self.faulted = arrival - since >= POSE_LATENCY_PERSISTENCE;
        self.faulted
    }
}

impl ControlCore {
    /// The capture time \[s\] of a pose arriving at `arrival` with the
    /// source's timestamp `source_time`: mapped by the pose clock with
    /// `link.pose_time = "source"` (until the clock is found unusable),
    /// else the arrival time.
    pub(super) fn capture_time(&mut self, arrival: f64, source_time: Option<f64>) -> f64 {
        if self.settings.pose.time == PoseTime::Arrival || self.poses.latency.faulted() {
            return arrival;
        }
        let capture = self.poses.clock.capture_time(arrival, source_time);
        let max = self.settings.pose.max_latency;
        if !self.poses.latency.check(arrival, capture, max) {
            return capture;
        }
        self.counts.guards.pose_clock_faults += 1;
        error!(
            lag_s = arrival - capture,
            "pose source clock runs slow or ever later: poses stamped with their arrival time"
        );
        self.text(
            MavSeverity::MAV_SEVERITY_WARNING,
            "dflat: pose clock lags, using arrival time",
        );
        // The samples held were stamped by the bad clock.
        self.reset_controller();
        arrival
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lag_counts_once_it_persists() {
        let mut l = PoseLatency::default();
        // Within the bound: nothing.
        assert!(!l.check(0.0, -0.05, 0.1));
        // Late from 1.0 s on; a timely pose in between restarts the wait.
        assert!(!l.check(1.0, 0.8, 0.1));
        assert!(!l.check(1.5, 1.45, 0.1));
        assert!(!l.check(1.6, 1.4, 0.1));
        assert!(!l.check(2.59, 2.3, 0.1));
        assert!(l.check(2.7, 2.3, 0.1));
        assert!(l.faulted());
        // Said once.
        assert!(!l.check(3.0, 2.0, 0.1));
        assert!(l.faulted());
    }
}
