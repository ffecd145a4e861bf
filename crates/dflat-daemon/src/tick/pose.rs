//! Poses into the core: the capture time (`tick/pose_clock.rs`), the
//! newest pose, the samples a multi-rate controller observes, the motion
//! estimate, and jumps (re-anchoring).

use dflat_control::Measurement;
use dflat_link::dialect::MavSeverity;
use nalgebra::Vector3;
use tracing::warn;

use super::ControlCore;
use super::pose_clock::PoseLatency;
use super::settings::PoseSettings;
use crate::clock::PoseClock;
use crate::config::PoseSourceKind;
use crate::guard::{departs_from_motion, is_pose_jump};
use crate::motion::MotionEstimator;

/// The pose clock and window: the core's part that owns what the poses
/// and the autopilot's attitude said.
#[derive(Debug)]
pub(super) struct Poses {
    /// Maps the pose source's clock onto this computer's.
    pub(super) clock: PoseClock,
    /// The pose clock's lateness check (`tick/pose_clock.rs`).
    pub(super) latency: PoseLatency,
    /// The newest pose.
    pub(super) newest: Option<PoseSample>,
    /// Newest ATTITUDE yaw \[rad\].
    pub(super) attitude_yaw: Option<f64>,
    /// Newest ATTITUDE (pitch, roll) as a world-frame tilt \[rad\].
    pub(super) attitude: Option<[f64; 2]>,
    /// The vehicle's motion from the poses (engagement's stop point).
    pub(super) motion: MotionEstimator,
    /// Arrival \[s\] of the pose the last command used.
    pub(super) last_used_arrival: Option<f64>,
}

impl Poses {
    /// Nothing heard yet, the clock per `settings`.
    pub(super) fn new(settings: &PoseSettings) -> Self {
        Self {
            clock: PoseClock::new(settings.clock_window, settings.min_latency),
            latency: PoseLatency::default(),
            newest: None,
            attitude_yaw: None,
            attitude: None,
            motion: MotionEstimator::new(),
            last_used_arrival: None,
        }
    }
}

/// One pose as the control core keeps it.
#[derive(Debug, Clone, Copy)]
pub(super) struct PoseSample {
    /// Arrival on this computer \[s\].
    pub(super) arrival: f64,
    /// Capture time on this computer's clock \[s\].
    pub(super) capture: f64,
    /// The source's own timestamp \[s\], if it has one.
    pub(super) source_time: Option<f64>,
    /// Position, local NED \[m\].
    pub(super) position: [f64; 3],
    /// Yaw from the pose message \[rad\], if it has one.
    pub(super) yaw: Option<f64>,
    /// Estimator reset counter, if the message has one.
    pub(super) reset_counter: Option<u8>,
}

impl ControlCore {
    /// A pose arrived: the supervisor learns it, it is stamped, checked
    /// for a jump and kept when newer than the one held.
    pub(super) fn apply_pose(
        &mut self,
        arrival: f64,
        source_time: Option<f64>,
        position: [f64; 3],
        yaw: Option<f64>,
        reset_counter: Option<u8>,
    ) {
        self.supervisor.on_pose(arrival, position);
        let capture = self.capture_time(arrival, source_time);
        let mut pose = PoseSample {
            arrival,
            capture,
            source_time,
            position,
            yaw,
            reset_counter,
        };
        // A jump from the newest pose (further than the vehicle can fly in
        // between, or an estimator reset): re-anchor below.
        // Judged against the motion the poses show (a fast vehicle is not
        // a jump); without a motion estimate yet, against the speed limit.
        let margin = self.settings.pose.jump_margin;
        let max_speed = self.settings.goals.max_speed;
        let velocity = self.poses.motion.estimate().map(|m| m.velocity);
        let max_acceleration = self.goals.envelope.max_acceleration;
        let jump = self.poses.newest.is_some_and(|p| {
            let dt = capture - p.capture;
            let counters = (p.reset_counter, reset_counter);
            capture >= p.capture
                && match velocity {
                    Some(v) => departs_from_motion(
                        p.position,
                        v,
                        position,
                        dt,
                        self.settings.period,
                        max_acceleration,
                        margin,
                        counters,
                    ),
                    None => is_pose_jump(
                        p.position,
                        position,
                        dt,
                        max_speed,
                        self.settings.period,
                        margin,
                        counters,
                    ),
                }
        });
        // Every sample to a multi-rate controller (late ones too).
        // The motion estimate restarts at a jump (the old poses are
        // another frame).
        if jump {
            self.poses.motion.reset();
        } else {
            self.observe(&pose);
        }
        self.poses.motion.push(capture, position);
        // The newest for the others, by the source's own clock when both
        // have one (a falling offset estimate may map a newer pose before
        // the previous capture), else by capture time; its time must then
        // be newer than the previous one's, or the controller takes the
        // tick as one without a new pose.
        let newer = |p: &PoseSample| match (source_time, p.source_time) {
            (Some(a), Some(b)) if (a - b).abs() < crate::clock::SOURCE_RESET => a > b,
            _ => capture > p.capture,
        };
        match self.poses.newest {
            None => self.poses.newest = Some(pose),
            Some(p) if newer(&p) => {
                pose.capture = pose.capture.max(p.capture + 1e-6);
                self.poses.newest = Some(pose);
            }
            Some(_) => {}
        }
        if jump {
            // The jumped pose is the newest one now.
            self.poses.newest = Some(pose);
            self.re_anchor(arrival, &pose);
        }
    }

    /// Re-anchors after a pose jump to `pose`: controller window reset (a
    /// multi-rate one gets this pose), held / predicted state forgotten,
    /// the reference holds the new position.
    pub(super) fn re_anchor(&mut self, t: f64, pose: &PoseSample) {
        self.counts.guards.pose_jumps += 1;
        self.controller.reset();
        if self.settings.multi_rate {
            self.observe(pose);
        }
        self.failsafe.fallback.forget();
        self.failsafe.residual.forget();
        self.guard_note = Some("jump");
        warn!(position = ?pose.position, "pose jump: re-anchored");
        match self.supervisor.re_anchor(t, pose.position) {
            Some(tr) => self.announce(tr),
            None => self.text(
                MavSeverity::MAV_SEVERITY_WARNING,
                "dflat: pose jump, re-anchored",
            ),
        }
        self.refresh_reference();
    }

    /// The yaw a measurement carries: the pose message's (ODOMETRY,
    /// VISION_POSITION_ESTIMATE), ATTITUDE's (LOCAL_POSITION_NED), else the
    /// configured fixed yaw.
    pub(super) fn yaw_of(&self, pose_yaw: Option<f64>, attitude_yaw: Option<f64>) -> f64 {
        let yaw = if self.settings.pose.source == PoseSourceKind::LocalPositionNed {
            attitude_yaw
        } else {
            pose_yaw
        };
        yaw.unwrap_or(self.settings.vehicle.yaw)
    }

    /// Hands a pose to a multi-rate controller at its capture time.
    pub(super) fn observe(&mut self, pose: &PoseSample) {
        let sample = Measurement {
            t: pose.capture,
            position: Vector3::from(pose.position),
            yaw: self.yaw_of(pose.yaw, self.poses.attitude_yaw),
        };
        self.controller.observe(&sample);
    }
}
