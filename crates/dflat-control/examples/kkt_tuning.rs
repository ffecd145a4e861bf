//! Times the constrained DF solve (one axis, bounds binding) on four
//! problem types: the banded interior point (the default) and clarabel
//! under a few KKT tunings, with the first planned jerk of each so their
//! accuracy can be compared. The data behind `KktTuning::SHIPPED`.
//!
//! Run: `cargo run --release -p dflat-control --example kkt_tuning`.

use dflat_control::optimise::{
    AxisBounds, AxisProblem, BandedInteriorPointSolver, ClarabelSolver, KktTuning, Smoothness,
};

const DT: f64 = 0.02;
const G: f64 = 9.81;
const REPS: usize = 200;

/// One problem: horizon, q, r, smoothness weight, tilt bound \[deg\], fixed
/// window, setpoint.
struct Case {
    name: &'static str,
    horizon: usize,
    q: f64,
    r: f64,
    smoothness: f64,
    tilt_deg: f64,
    fixed: [f64; 3],
    target: f64,
}

/// The shipped tuning's horizon and weights, 30° tilt, moving start.
const SMOOTH_100: Case = Case {
    name: "N=100 smooth",
    horizon: 100,
    q: 1.0,
    r: 0.003,
    smoothness: 50.0,
    tilt_deg: 30.0,
    fixed: [0.0, 0.1, 0.2],
    target: 10.0,
};

const CASES: [Case; 4] = [
    Case {
        name: "bench N=200",
        horizon: 200,
        q: 5.0,
        r: 0.01,
        smoothness: 0.0,
        tilt_deg: 15.0,
        fixed: [0.0; 3],
        target: 8.0,
    },
    SMOOTH_100,
    Case {
        name: "N=100 smooth, turn",
        target: -3.0,
        ..SMOOTH_100
    },
    Case {
        name: "N=100",
        horizon: 100,
        q: 1.0,
        r: 0.003,
        smoothness: 0.0,
        tilt_deg: 30.0,
        fixed: [0.0, 0.1, 0.2],
        target: 10.0,
    },
];

/// A case's smoothness term and bounds.
fn problem(c: &Case) -> (Smoothness, AxisBounds) {
    let a = G * c.tilt_deg.to_radians().tan();
    (
        Smoothness {
            weight: c.smoothness,
            kappa: 0.2 / DT,
            gravity: G,
        },
        AxisBounds {
            acceleration: Some([-a, a]),
            ..Default::default()
        },
    )
}

/// Median time of `REPS` solves [µs] and the first planned jerk [m/s³].
fn time_solves(c: &Case, mut solve: impl FnMut(AxisProblem<'_>)) -> (f64, f64) {
    let reference = vec![c.target; c.horizon + 1];
    let mut plan = vec![0.0; c.horizon + 1];
    let mut times: Vec<f64> = (0..REPS)
        .map(|_| {
            let t0 = std::time::Instant::now();
            solve(AxisProblem {
                fixed: &c.fixed,
                sent: Some(0.0),
                reference: &reference,
                plan: &mut plan,
            });
            t0.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    times.sort_by(f64::total_cmp);
    let jerk = (plan[3] - 3.0 * plan[2] + 3.0 * plan[1] - plan[0]) / DT.powi(3);
    (times[REPS / 2], jerk)
}

fn main() {
    let tunings = [
        ("clarabel defaults", KktTuning::CLARABEL_DEFAULTS),
        ("clarabel shipped", KktTuning::SHIPPED),
        (
            "clarabel 1e-12, 1e-10",
            KktTuning {
                static_regularization: 1e-12,
                refinement_reltol: 1e-10,
                refinement_abstol: 1e-10,
                gap_tolerance: 1e-8,
            },
        ),
    ];
    println!("median of {REPS} solves [µs] (first planned jerk [m/s³])");
    print!("{:<24}", "banded interior point");
    for c in &CASES {
        let (smooth, bounds) = problem(c);
        let mut solver = BandedInteriorPointSolver::new(c.horizon, (c.q, c.r, DT), bounds, smooth)
            .expect("valid problem");
        let (us, jerk) = time_solves(c, |p| solver.solve_problem(p).expect("solves"));
        let it = solver.iterations();
        print!(" | {}: {us:4.0} ({jerk:.10e}) {it} it", c.name);
    }
    println!();
    for (label, tuning) in tunings {
        print!("{label:<24}");
        for c in &CASES {
            let (smooth, bounds) = problem(c);
            let weights = (c.q, c.r, DT);
            let mut solver = ClarabelSolver::with_tuning(
                c.horizon,
                weights,
                bounds,
                f64::INFINITY,
                smooth,
                tuning,
            )
            .expect("valid problem");
            let (us, jerk) = time_solves(c, |p| solver.solve_problem(p).expect("solves"));
            print!(" | {}: {us:4.0} ({jerk:.10e})", c.name);
        }
        println!();
    }
}
