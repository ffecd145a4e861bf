//! Structured input → a controller (DF-MPC in every configuration the
//! daemon can build, Flatness MPC, PD; planar or spatial model) driven
//! through a sequence of ticks with arbitrary, non-finite, huge and
//! jumping poses and setpoints, stale and out-of-order times, poses stamped
//! off the tick, ticks the shell skipped (`Controller::skipped`), an input
//! delay (DF-MPC's `delay_ticks`), failed ticks answered by
//! `plan_fallback`, standby corrections (`correct_last_input`), resets and
//! multi-rate samples.
//!
//! Checks, besides "no panic": every command a controller returns (from
//! `update` or `plan_fallback`) is finite with |pitch|, |roll| within the
//! 35° saturation (with the cone, bit 7 of `kind`, the combined tilt too),
//! the spatial DF-MPC thrust within its limits, and every
//! planned output finite on the axes the model controls (planar models pass
//! the measured z through); a failed tick is an `Err`, never a NaN command.
#![no_main]

use dflat_control::dfmpc::{
    DfMpc, DfMpcSettings, InputSaturation, OutputConstraints, PlanTiltBound,
};
use dflat_control::disturbance::DisturbanceSettings;
use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::window::MultiRateSettings;
use dflat_control::{
    ControlModel, Controller, Frame, Measurement, ReferenceSource, TickOutput, TiltLimit,
};
use dflat_model::{PlanarModel, PlanarParams, SpatialModel, SpatialParams};
use libfuzzer_sys::arbitrary::{self, Arbitrary};
use libfuzzer_sys::fuzz_target;
use nalgebra::Vector3;

const DT: f64 = 0.02;
const MAX_TILT_DEG: f64 = 35.0;

/// A coordinate: mostly ordinary, sometimes hostile.
#[derive(Debug, Clone, Copy, Arbitrary)]
enum Coord {
    Step(i16),
    Jump(f32),
    Nan,
    Inf,
    Huge,
}

impl Coord {
    fn apply(self, previous: f64) -> f64 {
        match self {
            Coord::Step(d) => previous + f64::from(d) * 1e-4,
            Coord::Jump(v) => f64::from(v),
            Coord::Nan => f64::NAN,
            Coord::Inf => f64::INFINITY,
            Coord::Huge => 1e300,
        }
    }
}

#[derive(Debug, Arbitrary)]
enum Op {
    /// One tick with a pose (and, multi-rate, its sample) `steps` ticks on,
    /// the pose stamped `offset_ms` from the tick.
    Tick {
        position: [Coord; 3],
        yaw: Coord,
        steps: i8,
        offset_ms: i8,
    },
    /// The shell skipped `ticks` ticks (its loop stalled).
    Skip {
        ticks: u8,
    },
    /// The autopilot flew its own position mode: this input explains what
    /// the vehicle did (standby).
    Standby([Coord; 3]),
    /// A pose sample between ticks (multi-rate).
    Sample {
        position: [Coord; 3],
        age_ms: u8,
    },
    /// A tick whose update fails (NaN reference), answered by the plan.
    Fail {
        max_steps: u8,
    },
    /// A new setpoint.
    Target([Coord; 3]),
    Reset,
}

#[derive(Debug, Arbitrary)]
struct Input {
    kind: u8,
    spatial: bool,
    multi_rate: bool,
    smooth: bool,
    tilt_bound: bool,
    speed_bound: bool,
    disturbance: bool,
    horizon: u8,
    delay: u8,
    ops: Vec<Op>,
}

struct Reference {
    target: Vector3<f64>,
    broken: bool,
}

impl ReferenceSource for Reference {
    fn horizon(&mut self, _measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        let v = if self.broken {
            Vector3::repeat(f64::NAN)
        } else {
            self.target
        };
        out.iter_mut().for_each(|o| *o = v);
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let v = if self.broken {
            Vector3::repeat(f64::NAN)
        } else {
            self.target
        };
        (v, Vector3::zeros())
    }
}

/// The controller, whether it is a spatial DF-MPC, and whether its tilt
/// limit is the cone (bit 7 of `kind`; else per channel).
fn build(input: &Input) -> Option<(Box<dyn Controller>, bool, bool)> {
    let cone = input.kind & 0x80 != 0;
    let tilt_limit = if cone {
        TiltLimit::Cone
    } else {
        TiltLimit::PerAxis
    };
    let model = if input.spatial {
        ControlModel::Spatial(
            SpatialModel::new(SpatialParams {
                dt: DT,
                frame: Frame::Ned,
                psi: 0.4,
                ..Default::default()
            })
            .ok()?,
        )
    } else {
        ControlModel::Planar(
            PlanarModel::new(PlanarParams {
                dt: DT,
                frame: Frame::Ned,
                psi: 0.4,
                ..Default::default()
            })
            .ok()?,
        )
    };
    let horizon = 10 + usize::from(input.horizon % 60);
    // DF-MPC's plan bound and tilt rate (bits 5 and 6 of `kind`; `kind % 3`
    // picks the controller): the tilt cone in the plan, and the tilt-rate
    // bound of the shipped configs (150°/s), with either plan bound.
    let plan_cone = input.kind & 0x20 != 0;
    let tilt_rate = input.kind & 0x40 != 0;
    let is_df = input.kind % 3 == 0;
    let controller: Box<dyn Controller> = match input.kind % 3 {
        0 => Box::new(
            DfMpc::new(
                model,
                DfMpcSettings {
                    horizon,
                    smoothness_weight: if input.smooth { [20.0; 3] } else { [0.0; 3] },
                    constraints: OutputConstraints {
                        max_tilt: input.tilt_bound.then(|| 20f64.to_radians()),
                        max_speed: input.speed_bound.then_some(3.0),
                        vertical_acceleration: None,
                        max_tilt_rate: tilt_rate.then(|| 150f64.to_radians()),
                    },
                    plan_tilt_bound: if plan_cone {
                        PlanTiltBound::Cone
                    } else {
                        PlanTiltBound::Box
                    },
                    multi_rate: input.multi_rate.then(|| MultiRateSettings {
                        fit_span: 10,
                        ..MultiRateSettings::default()
                    }),
                    disturbance: input.disturbance.then(DisturbanceSettings::default),
                    delay_ticks: usize::from(input.delay % 6),
                    saturation: Some(InputSaturation {
                        tilt_limit,
                        ..InputSaturation::default()
                    }),
                    ..DfMpcSettings::default()
                },
            )
            .ok()?,
        ),
        1 => Box::new(
            FlatnessMpc::new(
                model,
                FmpcSettings {
                    horizon,
                    tilt_limit,
                    ..FmpcSettings::default()
                },
            )
            .ok()?,
        ),
        _ => Box::new(
            Pd::new(
                model,
                PdSettings {
                    tilt_limit,
                    ..PdSettings::default()
                },
            )
            .ok()?,
        ),
    };
    Some((controller, is_df && input.spatial, cone))
}

/// `axes`: the outputs the model controls (a planar model passes the
/// measured z through untouched, whatever it is).
fn check(out: &TickOutput, axes: usize, spatial_df: bool, cone: bool) {
    let c = out.command;
    assert!(c.is_finite(), "non-finite command {c:?}");
    let max = MAX_TILT_DEG.to_radians() + 1e-12;
    assert!(c.pitch.abs() <= max && c.roll.abs() <= max, "tilt {c:?}");
    if cone {
        let t = dflat_control::tilt::tilt(c.pitch, c.roll);
        assert!(t <= max, "combined tilt {t} rad: {c:?}");
    }
    if spatial_df {
        let s = dflat_control::dfmpc::InputSaturation::default();
        assert!(
            c.thrust >= s.thrust_min - 1e-12 && c.thrust <= s.thrust_max + 1e-12,
            "thrust {c:?}"
        );
    }
    for p in &out.plan {
        assert!(
            p.iter().take(axes).all(|v| v.is_finite()),
            "plan {:?}",
            out.plan
        );
    }
}

fuzz_target!(|input: Input| {
    let Some((mut controller, spatial_df, cone)) = build(&input) else {
        return;
    };
    let axes = if input.spatial { 3 } else { 2 };
    let mut reference = Reference {
        target: Vector3::new(3.0, -2.0, -5.0),
        broken: false,
    };
    let mut t = 0.0f64;
    let mut position = Vector3::new(0.0, 0.0, -5.0);
    for op in input.ops.iter().take(200) {
        match op {
            Op::Tick {
                position: p,
                yaw,
                steps,
                offset_ms,
            } => {
                t += f64::from(*steps) * DT;
                for (axis, c) in p.iter().enumerate() {
                    position[axis] = c.apply(position[axis]);
                }
                let m = Measurement {
                    t: t + f64::from(*offset_ms) * 1e-3,
                    position,
                    yaw: yaw.apply(0.4),
                };
                controller.observe(&m);
                if let Ok(out) = controller.update(&m, &mut reference) {
                    check(&out, axes, spatial_df, cone);
                }
                // Keep later steps meaningful after a hostile value.
                if !position.iter().all(|v| v.is_finite() && v.abs() < 1e6) {
                    position = Vector3::new(0.0, 0.0, -5.0);
                }
            }
            Op::Sample {
                position: p,
                age_ms,
            } => {
                let mut s = position;
                for (axis, c) in p.iter().enumerate() {
                    s[axis] = c.apply(s[axis]);
                }
                controller.observe(&Measurement {
                    t: t - f64::from(*age_ms) * 1e-3,
                    position: s,
                    yaw: 0.4,
                });
            }
            Op::Fail { max_steps } => {
                t += DT;
                let m = Measurement {
                    t,
                    position,
                    yaw: 0.4,
                };
                reference.broken = true;
                let result = controller.update(&m, &mut reference);
                reference.broken = false;
                assert!(result.is_err(), "a NaN reference must fail the tick");
                if let Some(out) = controller.plan_fallback(&m, usize::from(*max_steps)) {
                    check(&out, axes, spatial_df, cone);
                }
            }
            Op::Target(p) => {
                for (axis, c) in p.iter().enumerate() {
                    reference.target[axis] = c.apply(reference.target[axis]);
                }
                if !reference.target.iter().all(|v| v.is_finite()) {
                    reference.target = Vector3::new(3.0, -2.0, -5.0);
                }
            }
            Op::Skip { ticks } => {
                t += f64::from(*ticks) * DT;
                controller.skipped(u32::from(*ticks));
            }
            Op::Standby(u) => {
                let mut applied = Vector3::new(0.0, 0.0, 9.81);
                for (axis, c) in u.iter().enumerate() {
                    applied[axis] = c.apply(applied[axis]);
                }
                controller.correct_last_input(&applied);
            }
            Op::Reset => controller.reset(),
        }
    }
});
