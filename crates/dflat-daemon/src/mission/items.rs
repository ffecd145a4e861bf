//! Mission items as the daemon flies them: the supported commands read
//! from MISSION_ITEM_INT / MISSION_ITEM, checked, and the mission they make.

use dflat_link::dialect::{MavCmd, MavFrame, MavMissionResult};
use dflat_link::mission::ItemFields;

/// How the items' x / y are read and checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ItemRules {
    /// MISSION_ITEM_INT's x and y in local frames are metres × this
    /// (`mission.local_xy_scale`: 1e4 per the specification; pymavlink's
    /// `mavwp` and MAVProxy's `wp` send metres × 1e7).
    pub int_scale: f64,
    /// The fence's smallest x, y, z \[m\] (NED: z's is the ceiling).
    pub fence_min: [f64; 3],
    /// The fence's largest x, y, z \[m\] (NED: z's is the floor).
    pub fence_max: [f64; 3],
    /// Acceptance radius \[m\] of a waypoint whose param2 is 0.
    pub acceptance_radius: f64,
}

impl ItemRules {
    /// The rules of the `[mission]` table (`local_xy_scale`, `geofence`,
    /// `acceptance_radius_m`), as the receive task and a replay read
    /// uploads.
    pub fn of(mission: &crate::config::MissionConfig) -> Self {
        Self {
            int_scale: mission.local_xy_scale,
            fence_min: [
                -mission.geofence[0],
                -mission.geofence[1],
                -mission.geofence[2],
            ],
            fence_max: [
                mission.geofence[0],
                mission.geofence[1],
                mission.geofence_down_m,
            ],
            acceptance_radius: mission.acceptance_radius_m,
        }
    }
}

/// One supported item.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MissionItem {
    /// MAV_CMD_NAV_WAYPOINT (16): fly to `position`, hold `hold` \[s\]
    /// (param1), reached within `acceptance` \[m\] (param2; 0 = the
    /// configured radius); `yaw` \[rad\] (param4 in degrees, NaN = keep).
    Waypoint {
        /// Local NED \[m\].
        position: [f64; 3],
        /// Hold time at the waypoint \[s\] (≥ 0).
        hold: f64,
        /// Acceptance radius \[m\] (> 0).
        acceptance: f64,
        /// Heading to fly \[rad\], `None` = unchanged.
        yaw: Option<f64>,
    },
    /// MAV_CMD_NAV_LOITER_TIME (19): fly to `position` and hold there
    /// `time` \[s\] (param1); param4-free; yaw unchanged.
    LoiterTime {
        /// Local NED \[m\].
        position: [f64; 3],
        /// Hold time \[s\] (≥ 0).
        time: f64,
        /// Acceptance radius \[m\] (the configured one).
        acceptance: f64,
    },
    /// MAV_CMD_DO_CHANGE_SPEED (178): the speed \[m/s\] (param2) of the
    /// legs that follow; `None` (param2 = −1) leaves it.
    ChangeSpeed {
        /// Speed \[m/s\], if changed.
        speed: Option<f64>,
    },
}

impl MissionItem {
    /// The position it flies to, for a navigation item.
    pub fn position(&self) -> Option<[f64; 3]> {
        match self {
            MissionItem::Waypoint { position, .. } | MissionItem::LoiterTime { position, .. } => {
                Some(*position)
            }
            MissionItem::ChangeSpeed { .. } => None,
        }
    }
}

/// Why an item was refused: the MISSION_ACK result and the words of the
/// STATUSTEXT.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemError {
    /// The MISSION_ACK result.
    pub result: MavMissionResult,
    /// The STATUSTEXT (≤ 50 bytes).
    pub text: String,
}

fn refuse(result: MavMissionResult, text: String) -> ItemError {
    ItemError { result, text }
}

/// Largest speed a DO_CHANGE_SPEED may ask for \[m/s\] (`mission.speed`'s range).
pub const MAX_SPEED: f64 = 20.0;

/// Reads one item (`fields`) under `rules`: the supported commands in
/// MAV_FRAME_LOCAL_NED (DO_CHANGE_SPEED in any frame: it has no position),
/// finite, inside the geofence.
pub fn parse_item(fields: &ItemFields, rules: &ItemRules) -> Result<MissionItem, ItemError> {
    let seq = fields.seq;
    let [p1, p2, _p3, p4] = fields.params.map(f64::from);
    if fields.command == MavCmd::MAV_CMD_DO_CHANGE_SPEED {
        if !p2.is_finite() {
            return Err(refuse(
                MavMissionResult::MAV_MISSION_INVALID_PARAM2,
                format!("dflat: item {seq}: speed not finite"),
            ));
        }
        if p2 == -1.0 || p2 == -2.0 {
            return Ok(MissionItem::ChangeSpeed { speed: None });
        }
        if !(0.1..=MAX_SPEED).contains(&p2) {
            return Err(refuse(
                MavMissionResult::MAV_MISSION_INVALID_PARAM2,
                format!("dflat: item {seq}: speed {p2:.1} not 0.1-20"),
            ));
        }
        return Ok(MissionItem::ChangeSpeed { speed: Some(p2) });
    }
    let navigation = matches!(
        fields.command,
        MavCmd::MAV_CMD_NAV_WAYPOINT | MavCmd::MAV_CMD_NAV_LOITER_TIME
    );
    if !navigation {
        return Err(refuse(
            MavMissionResult::MAV_MISSION_UNSUPPORTED,
            format!(
                "dflat: item {seq}: command {} unsupported",
                fields.command as u32
            ),
        ));
    }
    if fields.frame != MavFrame::MAV_FRAME_LOCAL_NED {
        return Err(refuse(
            MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
            format!(
                "dflat: item {seq}: frame {} not LOCAL_NED",
                fields.frame as u32
            ),
        ));
    }
    let scale = if fields.int { rules.int_scale } else { 1.0 };
    let position = [fields.x / scale, fields.y / scale, f64::from(fields.z)];
    for (i, (v, result)) in position
        .iter()
        .zip([
            MavMissionResult::MAV_MISSION_INVALID_PARAM5_X,
            MavMissionResult::MAV_MISSION_INVALID_PARAM6_Y,
            MavMissionResult::MAV_MISSION_INVALID_PARAM7,
        ])
        .enumerate()
    {
        if !v.is_finite() || *v < rules.fence_min[i] || *v > rules.fence_max[i] {
            return Err(refuse(
                result,
                format!(
                    "dflat: item {seq}: {} outside the fence",
                    ["x", "y", "z"][i]
                ),
            ));
        }
    }
    let time = if p1.is_finite() { p1.max(0.0) } else { 0.0 };
    Ok(if fields.command == MavCmd::MAV_CMD_NAV_WAYPOINT {
        let acceptance = if p2.is_finite() && p2 > 0.0 {
            p2
        } else {
            rules.acceptance_radius
        };
        MissionItem::Waypoint {
            position,
            hold: time,
            acceptance,
            yaw: p4.is_finite().then(|| p4.to_radians()),
        }
    } else {
        MissionItem::LoiterTime {
            position,
            time,
            acceptance: rules.acceptance_radius,
        }
    })
}

/// An uploaded mission: the items as received (for download) and as read.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mission {
    /// The items as they arrived (returned on download unchanged).
    pub raw: Vec<ItemFields>,
    /// The items read, one per raw item.
    pub items: Vec<MissionItem>,
}

impl Mission {
    /// Number of items.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True with no item.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// True when some item flies somewhere (a mission that can be started).
    pub fn has_navigation(&self) -> bool {
        self.items.iter().any(|i| i.position().is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULES: ItemRules = ItemRules {
        int_scale: 1e4,
        fence_min: [-100.0, -100.0, -50.0],
        fence_max: [100.0, 100.0, 50.0],
        acceptance_radius: 1.0,
    };

    fn fields(command: MavCmd, params: [f32; 4], xyz: [f64; 3]) -> ItemFields {
        ItemFields {
            seq: 0,
            frame: MavFrame::MAV_FRAME_LOCAL_NED,
            command,
            params,
            x: xyz[0],
            y: xyz[1],
            z: xyz[2] as f32,
            current: 0,
            autocontinue: 1,
            int: true,
        }
    }

    #[test]
    fn supported_items_are_read_in_metres() {
        let w = parse_item(
            &fields(
                MavCmd::MAV_CMD_NAV_WAYPOINT,
                [2.0, 0.5, 0.0, 90.0],
                [40_000.0, -20_000.0, -10.0],
            ),
            &RULES,
        )
        .unwrap();
        assert_eq!(
            w,
            MissionItem::Waypoint {
                position: [4.0, -2.0, -10.0],
                hold: 2.0,
                acceptance: 0.5,
                yaw: Some(90f64.to_radians())
            }
        );
        let w = parse_item(
            &fields(
                MavCmd::MAV_CMD_NAV_WAYPOINT,
                [0.0, 0.0, 0.0, f32::NAN],
                [0.0, 0.0, -10.0],
            ),
            &RULES,
        )
        .unwrap();
        assert!(matches!(
            w,
            MissionItem::Waypoint {
                acceptance: 1.0,
                yaw: None,
                ..
            }
        ));
        let l = parse_item(
            &fields(
                MavCmd::MAV_CMD_NAV_LOITER_TIME,
                [3.0, 0.0, 0.0, 0.0],
                [10_000.0, 0.0, -5.0],
            ),
            &RULES,
        )
        .unwrap();
        assert_eq!(l.position(), Some([1.0, 0.0, -5.0]));
        let s = parse_item(
            &fields(
                MavCmd::MAV_CMD_DO_CHANGE_SPEED,
                [1.0, 3.0, -1.0, 0.0],
                [0.0; 3],
            ),
            &RULES,
        )
        .unwrap();
        assert_eq!(s, MissionItem::ChangeSpeed { speed: Some(3.0) });
        let mut legacy = fields(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], [4.0, 2.0, -10.0]);
        legacy.int = false;
        assert_eq!(
            parse_item(&legacy, &RULES).unwrap().position(),
            Some([4.0, 2.0, -10.0])
        );
    }

    #[test]
    fn refusals_name_the_field() {
        let table: [(ItemFields, MavMissionResult); 6] = [
            (
                fields(MavCmd::MAV_CMD_NAV_TAKEOFF, [0.0; 4], [0.0; 3]),
                MavMissionResult::MAV_MISSION_UNSUPPORTED,
            ),
            (
                ItemFields {
                    frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
                    ..fields(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], [0.0; 3])
                },
                MavMissionResult::MAV_MISSION_UNSUPPORTED_FRAME,
            ),
            (
                fields(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], [2e7, 0.0, 0.0]),
                MavMissionResult::MAV_MISSION_INVALID_PARAM5_X,
            ),
            (
                fields(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], [0.0, -2e7, 0.0]),
                MavMissionResult::MAV_MISSION_INVALID_PARAM6_Y,
            ),
            (
                fields(MavCmd::MAV_CMD_NAV_WAYPOINT, [0.0; 4], [0.0, 0.0, f64::NAN]),
                MavMissionResult::MAV_MISSION_INVALID_PARAM7,
            ),
            (
                fields(
                    MavCmd::MAV_CMD_DO_CHANGE_SPEED,
                    [1.0, 50.0, 0.0, 0.0],
                    [0.0; 3],
                ),
                MavMissionResult::MAV_MISSION_INVALID_PARAM2,
            ),
        ];
        for (f, result) in table {
            let e = parse_item(&f, &RULES).unwrap_err();
            assert_eq!(e.result, result, "{f:?}");
            assert!(
                e.text.len() <= 50 && e.text.starts_with("dflat: item 0"),
                "{e:?}"
            );
        }
    }
}
