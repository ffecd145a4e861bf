//! One controller tick (window update + prediction + solve + output-to-input
//! map) for horizons N ∈ {50, 100, 200, 400, 800}, planar model, 2 axes.
//!
//! * `df_mpc::fast_tick` — DF-MPC, no binding constraint: banded Cholesky.
//! * `df_mpc::smooth_tick` — DF-MPC with the command-smoothness term
//!   (half-bandwidth 4), classic window.
//! * `df_mpc::multirate_smooth_tick` — steady-state tick with multi-rate
//!   windows (15 Hz samples, 60 ms late) and the smoothness term.
//! * `df_mpc::tilt_constrained_tick` — DF-MPC with a 15° tilt bound as a
//!   box per axis that binds on both axes (banded interior point, the
//!   default); `tilt_constrained_tick_clarabel` the same solved by clarabel.
//! * `df_mpc::tilt_cone_tick` — the 15° bound as the tilt cone (both axes
//!   in one banded interior point); `tilt_cone_tick_clarabel` the same SOCP
//!   in clarabel. Percentiles over a corner manoeuvre: `benches/corner.rs`.
//! * `df_mpc::tilt_rate_tick` — the 15° box plus a 150°/s tilt-rate bound
//!   (the first tick of a 10 m step: the rate rows bind from the first
//!   command), banded interior point; `tilt_rate_tick_clarabel` the same
//!   solved by clarabel.
//! * `df_mpc::qp_banded` / `df_mpc::qp_clarabel` — the same unconstrained
//!   DF QP (both axes) solved by the banded solver and handed whole to
//!   clarabel: the generic baseline (`qp_clarabel` with the KKT tuning
//!   dflat ships, `qp_clarabel_defaults` with clarabel's own).
//!
//! Each tick iteration resets the controller and runs the first tick from
//! rest 10 m from the setpoint, so every iteration solves the same problem.
//!
//! Run: `cargo bench -p dflat-control`.

#![allow(missing_docs)]

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, OutputConstraints, PlanTiltBound, QpSolver};
use dflat_control::optimise::{
    AxisBounds, AxisProblem, ClarabelSolver, FastBandedSolver, KktTuning, Smoothness,
};
use dflat_control::window::MultiRateSettings;
use dflat_control::{ControlModel, Controller, Frame, Measurement, ReferenceSource};
use dflat_model::{PlanarModel, PlanarParams};
use divan::{Bencher, black_box};
use nalgebra::Vector3;

const HORIZONS: &[usize] = &[50, 100, 200, 400, 800];
const DT: f64 = 0.02;

fn main() {
    divan::main();
}

/// Constant setpoint.
struct Setpoint(Vector3<f64>);

impl ReferenceSource for Setpoint {
    fn horizon(&mut self, _measured: &Vector3<f64>, _dt: f64, out: &mut [Vector3<f64>]) {
        out.iter_mut().for_each(|o| *o = self.0);
    }
    fn closest(&mut self, _measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        (self.0, Vector3::zeros())
    }
}

fn model() -> ControlModel {
    ControlModel::Planar(
        PlanarModel::new(PlanarParams {
            psi: 0.6,
            frame: Frame::Ned,
            ..Default::default()
        })
        .unwrap(),
    )
}

fn measurement() -> Measurement {
    Measurement {
        t: 0.0,
        position: Vector3::new(0.0, 0.0, -2.0),
        yaw: 0.6,
    }
}

fn target() -> Setpoint {
    Setpoint(Vector3::new(8.0, -6.0, -2.0))
}

mod df_mpc {
    use super::*;

    fn bench_tick(bencher: Bencher, settings: DfMpcSettings, expect_constrained: bool) {
        let mut ctrl = DfMpc::new(model(), settings).unwrap();
        let mut reference = target();
        let m = measurement();
        let out = ctrl.update(&m, &mut reference).unwrap();
        assert_eq!(out.constrained, expect_constrained);
        bencher.bench_local(|| {
            ctrl.reset();
            black_box(ctrl.update(black_box(&m), &mut reference).unwrap())
        });
    }

    /// DF-MPC tick, fast path (no constraints), 2 axes.
    #[divan::bench(args = HORIZONS)]
    fn fast_tick(bencher: Bencher, n: usize) {
        let settings = DfMpcSettings {
            horizon: n,
            ..Default::default()
        };
        bench_tick(bencher, settings, false);
    }

    fn tilt_constrained(n: usize, qp_solver: QpSolver) -> DfMpcSettings {
        tilt_bounded(n, qp_solver, PlanTiltBound::Box)
    }

    fn tilt_bounded(n: usize, qp_solver: QpSolver, bound: PlanTiltBound) -> DfMpcSettings {
        DfMpcSettings {
            horizon: n,
            constraints: OutputConstraints {
                max_tilt: Some(15f64.to_radians()),
                ..Default::default()
            },
            plan_tilt_bound: bound,
            qp_solver,
            solver_time_limit: f64::INFINITY,
            ..Default::default()
        }
    }

    /// DF-MPC tick with a binding 15° tilt constraint, 2 axes: the banded
    /// interior point (the default).
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_constrained_tick(bencher: Bencher, n: usize) {
        bench_tick(bencher, tilt_constrained(n, QpSolver::Banded), true);
    }

    /// DF-MPC tick with a binding 15° tilt *cone* (both axes in one QP,
    /// banded interior point, cold: every iteration is the first tick).
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_cone_tick(bencher: Bencher, n: usize) {
        bench_tick(
            bencher,
            tilt_bounded(n, QpSolver::Banded, PlanTiltBound::Cone),
            true,
        );
    }

    /// As `tilt_cone_tick`, the same cone problem solved by clarabel (SOCP).
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_cone_tick_clarabel(bencher: Bencher, n: usize) {
        bench_tick(
            bencher,
            tilt_bounded(n, QpSolver::Clarabel, PlanTiltBound::Cone),
            true,
        );
    }

    fn tilt_rate(n: usize, qp_solver: QpSolver) -> DfMpcSettings {
        let mut s = tilt_constrained(n, qp_solver);
        s.constraints.max_tilt_rate = Some(150f64.to_radians());
        s
    }

    /// DF-MPC tick with the 15° box and a 150°/s tilt-rate bound, both
    /// binding (banded interior point).
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_rate_tick(bencher: Bencher, n: usize) {
        bench_tick(bencher, tilt_rate(n, QpSolver::Banded), true);
    }

    /// As `tilt_rate_tick`, solved by clarabel.
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_rate_tick_clarabel(bencher: Bencher, n: usize) {
        bench_tick(bencher, tilt_rate(n, QpSolver::Clarabel), true);
    }

    /// As `tilt_constrained_tick`, solved by clarabel.
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn tilt_constrained_tick_clarabel(bencher: Bencher, n: usize) {
        bench_tick(bencher, tilt_constrained(n, QpSolver::Clarabel), true);
    }

    /// DF-MPC tick with the command-smoothness term (half-bandwidth 4),
    /// classic window, 2 axes (first tick from rest, as `fast_tick`).
    #[divan::bench(args = HORIZONS)]
    fn smooth_tick(bencher: Bencher, n: usize) {
        let settings = DfMpcSettings {
            horizon: n,
            smoothness_weight: [50.0; 3],
            ..Default::default()
        };
        bench_tick(bencher, settings, false);
    }

    /// Steady-state DF-MPC tick with multi-rate windows (M = 25, arrival
    /// cost) and the smoothness term, 2 axes: a 15 Hz pose sample, 60 ms
    /// late, every third tick, hovering at the setpoint; 200 ticks of
    /// warm-up, then every iteration is the next tick (window shift, arrival
    /// update, fit, 2·M F⁻¹ steps, banded solve, F).
    #[divan::bench(args = HORIZONS)]
    fn multirate_smooth_tick(bencher: Bencher, n: usize) {
        let settings = DfMpcSettings {
            horizon: n,
            smoothness_weight: [50.0; 3],
            multi_rate: Some(MultiRateSettings::default()),
            ..Default::default()
        };
        let mut ctrl = DfMpc::new(model(), settings).unwrap();
        let hover = Vector3::new(0.0, 0.0, -2.0);
        let mut reference = Setpoint(hover);
        let mut k = 0u64;
        let mut tick = move |ctrl: &mut DfMpc, reference: &mut Setpoint| {
            let t = k as f64 * DT;
            if k.is_multiple_of(3) {
                let wiggle = 0.002 * ((k % 7) as f64 - 3.0);
                ctrl.observe(&Measurement {
                    t: t - 0.06,
                    position: hover + Vector3::new(wiggle, -wiggle, 0.0),
                    yaw: 0.6,
                });
            }
            k += 1;
            ctrl.update(&Measurement { t, ..measurement() }, reference)
                .unwrap()
        };
        for _ in 0..200 {
            tick(&mut ctrl, &mut reference);
        }
        bencher.bench_local(|| black_box(tick(&mut ctrl, &mut reference)));
    }

    fn qp_data(n: usize) -> ([[f64; 3]; 2], Vec<f64>, Vec<f64>) {
        let fixed = [[0.0, 0.01, 0.021], [0.0, -0.005, -0.011]];
        (fixed, vec![8.0; n + 1], vec![-6.0; n + 1])
    }

    /// The unconstrained DF QP on 2 axes, banded solver (solve only, the
    /// two axes together as in the tick).
    #[divan::bench(args = HORIZONS)]
    fn qp_banded(bencher: Bencher, n: usize) {
        let s = DfMpcSettings::default();
        let (q, r) = (s.tracking_weight[0], s.jerk_weight[0]);
        let mut solver = FastBandedSolver::new(n, q, r, DT).unwrap();
        let (fixed, rx, ry) = qp_data(n);
        let (mut px, mut py) = (vec![0.0; n + 1], vec![0.0; n + 1]);
        bencher.bench_local(|| {
            let a = AxisProblem {
                fixed: &fixed[0],
                sent: None,
                reference: black_box(&rx),
                plan: &mut px,
            };
            let b = AxisProblem {
                fixed: &fixed[1],
                sent: None,
                reference: black_box(&ry),
                plan: &mut py,
            };
            solver.solve_pair(a, b).unwrap();
            black_box(px[3] + py[3])
        });
    }

    fn bench_qp_clarabel(bencher: Bencher, n: usize, tuning: KktTuning) {
        let s = DfMpcSettings::default();
        let (q, r) = (s.tracking_weight[0], s.jerk_weight[0]);
        let new = || {
            let (bounds, smooth) = (AxisBounds::default(), Smoothness::default());
            ClarabelSolver::with_tuning(n, (q, r, DT), bounds, f64::INFINITY, smooth, tuning)
                .unwrap()
        };
        let mut solvers = [new(), new()];
        let (fixed, rx, ry) = qp_data(n);
        let mut plan = vec![0.0; n + 1];
        bencher.bench_local(|| {
            solvers[0]
                .solve_problem(AxisProblem::new(&fixed[0], black_box(&rx), &mut plan))
                .unwrap();
            solvers[1]
                .solve_problem(AxisProblem::new(&fixed[1], black_box(&ry), &mut plan))
                .unwrap();
            black_box(plan[3])
        });
    }

    /// The same unconstrained DF QP on 2 axes handed to clarabel (solve
    /// only), with the KKT tuning dflat ships for constrained solves.
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn qp_clarabel(bencher: Bencher, n: usize) {
        bench_qp_clarabel(bencher, n, KktTuning::SHIPPED);
    }

    /// As `qp_clarabel` with clarabel's default KKT settings.
    #[divan::bench(args = HORIZONS, sample_count = 20, sample_size = 5)]
    fn qp_clarabel_defaults(bencher: Bencher, n: usize) {
        bench_qp_clarabel(bencher, n, KktTuning::CLARABEL_DEFAULTS);
    }
}

// ---------------------------------------------------------------------------
// Flatness MPC (owned by the Flatness MPC engineer).
// ---------------------------------------------------------------------------

mod fmpc {
    use super::*;
    use dflat_control::fmpc::{FlatnessMpc, FmpcSettings};

    /// Flatness MPC tick, 2 axes: flat state from finite differences, the
    /// three needed rows of the precomputed gain H⁻¹Γᵀq (O(N) per axis),
    /// feedback linearisation. Same fixtures as the DF-MPC ticks.
    #[divan::bench(args = HORIZONS)]
    fn fmpc_tick(bencher: Bencher, n: usize) {
        let settings = FmpcSettings {
            horizon: n,
            ..Default::default()
        };
        let mut ctrl = FlatnessMpc::new(model(), settings).unwrap();
        let mut reference = target();
        let m = measurement();
        bencher.bench_local(|| {
            ctrl.reset();
            black_box(ctrl.update(black_box(&m), &mut reference).unwrap())
        });
    }
}
