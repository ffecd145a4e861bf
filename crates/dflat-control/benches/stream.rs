//! The tick's cost with a streamed reference (issue 22): DF-MPC with the
//! daemon's set-up (multi-rate window, smoothness term) tracking a 4 m/s,
//! 6 m circle streamed at 20 Hz with p, v, a — a new sample every 2–3
//! ticks (`Reference::push_sample`), the clock set each tick
//! (`Reference::set_time`), the horizon predicted by the coordinated turn.
//! Next to it, in the same run, the same tick with a fixed setpoint at the
//! vehicle, and the stream's horizon alone.
//!
//! Run: `cargo bench -p dflat-control --bench stream`.

#![allow(missing_docs)]

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::reference::{Reference, StreamSample, StreamSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller, Frame, Measurement, ReferenceSource};
use dflat_model::{PlanarModel, PlanarParams};
use divan::{Bencher, black_box};
use nalgebra::Vector3;

const HORIZONS: &[usize] = &[100, 200];
const DT: f64 = 0.02;
const RADIUS: f64 = 6.0;
const SPEED: f64 = 4.0;

fn main() {
    divan::main();
}

fn model() -> ControlModel {
    ControlModel::Planar(
        PlanarModel::new(PlanarParams {
            frame: Frame::Ned,
            ..Default::default()
        })
        .unwrap(),
    )
}

fn settings(n: usize) -> DfMpcSettings {
    DfMpcSettings {
        horizon: n,
        smoothness_weight: [50.0; 3],
        multi_rate: Some(MultiRateSettings::default()),
        ..Default::default()
    }
}

/// The circle's sample at `t`.
fn sample(t: f64) -> StreamSample {
    let w = SPEED / RADIUS;
    let (s, c) = (w * t).sin_cos();
    StreamSample {
        t,
        position: Vector3::new(RADIUS * c, RADIUS * s, -10.0),
        velocity: Some(Vector3::new(-SPEED * s, SPEED * c, 0.0)),
        acceleration: Some(Vector3::new(-SPEED * w * c, -SPEED * w * s, 0.0)),
        yaw: None,
        yaw_rate: None,
    }
}

/// One tick at tick number `k` on the circle (the vehicle on it).
fn tick(ctrl: &mut DfMpc, reference: &mut Reference, k: u64) {
    let t = k as f64 * DT;
    // 20 Hz samples: at ticks 0, 2.5, 5, … (rounded down).
    if (k * 2) % 5 < 2 {
        let _ = reference.push_sample(&sample((k * 2 / 5) as f64 * 0.05));
    }
    let m = Measurement {
        t,
        position: sample(t).position,
        yaw: 0.0,
    };
    ctrl.observe(&m);
    reference.set_time(t);
    black_box(ctrl.update(&m, reference).unwrap());
}

/// Steady-state DF-MPC tick on the streamed circle (200 ticks of warm-up,
/// then each iteration is the next tick).
#[divan::bench(args = HORIZONS)]
fn stream_tick(bencher: Bencher, n: usize) {
    let mut ctrl = DfMpc::new(model(), settings(n)).unwrap();
    let mut reference = Reference::stream(StreamSettings::default(), &sample(0.0)).unwrap();
    let mut k = 0;
    for _ in 0..200 {
        tick(&mut ctrl, &mut reference, k);
        k += 1;
    }
    bencher.bench_local(|| {
        tick(&mut ctrl, &mut reference, k);
        k += 1;
    });
}

/// The same tick with a fixed setpoint at the vehicle (no preview of
/// motion): the reference's share of `stream_tick` is the difference.
#[divan::bench(args = HORIZONS)]
fn setpoint_tick(bencher: Bencher, n: usize) {
    let mut ctrl = DfMpc::new(model(), settings(n)).unwrap();
    let mut reference = Reference::setpoint(sample(0.0).position).unwrap();
    let mut k = 0u64;
    let mut step = move |ctrl: &mut DfMpc, reference: &mut Reference| {
        let m = Measurement {
            t: k as f64 * DT,
            position: sample(0.0).position,
            yaw: 0.0,
        };
        k += 1;
        ctrl.observe(&m);
        black_box(ctrl.update(&m, reference).unwrap());
    };
    for _ in 0..200 {
        step(&mut ctrl, &mut reference);
    }
    bencher.bench_local(|| step(&mut ctrl, &mut reference));
}

/// The stream's horizon alone (N + 1 points of the coordinated turn).
#[divan::bench(args = HORIZONS)]
fn stream_horizon(bencher: Bencher, n: usize) {
    let mut reference = Reference::stream(StreamSettings::default(), &sample(1.0)).unwrap();
    reference.set_time(1.013);
    let mut out = vec![Vector3::zeros(); n + 1];
    bencher.bench_local(|| {
        reference.horizon(&Vector3::zeros(), DT, &mut out);
        black_box(&out);
    });
}
