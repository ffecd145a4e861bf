//! Goals the supervisor accepts: setpoints, streams, missions, the path's
//! end, pause and continue. Each may change the goal (a new generation)
//! and the state (Holding ↔ Tracking); standby keeps them for the next
//! engagement.

use super::{Cause, FlightState, Goal, Refusal, SetpointOutcome, Supervisor, Transition};

impl Supervisor {
    /// Why a setpoint or stream sample at `position` (local NED \[m\]) is
    /// refused, if it is: not finite, outside the fence, or the daemon not
    /// in control.
    fn refusal(&self, position: [f64; 3]) -> Option<Refusal> {
        if !position.iter().all(|v| v.is_finite()) {
            return Some(Refusal::NonFinite);
        }
        if !self.cfg.envelope.contains(position) {
            return Some(Refusal::Geofence { position });
        }
        if self.stopping {
            return Some(Refusal::Stopping);
        }
        if !self.state.streams() {
            return Some(Refusal::NotInControl(self.state));
        }
        None
    }

    /// A position setpoint (local NED \[m\]) arrived at `t` \[s\].
    pub fn on_setpoint(&mut self, t: f64, position: [f64; 3]) -> SetpointOutcome {
        if let Some(refusal) = self.refusal(position) {
            return SetpointOutcome::Refused(refusal);
        }
        if self.last_setpoint == Some(position) {
            return SetpointOutcome::Unchanged;
        }
        self.last_setpoint = Some(position);
        let triggers_path = self.cfg.path_trigger_radius > 0.0
            && self.cfg.path_ends.is_some_and(|(first, _)| {
                distance(&first, &position) <= self.cfg.path_trigger_radius
            });
        if triggers_path {
            self.path_started = true;
        }
        let (goal, cause) = if triggers_path {
            (Goal::Path, Cause::PathTrigger)
        } else {
            (Goal::Setpoint(position), Cause::Setpoint)
        };
        if self.state == FlightState::Standby {
            // Flown after the next engagement (once braked).
            self.pending = goal;
            return SetpointOutcome::Accepted {
                goal,
                transition: None,
            };
        }
        self.braking = None;
        self.pending = goal;
        self.set_goal(goal);
        let transition = if self.state == FlightState::Tracking {
            None
        } else {
            Some(self.enter(FlightState::Tracking, cause, t))
        };
        SetpointOutcome::Accepted { goal, transition }
    }

    /// A sample of a streamed trajectory at `position` (local NED \[m\])
    /// arrived at `t` \[s\]; the shell checked its jump
    /// ([`Refusal::StreamJump`]). Refused like a setpoint (non-finite,
    /// outside the fence, not in control). Standby: the stream is flown
    /// after the next engagement, once braked. Engaged: the goal becomes
    /// [`Goal::Stream`] (a new generation only when it was not already).
    pub fn on_stream(&mut self, t: f64, position: [f64; 3]) -> SetpointOutcome {
        if let Some(refusal) = self.refusal(position) {
            return SetpointOutcome::Refused(refusal);
        }
        // A position setpoint after the stream is a new request.
        self.last_setpoint = None;
        let goal = Goal::Stream;
        if self.state == FlightState::Standby {
            self.pending = goal;
            return SetpointOutcome::Accepted {
                goal,
                transition: None,
            };
        }
        if self.goal == goal && self.braking.is_none() {
            return SetpointOutcome::Unchanged;
        }
        self.braking = None;
        self.pending = goal;
        self.set_goal(goal);
        let transition = (self.state != FlightState::Tracking)
            .then(|| self.enter(FlightState::Tracking, Cause::Stream, t));
        SetpointOutcome::Accepted { goal, transition }
    }

    /// The stream went silent at `t`: hold `rest` (local NED \[m\], where
    /// the stream's extrapolation stops). `None` unless a stream is flown.
    pub fn on_stream_timeout(&mut self, t: f64, rest: [f64; 3]) -> Option<Transition> {
        if self.goal != Goal::Stream || !self.state.engaged() {
            return None;
        }
        self.set_goal(Goal::Hold(rest));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::StreamTimeout, t))
    }

    /// The path reached its end at `t`: hold the last waypoint.
    pub fn on_path_finished(&mut self, t: f64) -> Option<Transition> {
        if self.state != FlightState::Tracking || self.goal != Goal::Path {
            return None;
        }
        let (_, end) = self.cfg.path_ends?;
        if self.cfg.repeat_path {
            // The same goal again: a new generation rebuilds the reference.
            self.generation += 1;
            return None;
        }
        self.set_goal(Goal::Hold(end));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::PathFinished, t))
    }

    /// MAV_CMD_MISSION_START at `t`: fly the mission (from its start). In
    /// standby it is flown after the next engagement, once braked. Refused
    /// when not streaming.
    pub fn on_mission_start(&mut self, t: f64) -> Result<Option<Transition>, Refusal> {
        if self.stopping {
            return Err(Refusal::Stopping);
        }
        if !self.state.streams() {
            return Err(Refusal::NotInControl(self.state));
        }
        self.paused = false;
        self.last_setpoint = None;
        self.pending = Goal::Mission;
        if self.state == FlightState::Standby {
            return Ok(None);
        }
        self.braking = None;
        // A restart of the mission being flown is a new goal too.
        self.goal = Goal::None;
        self.set_goal(Goal::Mission);
        Ok(Some(self.enter(
            FlightState::Tracking,
            Cause::MissionStarted,
            t,
        )))
    }

    /// The mission's last item was reached (and held) at `t`: hold `end`.
    pub fn on_mission_finished(&mut self, t: f64, end: [f64; 3]) -> Option<Transition> {
        if self.goal != Goal::Mission || self.state != FlightState::Tracking {
            return None;
        }
        self.set_goal(Goal::Hold(end));
        self.pending = Goal::None;
        Some(self.enter(FlightState::Holding, Cause::MissionFinished, t))
    }

    /// MAV_CMD_DO_PAUSE_CONTINUE 0 at `t`: while tracking a path, a
    /// setpoint or a mission, stop from the vehicle's motion (the braking
    /// reference) and hold; the goal is kept for [`Supervisor::resume`].
    /// `None` when there is nothing to pause (holding already).
    pub fn pause(&mut self, t: f64) -> Option<Transition> {
        if self.state != FlightState::Tracking {
            return None;
        }
        let goal = self.goal;
        let stop = self.stop_goal()?;
        self.set_goal(stop);
        self.pending = goal;
        self.paused = true;
        Some(self.enter(FlightState::Holding, Cause::Paused, t))
    }

    /// MAV_CMD_DO_PAUSE_CONTINUE 1 at `t`: the paused goal goes on (a path
    /// from its closest point). `None` when not paused.
    pub fn resume(&mut self, t: f64) -> Option<Transition> {
        if self.stopping || !(self.paused && self.state == FlightState::Holding) {
            return None;
        }
        self.paused = false;
        let goal = self.pending;
        if !matches!(goal, Goal::Path | Goal::Setpoint(_) | Goal::Mission) {
            return None;
        }
        self.set_goal(goal);
        self.path_resumed = goal == Goal::Path;
        Some(self.enter(FlightState::Tracking, Cause::Continued, t))
    }

    /// True while paused (MAV_CMD_DO_PAUSE_CONTINUE 0).
    pub fn paused(&self) -> bool {
        self.paused
    }
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
