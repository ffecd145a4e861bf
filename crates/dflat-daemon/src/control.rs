//! From the configuration to the controller, the reference and the thrust
//! mapping the control loop runs with.

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, InputSaturation};
use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::reference::Reference;
use dflat_control::{ControlError, ControlModel, Controller, TiltLimit};
use dflat_link::ThrustMapping;
use dflat_model::{Frame, PlanarModel, PlanarParams, SpatialModel, SpatialParams};
use nalgebra::Vector3;

use crate::config::{Config, ControllerKind, ModelKind, ThrustMode};

/// Smallest specific thrust the spatial model may command \[m/s²\].
const THRUST_MIN: f64 = 2.0;
/// Largest vertical acceleration the PD baseline may demand \[m/s²\].
const PD_MAX_VERTICAL_ACCELERATION: f64 = 4.0;

/// The control model of `[vehicle]` at step δt = 1 / `controller.rate_hz`.
pub fn control_model(cfg: &Config) -> Result<ControlModel, ControlError> {
    let v = &cfg.vehicle;
    let dt = 1.0 / cfg.controller.rate_hz;
    let psi = v.yaw_deg.to_radians();
    Ok(match v.model {
        ModelKind::Planar => ControlModel::Planar(PlanarModel::new(PlanarParams {
            dt,
            tau: v.tau,
            k: v.k,
            g: v.gravity,
            psi,
            frame: Frame::Ned,
            drag_h: v.drag_h,
        })?),
        ModelKind::Spatial => ControlModel::Spatial(SpatialModel::new(SpatialParams {
            dt,
            tau: v.tau,
            k: v.k,
            tau_thrust: v.tau_thrust,
            g: v.gravity,
            psi,
            frame: Frame::Ned,
            drag_h: v.drag_h,
            drag_v: v.drag_v,
            drag_rotor: v.drag_rotor,
        })?),
    })
}

/// How SET_ATTITUDE_TARGET's thrust is filled (`vehicle.thrust_mode`).
pub fn thrust_mapping(cfg: &Config) -> ThrustMapping {
    let v = &cfg.vehicle;
    match v.thrust_mode {
        ThrustMode::Fixed => ThrustMapping::Fixed(v.thrust_value),
        ThrustMode::Normalized => ThrustMapping::Normalized {
            hover_thrust: v.hover_thrust,
            gravity: v.gravity,
        },
    }
}

/// `vehicle.delay_ms` rounded to control ticks at `controller.rate_hz`.
pub fn delay_ticks(cfg: &Config) -> usize {
    (cfg.vehicle.delay_ms * 1e-3 * cfg.controller.rate_hz)
        .round()
        .clamp(0.0, dflat_control::dfmpc::MAX_DELAY_TICKS as f64) as usize
}

/// The controller chosen by `controller.kind`, with the configured model,
/// weights, horizons, saturation (`vehicle.max_tilt_deg` as a bound on the
/// combined tilt, [`TiltLimit::Cone`], as the exit guard applies it) and
/// constraints;
/// for fmpc and pd the state source (`[controller.estimator]`: by default
/// a state estimator fed with every pose, then the shell feeds them through
/// [`Controller::observe`]);
/// for df-mpc (`[controller.dfmpc]`) also the smoothness weight, the
/// multi-rate window (`controller.dfmpc.multi_rate`, then the shell feeds
/// every pose through [`Controller::observe`]) and the disturbance
/// estimator (`[controller.disturbance]`), and the learned residual
/// (`controller.dfmpc.learned_model`, [`crate::learned::configured`]).
pub fn build_controller(cfg: &Config) -> Result<Box<dyn Controller>, ControlError> {
    let model = control_model(cfg)?;
    let c = &cfg.controller;
    let v = &cfg.vehicle;
    let max_tilt = v.max_tilt_deg.to_radians();
    Ok(match c.kind {
        ControllerKind::DfMpc => {
            let d = &c.dfmpc;
            let settings = DfMpcSettings {
                horizon: d.horizon,
                tracking_weight: d.q,
                jerk_weight: d.r_jerk,
                saturation: Some(InputSaturation {
                    max_tilt,
                    // As the exit guard bounds it: the window records what is sent.
                    tilt_limit: TiltLimit::Cone,
                    thrust_min: THRUST_MIN,
                    // Normalised thrust 1 is g / hover_thrust.
                    thrust_max: (v.gravity / v.hover_thrust).max(THRUST_MIN + 1.0),
                }),
                constraints: c.output_constraints(),
                qp_solver: d.qp_solver,
                plan_tilt_bound: d.plan_tilt_bound,
                smoothness_weight: d.smoothness_weight,
                multi_rate: c.multi_rate(),
                disturbance: c.disturbance.settings(),
                delay_ticks: delay_ticks(cfg),
                ..DfMpcSettings::default()
            };
            let mut mpc = DfMpc::new(model, settings)?;
            mpc.set_learned(crate::learned::configured(cfg)?);
            Box::new(mpc)
        }
        ControllerKind::Fmpc => Box::new(FlatnessMpc::new(
            model,
            FmpcSettings {
                horizon: c.fmpc.horizon,
                q: c.fmpc.q,
                r: c.fmpc.r_jerk,
                max_tilt: Some(max_tilt),
                tilt_limit: TiltLimit::Cone,
                state: c.estimator.state_source(c, v),
            },
        )?),
        ControllerKind::Pd => Box::new(Pd::new(
            model,
            PdSettings {
                kp: [c.pd.kp; 3],
                kd: [c.pd.kd; 3],
                max_horizontal_acceleration: v.gravity * max_tilt.tan(),
                max_vertical_acceleration: PD_MAX_VERTICAL_ACCELERATION.min(0.9 * v.gravity),
                velocity_cutoff_hz: None,
                max_tilt,
                tilt_limit: TiltLimit::Cone,
                corners: c.pd.corners(),
                state: c.estimator.state_source(c, v),
                acceleration_feed_forward: false,
            },
        )?),
    })
}

/// The configured path (`mission.path` at `mission.speed`), if it has at
/// least two waypoints.
pub fn configured_path(cfg: &Config) -> Option<Result<Reference, ControlError>> {
    let m = &cfg.mission;
    (m.path.len() >= 2).then(|| {
        let points: Vec<Vector3<f64>> = m.path.iter().map(|p| Vector3::from(*p)).collect();
        let path = Reference::path(&points, m.speed)?;
        if m.start_acceleration > 0.0 {
            // From rest (a path starts or resumes after braking).
            path.with_ramp(0.0, m.start_acceleration)
        } else {
            Ok(path)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_control::{Measurement, ReferenceSource};

    fn hover(controller: &mut dyn Controller, at: [f64; 3]) {
        let mut reference = Reference::setpoint(Vector3::from(at)).unwrap();
        for k in 0..10 {
            let m = Measurement {
                t: k as f64 * 0.02,
                position: Vector3::from(at),
                yaw: 0.0,
            };
            // Multi-rate controllers take the sample here, the others ignore it.
            controller.observe(&m);
            let out = controller
                .update(&m, &mut reference as &mut dyn ReferenceSource)
                .unwrap();
            assert!(out.command.is_finite());
            assert!(out.command.pitch.abs() < 1e-9 && out.command.roll.abs() < 1e-9);
        }
    }

    #[test]
    fn every_kind_builds_from_the_shipped_defaults_and_hovers_level() {
        for kind in [
            ControllerKind::DfMpc,
            ControllerKind::Fmpc,
            ControllerKind::Pd,
        ] {
            let mut cfg = Config::default();
            cfg.controller.kind = kind;
            let mut c = build_controller(&cfg).unwrap();
            hover(c.as_mut(), [1.0, 2.0, -10.0]);
            cfg.vehicle.model = ModelKind::Spatial;
            cfg.vehicle.thrust_mode = ThrustMode::Normalized;
            let mut c = build_controller(&cfg).unwrap();
            hover(c.as_mut(), [1.0, 2.0, -10.0]);
        }
    }

    #[test]
    fn thrust_mappings() {
        let mut cfg = Config::default();
        assert_eq!(thrust_mapping(&cfg), ThrustMapping::Fixed(0.5));
        cfg.vehicle.thrust_mode = ThrustMode::Normalized;
        let m = thrust_mapping(&cfg);
        assert!((m.normalized(cfg.vehicle.gravity).unwrap() - 0.5).abs() < 1e-12);
    }
}
