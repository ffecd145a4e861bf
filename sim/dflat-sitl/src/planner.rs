//! `[sitl.planner]`: the SITL as a planner. Once the autopilot is in
//! offboard, it streams SET_POSITION_TARGET_LOCAL_NED to the daemon (1/191
//! by default) with position, velocity and acceleration (or fewer:
//! `fields`) and yaw with its rate, as MAVROS, MAVSDK or any planner sends
//! them, along a shape of [`dflat_sim::trajectory`] that starts where the
//! vehicle is. With `ahead_s > 0` each send is the present sample and the
//! trajectory's next `ahead_s` seconds at the same spacing, stamped in the
//! autopilot's boot time ahead of now: the trajectory sent ahead (the
//! daemon with `stream.time_base = "autopilot"`).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use dflat_link::MavMessage;
use dflat_link::dialect::{MavFrame, PositionTargetTypemask, SET_POSITION_TARGET_LOCAL_NED_DATA};
use dflat_sim::trajectory::{Shape, Trajectory, TrajectoryPoint};

/// `[sitl.planner]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlannerConfig {
    /// `circle`, `figure_eight`, `racing_line` or `lemniscate`.
    pub shape: Shape,
    /// Radius (circle) or half-width (figure eight) \[m\] (0.5–100).
    pub size: f64,
    /// Cruise speed [m/s] (0.1–20).
    pub speed: f64,
    /// Speed ramp from rest \[s\] (0–30).
    pub ramp_s: f64,
    /// Samples per second \[Hz\] (1–100).
    pub rate_hz: f64,
    /// Seconds after the autopilot first enters offboard before the
    /// stream starts (0–600).
    pub start_after_s: f64,
    /// Seconds the stream lasts; 0 = until the SITL stops (0–3600). A
    /// stream that ends shows the daemon's smooth stop and hold.
    pub duration_s: f64,
    /// The planner's MAVLink system id (1–255): one the daemon hears
    /// (`link.gcs_system_ids`, default 255 and 245).
    pub system_id: u8,
    /// The planner's component id (1–255; 190 = MAV_COMP_ID_MISSIONPLANNER).
    pub component_id: u8,
    /// The component the samples are for (1–255; 191 = the daemon).
    pub target_component: u8,
    /// Send the heading along the velocity and its rate (else the yaw and
    /// yaw-rate fields are masked).
    pub yaw: bool,
    /// The fields sent: `pva` (position, velocity, acceleration), `pv` or
    /// `p` (the others masked).
    pub fields: PlannerFields,
    /// How far ahead \[s\] each send carries the trajectory (0–10; 0 = the
    /// present sample only): the samples every `1/rate_hz` up to `ahead_s`
    /// after now, stamped ahead in the autopilot's boot time.
    pub ahead_s: f64,
    /// The anchor: the autopilot flies the samples itself, with its own
    /// position loop (PD with velocity and acceleration feed-forward, as
    /// PX4's in OFFBOARD with position setpoints) — nothing is sent; the
    /// stream starts `start_after_s` after the SITL does, and its live
    /// setpoints engage offboard. The same stream on the same plant, for
    /// comparing the daemon against.
    pub anchor: bool,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            shape: Shape::Circle,
            size: 6.0,
            speed: 4.0,
            ramp_s: 3.0,
            rate_hz: 20.0,
            start_after_s: 2.0,
            duration_s: 0.0,
            system_id: 255,
            component_id: 190,
            target_component: 191,
            yaw: true,
            fields: PlannerFields::Pva,
            ahead_s: 0.0,
            anchor: false,
        }
    }
}

impl PlannerConfig {
    /// The ranges: `(field, value, lo, hi)` (checked by the `[sitl]`
    /// validation, which names the field).
    pub fn ranges(&self) -> [(&'static str, f64, f64, f64); 7] {
        [
            ("sitl.planner.size", self.size, 0.5, 100.0),
            ("sitl.planner.speed", self.speed, 0.1, 20.0),
            ("sitl.planner.ramp_s", self.ramp_s, 0.0, 30.0),
            ("sitl.planner.rate_hz", self.rate_hz, 1.0, 100.0),
            ("sitl.planner.start_after_s", self.start_after_s, 0.0, 600.0),
            ("sitl.planner.duration_s", self.duration_s, 0.0, 3600.0),
            ("sitl.planner.ahead_s", self.ahead_s, 0.0, 10.0),
        ]
    }
}

/// `sitl.planner.fields`: which fields each sample carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PlannerFields {
    /// Position, velocity and acceleration.
    #[default]
    Pva,
    /// Position and velocity.
    Pv,
    /// Position only.
    P,
}

/// The planner's state in the SITL's step ([`crate::SitlCore`]).
#[derive(Debug, Clone)]
pub struct Planner {
    config: PlannerConfig,
    /// SITL time the autopilot first entered offboard \[s\].
    offboard_since: Option<f64>,
    /// The trajectory and its start time \[s\], once streaming.
    stream: Option<(Trajectory, f64)>,
    /// SITL time of the last sample \[s\].
    last_sent: Option<f64>,
    /// Samples sent.
    sent: u64,
    /// The planner's own MAVLink sequence.
    seq: u8,
}

impl Planner {
    /// A planner that waits for offboard.
    pub fn new(config: PlannerConfig) -> Self {
        Self {
            config,
            offboard_since: None,
            stream: None,
            last_sent: None,
            sent: 0,
            seq: 0,
        }
    }

    /// SITL time \[s\] the trajectory started (t = 0), once streaming.
    pub fn started_at(&self) -> Option<f64> {
        self.stream.map(|(_, t0)| t0)
    }

    /// The autopilot flies the samples itself ([`PlannerConfig::anchor`]).
    pub fn anchor(&self) -> bool {
        self.config.anchor
    }

    /// The planner's (system, component) ids.
    pub fn ids(&self) -> (u8, u8) {
        (self.config.system_id, self.config.component_id)
    }

    /// The next sequence number of the planner's frames.
    pub fn sequence(&mut self) -> u8 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    /// Samples sent so far.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// The samples due at SITL time `t` \[s\], if any: the present one
    /// first, then (`ahead_s > 0`) the trajectory ahead. `offboard` says
    /// whether the autopilot is in offboard, `position` is the vehicle's
    /// (NED \[m\]; the trajectory starts there), `time_boot_ms` the
    /// autopilot clock at `t` (the samples ahead are stamped ahead of it).
    pub fn due(
        &mut self,
        t: f64,
        offboard: bool,
        position: Vector3<f64>,
        time_boot_ms: u32,
        target_system: u8,
    ) -> Vec<MavMessage> {
        if offboard && self.offboard_since.is_none() {
            self.offboard_since = Some(t);
        }
        let Some(since) = self.offboard_since else {
            return Vec::new();
        };
        if self.stream.is_none() {
            if t < since + self.config.start_after_s {
                return Vec::new();
            }
            let c = &self.config;
            self.stream = Some((
                Trajectory {
                    shape: c.shape,
                    size: c.size,
                    speed: c.speed,
                    ramp_s: c.ramp_s,
                    start: position,
                },
                t,
            ));
        }
        let Some((trajectory, t0)) = self.stream else {
            return Vec::new();
        };
        if self.config.duration_s > 0.0 && t - t0 > self.config.duration_s {
            return Vec::new();
        }
        let period = 1.0 / self.config.rate_hz;
        if self.last_sent.is_some_and(|last| t - last < period - 1e-9) {
            return Vec::new();
        }
        self.last_sent = Some(t);
        self.sent += 1;
        let ahead = (self.config.ahead_s * self.config.rate_hz).round() as usize;
        (0..=ahead)
            .map(|k| {
                let dt = k as f64 * period;
                let stamp = time_boot_ms.wrapping_add((dt * 1e3).round() as u32);
                self.sample(&trajectory.at(t - t0 + dt), stamp, target_system)
            })
            .collect()
    }

    /// One SET_POSITION_TARGET_LOCAL_NED of the trajectory's point `p`.
    fn sample(&self, p: &TrajectoryPoint, time_boot_ms: u32, target_system: u8) -> MavMessage {
        use PositionTargetTypemask as M;
        let c = &self.config;
        let mut mask = M::empty();
        if !c.yaw {
            mask |= M::POSITION_TARGET_TYPEMASK_YAW_IGNORE
                | M::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
        }
        if c.fields != PlannerFields::Pva {
            mask |= M::POSITION_TARGET_TYPEMASK_AX_IGNORE
                | M::POSITION_TARGET_TYPEMASK_AY_IGNORE
                | M::POSITION_TARGET_TYPEMASK_AZ_IGNORE;
        }
        if c.fields == PlannerFields::P {
            mask |= M::POSITION_TARGET_TYPEMASK_VX_IGNORE
                | M::POSITION_TARGET_TYPEMASK_VY_IGNORE
                | M::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
        }
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
            time_boot_ms,
            x: p.position.x as f32,
            y: p.position.y as f32,
            z: p.position.z as f32,
            vx: p.velocity.x as f32,
            vy: p.velocity.y as f32,
            vz: p.velocity.z as f32,
            afx: p.acceleration.x as f32,
            afy: p.acceleration.y as f32,
            afz: p.acceleration.z as f32,
            yaw: if c.yaw { p.yaw as f32 } else { 0.0 },
            yaw_rate: if c.yaw { p.yaw_rate as f32 } else { 0.0 },
            type_mask: mask,
            target_system,
            target_component: c.target_component,
            coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(m: &MavMessage) -> SET_POSITION_TARGET_LOCAL_NED_DATA {
        match m {
            MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) => d.clone(),
            other => panic!("{other:?}"),
        }
    }

    /// Nothing before offboard and `start_after_s`; then samples at the
    /// rate, from where the vehicle was, with p, v, a and yaw set and
    /// addressed to the daemon; nothing after `duration_s`.
    #[test]
    fn streams_after_offboard_at_its_rate_and_stops() {
        let mut p = Planner::new(PlannerConfig {
            start_after_s: 1.0,
            duration_s: 2.0,
            ..PlannerConfig::default()
        });
        let here = Vector3::new(1.0, 2.0, -10.0);
        let dt = 0.005;
        let mut samples = Vec::new();
        for k in 0..1200 {
            let t = k as f64 * dt;
            for m in p.due(t, t >= 0.5, here, (t * 1e3) as u32, 1) {
                samples.push((t, fields(&m)));
            }
        }
        let (t_first, first) = &samples[0];
        assert!((t_first - 1.5).abs() < 1e-9, "{t_first}");
        assert!((first.x as f64 - 1.0).abs() < 1e-6 && (first.y as f64 - 2.0).abs() < 1e-6);
        assert_eq!((first.target_system, first.target_component), (1, 191));
        assert!(
            !first
                .type_mask
                .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE)
        );
        assert!(
            !first
                .type_mask
                .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE)
        );
        assert!(
            !first
                .type_mask
                .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
        );
        // 20 Hz over 2 s: 41 samples (both ends).
        assert_eq!(samples.len(), 41, "{}", samples.len());
        assert_eq!(p.sent(), 41);
        let (t_last, last) = samples.last().unwrap();
        assert!((t_last - 3.5).abs() < 1e-6, "{t_last}");
        // At speed by then: the velocity is set.
        assert!((last.vx as f64).hypot(last.vy as f64) > 1.0, "{last:?}");
    }
}
