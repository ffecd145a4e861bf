//! The L path (0, 0) → (20, 0) → (20, 20) m at 8 m/s from rest, flown in
//! closed loop by DF-MPC as the daemon ships it — multi-rate windows,
//! smoothness 50 on x and y, the plan's tilt box at 20° and the tilt-rate
//! bound 150°/s — on a planar plant with aerodynamics the model has no
//! term for (parasitic drag 0.03 |v|v, rotor drag 0.2 /s in the body
//! plane). Shared by `benches/learned.rs` (each tick timed) and
//! `tests/df_tilt_rate.rs` (which solver took each tick), each
//! `#[path]`-including this file.

#![allow(dead_code)]

use std::time::Instant;

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, OutputConstraints};
use dflat_control::reference::Reference;
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlError, Controller, Measurement, TickOutput};
use dflat_model::{FlatModel, PlanarModel};
use nalgebra::{SVector, Vector2, Vector3};

/// The controller's period \[s\].
const DT: f64 = 0.02;
/// The path's speed [m/s].
pub const SPEED: f64 = 8.0;
/// The tilt-rate bound [deg/s] (the daemon's default).
pub const RATE_DEG_S: f64 = 150.0;

/// DF-MPC's settings at horizon `n` (module docs).
pub fn settings(n: usize) -> DfMpcSettings {
    DfMpcSettings {
        horizon: n,
        smoothness_weight: [50.0, 50.0, 0.0],
        jerk_weight: [0.003; 3],
        multi_rate: Some(MultiRateSettings::default()),
        constraints: OutputConstraints {
            max_tilt: Some(20f64.to_radians()),
            max_tilt_rate: Some(RATE_DEG_S.to_radians()),
            ..OutputConstraints::default()
        },
        solver_time_limit: f64::INFINITY,
        ..DfMpcSettings::default()
    }
}

/// The aerodynamic acceleration [m/s², NED] at the planar state `s`.
fn aero(s: &SVector<f64, 6>) -> Vector3<f64> {
    let v = Vector3::new(s[1], s[3], 0.0);
    let n = dflat_control::learned::thrust_axis(s[5], s[4], 0.0);
    -v * (0.03 * v.norm()) - (v - n * n.dot(&v)) * 0.2
}

/// Flies `ticks` ticks of `mpc` on the planar plant `p` (ψ = 0, NED) at
/// 10 m up, the aerodynamics at the middle of each step; after each
/// update `on_tick(k, mpc, result, µs)` with the update's time. A tick
/// whose update failed sends nothing (the plant is not stepped).
pub fn fly(
    p: &PlanarModel,
    mpc: &mut DfMpc,
    ticks: usize,
    mut on_tick: impl FnMut(usize, &DfMpc, &Result<TickOutput, ControlError>, f64),
) {
    let w = [
        Vector3::new(0.0, 0.0, -10.0),
        Vector3::new(20.0, 0.0, -10.0),
        Vector3::new(20.0, 20.0, -10.0),
    ];
    let mut reference = Reference::path(&w, SPEED).unwrap();
    let mut x = SVector::<f64, 6>::zeros();
    for k in 0..ticks {
        let y = p.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(y.x, y.y, -10.0),
            yaw: 0.0,
        };
        mpc.observe(&m);
        let started = Instant::now();
        let r = mpc.update(&m, &mut reference);
        let us = started.elapsed().as_secs_f64() * 1e6;
        on_tick(k, mpc, &r, us);
        let Ok(o) = r else {
            continue;
        };
        let pre = x;
        x = p.step(&x, &Vector2::new(o.command.pitch, o.command.roll));
        let a = (aero(&pre) + aero(&x)) * 0.5;
        x[1] += DT * a.x;
        x[3] += DT * a.y;
    }
}
