//! The SITL's parameters (pure): what a ground station (or the daemon)
//! reads over the parameter protocol, per flavour (`sitl.autopilot`).
//!
//! | PX4 | ArduPilot | value | unit | writable |
//! |---|---|---|---|---|
//! | `MPC_THR_HOVER` | `MOT_THST_HOVER` | `sitl.hover_thrust` | normalised 0–1 | no: the plant's truth |
//! | `MPC_TILTMAX_AIR` | `ANGLE_MAX` | 35° ([`super::TILT_LIMIT_DEG`]) | deg / centidegrees | no: the plant's saturation |
//! | `COM_OF_LOSS_T` | `GUID_TIMEOUT` | `sitl.command_timeout_s` | s | yes, 0.1–60 s: applied at once (offboard loss → position mode) |
//! | `MAV_SYS_ID` | `SYSID_THISMAV` | `[link] system_id` | – | no |
//!
//! Names, units and the wire encoding are [`dflat_link::params`] (shared
//! with the daemon, which reads the same names from a real autopilot).
//! A PARAM_SET of a read-only parameter is refused with a STATUSTEXT and
//! answered with the unchanged PARAM_VALUE; one of an unknown name, with
//! a non-finite or out-of-range value, is refused with a STATUSTEXT.

use dflat_link::MavMessage;
use dflat_link::modes::AutopilotFamily;
use dflat_link::params::{AutopilotParam, decode_value, encode_value, param_value};

use super::SitlAutopilot;

/// Range of the writable offboard-loss timeout \[s\].
pub const LOSS_TIMEOUT_RANGE: (f64, f64) = (0.1, 60.0);

/// One parameter of the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SitlParam {
    /// Which one.
    pub param: AutopilotParam,
    /// Its name in the flavour's firmware.
    pub name: &'static str,
    /// Its value in the flavour's unit (see the module table).
    pub value: f64,
    /// Whether PARAM_SET may change it.
    pub writable: bool,
}

/// Why a PARAM_SET or PARAM_REQUEST_READ was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// No parameter of that name (or index).
    #[error("SITL: no parameter {0}")]
    Unknown(String),
    /// The parameter is read-only here.
    #[error("SITL: {0} is read-only")]
    ReadOnly(&'static str),
    /// The value is not finite or out of range.
    #[error("SITL: {name} = {value} refused, range {min}..{max}")]
    OutOfRange {
        /// The parameter.
        name: &'static str,
        /// The value asked for.
        value: f64,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
}

/// The SITL's parameter table.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamTable {
    family: AutopilotFamily,
    params: Vec<SitlParam>,
}

/// The firmware family of a SITL flavour.
pub fn family(autopilot: SitlAutopilot) -> AutopilotFamily {
    match autopilot {
        SitlAutopilot::Px4 => AutopilotFamily::Px4,
        SitlAutopilot::Ardupilot => AutopilotFamily::ArduPilot,
    }
}

impl ParamTable {
    /// The table of `autopilot` for a plant hovering at `hover_thrust`,
    /// saturating at `tilt_limit_deg`, dropping out of offboard after
    /// `loss_timeout_s`, as system `system_id`.
    pub fn new(
        autopilot: SitlAutopilot,
        hover_thrust: f64,
        tilt_limit_deg: f64,
        loss_timeout_s: f64,
        system_id: u8,
    ) -> Self {
        let family = family(autopilot);
        let si = [
            (AutopilotParam::HoverThrust, hover_thrust, false),
            (AutopilotParam::TiltMax, tilt_limit_deg.to_radians(), false),
            (AutopilotParam::OffboardLossTimeout, loss_timeout_s, true),
            (AutopilotParam::SystemId, f64::from(system_id), false),
        ];
        let params = si
            .into_iter()
            .map(|(param, value, writable)| SitlParam {
                param,
                // Both flavours name every parameter.
                name: param.name(family).unwrap_or("?"),
                value: param.from_si(family, value),
                writable,
            })
            .collect();
        Self { family, params }
    }

    /// The firmware family the names belong to.
    pub fn family(&self) -> AutopilotFamily {
        self.family
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.params.len()
    }

    /// True when there are none (never, for a built table).
    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// The parameters in index order.
    pub fn iter(&self) -> impl Iterator<Item = &SitlParam> {
        self.params.iter()
    }

    /// Index and entry of `name`.
    pub fn find(&self, name: &str) -> Option<(usize, &SitlParam)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }

    /// The value of `param` in SI (tilt \[rad\], timeout \[s\]).
    pub fn si(&self, param: AutopilotParam) -> Option<f64> {
        self.params
            .iter()
            .find(|p| p.param == param)
            .map(|p| param.to_si(self.family, p.value))
    }

    /// PARAM_VALUE of entry `index`.
    pub fn value_message(&self, index: usize) -> Option<MavMessage> {
        let p = self.params.get(index)?;
        let ty = p.param.param_type(self.family);
        Some(param_value(
            p.name,
            encode_value(self.family, ty, p.value),
            ty,
            u16::try_from(index).ok()?,
            u16::try_from(self.params.len()).ok()?,
        ))
    }

    /// The index PARAM_REQUEST_READ asks for: `param_index` ≥ 0, else the
    /// name.
    pub fn lookup(&self, index: i16, name: &str) -> Result<usize, ParamError> {
        if index >= 0 {
            let i = index as usize;
            return (i < self.params.len())
                .then_some(i)
                .ok_or_else(|| ParamError::Unknown(format!("#{index}")));
        }
        self.find(name)
            .map(|(i, _)| i)
            .ok_or_else(|| ParamError::Unknown(name.to_owned()))
    }

    /// PARAM_SET of `name` to the wire value `wire` (type as the table
    /// says): the index of the changed entry.
    pub fn set(&mut self, name: &str, wire: f32) -> Result<usize, ParamError> {
        let family = self.family;
        let (i, p) = self
            .find(name)
            .ok_or_else(|| ParamError::Unknown(name.to_owned()))?;
        if !p.writable {
            return Err(ParamError::ReadOnly(p.name));
        }
        let value = decode_value(family, p.param.param_type(family), wire);
        let (min, max) = LOSS_TIMEOUT_RANGE;
        let si = p.param.to_si(family, value);
        if !(si.is_finite() && (min..=max).contains(&si)) {
            return Err(ParamError::OutOfRange {
                name: p.name,
                value,
                min,
                max,
            });
        }
        self.params[i].value = value;
        Ok(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_link::dialect::MavParamType;

    fn px4() -> ParamTable {
        ParamTable::new(SitlAutopilot::Px4, 0.42, 35.0, 0.5, 1)
    }

    fn value(m: &MavMessage) -> (String, f32, MavParamType, u16, u16) {
        match m {
            MavMessage::PARAM_VALUE(d) => (
                d.param_id.to_str().unwrap().to_owned(),
                d.param_value,
                d.param_type,
                d.param_index,
                d.param_count,
            ),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn px4_values_in_px4_units() {
        let t = px4();
        let names: Vec<_> = t.iter().map(|p| p.name).collect();
        assert_eq!(
            names,
            [
                "MPC_THR_HOVER",
                "MPC_TILTMAX_AIR",
                "COM_OF_LOSS_T",
                "MAV_SYS_ID"
            ]
        );
        let (name, v, ty, i, n) = value(&t.value_message(1).unwrap());
        assert_eq!(
            (name.as_str(), ty, i, n),
            ("MPC_TILTMAX_AIR", MavParamType::MAV_PARAM_TYPE_REAL32, 1, 4)
        );
        assert!((v - 35.0).abs() < 1e-4);
        assert_eq!(value(&t.value_message(0).unwrap()).1, 0.42);
        // PX4 integers travel bytewise.
        assert_eq!(value(&t.value_message(3).unwrap()).1.to_bits(), 1);
        assert!(t.value_message(4).is_none());
    }

    #[test]
    fn ardupilot_values_in_ardupilot_units() {
        let t = ParamTable::new(SitlAutopilot::Ardupilot, 0.5, 35.0, 3.0, 1);
        let (i, p) = t.find("ANGLE_MAX").unwrap();
        assert!((p.value - 3500.0).abs() < 1e-6);
        let (_, v, ty, ..) = value(&t.value_message(i).unwrap());
        assert_eq!((v, ty), (3500.0, MavParamType::MAV_PARAM_TYPE_INT16));
        assert!(t.find("GUID_TIMEOUT").is_some() && t.find("MOT_THST_HOVER").is_some());
        assert!((t.si(AutopilotParam::TiltMax).unwrap() - 35f64.to_radians()).abs() < 1e-9);
    }

    #[test]
    fn only_the_loss_timeout_is_writable_within_range() {
        let mut t = px4();
        assert_eq!(t.set("COM_OF_LOSS_T", 1.5), Ok(2));
        assert_eq!(t.si(AutopilotParam::OffboardLossTimeout), Some(1.5));
        assert_eq!(
            t.set("MPC_THR_HOVER", 0.3),
            Err(ParamError::ReadOnly("MPC_THR_HOVER"))
        );
        assert!(matches!(
            t.set("COM_OF_LOSS_T", f32::NAN),
            Err(ParamError::OutOfRange { .. })
        ));
        assert!(matches!(
            t.set("COM_OF_LOSS_T", 0.0),
            Err(ParamError::OutOfRange { .. })
        ));
        assert!(matches!(t.set("NOPE", 1.0), Err(ParamError::Unknown(_))));
        assert_eq!(t.si(AutopilotParam::OffboardLossTimeout), Some(1.5));
        assert_eq!(t.lookup(-1, "MAV_SYS_ID"), Ok(3));
        assert_eq!(t.lookup(2, "ignored"), Ok(2));
        assert!(t.lookup(9, "").is_err() && t.lookup(-1, "NOPE").is_err());
    }
}
