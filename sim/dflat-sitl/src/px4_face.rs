//! What a PX4 an SDK can script sends and answers, beyond the pose stream
//! (pure message builders and tables; the state and the answers are the
//! step's, [`super::step`]):
//!
//! * HOME_POSITION (the start point), EXTENDED_SYS_STATE (in air,
//!   multicopter), ATTITUDE_QUATERNION, GLOBAL_POSITION_INT and
//!   BATTERY_STATUS (no battery model: every field "unknown" as the
//!   MAVLink spec writes it), each a stream whose interval
//!   SET_MESSAGE_INTERVAL sets ([`Streams`]);
//! * AUTOPILOT_VERSION with a version, a uid and the capabilities the SITL
//!   implements;
//! * the mission protocol on the autopilot: the SITL flies no missions, so
//!   an upload is answered MAV_MISSION_UNSUPPORTED, a download with an
//!   empty list and MISSION_CLEAR_ALL with ACCEPTED — no client times out;
//! * the local frame's geodetic origin ([`GeoOrigin`]): lat/lon/alt of
//!   HOME_POSITION and GLOBAL_POSITION_INT, and of MAV_CMD_DO_REPOSITION
//!   targets (`goto_location`), by a flat-earth map around PX4 SITL's
//!   default origin.

use dflat_link::MavMessage;
use dflat_link::dialect::{
    ATTITUDE_QUATERNION_DATA, AUTOPILOT_VERSION_DATA, BATTERY_STATUS_DATA, EXTENDED_SYS_STATE_DATA,
    GLOBAL_POSITION_INT_DATA, HOME_POSITION_DATA, MISSION_ACK_DATA, MISSION_COUNT_DATA,
    MavBatteryChargeState, MavBatteryFault, MavBatteryFunction, MavBatteryMode, MavBatteryType,
    MavLandedState, MavMissionResult, MavProtocolCapability, MavSysStatusSensor,
    MavSysStatusSensorExtended, MavVtolState, SYS_STATUS_DATA,
};
use dflat_link::quaternion_from_euler;

/// PX4 main mode AUTO (custom_mode bits 16–23).
pub const PX4_MAIN_AUTO: u32 = 4;
/// PX4 AUTO sub mode TAKEOFF (custom_mode bits 24–31).
pub const PX4_AUTO_TAKEOFF: u32 = 2;
/// PX4 AUTO sub mode LOITER (hold).
pub const PX4_AUTO_LOITER: u32 = 3;
/// PX4 AUTO sub mode MISSION.
pub const PX4_AUTO_MISSION: u32 = 4;
/// PX4 AUTO sub mode RTL.
pub const PX4_AUTO_RTL: u32 = 5;
/// PX4 AUTO sub mode LAND.
pub const PX4_AUTO_LAND: u32 = 6;

/// PX4's `custom_mode` of AUTO with sub mode `sub`.
pub const fn px4_auto(sub: u32) -> u32 {
    (PX4_MAIN_AUTO << 16) | (sub << 24)
}

/// The version the SITL reports: PX4's encoding (major, minor, patch,
/// type 255 = official), 1.15.0.
pub const FLIGHT_SW_VERSION: u32 = (1 << 24) | (15 << 16) | 255;

/// Mean Earth radius of the flat-earth map \[m\].
const EARTH_RADIUS: f64 = 6_371_000.0;

/// The geodetic origin of the local NED frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoOrigin {
    /// Latitude \[deg\].
    pub lat_deg: f64,
    /// Longitude \[deg\].
    pub lon_deg: f64,
    /// Altitude AMSL \[m\].
    pub alt_m: f64,
}

impl GeoOrigin {
    /// PX4 SITL's default origin (Zürich, 488 m AMSL).
    pub const PX4_SITL: Self = Self {
        lat_deg: 47.397_742,
        lon_deg: 8.545_594,
        alt_m: 488.0,
    };

    /// Local NED `p` \[m\] → (lat \[deg\], lon \[deg\], alt AMSL \[m\]).
    pub fn global(&self, p: [f64; 3]) -> (f64, f64, f64) {
        let lat = self.lat_deg + (p[0] / EARTH_RADIUS).to_degrees();
        let lon =
            self.lon_deg + (p[1] / (EARTH_RADIUS * self.lat_deg.to_radians().cos())).to_degrees();
        (lat, lon, self.alt_m - p[2])
    }

    /// (lat, lon \[deg\], alt AMSL \[m\]) → local NED \[m\] (the inverse of
    /// [`global`](Self::global)); `None` when not finite.
    pub fn local(&self, lat: f64, lon: f64, alt: f64) -> Option<[f64; 3]> {
        let p = [
            (lat - self.lat_deg).to_radians() * EARTH_RADIUS,
            (lon - self.lon_deg).to_radians() * EARTH_RADIUS * self.lat_deg.to_radians().cos(),
            self.alt_m - alt,
        ];
        p.iter().all(|x| x.is_finite()).then_some(p)
    }
}

/// HOME_POSITION: `home` (local NED \[m\]) with its geodetic position.
pub fn home_position(origin: &GeoOrigin, home: [f64; 3], time_usec: u64) -> MavMessage {
    let (lat, lon, alt) = origin.global(home);
    MavMessage::HOME_POSITION(HOME_POSITION_DATA {
        latitude: (lat * 1e7).round() as i32,
        longitude: (lon * 1e7).round() as i32,
        altitude: (alt * 1000.0).round() as i32,
        x: home[0] as f32,
        y: home[1] as f32,
        z: home[2] as f32,
        q: [1.0, 0.0, 0.0, 0.0],
        approach_x: 0.0,
        approach_y: 0.0,
        approach_z: 0.0,
        time_usec,
    })
}

/// EXTENDED_SYS_STATE of a multicopter (no VTOL) in `landed` state.
pub fn extended_sys_state(landed: MavLandedState) -> MavMessage {
    MavMessage::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
        vtol_state: MavVtolState::MAV_VTOL_STATE_UNDEFINED,
        landed_state: landed,
    })
}

/// ATTITUDE_QUATERNION of ZYX `euler` \[rad\] and body `rates` \[rad/s\].
pub fn attitude_quaternion(time_boot_ms: u32, euler: [f64; 3], rates: [f64; 3]) -> MavMessage {
    let q = quaternion_from_euler(euler[0], euler[1], euler[2]);
    MavMessage::ATTITUDE_QUATERNION(ATTITUDE_QUATERNION_DATA {
        time_boot_ms,
        q1: q[0] as f32,
        q2: q[1] as f32,
        q3: q[2] as f32,
        q4: q[3] as f32,
        rollspeed: rates[0] as f32,
        pitchspeed: rates[1] as f32,
        yawspeed: rates[2] as f32,
        repr_offset_q: [0.0; 4],
    })
}

/// GLOBAL_POSITION_INT of local `p`, `v` (NED) at heading `yaw` \[rad\];
/// relative altitude above `home`.
pub fn global_position_int(
    origin: &GeoOrigin,
    home: [f64; 3],
    time_boot_ms: u32,
    p: [f64; 3],
    v: [f64; 3],
    yaw: f64,
) -> MavMessage {
    let (lat, lon, alt) = origin.global(p);
    let cm = |x: f64| (x * 100.0).round().clamp(-32767.0, 32767.0) as i16;
    let hdg = yaw.to_degrees().rem_euclid(360.0);
    MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
        time_boot_ms,
        lat: (lat * 1e7).round() as i32,
        lon: (lon * 1e7).round() as i32,
        alt: (alt * 1000.0).round() as i32,
        relative_alt: ((home[2] - p[2]) * 1000.0).round() as i32,
        vx: cm(v[0]),
        vy: cm(v[1]),
        vz: cm(v[2]),
        hdg: ((hdg * 100.0).round() as u16) % 36000,
    })
}

/// BATTERY_STATUS of a battery the SITL does not model: every value
/// "unknown" as the spec writes it (voltages UINT16_MAX, current −1,
/// remaining −1, consumed −1, temperature INT16_MAX, time 0), no fault.
pub fn battery_status() -> MavMessage {
    MavMessage::BATTERY_STATUS(BATTERY_STATUS_DATA {
        current_consumed: -1,
        energy_consumed: -1,
        temperature: i16::MAX,
        voltages: [u16::MAX; 10],
        current_battery: -1,
        id: 0,
        battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_UNKNOWN,
        mavtype: MavBatteryType::MAV_BATTERY_TYPE_UNKNOWN,
        battery_remaining: -1,
        time_remaining: 0,
        charge_state: MavBatteryChargeState::MAV_BATTERY_CHARGE_STATE_UNDEFINED,
        voltages_ext: [0; 4],
        mode: MavBatteryMode::MAV_BATTERY_MODE_UNKNOWN,
        fault_bitmask: MavBatteryFault::empty(),
    })
}

/// SYS_STATUS: what the stand-in has — gyro, accelerometer, rate and
/// attitude control, altitude and position control, motor outputs —
/// present, enabled and healthy, and the pre-arm check passed (health bit
/// of MAV_SYS_STATUS_PREARM_CHECK); no battery sensor (voltage UINT16_MAX,
/// current −1, remaining −1: unknown), no extended sensors (no parachute).
pub fn sys_status() -> MavMessage {
    let sensors = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS;
    let prearm = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
    MavMessage::SYS_STATUS(SYS_STATUS_DATA {
        onboard_control_sensors_present: sensors | prearm,
        onboard_control_sensors_enabled: sensors | prearm,
        onboard_control_sensors_health: sensors | prearm,
        load: 0,
        voltage_battery: u16::MAX,
        current_battery: -1,
        drop_rate_comm: 0,
        errors_comm: 0,
        errors_count1: 0,
        errors_count2: 0,
        errors_count3: 0,
        errors_count4: 0,
        battery_remaining: -1,
        onboard_control_sensors_present_extended: MavSysStatusSensorExtended::empty(),
        onboard_control_sensors_enabled_extended: MavSysStatusSensorExtended::empty(),
        onboard_control_sensors_health_extended: MavSysStatusSensorExtended::empty(),
    })
}

/// AUTOPILOT_VERSION: [`FLIGHT_SW_VERSION`], a uid from the system id
/// (`0xDF1A_7000_0000_00ss`, also in `uid2`), and the capabilities the
/// SITL implements: MAVLink 2, COMMAND_INT, PARAM_FLOAT, MISSION_INT (the
/// protocol is answered, see the module docs), SET_ATTITUDE_TARGET,
/// SET_POSITION_TARGET_LOCAL_NED, and the parameter encoding `encoding`.
// PARAM_FLOAT is deprecated in favour of the encoding bits (also set); it
// is still read by ground stations and SDKs, so it is advertised too.
#[allow(deprecated)]
pub fn autopilot_version(system_id: u8, encoding: MavProtocolCapability) -> MavMessage {
    let uid = 0xDF1A_7000_0000_0000u64 | u64::from(system_id);
    let mut uid2 = [0u8; 18];
    uid2[..8].copy_from_slice(&uid.to_be_bytes());
    MavMessage::AUTOPILOT_VERSION(AUTOPILOT_VERSION_DATA {
        capabilities: MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
            | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | encoding,
        uid,
        flight_sw_version: FLIGHT_SW_VERSION,
        middleware_sw_version: FLIGHT_SW_VERSION,
        os_sw_version: 0,
        board_version: 0,
        vendor_id: 0,
        product_id: 0,
        flight_custom_version: *b"dflatsim",
        middleware_custom_version: [0; 8],
        os_custom_version: [0; 8],
        uid2,
    })
}

/// The SITL's answer to a mission-protocol message addressed to it from
/// `sender` (`None`: not a mission request): uploads UNSUPPORTED, a
/// download an empty list, MISSION_CLEAR_ALL ACCEPTED.
pub fn mission_answer(msg: &MavMessage, sender: (u8, u8)) -> Option<MavMessage> {
    let ack = |result, mission_type| {
        MavMessage::MISSION_ACK(MISSION_ACK_DATA {
            target_system: sender.0,
            target_component: sender.1,
            mavtype: result,
            mission_type,
            opaque_id: 0,
        })
    };
    Some(match msg {
        MavMessage::MISSION_COUNT(d) => {
            ack(MavMissionResult::MAV_MISSION_UNSUPPORTED, d.mission_type)
        }
        MavMessage::MISSION_ITEM_INT(d) => {
            ack(MavMissionResult::MAV_MISSION_UNSUPPORTED, d.mission_type)
        }
        MavMessage::MISSION_CLEAR_ALL(d) => {
            ack(MavMissionResult::MAV_MISSION_ACCEPTED, d.mission_type)
        }
        MavMessage::MISSION_REQUEST_LIST(d) => MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: 0,
            target_system: sender.0,
            target_component: sender.1,
            mission_type: d.mission_type,
            opaque_id: 0,
        }),
        _ => return None,
    })
}

/// A stream the SITL sends besides its pose telemetry, with the interval
/// MAV_CMD_SET_MESSAGE_INTERVAL may change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stream {
    /// ATTITUDE_QUATERNION (31), default 10 Hz.
    AttitudeQuaternion,
    /// GLOBAL_POSITION_INT (33), default 10 Hz.
    GlobalPosition,
    /// BATTERY_STATUS (147), default 0.5 Hz.
    Battery,
    /// HOME_POSITION (242), default 0.5 Hz (and on change, on request).
    Home,
    /// EXTENDED_SYS_STATE (245), default 1 Hz.
    ExtendedSysState,
}

impl Stream {
    /// Every stream.
    pub const ALL: [Stream; 5] = [
        Stream::AttitudeQuaternion,
        Stream::GlobalPosition,
        Stream::Battery,
        Stream::Home,
        Stream::ExtendedSysState,
    ];

    /// The MAVLink message id.
    pub fn id(self) -> u32 {
        match self {
            Stream::AttitudeQuaternion => 31,
            Stream::GlobalPosition => 33,
            Stream::Battery => 147,
            Stream::Home => 242,
            Stream::ExtendedSysState => 245,
        }
    }

    /// The stream of message `id`.
    pub fn from_id(id: u32) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.id() == id)
    }

    /// The default interval \[s\].
    pub fn default_interval(self) -> f64 {
        match self {
            Stream::ExtendedSysState => 1.0,
            Stream::AttitudeQuaternion | Stream::GlobalPosition => 0.1,
            Stream::Battery | Stream::Home => 2.0,
        }
    }
}

/// Message ids the SITL sends at 1 Hz, whose interval it does not change.
pub const FIXED_STREAMS: [(u32, &str); 2] = [(0, "HEARTBEAT"), (1, "SYS_STATUS")];

/// The intervals of ATTITUDE (30) and LOCAL_POSITION_NED (32), the
/// messages the daemon flies on, in plant steps: `sitl.telemetry_rate_hz`
/// at start, then what MAV_CMD_SET_MESSAGE_INTERVAL sets (as PX4 and
/// ArduPilot do, from the vehicle link: the SITL sends them at one rate
/// on both links, where PX4 keeps one per link, so the ground station's
/// requests are refused), or refused with `sitl.fixed_telemetry_rate` (an
/// autopilot whose own settings alone set them). Pure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TelemetryRates {
    /// Plant steps per message at `sitl.telemetry_rate_hz`.
    pub default_every: u64,
    /// ATTITUDE's plant steps per message (`None`: stopped).
    pub attitude_every: Option<u64>,
    /// LOCAL_POSITION_NED's plant steps per message (`None`: stopped).
    pub position_every: Option<u64>,
    /// `sitl.fixed_telemetry_rate`: requests refused.
    pub fixed: bool,
}

impl TelemetryRates {
    /// Both at `default_every` plant steps.
    pub fn new(default_every: u64, fixed: bool) -> Self {
        Self {
            default_every,
            attitude_every: Some(default_every),
            position_every: Some(default_every),
            fixed,
        }
    }

    /// The name of message `id` when it is one of these two.
    fn name(id: u32) -> Option<&'static str> {
        match id {
            30 => Some("ATTITUDE"),
            32 => Some("LOCAL_POSITION_NED"),
            _ => None,
        }
    }

    /// The interval slot of message `id` when it is one of these two.
    fn slot(&mut self, id: u32) -> Option<&mut Option<u64>> {
        match id {
            30 => Some(&mut self.attitude_every),
            32 => Some(&mut self.position_every),
            _ => None,
        }
    }

    /// MAV_CMD_SET_MESSAGE_INTERVAL for message `id` (`None`: not one of
    /// these two) at plant step `dt` \[s\]: `interval_us` −1 stops it, 0
    /// restores `sitl.telemetry_rate_hz`, > 0 sets it (rounded to whole
    /// plant steps, at least one). `Err`: the refusal in words.
    pub fn set(&mut self, id: u32, interval_us: f32, dt: f64) -> Option<Result<(), String>> {
        let name = Self::name(id)?;
        if self.fixed {
            return Some(Err(format!("SITL: {name} rate fixed by config")));
        }
        let every = if interval_us == -1.0 {
            None
        } else if interval_us == 0.0 {
            Some(self.default_every)
        } else if interval_us.is_finite() && interval_us > 0.0 {
            Some(((f64::from(interval_us) * 1e-6 / dt).round() as u64).max(1))
        } else {
            return Some(Err(format!("SITL: interval {interval_us} us refused")));
        };
        *self.slot(id)? = every;
        Some(Ok(()))
    }

    /// A request for message `id` from the ground-station link (`None`:
    /// not one of these two): refused, their rate is the vehicle link's.
    pub fn refuse_on_gcs(&self, id: u32) -> Option<Result<(), String>> {
        let name = Self::name(id)?;
        Some(Err(format!("SITL: {name} rate set on the vehicle link")))
    }

    /// The interval of message `id` \[µs\] at plant step `dt` (−1 stopped;
    /// `None`: not one of these two).
    pub fn interval_us(&self, id: u32, dt: f64) -> Option<i32> {
        let every = match id {
            30 => self.attitude_every,
            32 => self.position_every,
            _ => return None,
        };
        Some(every.map_or(-1, |e| (e as f64 * dt * 1e6).round() as i32))
    }
}

/// The intervals of the [`Stream`]s and when each is next due (pure: time
/// in seconds enters as an argument).
#[derive(Debug, Clone, PartialEq)]
pub struct Streams {
    /// (stream, interval \[s\] or `None` = off, next due \[s\]).
    entries: Vec<(Stream, Option<f64>, f64)>,
}

impl Default for Streams {
    fn default() -> Self {
        Self {
            entries: Stream::ALL
                .into_iter()
                .map(|s| (s, Some(s.default_interval()), 0.0))
                .collect(),
        }
    }
}

impl Streams {
    /// MAV_CMD_SET_MESSAGE_INTERVAL for message `id`: `interval_us` −1
    /// stops it, 0 restores the default, > 0 sets it (at least 1 ms).
    /// `Err`: the refusal in words.
    pub fn set(&mut self, id: u32, interval_us: f32, now: f64) -> Result<(), String> {
        if let Some((_, name)) = FIXED_STREAMS.iter().find(|(i, _)| *i == id) {
            return Err(format!("SITL: {name} rate fixed"));
        }
        let Some(stream) = Stream::from_id(id) else {
            return Err(format!("SITL: message {id} not streamed"));
        };
        let interval = if interval_us == -1.0 {
            None
        } else if interval_us == 0.0 {
            Some(stream.default_interval())
        } else if interval_us.is_finite() && interval_us > 0.0 {
            Some((f64::from(interval_us) * 1e-6).max(1e-3))
        } else {
            return Err(format!("SITL: interval {interval_us} us refused"));
        };
        if let Some(e) = self.entries.iter_mut().find(|e| e.0 == stream) {
            e.1 = interval;
            e.2 = now;
        }
        Ok(())
    }

    /// The interval of message `id` \[µs\] as MESSAGE_INTERVAL reports it
    /// (−1 off, 0 not sent by the SITL).
    pub fn interval_us(&self, id: u32) -> i32 {
        match self.entries.iter().find(|e| e.0.id() == id) {
            Some((_, Some(i), _)) => (i * 1e6).round() as i32,
            Some((_, None, _)) => -1,
            None => 0,
        }
    }

    /// The streams due at `now` \[s\] (each at most once per call; a late
    /// call does not bunch them).
    pub fn due(&mut self, now: f64) -> Vec<Stream> {
        let mut out = Vec::new();
        for (s, interval, next) in &mut self.entries {
            if let Some(i) = interval
                && now + 1e-9 >= *next
            {
                out.push(*s);
                *next = (*next + *i).max(now);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_geodetic_map_round_trips_and_points_north_east_down() {
        let o = GeoOrigin::PX4_SITL;
        let (lat, lon, alt) = o.global([100.0, -50.0, -10.0]);
        assert!(lat > o.lat_deg && lon < o.lon_deg && (alt - 498.0).abs() < 1e-9);
        let p = o.local(lat, lon, alt).unwrap();
        for (a, b) in p.iter().zip([100.0, -50.0, -10.0]) {
            assert!((a - b).abs() < 1e-6, "{p:?}");
        }
        assert!(o.local(f64::NAN, 0.0, 0.0).is_none());
    }

    #[test]
    fn home_is_the_start_point() {
        let o = GeoOrigin::PX4_SITL;
        let MavMessage::HOME_POSITION(h) = home_position(&o, [0.0, 0.0, -1.5], 7) else {
            panic!()
        };
        assert_eq!((h.x, h.y, h.z), (0.0, 0.0, -1.5));
        assert_eq!(h.latitude, 473_977_420);
        assert_eq!(h.altitude, 489_500);
    }

    #[test]
    fn unknown_battery_and_honest_status_bits() {
        let MavMessage::SYS_STATUS(s) = sys_status() else {
            panic!()
        };
        assert_eq!(
            (s.voltage_battery, s.current_battery, s.battery_remaining),
            (u16::MAX, -1, -1)
        );
        assert!(
            s.onboard_control_sensors_present_extended.is_empty(),
            "no parachute"
        );
        assert!(
            s.onboard_control_sensors_health
                .contains(MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK)
        );
        assert!(
            !s.onboard_control_sensors_present
                .contains(MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY)
        );
        let MavMessage::BATTERY_STATUS(b) = battery_status() else {
            panic!()
        };
        assert_eq!(
            (b.voltages[0], b.current_battery, b.battery_remaining),
            (u16::MAX, -1, -1)
        );
        assert!(b.fault_bitmask.is_empty());
    }

    #[test]
    #[allow(deprecated)] // PARAM_FLOAT, asked for by MAVSDK's param plugin
    fn the_version_advertises_what_is_implemented() {
        let MavMessage::AUTOPILOT_VERSION(v) = autopilot_version(
            1,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE,
        ) else {
            panic!()
        };
        assert_ne!(v.uid, 0);
        assert_eq!(v.flight_sw_version >> 24, 1);
        for c in [
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MISSION_INT,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
            MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED,
        ] {
            assert!(v.capabilities.contains(c), "{c:?}");
        }
        assert!(
            !v.capabilities
                .contains(MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_FTP)
        );
    }

    #[test]
    fn missions_are_answered_so_no_client_times_out() {
        use dflat_link::dialect::{MISSION_CLEAR_ALL_DATA, MISSION_REQUEST_LIST_DATA};
        let count = MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
            count: 3,
            target_system: 1,
            target_component: 1,
            ..Default::default()
        });
        match mission_answer(&count, (245, 190)) {
            Some(MavMessage::MISSION_ACK(a)) => {
                assert_eq!(a.mavtype, MavMissionResult::MAV_MISSION_UNSUPPORTED);
                assert_eq!((a.target_system, a.target_component), (245, 190));
            }
            other => panic!("{other:?}"),
        }
        let clear = MavMessage::MISSION_CLEAR_ALL(MISSION_CLEAR_ALL_DATA {
            target_system: 1,
            target_component: 1,
            ..Default::default()
        });
        assert!(matches!(
            mission_answer(&clear, (245, 190)),
            Some(MavMessage::MISSION_ACK(a)) if a.mavtype == MavMissionResult::MAV_MISSION_ACCEPTED
        ));
        let list = MavMessage::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
            target_system: 1,
            target_component: 1,
            ..Default::default()
        });
        assert!(matches!(
            mission_answer(&list, (245, 190)),
            Some(MavMessage::MISSION_COUNT(c)) if c.count == 0
        ));
        assert!(mission_answer(&sys_status(), (245, 190)).is_none());
    }

    #[test]
    fn message_intervals_are_set_restored_and_refused_in_words() {
        let mut s = Streams::default();
        assert_eq!(s.due(0.0).len(), Stream::ALL.len(), "all due at start");
        assert!(s.due(0.05).is_empty());
        assert_eq!(
            s.due(0.1),
            vec![Stream::AttitudeQuaternion, Stream::GlobalPosition]
        );
        s.set(31, 20_000.0, 0.2).unwrap();
        assert_eq!(s.interval_us(31), 20_000);
        let mut n = 0;
        for k in 0..50 {
            n += s
                .due(0.2 + f64::from(k) * 0.02)
                .iter()
                .filter(|x| **x == Stream::AttitudeQuaternion)
                .count();
        }
        assert_eq!(n, 50, "50 Hz for one second");
        s.set(31, -1.0, 1.2).unwrap();
        assert_eq!(s.interval_us(31), -1);
        assert!(!s.due(5.0).contains(&Stream::AttitudeQuaternion));
        s.set(31, 0.0, 5.0).unwrap();
        assert_eq!(s.interval_us(31), 100_000);
        assert!(s.set(0, 1000.0, 0.0).unwrap_err().contains("HEARTBEAT"));
        assert!(s.set(77, 1000.0, 0.0).unwrap_err().contains("77"));
        assert!(s.set(31, f32::NAN, 0.0).is_err());
        assert_eq!(s.interval_us(77), 0);
    }

    /// ATTITUDE and LOCAL_POSITION_NED: set in whole plant steps, stopped,
    /// restored to `sitl.telemetry_rate_hz`, refused when fixed; other ids
    /// are not theirs.
    #[test]
    fn the_daemons_messages_take_their_interval_unless_fixed() {
        let dt = 1.0 / 200.0;
        let mut r = TelemetryRates::new(40, false);
        assert_eq!(r.interval_us(32, dt), Some(200_000));
        assert_eq!(r.set(32, 20_000.0, dt), Some(Ok(())));
        assert_eq!(r.position_every, Some(4));
        assert_eq!(r.interval_us(32, dt), Some(20_000));
        assert_eq!(r.attitude_every, Some(40), "the other one unchanged");
        assert_eq!(r.set(30, 1.0, dt), Some(Ok(())));
        assert_eq!(r.attitude_every, Some(1), "at least one step");
        assert_eq!(r.set(30, -1.0, dt), Some(Ok(())));
        assert_eq!(r.interval_us(30, dt), Some(-1));
        assert_eq!(r.set(30, 0.0, dt), Some(Ok(())));
        assert_eq!(r.attitude_every, Some(40));
        assert!(r.set(32, f32::NAN, dt).unwrap().is_err());
        assert_eq!(r.set(31, 1000.0, dt), None);
        assert_eq!(r.interval_us(31, dt), None);
        let mut fixed = TelemetryRates::new(40, true);
        let refused = fixed.set(32, 20_000.0, dt).unwrap().unwrap_err();
        assert_eq!(refused, "SITL: LOCAL_POSITION_NED rate fixed by config");
        assert_eq!(fixed.position_every, Some(40));
        assert!(r.refuse_on_gcs(30).unwrap().is_err());
        assert_eq!(r.refuse_on_gcs(31), None);
    }
}
