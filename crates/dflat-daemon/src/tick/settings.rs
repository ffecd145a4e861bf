//! The control core's settings, built once from the configuration: angles
//! in radians, times in seconds, each part's own (the pose clock, the
//! vehicle, the goals, the failsafe). The core reads these, never the raw
//! [`Config`].

use dflat_control::reference::{Reference, StreamSettings};
use dflat_control::{ControlError, Controller};
use dflat_link::Target;

use crate::config::{
    AutopilotKind, Config, PoseSourceKind, PoseTime, ThrustMode, TimeBase, YawMode,
};
use crate::control::configured_path;

/// Everything the control core decides with that the configuration sets.
#[derive(Debug, Clone)]
pub struct CoreSettings {
    /// Tick period \[s\] (`controller.rate_hz`).
    pub period: f64,
    /// The controller observes every pose (multi-rate).
    pub multi_rate: bool,
    /// The autopilot commands go to (`link.system_id`,
    /// `link.autopilot_component`).
    pub target: Target,
    /// Poses in.
    pub pose: PoseSettings,
    /// The vehicle and its autopilot.
    pub vehicle: VehicleSettings,
    /// Goals and their references.
    pub goals: GoalSettings,
    /// The failsafe and the stop.
    pub failsafe: FailsafeSettings,
    /// The messages the autopilot is asked to stream at the tick rate
    /// (`link.request_streams`; empty: none asked).
    pub streams: Vec<crate::stream_rates::StreamRequest>,
}

/// Poses in (`[link]`, `[safety]`).
#[derive(Debug, Clone, Copy)]
pub struct PoseSettings {
    /// Which clock stamps a pose (`link.pose_time`).
    pub time: PoseTime,
    /// The pose message (`link.pose_source`).
    pub source: PoseSourceKind,
    /// The pose clock's lag bound \[s\] (`safety.pose_max_latency_ms`).
    pub max_latency: f64,
    /// Margin of the pose jump check \[m\] (`safety.pose_jump_margin_m`).
    pub jump_margin: f64,
    /// The pose clock's window \[s\] (`link.pose_clock_window_s`).
    pub clock_window: f64,
    /// The least latency a pose has \[s\] (`link.pose_min_latency_ms`).
    pub min_latency: f64,
}

/// The vehicle and its autopilot (`[vehicle]`, `link.autopilot`).
#[derive(Debug, Clone, Copy)]
pub struct VehicleSettings {
    /// Tilt limit \[rad\] (`vehicle.max_tilt_deg`).
    pub max_tilt: f64,
    /// The model's fixed heading ψ⋆ \[rad\] (`vehicle.yaw_deg`).
    pub yaw: f64,
    /// How the heading is commanded (`vehicle.yaw_mode`).
    pub yaw_mode: YawMode,
    /// How far ahead a stream's heading is commanded \[s\]:
    /// `vehicle.yaw_lead_s` plus the input delay the controller plans over
    /// (`vehicle.delay_ms`, in whole control ticks), so a heading sent now
    /// is the stream's when it acts.
    pub yaw_lead: f64,
    /// Heading rate limit \[rad/s\] (`vehicle.max_yaw_rate_deg_s`).
    pub max_yaw_rate: f64,
    /// Attitude time constant τ \[s\] (`vehicle.tau`).
    pub tau: f64,
    /// Attitude gain k̃ \[-\] (`vehicle.k`).
    pub k: f64,
    /// Gravity \[m/s²\] (`vehicle.gravity`).
    pub gravity: f64,
    /// Hover thrust \[0–1\] (`vehicle.hover_thrust`).
    pub hover_thrust: f64,
    /// Fly the autopilot's hover thrust (`vehicle.hover_thrust_from_autopilot`).
    pub hover_thrust_from_autopilot: bool,
    /// How thrust is sent (`vehicle.thrust_mode`).
    pub thrust_mode: ThrustMode,
    /// The autopilot's family, or `Auto` (`link.autopilot`).
    pub autopilot: AutopilotKind,
}

/// Goals and their references (`[stream]`, `[mission]`, `safety.max_speed_mps`).
#[derive(Debug, Clone)]
pub struct GoalSettings {
    /// The stream's reference (`[stream]`).
    pub stream: StreamSettings,
    /// Which clock stamps a stream sample (`stream.time_base`).
    pub stream_time_base: TimeBase,
    /// A sample jumping further is refused \[m\] (`stream.max_jump_m`).
    pub stream_max_jump: f64,
    /// No sample for this long: the stream is lost \[s\] (`stream.timeout_s`).
    pub stream_timeout: f64,
    /// Speed of routes and missions \[m/s\] (`mission.speed`).
    pub speed: f64,
    /// Ramps of a setpoint's route \[m/s²\] (`stream.route_acceleration`).
    pub route_acceleration: f64,
    /// A mission section's start ramp \[m/s²\] (`mission.start_acceleration`).
    pub start_acceleration: f64,
    /// The speed limit \[m/s\] (`safety.max_speed_mps`).
    pub max_speed: f64,
    /// Braking deceleration at engagement \[m/s²\] (see
    /// [`super::brake_acceleration`]).
    pub brake_acceleration: f64,
    /// The attitude loop's lag before braking builds up \[s\] (τ/2).
    pub brake_lag: f64,
    /// The configured path (`mission.path`), if it has two waypoints.
    pub path: Option<Result<Reference, ControlError>>,
}

/// The failsafe and the stop (`[safety]`).
#[derive(Debug, Clone, Copy)]
pub struct FailsafeSettings {
    /// Ticks a command may be held (`safety.hold_last_ticks`).
    pub hold_ticks: u32,
    /// Longest level hover \[s\] (`safety.level_hover_max_ms`).
    pub level_hover_max: f64,
    /// The stop's braking time \[s\] (`safety.stop_brake_ms`).
    pub stop_brake: f64,
    /// The stop's level time \[s\] (`safety.stop_level_ms`).
    pub stop_level: f64,
    /// The stop asks the autopilot to hold (`safety.stop_requests_hold`).
    pub stop_requests_hold: bool,
    /// The model residual's failsafe threshold \[m\]
    /// (`safety.residual_failsafe_m`).
    pub residual_failsafe: f64,
}

impl CoreSettings {
    /// The settings of `config` (validated) for `controller`.
    pub fn new(config: &Config, controller: &dyn Controller) -> Self {
        let (link, vehicle, safety) = (&config.link, &config.vehicle, &config.safety);
        Self {
            period: 1.0 / config.controller.rate_hz,
            multi_rate: controller.multi_rate(),
            target: Target {
                system: link.system_id,
                component: link.autopilot_component,
            },
            pose: PoseSettings {
                time: link.pose_time,
                source: link.pose_source,
                max_latency: safety.pose_max_latency_ms / 1000.0,
                jump_margin: safety.pose_jump_margin_m,
                clock_window: link.pose_clock_window_s,
                min_latency: link.pose_min_latency_ms / 1000.0,
            },
            vehicle: VehicleSettings {
                max_tilt: vehicle.max_tilt_deg.to_radians(),
                yaw: vehicle.yaw_deg.to_radians(),
                yaw_mode: vehicle.yaw_mode,
                yaw_lead: vehicle.yaw_lead_s
                    + crate::control::delay_ticks(config) as f64 / config.controller.rate_hz,
                max_yaw_rate: vehicle.max_yaw_rate_deg_s.to_radians(),
                tau: vehicle.tau,
                k: vehicle.k,
                gravity: vehicle.gravity,
                hover_thrust: vehicle.hover_thrust,
                hover_thrust_from_autopilot: vehicle.hover_thrust_from_autopilot,
                thrust_mode: vehicle.thrust_mode,
                autopilot: link.autopilot,
            },
            goals: GoalSettings::new(config),
            failsafe: FailsafeSettings {
                hold_ticks: safety.hold_last_ticks,
                level_hover_max: safety.level_hover_max_ms / 1000.0,
                stop_brake: safety.stop_brake_ms / 1000.0,
                stop_level: safety.stop_level_ms / 1000.0,
                stop_requests_hold: safety.stop_requests_hold,
                residual_failsafe: safety.residual_failsafe_m,
            },
            streams: if link.request_streams {
                crate::stream_rates::requests_for(
                    link.pose_source,
                    !link.pose_components.is_empty(),
                    config.controller.rate_hz,
                )
            } else {
                Vec::new()
            },
        }
    }
}

impl GoalSettings {
    /// The goal settings of `config` (validated).
    pub fn new(config: &Config) -> Self {
        let s = &config.stream;
        Self {
            stream: s.settings(),
            stream_time_base: s.time_base,
            stream_max_jump: s.max_jump_m,
            stream_timeout: s.timeout_s,
            speed: config.mission.speed,
            route_acceleration: s.route_acceleration,
            start_acceleration: config.mission.start_acceleration,
            max_speed: config.safety.max_speed_mps,
            brake_acceleration: super::brake_acceleration(config),
            brake_lag: 0.5 * config.vehicle.tau,
            path: configured_path(config),
        }
    }
}
