//! The SITL's flight modes and its pilot: what decides whether the
//! autopilot stand-in applies the companion's SET_ATTITUDE_TARGET.
//!
//! Two modes, as a PX4 or ArduPilot vehicle flown with a companion has
//! them:
//!
//! * **position** ([`SitlMode::Hold`]; PX4 POSCTL, ArduPilot LOITER): the
//!   autopilot's own position hold, following the pilot's stick (a
//!   velocity, [`PilotAction::velocity`]); incoming attitude targets are
//!   received but not applied. The SITL starts here.
//! * **offboard** ([`SitlMode::Offboard`]; PX4 OFFBOARD, ArduPilot
//!   GUIDED_NOGPS): the attitude targets are applied.
//!
//! * **hold / goto / return** ([`SitlMode::Loiter`], [`SitlMode::Rtl`];
//!   PX4 AUTO_LOITER / AUTO_RTL, from MAV_CMD_DO_SET_MODE, DO_REPOSITION and
//!   NAV_RETURN_TO_LAUNCH): the SITL's position loop flies to a goal and
//!   holds; like position mode, an override of auto engagement.
//!
//! Entering offboard needs a live stream (a command within
//! `sitl.command_timeout_s`): a request without one is refused (counted,
//! STATUSTEXT), as PX4 refuses OFFBOARD without a setpoint stream. A stream
//! that dies in offboard drops the vehicle back to position mode (PX4's
//! offboard-loss failsafe with `COM_OBL_RC_ACT` = position).
//!
//! Who switches: with `sitl.engage = "auto"` (the default, as the
//! companion scripts of PX4's offboard examples do) the SITL enters
//! offboard whenever the stream is alive, unless the pilot took over; with
//! `"pilot"` only the pilot does — scripted in `[[sitl.pilot]]` (times
//! since the SITL started) or through [`super::SitlHandle::request_mode`].
//! A pilot switch to position mode is an override: auto engagement stays
//! off until the pilot hands back (requests offboard).

use serde::{Deserialize, Serialize};

use super::SitlMode;

/// `sitl.engage`: who switches to offboard.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SitlEngage {
    /// Whenever the stream is alive and the pilot has not taken over.
    #[default]
    Auto,
    /// Only the pilot ([`PilotAction`], [`super::SitlHandle::request_mode`]).
    Pilot,
}

/// The mode a pilot action switches to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PilotMode {
    /// Position mode (PX4 POSCTL, ArduPilot LOITER): an override.
    Position,
    /// Offboard (PX4 OFFBOARD, ArduPilot GUIDED_NOGPS): engage / hand back.
    Offboard,
}

impl PilotMode {
    /// The SITL mode it requests.
    pub fn sitl_mode(self) -> SitlMode {
        match self {
            PilotMode::Position => SitlMode::Hold,
            PilotMode::Offboard => SitlMode::Offboard,
        }
    }
}

/// One scripted pilot action (`[[sitl.pilot]]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PilotAction {
    /// When \[s\] since the SITL started (0–3600).
    pub at_s: f64,
    /// Switch to this mode (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mode: Option<PilotMode>,
    /// Stick: fly at this velocity in position mode, local NED \[m/s\]
    /// (each component within ±20; `[0, 0, 0]` = sticks centred: brake and
    /// hold). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<[f64; 3]>,
}

/// What one step of the [`ModeMachine`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ModeStep {
    /// The mode changed at this step.
    pub changed: bool,
    /// A request for offboard was refused (no stream).
    pub refused: bool,
}

/// The mode logic (see the module docs). Pure: time and the stream's
/// liveness enter as arguments.
#[derive(Debug, Clone)]
pub struct ModeMachine {
    engage: SitlEngage,
    script: Vec<PilotAction>,
    next: usize,
    mode: SitlMode,
    overridden: bool,
    velocity: [f64; 3],
    /// Offboard survives the stream's loss (`sitl.stays_offboard`).
    stays_offboard: bool,
}

impl ModeMachine {
    /// Offboard stays when the stream is lost (ArduPilot's GUIDED after
    /// GUID_TIMEOUT) instead of falling back to position mode.
    pub fn with_stays_offboard(mut self, stays: bool) -> Self {
        self.stays_offboard = stays;
        self
    }

    /// In position mode, sticks centred; `script` sorted by time here.
    pub fn new(engage: SitlEngage, mut script: Vec<PilotAction>) -> Self {
        script.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        Self {
            engage,
            script,
            next: 0,
            mode: SitlMode::Hold,
            overridden: false,
            velocity: [0.0; 3],
            stays_offboard: false,
        }
    }

    /// The current mode.
    pub fn mode(&self) -> SitlMode {
        self.mode
    }

    /// The pilot's stick velocity, local NED \[m/s\] (position mode).
    pub fn velocity(&self) -> [f64; 3] {
        self.velocity
    }

    /// Sets the pilot's stick velocity (non-finite values are ignored).
    pub fn set_velocity(&mut self, v: [f64; 3]) {
        if v.iter().all(|x| x.is_finite()) {
            self.velocity = v;
        }
    }

    /// One step at SITL time `t` \[s\]: the scripted actions due, an
    /// explicit `request`, then the automatic rules.
    pub fn step(&mut self, t: f64, stream_alive: bool, request: Option<SitlMode>) -> ModeStep {
        let before = self.mode;
        let mut out = ModeStep::default();
        while let Some(a) = self.script.get(self.next).copied() {
            if a.at_s > t {
                break;
            }
            self.next += 1;
            if let Some(v) = a.velocity {
                self.set_velocity(v);
            }
            if let Some(m) = a.mode {
                out.refused |= self.request(m.sitl_mode(), stream_alive);
            }
        }
        if let Some(m) = request {
            out.refused |= self.request(m, stream_alive);
        }
        match self.mode {
            SitlMode::Offboard if !stream_alive && !self.stays_offboard => {
                self.mode = SitlMode::Hold
            }
            SitlMode::Hold
                if stream_alive && self.engage == SitlEngage::Auto && !self.overridden =>
            {
                self.mode = SitlMode::Offboard;
            }
            _ => {}
        }
        out.changed = self.mode != before;
        out
    }

    /// A mode request; returns true when refused.
    fn request(&mut self, mode: SitlMode, stream_alive: bool) -> bool {
        match mode {
            SitlMode::Hold | SitlMode::Loiter | SitlMode::Rtl => {
                self.mode = mode;
                self.overridden = true;
                false
            }
            SitlMode::Offboard if stream_alive => {
                self.mode = SitlMode::Offboard;
                self.overridden = false;
                false
            }
            SitlMode::Offboard => true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_engages_with_the_stream_and_falls_back_without_it() {
        let mut m = ModeMachine::new(SitlEngage::Auto, vec![]);
        assert_eq!(m.step(0.0, false, None), ModeStep::default());
        assert_eq!(m.mode(), SitlMode::Hold);
        assert!(m.step(0.1, true, None).changed);
        assert_eq!(m.mode(), SitlMode::Offboard);
        assert!(m.step(0.2, false, None).changed);
        assert_eq!(m.mode(), SitlMode::Hold);
        assert!(m.step(0.3, true, None).changed, "auto again");
    }

    #[test]
    fn the_pilot_overrides_and_hands_back() {
        let script = vec![
            PilotAction {
                at_s: 2.0,
                mode: Some(PilotMode::Offboard),
                velocity: None,
            },
            PilotAction {
                at_s: 1.0,
                mode: None,
                velocity: Some([2.0, 0.0, 0.0]),
            },
            PilotAction {
                at_s: 3.0,
                mode: Some(PilotMode::Position),
                velocity: Some([0.0; 3]),
            },
        ];
        let mut m = ModeMachine::new(SitlEngage::Pilot, script);
        // Pilot engagement: the stream alone does not switch.
        m.step(0.5, true, None);
        assert_eq!(m.mode(), SitlMode::Hold);
        m.step(1.0, true, None);
        assert_eq!(m.velocity(), [2.0, 0.0, 0.0]);
        assert!(m.step(2.0, true, None).changed);
        assert_eq!(m.mode(), SitlMode::Offboard);
        assert!(m.step(3.0, true, None).changed);
        assert_eq!((m.mode(), m.velocity()), (SitlMode::Hold, [0.0; 3]));
        // Hand-back through the hook.
        assert!(m.step(4.0, true, Some(SitlMode::Offboard)).changed);
        assert_eq!(m.mode(), SitlMode::Offboard);
    }

    #[test]
    fn offboard_without_a_stream_is_refused_and_an_override_stops_auto() {
        let mut m = ModeMachine::new(SitlEngage::Auto, vec![]);
        let s = m.step(0.0, false, Some(SitlMode::Offboard));
        assert!(s.refused && !s.changed);
        assert_eq!(m.mode(), SitlMode::Hold);
        m.step(0.1, true, None);
        assert_eq!(m.mode(), SitlMode::Offboard);
        m.step(0.2, true, Some(SitlMode::Hold));
        assert_eq!(m.mode(), SitlMode::Hold);
        // The stream is alive, but the pilot took over: no auto engagement.
        assert!(!m.step(0.3, true, None).changed);
        assert_eq!(m.mode(), SitlMode::Hold);
        m.set_velocity([f64::NAN; 3]);
        assert_eq!(m.velocity(), [0.0; 3]);
    }
}
