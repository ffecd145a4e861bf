//! A tick without a new pose (the measurement's time is not newer than the
//! last one) must not be read as a stop: the controllers substitute their
//! own prediction (PD: its velocity estimate; DF-MPC: F⁻¹ over the window
//! with the input already sent). Flown on the planar model's own step with
//! poses missing on some ticks, each controller must reach the setpoint and
//! keep its command as smooth as with a pose every tick.
//!
//! PD is flown with a pose only every other tick. DF-MPC is flown with an
//! isolated tick without pose every fifth tick (what phase jitter between
//! a 50 Hz pose stream and the 50 Hz loop produces in the daemon): its
//! window reconstructs the state from second differences, so a predicted
//! output that later ticks difference again amplifies errors by
//! −(1 + 2β) ≈ −2.8 (β = 1 − δt/τ) per substitution. Isolated predictions
//! leave the 3-sample window after three ticks; a pose stream that is
//! *persistently* slower than the loop needs the multi-rate window
//! (`DfMpcSettings::multi_rate`), not repeated predictions. (Flatness MPC, the paper's
//! baseline, carries its finite-difference state forward along the
//! quadratic through its three newest poses, never entering a prediction
//! into its differences: `baseline_pose_timing.rs` flies it through
//! missing, late and skipped poses.)

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::pd::{Pd, PdSettings};
use dflat_control::{ControlModel, Controller, Measurement};
use dflat_model::{FlatModel, Frame, PlanarModel, PlanarParams};
use nalgebra::{Vector2, Vector3};

mod common;
use common::{DT, Setpoint};

fn model() -> (PlanarModel, ControlModel) {
    let m = PlanarModel::new(PlanarParams {
        dt: DT,
        frame: Frame::Ned,
        psi: 0.3,
        ..Default::default()
    })
    .unwrap();
    (m, ControlModel::Planar(m))
}

/// Flies 4 s towards a 3 m setpoint; a new pose arrives at the ticks where
/// `fresh(k)` (the others repeat the last one with its old time). Returns
/// the largest tick-to-tick change of the pitch command \[rad\] and the final
/// distance to the setpoint \[m\].
fn fly(ctrl: &mut dyn Controller, fresh: &dyn Fn(usize) -> bool) -> (f64, f64) {
    fly_stamped(ctrl, fresh, false)
}

/// As [`fly`]; with `restamp` a tick without a new pose passes the old
/// position with the tick's own time — the naive shell, which the
/// controller cannot tell from a pose that did not move.
fn fly_stamped(
    ctrl: &mut dyn Controller,
    fresh: &dyn Fn(usize) -> bool,
    restamp: bool,
) -> (f64, f64) {
    let (m, _) = model();
    let mut x = nalgebra::SVector::<f64, 6>::zeros();
    let mut reference = Setpoint(Vector3::new(3.0, -2.0, 0.0));
    let mut last = Measurement {
        t: 0.0,
        position: Vector3::zeros(),
        yaw: 0.3,
    };
    let mut prev_pitch: Option<f64> = None;
    let mut max_jump: f64 = 0.0;
    for k in 0..200 {
        if fresh(k) {
            last = Measurement {
                t: k as f64 * DT,
                position: Vector3::new(x[0], x[2], 0.0),
                yaw: 0.3,
            };
        } else if restamp {
            last.t = k as f64 * DT;
        }
        let out = ctrl.update(&last, &mut reference).unwrap();
        if let Some(p) = prev_pitch {
            max_jump = max_jump.max((out.command.pitch - p).abs());
        }
        prev_pitch = Some(out.command.pitch);
        x = m.step(&x, &Vector2::new(out.command.pitch, out.command.roll));
    }
    let d = ((x[0] - 3.0).powi(2) + (x[2] + 2.0).powi(2)).sqrt();
    (max_jump, d)
}

fn check(make: &dyn Fn() -> Box<dyn Controller>, fresh: &dyn Fn(usize) -> bool) {
    let (jump_every, d_every) = fly(make().as_mut(), &|_| true);
    let (jump_half, d_half) = fly(make().as_mut(), fresh);
    assert!(
        d_every < 0.2 && d_half < 0.2,
        "not reached: {d_every} {d_half}"
    );
    // Without the substitution a repeated pose spikes the command by tens
    // of degrees; with it the jumps stay comparable to the every-tick run.
    assert!(
        jump_half < 2.0 * jump_every + 0.02,
        "stale poses spike the command: {jump_half} vs {jump_every}"
    );
}

#[test]
fn pd_extrapolates_through_ticks_without_pose() {
    check(
        &|| Box::new(Pd::new(model().1, PdSettings::default()).unwrap()) as Box<dyn Controller>,
        &|k| k % 2 == 0,
    );
}

/// Every fifth tick has no new pose.
fn isolated_gaps(k: usize) -> bool {
    k % 5 != 4
}

#[test]
fn df_mpc_predicts_through_ticks_without_pose() {
    // The library defaults (q = 5, r = 0.01) and the lab's recommended
    // weights (q = 1, r = 0.003, smoothness s = 50).
    check(
        &|| {
            Box::new(DfMpc::new(model().1, DfMpcSettings::default()).unwrap())
                as Box<dyn Controller>
        },
        &isolated_gaps,
    );
    check(
        &|| {
            let settings = DfMpcSettings {
                tracking_weight: [1.0; 3],
                jerk_weight: [0.003; 3],
                smoothness_weight: [50.0; 3],
                ..DfMpcSettings::default()
            };
            Box::new(DfMpc::new(model().1, settings).unwrap()) as Box<dyn Controller>
        },
        &isolated_gaps,
    );
}

/// Negative control: the same flight with the stale pose re-stamped as new
/// (what a shell without the "not newer" rule would pass) reads every gap
/// as a stop, and the command spikes far beyond the substituted run's.
#[test]
fn df_mpc_without_the_substitution_spikes_the_command() {
    let make = || DfMpc::new(model().1, DfMpcSettings::default()).unwrap();
    let (jump_every, _) = fly(&mut make(), &|_| true);
    let (jump_substituted, _) = fly(&mut make(), &isolated_gaps);
    let (jump_naive, _) = fly_stamped(&mut make(), &isolated_gaps, true);
    println!(
        "largest pitch step: every tick {jump_every:.4} rad, gaps substituted \
         {jump_substituted:.4} rad, gaps re-stamped {jump_naive:.4} rad"
    );
    assert!(
        jump_naive > 3.0 * jump_substituted && jump_naive > 2.0 * jump_every + 0.02,
        "naive {jump_naive} vs substituted {jump_substituted} vs every tick {jump_every}"
    );
}
