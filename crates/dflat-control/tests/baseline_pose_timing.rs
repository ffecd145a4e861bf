//! The baselines' finite-difference state (`StateSource::FiniteDifference`,
//! the paper's §VI definition) when poses and ticks stop being one to one,
//! as on a starved companion computer (`common::timing`). Differenced as
//! if a tick apart, a repeated pose read at 4 m/s as a 200 m/s² stop:
//! Flatness MPC asked for negative thrust at the first tick without a pose
//! (`FreeFall`), and PD stepped its tilt by up to 1 rad and its thrust by
//! 2.2 m/s² in one tick after a late pose or a skipped tick. The
//! differences now take each pose at its capture time
//! (`dflat_control::estimator::differences`).
//!
//! Each baseline is judged against its own flight with every pose on time:
//! the altitude and the line held, the command as smooth.

use dflat_control::ControlModel;
use dflat_control::estimator::{EstimatorSettings, StateSource};
use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_model::{SpatialModel, SpatialParams};
use proptest::prelude::*;

mod common;
use common::timing::{self, Flown, TICKS, Tick};

fn model() -> ControlModel {
    ControlModel::Spatial(SpatialModel::new(SpatialParams::default()).unwrap())
}

/// Flatness MPC on finite differences flies the line.
fn fmpc(ticks: &dyn Fn(usize) -> Tick) -> Flown {
    let mut c = FlatnessMpc::new(model(), FmpcSettings::default()).unwrap();
    timing::fly(&mut c, 1.0, ticks)
}

/// PD on finite differences flies the line.
fn pd(ticks: &dyn Fn(usize) -> Tick) -> Flown {
    let mut c = Pd::new(model(), PdSettings::default()).unwrap();
    timing::fly(&mut c, 1.0, ticks)
}

/// A baseline's flight of the line under a tick pattern.
type Baseline = fn(&dyn Fn(usize) -> Tick) -> Flown;

/// Both baselines fly `ticks` as they fly every pose on time (no plan
/// tilt-rate bound: no catch-up allowance beyond the clean step).
fn judge_both(ticks: &dyn Fn(usize) -> Tick, what: &str) {
    let baselines: [(&str, Baseline); 2] = [("fmpc", fmpc), ("pd", pd)];
    for (name, fly) in baselines {
        let clean = fly(&|_| Tick::OnTime);
        let perturbed = fly(ticks);
        println!("{name} {what}: {perturbed:?} against {clean:?}");
        timing::judge(&clean, &perturbed, 0.0, &format!("{name}, {what}"));
    }
}

#[test]
fn a_pose_a_tick_late_is_differenced_at_its_time() {
    judge_both(
        &|k| match k % 20 {
            7 => Tick::NoPose,
            8 => Tick::Late,
            _ => Tick::OnTime,
        },
        "a late pose every 20 ticks",
    );
}

#[test]
fn ticks_without_a_pose_are_carried_forward() {
    judge_both(
        &|k| {
            if k % 5 == 0 {
                Tick::NoPose
            } else {
                Tick::OnTime
            }
        },
        "no pose every fifth tick",
    );
}

#[test]
fn skipped_ticks_are_differenced_over_their_gap() {
    judge_both(
        &|k| {
            if k % 17 == 5 {
                Tick::Skipped
            } else {
                Tick::OnTime
            }
        },
        "one tick skipped in 17",
    );
    judge_both(
        &|k| {
            if k % 40 < 3 {
                Tick::Skipped
            } else {
                Tick::OnTime
            }
        },
        "three ticks skipped in 40",
    );
}

/// Skipped ticks and then no new pose: only the shell's clock says how
/// much time passed (`Controller::skipped`). Taken as a step, the state
/// was two steps behind the line for a tick: PD's tilt stepped 0.026 rad
/// there and back against 0.0003 rad on time.
#[test]
fn skipped_ticks_then_no_pose_are_counted_from_the_shells_clock() {
    judge_both(
        &|k| match k % 23 {
            5 | 6 => Tick::Skipped,
            7 => Tick::NoPose,
            _ => Tick::OnTime,
        },
        "two ticks skipped, then no pose, in 23",
    );
}

#[test]
fn a_stream_a_tick_late_for_good_is_carried_to_the_tick() {
    judge_both(
        &|k| if k < 50 { Tick::OnTime } else { Tick::Late },
        "every pose a tick late from tick 50",
    );
}

#[test]
fn poses_taken_off_the_tick_are_differenced_at_their_times() {
    judge_both(
        &|k| Tick::Early(((k * 37 + 11) % 46) as u8),
        "capture times up to 0.45 δt early",
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// Any mix of late poses, ticks without a pose, skipped ticks and poses
    /// taken early, each on up to a fifth of the ticks.
    #[test]
    fn any_mix_of_late_missing_and_skipped_holds_the_line(
        events in prop::collection::vec((0u8..4, 0.0f64..1.0, 0u8..46), TICKS),
        rate in 0.02f64..0.2,
    ) {
        judge_both(&|k| Tick::drawn(events[k], rate), "a random mix");
    }
}

/// A 15 Hz pose stream (vision) on the 50 Hz loop: a new pose every third
/// or fourth tick, taken between the ticks. The paper's differences, a
/// tick apart, read it as a stop for two ticks and then a tripled speed.
/// Differenced at the capture times, each baseline flies it as it does
/// fed by its state estimator (the daemon's default) from the same poses.
#[test]
fn a_15_hz_stream_flies_as_the_estimator_does() {
    let estimator = StateSource::Estimator(EstimatorSettings::for_sensor(0.002, 15.0));
    let fmpc_estimated = {
        let settings = FmpcSettings {
            state: estimator,
            ..FmpcSettings::default()
        };
        timing::fly(
            &mut FlatnessMpc::new(model(), settings).unwrap(),
            1.0,
            &vision_15_hz,
        )
    };
    let pd_estimated = {
        let settings = PdSettings {
            state: estimator,
            ..PdSettings::default()
        };
        timing::fly(&mut Pd::new(model(), settings).unwrap(), 1.0, &vision_15_hz)
    };
    for (name, estimated, differenced) in [
        ("fmpc", fmpc_estimated, fmpc(&vision_15_hz)),
        ("pd", pd_estimated, pd(&vision_15_hz)),
    ] {
        println!("{name}, 15 Hz: {differenced:?} against the estimator's {estimated:?}");
        timing::judge(
            &estimated,
            &differenced,
            0.0,
            &format!("{name}, 15 Hz poses"),
        );
    }
}

/// Tick k of a 15 Hz stream (pose i taken at i/15 s): the newest pose,
/// taken this many hundredths of a step before the tick, or none new.
fn vision_15_hz(k: usize) -> Tick {
    let t = k as f64 * common::DT;
    let newest = (t * 15.0 + 1e-9).floor();
    let previous_tick = ((k as f64 - 1.0) * common::DT * 15.0 + 1e-9).floor();
    if newest > previous_tick {
        let early = (t - newest / 15.0) / common::DT;
        Tick::Early((early * 100.0).round().min(99.0) as u8)
    } else {
        Tick::NoPose
    }
}
