//! The parts of the tick that decide whether commands are applied and
//! whether the daemon can fly at all: standby's input correction, the
//! autopilot's mode, letting go when the controller cannot fly (and the
//! trial solves that end it), and the pose clock's sanity check.

use dflat_link::dialect::MavSeverity;
use dflat_link::{AutopilotFamily, AutopilotMode, ThrustMapping};
use nalgebra::Vector3;
use tracing::{error, info, warn};

use super::exit::update_caught;
use super::{ControlCore, POSE_LATENCY_PERSISTENCE, TRIAL_TICKS};
use crate::autopilot_params::ParamKind;
use crate::config::{AutopilotKind, ThrustMode};
use crate::supervisor::Cause;

impl ControlCore {
    /// The controller cannot fly: failsafe until it solves again
    /// ([`ControlCore::trial`]); the cause is said (STATUSTEXT) and counted.
    pub(super) fn let_go(&mut self, t: f64) {
        self.level_hover_since = None;
        if let Some(tr) = self
            .supervisor
            .force_failsafe(t, Cause::ControlFailed, f64::INFINITY)
        {
            self.counts.guards.control_failsafes += 1;
            self.control_failsafe = true;
            self.trial_streak = 0;
            self.fallback_kind = None;
            error!(
                level_hover_ms = self.config.safety.level_hover_max_ms,
                "controller cannot fly: stream stopped, the autopilot's failsafe takes over"
            );
            self.reset_controller();
            self.last_used_arrival = None;
            self.announce(tr);
        }
    }

    /// In a control failsafe: one solve on the newest pose, not sent
    /// (the controller is reset afterwards, so nothing unsent stays in its
    /// window). After [`TRIAL_TICKS`] good ones in a row the latch is
    /// lifted and the stream resumes at the next tick.
    pub(super) fn trial(&mut self, t: f64) {
        let (Some(pose), Some(reference)) = (self.pose, self.reference.as_ref()) else {
            return;
        };
        // On a copy: a trial must not move a path's progress.
        let mut reference = reference.clone();
        let measurement = self.tick_measurement(t, &pose);
        let ok = update_caught(self.controller.as_mut(), &measurement, &mut reference).is_ok();
        self.reset_controller();
        self.trial_streak = if ok { self.trial_streak + 1 } else { 0 };
        if self.trial_streak >= TRIAL_TICKS {
            self.control_failsafe = false;
            self.trial_streak = 0;
            self.supervisor.release_latch();
            info!("controller solves again: the stream may resume");
            self.text(
                MavSeverity::MAV_SEVERITY_NOTICE,
                "dflat: controller flies again",
            );
        }
    }

    /// The input that explains the attitude change since the previous
    /// (standby) tick replaces the one recorded then
    /// ([`Controller::correct_last_input`]). Thrust: the hover thrust
    /// (the autopilot's position mode holds altitude), with the disturbance
    /// estimate's thrust scale when there is one.
    pub(super) fn correct_standby_input(&mut self) {
        let (Some(before), Some(now), Some(model)) =
            (self.standby_attitude.take(), self.attitude, self.model)
        else {
            return;
        };
        let [pitch, roll] = model.input_from_attitude(before, now);
        let thrust = self
            .controller
            .disturbance()
            .map_or(model.gravity(), |d| d.hover_thrust);
        self.controller
            .correct_last_input(&Vector3::new(pitch, roll, thrust));
    }

    /// The autopilot's HEARTBEAT mode (family per `link.autopilot`): the
    /// supervisor learns whether our commands are applied; a change is
    /// logged and said once.
    pub(super) fn apply_mode(&mut self, mut mode: AutopilotMode, arrival: f64) {
        mode.family = match self.config.link.autopilot {
            AutopilotKind::Auto => mode.family,
            AutopilotKind::Px4 => AutopilotFamily::Px4,
            AutopilotKind::Ardupilot => AutopilotFamily::ArduPilot,
        };
        if mode.family != AutopilotFamily::Other {
            self.params.start(mode.family, arrival);
        }
        let refused = self.tilt_refused();
        if refused && mode.applies_commands() && !self.tilt_refusal_said {
            self.tilt_refusal_said = true;
            let limit = self.params.tilt_limit().map_or(0.0, |p| p.value);
            let name = self.params.tilt_limit().map_or("", |p| p.spec.name);
            error!(
                max_tilt_deg = self.config.vehicle.max_tilt_deg,
                autopilot_limit_deg = limit,
                "not engaging: vehicle.max_tilt_deg exceeds the autopilot's {name}"
            );
            let text = format!(
                "dflat: not engaging, tilt {:.0} > {name} {limit:.0}",
                self.config.vehicle.max_tilt_deg
            );
            self.text(MavSeverity::MAV_SEVERITY_CRITICAL, &text);
        }
        self.supervisor.on_mode(mode.applies_commands() && !refused);
        if self.mode != Some(mode) {
            info!(mode = %mode, applies = mode.applies_commands(), "autopilot mode");
            let text = format!("dflat: autopilot {mode}");
            self.text(MavSeverity::MAV_SEVERITY_INFO, &text);
            self.mode = Some(mode);
        }
    }

    /// The autopilot's tilt limit is known and below `vehicle.max_tilt_deg`:
    /// it would cut commands the window records as sent.
    fn tilt_refused(&self) -> bool {
        self.params
            .tilt_limit()
            .is_some_and(|p| self.config.vehicle.max_tilt_deg > p.value + 1e-6)
    }

    /// A PARAM_VALUE from the autopilot: a value dflat reads is logged next
    /// to the configuration's, and said when they differ.
    pub(super) fn apply_param(&mut self, name: &str, value: f64) {
        let Some(known) = self.params.on_value(name, value) else {
            return;
        };
        let v = &self.config.vehicle;
        match known.spec.kind {
            ParamKind::HoverThrust if v.hover_thrust_from_autopilot => {
                self.fly_autopilot_hover(name, known.value);
            }
            ParamKind::HoverThrust => {
                info!(
                    param = name,
                    autopilot = known.value,
                    config = v.hover_thrust,
                    "hover thrust: the configuration's vehicle.hover_thrust is flown; \
                     the disturbance estimator takes up a difference"
                );
                if v.thrust_mode == ThrustMode::Normalized
                    && (known.value - v.hover_thrust).abs() > 0.05
                {
                    let text = format!(
                        "dflat: {name} {:.2}, config hover {:.2}",
                        known.value, v.hover_thrust
                    );
                    self.text(MavSeverity::MAV_SEVERITY_WARNING, &text);
                }
            }
            ParamKind::TiltLimitDeg => {
                info!(
                    param = name,
                    autopilot_deg = known.value,
                    config_deg = v.max_tilt_deg,
                    "tilt limit"
                );
            }
        }
    }

    /// `vehicle.hover_thrust_from_autopilot`: the autopilot's hover thrust
    /// `value` (parameter `name`) becomes the one flown — the thrust
    /// mapping and the level hover's thrust — if it is in 0.05–0.95 and
    /// the daemon has not engaged yet (a change in flight would step the
    /// thrust). Said either way.
    fn fly_autopilot_hover(&mut self, name: &str, value: f64) {
        let v = &self.config.vehicle;
        if v.thrust_mode != ThrustMode::Normalized {
            return;
        }
        let (engagements, _) = self.supervisor.engagement_counts();
        let (lo, hi) = crate::config::HOVER_THRUST_RANGE;
        let text = if !(lo..=hi).contains(&value) {
            warn!(
                param = name,
                value, "autopilot hover thrust outside 0.05–0.95: vehicle.hover_thrust flown"
            );
            format!(
                "dflat: {name} {value:.2} refused, hover {:.2} flown",
                v.hover_thrust
            )
        } else if engagements > 0 {
            warn!(
                param = name,
                value, "autopilot hover thrust arrived after engagement: not flown"
            );
            format!(
                "dflat: {name} {value:.2} late, hover {:.2} flown",
                v.hover_thrust
            )
        } else {
            self.mapping = ThrustMapping::Normalized {
                hover_thrust: value,
                gravity: v.gravity,
            };
            self.fallback.hover_thrust = value;
            info!(
                param = name,
                value,
                config = v.hover_thrust,
                "flying the autopilot's hover thrust"
            );
            format!("dflat: flying {name} {value:.2} as hover thrust")
        };
        self.text(MavSeverity::MAV_SEVERITY_INFO, &text);
    }

    /// A pose captured (by the mapped source clock) more than
    /// `safety.pose_max_latency_ms` before its arrival, for
    /// [`POSE_LATENCY_PERSISTENCE`] on end: the source clock runs slow or
    /// ever later than ours. From then on poses are stamped with their
    /// arrival time (said, logged, counted).
    pub(super) fn check_pose_clock(&mut self, arrival: f64, capture: f64) {
        let late = arrival - capture > self.config.safety.pose_max_latency_ms / 1000.0;
        if !late {
            self.pose_late_since = None;
            return;
        }
        let since = *self.pose_late_since.get_or_insert(arrival);
        if arrival - since >= POSE_LATENCY_PERSISTENCE {
            self.pose_time_arrival = true;
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
        }
    }
}
