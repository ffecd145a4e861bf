//! The flight envelope in the core ([`crate::envelope`]): every reference
//! clamped into the fence, a vehicle faster than the speed limit braked,
//! and the stop sequence that leaves the autopilot a level command when
//! the daemon is asked to stop.
//!
//! **The stop** (SIGTERM / SIGINT, [`ControlCore::begin_stop`]): while
//! engaged, (optionally) the autopilot is asked for its own position hold;
//! the supervisor's goal becomes a stop from the vehicle's motion, flown by
//! the controller on live poses for at most `safety.stop_brake_ms` (over
//! sooner once slower than [`crate::supervisor::BRAKED_SPEED`]); then the
//! failsafe's level hover for `safety.stop_level_ms`; then the stream
//! stops ([`ControlCore::stop_done`]). Not engaged, or the autopilot left
//! its offboard mode: done at once.

use dflat_link::dialect::{COMMAND_LONG_DATA, MavCmd, MavSeverity};
use dflat_link::{AttitudeCommand, AutopilotFamily, MavMessage};
use tracing::{info, warn};

use super::ControlCore;
use crate::supervisor::{BRAKED_SPEED, Cause, FlightState};

/// Speeds above the limit by less than this fraction are measurement noise
/// (the motion estimate of a vehicle flying at the limit).
pub const OVERSPEED_MARGIN: f64 = 0.1;

/// The CSV `guard` of the tick at which the stop was asked for.
pub const STOP_GUARD: &str = "stop";

/// Where the stop sequence stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Stop {
    /// When the stop was asked for \[s\].
    started: f64,
    /// The flight state then (the flight's last state before the stop).
    state: FlightState,
    /// When the level hover began \[s\] (`None`: still braking).
    level_since: Option<f64>,
    /// Nothing to brake (not engaged when asked, or the autopilot left
    /// offboard): the stream may stop now.
    done: bool,
    /// The supervisor's time in states and transitions when asked.
    times: [f64; 5],
    transitions: u64,
    /// Commands sent since, and the last one's tick time \[s\].
    pub(super) commands: u64,
    pub(super) last_command: Option<f64>,
}

/// The stop's level phase moves roll and pitch towards level by at most
/// this much per tick \[rad\] (4°: under the 5°/tick of any goal change).
pub const STOP_LEVEL_RAMP: f64 = 4.0 * std::f64::consts::PI / 180.0;

impl ControlCore {
    /// Clamps the reference about to be flown into the fence (idempotent).
    pub(super) fn bound_reference(&mut self) {
        let bounds = self.goals.envelope.bounds;
        if let Some(r) = self.goals.reference.as_mut()
            && r.bounds().is_none()
        {
            r.set_bounds(Some(bounds));
        }
    }

    /// A vehicle measured faster than the speed limit while engaged is
    /// braked to a stop (said once per excursion, counted).
    pub(super) fn check_overspeed(&mut self, t: f64) {
        let Some(speed) = self.poses.motion.estimate().map(|m| m.speed()) else {
            return;
        };
        let limit = self.goals.envelope.max_speed;
        if speed <= limit {
            self.goals.overspeed = false;
            return;
        }
        if self.goals.overspeed || speed <= limit * (1.0 + OVERSPEED_MARGIN) {
            return;
        }
        if let Some(tr) = self.supervisor.overspeed(t) {
            self.goals.overspeed = true;
            self.counts.guards.overspeed_brakes += 1;
            warn!(speed, limit, "faster than safety.max_speed_mps: braking");
            self.announce(tr);
            self.text(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("dflat: speed {speed:.1} > limit {limit:.1} m/s"),
            );
            self.refresh_reference();
        }
    }

    /// Begins the stop sequence at `t` (module docs). Idempotent.
    pub fn begin_stop(&mut self, t: f64) {
        if self.engagement.stop.is_some() {
            return;
        }
        // The records say where the stop began (a replay begins it there).
        self.engagement.stop_marked = true;
        let state = self.supervisor.state();
        let engaged = state.engaged();
        let (times, transitions) = (
            self.supervisor.time_in_states(t),
            self.supervisor.transitions(),
        );
        let f = &self.settings.failsafe;
        let brakes = f.stop_brake > 0.0 || f.stop_level > 0.0;
        if !engaged || !brakes {
            // Not engaged: no transition, nothing to brake.
            let _ = self.supervisor.begin_stop(t);
            self.engagement.stop = Some(Stop {
                started: t,
                state,
                level_since: None,
                done: true,
                times,
                transitions,
                commands: 0,
                last_command: None,
            });
            return;
        }
        info!("stopping: brake, level, then the stream stops");
        if self.settings.failsafe.stop_requests_hold
            && let Some(request) = self.hold_request()
        {
            self.text(
                MavSeverity::MAV_SEVERITY_NOTICE,
                "dflat: stopping, asking the autopilot to hold",
            );
            self.pending_texts.push(request);
        }
        if let Some(tr) = self.supervisor.begin_stop(t) {
            self.announce(tr);
            self.refresh_reference();
        }
        self.engagement.stop = Some(Stop {
            started: t,
            state,
            level_since: None,
            done: false,
            times,
            transitions,
            commands: 0,
            last_command: None,
        });
    }

    /// During the stop, `level` reached from the last command sent at most
    /// [`STOP_LEVEL_RAMP`] per tick in roll and in pitch (no step); else
    /// `level` unchanged.
    pub(super) fn stop_ramp(&self, level: AttitudeCommand) -> AttitudeCommand {
        if self.engagement.stop.is_none() {
            return level;
        }
        let Some(last) = self.last_sent else {
            return level;
        };
        let toward =
            |from: f64, to: f64| from + (to - from).clamp(-STOP_LEVEL_RAMP, STOP_LEVEL_RAMP);
        AttitudeCommand {
            roll: toward(last.roll, level.roll),
            pitch: toward(last.pitch, level.pitch),
            ..level
        }
    }

    /// The flight state when the stop was asked for (`None` before):
    /// the summary's final state (the stop's own brake and level follow it).
    pub fn state_at_stop(&self) -> Option<FlightState> {
        self.engagement.stop.map(|s| s.state)
    }

    /// Time in each state up to the stop (`now` without one) \[s\].
    pub fn time_in_states_before_stop(&self, now: f64) -> [f64; 5] {
        self.engagement
            .stop
            .map_or_else(|| self.supervisor.time_in_states(now), |s| s.times)
    }

    /// State changes up to the stop.
    pub fn transitions_before_stop(&self) -> u64 {
        self.engagement
            .stop
            .map_or_else(|| self.supervisor.transitions(), |s| s.transitions)
    }

    /// What the stop sequence did, if one streamed anything.
    pub fn stop_summary(&self) -> Option<crate::summary::StopSummary> {
        let s = self.engagement.stop?;
        Some(crate::summary::StopSummary {
            duration_s: s.last_command.map_or(0.0, |t| (t - s.started).max(0.0)),
            commands: s.commands,
        })
    }

    /// How long the stop sequence may take \[s\]: `safety.stop_brake_ms`
    /// plus `safety.stop_level_ms`.
    pub fn stop_bound(&self) -> f64 {
        let f = &self.settings.failsafe;
        f.stop_brake + f.stop_level
    }

    /// True once the stop sequence has run: the stream may stop. `false`
    /// before [`ControlCore::begin_stop`].
    pub fn stop_done(&self, t: f64) -> bool {
        let Some(stop) = self.engagement.stop else {
            return false;
        };
        if stop.done {
            return true;
        }
        let f = &self.settings.failsafe;
        match stop.level_since {
            Some(since) => t - since >= f.stop_level,
            // Braking ran out, and no level is asked for.
            None => f.stop_level <= 0.0 && t - stop.started >= f.stop_brake,
        }
    }

    /// The stop sequence at tick `t`: from braking to level when braked or
    /// out of time; done when the autopilot no longer applies our commands
    /// or the stream stopped anyway (a failsafe let go).
    pub(super) fn stop_tick(&mut self, t: f64, level: dflat_link::AttitudeCommand) {
        let Some(mut stop) = self.engagement.stop else {
            return;
        };
        if stop.done {
            return;
        }
        let state = self.supervisor.state();
        let streaming_level = matches!(
            self.failsafe.state,
            super::failsafe::Failsafe::FailsafeLevel { .. }
        );
        let stream_off = if state == FlightState::Failsafe {
            !streaming_level
        } else {
            !state.streams()
        };
        if stream_off {
            stop.done = true;
        } else if state == FlightState::Standby {
            // The autopilot left offboard (its own hold): nothing to brake.
            stop.done = true;
        } else if stop.level_since.is_none() {
            let f = &self.settings.failsafe;
            let braked = self.supervisor.speed().is_some_and(|v| v < BRAKED_SPEED);
            let out_of_time = t - stop.started >= f.stop_brake;
            if (braked || out_of_time) && f.stop_level > 0.0 {
                // The stop's level follows a brake flown on live poses: no
                // velocity to cancel, only a ramp to level (`idle_tick`).
                let tripped = super::failsafe::Event::Tripped {
                    t,
                    cause: Cause::ShutdownLevel,
                    engaged: state.engaged(),
                    level: super::failsafe::LevelPlan {
                        command: level,
                        brake: None,
                    },
                };
                self.failsafe_on(t, tripped, None, &mut None);
                stop.level_since = Some(t);
            }
        }
        self.engagement.stop = Some(stop);
    }

    /// MAV_CMD_DO_SET_MODE to the autopilot's own position hold (PX4
    /// AUTO.LOITER, ArduPilot LOITER); `None` for an autopilot of unknown
    /// family.
    fn hold_request(&self) -> Option<MavMessage> {
        use dflat_link::dialect::MavModeFlag;
        let custom = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits() as f32;
        let (param2, param3) = match self.engagement.mode.map(|m| m.family)? {
            AutopilotFamily::Px4 => (
                f32::from(dflat_link::modes::px4::AUTO),
                3.0, // AUTO_LOITER
            ),
            AutopilotFamily::ArduPilot => (dflat_link::modes::ardupilot::LOITER as f32, 0.0),
            AutopilotFamily::Other => return None,
        };
        Some(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: self.settings.target.system,
            target_component: self.settings.target.component,
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            confirmation: 0,
            param1: custom,
            param2,
            param3,
            ..COMMAND_LONG_DATA::default()
        }))
    }
}
