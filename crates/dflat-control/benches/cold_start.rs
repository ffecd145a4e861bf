//! Cold solves of the corner's box + tilt-rate problems, axis by axis:
//! the active set's cold start (its working set from the condensed
//! interior point, `optimise/active_set/interior.rs`) against the stage
//! interior point (`BandedInteriorPointSolver`) on the same QPs — the
//! first `TICKS` ticks of the corner replay (`benches/corner.rs`: the L at
//! 8 m/s flown by the cone, replayed with `plan_tilt_bound = "box"`, the
//! 20° tilt and 150°/s tilt rate). Each solve is timed `REPS` times (min).
//!
//! Run: `cargo bench -p dflat-control --bench cold_start` (N = 200; a
//! horizon as argument, e.g. `-- 100`). `docs/performance-log.md`, "The cold
//! start from a condensed interior point".

#![allow(missing_docs)]

#[path = "common/mod.rs"]
mod common;

use std::sync::{Arc, Mutex};
use std::time::Instant;

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, OutputConstraints, PlanTiltBound};
use dflat_control::optimise::alm::AlmTuning;
use dflat_control::optimise::problem::AxisProblem;
use dflat_control::optimise::{
    AxisSolver, BandedInteriorPointSolver, BoxAlmSolver, Carry, SolveFailure, SolveInfo,
};
use dflat_control::reference::Reference;
use dflat_control::{ControlModel, Controller};
use nalgebra::Vector3;

use common::{DT, plant};

/// Ticks of the replay whose problems are solved cold.
const TICKS: usize = 12;
/// Times each solve is repeated (the minimum is reported).
const REPS: usize = 30;

fn settings(n: usize, bound: PlanTiltBound, rate: bool) -> DfMpcSettings {
    DfMpcSettings {
        horizon: n,
        constraints: OutputConstraints {
            max_tilt: Some(20f64.to_radians()),
            max_tilt_rate: rate.then(|| 150f64.to_radians()),
            ..Default::default()
        },
        plan_tilt_bound: bound,
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    }
}

/// One cold solve's outcome: tick, axis; the active set's condensed
/// interior-point iterations, KKT solves and µs; the stage interior
/// point's iterations and µs.
type Row = (usize, usize, usize, usize, f64, usize, f64);

/// Solves every problem it is handed (up to [`TICKS`]) cold with both
/// solvers, then passes it on to the cascade.
struct Cold {
    active_set: BoxAlmSolver,
    interior_point: BandedInteriorPointSolver,
    rows: Arc<Mutex<Vec<Row>>>,
    tick: usize,
    axis: usize,
    scratch: Vec<f64>,
}

impl std::fmt::Debug for Cold {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("cold-start timer")
    }
}

impl Cold {
    fn time(&mut self, a: &AxisProblem<'_>, ip: bool) -> f64 {
        let mut best = f64::INFINITY;
        for _ in 0..REPS {
            self.active_set.carry(Carry::Reset);
            self.scratch.copy_from_slice(a.plan);
            let p = AxisProblem {
                fixed: a.fixed,
                sent: a.sent,
                reference: a.reference,
                plan: &mut self.scratch,
            };
            let start = Instant::now();
            let ok = if ip {
                self.interior_point.solve_problem(p).is_ok()
            } else {
                self.active_set.solve_problem(p).is_ok()
            };
            assert!(
                ok,
                "tick {} axis {}: a cold solve failed",
                self.tick, self.axis
            );
            best = best.min(start.elapsed().as_secs_f64() * 1e6);
        }
        best
    }
}

impl AxisSolver for Cold {
    fn solve(&mut self, a: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        if self.tick < TICKS {
            let t_as = self.time(&a, false);
            let t_ip = self.time(&a, true);
            let work = self.active_set.active_set_work();
            self.rows.lock().unwrap().push((
                self.tick,
                self.axis,
                work.interior,
                work.solves,
                t_as,
                self.interior_point.iterations(),
                t_ip,
            ));
        }
        self.tick += 1;
        Err(SolveFailure::Observer)
    }

    fn carry(&mut self, _event: Carry<'_>) {}

    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }

    /// Both timed solvers take the tick's offsets (none on the corner
    /// replay, which flies without drag).
    fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.active_set.set_offset(offset, slope);
        self.interior_point.set_offset(offset, slope);
    }
}

fn main() {
    let n: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(200);
    let p = plant();
    let corners: Vec<Vector3<f64>> = [[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]]
        .iter()
        .map(|[x, y]| Vector3::new(*x, *y, -2.0))
        .collect();
    // The flight, flown by the cone (as `benches/corner.rs` records it).
    let mut ctrl = DfMpc::new(
        ControlModel::Planar(p),
        settings(n, PlanTiltBound::Cone, false),
    )
    .unwrap();
    let flight = common::record(
        &mut ctrl,
        &mut Reference::path(&corners, 8.0).unwrap(),
        TICKS + 1,
    );
    // Replayed with box + tilt rate, the timer first in each axis's cascade.
    let s = settings(n, PlanTiltBound::Box, true);
    let rows = Arc::new(Mutex::new(Vec::new()));
    let mut ctrl = DfMpc::new(ControlModel::Planar(p), s).unwrap();
    for axis in 0..2 {
        let bounds = *ctrl.bounds(axis).unwrap();
        let smoothness = dflat_control::optimise::Smoothness {
            weight: s.smoothness_weight[axis],
            kappa: p.params().tau / DT,
            gravity: p.params().g,
        };
        let weights = (s.tracking_weight[axis], s.jerk_weight[axis], DT);
        let tuning = AlmTuning {
            max_kkt_solves: 5000,
            ..AlmTuning::default()
        };
        let timer = Cold {
            active_set: BoxAlmSolver::with_tuning(n, weights, bounds, smoothness, true, tuning)
                .unwrap(),
            interior_point: BandedInteriorPointSolver::new(n, weights, bounds, smoothness).unwrap(),
            rows: Arc::clone(&rows),
            tick: 0,
            axis,
            scratch: vec![0.0; n + 1],
        };
        ctrl.box_cascade_mut(axis)
            .unwrap()
            .insert(0, Box::new(timer))
            .unwrap();
    }
    let mut reference = Reference::path(&corners, 8.0).unwrap();
    for m in &flight {
        ctrl.update(m, &mut reference).unwrap();
    }
    println!("cold solves of the corner's box + tilt-rate QPs, N = {n}; min of {REPS}, µs");
    println!(
        "| tick | axis | active set: its interior point's iterations | KKT solves | µs | stage interior point: iterations | µs |"
    );
    println!("|---|---|---|---|---|---|---|");
    for (tick, axis, guess, kkt, t_as, its, t_ip) in rows.lock().unwrap().iter() {
        println!("| {tick} | {axis} | {guess} | {kkt} | {t_as:.0} | {its} | {t_ip:.0} |");
    }
}
