//! Pose capture times on this computer's clock.
//!
//! The multi-rate DF-MPC window fits every pose at the time it was
//! *captured*, on the clock of the control ticks (this computer's monotonic
//! clock, seconds since the daemon started). A pose message carries its
//! capture time on the *source's* clock: LOCAL_POSITION_NED `time_boot_ms`
//! (the autopilot's boot clock), ODOMETRY / VISION_POSITION_ESTIMATE
//! `time_usec` (the estimator's clock: boot time or Unix time). The two
//! clocks differ by an unknown offset and drift slowly.
//!
//! # The offset estimate
//!
//! Every pose gives `arrival − source time = offset + latency`, with latency
//! ≥ its minimum. The running minimum over a sliding window
//! (`link.pose_clock_window_s`, default 10 s) therefore converges to
//! `offset + minimum latency` from above, as soon as one message travels at
//! the minimum latency, and follows drift within the window. The capture
//! time on this computer's clock is
//!
//! ```text
//! t_capture = source time + min_window(arrival − source time) − min_latency
//! ```
//!
//! with `min_latency` = `link.pose_min_latency_ms` (default 0). With the
//! default the estimate **assumes a minimum transport latency ≈ 0**: a
//! constant part of the latency (a vision pipeline's exposure-to-message
//! delay) is indistinguishable from the clock offset and is *not*
//! compensated, only the variable part (jitter, queueing, late or
//! out-of-order messages) is. Configure the known minimum latency to have
//! it compensated too. The alternative is MAVLink TIMESYNC (round-trip
//! offset estimation with the autopilot; it measures the offset without
//! the latency assumption, but only for the autopilot's clock, not for a
//! separate vision component). Capture times never lie after the arrival
//! (with `min_latency` = 0 they are ≤ arrival by construction).
//!
//! A source timestamp that goes backwards by more than
//! [`SOURCE_RESET`] (a rebooted autopilot or estimator) restarts the
//! estimate. A pose without a timestamp (0), or `link.pose_time =
//! "arrival"`, uses the arrival time.
//!
//! Storage: a monotone deque (the classic sliding-window minimum, amortised
//! O(1) per pose), capacity fixed at construction; when full the oldest
//! entry is dropped, which only shortens the window.

use std::collections::VecDeque;

/// A source clock that jumps back by more than this \[s\] restarts the estimate.
pub const SOURCE_RESET: f64 = 1.0;
/// Entries the sliding minimum keeps at most (a window of 10 s at 200 Hz
/// needs 2000 only when the offset grows monotonically).
pub const CAPACITY: usize = 4096;

/// The clock-offset estimator of one pose source (see the module docs).
#[derive(Debug, Clone)]
pub struct PoseClock {
    window: f64,
    min_latency: f64,
    /// (arrival \[s\], arrival − source \[s\]), offsets increasing front to back.
    minima: VecDeque<(f64, f64)>,
    last_source: Option<f64>,
}

impl PoseClock {
    /// An estimator over a sliding `window` \[s\] with a known minimum
    /// latency `min_latency` \[s\] (0: assume none).
    pub fn new(window: f64, min_latency: f64) -> Self {
        Self {
            window: if window.is_finite() && window > 0.0 {
                window
            } else {
                1.0
            },
            min_latency: if min_latency.is_finite() {
                min_latency.max(0.0)
            } else {
                0.0
            },
            minima: VecDeque::with_capacity(CAPACITY),
            last_source: None,
        }
    }

    /// Forgets the estimate.
    pub fn reset(&mut self) {
        self.minima.clear();
        self.last_source = None;
    }

    /// The current offset estimate `min(arrival − source)` \[s\], if any.
    pub fn offset(&self) -> Option<f64> {
        self.minima.front().map(|&(_, o)| o)
    }

    /// The time on this computer's clock \[s\] of source time `source` \[s\]
    /// by the current estimate, without updating it (`None` before any
    /// estimate, or for a non-finite `source`).
    pub fn map(&self, source: f64) -> Option<f64> {
        let t = source + self.offset()? - self.min_latency;
        t.is_finite().then_some(t)
    }

    /// The capture time on this computer's clock \[s\] of a pose that arrived
    /// at `arrival` \[s\] with source timestamp `source` \[s\] (`None`: no
    /// timestamp, the arrival time is returned). Non-finite inputs return
    /// the arrival time and leave the estimate unchanged.
    pub fn capture_time(&mut self, arrival: f64, source: Option<f64>) -> f64 {
        let Some(source) = source.filter(|s| s.is_finite() && arrival.is_finite()) else {
            return arrival;
        };
        if self
            .last_source
            .is_some_and(|last| source < last - SOURCE_RESET)
        {
            self.minima.clear();
        }
        self.last_source = Some(self.last_source.map_or(source, |l| l.max(source)));
        let offset = arrival - source;
        while self.minima.back().is_some_and(|&(_, o)| o >= offset) {
            self.minima.pop_back();
        }
        if self.minima.len() == CAPACITY {
            self.minima.pop_front();
        }
        self.minima.push_back((arrival, offset));
        while self.minima.len() > 1
            && self
                .minima
                .front()
                .is_some_and(|&(a, _)| a < arrival - self.window)
        {
            self.minima.pop_front();
        }
        let min = self.offset().unwrap_or(offset);
        source + min - self.min_latency
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_to_the_latency_floor_and_removes_jitter() {
        let mut c = PoseClock::new(5.0, 0.0);
        // Source clock 100 s ahead; latency 5 ms + jitter up to 20 ms.
        let mut last = 0.0;
        for i in 0..500 {
            let capture = i as f64 * 0.02;
            let jitter = ((i * 7919) % 20) as f64 * 1e-3;
            let arrival = capture + 0.005 + jitter;
            let t = c.capture_time(arrival, Some(capture + 100.0));
            assert!(t <= arrival + 1e-12);
            last = t - capture;
        }
        // After the window filled: capture time + the 5 ms floor.
        assert!((last - 0.005).abs() < 1e-9, "{last}");
        assert!((c.offset().unwrap() - (0.005 - 100.0)).abs() < 1e-9);
    }

    #[test]
    fn known_minimum_latency_is_compensated() {
        let mut c = PoseClock::new(5.0, 0.06);
        for i in 0..100 {
            let capture = i as f64 / 15.0;
            let t = c.capture_time(capture + 0.06, Some(capture + 3.0));
            assert!((t - capture).abs() < 1e-9, "{t} vs {capture}");
        }
    }

    #[test]
    fn follows_drift_and_restarts_on_a_source_reset() {
        let mut c = PoseClock::new(1.0, 0.0);
        // The offset grows (source clock slow); the window forgets old minima.
        for i in 0..300 {
            let a = i as f64 * 0.02;
            c.capture_time(a, Some(a * 0.99));
        }
        let expected = 299.0 * 0.02 * 0.01;
        assert!(
            (c.offset().unwrap() - expected).abs() < 0.011,
            "{:?}",
            c.offset()
        );
        // Source reboots: time starts again near 0.
        let t = c.capture_time(10.0, Some(0.5));
        assert!((t - 10.0).abs() < 1e-12);
        assert!((c.offset().unwrap() - 9.5).abs() < 1e-12);
    }

    #[test]
    fn missing_or_bad_timestamps_use_arrival() {
        let mut c = PoseClock::new(5.0, 0.0);
        assert_eq!(c.capture_time(1.5, None), 1.5);
        assert_eq!(c.capture_time(1.5, Some(f64::NAN)), 1.5);
        assert!(c.offset().is_none());
    }
}
