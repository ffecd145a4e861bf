//! The SITL's configuration: its own `[sitl]` table and the MAVLink ids of
//! `[link]`, read from the same TOML file as the daemon's configuration.
//!
//! The daemon keeps `[sitl]` unparsed (it does not depend on the lab); this
//! module parses and validates it. Errors name the file, the field (dotted
//! path) and the allowed range.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::pilot::{PilotAction, SitlEngage};

/// A SITL configuration that could not be read or is out of range.
#[derive(Debug, Error)]
pub enum SitlConfigError {
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

/// The MAVLink ids the SITL takes from `[link]` (the same fields the daemon
/// reads): it is component `autopilot_component` of system `system_id`, and
/// routes a ground station of system `gcs_system_id`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct SitlIds {
    /// Vehicle system id (1–255).
    pub system_id: u8,
    /// The autopilot's component id (1–255): the SITL's own.
    pub autopilot_component: u8,
    /// The ground station's system id (1–255).
    pub gcs_system_id: u8,
}

impl Default for SitlIds {
    fn default() -> Self {
        Self {
            system_id: 1,
            autopilot_component: 1,
            gcs_system_id: 255,
        }
    }
}

/// Everything the SITL reads from a configuration file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SitlSettings {
    /// `[sitl]`.
    pub sitl: SitlConfig,
    /// From `[link]`.
    pub ids: SitlIds,
}

impl SitlSettings {
    /// Reads, parses and validates a file.
    pub fn load(path: &Path) -> Result<Self, SitlConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| SitlConfigError::Read {
            file: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates TOML text (a whole dflat configuration; every
    /// table but `[sitl]` and the ids of `[link]` is ignored here); `file` is
    /// used in error messages.
    pub fn parse(text: &str, file: &Path) -> Result<Self, SitlConfigError> {
        let parse_err = |message: String| SitlConfigError::Parse {
            file: file.to_owned(),
            message: message.trim_end().to_owned(),
        };
        let table: toml::Table = toml::from_str(text).map_err(|e| parse_err(e.to_string()))?;
        let sitl = match table.get("sitl") {
            Some(v) => {
                SitlConfig::deserialize(v.clone()).map_err(|e| parse_err(format!("[sitl]: {e}")))?
            }
            None => SitlConfig::default(),
        };
        let mut ids = SitlIds::default();
        if let Some(link) = table.get("link").and_then(|l| l.as_table()) {
            for (name, slot) in [
                ("system_id", &mut ids.system_id),
                ("autopilot_component", &mut ids.autopilot_component),
                ("gcs_system_id", &mut ids.gcs_system_id),
            ] {
                if let Some(v) = link.get(name) {
                    let n = v
                        .as_integer()
                        .filter(|n| (1..=255).contains(n))
                        .ok_or_else(|| SitlConfigError::Range {
                            file: file.to_owned(),
                            field: format!("link.{name}"),
                            value: v.to_string(),
                            allowed: "1 to 255".into(),
                        })?;
                    *slot = n as u8;
                }
            }
        }
        let settings = Self { sitl, ids };
        settings.sitl.validate(file)?;
        Ok(settings)
    }

    /// The effective `[sitl]` table as TOML.
    pub fn to_toml(&self) -> String {
        #[derive(Serialize)]
        struct Wrap<'a> {
            sitl: &'a SitlConfig,
        }
        toml::to_string_pretty(&Wrap { sitl: &self.sitl })
            .unwrap_or_else(|e| format!("# cannot print: {e}"))
    }
}

/// The SITL's plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SitlPlant {
    /// Planar plant; altitude held.
    #[default]
    Planar,
    /// Spatial plant with collective thrust.
    Spatial,
    /// Full rigid body with an inner attitude controller.
    Full,
}

/// `sitl.autopilot`: which autopilot the SITL plays (HEARTBEAT `autopilot`
/// field and mode numbers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SitlAutopilot {
    /// PX4: MAV_AUTOPILOT_PX4, POSCTL (main mode 3) / OFFBOARD (6).
    #[default]
    Px4,
    /// ArduPilot Copter: MAV_AUTOPILOT_ARDUPILOTMEGA, LOITER (5) /
    /// GUIDED_NOGPS (20). The planar plant only (altitude held: thrust 0.5
    /// is a climb rate of 0, as ArduPilot reads it by default).
    Ardupilot,
}

/// `[sitl]`: the autopilot stand-in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SitlConfig {
    /// Where the SITL listens (`udpin:HOST:PORT`).
    pub url: String,
    /// Plant kind.
    pub plant: SitlPlant,
    /// Plant integration rate \[Hz\] (100–2000).
    pub plant_rate_hz: f64,
    /// Rate of LOCAL_POSITION_NED / ATTITUDE out \[Hz\] (1–200) until
    /// MAV_CMD_SET_MESSAGE_INTERVAL changes it (the daemon asks for its
    /// tick rate: `link.request_streams`).
    pub telemetry_rate_hz: f64,
    /// Refuse MAV_CMD_SET_MESSAGE_INTERVAL for LOCAL_POSITION_NED and
    /// ATTITUDE (DENIED, STATUSTEXT): an autopilot whose own settings
    /// alone set those rates. `false` (default): set, as PX4 and ArduPilot
    /// do.
    pub fixed_telemetry_rate: bool,
    /// Plant attitude time constant \[s\] (may differ from the model's).
    pub tau: f64,
    /// Plant attitude gain [-].
    pub k: f64,
    /// Plant hover thrust (normalised 0–1) — spatial/full plants.
    pub hover_thrust: f64,
    /// Plant thrust time constant τ_T \[s\] (0.005–1) — spatial plant's
    /// thrust lag, the rigid body's motor lag.
    pub tau_thrust: f64,
    /// Pure delay \[ms\] (0–500) between a received command and its
    /// application by the plant (the autopilot's and actuators' latency).
    pub command_delay_ms: f64,
    /// Rate of the clock that stamps the poses (LOCAL_POSITION_NED
    /// `time_boot_ms`, vision `time_usec`) relative to real time (0.1–10;
    /// 1 = true): a lagging simulator or a drifting VIO clock (< 1), or a
    /// fast one (> 1). The plant and every other timing stay real time.
    pub pose_clock_rate: f64,
    /// Plant mass factor relative to nominal (0.5–2).
    pub mass_factor: f64,
    /// Gaussian position noise σ \[m\] (0–1).
    pub noise_sigma: f64,
    /// Also send VISION_POSITION_ESTIMATE at this rate \[Hz\] (0 = off;
    /// 1–100): a vision pipeline stand-in for `link.pose_source =
    /// "vision_position_estimate"`. LOCAL_POSITION_NED goes on as well.
    pub vision_rate_hz: f64,
    /// Vision latency \[ms\] (0–500): each sample's `time_usec` is its capture
    /// time on the SITL's clock, and it is sent this much later.
    pub vision_latency_ms: f64,
    /// Gaussian noise σ of the vision position \[m\] (0–1).
    pub vision_noise_sigma: f64,
    /// Initial position, local NED \[m\].
    pub start: [f64; 3],
    /// Seconds without SET_ATTITUDE_TARGET after which the SITL holds position.
    pub command_timeout_s: f64,
    /// After `command_timeout_s` without a stream, stay in the offboard
    /// mode and fly level at hover thrust instead of falling back to
    /// position mode: ArduPilot Copter, which stays in GUIDED / GUIDED_NOGPS
    /// after GUID_TIMEOUT (its attitude target times out to level). A
    /// daemon (re)started then finds the autopilot applying its commands.
    pub stays_offboard: bool,
    /// A gust (an impulse of velocity, local NED [m/s], each within ±50) added
    /// to the vehicle `gust_at_s` seconds after the SITL started (0 = none;
    /// 0–3600): a vehicle pushed past the daemon's speed limit.
    pub gust_velocity: [f64; 3],
    /// When the gust hits \[s\] since the SITL started (0 = never).
    pub gust_at_s: f64,
    /// Random seed.
    pub seed: u64,
    /// MAVLink 2 signing key file of the SITL; empty = signing off. Same
    /// rules as `link.signing_key_file` (mode 0600, owned by the running
    /// user; 64 hex digits, 32 raw bytes or a passphrase), checked when the
    /// SITL starts. With a key the SITL signs everything it sends (link id
    /// 1, timestamps from the wall clock, nothing persisted), refuses
    /// SET_ATTITUDE_TARGET without a valid signature and drops badly signed
    /// or replayed frames; other unsigned messages are still accepted. See
    /// the crate root.
    pub signing_key_file: String,
    /// The autopilot played: `px4` or `ardupilot` (see [`SitlAutopilot`]).
    pub autopilot: SitlAutopilot,
    /// Who switches to offboard: `auto` (whenever the stream is alive and
    /// the pilot has not taken over) or `pilot` (only `[[sitl.pilot]]` and
    /// the in-process hook). See [`super::pilot`].
    pub engage: SitlEngage,
    /// Scripted pilot actions: `[[sitl.pilot]]` tables with `at_s`,
    /// optional `mode` (`position` / `offboard`) and optional `velocity`
    /// (stick, local NED m/s, flown in position mode).
    pub pilot: Vec<PilotAction>,
    /// The autopilot's yaw loop (planar and spatial plants): the heading
    /// follows SET_ATTITUDE_TARGET's yaw at most this fast \[deg/s\]
    /// (0 = the heading never changes; 0–720), with a 0.1 s time constant,
    /// while the thrust axis tracks the command's (its pitch and roll at
    /// its yaw), as PX4's and ArduPilot's attitude controllers do.
    pub max_yaw_rate_deg_s: f64,
    /// Linear aerodynamic drag of the plant \[1/s\] on every axis (0–2,
    /// default 0): `v̇ = … − drag·v`. The truth `dflat identify` should find.
    pub drag: f64,
    /// Quadratic parasitic drag of the plant \[1/m\] (0–1, default 0):
    /// `v̇ = … − quadratic_drag·|v|·v` (the spatial and full plants in 3-D;
    /// the planar plant on its horizontal velocity). No parametric term of
    /// the daemon's model has it: `dflat learn` fits it.
    pub quadratic_drag: f64,
    /// Rotor drag of the plant in the body plane \[1/s\] (0–2, default 0):
    /// `v̇ = … − rotor_drag·R·diag(1, 1, 0)·Rᵀ·v`, the velocity's part across
    /// the thrust axis (induced drag of the rotors, blade flapping).
    pub rotor_drag: f64,
    /// The full plant's autopilot limits its roll and pitch rate setpoints
    /// to this \[deg/s\] (PX4's MC_ROLLRATE_MAX / MC_PITCHRATE_MAX,
    /// ArduPilot's ATC_RATE_R_MAX / ATC_RATE_P_MAX; 0 = no limit, the
    /// default; 0–2000). Other plants: unused.
    pub max_tilt_rate_deg_s: f64,
    /// `[sitl.planner]`: stream a circle or a figure eight to the daemon
    /// once offboard (absent: no planner). See [`super::planner`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planner: Option<super::planner::PlannerConfig>,
}

impl Default for SitlConfig {
    fn default() -> Self {
        Self {
            url: "udpin:127.0.0.1:14540".into(),
            plant: SitlPlant::Planar,
            plant_rate_hz: 200.0,
            telemetry_rate_hz: 50.0,
            fixed_telemetry_rate: false,
            tau: 0.2,
            k: 1.0,
            hover_thrust: 0.5,
            tau_thrust: 0.04,
            command_delay_ms: 0.0,
            pose_clock_rate: 1.0,
            mass_factor: 1.0,
            noise_sigma: 0.0,
            vision_rate_hz: 0.0,
            vision_latency_ms: 60.0,
            vision_noise_sigma: 0.02,
            start: [-20.0, -30.0, -10.0],
            command_timeout_s: 0.5,
            stays_offboard: false,
            gust_velocity: [0.0; 3],
            gust_at_s: 0.0,
            seed: 1,
            signing_key_file: String::new(),
            autopilot: SitlAutopilot::Px4,
            engage: SitlEngage::Auto,
            pilot: Vec::new(),
            max_yaw_rate_deg_s: 90.0,
            drag: 0.0,
            quadratic_drag: 0.0,
            rotor_drag: 0.0,
            max_tilt_rate_deg_s: 0.0,
            planner: None,
        }
    }
}

impl SitlConfig {
    /// Checks every range; the error names the first offending field.
    pub fn validate(&self, file: &Path) -> Result<(), SitlConfigError> {
        let err = |field: &str, value: String, allowed: String| SitlConfigError::Range {
            file: file.to_owned(),
            field: field.to_owned(),
            value,
            allowed,
        };
        let range = |field: &str, x: f64, lo: f64, hi: f64| {
            if x.is_finite() && x >= lo && x <= hi {
                Ok(())
            } else {
                Err(err(field, x.to_string(), format!("{lo} to {hi}")))
            }
        };
        let si = self;
        if si.url.trim().is_empty() {
            return Err(err(
                "sitl.url",
                "\"\"".into(),
                "a non-empty connection string".into(),
            ));
        }
        range("sitl.plant_rate_hz", si.plant_rate_hz, 100.0, 2000.0)?;
        range("sitl.telemetry_rate_hz", si.telemetry_rate_hz, 1.0, 200.0)?;
        range("sitl.tau", si.tau, 0.02, 2.0)?;
        range("sitl.k", si.k, 0.2, 5.0)?;
        range("sitl.hover_thrust", si.hover_thrust, 0.05, 0.95)?;
        range("sitl.tau_thrust", si.tau_thrust, 0.005, 1.0)?;
        range("sitl.max_yaw_rate_deg_s", si.max_yaw_rate_deg_s, 0.0, 720.0)?;
        range("sitl.command_delay_ms", si.command_delay_ms, 0.0, 500.0)?;
        range("sitl.drag", si.drag, 0.0, 2.0)?;
        range("sitl.quadratic_drag", si.quadratic_drag, 0.0, 1.0)?;
        range("sitl.rotor_drag", si.rotor_drag, 0.0, 2.0)?;
        range(
            "sitl.max_tilt_rate_deg_s",
            si.max_tilt_rate_deg_s,
            0.0,
            2000.0,
        )?;
        range("sitl.pose_clock_rate", si.pose_clock_rate, 0.1, 10.0)?;
        range("sitl.mass_factor", si.mass_factor, 0.5, 2.0)?;
        range("sitl.noise_sigma", si.noise_sigma, 0.0, 1.0)?;
        if si.vision_rate_hz != 0.0 {
            range("sitl.vision_rate_hz", si.vision_rate_hz, 1.0, 100.0)?;
        }
        range("sitl.vision_latency_ms", si.vision_latency_ms, 0.0, 500.0)?;
        range("sitl.vision_noise_sigma", si.vision_noise_sigma, 0.0, 1.0)?;
        range("sitl.command_timeout_s", si.command_timeout_s, 0.05, 10.0)?;
        range("sitl.gust_at_s", si.gust_at_s, 0.0, 3600.0)?;
        for (i, v) in si.gust_velocity.iter().enumerate() {
            range(&format!("sitl.gust_velocity[{i}]"), *v, -50.0, 50.0)?;
        }
        for i in 0..3 {
            range(&format!("sitl.start[{i}]"), si.start[i], -1e4, 1e4)?;
        }
        if si.autopilot == SitlAutopilot::Ardupilot && si.plant != SitlPlant::Planar {
            return Err(err(
                "sitl.autopilot",
                "\"ardupilot\"".into(),
                "\"ardupilot\" with sitl.plant = \"planar\" only (thrust is a climb rate)".into(),
            ));
        }
        if let Some(p) = &si.planner {
            for (field, x, lo, hi) in p.ranges() {
                range(field, x, lo, hi)?;
            }
            for (field, id) in [
                ("sitl.planner.system_id", p.system_id),
                ("sitl.planner.component_id", p.component_id),
                ("sitl.planner.target_component", p.target_component),
            ] {
                if id == 0 {
                    return Err(err(field, "0".into(), "1 to 255".into()));
                }
            }
        }
        for (i, a) in si.pilot.iter().enumerate() {
            range(&format!("sitl.pilot[{i}].at_s"), a.at_s, 0.0, 3600.0)?;
            if let Some(v) = a.velocity {
                for (j, x) in v.iter().enumerate() {
                    range(&format!("sitl.pilot[{i}].velocity[{j}]"), *x, -20.0, 20.0)?;
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SitlSettings, SitlConfigError> {
        SitlSettings::parse(text, Path::new("test.toml"))
    }

    #[test]
    fn defaults_ids_and_other_tables_ignored() {
        let s = parse("[vehicle]\ntau = 0.3\n[link]\nsystem_id = 7\nurl = \"udpout:x:1\"").unwrap();
        assert_eq!(s.ids.system_id, 7);
        assert_eq!(s.ids.autopilot_component, 1);
        assert_eq!(s.sitl, SitlConfig::default());
    }

    #[test]
    fn fields_are_checked_and_named() {
        let err = parse("[sitl]\ntau = 9.0").unwrap_err().to_string();
        assert!(
            err.contains("sitl.tau") && err.contains("0.02 to 2"),
            "{err}"
        );
        let err = parse("[sitl]\nbogus = 1").unwrap_err().to_string();
        assert!(err.contains("bogus"), "{err}");
        let err = parse("[link]\nsystem_id = 0").unwrap_err().to_string();
        assert!(err.contains("link.system_id"), "{err}");
        let s = parse("[sitl]\nsigning_key_file = \"/etc/dflat/sitl.key\"").unwrap();
        assert_eq!(s.sitl.signing_key_file, "/etc/dflat/sitl.key");
    }

    #[test]
    fn effective_table_round_trips() {
        let mut s = SitlSettings::default();
        s.sitl.tau = 0.35;
        s.sitl.start = [1.0, 2.0, -3.0];
        assert_eq!(parse(&s.to_toml()).unwrap(), s);
    }
}
