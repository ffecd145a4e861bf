//! Tests of the per-axis solvers and of DF-MPC on fixtures.

use super::*;
use crate::optimise::alm::COLD_TUNING;
use crate::optimise::problem::baseline;
use crate::optimise::smoothness::accel_block;
use crate::optimise::{
    AxisCascade, AxisProblem, AxisSolver, BandedInteriorPointSolver, BoxAlmSolver, ClarabelSolver,
    FastBandedSolver, KktTuning, Smoothness, SolverFault, SolverMethod,
};

const DT: f64 = 0.02;

/// Exact optima (80-digit decimal arithmetic, independent code) of the
/// paper's problem: N = 200, q = 1, R = 1.25e9 (r = 0.08), for three
/// fixed windows and references; y_3, y_4, y_5, y_100, y_200.
#[allow(clippy::excessive_precision)] // the digits of the exact values
const EXACT: [([f64; 3], f64, [f64; 5]); 3] = [
    (
        [0.0, 0.0, 0.0],
        0.0,
        [
            2.72675475085858078517e-04,
            1.07424301111137365621e-03,
            2.64496673212843459722e-03,
            8.45180325427767975555e+00,
            8.91593139813904400626e+00,
        ],
    ),
    (
        [2.5, 2.625, 2.75],
        0.0,
        [
            2.87497597001641924663e+00,
            2.99990197984912443374e+00,
            3.12475036050520094122e+00,
            1.05579462561709682689e+01,
            9.27165464345517875699e+00,
        ],
    ),
    (
        [-1.0, -0.984375, -0.953125],
        0.125,
        [
            -9.06970419872583422105e-01,
            -8.46613469096172632788e-01,
            -7.72738357578821921656e-01,
            1.61152326483895080855e+01,
            2.35161257238214140841e+01,
        ],
    ),
];

/// Reference of the fixtures: 10 m, or a ramp `slope·j` when slope ≠ 0.
fn fixture_reference(slope: f64) -> Vec<f64> {
    (0..=200)
        .map(|j| if slope == 0.0 { 10.0 } else { slope * j as f64 })
        .collect()
}

#[test]
fn fast_path_matches_exact_optimum() {
    let mut s = FastBandedSolver::new(200, 1.0, 0.08, DT).unwrap();
    let mut plan = vec![0.0; 201];
    for (fixed, slope, exact) in EXACT {
        s.solve(&fixed, &fixture_reference(slope), &mut plan)
            .unwrap();
        assert_eq!(&plan[..3], &fixed);
        for (&j, &e) in [3usize, 4, 5, 100, 200].iter().zip(&exact) {
            let err = (plan[j] - e).abs() / e.abs();
            // The command needs y_3 to ~1e-12 m; we get ~1e-17 m.
            let tol = if j <= 5 { 1e-12 } else { 1e-11 };
            assert!(
                err < tol,
                "y_{j} = {} vs exact {e}: rel err {err:e}",
                plan[j]
            );
        }
    }
}

#[test]
fn clarabel_without_bounds_agrees_with_fast_path() {
    let mut fast = FastBandedSolver::new(100, 1.0, 0.08, DT).unwrap();
    let mut generic =
        ClarabelSolver::new(100, 1.0, 0.08, DT, AxisBounds::default(), f64::INFINITY).unwrap();
    let reference = vec![10.0; 101];
    let fixed = [1.0, 1.05, 1.11];
    let (mut a, mut b) = (vec![0.0; 101], vec![0.0; 101]);
    fast.solve(&fixed, &reference, &mut a).unwrap();
    generic
        .solve_problem(AxisProblem::new(&fixed, &reference, &mut b))
        .unwrap();
    for j in 0..=100 {
        assert!(
            (a[j] - b[j]).abs() < 1e-5 * (1.0 + a[j].abs()),
            "j={j}: {} vs {}",
            a[j],
            b[j]
        );
    }
    // The jerk at the first free output (what the command depends on).
    let jerk = |p: &[f64]| (p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0]) / DT.powi(3);
    assert!(
        (jerk(&a) - jerk(&b)).abs() < 1e-3 * jerk(&a).abs(),
        "{} vs {}",
        jerk(&a),
        jerk(&b)
    );
}

#[test]
fn constrained_plan_respects_bounds() {
    let a_max = 2.0;
    let v_max = 3.0;
    let bounds = AxisBounds {
        acceleration: Some([-a_max, a_max]),
        speed: Some(v_max),
        ..Default::default()
    };
    let mut fast = FastBandedSolver::new(100, 1.0, 0.08, DT).unwrap();
    let mut cs = ClarabelSolver::new(100, 1.0, 0.08, DT, bounds, f64::INFINITY).unwrap();
    let reference = vec![10.0; 101];
    let mut plan = vec![0.0; 101];
    fast.solve(&[0.0; 3], &reference, &mut plan).unwrap();
    assert!(bounds.violated_by(&plan, DT));
    cs.solve_problem(AxisProblem::new(&[0.0; 3], &reference, &mut plan))
        .unwrap();
    assert!(
        !AxisBounds {
            acceleration: Some([-a_max * 1.0001, a_max * 1.0001]),
            speed: Some(v_max * 1.0001),
            ..Default::default()
        }
        .violated_by(&plan, DT)
    );
    // The bound binds: some planned acceleration is at the limit.
    let amax = (1..99)
        .map(|j| ((plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / (DT * DT)).abs())
        .fold(0.0, f64::max);
    assert!(amax > 0.99 * a_max, "{amax}");
}

/// Clarabel's objective `½xᵀPx + cᵀx` ([`ClarabelSolver`]) of a
/// plan: p its deviation from the baseline, ã = Δ²p/δt².
fn qp_objective(
    horizon: usize,
    (q, r, dt): (f64, f64, f64),
    smoothness: &Smoothness,
    fixed: &[f64; 3],
    sent: Option<f64>,
    reference: &[f64],
    plan: &[f64],
) -> f64 {
    let n = horizon - 2;
    let p: Vec<f64> = (0..n)
        .map(|f| plan[f + 3] - baseline(fixed, f + 3))
        .collect();
    let at = |f: isize| if f < 0 { 0.0 } else { p[f as usize] };
    let a: Vec<f64> = (0..n as isize)
        .map(|f| (at(f) - 2.0 * at(f - 1) + at(f - 2)) / (dt * dt))
        .collect();
    let band = accel_block(n, r, dt, smoothness);
    let mut obj = 0.0;
    for f in 0..n {
        obj += q * p[f] * p[f] + 2.0 * q * (baseline(fixed, f + 3) - reference[f + 3]) * p[f];
        obj += 0.5 * band[f][0] * a[f] * a[f];
        if f >= 1 {
            obj += band[f][1] * a[f - 1] * a[f];
        }
        if f >= 2 {
            obj += band[f][2] * a[f - 2] * a[f];
        }
    }
    if let Some(c) = sent
        && smoothness.weight > 0.0
    {
        let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        let g2 = smoothness.gravity.powi(2);
        obj += 2.0 * smoothness.weight / g2 * smoothness.kappa * (a0 - c) * a[0];
    }
    obj
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config::with_cases(256))]
    /// Clarabel with the shipped KKT tuning ([`KktTuning::SHIPPED`]) gives
    /// the plan of clarabel's default settings, and the banded interior
    /// point ([`BandedInteriorPointSolver`]) and [`BoxAlmSolver`] (with
    /// speed rows: the active-set method) the plan of clarabel solved to
    /// a duality gap of 1e-11 ([`KktTuning::REFERENCE`]), on random
    /// constrained instances — with and without the smoothness term,
    /// windows faster than the speed bound (funnel) included — to the
    /// tolerances below; the acceleration bounds hold. The defaults stop
    /// at a relative gap of 1e-8, which on costs near 1e5 leaves the
    /// horizon's last outputs (a flat direction of the cost) a millimetre
    /// loose: seed `cc feddc4ef…` (N = 194) had y_194 1.1e-3 m from the
    /// exact optimum there, which the active-set method and the 1e-11
    /// reference agree on to 2e-7 m. 256 cases per run
    /// (`PROPTEST_CASES=2000` for more).
    #[test]
    fn constrained_solvers_match_clarabel_defaults(
        horizon in 20usize..=200,
        q in 0.5f64..10.0,
        r in 1e-3f64..0.1,
        a_max in 1.0f64..5.0,
        speed in proptest::option::of(2.0f64..8.0),
        y0 in -5.0f64..5.0,
        v0_frac in -1.5f64..1.5,
        a0_frac in -0.8f64..0.8,
        target in -20.0f64..20.0,
        slope in -3.0f64..3.0,
        smooth in proptest::option::of((1.0f64..50.0, 1.0f64..8.0, -0.5f64..0.5)),
    ) {
        let v0 = v0_frac * speed.unwrap_or(4.0);
        let a0 = a0_frac * a_max;
        let fixed = [y0, y0 + v0 * DT, y0 + 2.0 * v0 * DT + a0 * DT * DT];
        let reference: Vec<f64> =
            (0..=horizon).map(|j| target + slope * DT * j as f64).collect();
        let bounds = AxisBounds { acceleration: Some([-a_max, a_max]), speed, ..Default::default() };
        let (smoothness, sent) = match smooth {
            Some((weight, kappa, delta)) => (
                Smoothness { weight, kappa, gravity: 9.81 },
                Some(a0 + delta),
            ),
            None => (Smoothness::default(), None),
        };
        let build = |tuning| {
            ClarabelSolver::with_tuning(
                horizon, (q, r, DT), bounds, f64::INFINITY, smoothness, tuning,
            )
            .unwrap()
        };
        let (mut shipped, mut reference_solver) =
            (build(KktTuning::SHIPPED), build(KktTuning::CLARABEL_DEFAULTS));
        let mut want = vec![0.0; horizon + 1];
        let ok = reference_solver.solve_problem(AxisProblem {
            fixed: &fixed, sent, reference: &reference, plan: &mut want,
        });
        proptest::prop_assume!(ok.is_ok(), "reference solver: {:?}", ok);
        // Our solvers' reference: clarabel to a gap of 1e-11.
        let mut exact = vec![0.0; horizon + 1];
        let ok = build(KktTuning::REFERENCE).solve_problem(AxisProblem {
            fixed: &fixed, sent, reference: &reference, plan: &mut exact,
        });
        proptest::prop_assume!(ok.is_ok(), "reference solver: {:?}", ok);
        let mut got = vec![0.0; horizon + 1];
        shipped
            .solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut got,
            })
            .unwrap();
        let mut banded = BandedInteriorPointSolver::new(horizon, (q, r, DT), bounds, smoothness).unwrap();
        let mut got_banded = vec![0.0; horizon + 1];
        banded
            .solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut got_banded,
            })
            .unwrap();
        // The augmented Lagrangian from the fast path's plan (as the
        // cascade gives it), cold.
        let mut got_alm = vec![0.0; horizon + 1];
        FastBandedSolver::with_smoothness(horizon, q, r, DT, smoothness)
            .unwrap()
            .solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut got_alm,
            })
            .unwrap();
        let mut alm = BoxAlmSolver::with_tuning(horizon, (q, r, DT), bounds, smoothness, true, COLD_TUNING).unwrap();
        alm
            .solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut got_alm,
            })
            .unwrap();
        let jerk = |p: &[f64]| (p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0]) / DT.powi(3);
        // Both stop at ~1e-8 relative gaps, so outputs far out in the
        // horizon (flat directions of the cost) may differ by µm even
        // between the two clarabel tunings (up to 1e-5 m over 2000 cases;
        // on the speed-limited regression case `cc 1a7fb36e…`, found in a
        // full run, and its neighbours up to 1.06e-5 m at y_35 and 2.1e-6 m
        // at y_10 — each tighter tolerance tried found the next: the
        // tunings are held to each other as our solvers are held to the
        // reference, 1e-5 m over the first ten outputs and 1e-3 m beyond),
        // more for the independent banded interior point: it is held to
        // a cost no higher than clarabel's (1e-7 relative, the gap it
        // accepts from a stalled iterate: the measure of a QP solution), the first jerk to 1e-3 relative (near a
        // bound the cost can be flat in it too: 2000 cases showed 1.1e-4,
        // 0.035° of command at −269 m/s³), the first ten outputs to
        // 1e-5 m. The two clarabel tunings' first jerks, a third
        // difference over δt³ (1.25e5 per metre), differ by up to 1.2e-6
        // relative (1000 cases, `PROPTEST_RNG_SEED=12`): held to 3e-6.
        let objective = |plan: &[f64]| {
            qp_objective(horizon, (q, r, DT), &smoothness, &fixed, sent, &reference, plan)
        };
        let ow = objective(&exact);
        for (name, plan) in [("banded", &got_banded), ("ALM", &got_alm)] {
            let ob = objective(plan);
            proptest::prop_assert!(
                ob <= ow + 1e-7 * (1.0 + ow.abs()),
                "{name} cost {ob} above clarabel's {ow}"
            );
        }
        // (name, plan, first-jerk tolerance (relative), tolerance on
        // the first ten outputs, on the rest [m]).
        let cases = [
            ("clarabel shipped", &got, &want, 3e-6, 1e-5, 1e-3),
            ("banded", &got_banded, &exact, 1e-3, 1e-5, 1e-3),
            ("ALM", &got_alm, &exact, 1e-3, 1e-5, 1e-3),
        ];
        for (name, got, want, jerk_tol, near_tol, far_tol) in cases {
            let (jg, jw) = (jerk(got), jerk(want));
            proptest::prop_assert!(
                (jg - jw).abs() <= jerk_tol * jw.abs().max(1.0),
                "{name}: first jerk {jg} vs {jw}"
            );
            for (j, (g, w)) in got.iter().zip(want).enumerate() {
                let tol = if j <= 10 { near_tol } else { far_tol };
                proptest::prop_assert!((g - w).abs() <= tol, "{name}: y_{j}: {g} vs {w}");
            }
            // The funnel relaxes the speed bound near the start.
            let check = AxisBounds { speed: None, ..bounds };
            proptest::prop_assert!(!check.violated_by(got, DT), "{name}");
        }
    }
}

#[test]
fn faster_than_the_speed_bound_brakes_in_a_funnel() {
    // Moving at 5 m/s with |v| ≤ 1 m/s and |a| ≤ 1 m/s²: a hard bound
    // from the first free step would be infeasible (the window cannot
    // slow down in one step); the funnel brakes at 0.9 m/s² instead.
    let (v_max, a_max) = (1.0, 1.0);
    let bounds = AxisBounds {
        acceleration: Some([-a_max, a_max]),
        speed: Some(v_max),
        ..Default::default()
    };
    let n = 300; // 6 s: long enough to get down to 1 m/s
    let mut cs = ClarabelSolver::new(n, 1.0, 0.08, DT, bounds, f64::INFINITY).unwrap();
    let mut plan = vec![0.0; n + 1];
    let fixed = [0.0, 0.1, 0.2];
    cs.solve_problem(AxisProblem::new(&fixed, &vec![10.0; n + 1], &mut plan))
        .unwrap();
    let speed = |j: usize| (plan[j + 1] - plan[j]) / DT;
    for j in 2..n {
        let funnel = v_max.max(5.0 - 0.9 * a_max * (j - 1) as f64 * DT);
        assert!(
            speed(j).abs() <= funnel * (1.0 + 1e-6),
            "j={j}: {}",
            speed(j)
        );
        let a = (plan[j + 1] - 2.0 * plan[j] + plan[j - 1]) / (DT * DT);
        assert!(a.abs() <= a_max * (1.0 + 1e-6), "j={j}: a = {a}");
    }
    // It brakes: within the bound once the funnel has closed (4.4 s).
    assert!(speed(250).abs() <= v_max * (1.0 + 1e-6), "{}", speed(250));
    assert!(speed(10) < 5.0 && speed(100) < speed(10));
}

#[test]
fn solver_failure_is_an_error() {
    // A time limit no solve can meet.
    let bounds = AxisBounds {
        acceleration: Some([-1.0, 1.0]),
        speed: Some(1.0),
        ..Default::default()
    };
    let mut cs = ClarabelSolver::new(50, 1.0, 0.08, DT, bounds, 1e-12).unwrap();
    let mut plan = vec![0.0; 51];
    let r = cs.solve_problem(AxisProblem::new(&[0.0, 0.1, 0.2], &[10.0; 51], &mut plan));
    // The outcome is clarabel's own status, as a value (never a string).
    assert!(
        matches!(
            r,
            Err(ControlError::Solver {
                method: None,
                fault: SolverFault::Clarabel(clarabel::solver::SolverStatus::MaxTime)
            })
        ),
        "{r:?}"
    );
    // The cascade names the method that failed last.
    let mut cascade = AxisCascade::new(vec![Box::new(cs) as Box<dyn AxisSolver>]).unwrap();
    let e = cascade
        .solve(AxisProblem::new(&[0.0, 0.1, 0.2], &[10.0; 51], &mut plan))
        .unwrap_err();
    assert_eq!(
        e,
        ControlError::Solver {
            method: Some(SolverMethod::Clarabel),
            fault: SolverFault::Clarabel(clarabel::solver::SolverStatus::MaxTime)
        }
    );
    assert_eq!(e.to_string(), "QP solver failed: clarabel: status MaxTime");
}

#[test]
fn lengths_and_arguments_are_checked() {
    assert!(matches!(
        FastBandedSolver::new(2, 1.0, 0.08, DT),
        Err(ControlError::InvalidSetting {
            field: "horizon",
            ..
        })
    ));
    assert!(matches!(
        FastBandedSolver::new(10, 1.0, 0.0, DT),
        Err(ControlError::InvalidSetting {
            field: "jerk_weight",
            ..
        })
    ));
    let mut s = FastBandedSolver::new(10, 1.0, 0.08, DT).unwrap();
    let mut plan = vec![0.0; 11];
    assert!(matches!(
        s.solve(&[0.0; 3], &[0.0; 10], &mut plan),
        Err(ControlError::InvalidSetting {
            field: "reference",
            ..
        })
    ));
}

#[test]
fn validate_names_the_field() {
    let field = |s: DfMpcSettings| match s.validate() {
        Err(ControlError::InvalidSetting { field, .. }) => field,
        other => panic!("expected an invalid setting, got {other:?}"),
    };
    assert!(DfMpcSettings::default().validate().is_ok());
    let d = DfMpcSettings::default();
    assert_eq!(field(DfMpcSettings { horizon: 1, ..d }), "horizon");
    assert_eq!(
        field(DfMpcSettings {
            tracking_weight: [1.0, f64::NAN, 1.0],
            ..d
        }),
        "tracking_weight"
    );
    assert_eq!(
        field(DfMpcSettings {
            jerk_weight: [0.08, 0.08, -1.0],
            ..d
        }),
        "jerk_weight"
    );
    let sat = InputSaturation {
        max_tilt: 2.0,
        ..Default::default()
    };
    assert_eq!(
        field(DfMpcSettings {
            saturation: Some(sat),
            ..d
        }),
        "saturation.max_tilt"
    );
    let sat = InputSaturation {
        thrust_max: 1.0,
        ..Default::default()
    };
    assert_eq!(
        field(DfMpcSettings {
            saturation: Some(sat),
            ..d
        }),
        "saturation.thrust_max"
    );
    let c = OutputConstraints {
        max_speed: Some(0.0),
        ..Default::default()
    };
    assert_eq!(
        field(DfMpcSettings {
            constraints: c,
            ..d
        }),
        "constraints.max_speed"
    );
    let c = OutputConstraints {
        vertical_acceleration: Some([1.0, 2.0]),
        ..Default::default()
    };
    assert_eq!(
        field(DfMpcSettings {
            constraints: c,
            ..d
        }),
        "constraints.vertical_acceleration"
    );
    assert_eq!(
        field(DfMpcSettings {
            solver_time_limit: 0.0,
            ..d
        }),
        "solver_time_limit"
    );
}

#[test]
fn banded_failure_falls_back_to_clarabel_and_says_so() {
    let model = || {
        ControlModel::Planar(
            dflat_model::PlanarModel::new(dflat_model::PlanarParams::default()).unwrap(),
        )
    };
    let settings = |qp_solver| DfMpcSettings {
        constraints: OutputConstraints {
            max_tilt: Some(20f64.to_radians()),
            ..Default::default()
        },
        plan_tilt_bound: PlanTiltBound::Box,
        qp_solver,
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut banded = DfMpc::new(model(), settings(QpSolver::Banded)).unwrap();
    let mut broken = DfMpc::new(model(), settings(QpSolver::Banded)).unwrap();
    let mut clarabel = DfMpc::new(model(), settings(QpSolver::Clarabel)).unwrap();
    // A banded solver built for another horizon refuses every problem
    // of this controller (length check): the axis goes to clarabel.
    let bounds = AxisBounds {
        acceleration: Some([-1.0, 1.0]),
        ..Default::default()
    };
    let weights = DfMpcSettings::default();
    for (axis, p) in broken.axes.iter_mut().enumerate() {
        assert!(p.bounded.is_some(), "the axis has bounds");
        let (q, r) = (weights.tracking_weight[axis], weights.jerk_weight[axis]);
        let clarabel = crate::optimise::ClarabelSolver::with_smoothness(
            p.fast.horizon(),
            q,
            r,
            DT,
            p.bounds,
            f64::INFINITY,
            p.fast.smoothness(),
        )
        .unwrap();
        let alm =
            BoxAlmSolver::new(10, (1.0, 0.08, DT), bounds, Smoothness::default(), true).unwrap();
        let ip = BandedInteriorPointSolver::new(10, (1.0, 0.08, DT), bounds, Smoothness::default())
            .unwrap();
        p.bounded = Some(
            crate::optimise::AxisCascade::new(vec![
                Box::new(alm),
                Box::new(ip),
                Box::new(clarabel),
            ])
            .unwrap(),
        );
    }
    let m = Measurement {
        t: 0.0,
        position: Vector3::zeros(),
        yaw: 0.0,
    };
    let target = Vector3::new(10.0, -10.0, 0.0);
    let tick = |c: &mut DfMpc| {
        let mut r = crate::reference::Reference::setpoint(target).unwrap();
        c.update(&m, &mut r).unwrap()
    };
    let (a, b, c) = (tick(&mut banded), tick(&mut broken), tick(&mut clarabel));
    assert!(a.constrained && b.constrained && c.constrained);
    assert!(!a.qp_fallback && b.qp_fallback && !c.qp_fallback);
    // The fallback's command is clarabel's.
    assert_eq!(b.command, c.command);
    assert!(
        (a.command.pitch - c.command.pitch).abs() < 1e-4,
        "{a:?} {c:?}"
    );
}

/// The corner flights' settings: N = 100, a 20° tilt cone in the plan,
/// `qp_solver`, no time limit.
pub(super) fn corner_cone(qp_solver: QpSolver) -> DfMpcSettings {
    DfMpcSettings {
        horizon: 100,
        constraints: OutputConstraints {
            max_tilt: Some(20f64.to_radians()),
            ..Default::default()
        },
        plan_tilt_bound: PlanTiltBound::Cone,
        qp_solver,
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    }
}

/// The corner flights' plant: the planar model (ψ = 0, NED) with a
/// horizontal drag of `drag_h` \[1/s\].
pub(super) fn corner_plant(drag_h: f64) -> dflat_model::PlanarModel {
    dflat_model::PlanarModel::new(dflat_model::PlanarParams {
        psi: 0.0,
        frame: crate::Frame::Ned,
        drag_h,
        ..Default::default()
    })
    .unwrap()
}

/// The corner flights' path: the L (0, 0) → (20, 0) → (20, 20) m at
/// 8 m/s, 2 m up.
pub(super) fn corner_path() -> crate::reference::Reference {
    let w = [[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]].map(|[x, y]| Vector3::new(x, y, -2.0));
    crate::reference::Reference::path(&w, 8.0).unwrap()
}

/// The warm-started cone through the DF-MPC, in closed loop: an L path at
/// 8 m/s under a 20° cone (start, corner and stop bind it), the banded
/// solver's commands against clarabel's SOCP fed the same measurements
/// (each controller's own commands in its window), the plan inside the
/// cone, and the tick's report consistent with the solver's.
#[test]
fn warm_cone_flies_the_corner_as_clarabel_does() {
    use dflat_model::FlatModel;
    let plant = corner_plant(0.0);
    let mut banded =
        DfMpc::new(ControlModel::Planar(plant), corner_cone(QpSolver::Banded)).unwrap();
    let mut clarabel =
        DfMpc::new(ControlModel::Planar(plant), corner_cone(QpSolver::Clarabel)).unwrap();
    let (mut rb, mut rc) = (corner_path(), corner_path());
    let mut x = nalgebra::SVector::<f64, 6>::zeros();
    let (mut constrained, mut warm) = (0, 0);
    for k in 0..200 {
        let y = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(y.x, y.y, -2.0),
            yaw: 0.0,
        };
        let a = banded.update(&m, &mut rb).unwrap();
        let c = clarabel.update(&m, &mut rc).unwrap();
        assert_eq!(a.constrained, c.constrained, "tick {k}");
        assert!(!a.qp_fallback, "tick {k}: clarabel had to solve");
        let cascade = banded.cone_cascade().expect("the cone's cascade");
        if a.constrained {
            constrained += 1;
            let (place, info) = cascade.solved_by().expect("a solver solved");
            warm += usize::from(info.warm_started);
            assert_eq!(
                a.cone_interior_point,
                info.method == crate::optimise::SolverMethod::InteriorPoint,
                "tick {k}"
            );
            assert_eq!(
                place == 0,
                info.method == crate::optimise::SolverMethod::Alm
            );
            let cone = banded.cone_bounds().unwrap();
            assert!(!cone.violated_by(banded.plan(0).unwrap(), banded.plan(1).unwrap(), DT));
        } else {
            assert!(!a.cone_interior_point);
        }
        for (p, q) in [
            (a.command.pitch, c.command.pitch),
            (a.command.roll, c.command.roll),
        ] {
            assert!((p - q).abs() < 1e-4, "tick {k}: {a:?} vs {c:?}");
        }
        x = plant.step(&x, &nalgebra::Vector2::new(a.command.pitch, a.command.roll));
    }
    // The cone binds on most of the flight, and the solver runs warm there.
    assert!(constrained > 100, "{constrained}");
    assert!(warm * 10 >= constrained * 8, "{warm} of {constrained}");
}

/// A solver that sees each problem and passes it on (the corner bench's
/// OSQP anchor is one): the cascade still solves with its own solvers.
#[derive(Debug, Default)]
struct Observer {
    seen: usize,
    accepted: usize,
}

impl crate::optimise::AxisSolver for Observer {
    fn solve(
        &mut self,
        _axis: AxisProblem<'_>,
    ) -> Result<crate::optimise::SolveInfo, crate::optimise::SolveFailure> {
        self.seen += 1;
        Err(crate::optimise::SolveFailure::Observer)
    }
    fn carry(&mut self, event: crate::optimise::Carry<'_>) {
        if let crate::optimise::Carry::Accepted { .. } = event {
            self.accepted += 1;
        }
    }
    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }
    fn set_offset(&mut self, _offset: Option<f64>, _slope: f64) {}
}

/// `Cascade::insert` checks its place; a solver
/// inserted first that declines every tick leaves the commands as they
/// were and is told each accepted solution.
#[test]
fn an_inserted_observer_leaves_the_commands_unchanged() {
    let plant = dflat_model::PlanarModel::new(dflat_model::PlanarParams::default()).unwrap();
    let settings = DfMpcSettings {
        constraints: OutputConstraints {
            max_tilt: Some(10f64.to_radians()),
            ..Default::default()
        },
        plan_tilt_bound: PlanTiltBound::Box,
        solver_time_limit: f64::INFINITY,
        ..Default::default()
    };
    let mut plain = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
    let mut observed = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
    let cascade = observed.box_cascade_mut(0).unwrap();
    let len = cascade.solvers().count();
    assert!(
        cascade
            .insert(len + 1, Box::new(Observer::default()))
            .is_err()
    );
    cascade.insert(0, Box::new(Observer::default())).unwrap();
    assert_eq!(cascade.solvers().count(), len + 1);
    let path = [Vector3::new(0.0, 0.0, -2.0), Vector3::new(20.0, 0.0, -2.0)];
    let (mut ra, mut rb) = (
        crate::reference::Reference::path(&path, 8.0).unwrap(),
        crate::reference::Reference::path(&path, 8.0).unwrap(),
    );
    let mut constrained = 0;
    for k in 0..60 {
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(0.0, 0.0, -2.0),
            yaw: 0.0,
        };
        let (a, b) = (
            plain.update(&m, &mut ra).unwrap(),
            observed.update(&m, &mut rb).unwrap(),
        );
        assert_eq!(a.command, b.command, "tick {k}");
        constrained += usize::from(b.constrained);
    }
    assert!(constrained > 0, "the bound bound");
    let (place, _) = observed.box_cascade(0).unwrap().solved_by().unwrap();
    assert!(place >= 1, "the observer never solves");
}
