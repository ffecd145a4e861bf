//! What the autopilot already knows about the vehicle, read over the
//! MAVLink parameter protocol at start-up (PARAM_REQUEST_READ →
//! PARAM_VALUE): its hover thrust and its tilt limit.
//!
//! | family | hover thrust | tilt limit |
//! |---|---|---|
//! | PX4 | `MPC_THR_HOVER` (normalised 0–1) | `MPC_TILTMAX_AIR` (deg) |
//! | ArduPilot | `MOT_THST_HOVER` (normalised 0–1) | `ANGLE_MAX` (centidegrees) |
//!
//! The daemon asks as soon as the autopilot's HEARTBEAT names its family,
//! retries every [`RETRY_S`] up to [`TRIES`] times, and then goes on
//! without (an autopilot that does not answer is not an error: the
//! configuration's values stand, and the log says so). A tilt limit
//! smaller than `vehicle.max_tilt_deg` refuses engagement ([`crate::tick`]):
//! the autopilot would cut what the window records as sent. Pure: time
//! enters as arguments.

use dflat_link::AutopilotFamily;
use dflat_link::params::AutopilotParam;

/// Seconds between two requests for a parameter not answered yet.
pub const RETRY_S: f64 = 1.0;
/// Requests per parameter before giving up.
pub const TRIES: u32 = 3;

/// What a parameter tells dflat.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParamKind {
    /// Normalised hover thrust (0–1).
    HoverThrust,
    /// Largest tilt the autopilot allows \[deg\].
    TiltLimitDeg,
}

/// One parameter dflat reads: its name in the autopilot's firmware and its
/// meaning (names, wire units and conversions from [`dflat_link::params`],
/// the table the SITL serves too).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// The autopilot's name.
    pub name: &'static str,
    /// What it means.
    pub kind: ParamKind,
    /// The shared parameter.
    pub param: AutopilotParam,
    /// The firmware it is read from.
    pub family: AutopilotFamily,
}

impl ParamSpec {
    /// A wire value in dflat's unit (tilt in degrees, thrust 0–1).
    pub fn convert(&self, value: f64) -> f64 {
        let si = self.param.to_si(self.family, value);
        match self.kind {
            ParamKind::HoverThrust => si,
            ParamKind::TiltLimitDeg => si.to_degrees(),
        }
    }
}

/// The parameters dflat reads from an autopilot of `family` (none for
/// families whose parameters it does not know).
pub fn params_for(family: AutopilotFamily) -> Vec<ParamSpec> {
    [
        (AutopilotParam::HoverThrust, ParamKind::HoverThrust),
        (AutopilotParam::TiltMax, ParamKind::TiltLimitDeg),
    ]
    .into_iter()
    .filter_map(|(param, kind)| {
        Some(ParamSpec {
            name: param.name(family)?,
            kind,
            param,
            family,
        })
    })
    .collect()
}

/// A value received for one of the parameters dflat reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownParam {
    /// Which.
    pub spec: ParamSpec,
    /// In dflat's unit (see [`ParamSpec::convert`]).
    pub value: f64,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    spec: ParamSpec,
    tries: u32,
    next_at: f64,
}

/// The reader (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct AutopilotParams {
    family: Option<AutopilotFamily>,
    pending: Vec<Pending>,
    hover_thrust: Option<KnownParam>,
    tilt_limit: Option<KnownParam>,
    given_up: Vec<&'static str>,
}

impl AutopilotParams {
    /// A reader that has asked nothing yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The autopilot's family is known at `t` \[s\]: the first call
    /// schedules the requests (later calls do nothing).
    pub fn start(&mut self, family: AutopilotFamily, t: f64) {
        if self.family.is_some() {
            return;
        }
        self.family = Some(family);
        self.pending = params_for(family)
            .into_iter()
            .map(|spec| Pending {
                spec,
                tries: 0,
                next_at: t,
            })
            .collect();
    }

    /// Names to request at `t` \[s\]; parameters asked [`TRIES`] times
    /// without an answer are given up (see [`AutopilotParams::given_up`]).
    pub fn due(&mut self, t: f64) -> Vec<&'static str> {
        let mut out = Vec::new();
        let given_up = &mut self.given_up;
        self.pending.retain_mut(|p| {
            if t < p.next_at {
                return true;
            }
            if p.tries >= TRIES {
                given_up.push(p.spec.name);
                return false;
            }
            p.tries += 1;
            p.next_at = t + RETRY_S;
            out.push(p.spec.name);
            true
        });
        out
    }

    /// A PARAM_VALUE from the autopilot: `Some` when it is one dflat reads
    /// (finite values only).
    pub fn on_value(&mut self, name: &str, value: f64) -> Option<KnownParam> {
        if !value.is_finite() {
            return None;
        }
        let i = self.pending.iter().position(|p| p.spec.name == name);
        let spec = match i {
            Some(i) => self.pending.remove(i).spec,
            // A late answer, after the requests were given up.
            None => params_for(self.family?)
                .into_iter()
                .find(|s| s.name == name)?,
        };
        let known = KnownParam {
            spec,
            value: spec.convert(value),
        };
        match spec.kind {
            ParamKind::HoverThrust => self.hover_thrust = Some(known),
            ParamKind::TiltLimitDeg => self.tilt_limit = Some(known),
        }
        Some(known)
    }

    /// The autopilot's hover thrust, if read.
    pub fn hover_thrust(&self) -> Option<KnownParam> {
        self.hover_thrust
    }

    /// The autopilot's tilt limit \[deg\], if read.
    pub fn tilt_limit(&self) -> Option<KnownParam> {
        self.tilt_limit
    }

    /// Parameters asked [`TRIES`] times without an answer.
    pub fn given_up(&self) -> &[&'static str] {
        &self.given_up
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asks_retries_and_gives_up() {
        let mut p = AutopilotParams::new();
        assert!(p.due(0.0).is_empty(), "nothing before the family is known");
        p.start(AutopilotFamily::Px4, 1.0);
        assert_eq!(p.due(1.0), ["MPC_THR_HOVER", "MPC_TILTMAX_AIR"]);
        assert!(p.due(1.5).is_empty());
        let hover = p.on_value("MPC_THR_HOVER", 0.42).unwrap();
        assert_eq!(hover.value, 0.42);
        assert_eq!(p.due(2.0), ["MPC_TILTMAX_AIR"]);
        assert_eq!(p.due(3.0), ["MPC_TILTMAX_AIR"]);
        assert!(p.due(4.0).is_empty());
        assert_eq!(p.given_up(), ["MPC_TILTMAX_AIR"]);
        assert_eq!(p.hover_thrust().unwrap().value, 0.42);
        assert!(p.tilt_limit().is_none());
        // A late answer still counts; unknown names and NaN do not.
        assert!((p.on_value("MPC_TILTMAX_AIR", 30.0).unwrap().value - 30.0).abs() < 1e-9);
        assert!(p.on_value("BAT_V_CHARGED", 4.2).is_none());
        assert!(p.on_value("MPC_THR_HOVER", f64::NAN).is_none());
        assert_eq!(p.hover_thrust().unwrap().value, 0.42);
    }

    #[test]
    fn ardupilot_angle_max_is_in_centidegrees() {
        let mut p = AutopilotParams::new();
        p.start(AutopilotFamily::ArduPilot, 0.0);
        assert_eq!(p.due(0.0), ["MOT_THST_HOVER", "ANGLE_MAX"]);
        assert!((p.on_value("ANGLE_MAX", 3000.0).unwrap().value - 30.0).abs() < 1e-9);
        let mut other = AutopilotParams::new();
        other.start(AutopilotFamily::Other, 0.0);
        assert!(other.due(0.0).is_empty());
    }
}
