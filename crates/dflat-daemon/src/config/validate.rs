//! [`Config::validate`]: every range, the first offending field named.

use std::path::Path;

use dflat_control::Limit;

use super::*;

impl Config {
    /// Checks every range, table by table; the error names the first
    /// offending field (by its TOML key).
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let mut v = Validator { file };
        self.link.validate(&mut v)?;
        self.vehicle.validate(&mut v)?;
        self.records
            .validate(|field, x, allowed| v.err(field, &x.to_string(), allowed))?;
        let rt = &self.realtime;
        v.range(
            "realtime.fifo_priority",
            f64::from(rt.fifo_priority),
            0.0,
            99.0,
        )?;
        self.controller.validate(&mut v)?;
        self.validate_mission(&mut v)?;
        self.safety.validate(&mut v)?;
        self.stream.validate(file)?;
        Ok(())
    }

    /// `[mission]`, against the fence and `safety.max_speed_mps`.
    fn validate_mission(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        let m = &self.mission;
        v.range("mission.speed", m.speed, 0.1, 20.0)?;
        v.range("mission.brake_fraction", m.brake_fraction, 0.1, 1.0)?;
        v.range(
            "mission.acceptance_radius_m",
            m.acceptance_radius_m,
            0.05,
            50.0,
        )?;
        if m.local_xy_scale != 1e4 && m.local_xy_scale != 1e7 {
            return Err(v.err(
                "mission.local_xy_scale",
                &m.local_xy_scale.to_string(),
                "1e4 (the MAVLink specification) or 1e7 (MAVProxy, pymavlink mavwp)",
            ));
        }
        if m.start_acceleration != 0.0 {
            v.range(
                "mission.start_acceleration",
                m.start_acceleration,
                0.5,
                10.0,
            )?;
        }
        v.range(
            "mission.path_trigger_radius",
            m.path_trigger_radius,
            0.0,
            100.0,
        )?;
        for i in 0..3 {
            v.positive(&format!("mission.geofence[{i}]"), m.geofence[i])?;
        }
        v.range("mission.geofence_down_m", m.geofence_down_m, 0.0, 1000.0)?;
        if m.start == MissionStart::Path && m.path.len() < 2 {
            return Err(v.err(
                "mission.path",
                &format!("{} waypoints", m.path.len()),
                "at least 2 waypoints when mission.start = \"path\"",
            ));
        }
        if m.path.len() == 1 {
            // A path of one waypoint has no leg to fly: a hold point is a
            // setpoint (SET_POSITION_TARGET_LOCAL_NED), not a path.
            return Err(v.err(
                "mission.path",
                "1 waypoint",
                "none, or at least 2 waypoints (a single point is a setpoint, not a path)",
            ));
        }
        if m.speed > self.safety.max_speed_mps {
            return Err(v.err(
                "mission.speed",
                &m.speed.to_string(),
                &format!(
                    "at most safety.max_speed_mps ({})",
                    self.safety.max_speed_mps
                ),
            ));
        }
        // One fence for every goal: the box of crate::envelope (a floor
        // `geofence_down_m` below the origin, a ceiling `geofence[2]` above).
        let fence = crate::envelope::Envelope::from_config(self).bounds;
        let (lo, hi) = (fence.min, fence.max);
        for (i, w) in m.path.iter().enumerate() {
            for (j, x) in w.iter().enumerate() {
                if !x.is_finite() || *x < lo[j] || *x > hi[j] {
                    return Err(v.err(
                        &format!("mission.path[{i}][{j}]"),
                        &x.to_string(),
                        &format!("finite and inside the fence [{}, {}]", lo[j], hi[j]),
                    ));
                }
            }
            if i > 0 && *w == m.path[i - 1] {
                return Err(v.err(
                    &format!("mission.path[{i}]"),
                    &format!("{w:?}"),
                    "distinct from the previous waypoint",
                ));
            }
        }
        if m.repeat && (m.path.len() < 3 || m.path.first() != m.path.last()) {
            return Err(v.err(
                "mission.repeat",
                "true",
                "a closed path (≥ 3 waypoints, the last equal to the first)",
            ));
        }
        Ok(())
    }
}

impl LinkConfig {
    /// `[link]`: the connection, the ids, the pose clock, signing, the peer.
    fn validate(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        let l = self;
        v.nonempty("link.url", &l.url)?;
        // The daemon opens exactly what this parses (one parser for both).
        if let Err(e) = dflat_link::transport::Endpoint::parse(&l.url) {
            let reason = match e {
                dflat_link::transport::TransportError::BadUrl { reason, .. } => reason,
                other => other.to_string(),
            };
            return Err(v.err("link.url", &format!("{:?}", l.url), &reason));
        }
        for (name, id) in [
            ("link.system_id", l.system_id),
            ("link.autopilot_component", l.autopilot_component),
            ("link.component_id", l.component_id),
        ] {
            v.range(name, f64::from(id), 1.0, 255.0)?;
        }
        if let Some(id) = l.gcs_system_id {
            v.range("link.gcs_system_id", f64::from(id), 1.0, 255.0)?;
            if l.gcs_system_ids != dflat_link::DEFAULT_GCS_SYSTEM_IDS {
                return Err(v.err(
                    "link.gcs_system_id",
                    &id.to_string(),
                    "unset when link.gcs_system_ids is set (it is the deprecated one-id form)",
                ));
            }
        }
        if l.gcs_system_ids.is_empty() {
            return Err(v.err(
                "link.gcs_system_ids",
                "[]",
                "at least one ground-station id, each 1 to 255",
            ));
        }
        for (i, id) in l.gcs_system_ids.iter().enumerate() {
            v.range(
                &format!("link.gcs_system_ids[{i}]"),
                f64::from(*id),
                1.0,
                255.0,
            )?;
        }
        for (i, c) in l.pose_components.iter().enumerate() {
            v.range(
                &format!("link.pose_components[{i}]"),
                f64::from(*c),
                1.0,
                255.0,
            )?;
        }
        v.range(
            "link.pose_clock_window_s",
            l.pose_clock_window_s,
            1.0,
            600.0,
        )?;
        v.range(
            "link.pose_min_latency_ms",
            l.pose_min_latency_ms,
            0.0,
            1000.0,
        )?;
        // signing_link_id: any u8 (0–255) is valid; the key file's mode and
        // owner are checked when the daemon starts (crate::signing).
        if !l.signing_key_file.trim().is_empty() {
            if l.signing_timestamp_file.trim().is_empty() {
                return Err(v.err(
                    "link.signing_timestamp_file",
                    "\"\"",
                    "a file path (required when link.signing_key_file is set)",
                ));
            }
            if l.signing_timestamp_file.trim() == l.signing_key_file.trim() {
                return Err(v.err(
                    "link.signing_timestamp_file",
                    &format!("{:?}", l.signing_timestamp_file),
                    "a file other than link.signing_key_file",
                ));
            }
        }
        for (i, name) in l.signing_accept_unsigned.iter().enumerate() {
            let field = format!("link.signing_accept_unsigned[{i}]");
            match dflat_link::unsigned_message_id(name) {
                Ok(_) => {}
                Err(reason) => return Err(v.err(&field, &format!("{name:?}"), reason)),
            }
        }
        if !l.peer.trim().is_empty() {
            if !l.url.trim().starts_with("udpin:") {
                return Err(v.err(
                    "link.peer",
                    &format!("{:?}", l.peer),
                    "\"\" unless link.url is udpin:HOST:PORT (udpout, tcp and serial have one peer)",
                ));
            }
            if l.peer.trim().parse::<std::net::SocketAddr>().is_err() {
                return Err(v.err(
                    "link.peer",
                    &format!("{:?}", l.peer),
                    "an address IP:PORT (e.g. \"192.168.1.10:14550\") or \"\"",
                ));
            }
        }
        Ok(())
    }
}

impl VehicleConfig {
    /// `[vehicle]`.
    fn validate(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        let ve = self;
        v.range("vehicle.tau", ve.tau, 0.02, 2.0)?;
        v.range("vehicle.k", ve.k, 0.2, 5.0)?;
        v.range("vehicle.tau_thrust", ve.tau_thrust, 0.005, 1.0)?;
        v.range("vehicle.gravity", ve.gravity, 9.0, 10.5)?;
        v.range("vehicle.yaw_deg", ve.yaw_deg, -180.0, 180.0)?;
        v.range("vehicle.max_tilt_deg", ve.max_tilt_deg, 1.0, 60.0)?;
        v.range("vehicle.thrust_value", ve.thrust_value, 0.0, 1.0)?;
        let (lo, hi) = super::HOVER_THRUST_RANGE;
        v.range("vehicle.hover_thrust", ve.hover_thrust, lo, hi)?;
        v.range(
            "vehicle.max_yaw_rate_deg_s",
            ve.max_yaw_rate_deg_s,
            5.0,
            360.0,
        )?;
        v.range("vehicle.yaw_lead_s", ve.yaw_lead_s, 0.0, 1.0)?;
        v.range("vehicle.drag_h", ve.drag_h, 0.0, 2.0)?;
        v.range("vehicle.drag_v", ve.drag_v, 0.0, 2.0)?;
        v.range("vehicle.drag_rotor", ve.drag_rotor, 0.0, 2.0)?;
        v.range("vehicle.delay_ms", ve.delay_ms, 0.0, 500.0)?;
        if ve.model == ModelKind::Planar && ve.drag_rotor != 0.0 {
            return Err(v.err(
                "vehicle.drag_rotor",
                &ve.drag_rotor.to_string(),
                "0 with model = \"planar\" (the rotor drag's lift needs the spatial model, \
                 which flies the thrust; fold it into drag_h)",
            ));
        }
        if ve.model == ModelKind::Spatial && ve.thrust_mode == ThrustMode::Fixed {
            return Err(v.err(
                "vehicle.thrust_mode",
                "\"fixed\"",
                "\"normalized\" with model = \"spatial\" (the spatial model commands thrust)",
            ));
        }
        Ok(())
    }
}

impl SafetyConfig {
    /// `[safety]`.
    fn validate(&self, v: &mut Validator<'_>) -> Result<(), ConfigError> {
        let s = self;
        v.range("safety.pose_timeout_ms", s.pose_timeout_ms, 5.0, 2000.0)?;
        v.range(
            "safety.autopilot_timeout_ms",
            s.autopilot_timeout_ms,
            100.0,
            10000.0,
        )?;
        v.range("safety.max_speed_mps", s.max_speed_mps, 0.5, 100.0)?;
        v.range("safety.pose_jump_margin_m", s.pose_jump_margin_m, 0.0, 10.0)?;
        v.range("safety.stop_brake_ms", s.stop_brake_ms, 0.0, 10000.0)?;
        v.range("safety.stop_level_ms", s.stop_level_ms, 0.0, 5000.0)?;
        v.range(
            "safety.hold_last_ticks",
            f64::from(s.hold_last_ticks),
            0.0,
            50.0,
        )?;
        if s.residual_failsafe_m != 0.0 {
            v.range(
                "safety.residual_failsafe_m",
                s.residual_failsafe_m,
                0.05,
                100.0,
            )?;
        }
        v.range(
            "safety.level_hover_max_ms",
            s.level_hover_max_ms,
            0.0,
            10000.0,
        )?;
        v.range(
            "safety.pose_max_latency_ms",
            s.pose_max_latency_ms,
            10.0,
            5000.0,
        )?;
        Ok(())
    }
}

pub(super) struct Validator<'a> {
    file: &'a Path,
}

impl Validator<'_> {
    pub(super) fn err(&self, field: &str, value: &str, allowed: &str) -> ConfigError {
        ConfigError::Range {
            file: self.file.to_owned(),
            field: field.to_owned(),
            value: value.to_owned(),
            allowed: allowed.to_owned(),
        }
    }

    pub(super) fn range(
        &mut self,
        field: &str,
        x: f64,
        lo: f64,
        hi: f64,
    ) -> Result<(), ConfigError> {
        if x.is_finite() && x >= lo && x <= hi {
            Ok(())
        } else {
            Err(self.err(field, &x.to_string(), &format!("{lo} to {hi}")))
        }
    }

    /// `x` inside the core's `limit` ([`dflat_control::Limit`]).
    pub(super) fn limit(&mut self, field: &str, x: f64, limit: Limit) -> Result<(), ConfigError> {
        if limit.contains(x) {
            Ok(())
        } else {
            Err(self.err(field, &x.to_string(), &limit.to_string()))
        }
    }

    /// Each element of `xs` inside `limit`, named `field[i]`.
    pub(super) fn limits(
        &mut self,
        field: &str,
        xs: &[f64],
        limit: Limit,
    ) -> Result<(), ConfigError> {
        for (i, x) in xs.iter().enumerate() {
            self.limit(&format!("{field}[{i}]"), *x, limit)?;
        }
        Ok(())
    }

    /// `x` exactly 0 ("off") or inside `limit`.
    pub(super) fn limit_or_off(
        &mut self,
        field: &str,
        x: f64,
        limit: Limit,
    ) -> Result<(), ConfigError> {
        if x == 0.0 || limit.contains(x) {
            Ok(())
        } else {
            Err(self.err(field, &x.to_string(), &format!("0 (off) or {limit}")))
        }
    }

    fn positive(&mut self, field: &str, x: f64) -> Result<(), ConfigError> {
        if x.is_finite() && x > 0.0 {
            Ok(())
        } else {
            Err(self.err(field, &x.to_string(), "finite and > 0"))
        }
    }

    fn nonempty(&mut self, field: &str, s: &str) -> Result<(), ConfigError> {
        if s.trim().is_empty() {
            Err(self.err(field, "\"\"", "a non-empty connection string"))
        } else {
            Ok(())
        }
    }
}
