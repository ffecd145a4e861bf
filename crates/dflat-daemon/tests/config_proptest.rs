//! Property tests of configuration parsing (`Config::parse`):
//!
//! * arbitrary text — random strings, TOML-shaped lines, and the default file
//!   with one value replaced — never panics: an error that names the file,
//!   or a configuration that validates and round-trips;
//! * valid configurations built from random in-range values round-trip
//!   through `to_toml` → `parse` unchanged;
//! * one field set out of range (below, above, NaN, ±∞) in an otherwise
//!   valid configuration is refused with an error naming that field.

use std::path::Path;

use dflat_daemon::config::{
    Config, ConfigError, ControllerKind, LogFormat, MissionStart, ModelKind, PoseSourceKind,
    PoseTime, ThrustMode,
};
use proptest::prelude::*;

const FILE: &str = "fuzz.toml";

fn parse(text: &str) -> Result<Config, ConfigError> {
    Config::parse(text, Path::new(FILE))
}

/// How a field is stored and checked.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// f64 in [lo, hi].
    Float,
    /// f64 > 0 (`lo`, `hi` only bound the valid values generated).
    Positive,
    /// f64 in [lo, hi] or exactly 0 ("off").
    FloatOrOff,
    /// usize in [lo, hi].
    Usize,
    /// u8 in [1, 255].
    Id,
}

type Set = fn(&mut Config, f64);

/// (dotted name, kind, lo, hi, setter). `hi` is the real upper limit except
/// where marked in [`upper_is_fixed`].
const FIELDS: &[(&str, Kind, f64, f64, Set)] = &[
    ("link.system_id", Kind::Id, 1.0, 255.0, |c, v| {
        c.link.system_id = v as u8
    }),
    ("link.autopilot_component", Kind::Id, 1.0, 255.0, |c, v| {
        c.link.autopilot_component = v as u8
    }),
    ("link.component_id", Kind::Id, 1.0, 255.0, |c, v| {
        c.link.component_id = v as u8
    }),
    // The deprecated one-id `link.gcs_system_id` conflicts with any list
    // the generator draws; its reading and refusal are tested in
    // tests/gcs_ids_config.rs.
    ("link.gcs_system_ids[0]", Kind::Id, 1.0, 255.0, |c, v| {
        c.link.gcs_system_ids[0] = v as u8
    }),
    (
        "link.pose_clock_window_s",
        Kind::Float,
        1.0,
        600.0,
        |c, v| c.link.pose_clock_window_s = v,
    ),
    (
        "link.pose_min_latency_ms",
        Kind::Float,
        0.0,
        1000.0,
        |c, v| c.link.pose_min_latency_ms = v,
    ),
    ("vehicle.tau", Kind::Float, 0.02, 2.0, |c, v| {
        c.vehicle.tau = v
    }),
    ("vehicle.k", Kind::Float, 0.2, 5.0, |c, v| c.vehicle.k = v),
    ("vehicle.tau_thrust", Kind::Float, 0.005, 1.0, |c, v| {
        c.vehicle.tau_thrust = v
    }),
    ("vehicle.gravity", Kind::Float, 9.0, 10.5, |c, v| {
        c.vehicle.gravity = v
    }),
    ("vehicle.yaw_deg", Kind::Float, -180.0, 180.0, |c, v| {
        c.vehicle.yaw_deg = v
    }),
    ("vehicle.max_tilt_deg", Kind::Float, 1.0, 60.0, |c, v| {
        c.vehicle.max_tilt_deg = v
    }),
    ("vehicle.thrust_value", Kind::Float, 0.0, 1.0, |c, v| {
        c.vehicle.thrust_value = v
    }),
    ("vehicle.hover_thrust", Kind::Float, 0.05, 0.95, |c, v| {
        c.vehicle.hover_thrust = v
    }),
    ("controller.rate_hz", Kind::Float, 10.0, 200.0, |c, v| {
        c.controller.rate_hz = v
    }),
    ("controller.pose_wait_ms", Kind::Float, 0.0, 10.0, |c, v| {
        c.controller.pose_wait_ms = v
    }),
    (
        "controller.dfmpc.horizon",
        Kind::Usize,
        10.0,
        2000.0,
        |c, v| c.controller.dfmpc.horizon = v as usize,
    ),
    (
        "controller.fmpc.horizon",
        Kind::Usize,
        10.0,
        2000.0,
        |c, v| c.controller.fmpc.horizon = v as usize,
    ),
    (
        "controller.dfmpc.q[0]",
        Kind::Positive,
        1e-3,
        1e3,
        |c, v| c.controller.dfmpc.q[0] = v,
    ),
    (
        "controller.dfmpc.q[1]",
        Kind::Positive,
        1e-3,
        1e3,
        |c, v| c.controller.dfmpc.q[1] = v,
    ),
    (
        "controller.dfmpc.q[2]",
        Kind::Positive,
        1e-3,
        1e3,
        |c, v| c.controller.dfmpc.q[2] = v,
    ),
    (
        "controller.dfmpc.r_jerk[0]",
        Kind::Positive,
        1e-6,
        10.0,
        |c, v| c.controller.dfmpc.r_jerk[0] = v,
    ),
    (
        "controller.dfmpc.r_jerk[1]",
        Kind::Positive,
        1e-6,
        10.0,
        |c, v| c.controller.dfmpc.r_jerk[1] = v,
    ),
    (
        "controller.dfmpc.r_jerk[2]",
        Kind::Positive,
        1e-6,
        10.0,
        |c, v| c.controller.dfmpc.r_jerk[2] = v,
    ),
    ("controller.fmpc.q[1]", Kind::Positive, 1e-3, 1e3, |c, v| {
        c.controller.fmpc.q[1] = v
    }),
    (
        "controller.pd.corner_radius",
        Kind::Float,
        0.0,
        50.0,
        |c, v| c.controller.pd.corner_radius = v,
    ),
    (
        "controller.pd.corner_acceleration",
        Kind::Float,
        0.1,
        20.0,
        |c, v| c.controller.pd.corner_acceleration = v,
    ),
    (
        "controller.dfmpc.max_tilt_rate_deg_s",
        Kind::FloatOrOff,
        10.0,
        1000.0,
        |c, v| c.controller.dfmpc.max_tilt_rate_deg_s = v,
    ),
    (
        "controller.fmpc.r_jerk[0]",
        Kind::Positive,
        1e-6,
        10.0,
        |c, v| c.controller.fmpc.r_jerk[0] = v,
    ),
    (
        "controller.fmpc.r_jerk[2]",
        Kind::Positive,
        1e-6,
        10.0,
        |c, v| c.controller.fmpc.r_jerk[2] = v,
    ),
    ("controller.pd.kp", Kind::Positive, 0.01, 100.0, |c, v| {
        c.controller.pd.kp = v
    }),
    ("controller.pd.kd", Kind::Positive, 0.01, 100.0, |c, v| {
        c.controller.pd.kd = v
    }),
    (
        "controller.constraint_tilt_deg",
        Kind::FloatOrOff,
        1.0,
        60.0,
        |c, v| c.controller.constraint_tilt_deg = v,
    ),
    (
        "controller.dfmpc.constraint_speed",
        Kind::Float,
        0.0,
        50.0,
        |c, v| c.controller.dfmpc.constraint_speed = v,
    ),
    (
        "controller.dfmpc.smoothness_weight[0]",
        Kind::Float,
        0.0,
        1e4,
        |c, v| c.controller.dfmpc.smoothness_weight[0] = v,
    ),
    (
        "controller.dfmpc.smoothness_weight[2]",
        Kind::Float,
        0.0,
        1e4,
        |c, v| c.controller.dfmpc.smoothness_weight[2] = v,
    ),
    (
        "controller.dfmpc.multi_rate_window",
        Kind::Usize,
        2.0,
        250.0,
        |c, v| c.controller.dfmpc.multi_rate_window = v as usize,
    ),
    ("controller.sample_sigma", Kind::Float, 1e-4, 1.0, |c, v| {
        c.controller.sample_sigma = v
    }),
    // Upper limit rate_hz / 10 ≥ 1: see `upper_is_fixed`.
    (
        "controller.disturbance.bandwidth_hz",
        Kind::Float,
        0.001,
        1.0,
        |c, v| c.controller.disturbance.bandwidth_hz = v,
    ),
    (
        "controller.disturbance.window",
        Kind::Usize,
        10.0,
        2000.0,
        |c, v| c.controller.disturbance.window = v as usize,
    ),
    (
        "controller.disturbance.max_acceleration",
        Kind::Float,
        0.0,
        10.0,
        |c, v| c.controller.disturbance.max_acceleration = v,
    ),
    (
        "controller.disturbance.thrust_scale_range[0]",
        Kind::Float,
        0.1,
        1.0,
        |c, v| c.controller.disturbance.thrust_scale_range[0] = v,
    ),
    (
        "controller.disturbance.thrust_scale_range[1]",
        Kind::Float,
        1.0,
        10.0,
        |c, v| c.controller.disturbance.thrust_scale_range[1] = v,
    ),
    (
        "controller.disturbance.max_step",
        Kind::Float,
        0.01,
        100.0,
        |c, v| c.controller.disturbance.max_step = v,
    ),
    ("mission.speed", Kind::Float, 0.1, 20.0, |c, v| {
        c.mission.speed = v
    }),
    (
        "mission.path_trigger_radius",
        Kind::Float,
        0.0,
        100.0,
        |c, v| c.mission.path_trigger_radius = v,
    ),
    // Valid fences stay outside the generated paths (|coordinate| ≤ 30).
    (
        "mission.geofence[0]",
        Kind::Positive,
        31.0,
        1000.0,
        |c, v| c.mission.geofence[0] = v,
    ),
    (
        "mission.geofence[1]",
        Kind::Positive,
        31.0,
        1000.0,
        |c, v| c.mission.geofence[1] = v,
    ),
    (
        "mission.geofence[2]",
        Kind::Positive,
        31.0,
        1000.0,
        |c, v| c.mission.geofence[2] = v,
    ),
    (
        "safety.pose_timeout_ms",
        Kind::Float,
        5.0,
        2000.0,
        |c, v| c.safety.pose_timeout_ms = v,
    ),
    (
        "safety.autopilot_timeout_ms",
        Kind::Float,
        100.0,
        10000.0,
        |c, v| c.safety.autopilot_timeout_ms = v,
    ),
    ("safety.stop_brake_ms", Kind::Float, 0.0, 10000.0, |c, v| {
        c.safety.stop_brake_ms = v
    }),
    ("safety.stop_level_ms", Kind::Float, 0.0, 5000.0, |c, v| {
        c.safety.stop_level_ms = v
    }),
];

/// False where the table's `hi` is not the validator's limit.
fn upper_is_fixed(name: &str) -> bool {
    name != "controller.disturbance.bandwidth_hz"
}

/// A value in [lo, hi] of the field's type from `u` ∈ [0, 1].
fn in_range(kind: Kind, lo: f64, hi: f64, u: f64) -> f64 {
    match kind {
        Kind::Usize | Kind::Id => (lo + u * (hi - lo)).round().clamp(lo, hi),
        // Log-uniform: covers tiny and large weights alike.
        Kind::Positive => lo * (hi / lo).powf(u),
        Kind::Float | Kind::FloatOrOff => (lo + u * (hi - lo)).clamp(lo, hi),
    }
}

/// A random valid configuration.
fn valid_config() -> impl Strategy<Value = Config> {
    let numbers = prop::collection::vec(0.0..=1.0f64, FIELDS.len());
    let enums = (
        0..3u8,
        any::<bool>(),
        0..3u8,
        any::<bool>(),
        any::<bool>(),
        0..3u8,
        any::<[bool; 6]>(),
    );
    let path = prop::collection::vec(prop::array::uniform3(-30.0..=30.0f64), 0..6);
    let strings = (
        // What the daemon opens (check-config parses link.url the same way).
        "(udpin|udpout|tcpout):(127\\.0\\.0\\.1|[a-z]{1,8}):[0-9]{1,4}|serial:/dev/tty[A-Z]{1,4}[0-9]:(57600|115200|921600)",
        "\\PC{0,16}",
        prop::collection::vec(1..=255u8, 0..4),
        any::<u64>(),
    );
    (numbers, enums, path, strings).prop_map(
        |(u, (pose, pose_time, kind, spatial, start_path, _plant, flags), path, strings)| {
            let (url, dir, pose_components, seed) = strings;
            let mut c = Config::default();
            for ((_, k, lo, hi, set), u) in FIELDS.iter().zip(&u) {
                set(&mut c, in_range(*k, *lo, *hi, *u));
            }
            c.link.url = url;
            // The envelope: paths fly at most at the speed limit, and the
            // fence's floor lies below the generated paths (|z| ≤ 30).
            c.mission.speed = c.mission.speed.min(c.safety.max_speed_mps);
            c.mission.geofence_down_m = 31.0;
            c.link.pose_source = [
                PoseSourceKind::LocalPositionNed,
                PoseSourceKind::Odometry,
                PoseSourceKind::VisionPositionEstimate,
            ][usize::from(pose)];
            c.link.pose_time = if pose_time {
                PoseTime::Arrival
            } else {
                PoseTime::Source
            };
            c.link.pose_components = pose_components;
            c.link.vehicle_setpoints = flags[0];
            c.vehicle.model = if spatial {
                ModelKind::Spatial
            } else {
                ModelKind::Planar
            };
            c.vehicle.thrust_mode = if spatial || flags[1] {
                ThrustMode::Normalized
            } else {
                ThrustMode::Fixed
            };
            c.controller.kind = [
                ControllerKind::DfMpc,
                ControllerKind::Fmpc,
                ControllerKind::Pd,
            ][usize::from(kind)];
            c.controller.dfmpc.multi_rate = flags[2];
            c.controller.disturbance.enabled = flags[3];
            // Consecutive waypoints distinct (random reals: a repeat means
            // the same draw).
            let mut waypoints: Vec<[f64; 3]> = Vec::new();
            for w in path {
                if waypoints.last() != Some(&w) {
                    waypoints.push(w);
                }
            }
            c.mission.start = if start_path && waypoints.len() >= 2 {
                MissionStart::Path
            } else {
                MissionStart::Hold
            };
            // One waypoint is not a path (a setpoint is): none, or ≥ 2.
            if waypoints.len() == 1 {
                waypoints.clear();
            }
            c.mission.path = waypoints;
            c.logging.dir = dir;
            c.logging.csv = flags[4];
            c.logging.tlog = flags[5];
            c.logging.format = if seed.is_multiple_of(2) {
                LogFormat::Text
            } else {
                LogFormat::Json
            };
            c
        },
    )
}

/// A value outside the field's allowed set, from `which` and `u` ∈ [0, 1].
fn out_of_range(name: &str, kind: Kind, lo: f64, hi: f64, which: u8, u: f64) -> f64 {
    let span = hi - lo;
    match kind {
        Kind::Id => 0.0,
        Kind::Usize => {
            if which.is_multiple_of(2) && lo >= 1.0 {
                (u * (lo - 1.0)).round()
            } else {
                hi + 1.0 + (u * 1000.0).round()
            }
        }
        Kind::Positive => match which % 4 {
            0 => -u * 1e3,
            1 => f64::NAN,
            2 => f64::INFINITY,
            _ => f64::NEG_INFINITY,
        },
        Kind::Float | Kind::FloatOrOff => {
            let v = match which % 5 {
                0 => lo - 1e-6 * lo.abs().max(1.0) - u * span,
                1 if upper_is_fixed(name) => hi + 1e-6 * hi.abs().max(1.0) + u * span,
                1 => -1.0 - u,
                2 => f64::NAN,
                3 => f64::INFINITY,
                _ => f64::NEG_INFINITY,
            };
            // 0 means "off" for these.
            if kind == Kind::FloatOrOff && v == 0.0 {
                -1.0
            } else {
                v
            }
        }
    }
}

/// TOML-shaped lines with random tables, keys and values.
fn tomlish() -> impl Strategy<Value = String> {
    let table = prop_oneof![
        Just(String::new()),
        "\\[(link|vehicle|controller|mission|safety|logging|sitl|[a-z]{1,6})\\]\n",
    ];
    let key = prop_oneof![
        Just("tau".to_owned()),
        Just("rate_hz".to_owned()),
        Just("path".to_owned()),
        Just("geofence".to_owned()),
        Just("system_id".to_owned()),
        Just("horizon".to_owned()),
        "[a-z_]{1,24}",
    ];
    let value = prop_oneof![
        "-?[0-9]{1,20}(\\.[0-9]{0,6})?(e-?[0-9]{1,3})?",
        "(nan|inf|-inf|\\+inf|true|false|1979-05-27T07:32:00Z)",
        "\"\\PC{0,10}\"",
        "'\\PC{0,10}'",
        "\\[(-?[0-9.e]{1,6}, ?){0,4}\\]",
        "\\[\\[(-?[0-9.]{1,4}, ?){0,3}\\](, ?\\[[0-9, .]{0,10}\\]){0,3}\\]",
        "\\{ ?([a-z]{1,4} ?= ?[0-9]{1,3},? ?){0,3}\\}",
        "\\PC{0,12}",
    ];
    let line = (table, key, value).prop_map(|(t, k, v)| format!("{t}{k} = {v}\n"));
    prop::collection::vec(line, 0..8).prop_map(|lines| lines.concat())
}

/// The default file with one line's value replaced by random text.
fn mutated_default() -> impl Strategy<Value = String> {
    let lines: Vec<String> = Config::default()
        .to_toml()
        .lines()
        .map(str::to_owned)
        .collect();
    let n = lines.len();
    (0..n, "\\PC{0,12}|-?[0-9]{1,5}(\\.[0-9]{1,3})?|nan|-inf").prop_map(move |(i, v)| {
        let mut out = lines.clone();
        out[i] = match out[i].split_once(" = ") {
            Some((k, _)) => format!("{k} = {v}"),
            None => v,
        };
        out.join("\n")
    })
}

fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<String>(),
        "\\PC{0,200}",
        prop::collection::vec(any::<u8>(), 0..200)
            .prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        tomlish(),
        mutated_default(),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_text_never_panics_parse(text in text()) {
        match parse(&text) {
            Ok(cfg) => {
                // Whatever was accepted is valid and prints back to itself.
                // Compared as printed text: the `[sitl]` table is kept
                // unparsed by the daemon (the SITL validates it), so it may
                // hold a NaN, which is never equal to itself as a value.
                prop_assert!(cfg.validate(Path::new(FILE)).is_ok());
                let printed = cfg.to_toml();
                prop_assert_eq!(parse(&printed).unwrap().to_toml(), printed);
            }
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.starts_with(FILE), "error does not name the file: {}", msg);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn valid_random_configs_round_trip(cfg in valid_config()) {
        if let Err(e) = cfg.validate(Path::new(FILE)) {
            panic!("generator made an invalid config: {e}");
        }
        let text = cfg.to_toml();
        let back = parse(&text);
        prop_assert!(back.is_ok(), "{:?}\n{}", back.err().map(|e| e.to_string()), text);
        prop_assert_eq!(back.unwrap(), cfg);
    }

    #[test]
    fn one_field_out_of_range_is_named(
        cfg in valid_config(),
        field in 0..FIELDS.len(),
        which in any::<u8>(),
        u in 0.0..=1.0f64,
    ) {
        let (name, kind, lo, hi, set) = FIELDS[field];
        let bad = out_of_range(name, kind, lo, hi, which, u);
        let mut cfg = cfg;
        set(&mut cfg, bad);
        let text = cfg.to_toml();
        match parse(&text) {
            Err(ConfigError::Range { field, value, ref file, .. }) => {
                prop_assert_eq!(file.as_path(), Path::new(FILE));
                prop_assert_eq!(&field, name, "value {} ({})", value, bad);
            }
            Err(e) => prop_assert!(false, "{} = {}: not a range error: {}", name, bad, e),
            Ok(_) => prop_assert!(false, "{} = {} accepted", name, bad),
        }
        // The message names the field, too.
        let msg = parse(&text).unwrap_err().to_string();
        prop_assert!(msg.contains(name), "{}", msg);
    }
}
