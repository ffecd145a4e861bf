//! The tick's mission and yaw parts: an uploaded mission loaded, started,
//! paused and continued, its sections' references, MISSION_ITEM_REACHED
//! and MISSION_CURRENT; and the heading each command carries.

use dflat_control::ControlError;
use dflat_control::reference::Reference;
use dflat_link::dialect::{MavSeverity, MissionState};
use dflat_link::mission::{mission_current, mission_item_reached};
use tracing::{info, warn};

use super::ControlCore;
use crate::config::YawMode;
use crate::mission::{Mission, MissionRunner, MissionStatus};
use crate::supervisor::{FlightState, Goal};
use crate::yaw::tilt_at_heading;

/// A mission command for the control thread (the receive task answered it
/// with COMMAND_ACK ACCEPTED).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MissionAction {
    /// MAV_CMD_MISSION_START: fly the loaded mission from this item.
    Start {
        /// The first item (param1).
        first: u16,
    },
    /// MAV_CMD_DO_PAUSE_CONTINUE 0: stop and hold.
    Pause,
    /// MAV_CMD_DO_PAUSE_CONTINUE 1: go on.
    Continue,
    /// MAV_CMD_DO_CHANGE_SPEED: the mission's speed \[m/s\] from now on.
    Speed(f64),
}

/// MISSION_CURRENT is sent at least this often \[s\] while a mission is
/// loaded (and at once on a change), as PX4 does.
const MISSION_CURRENT_INTERVAL: f64 = 1.0;

impl ControlCore {
    /// Loads the mission the protocol accepted (`None`: cleared). The
    /// mission being flown is not touched by an upload: a new one is
    /// flown from the next MAV_CMD_MISSION_START. A clear while the
    /// mission is flown stops it (the vehicle brakes and holds).
    pub fn load_mission(&mut self, t: f64, mission: Option<Mission>) {
        info!(
            items = mission.as_ref().map_or(0, Mission::len),
            "mission loaded"
        );
        if mission.is_none()
            && self.supervisor.goal() == Goal::Mission
            && let Some(tr) = self.supervisor.pause(t)
        {
            self.goals.runner = None;
            self.announce(tr);
            self.refresh_reference();
        }
        self.goals.mission = mission;
        self.goals.mission_current_sent = None;
    }

    /// A mission command at `t` \[s\].
    pub(super) fn apply_mission(&mut self, t: f64, action: MissionAction) {
        match action {
            MissionAction::Start { first } => {
                let runner = self
                    .goals
                    .mission
                    .as_ref()
                    .and_then(|m| MissionRunner::new(m, self.settings.goals.speed))
                    .map(|r| r.with_speed_limit(self.settings.goals.max_speed));
                let Some(mut runner) = runner else {
                    self.text(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        "dflat: no mission to start",
                    );
                    return;
                };
                runner.start(first);
                self.goals.runner = Some(runner);
                match self.supervisor.on_mission_start(t) {
                    Ok(tr) => {
                        info!(first, "mission start");
                        if let Some(tr) = tr {
                            self.announce(tr);
                        }
                        self.refresh_reference();
                    }
                    Err(refusal) => {
                        self.goals.runner = None;
                        self.text(MavSeverity::MAV_SEVERITY_WARNING, &refusal.text());
                    }
                }
            }
            MissionAction::Pause => {
                if let Some(tr) = self.supervisor.pause(t) {
                    if let Some(r) = self.goals.runner.as_mut() {
                        r.pause();
                    }
                    self.announce(tr);
                    self.refresh_reference();
                }
            }
            MissionAction::Continue => {
                if self.supervisor.pending_goal() == Goal::Mission
                    && let Some(r) = self.goals.runner.as_mut()
                {
                    r.resume();
                }
                if let Some(tr) = self.supervisor.resume(t) {
                    self.announce(tr);
                    self.refresh_reference();
                }
            }
            MissionAction::Speed(speed) => {
                info!(speed, "mission speed");
                let limit = self.settings.goals.max_speed;
                if speed > limit {
                    warn!(
                        speed,
                        limit, "DO_CHANGE_SPEED above safety.max_speed_mps: flown at the limit"
                    );
                    self.text(
                        MavSeverity::MAV_SEVERITY_WARNING,
                        &format!("dflat: speed {speed:.1} > limit, flying {limit:.1}"),
                    );
                }
                if let Some(r) = self.goals.runner.as_mut() {
                    r.set_speed(speed);
                }
                if self.supervisor.goal() == Goal::Mission
                    && self.supervisor.state() == FlightState::Tracking
                {
                    // From where the vehicle is, at its speed: no jump.
                    if let Some(Ok(r)) = self.mission_reference() {
                        self.goals.reference = Some(r);
                    }
                }
            }
        }
    }

    /// The reference of the mission's current section from the vehicle's
    /// position and speed (`None` without a mission being flown or a pose).
    pub(super) fn mission_reference(&mut self) -> Option<Result<Reference, ControlError>> {
        let position = self.poses.newest.map(|p| p.position)?;
        let v0 = self.poses.motion.estimate().map_or(0.0, |m| m.speed());
        let accel = self.settings.goals.start_acceleration;
        let runner = self.goals.runner.as_mut()?;
        Some(runner.section(position, v0, accel))
    }

    /// After the tick's control: waypoints reached, the next section, the
    /// end of the mission, and MISSION_CURRENT when due.
    pub(super) fn mission_tick(&mut self, t: f64) {
        if self.supervisor.goal() == Goal::Mission
            && self.supervisor.state() == FlightState::Tracking
            && let (Some(pose), Some(reference), Some(runner)) = (
                self.poses.newest,
                self.goals.reference.as_ref(),
                self.goals.runner.as_mut(),
            )
        {
            let up = runner.update(
                t,
                pose.position,
                reference.progress(),
                reference.is_finished(),
            );
            for seq in &up.reached {
                info!(seq, "mission item reached");
                self.pending_texts.push(mission_item_reached(*seq));
            }
            if up.new_section {
                match self.mission_reference() {
                    Some(Ok(r)) => self.goals.reference = Some(r),
                    Some(Err(e)) => warn!(error = %e, "mission section: keeping the reference"),
                    None => {}
                }
            }
            if up.finished {
                let end = self.goals.runner.as_ref().map(MissionRunner::end);
                if let Some(end) = end
                    && let Some(tr) = self.supervisor.on_mission_finished(t, end)
                {
                    self.announce(tr);
                    self.refresh_reference();
                }
            }
        }
        let Some(mission) = &self.goals.mission else {
            return;
        };
        let now = match &self.goals.runner {
            Some(r) => {
                let (seq, total) = r.current_item();
                let state = match r.status() {
                    MissionStatus::NotStarted => MissionState::MISSION_STATE_NOT_STARTED,
                    MissionStatus::Active => MissionState::MISSION_STATE_ACTIVE,
                    MissionStatus::Paused => MissionState::MISSION_STATE_PAUSED,
                    MissionStatus::Complete => MissionState::MISSION_STATE_COMPLETE,
                };
                (seq, total, state)
            }
            None => (
                0,
                mission.len() as u16,
                MissionState::MISSION_STATE_NOT_STARTED,
            ),
        };
        let due = self
            .goals
            .mission_current_sent
            .is_none_or(|(at, last)| last != now || t - at >= MISSION_CURRENT_INTERVAL);
        if due {
            self.goals.mission_current_sent = Some((t, now));
            self.pending_texts
                .push(mission_current(now.0, now.1, now.2));
        }
    }

    /// The heading the tick commands \[rad\]: `vehicle.yaw_deg` with
    /// `yaw_mode = "fixed"`; else, streaming engaged, one rate-limited step
    /// towards the goal's yaw (a setpoint's, the mission's, a stream's
    /// trajectory's `vehicle.yaw_lead_s` plus the input delay ahead; none:
    /// the heading is kept);
    /// in standby the vehicle's own heading.
    pub(super) fn heading(&mut self, t: f64) -> f64 {
        let fixed = self.settings.vehicle.yaw;
        if self.settings.vehicle.yaw_mode == YawMode::Fixed {
            return fixed;
        }
        let measured = self.measured_yaw();
        if !self.supervisor.state().engaged() {
            if let Some(m) = measured {
                self.goals.yaw_command.follow(t, m);
            }
            return self.goals.yaw_command.current().unwrap_or(fixed);
        }
        let target = match self.supervisor.goal() {
            Goal::Mission => self.goals.runner.as_ref().and_then(MissionRunner::yaw),
            // A stream's heading from its trajectory, its rate fed
            // forward by commanding it `yaw_lead_s` ahead, and the input
            // delay further (as the plan starts `delay_ms` ahead).
            Goal::Stream => self
                .goals
                .reference
                .as_ref()
                .and_then(|r| r.yaw_reference(self.settings.vehicle.yaw_lead))
                .map(|(yaw, _)| yaw)
                .or(self.goals.setpoint_yaw),
            Goal::Setpoint(_) => self.goals.setpoint_yaw,
            _ => None,
        };
        self.goals
            .yaw_command
            .step(t, target, measured.unwrap_or(fixed))
    }

    /// The vehicle's heading as measured (the pose message's, else
    /// ATTITUDE's) \[rad\], if known.
    fn measured_yaw(&self) -> Option<f64> {
        self.poses
            .newest
            .and_then(|p| p.yaw)
            .or(self.poses.attitude_yaw)
    }

    /// The controller's tilt (pitch, roll at the model's heading ψ⋆, a
    /// world-frame tilt) at the commanded heading; unchanged with
    /// `yaw_mode = "fixed"`.
    pub(super) fn tilt_to_command(&self, pitch: f64, roll: f64) -> (f64, f64, f64) {
        let fixed = self.settings.vehicle.yaw;
        if self.settings.vehicle.yaw_mode == YawMode::Fixed {
            return (pitch, roll, fixed);
        }
        let (p, r) = tilt_at_heading(pitch, roll, fixed, self.goals.commanded_yaw);
        (p, r, self.goals.commanded_yaw)
    }

    /// A measured attitude (pitch, roll at heading `yaw`) as the world-frame
    /// tilt the window records (at ψ⋆); unchanged with `yaw_mode = "fixed"`.
    pub(super) fn tilt_from_measured(&self, pitch: f64, roll: f64, yaw: f64) -> [f64; 2] {
        if self.settings.vehicle.yaw_mode == YawMode::Fixed {
            return [pitch, roll];
        }
        let fixed = self.settings.vehicle.yaw;
        let (p, r) = tilt_at_heading(pitch, roll, yaw, fixed);
        [p, r]
    }
}
