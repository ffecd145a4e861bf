//! The SITL autopilot's own position controller (pure): what flies
//! OFFBOARD position setpoints addressed to the autopilot, AUTO_LOITER
//! (hold), goto and return-to-launch — the loop PX4's `mc_pos_control`
//! closes around its attitude controller.
//!
//! A PD on position and velocity with feed-forward of the setpoint's
//! velocity and acceleration:
//!
//! ```text
//! a = a_ff + Kp·(p_ref − p) + Kd·(v_ref − v)      (NED, m/s²)
//! ```
//!
//! the horizontal part limited to `g·tan(max_tilt)` (its direction kept),
//! then the tilt that produces it at the current yaw (ZYX: at ψ = 0 a
//! nose-down pitch accelerates north, `ẍ = −g·tanθ`, `ÿ = g·tanφ/cosθ`)
//! and the collective thrust that holds the vertical part. Pure: the state
//! and the setpoint enter as arguments.
//!
//! With the plant's first-order attitude lag τ the loop
//! `τs³ + s² + Kd·s + Kp` is stable for `Kd > τ·Kp`; the default gains
//! ([`PositionGains::OFFBOARD`]) keep a margin of 5× at τ = 0.2 s.

use dflat_control::AttitudeCommand;
use dflat_link::MavMessage;
use dflat_link::dialect::{MavFrame, PositionTargetTypemask};

use dflat_sim::plant::{PlantOptions, PlantState};

/// Gains of the position loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionGains {
    /// Horizontal position gain Kp \[1/s²\].
    pub kp_xy: f64,
    /// Horizontal velocity gain Kd \[1/s\].
    pub kd_xy: f64,
    /// Vertical position gain \[1/s²\].
    pub kp_z: f64,
    /// Vertical velocity gain \[1/s\].
    pub kd_z: f64,
    /// Largest tilt the loop asks for \[deg\].
    pub max_tilt_deg: f64,
}

impl PositionGains {
    /// The gains that fly OFFBOARD position setpoints, goto and RTL:
    /// about 1.7 rad/s closed-loop, well damped with τ = 0.2 s.
    pub const OFFBOARD: Self = Self {
        kp_xy: 3.0,
        kd_xy: 3.0,
        kp_z: 3.0,
        kd_z: 3.0,
        max_tilt_deg: 30.0,
    };
}

/// A position setpoint with feed-forward, local NED.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionTarget {
    /// Position \[m\].
    pub position: [f64; 3],
    /// Velocity feed-forward \[m/s\] (zero when not given).
    pub velocity: [f64; 3],
    /// Acceleration feed-forward \[m/s²\] (zero when not given).
    pub acceleration: [f64; 3],
    /// Yaw \[rad\] (`None`: keep the current heading).
    pub yaw: Option<f64>,
}

impl PositionTarget {
    /// Hold `position` (no feed-forward, current heading).
    pub fn hold(position: [f64; 3]) -> Self {
        Self {
            position,
            velocity: [0.0; 3],
            acceleration: [0.0; 3],
            yaw: None,
        }
    }
}

/// Why a SET_POSITION_TARGET_LOCAL_NED is not flown by the SITL (the
/// refusal text, said rate-limited).
pub fn position_target(msg: &MavMessage) -> Option<Result<PositionTarget, &'static str>> {
    let MavMessage::SET_POSITION_TARGET_LOCAL_NED(d) = msg else {
        return None;
    };
    let m = d.type_mask;
    let ignored = |b: PositionTargetTypemask| m.contains(b);
    use PositionTargetTypemask as T;
    if d.coordinate_frame != MavFrame::MAV_FRAME_LOCAL_NED {
        return Some(Err("SITL: setpoint refused: frame not LOCAL_NED"));
    }
    if ignored(T::POSITION_TARGET_TYPEMASK_X_IGNORE)
        || ignored(T::POSITION_TARGET_TYPEMASK_Y_IGNORE)
        || ignored(T::POSITION_TARGET_TYPEMASK_Z_IGNORE)
    {
        return Some(Err("SITL: setpoint refused: position required"));
    }
    let pick = |ign: bool, v: [f32; 3]| {
        if ign { [0.0; 3] } else { v.map(f64::from) }
    };
    let velocity = pick(
        ignored(T::POSITION_TARGET_TYPEMASK_VX_IGNORE),
        [d.vx, d.vy, d.vz],
    );
    let acceleration = pick(
        ignored(T::POSITION_TARGET_TYPEMASK_AX_IGNORE)
            || ignored(T::POSITION_TARGET_TYPEMASK_FORCE_SET),
        [d.afx, d.afy, d.afz],
    );
    let yaw = (!ignored(T::POSITION_TARGET_TYPEMASK_YAW_IGNORE)).then_some(f64::from(d.yaw));
    let t = PositionTarget {
        position: [d.x, d.y, d.z].map(f64::from),
        velocity,
        acceleration,
        yaw,
    };
    let finite = t
        .position
        .iter()
        .chain(&t.velocity)
        .chain(&t.acceleration)
        .chain(t.yaw.iter())
        .all(|x| x.is_finite());
    Some(if finite {
        Ok(t)
    } else {
        Err("SITL: setpoint refused: not finite")
    })
}

/// The acceleration the loop asks for, NED \[m/s²\] (horizontal part
/// limited to `g·tan(max_tilt)`, its direction kept).
pub fn acceleration(
    gains: &PositionGains,
    g: f64,
    target: &PositionTarget,
    position: [f64; 3],
    velocity: [f64; 3],
) -> [f64; 3] {
    let mut a: [f64; 3] = std::array::from_fn(|i| {
        let (kp, kd) = if i < 2 {
            (gains.kp_xy, gains.kd_xy)
        } else {
            (gains.kp_z, gains.kd_z)
        };
        target.acceleration[i]
            + kp * (target.position[i] - position[i])
            + kd * (target.velocity[i] - velocity[i])
    });
    let max_h = g * gains.max_tilt_deg.to_radians().tan();
    let h = a[0].hypot(a[1]);
    if h > max_h {
        a[0] *= max_h / h;
        a[1] *= max_h / h;
    }
    // Never ask for less than a quarter g of thrust, nor more than 2 g.
    a[2] = a[2].clamp(-g, 0.75 * g);
    a
}

/// The attitude and thrust command that produces `a` (NED \[m/s²\]) at
/// heading `yaw` \[rad\] (ZYX; thrust through the plant's thrust map).
pub fn attitude_for(options: &PlantOptions, g: f64, a: [f64; 3], yaw: f64) -> AttitudeCommand {
    let (sy, cy) = yaw.sin_cos();
    let a_fwd = cy * a[0] + sy * a[1];
    let a_right = -sy * a[0] + cy * a[1];
    let pitch = (-a_fwd / g).atan();
    let roll = (a_right * pitch.cos() / g).atan();
    let specific = (g - a[2]) / (pitch.cos() * roll.cos()).max(0.5);
    AttitudeCommand {
        pitch,
        roll,
        yaw,
        thrust: options.thrust_command_for(specific),
    }
}

/// One step of the loop: the command that flies `target` from state `s`.
pub fn command(
    gains: &PositionGains,
    options: &PlantOptions,
    target: &PositionTarget,
    s: &PlantState,
) -> AttitudeCommand {
    let a = acceleration(
        gains,
        options.g,
        target,
        s.position.into(),
        s.velocity.into(),
    );
    attitude_for(options, options.g, a, target.yaw.unwrap_or(s.yaw))
}

/// Cruise speed of goto, hold and return-to-launch \[m/s\] (PX4's
/// `MPC_XY_CRUISE` default).
pub const CRUISE_SPEED: f64 = 5.0;
/// Acceleration of the moving target of goto / RTL \[m/s²\].
pub const CRUISE_ACCEL: f64 = 2.0;

/// One step `dt` \[s\] of a target moving from `position` at `velocity`
/// towards `goal` (NED): accelerating at most `accel`, at most `speed`,
/// braking to stop at the goal. Returns the new (position, velocity).
pub fn approach(
    position: [f64; 3],
    velocity: [f64; 3],
    goal: [f64; 3],
    dt: f64,
    speed: f64,
    accel: f64,
) -> ([f64; 3], [f64; 3]) {
    let d = [
        goal[0] - position[0],
        goal[1] - position[1],
        goal[2] - position[2],
    ];
    let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if dist < 1e-6 {
        return (goal, [0.0; 3]);
    }
    // The speed from which braking at `accel` stops at the goal.
    let v_des = speed.min((2.0 * accel * dist).sqrt());
    let want = d.map(|x| x / dist * v_des);
    let dv = [
        want[0] - velocity[0],
        want[1] - velocity[1],
        want[2] - velocity[2],
    ];
    let n = (dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2]).sqrt();
    let scale = if n > accel * dt { accel * dt / n } else { 1.0 };
    let v = [
        velocity[0] + dv[0] * scale,
        velocity[1] + dv[1] * scale,
        velocity[2] + dv[2] * scale,
    ];
    let step = [v[0] * dt, v[1] * dt, v[2] * dt];
    let step_len = (step[0] * step[0] + step[1] * step[1] + step[2] * step[2]).sqrt();
    if step_len >= dist {
        return (goal, [0.0; 3]);
    }
    (
        [
            position[0] + step[0],
            position[1] + step[1],
            position[2] + step[2],
        ],
        v,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_link::dialect::SET_POSITION_TARGET_LOCAL_NED_DATA;
    use dflat_sim::plant::{PlantKind, build_plant};
    use nalgebra::Vector3;

    fn options() -> PlantOptions {
        PlantOptions {
            plant_dt: 1.0 / 200.0,
            attitude_tau: 0.2,
            tilt_limit: 35f64.to_radians(),
            ..PlantOptions::default()
        }
    }

    #[test]
    fn feed_forward_alone_gives_the_tilt_of_the_acceleration() {
        let o = options();
        let t = PositionTarget {
            position: [0.0; 3],
            velocity: [0.0; 3],
            acceleration: [2.0, 0.0, 0.0],
            yaw: Some(0.0),
        };
        let a = acceleration(&PositionGains::OFFBOARD, o.g, &t, [0.0; 3], [0.0; 3]);
        assert_eq!(a, [2.0, 0.0, 0.0]);
        let c = attitude_for(&o, o.g, a, 0.0);
        // Nose down accelerates north.
        assert!((c.pitch - (-2.0 / o.g).atan()).abs() < 1e-12);
        assert!(c.roll.abs() < 1e-12);
        // East at ψ = 90° is forward: pitch, not roll.
        let c = attitude_for(&o, o.g, [0.0, 2.0, 0.0], std::f64::consts::FRAC_PI_2);
        assert!((c.pitch - (-2.0 / o.g).atan()).abs() < 1e-9 && c.roll.abs() < 1e-9);
    }

    #[test]
    fn the_horizontal_demand_is_limited_in_norm() {
        let o = options();
        let g = PositionGains::OFFBOARD;
        let t = PositionTarget::hold([100.0, 100.0, 0.0]);
        let a = acceleration(&g, o.g, &t, [0.0; 3], [0.0; 3]);
        let max = o.g * g.max_tilt_deg.to_radians().tan();
        assert!((a[0].hypot(a[1]) - max).abs() < 1e-9);
        assert!((a[0] - a[1]).abs() < 1e-12, "direction kept");
    }

    #[test]
    fn flies_a_step_without_overshooting_much() {
        let o = options();
        let mut plant = build_plant(PlantKind::Spatial, &o, 1).unwrap();
        plant.reset(&PlantState::hover(Vector3::new(0.0, 0.0, -2.0), o.g));
        let target = PositionTarget::hold([5.0, 0.0, -2.0]);
        let mut max_x: f64 = 0.0;
        for _ in 0..(8 * 200) {
            let c = command(&PositionGains::OFFBOARD, &o, &target, &plant.true_state());
            plant.apply(&c);
            plant.advance(o.plant_dt);
            max_x = max_x.max(plant.true_state().position.x);
        }
        let s = plant.true_state();
        assert!((s.position.x - 5.0).abs() < 0.05, "{:?}", s.position);
        assert!((s.position.z + 2.0).abs() < 0.05, "{:?}", s.position);
        assert!(max_x < 5.5, "overshoot {max_x}");
    }

    #[test]
    fn the_moving_target_reaches_the_goal_within_its_limits() {
        let (mut p, mut v) = ([0.0; 3], [0.0; 3]);
        let mut max_speed: f64 = 0.0;
        let mut steps = 0;
        while p != [30.0, 40.0, 0.0] && steps < 100_000 {
            let (p2, v2) = approach(p, v, [30.0, 40.0, 0.0], 0.005, CRUISE_SPEED, CRUISE_ACCEL);
            let dv = ((v2[0] - v[0]).powi(2) + (v2[1] - v[1]).powi(2)).sqrt();
            assert!(dv <= CRUISE_ACCEL * 0.005 + 1e-9 || v2 == [0.0; 3]);
            max_speed = max_speed.max(v2[0].hypot(v2[1]));
            (p, v) = (p2, v2);
            steps += 1;
        }
        assert_eq!((p, v), ([30.0, 40.0, 0.0], [0.0; 3]));
        assert!(
            max_speed <= CRUISE_SPEED + 1e-9 && max_speed > 4.9,
            "{max_speed}"
        );
        // 50 m at 5 m/s with 2 m/s² ramps: 12.5 s.
        assert!((f64::from(steps) * 0.005 - 12.5).abs() < 0.2, "{steps}");
    }

    #[test]
    fn setpoints_are_read_with_their_type_mask() {
        let mut d = SET_POSITION_TARGET_LOCAL_NED_DATA {
            coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            type_mask: PositionTargetTypemask::empty(),
            x: 1.0,
            y: 2.0,
            z: -3.0,
            vx: 4.0,
            afx: 0.5,
            yaw: 0.25,
            ..Default::default()
        };
        let t = position_target(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(d.clone()))
            .unwrap()
            .unwrap();
        assert_eq!(t.position, [1.0, 2.0, -3.0]);
        assert_eq!(
            (t.velocity[0], t.acceleration[0], t.yaw),
            (4.0, 0.5, Some(0.25))
        );
        d.type_mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE;
        let t = position_target(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(d.clone()))
            .unwrap()
            .unwrap();
        assert_eq!(
            (t.velocity, t.acceleration, t.yaw),
            ([0.0; 3], [0.0; 3], None)
        );
        d.type_mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE;
        assert!(
            position_target(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(d.clone()))
                .unwrap()
                .is_err()
        );
        d.type_mask = PositionTargetTypemask::empty();
        d.x = f32::NAN;
        assert!(
            position_target(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(d.clone()))
                .unwrap()
                .is_err()
        );
        d.x = 0.0;
        d.coordinate_frame = MavFrame::MAV_FRAME_BODY_FRD;
        assert!(
            position_target(&MavMessage::SET_POSITION_TARGET_LOCAL_NED(d))
                .unwrap()
                .is_err()
        );
    }
}
