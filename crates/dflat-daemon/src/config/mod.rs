//! The daemon's TOML configuration: schema, defaults, validation.
//!
//! Every field has a default (the values of `config/default.toml`), unknown
//! fields are rejected, and [`Config::validate`] checks every range. Errors
//! name the file, the field (dotted path) and the allowed range. Angles are
//! in degrees in the file (fields end in `_deg`) and radians in code.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

mod stream;
pub use stream::{StreamConfig, TimeBase};
use thiserror::Error;

/// A configuration that could not be read or is out of range.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML did not parse or a field has the wrong type or name.
    #[error("{file}: {message}")]
    Parse {
        /// The file.
        file: PathBuf,
        /// The parser's message (names the field and the line).
        message: String,
    },
    /// The file uses keys of the flat `[controller]` table that moved to
    /// its sub-tables ([`migrate::MOVES`]).
    #[error(
        "{file}: {} (`dflat check-config --migrate {}` prints the file migrated)",
        .moved.iter().map(ToString::to_string).collect::<Vec<_>>().join("; "),
        .file.display()
    )]
    Moved {
        /// The file.
        file: PathBuf,
        /// Each old key and its new place.
        moved: Vec<migrate::MovedKey>,
    },
    /// A field is out of its allowed range.
    #[error("{file}: field `{field}` = {value}: allowed {allowed}")]
    Range {
        /// The file.
        file: PathBuf,
        /// Dotted path of the field.
        field: String,
        /// The value found.
        value: String,
        /// The allowed range, in words.
        allowed: String,
    },
}

/// The whole configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// MAVLink connection and ids.
    pub link: LinkConfig,
    /// The vehicle model the controller uses.
    pub vehicle: VehicleConfig,
    /// Controller choice and tuning.
    pub controller: ControllerConfig,
    /// What to fly: hold, a path, setpoints.
    pub mission: MissionConfig,
    /// Timeouts and failsafe behaviour.
    pub safety: SafetyConfig,
    /// Logs and flight records.
    pub logging: LoggingConfig,
    /// Real-time scheduling of the control thread (all off by default).
    pub realtime: crate::realtime::RealtimeConfig,
    /// Crash safety and disk quotas of the flight records.
    pub records: RecordsConfig,
    /// The SITL autopilot stand-in's `[sitl]` table, kept unparsed: the
    /// daemon does not read it (the SITL lives in `dflat-sitl`, which parses
    /// and validates it for `dflat sitl`, `dflat demo` and `dflat
    /// check-config`), so one file can configure both.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sitl: Option<toml::Table>,
    /// Streamed trajectories and setpoint routes (`[stream]`).
    pub stream: StreamConfig,
}

/// Which MAVLink message carries the pose the controller uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PoseSourceKind {
    /// LOCAL_POSITION_NED (#32); yaw from ATTITUDE (#30).
    #[default]
    LocalPositionNed,
    /// ODOMETRY (#331).
    Odometry,
    /// VISION_POSITION_ESTIMATE (#102).
    VisionPositionEstimate,
}

/// `[link]`: MAVLink connection and ids.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LinkConfig {
    /// Connection string of the mavlink crate: `udpout:HOST:PORT`,
    /// `udpin:HOST:PORT`, `tcpout:HOST:PORT`, `serial:/dev/ttyTHS2:921600`.
    pub url: String,
    /// The vehicle's MAVLink system id (1–255).
    pub system_id: u8,
    /// The autopilot's component id (1–255; 1 = MAV_COMP_ID_AUTOPILOT1).
    pub autopilot_component: u8,
    /// This daemon's component id (1–255; 191 = MAV_COMP_ID_ONBOARD_COMPUTER).
    pub component_id: u8,
    /// Deprecated: one ground station's system id (1–255). Still read: when
    /// set, it stands for `gcs_system_ids = [id]` (a note is logged at
    /// start). Use `gcs_system_ids`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gcs_system_id: Option<u8>,
    /// The pose message used by the controller.
    pub pose_source: PoseSourceKind,
    /// Also accept SET_POSITION_TARGET_LOCAL_NED from the vehicle's own
    /// components (system `system_id`, any component but this daemon's),
    /// besides the ground station.
    pub vehicle_setpoints: bool,
    /// Components of the own vehicle, besides the autopilot, whose ODOMETRY /
    /// VISION_POSITION_ESTIMATE are accepted as pose (e.g. `[197]` for a
    /// visual-odometry component; each 1–255).
    pub pose_components: Vec<u8>,
    /// Which time stamps a pose: `source` (its own timestamp —
    /// LOCAL_POSITION_NED `time_boot_ms`, ODOMETRY / VISION_POSITION_ESTIMATE
    /// `time_usec` — mapped to this computer's clock, see
    /// [`crate::clock::PoseClock`]) or `arrival` (the receive time). A pose
    /// whose timestamp is 0 falls back to its arrival time.
    pub pose_time: PoseTime,
    /// Sliding window of the clock-offset estimate \[s\] (1–600): the offset
    /// is the minimum of `arrival − source time` over this window.
    pub pose_clock_window_s: f64,
    /// Known minimum latency of the pose source \[ms\] (0–1000): the offset
    /// minimum is taken to be this latency, not zero (e.g. a vision
    /// pipeline's fixed exposure-to-message delay). 0 assumes the fastest
    /// message travels without delay.
    pub pose_min_latency_ms: f64,
    /// MAVLink 2 signing key file; empty = signing off. Refused at start
    /// unless mode 0600 and owned by the running user. Contents: 64 hex
    /// digits, 32 raw bytes, or a passphrase (key = SHA-256(passphrase), as
    /// MAVProxy's `signing setup`). See [`crate::signing`].
    pub signing_key_file: String,
    /// Link id in our signatures (0–255).
    pub signing_link_id: u8,
    /// File holding the last signing timestamp (required with a key file).
    pub signing_timestamp_file: String,
    /// How the autopilot's HEARTBEAT `custom_mode` is read: `auto` (from
    /// its `autopilot` field: MAV_AUTOPILOT_PX4 or _ARDUPILOTMEGA), `px4`
    /// or `ardupilot` (override, for a bridge that reports another type).
    pub autopilot: AutopilotKind,
    /// When the autopilot applies our commands: `mode` (engaged only while
    /// its HEARTBEAT says armed and PX4 OFFBOARD / ArduPilot GUIDED_NOGPS
    /// or GUIDED; standby otherwise) or `always` (every streamed command is
    /// taken as applied — for an autopilot whose modes dflat cannot read;
    /// no standby, no bumpless engagement).
    pub engagement: Engagement,
    /// With signing on, the messages (common-dialect names, e.g.
    /// `"SYS_STATUS"`) still accepted *unsigned* from trusted senders.
    /// Default empty: everything must be signed. Messages that move the
    /// vehicle or change the daemon's view of the autopilot (HEARTBEAT,
    /// ATTITUDE, PARAM_VALUE, the pose messages, setpoints, missions,
    /// COMMAND_LONG/INT, SETUP_SIGNING: [`dflat_link::MUST_BE_SIGNED`]) are
    /// refused here. Risk: anyone who can reach the link can forge a listed
    /// message; list only what the daemon does not act on.
    pub signing_accept_unsigned: Vec<String>,
    /// `udpin` only: the peer's address (`HOST:PORT`) the daemon talks to;
    /// frames from any other address are dropped, counted and said once.
    /// Empty (default): lock onto the first address that sends the
    /// configured autopilot's HEARTBEAT (signed, with signing on).
    pub peer: String,
    /// The ground stations' system ids whose setpoints, commands and
    /// missions are acted on (each 1–255, at least one; default `[255,
    /// 245]`: QGroundControl and MAVProxy use 255, MAVSDK 245). A request
    /// from another system is refused in words (STATUSTEXT naming the id
    /// and this key, COMMAND_ACK DENIED) and never flown. The id is not a
    /// security boundary: signing is (docs/safety.md).
    pub gcs_system_ids: Vec<u8>,
    /// Ask the autopilot (MAV_CMD_SET_MESSAGE_INTERVAL, at start-up and
    /// after it was silent) to stream the pose message and ATTITUDE at
    /// `controller.rate_hz`: LOCAL_POSITION_NED, or ODOMETRY when it is the
    /// pose source and no `pose_components` are set (a pose from another
    /// component is not the autopilot's to send). A refusal is said in
    /// words and the autopilot's own rates stand ([`crate::stream_rates`]).
    /// `false`: the autopilot's settings alone set the rates (PX4 `mavlink
    /// stream`, ArduPilot `SRn_POSITION` / `SRn_EXTRA1`).
    pub request_streams: bool,
}

impl LinkConfig {
    /// The ground-station ids in force: `[gcs_system_id]` when the
    /// deprecated key is set, else `gcs_system_ids`.
    pub fn ground_station_ids(&self) -> Vec<u8> {
        match self.gcs_system_id {
            Some(id) => vec![id],
            None => self.gcs_system_ids.clone(),
        }
    }
}

/// `link.autopilot`: how the autopilot's mode is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum AutopilotKind {
    /// From the HEARTBEAT's `autopilot` field.
    #[default]
    Auto,
    /// PX4 (main mode in `custom_mode` bits 16–23).
    Px4,
    /// ArduPilot Copter (mode number in `custom_mode`).
    Ardupilot,
}

/// `link.engagement`: when streamed commands count as applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Engagement {
    /// From the autopilot's HEARTBEAT: armed and in its offboard mode.
    #[default]
    Mode,
    /// Always (no mode is read).
    Always,
}

/// How a pose's capture time is obtained (`link.pose_time`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PoseTime {
    /// The pose message's own timestamp mapped to this computer's clock.
    #[default]
    Source,
    /// The arrival time on this computer (latency not compensated).
    Arrival,
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            url: "udpout:127.0.0.1:14540".into(),
            system_id: 1,
            autopilot_component: 1,
            component_id: 191,
            gcs_system_id: None,
            pose_source: PoseSourceKind::LocalPositionNed,
            vehicle_setpoints: true,
            pose_components: Vec::new(),
            pose_time: PoseTime::Source,
            pose_clock_window_s: 10.0,
            pose_min_latency_ms: 0.0,
            signing_key_file: String::new(),
            signing_link_id: 0,
            signing_timestamp_file: "/var/lib/dflat/signing_timestamp".into(),
            autopilot: AutopilotKind::Auto,
            engagement: Engagement::Mode,
            signing_accept_unsigned: Vec::new(),
            peer: String::new(),
            gcs_system_ids: dflat_link::DEFAULT_GCS_SYSTEM_IDS.to_vec(),
            request_streams: true,
        }
    }
}

/// The controller's model of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// x, y with first-order attitude; the autopilot holds altitude.
    #[default]
    Planar,
    /// x, y, z with first-order attitude and collective thrust.
    Spatial,
}

/// How the thrust field of SET_ATTITUDE_TARGET is filled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ThrustMode {
    /// A fixed value (`thrust_value`): the autopilot holds altitude; for
    /// ArduPilot GUIDED_NOGPS 0.5 means "climb rate 0".
    #[default]
    Fixed,
    /// Collective thrust normalised so that hover = `hover_thrust`
    /// (spatial model; PX4 offboard attitude).
    Normalized,
}

/// The normalised hover thrusts dflat flies: `vehicle.hover_thrust`'s range
/// and the autopilot's value with `hover_thrust_from_autopilot`.
pub const HOVER_THRUST_RANGE: (f64, f64) = (0.05, 0.95);

/// `[vehicle]`: the model the controller uses.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleConfig {
    /// `planar` or `spatial`.
    pub model: ModelKind,
    /// Attitude time constant τ \[s\] of the autopilot's attitude loop (0.02–2).
    pub tau: f64,
    /// Attitude gain k̃ [-] (0.2–5).
    pub k: f64,
    /// Thrust time constant τ_T \[s\] (spatial model; 0.005–1).
    pub tau_thrust: f64,
    /// Gravity [m/s²] (9–10.5).
    pub gravity: f64,
    /// Fixed yaw ψ⋆ \[deg\] (−180–180).
    pub yaw_deg: f64,
    /// Maximum commanded tilt (angle of body z from the vertical) \[deg\]
    /// (1–60); the controllers and the exit guard scale pitch and roll
    /// together to respect it.
    pub max_tilt_deg: f64,
    /// `fixed` or `normalized`.
    pub thrust_mode: ThrustMode,
    /// The fixed thrust value sent in `fixed` mode (0–1).
    pub thrust_value: f64,
    /// Normalised thrust that hovers, for `normalized` mode (0.05–0.95).
    pub hover_thrust: f64,
    /// `normalized` mode: fly the autopilot's own hover thrust
    /// (`MPC_THR_HOVER`, `MOT_THST_HOVER`, read at start) instead of
    /// `hover_thrust` once it answers before the first engagement (0.05–0.95
    /// only; `hover_thrust` stands until then, and if it never answers).
    /// Default false: `hover_thrust` is flown and a difference is said.
    pub hover_thrust_from_autopilot: bool,
    /// `flown` (default): the yaw of setpoints and mission items is flown,
    /// at most `max_yaw_rate_deg_s`, and the vehicle keeps its heading
    /// otherwise; `fixed`: every command carries `yaw_deg` and a
    /// setpoint's yaw is ignored (said once).
    pub yaw_mode: YawMode,
    /// Largest commanded yaw rate \[deg/s\] (5–360).
    pub max_yaw_rate_deg_s: f64,
    /// How far ahead \[s\] a stream's heading is commanded (0–1, default
    /// 0.1): the autopilot's yaw loop lags its command by about its time
    /// constant, so commanding the trajectory's heading that much later
    /// feeds its rate forward (`ψ(t + T) ≈ ψ + ψ̇·T`; docs/controllers.md,
    /// "Yaw from the trajectory").
    pub yaw_lead_s: f64,
    /// Linear horizontal drag \[1/s\] in the world frame (0–2, default 0):
    /// the model's velocity loses `drag_h·v` of acceleration
    /// (docs/controllers.md, *Drag and delay*). `dflat identify` estimates it.
    pub drag_h: f64,
    /// Linear vertical drag \[1/s\] (spatial model; 0–2, default 0).
    pub drag_v: f64,
    /// Rotor drag \[1/s\] in the body plane (spatial model; 0–2, default
    /// 0): the velocity's part across the thrust axis loses
    /// `drag_rotor·(v − n·(n·v))` of acceleration, which lifts a vehicle
    /// tilted into its motion (docs/controllers.md, *Rotor drag*).
    /// `dflat identify` estimates it from the vertical motion.
    pub drag_rotor: f64,
    /// Pure input delay \[ms\] between a command leaving the daemon and the
    /// autopilot acting on it (0–500, default 0), rounded to control ticks
    /// (said at start). DF-MPC predicts across the commands in flight.
    pub delay_ms: f64,
}

/// `vehicle.yaw_mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum YawMode {
    /// The goals' yaw is flown (rate-limited); the heading is kept otherwise.
    #[default]
    Flown,
    /// Every command carries `vehicle.yaw_deg`.
    Fixed,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            model: ModelKind::Planar,
            tau: 0.2,
            k: 1.0,
            tau_thrust: 0.04,
            gravity: 9.81,
            yaw_deg: 0.0,
            max_tilt_deg: 35.0,
            thrust_mode: ThrustMode::Fixed,
            thrust_value: 0.5,
            hover_thrust: 0.5,
            hover_thrust_from_autopilot: false,
            yaw_mode: YawMode::Flown,
            max_yaw_rate_deg_s: 45.0,
            yaw_lead_s: 0.1,
            drag_h: 0.0,
            drag_v: 0.0,
            drag_rotor: 0.0,
            delay_ms: 0.0,
        }
    }
}

/// What the daemon does once it has pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum MissionStart {
    /// Hold the first measured position until a setpoint arrives.
    #[default]
    Hold,
    /// Fly `path` at `speed` as soon as pose is fresh.
    Path,
}

/// `[mission]`: what to fly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MissionConfig {
    /// `hold` or `path`.
    pub start: MissionStart,
    /// Waypoints, local NED \[m\] (x north, y east, z down), ≥ 2 when used.
    pub path: Vec<[f64; 3]>,
    /// Desired speed along the path [m/s] (0.1–20).
    pub speed: f64,
    /// A SET_POSITION_TARGET_LOCAL_NED whose position equals the first
    /// waypoint within this distance \[m\] starts the path (0 = never).
    pub path_trigger_radius: f64,
    /// The fence around the local origin \[m\]: half-widths in x and y, and
    /// how far above the origin (z ≥ −geofence\[2\]). Goals outside are
    /// refused and every reference is clamped inside ([`crate::envelope`]).
    pub geofence: [f64; 3],
    /// The fence's floor: how far below the local origin \[m\] a goal may
    /// lie (z ≤ this; 0–1000, default 5).
    pub geofence_down_m: f64,
    /// Fly the path again and again (a closed path: its last waypoint must
    /// equal its first) instead of holding its end (soak tests, patrols).
    pub repeat: bool,
    /// What follows an engagement (the pilot switched to OFFBOARD /
    /// GUIDED_NOGPS, or handed back after an override), once the vehicle
    /// has braked to a stop where it was engaged: `resume` (the goal
    /// before: the path from its closest point, the last setpoint) or
    /// `hold` (hold the stop point until a new setpoint). A setpoint
    /// accepted during standby is flown in both cases, and
    /// `mission.start = "path"` starts the path at the first engagement.
    pub on_engage: OnEngage,
    /// Braking deceleration at engagement as a fraction of the plan's tilt
    /// bound (0.1–1): the stop reference coasts for half of `vehicle.tau`
    /// (the attitude builds up) and then decelerates at
    /// `a = brake_fraction · g · tan(controller.constraint_tilt_deg, or
    /// vehicle.max_tilt_deg without one)`, stopping at
    /// `p + v·τ/2 + v·|v| / (2·a)`.
    pub brake_fraction: f64,
    /// Peak acceleration of the path's speed ramp \[m/s²\] (0 = none, or
    /// 0.5–10): a path starts (and resumes) from rest with its reference
    /// speed rising smoothly to `speed`, no step in the reference
    /// acceleration — without it the first tick asks for the tilt limit.
    pub start_acceleration: f64,
    /// Acceptance radius \[m\] of an uploaded waypoint whose param2 is 0,
    /// and of a loiter (0.05–50).
    pub acceptance_radius_m: f64,
    /// MISSION_ITEM_INT's x and y in MAV_FRAME_LOCAL_NED are metres × this
    /// (1e4, the MAVLink specification; 1e7 for MAVProxy's `wp` and
    /// pymavlink's `mavwp`, which scale every frame like latitudes).
    pub local_xy_scale: f64,
}

/// `mission.on_engage`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum OnEngage {
    /// Resume the goal flown before (path from its closest point, setpoint).
    #[default]
    Resume,
    /// Hold where the vehicle stopped until a new setpoint.
    Hold,
}

impl Default for MissionConfig {
    fn default() -> Self {
        Self {
            start: MissionStart::Hold,
            path: vec![
                [-20.0, -30.0, -10.0],
                [0.0, -30.0, -10.0],
                [0.0, 0.0, -10.0],
            ],
            speed: 5.0,
            path_trigger_radius: 0.5,
            geofence: [500.0, 500.0, 200.0],
            geofence_down_m: 5.0,
            repeat: false,
            on_engage: OnEngage::Resume,
            brake_fraction: 1.0,
            start_acceleration: 3.0,
            acceptance_radius_m: 1.0,
            local_xy_scale: 1e4,
        }
    }
}

/// `[safety]`: timeouts and failsafe.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// Pose older than this \[ms\] stops the attitude stream (5–2000).
    pub pose_timeout_ms: f64,
    /// No autopilot HEARTBEAT for this long \[ms\] stops the stream (100–10000).
    pub autopilot_timeout_ms: f64,
    /// The speed limit [m/s] (0.5–100): no goal flies faster (stream
    /// samples above it are refused, `mission.speed` and DO_CHANGE_SPEED
    /// are at most this), and a vehicle measured faster while engaged is
    /// braked to a stop ([`crate::envelope`]).
    pub max_speed_mps: f64,
    /// Noise margin of the pose-jump test \[m\] (0–10): a pose further than
    /// this (plus what the tilt limit's acceleration allows) from where the
    /// previous pose and the measured velocity predict it is a pose jump →
    /// the controller and the reference re-anchor (hold there).
    pub pose_jump_margin_m: f64,
    /// Stopping the daemon (SIGTERM / SIGINT) while engaged: the controller
    /// brakes the vehicle to a stop for at most this long \[ms\] (0–10000;
    /// over sooner once slower than 0.3 m/s), then levels.
    pub stop_brake_ms: f64,
    /// Then a level attitude at hover thrust is streamed for this long
    /// \[ms\] (0–5000) before the stream stops, so the autopilot holds a
    /// level command until its own offboard-loss action. Both 0: the
    /// stream stops at once.
    pub stop_level_ms: f64,
    /// Stopping the daemon while engaged first asks the autopilot for its
    /// own position hold (MAV_CMD_DO_SET_MODE: PX4 AUTO.LOITER, ArduPilot
    /// LOITER), as PX4's and ArduPilot's offboard-loss actions would; the
    /// brake and level are streamed meanwhile and end as soon as the
    /// autopilot leaves its offboard mode.
    pub stop_requests_hold: bool,
    /// After a controller failure or deadline overrun, DF-MPC flies its
    /// previous plan shifted one step per tick, PD and Flatness MPC hold the
    /// last good command, for at most this many ticks (0–50); then level
    /// hover.
    pub hold_last_ticks: u32,
    /// Model-consistency failsafe \[m\] (0 = off; else 0.05–100): when the
    /// measured position is further than this from the position predicted
    /// for the tick (the previous plan's y*_{k+1}) for 5 ticks in a row, the
    /// stream stops (FAILSAFE) for 2 s.
    pub residual_failsafe_m: f64,
    /// When the controller cannot fly (failed or late ticks past the plan
    /// fallback), level hover is streamed for at most this long \[ms\]
    /// (0–10000); then the stream stops (FAILSAFE, "control failed") so
    /// the autopilot's own failsafe takes over, until the controller
    /// solves again on the live poses (tried each tick, not sent).
    pub level_hover_max_ms: f64,
    /// A pose whose capture time (source clock mapped to ours) lies more
    /// than this \[ms\] before its arrival for a second on end means the
    /// source clock runs slow or ever later than ours (a lagging simulator,
    /// a drifting VIO clock): poses are then stamped with their arrival
    /// time instead (logged, STATUSTEXT, counted in the summary).
    /// 10–5000.
    pub pose_max_latency_ms: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            pose_timeout_ms: 100.0,
            autopilot_timeout_ms: 3000.0,
            max_speed_mps: 15.0,
            pose_jump_margin_m: 0.5,
            stop_brake_ms: 1000.0,
            stop_level_ms: 500.0,
            stop_requests_hold: false,
            hold_last_ticks: 5,
            residual_failsafe_m: 0.0,
            level_hover_max_ms: 1000.0,
            pose_max_latency_ms: 500.0,
        }
    }
}

/// `[logging]`: logs and flight records.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoggingConfig {
    /// Directory for the per-flight CSV and .tlog ("" = no records).
    pub dir: String,
    /// Write the per-flight CSV.
    pub csv: bool,
    /// Write all MAVLink traffic to a .tlog.
    pub tlog: bool,
    /// Log format on stderr: `text` or `json`.
    pub format: LogFormat,
}

impl Default for LoggingConfig {
    fn default() -> Self {
        Self {
            dir: "flights".into(),
            csv: true,
            tlog: true,
            format: LogFormat::Text,
        }
    }
}

/// Log output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum LogFormat {
    /// Human-readable lines.
    #[default]
    Text,
    /// One JSON object per line.
    Json,
}

impl Config {
    /// Reads, parses and validates a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            file: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates TOML text; `file` is used in error messages.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ConfigError> {
        // Old keys first: `controller.disturbance = true` would otherwise
        // read as a type error of the new sub-table.
        if let Ok(doc) = toml::from_str::<toml::Table>(text) {
            let moved = migrate::moved_keys(&doc);
            if !moved.is_empty() {
                return Err(ConfigError::Moved {
                    file: file.to_owned(),
                    moved,
                });
            }
        }
        let cfg: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_owned(),
            message: e.to_string().trim_end().to_owned(),
        })?;
        cfg.validate(file)?;
        Ok(cfg)
    }

    /// The effective configuration as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot print: {e}"))
    }
}

mod controller;
mod estimator;
pub mod migrate;
mod records;
mod validate;

pub use controller::{
    ControllerConfig, ControllerKind, DfMpcConfig, DisturbanceConfig, FmpcConfig, PdConfig,
    TickMode,
};
pub use estimator::{EstimatorConfig, StateSourceKind};
pub use records::{MIB, RecordsConfig};

#[cfg(test)]
mod tests;
