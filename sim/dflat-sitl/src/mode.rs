//! The autopilot stand-in's mode and how its HEARTBEAT reports it.

use crate::{
    ARDUPILOT_MODE_GUIDED_NOGPS, ARDUPILOT_MODE_LOITER, ARDUPILOT_MODE_RTL, PX4_MODE_OFFBOARD,
    PX4_MODE_POSCTL, SitlAutopilot, px4_face,
};

/// What the autopilot stand-in is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SitlMode {
    /// Holding position on its own (start, and after a command timeout).
    Hold,
    /// Following the setpoint stream: SET_ATTITUDE_TARGET, or position
    /// setpoints to the autopilot flown by its position loop (the latest
    /// type wins).
    Offboard,
    /// PX4 AUTO_LOITER (`hold()`, `goto_location()`): the SITL's position
    /// loop flies to a goal and holds there.
    Loiter,
    /// PX4 AUTO_RTL: as [`SitlMode::Loiter`] with home (the start point)
    /// as the goal; the plant cannot land, so it holds there.
    Rtl,
}

impl SitlMode {
    /// Lower-case name, as printed and written to the truth CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            SitlMode::Hold => "hold",
            SitlMode::Offboard => "offboard",
            SitlMode::Loiter => "loiter",
            SitlMode::Rtl => "rtl",
        }
    }

    /// HEARTBEAT `custom_mode` as `autopilot` reports it: PX4 POSCTL /
    /// OFFBOARD, ArduPilot LOITER (5) / GUIDED_NOGPS (20).
    pub fn custom_mode(self, autopilot: SitlAutopilot) -> u32 {
        match (autopilot, self) {
            (SitlAutopilot::Px4, SitlMode::Hold) => PX4_MODE_POSCTL,
            (SitlAutopilot::Px4, SitlMode::Offboard) => PX4_MODE_OFFBOARD,
            (SitlAutopilot::Ardupilot, SitlMode::Hold) => ARDUPILOT_MODE_LOITER,
            (SitlAutopilot::Ardupilot, SitlMode::Offboard) => ARDUPILOT_MODE_GUIDED_NOGPS,
            (SitlAutopilot::Px4, SitlMode::Loiter) => px4_face::px4_auto(px4_face::PX4_AUTO_LOITER),
            (SitlAutopilot::Px4, SitlMode::Rtl) => px4_face::px4_auto(px4_face::PX4_AUTO_RTL),
            (SitlAutopilot::Ardupilot, SitlMode::Loiter) => ARDUPILOT_MODE_LOITER,
            (SitlAutopilot::Ardupilot, SitlMode::Rtl) => ARDUPILOT_MODE_RTL,
        }
    }
}
