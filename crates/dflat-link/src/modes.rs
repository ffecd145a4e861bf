//! Autopilot flight modes as their HEARTBEAT reports them, and whether the
//! autopilot applies an offboard computer's attitude targets in that mode.
//!
//! * **PX4** packs its mode in `custom_mode`: main mode in bits 16–23, sub
//!   mode in bits 24–31 (`px4_custom_mode.h`). The companion's
//!   SET_ATTITUDE_TARGET is applied in main mode OFFBOARD (6), armed.
//! * **ArduPilot Copter** reports its mode number in `custom_mode`
//!   (STABILIZE 0, ALT_HOLD 2, AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9,
//!   POSHOLD 16, BRAKE 17, GUIDED_NOGPS 20, …). Attitude targets are applied
//!   in GUIDED_NOGPS (20) and GUIDED (4), armed.
//!
//! The family comes from the HEARTBEAT's `autopilot` field
//! (MAV_AUTOPILOT_PX4 = 12, MAV_AUTOPILOT_ARDUPILOTMEGA = 3) unless the
//! configuration overrides it.

use std::fmt;

use mavlink::dialects::common::MavAutopilot;

/// Which autopilot firmware interprets `custom_mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum AutopilotFamily {
    /// PX4 (MAV_AUTOPILOT_PX4).
    Px4,
    /// ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA), Copter mode numbers.
    ArduPilot,
    /// Anything else: its modes are not understood.
    Other,
}

impl AutopilotFamily {
    /// The family a HEARTBEAT's `autopilot` field names.
    pub fn from_mav_autopilot(a: MavAutopilot) -> Self {
        match a {
            MavAutopilot::MAV_AUTOPILOT_PX4 => Self::Px4,
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Self::ArduPilot,
            _ => Self::Other,
        }
    }

    /// Lower-case name (`px4`, `ardupilot`, `other`), as in the config.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Px4 => "px4",
            Self::ArduPilot => "ardupilot",
            Self::Other => "other",
        }
    }
}

/// PX4 main modes (`PX4_CUSTOM_MAIN_MODE_*`).
pub mod px4 {
    /// MANUAL.
    pub const MANUAL: u8 = 1;
    /// ALTCTL.
    pub const ALTCTL: u8 = 2;
    /// POSCTL.
    pub const POSCTL: u8 = 3;
    /// AUTO (sub modes: takeoff, loiter, mission, RTL, land, …).
    pub const AUTO: u8 = 4;
    /// ACRO.
    pub const ACRO: u8 = 5;
    /// OFFBOARD.
    pub const OFFBOARD: u8 = 6;
    /// STABILIZED.
    pub const STABILIZED: u8 = 7;

    /// `custom_mode` for a main and sub mode.
    pub fn custom_mode(main: u8, sub: u8) -> u32 {
        (u32::from(main) << 16) | (u32::from(sub) << 24)
    }

    /// The main mode of a `custom_mode`.
    pub fn main_mode(custom_mode: u32) -> u8 {
        ((custom_mode >> 16) & 0xff) as u8
    }

    /// Name of a main mode (`"?"` when unknown).
    pub fn name(main: u8) -> &'static str {
        match main {
            MANUAL => "MANUAL",
            ALTCTL => "ALTCTL",
            POSCTL => "POSCTL",
            AUTO => "AUTO",
            ACRO => "ACRO",
            OFFBOARD => "OFFBOARD",
            STABILIZED => "STABILIZED",
            8 => "RATTITUDE",
            _ => "?",
        }
    }
}

/// ArduPilot Copter mode numbers.
pub mod ardupilot {
    /// STABILIZE.
    pub const STABILIZE: u32 = 0;
    /// ALT_HOLD.
    pub const ALT_HOLD: u32 = 2;
    /// AUTO.
    pub const AUTO: u32 = 3;
    /// GUIDED.
    pub const GUIDED: u32 = 4;
    /// LOITER.
    pub const LOITER: u32 = 5;
    /// RTL.
    pub const RTL: u32 = 6;
    /// LAND.
    pub const LAND: u32 = 9;
    /// POSHOLD.
    pub const POSHOLD: u32 = 16;
    /// BRAKE.
    pub const BRAKE: u32 = 17;
    /// GUIDED_NOGPS.
    pub const GUIDED_NOGPS: u32 = 20;

    /// Name of a Copter mode number (`"?"` when unknown).
    pub fn name(mode: u32) -> &'static str {
        match mode {
            STABILIZE => "STABILIZE",
            1 => "ACRO",
            ALT_HOLD => "ALT_HOLD",
            AUTO => "AUTO",
            GUIDED => "GUIDED",
            LOITER => "LOITER",
            RTL => "RTL",
            7 => "CIRCLE",
            LAND => "LAND",
            11 => "DRIFT",
            13 => "SPORT",
            14 => "FLIP",
            15 => "AUTOTUNE",
            POSHOLD => "POSHOLD",
            BRAKE => "BRAKE",
            18 => "THROW",
            19 => "AVOID_ADSB",
            GUIDED_NOGPS => "GUIDED_NOGPS",
            21 => "SMART_RTL",
            _ => "?",
        }
    }
}

/// An autopilot's mode as read from its HEARTBEAT.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AutopilotMode {
    /// How `custom_mode` is read.
    pub family: AutopilotFamily,
    /// The raw `custom_mode`.
    pub custom_mode: u32,
    /// MAV_MODE_FLAG_SAFETY_ARMED.
    pub armed: bool,
}

impl AutopilotMode {
    /// The mode's name in the family's terms (`OFFBOARD`, `POSCTL`,
    /// `GUIDED_NOGPS`, `LOITER`, …; `custom 0x…` when unknown).
    pub fn name(&self) -> String {
        let known = match self.family {
            AutopilotFamily::Px4 => px4::name(px4::main_mode(self.custom_mode)),
            AutopilotFamily::ArduPilot => ardupilot::name(self.custom_mode),
            AutopilotFamily::Other => "?",
        };
        if known == "?" {
            format!("custom {:#x}", self.custom_mode)
        } else {
            known.to_owned()
        }
    }

    /// Whether the autopilot's mode is the one in which it applies an
    /// offboard computer's SET_ATTITUDE_TARGET (PX4 OFFBOARD; ArduPilot
    /// GUIDED_NOGPS or GUIDED), regardless of arming.
    pub fn is_offboard(&self) -> bool {
        match self.family {
            AutopilotFamily::Px4 => px4::main_mode(self.custom_mode) == px4::OFFBOARD,
            AutopilotFamily::ArduPilot => {
                self.custom_mode == ardupilot::GUIDED_NOGPS || self.custom_mode == ardupilot::GUIDED
            }
            AutopilotFamily::Other => false,
        }
    }

    /// Armed and in the offboard mode: the commands are applied.
    pub fn applies_commands(&self) -> bool {
        self.armed && self.is_offboard()
    }
}

impl fmt::Display for AutopilotMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {}{}",
            self.family.as_str(),
            self.name(),
            if self.armed { " armed" } else { " disarmed" }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode(family: AutopilotFamily, custom_mode: u32, armed: bool) -> AutopilotMode {
        AutopilotMode {
            family,
            custom_mode,
            armed,
        }
    }

    #[test]
    fn px4_offboard_is_main_mode_6_whatever_the_sub_mode() {
        let off = mode(
            AutopilotFamily::Px4,
            px4::custom_mode(px4::OFFBOARD, 0),
            true,
        );
        assert_eq!(off.custom_mode, 6 << 16);
        assert!(off.applies_commands());
        assert_eq!(off.name(), "OFFBOARD");
        // Sub-mode bits do not change the main mode.
        assert!(
            mode(
                AutopilotFamily::Px4,
                px4::custom_mode(px4::OFFBOARD, 3),
                true
            )
            .is_offboard()
        );
        let pos = mode(AutopilotFamily::Px4, px4::custom_mode(px4::POSCTL, 0), true);
        assert!(!pos.is_offboard());
        assert_eq!(pos.to_string(), "px4 POSCTL armed");
        // ArduPilot's GUIDED_NOGPS number means nothing to PX4.
        assert!(!mode(AutopilotFamily::Px4, 20, true).is_offboard());
        // Disarmed OFFBOARD does not apply commands.
        assert!(!mode(AutopilotFamily::Px4, 6 << 16, false).applies_commands());
    }

    #[test]
    fn ardupilot_guided_modes_apply_commands() {
        for m in [ardupilot::GUIDED_NOGPS, ardupilot::GUIDED] {
            assert!(mode(AutopilotFamily::ArduPilot, m, true).applies_commands());
        }
        for m in [
            ardupilot::LOITER,
            ardupilot::ALT_HOLD,
            ardupilot::STABILIZE,
            6 << 16,
        ] {
            assert!(
                !mode(AutopilotFamily::ArduPilot, m, true).is_offboard(),
                "{m}"
            );
        }
        assert_eq!(
            mode(AutopilotFamily::ArduPilot, 20, true).name(),
            "GUIDED_NOGPS"
        );
        assert_eq!(
            mode(AutopilotFamily::ArduPilot, 99, true).name(),
            "custom 0x63"
        );
    }

    #[test]
    fn families_from_the_heartbeat() {
        assert_eq!(
            AutopilotFamily::from_mav_autopilot(MavAutopilot::MAV_AUTOPILOT_PX4),
            AutopilotFamily::Px4
        );
        assert_eq!(
            AutopilotFamily::from_mav_autopilot(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA),
            AutopilotFamily::ArduPilot
        );
        assert_eq!(
            AutopilotFamily::from_mav_autopilot(MavAutopilot::MAV_AUTOPILOT_GENERIC),
            AutopilotFamily::Other
        );
        assert!(!mode(AutopilotFamily::Other, 6 << 16, true).is_offboard());
    }
}
