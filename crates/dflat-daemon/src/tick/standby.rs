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
use super::envelope::Stop;
use crate::autopilot_params::AutopilotParams;
use crate::config::AutopilotKind;
use crate::stream_rates::{StreamRates, StreamRequest};

/// Engagement: the core's part that owns what the autopilot said of its
/// mode and parameters, and the stop sequence.
#[derive(Debug)]
pub(super) struct Engagement {
    /// The autopilot's mode as last reported.
    pub(super) mode: Option<AutopilotMode>,
    /// The autopilot's own hover thrust and tilt limit, read at start-up.
    pub(super) params: AutopilotParams,
    /// The telemetry rates asked of the autopilot (`link.request_streams`).
    pub(super) streams: StreamRates,
    /// Engagement is refused (the autopilot's tilt limit is below ours);
    /// said once.
    pub(super) tilt_refusal_said: bool,
    /// The attitude at the previous tick, when that tick's command was
    /// sent in standby (corrected from the attitude at this tick).
    pub(super) standby_attitude: Option<[f64; 2]>,
    /// The stop sequence, once asked for (`tick/envelope.rs`).
    pub(super) stop: Option<Stop>,
    /// The next step's CSV row carries [`super::STOP_GUARD`] (the stop began).
    pub(super) stop_marked: bool,
}

impl Engagement {
    /// Nothing heard from the autopilot yet; `streams` the messages to ask
    /// it for.
    pub(super) fn new(streams: Vec<StreamRequest>) -> Self {
        Self {
            mode: None,
            params: AutopilotParams::new(),
            streams: StreamRates::new(streams),
            tilt_refusal_said: false,
            standby_attitude: None,
            stop: None,
            stop_marked: false,
        }
    }
}

impl ControlCore {
    /// The input that explains the attitude change since the previous
    /// (standby) tick replaces the one recorded then
    /// ([`dflat_control::Controller::correct_last_input`]). Thrust: the hover thrust
    /// (the autopilot's position mode holds altitude), with the disturbance
    /// estimate's thrust scale when there is one.
    pub(super) fn correct_standby_input(&mut self) {
        let (Some(before), Some(now), Some(model)) = (
            self.engagement.standby_attitude.take(),
            self.poses.attitude,
            self.model,
        ) else {
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
        mode.family = match self.settings.vehicle.autopilot {
            AutopilotKind::Auto => mode.family,
            AutopilotKind::Px4 => AutopilotFamily::Px4,
            AutopilotKind::Ardupilot => AutopilotFamily::ArduPilot,
        };
        if mode.family != AutopilotFamily::Other {
            self.engagement.params.start(mode.family, arrival);
        }
        let refused = self.tilt_refused();
        if refused && mode.applies_commands() && !self.engagement.tilt_refusal_said {
            self.engagement.tilt_refusal_said = true;
            let limit = self.engagement.params.tilt_limit().map_or(0.0, |p| p.value);
            let name = self
                .engagement
                .params
                .tilt_limit()
                .map_or("", |p| p.spec.name);
            let max_tilt_deg = self.settings.vehicle.max_tilt.to_degrees();
            error!(
                max_tilt_deg,
                autopilot_limit_deg = limit,
                "not engaging: vehicle.max_tilt_deg exceeds the autopilot's {name}"
            );
            let text = format!("dflat: not engaging, tilt {max_tilt_deg:.0} > {name} {limit:.0}");
            self.text(MavSeverity::MAV_SEVERITY_CRITICAL, &text);
        }
        self.supervisor.on_mode(mode.applies_commands() && !refused);
        if self.engagement.mode != Some(mode) {
            info!(mode = %mode, applies = mode.applies_commands(), "autopilot mode");
            let text = format!("dflat: autopilot {mode}");
            self.text(MavSeverity::MAV_SEVERITY_INFO, &text);
            self.engagement.mode = Some(mode);
        }
    }

    /// The autopilot's tilt limit is known and below `vehicle.max_tilt_deg`:
    /// it would cut commands the window records as sent.
    fn tilt_refused(&self) -> bool {
        self.engagement
            .params
            .tilt_limit()
            .is_some_and(|p| self.settings.vehicle.max_tilt > (p.value + 1e-6).to_radians())
    }
}
