//! Round trips against each model's own `step`: random states within ±35°
//! of tilt, random inputs and parameters, both frames. Simulate R + 1 steps,
//! read the outputs, and check that at offsets j = 0 and 1
//! Λ(y_j..y_{j+R−1}) = x_j, F(y_j..y_{j+R}) = u_j and (planar, spatial)
//! F⁻¹(y_j..y_{j+R−1}, u_j) = y_{j+R}.
//!
//! Tolerance: `|err| ≤ 1e-9·max(1, |ref|)`, loosened only for quantities
//! that divide a third or fourth difference by δt³ or δt⁴ (attitude and
//! thrust commands, body rates, torques) to twice the float64 round-off
//! bound derived in `common/mod.rs`.

mod common;

use std::f64::consts::PI;

use common::{U, accel_roundoff, close, frame, max_abs};
use dflat_model::full::{FullInput, FullOutput, FullState};
use dflat_model::planar::{PlanarInput, PlanarState};
use dflat_model::spatial::{SpatialInput, SpatialState};
use dflat_model::{
    FlatModel, FullModel, FullParams, PlanarModel, PlanarParams, SpatialModel, SpatialParams,
};
use proptest::array::{uniform2, uniform3};
use proptest::prelude::*;

/// 35° in radians: the tilt bound of the random states.
const TILT: f64 = 35.0 * PI / 180.0;

/// States x_0..x_{n} and outputs y_0..y_{n} from x_0 and n inputs.
fn simulate<M: FlatModel>(
    m: &M,
    x0: M::State,
    inputs: &[M::Input],
) -> (Vec<M::State>, Vec<M::Output>) {
    let mut xs = vec![x0];
    for u in inputs {
        let next = m.step(xs.last().unwrap(), u);
        xs.push(next);
    }
    let ys = xs.iter().map(|x| m.output(x)).collect();
    (xs, ys)
}

/// Linear drag \[1/s\]: none (the paper's model) or up to 1.5 /s (far
/// beyond a multirotor's 0.1–0.5 /s).
fn drag() -> impl Strategy<Value = f64> {
    prop_oneof![Just(0.0), 0.0..1.5f64]
}

fn planar_params() -> impl Strategy<Value = PlanarParams> {
    (
        0.005..0.05f64,
        0.05..0.5f64,
        0.7..1.3f64,
        9.78..9.83f64,
        -PI..PI,
        frame(),
        drag(),
    )
        .prop_map(|(dt, tau, k, g, psi, frame, drag_h)| PlanarParams {
            dt,
            tau,
            k,
            g,
            psi,
            frame,
            drag_h,
        })
}

fn spatial_params() -> impl Strategy<Value = SpatialParams> {
    // τ_T in [δt, δt + 0.2 s]: forward Euler of a lag overshoots (and the
    // thrust goes negative) when δt > τ_T, which no real vehicle does.
    (
        planar_params(),
        0.0..0.2f64,
        drag(),
        prop_oneof![Just(0.0), 0.0..0.5f64],
    )
        .prop_map(|(p, extra, drag_v, drag_rotor)| SpatialParams {
            dt: p.dt,
            tau: p.tau,
            k: p.k,
            tau_thrust: p.dt + extra,
            g: p.g,
            psi: p.psi,
            frame: p.frame,
            drag_h: p.drag_h,
            drag_v,
            drag_rotor,
        })
}

fn full_params() -> impl Strategy<Value = FullParams> {
    (
        0.005..0.05f64,
        0.5..15.0f64,
        9.78..9.83f64,
        uniform2(0.005..1.0f64),
        0.01..1.5f64,
        frame(),
    )
        .prop_map(|(dt, m, g, [ixx, iyy], izz, frame)| FullParams {
            dt,
            m,
            g,
            ixx,
            iyy,
            izz,
            frame,
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn planar_round_trips(
        p in planar_params(),
        pos in uniform2(-20.0..20.0f64),
        vel in uniform2(-10.0..10.0f64),
        att in uniform2(-TILT..TILT),
        cmds in proptest::collection::vec(uniform2(-0.6..0.6f64), 4),
    ) {
        let m = PlanarModel::new(p).unwrap();
        let x0 = PlanarState::from([pos[0], vel[0], pos[1], vel[1], att[0], att[1]]);
        let us: Vec<PlanarInput> = cmds.iter().map(|c| PlanarInput::from(*c)).collect();
        let (xs, ys) = simulate(&m, x0, &us);
        let p_max = max_abs(ys.iter().map(|y| y.as_slice()));
        // |t| = g/(cθ·cφ) ≥ g in the planar model.
        let d_angle = 2.0 * accel_roundoff(p_max, p.dt) / p.g;
        let d_cmd = 2.0 * d_angle * (1.0 + 2.0 * p.tau / p.dt) / p.k;
        for j in 0..2 {
            let x = m.state_from_outputs(&ys[j..j + 3]).unwrap();
            close("state", x.as_slice(), xs[j].as_slice(), &[])?;
            let u = m.input_from_outputs(&ys[j..j + 4]).unwrap();
            close("input", u.as_slice(), us[j].as_slice(), &[d_cmd, d_cmd])?;
            let y = m.next_output(&ys[j..j + 3], &us[j]).unwrap();
            close("next_output", y.as_slice(), ys[j + 3].as_slice(), &[])?;
        }
    }

    #[test]
    fn spatial_round_trips(
        p in spatial_params(),
        pos in uniform3(-20.0..20.0f64),
        vel in uniform3(-10.0..10.0f64),
        att in uniform2(-TILT..TILT),
        thrust in 0.5..1.5f64,
        cmds in proptest::collection::vec((uniform2(-0.6..0.6f64), 0.5..1.5f64), 4),
    ) {
        let m = SpatialModel::new(p).unwrap();
        let x0 = SpatialState::from([
            pos[0], vel[0], pos[1], vel[1], pos[2], vel[2], att[0], att[1], thrust * p.g,
        ]);
        let us: Vec<SpatialInput> =
            cmds.iter().map(|(a, t)| SpatialInput::new(a[0], a[1], t * p.g)).collect();
        let (xs, ys) = simulate(&m, x0, &us);
        // The rotor drag's part along the thrust axis must not outweigh
        // the thrust (no multirotor flies there; the maps then say
        // FreeFall).
        prop_assume!(xs.iter().all(|x| {
            let speed = (x[1] * x[1] + x[3] * x[3] + x[5] * x[5]).sqrt();
            x[8] > 2.0 * p.drag_rotor * speed
        }));
        let p_max = max_abs(ys.iter().map(|y| y.as_slice()));
        let t_min = xs.iter().map(|x| x[8]).fold(f64::INFINITY, f64::min);
        let e_a = accel_roundoff(p_max, p.dt);
        let d_angle = 2.0 * e_a / t_min;
        let d_cmd = 2.0 * d_angle * (1.0 + 2.0 * p.tau / p.dt) / p.k;
        let d_thrust = 2.0 * e_a * (1.0 + 2.0 * p.tau_thrust / p.dt);
        for j in 0..2 {
            let x = m.state_from_outputs(&ys[j..j + 3]).unwrap();
            close("state", x.as_slice(), xs[j].as_slice(), &[])?;
            let u = m.input_from_outputs(&ys[j..j + 4]).unwrap();
            close("input", u.as_slice(), us[j].as_slice(), &[d_cmd, d_cmd, d_thrust])?;
            let y = m.next_output(&ys[j..j + 3], &us[j]).unwrap();
            close("next_output", y.as_slice(), ys[j + 3].as_slice(), &[])?;
        }
    }

    #[test]
    fn full_round_trips(
        p in full_params(),
        pos in uniform3(-20.0..20.0f64),
        vel in uniform3(-10.0..10.0f64),
        att in uniform2(-TILT..TILT),
        psi in -10.0..10.0f64,
        rates in uniform3(-1.0..1.0f64),
        // Thrust near hover ±50 %, angular accelerations within ±3 rad/s².
        cmds in proptest::collection::vec((0.5..1.5f64, uniform3(-3.0..3.0f64)), 6),
    ) {
        let m = FullModel::new(p).unwrap();
        let x0 = FullState::from([
            pos[0], vel[0], pos[1], vel[1], pos[2], vel[2], att[0], att[1], psi,
            rates[0], rates[1], rates[2],
        ]);
        let us: Vec<FullInput> = cmds
            .iter()
            .map(|(t, a)| FullInput::new(t * p.m * p.g, a[0] * p.ixx, a[1] * p.iyy, a[2] * p.izz))
            .collect();
        let (xs, ys) = simulate(&m, x0, &us[..5]);
        let p_max = max_abs(ys.iter().map(|y| y.as_slice()));
        let t_min = us.iter().map(|u| u[0] / p.m).fold(f64::INFINITY, f64::min);
        let t_max = us.iter().map(|u| u[0] / p.m).fold(0.0, f64::max);
        let w_max = max_abs(xs.iter().map(|x| &x.as_slice()[9..12]));
        let i_max = p.ixx.max(p.iyy).max(p.izz);
        let i_diff = (p.ixx - p.iyy).abs().max((p.iyy - p.izz).abs()).max((p.izz - p.ixx).abs());
        let d_angle = 2.0 * accel_roundoff(p_max, p.dt) / t_min + U * p_max;
        let d_rate = 2.0 * 2.0 * d_angle / p.dt;
        let d_torque = 2.0 * (i_max * 2.0 * d_rate / p.dt + i_diff * 2.0 * w_max * d_rate);
        let state_extra = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0 * d_rate, 2.0 * d_rate, 2.0 * d_rate];
        for j in 0..2 {
            let x = m.state_from_outputs(&ys[j..j + 4]).unwrap();
            close("state", x.as_slice(), xs[j].as_slice(), &state_extra)?;
            let u = m.input_from_outputs(&ys[j..j + 5]).unwrap();
            close("input", u.as_slice(), us[j].as_slice(), &[0.0, d_torque, d_torque, d_torque])?;
        }

        // General prediction: Λ(y_0..y_3), then step with u_0..u_3 → y_4, y_5.
        // The only new error is Λ's body-rate error integrated over n ≤ 6
        // steps (‖W⁻¹R‖ ≤ 3 below ~60° of tilt): yaw and tilt errors grow to
        // d_angle + n·δt·3·d_rate, and the positions by t_max·that·(n·δt)².
        let (_, ys6) = simulate(&m, x0, &us[..6]);
        let mut out = [FullOutput::zeros(); 2];
        m.predict_outputs(&ys6[..4], &us[..4], &mut out).unwrap();
        let d_pred = d_angle + 6.0 * p.dt * 3.0 * 2.0 * d_rate;
        let d_pos = 2.0 * t_max * d_pred * (6.0 * p.dt).powi(2);
        for (i, o) in out.iter().enumerate() {
            close("prediction", o.as_slice(), ys6[4 + i].as_slice(), &[d_pos, d_pos, d_pos, 2.0 * d_pred])?;
        }
    }
}
