//! Goals that arrive over MAVLink: position setpoints (flown as routes)
//! and samples of streamed trajectories; and the reference rebuilt
//! whenever the supervisor's goal changes.
//!
//! SET_POSITION_TARGET_LOCAL_NED is a **stream sample** when its velocity
//! and/or acceleration are given (type_mask bits clear), except a first
//! sample whose velocity and acceleration are both exactly zero (what a
//! sender that leaves every bit clear sends with a position setpoint):
//! that one is a position setpoint. With `stream.implied_velocity`, a
//! position-only setpoint arriving within `stream.implied_max_gap_s` of
//! the previous one is a sample too (its velocity implied).
//!
//! **Time base.** A sample's time is the sender's `time_boot_ms` mapped
//! onto this computer's clock by the same estimator as the pose's
//! (`crate::clock::PoseClock`, its own instance): the smallest
//! `arrival − time_boot_ms` over `link.pose_clock_window_s` is taken as
//! the clock offset, i.e. the fastest message is assumed to have arrived
//! without delay. `time_boot_ms = 0` means "no time": the arrival time is
//! used. A mapped time later than the arrival, or more than
//! [`MAX_SAMPLE_AGE`] before it, is implausible (a sender reboot, a
//! clock from another origin): the arrival time is used and the estimate
//! restarts.
//!
//! With `stream.time_base = "autopilot"` the sender stamps its samples in
//! the autopilot's boot time (as MAVROS does), and they are mapped by the
//! pose clock (the autopilot's): a sample may then lie up to
//! `stream.max_ahead_s` after its arrival — **the trajectory sent ahead**.
//! Its samples are the knots of the reference (`dflat_control::reference`,
//! streams): flown as sent, continuous across updates; a new sample
//! replaces the stream's samples at and after its time (a replan). An
//! implausible mapped time, or none yet (no pose), stamps the arrival.
//!
//! The stream's samples are kept from its first (`stream_buffer`), while
//! it is flown and while it waits for engagement, so the stream flown at
//! engagement has the whole future it was sent.

use dflat_control::reference::{Reference, StreamSample};
use dflat_link::dialect::MavSeverity;
use nalgebra::Vector3;
use tracing::{debug, error, info, warn};

use super::settings::{CoreSettings, GoalSettings};
use super::{ControlCore, REFUSAL_TEXT_INTERVAL};
use crate::clock::PoseClock;
use crate::config::TimeBase;
use crate::envelope::Envelope;
use crate::mission::{Mission, MissionRunner};
use crate::supervisor::{Goal, Refusal, SetpointOutcome};
use crate::yaw::YawCommand;

/// The goals and the reference: the core's part that owns what is flown
/// towards — setpoints, the stream's samples, the mission — and the
/// envelope that bounds it.
#[derive(Debug)]
pub(super) struct Goals {
    /// The reference flown, if any.
    pub(super) reference: Option<Reference>,
    /// The supervisor's goal generation the reference was built for.
    pub(super) generation: u64,
    /// The flight envelope (fence, speed limit).
    pub(super) envelope: Envelope,
    /// Braking for overspeed (said once per excursion).
    pub(super) overspeed: bool,
    /// When each kind of refusal was last said \[s\] ([`Refusal::kind`]).
    pub(super) last_refusal_text: [Option<f64>; Refusal::KINDS],
    /// The mission uploaded over MAVLink, if any.
    pub(super) mission: Option<Mission>,
    /// The mission being flown (started), if any.
    pub(super) runner: Option<MissionRunner>,
    /// The last MISSION_CURRENT sent: when, and (seq, total, state).
    pub(super) mission_current_sent: Option<(f64, (u16, u16, dflat_link::dialect::MissionState))>,
    /// The yaw of the setpoint being flown \[rad\], if it set one.
    pub(super) setpoint_yaw: Option<f64>,
    /// The commanded heading, rate-limited.
    pub(super) yaw_command: YawCommand,
    /// The heading this tick's command carries \[rad\].
    pub(super) commanded_yaw: f64,
    /// Maps stream senders' `time_boot_ms` onto this computer's clock.
    pub(super) stream_clock: PoseClock,
    /// The stream's samples so far (the flown stream is built from them;
    /// kept while a stream is flown or pending).
    pub(super) stream_buffer: Option<Reference>,
    /// Arrival of the newest stream sample \[s\].
    pub(super) last_sample_arrival: Option<f64>,
    /// The newest position-only setpoint: arrival \[s\], (time \[s\], position \[m\]).
    pub(super) last_position_setpoint: Option<(f64, (f64, [f64; 3]))>,
}

impl Goals {
    /// No goal yet: the reference of goal `generation` is none.
    pub(super) fn new(settings: &CoreSettings, envelope: Envelope, generation: u64) -> Self {
        Self {
            reference: None,
            generation,
            envelope,
            overspeed: false,
            last_refusal_text: [None; Refusal::KINDS],
            mission: None,
            runner: None,
            mission_current_sent: None,
            setpoint_yaw: None,
            yaw_command: YawCommand::new(settings.vehicle.max_yaw_rate),
            commanded_yaw: settings.vehicle.yaw,
            stream_clock: PoseClock::new(settings.pose.clock_window, 0.0),
            stream_buffer: None,
            last_sample_arrival: None,
            last_position_setpoint: None,
        }
    }
}

/// The reference for a goal (`None` for [`Goal::None`], and for
/// [`Goal::Mission`] and [`Goal::Stream`]: the core builds those section by
/// section and from the samples).
///
/// A setpoint is a route ([`Reference::setpoint_route`]) from `from`, the
/// vehicle's position and velocity (local NED \[m\], \[m/s\]), at
/// `mission.speed` with ramps of `stream.route_acceleration`; without
/// `from`, or at the target already, it is a fixed point.
pub fn reference_for(
    settings: &GoalSettings,
    goal: Goal,
    from: Option<([f64; 3], [f64; 3])>,
) -> Option<Result<Reference, dflat_control::ControlError>> {
    match goal {
        Goal::None | Goal::Mission | Goal::Stream => None,
        Goal::Hold(p) => Some(Reference::setpoint(Vector3::from(p))),
        Goal::Setpoint(p) => Some(match from {
            Some((q, v)) if (Vector3::from(p) - Vector3::from(q)).norm() > 1e-6 => {
                Reference::setpoint_route(
                    Vector3::from(q),
                    Vector3::from(v),
                    Vector3::from(p),
                    settings.speed,
                    settings.route_acceleration,
                )
            }
            _ => Reference::setpoint(Vector3::from(p)),
        }),
        Goal::Path => settings.path.clone(),
        // The attitude loop's response: half its time constant before the
        // deceleration builds up (a first-order lag reaches half its step
        // at 0.69 τ; the plan ramps the tilt in meanwhile).
        Goal::Brake { from, velocity } => Some(Reference::braking(
            Vector3::from(from),
            Vector3::from(velocity),
            settings.brake_acceleration,
            settings.brake_lag,
        )),
    }
}

/// A sample mapped to more than this long \[s\] before its arrival is
/// stamped with its arrival instead.
pub const MAX_SAMPLE_AGE: f64 = 1.0;

impl ControlCore {
    /// SET_POSITION_TARGET_LOCAL_NED arrived (see the module docs); `yaw`
    /// is its heading \[rad\] and heading rate \[rad/s\], each when given.
    pub(super) fn apply_setpoint(
        &mut self,
        arrival: f64,
        position: [f64; 3],
        (yaw, yaw_rate): (Option<f64>, Option<f64>),
        source_time: Option<f64>,
        velocity: Option<[f64; 3]>,
        acceleration: Option<[f64; 3]>,
    ) {
        let streaming = self.supervisor.goal() == Goal::Stream
            || self.supervisor.pending_goal() == Goal::Stream;
        let given = velocity.is_some() || acceleration.is_some();
        let zero =
            velocity.is_none_or(|v| v == [0.0; 3]) && acceleration.is_none_or(|a| a == [0.0; 3]);
        let s = &self.settings.goals.stream;
        let position_only = !given;
        let implied = position_only
            && s.implied_velocity
            && self
                .goals
                .last_position_setpoint
                .is_some_and(|(a, _)| arrival - a <= s.implied_max_gap_s && arrival > a);
        let t_sample = self.sample_time(arrival, source_time);
        let previous = self.goals.last_position_setpoint;
        if position_only {
            self.goals.last_position_setpoint = Some((arrival, (t_sample, position)));
        }
        if (given && (streaming || !zero)) || implied {
            let sample = StreamSample {
                t: t_sample,
                position: Vector3::from(position),
                velocity: velocity.map(Vector3::from),
                acceleration: acceleration.map(Vector3::from),
                yaw,
                yaw_rate,
            };
            let seed = if implied {
                previous.map(|(_, p)| p)
            } else {
                None
            };
            self.apply_sample(arrival, sample, seed);
            if self.supervisor.goal() == Goal::Stream {
                self.goals.setpoint_yaw = yaw;
            }
        } else {
            self.apply_position_setpoint(arrival, position, yaw);
        }
    }

    /// The sample's time on this computer's clock (module docs).
    fn sample_time(&mut self, arrival: f64, source_time: Option<f64>) -> f64 {
        if self.settings.goals.stream_time_base == TimeBase::Autopilot {
            // The autopilot's clock, as the poses map it; a sample may lie
            // ahead (the trajectory sent ahead).
            let mapped = source_time
                .filter(|_| !self.poses.latency.faulted())
                .and_then(|s| self.poses.clock.map(s));
            return match mapped {
                Some(t)
                    if t <= arrival + self.settings.goals.stream.max_ahead_s
                        && arrival - t <= MAX_SAMPLE_AGE =>
                {
                    t
                }
                _ => arrival,
            };
        }
        let t = self.goals.stream_clock.capture_time(arrival, source_time);
        if t > arrival + 1e-9 || arrival - t > MAX_SAMPLE_AGE || !t.is_finite() {
            self.goals.stream_clock.reset();
            return arrival;
        }
        t
    }

    /// Counts a refused goal and says why, each kind of refusal at most
    /// once per [`REFUSAL_TEXT_INTERVAL`] (a fence refusal said does not
    /// hide a speed refusal after it).
    fn refuse(&mut self, t: f64, refusal: Refusal) {
        self.counts.setpoints_refused += 1;
        let last = &mut self.goals.last_refusal_text[refusal.kind()];
        let due = last.is_none_or(|last| t - last >= REFUSAL_TEXT_INTERVAL);
        if due {
            *last = Some(t);
            info!(?refusal, "setpoint refused");
            self.text(MavSeverity::MAV_SEVERITY_WARNING, &refusal.text());
        }
    }

    /// A position setpoint: flown as a route from the vehicle's motion.
    fn apply_position_setpoint(&mut self, t: f64, position: [f64; 3], yaw: Option<f64>) {
        match self.supervisor.on_setpoint(t, position) {
            SetpointOutcome::Accepted { goal, transition } => {
                debug!(?goal, "setpoint accepted");
                self.goals.setpoint_yaw = yaw;
                if let Some(tr) = transition {
                    self.announce(tr);
                }
                self.refresh_reference();
            }
            SetpointOutcome::Unchanged => self.goals.setpoint_yaw = yaw,
            SetpointOutcome::Refused(refusal) => self.refuse(t, refusal),
        }
    }

    /// A stream sample (arrived at `arrival`); `seed` is the position-only
    /// setpoint before it (implied velocity).
    fn apply_sample(&mut self, arrival: f64, sample: StreamSample, seed: Option<(f64, [f64; 3])>) {
        // A trajectory the vehicle cannot have (the envelope's speed and
        // tilt limits) is refused in words, before it can fly anything.
        let motion = |v: Option<Vector3<f64>>| v.map(|v| [v.x, v.y, v.z]);
        if let Err(breach) = self
            .goals
            .envelope
            .check_motion(motion(sample.velocity), motion(sample.acceleration))
        {
            let refusal = match breach {
                crate::envelope::Breach::Speed(speed) => Refusal::Speed { speed },
                crate::envelope::Breach::Acceleration(acceleration) => {
                    Refusal::Acceleration { acceleration }
                }
                crate::envelope::Breach::Fence => Refusal::Geofence {
                    position: [sample.position.x, sample.position.y, sample.position.z],
                },
            };
            warn!(?refusal, "stream sample outside the envelope: refused");
            self.refuse(arrival, refusal);
            return;
        }
        // The stream's samples so far (a new stream starts here).
        let streaming = self.supervisor.goal() == Goal::Stream
            || self.supervisor.pending_goal() == Goal::Stream;
        if !streaming {
            self.goals.stream_buffer = None;
        }
        // The jump check: from the stream's own trajectory, else from the
        // vehicle.
        let from = match &self.goals.stream_buffer {
            Some(b) => b.stream_position_at(sample.t),
            None => self.poses.newest.map(|p| Vector3::from(p.position)),
        };
        if let Some(from) = from {
            let distance = (sample.position - from).norm();
            if distance > self.settings.goals.stream_max_jump {
                warn!(distance, "stream sample jumps: refused");
                self.refuse(arrival, Refusal::StreamJump { distance });
                return;
            }
        }
        if let Err(e) = self.buffer_sample(arrival, &sample, seed) {
            debug!(error = %e, "stream sample not used");
            return;
        }
        let position = [sample.position.x, sample.position.y, sample.position.z];
        match self.supervisor.on_stream(arrival, position) {
            SetpointOutcome::Refused(refusal) => self.refuse(arrival, refusal),
            SetpointOutcome::Unchanged => {
                self.goals.last_sample_arrival = Some(arrival);
                if let Some(r) = self.goals.reference.as_mut().filter(|r| r.is_stream())
                    && let Err(e) = r.push_sample(&sample)
                {
                    debug!(error = %e, "stream sample not used");
                }
            }
            SetpointOutcome::Accepted { goal, transition } => {
                debug!(?goal, "stream accepted");
                self.goals.last_sample_arrival = Some(arrival);
                if let Some(tr) = transition {
                    self.announce(tr);
                }
                self.refresh_reference();
            }
        }
    }

    /// Adds `sample`, arrived at `arrival` \[s\], to the stream's samples (a
    /// new stream from it, after
    /// `seed`, the position-only setpoint before it, if any). An error
    /// changes nothing.
    fn buffer_sample(
        &mut self,
        arrival: f64,
        sample: &StreamSample,
        seed: Option<(f64, [f64; 3])>,
    ) -> Result<(), dflat_control::ControlError> {
        if let Some(b) = self.goals.stream_buffer.as_mut() {
            b.set_time(arrival);
            return b.push_sample(sample);
        }
        let settings = self.settings.goals.stream;
        // A seed before the sample starts the stream; the sample follows.
        let seed = seed
            .filter(|&(t, _)| t < sample.t)
            .map(|(t, p)| StreamSample {
                t,
                position: Vector3::from(p),
                velocity: None,
                acceleration: None,
                yaw: None,
                yaw_rate: None,
            });
        let mut b = Reference::stream(settings, seed.as_ref().unwrap_or(sample))?;
        b.set_time(arrival);
        if seed.is_some() {
            b.push_sample(sample)?;
        }
        self.goals.stream_buffer = Some(b);
        Ok(())
    }

    /// The stream's reference: its samples so far (`None`: no sample).
    pub(super) fn stream_reference(&self) -> Option<Reference> {
        self.goals.stream_buffer.clone()
    }

    /// A flown stream without samples for `stream.timeout_s` (and past the
    /// end of any trajectory sent ahead for as long): stop smoothly where
    /// the extrapolation stops, and hold there.
    pub(super) fn check_stream_timeout(&mut self, t: f64) {
        if self.supervisor.goal() != Goal::Stream {
            return;
        }
        let Some(arrived) = self.goals.last_sample_arrival else {
            return;
        };
        // A trajectory sent ahead is flown to its end before it is lost.
        let sent_until = self
            .goals
            .reference
            .as_ref()
            .and_then(Reference::last_sample)
            .map_or(arrived, |s| s.t);
        let last = arrived.max(sent_until);
        if t - last <= self.settings.goals.stream_timeout {
            return;
        }
        // Where the stream stops lies inside the fence.
        self.bound_reference();
        let Some(rest) = self.goals.reference.as_ref().map(Reference::rest_point) else {
            return;
        };
        if let Some(tr) = self
            .supervisor
            .on_stream_timeout(t, [rest.x, rest.y, rest.z])
        {
            warn!(silent_s = t - last, "stream lost: stopping");
            self.counts.stream_timeouts += 1;
            self.announce(tr);
            self.refresh_reference();
        }
    }

    /// Rebuilds the reference when the supervisor's goal changed.
    pub(super) fn refresh_reference(&mut self) {
        let generation = self.supervisor.goal_generation();
        if generation == self.goals.generation {
            return;
        }
        self.goals.generation = generation;
        if self.supervisor.goal() == Goal::Mission {
            self.goals.reference = match self.mission_reference() {
                Some(Ok(r)) => Some(r),
                Some(Err(e)) => {
                    error!(error = %e, "cannot build the mission's reference; keeping the previous one");
                    self.goals.reference.take()
                }
                None => self.goals.reference.take(),
            };
            return;
        }
        let goal = self.supervisor.goal();
        // A lost stream holds where its extrapolation stops: keep flying
        // the stream's own smooth stop there.
        if let Goal::Hold(p) = goal
            && self
                .goals
                .reference
                .as_ref()
                .is_some_and(|r| r.is_stream() && (r.rest_point() - Vector3::from(p)).norm() < 1e-9)
        {
            return;
        }
        if goal == Goal::Stream {
            if let Some(r) = self.stream_reference() {
                self.goals.reference = Some(r);
            }
            return;
        }
        // Setpoints are routes from the vehicle's position and velocity.
        let from = match self.poses.motion.estimate() {
            Some(m) => Some((m.position, m.velocity)),
            None => self.poses.newest.map(|p| (p.position, [0.0; 3])),
        };
        self.goals.reference = match reference_for(&self.settings.goals, goal, from) {
            Some(Ok(mut r)) => {
                if self.supervisor.path_resumed()
                    && let Some(p) = self.poses.newest
                {
                    r.seek(&Vector3::from(p.position));
                }
                Some(r)
            }
            Some(Err(e)) => {
                // Validated at start; a setpoint is checked finite. Keep
                // flying the previous reference rather than none.
                error!(error = %e, "cannot build the reference; keeping the previous one");
                self.goals.reference.take()
            }
            None => None,
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    #[test]
    fn references_of_goals() {
        let mut cfg = Config::default();
        let goals = GoalSettings::new(&cfg);
        assert!(reference_for(&goals, Goal::None, None).is_none());
        assert!(reference_for(&goals, Goal::Path, None).unwrap().is_ok());
        assert!(
            reference_for(&goals, Goal::Hold([0.0; 3]), None)
                .unwrap()
                .is_ok()
        );
        cfg.mission.path.clear();
        assert!(reference_for(&GoalSettings::new(&cfg), Goal::Path, None).is_none());
    }
}
