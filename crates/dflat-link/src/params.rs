//! Autopilot parameters the daemon and the SITL agree on, and the
//! parameter protocol's encoding (pure).
//!
//! | what | PX4 | unit | ArduPilot | unit |
//! |---|---|---|---|---|
//! | [`AutopilotParam::HoverThrust`] | `MPC_THR_HOVER` (REAL32) | normalised thrust 0–1 | `MOT_THST_HOVER` (REAL32) | normalised thrust 0–1 |
//! | [`AutopilotParam::TiltMax`] | `MPC_TILTMAX_AIR` (REAL32) | deg | `ANGLE_MAX` (INT16) | centidegrees |
//! | [`AutopilotParam::OffboardLossTimeout`] | `COM_OF_LOSS_T` (REAL32) | s | `GUID_TIMEOUT` (REAL32) | s |
//! | [`AutopilotParam::SystemId`] | `MAV_SYS_ID` (INT32) | – | `SYSID_THISMAV` (INT16) | – |
//!
//! [`AutopilotParam::to_si`] turns a wire value into SI (tilt in radians,
//! times in seconds, thrust normalised); [`AutopilotParam::from_si`] the
//! other way.
//!
//! Values on the wire are `f32` whatever the type: PX4 puts the bytes of
//! an integer into the float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE),
//! ArduPilot casts it (PARAM_ENCODE_C_CAST); [`encode_value`] and
//! [`decode_value`] do both.

use mavlink::dialects::common::{
    MavMessage, MavParamType, PARAM_REQUEST_LIST_DATA, PARAM_REQUEST_READ_DATA, PARAM_VALUE_DATA,
};
use mavlink::types::CharArray;

use crate::modes::AutopilotFamily;

/// Longest parameter name (PARAM_VALUE's `param_id`).
pub const PARAM_ID_LEN: usize = 16;

/// An autopilot parameter dflat reads (see the module table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AutopilotParam {
    /// The autopilot's hover thrust, normalised 0–1.
    HoverThrust,
    /// The autopilot's tilt limit in flight.
    TiltMax,
    /// How long the autopilot keeps offboard / guided without a setpoint.
    OffboardLossTimeout,
    /// The vehicle's MAVLink system id.
    SystemId,
}

impl AutopilotParam {
    /// Every parameter, in table order.
    pub const ALL: [Self; 4] = [
        Self::HoverThrust,
        Self::TiltMax,
        Self::OffboardLossTimeout,
        Self::SystemId,
    ];

    /// Its name in `family`'s firmware (`None`: a family whose names are
    /// not known).
    pub fn name(self, family: AutopilotFamily) -> Option<&'static str> {
        let (px4, ardupilot) = match self {
            Self::HoverThrust => ("MPC_THR_HOVER", "MOT_THST_HOVER"),
            Self::TiltMax => ("MPC_TILTMAX_AIR", "ANGLE_MAX"),
            Self::OffboardLossTimeout => ("COM_OF_LOSS_T", "GUID_TIMEOUT"),
            Self::SystemId => ("MAV_SYS_ID", "SYSID_THISMAV"),
        };
        match family {
            AutopilotFamily::Px4 => Some(px4),
            AutopilotFamily::ArduPilot => Some(ardupilot),
            AutopilotFamily::Other => None,
        }
    }

    /// The parameter of `family` called `name`.
    pub fn from_name(family: AutopilotFamily, name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name(family) == Some(name))
    }

    /// Its unit on the wire in `family`'s firmware.
    pub fn unit(self, family: AutopilotFamily) -> &'static str {
        match (self, family) {
            (Self::HoverThrust, _) => "normalised 0-1",
            (Self::TiltMax, AutopilotFamily::ArduPilot) => "cdeg",
            (Self::TiltMax, _) => "deg",
            (Self::OffboardLossTimeout, _) => "s",
            (Self::SystemId, _) => "",
        }
    }

    /// Its MAVLink type in `family`'s firmware.
    pub fn param_type(self, family: AutopilotFamily) -> MavParamType {
        match (self, family) {
            (Self::TiltMax | Self::SystemId, AutopilotFamily::ArduPilot) => {
                MavParamType::MAV_PARAM_TYPE_INT16
            }
            (Self::SystemId, _) => MavParamType::MAV_PARAM_TYPE_INT32,
            _ => MavParamType::MAV_PARAM_TYPE_REAL32,
        }
    }

    /// A wire value (already [`decode_value`]d) in SI: tilt \[rad\],
    /// timeout \[s\], thrust normalised.
    pub fn to_si(self, family: AutopilotFamily, value: f64) -> f64 {
        match (self, family) {
            (Self::TiltMax, AutopilotFamily::ArduPilot) => (value / 100.0).to_radians(),
            (Self::TiltMax, _) => value.to_radians(),
            _ => value,
        }
    }

    /// An SI value as `family` states it (inverse of [`Self::to_si`]).
    pub fn from_si(self, family: AutopilotFamily, si: f64) -> f64 {
        match (self, family) {
            (Self::TiltMax, AutopilotFamily::ArduPilot) => si.to_degrees() * 100.0,
            (Self::TiltMax, _) => si.to_degrees(),
            _ => si,
        }
    }
}

/// Whether `ty` is an integer type.
fn is_integer(ty: MavParamType) -> bool {
    !matches!(
        ty,
        MavParamType::MAV_PARAM_TYPE_REAL32 | MavParamType::MAV_PARAM_TYPE_REAL64
    )
}

/// `value` as `family` puts it on the wire for type `ty`: PX4 integers
/// bytewise (the `i32`'s bits as an `f32`), everything else cast. Integers
/// are rounded.
pub fn encode_value(family: AutopilotFamily, ty: MavParamType, value: f64) -> f32 {
    if !is_integer(ty) {
        return value as f32;
    }
    let i = value.round();
    match family {
        AutopilotFamily::Px4 => f32::from_bits(i as i32 as u32),
        _ => i as f32,
    }
}

/// A wire `value` of type `ty` from `family` (inverse of [`encode_value`]).
pub fn decode_value(family: AutopilotFamily, ty: MavParamType, value: f32) -> f64 {
    if is_integer(ty) && family == AutopilotFamily::Px4 {
        f64::from(value.to_bits() as i32)
    } else {
        f64::from(value)
    }
}

/// `name` as a `param_id` (null-padded; longer names are cut at 16 bytes).
pub fn param_id(name: &str) -> CharArray<PARAM_ID_LEN> {
    let mut id = [0u8; PARAM_ID_LEN];
    for (d, s) in id.iter_mut().zip(name.bytes()) {
        *d = s;
    }
    CharArray::new(id)
}

/// A `param_id` as text (up to the first null; `None` when not UTF-8).
pub fn param_name(id: &CharArray<PARAM_ID_LEN>) -> Option<&str> {
    id.to_str().ok()
}

/// PARAM_VALUE: `name` = `value` (on the wire, see [`encode_value`]) of
/// type `ty`, number `index` of `count`.
pub fn param_value(name: &str, value: f32, ty: MavParamType, index: u16, count: u16) -> MavMessage {
    MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
        param_value: value,
        param_count: count,
        param_index: index,
        param_id: param_id(name),
        param_type: ty,
    })
}

/// PARAM_REQUEST_READ of `name` from `(system, component)`.
pub fn param_request_read(target: (u8, u8), name: &str) -> MavMessage {
    MavMessage::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
        param_index: -1,
        target_system: target.0,
        target_component: target.1,
        param_id: param_id(name),
    })
}

/// PARAM_REQUEST_LIST to `(system, component)`.
pub fn param_request_list(target: (u8, u8)) -> MavMessage {
    MavMessage::PARAM_REQUEST_LIST(PARAM_REQUEST_LIST_DATA {
        target_system: target.0,
        target_component: target.1,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_units_per_family() {
        use AutopilotFamily::*;
        assert_eq!(AutopilotParam::HoverThrust.name(Px4), Some("MPC_THR_HOVER"));
        assert_eq!(
            AutopilotParam::from_name(ArduPilot, "ANGLE_MAX"),
            Some(AutopilotParam::TiltMax)
        );
        assert_eq!(AutopilotParam::from_name(Px4, "ANGLE_MAX"), None);
        assert_eq!(AutopilotParam::TiltMax.name(Other), None);
        let t = AutopilotParam::TiltMax;
        assert!((t.to_si(ArduPilot, 3500.0) - 35f64.to_radians()).abs() < 1e-12);
        assert!((t.to_si(Px4, 35.0) - 35f64.to_radians()).abs() < 1e-12);
        assert!((t.from_si(ArduPilot, t.to_si(ArduPilot, 4500.0)) - 4500.0).abs() < 1e-9);
    }

    #[test]
    fn integers_are_bytewise_for_px4_and_cast_for_ardupilot() {
        let ty = MavParamType::MAV_PARAM_TYPE_INT32;
        let px4 = encode_value(AutopilotFamily::Px4, ty, 1.0);
        assert_eq!(px4.to_bits(), 1);
        assert_eq!(decode_value(AutopilotFamily::Px4, ty, px4), 1.0);
        let ap = encode_value(AutopilotFamily::ArduPilot, ty, 3500.0);
        assert_eq!(ap, 3500.0);
        assert_eq!(decode_value(AutopilotFamily::ArduPilot, ty, ap), 3500.0);
        let real = MavParamType::MAV_PARAM_TYPE_REAL32;
        assert_eq!(encode_value(AutopilotFamily::Px4, real, 0.5), 0.5);
    }

    #[test]
    fn param_ids_round_trip_and_are_cut_at_16_bytes() {
        assert_eq!(
            param_name(&param_id("MPC_THR_HOVER")),
            Some("MPC_THR_HOVER")
        );
        assert_eq!(
            param_name(&param_id("A_NAME_LONGER_THAN_16")),
            Some("A_NAME_LONGER_TH")
        );
    }
}
