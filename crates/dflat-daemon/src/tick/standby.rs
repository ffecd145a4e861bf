//! Standby and engagement: whether the autopilot applies our commands.
//!
//! The autopilot's HEARTBEAT mode tells the supervisor whether the stream
//! is flown (engaged) or only carried (standby); engagement is refused
//! while the autopilot's tilt limit is below ours. In standby the command
//! sent is not applied, so the input recorded for it is replaced by the
//! one the measured attitude shows.

use dflat_link::dialect::MavSeverity;
use dflat_link::{AutopilotFamily, AutopilotMode};
use nalgebra::Vector3;
use tracing::{error, info};

use super::ControlCore;
use crate::config::AutopilotKind;

impl ControlCore {
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
}
