//! The tilt-rate rows ([`TiltRate`]) in the box solvers: the banded stage
//! interior point and the augmented Lagrangian against clarabel on random instances, the rows hold,
//! and the first command's step through the per-axis tilt is within the
//! bound exactly.

use super::bounds::AxisBounds;
use super::box_alm::BoxAlmSolver;
use super::cascade::AxisCascade;
use super::clarabel::{ClarabelSolver, KktTuning};
use super::fast_banded::FastBandedSolver;
use super::interior_point::BandedInteriorPointSolver;
use super::problem::AxisProblem;
use super::smoothness::Smoothness;
use super::tilt_rate::TiltRate;

const DT: f64 = 0.02;
const G: f64 = 9.81;

/// `Σ q(y − ref)² + r(Δ³y/δt³)² + s((c_j − c_{j−1})/g)²` over the plan
/// (the problem's cost as defined, independent of the solvers' variables).
fn cost(
    (q, r): (f64, f64),
    sm: &Smoothness,
    sent: Option<f64>,
    reference: &[f64],
    plan: &[f64],
) -> f64 {
    let n = plan.len() - 1;
    let a = |j: usize| (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / (DT * DT);
    let mut c = 0.0;
    for (y, yr) in plan.iter().zip(reference) {
        c += q * (y - yr).powi(2);
    }
    for j in 0..=n - 3 {
        let d3 = plan[j + 3] - 3.0 * plan[j + 2] + 3.0 * plan[j + 1] - plan[j];
        c += r * (d3 / DT.powi(3)).powi(2);
    }
    if sm.weight > 0.0 {
        let cmd = |j: usize| a(j) + sm.kappa * (a(j + 1) - a(j));
        let mut prev = sent.unwrap_or(a(0));
        for j in 0..=n - 3 {
            let cj = cmd(j);
            c += sm.weight * ((cj - prev) / sm.gravity).powi(2);
            prev = cj;
        }
    }
    c
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config::with_cases(200))]
    /// With tilt-rate rows (and an acceleration bound, its funnel and the
    /// smoothness term, each optional), the banded interior point and the
    /// box's cascade (augmented Lagrangian, then interior point) give
    /// clarabel's plan (clarabel's defaults at a 1e-11 gap, the
    /// reference): cost no higher than 1e-7 relative, the first ten
    /// outputs to 1e-5 m, the first command to 1e-4 rad. Both plans keep
    /// every tilt-rate row, and the first command's step through the
    /// per-axis tilt (F's) is within the bound to 1e-7 rad.
    #[test]
    fn banded_tilt_rate_matches_clarabel(
        horizon in 20usize..=160,
        q in 0.5f64..10.0,
        r in 1e-3f64..0.1,
        step_deg in 0.5f64..5.0,
        kappa in 1.0f64..12.0,
        a_max in proptest::option::of(2.0f64..7.0),
        v0 in -5.0f64..5.0,
        a0 in -5.0f64..5.0,
        sent_delta in -3.0f64..3.0,
        target in -20.0f64..20.0,
        slope in -3.0f64..3.0,
        smooth in proptest::option::of(1.0f64..80.0),
    ) {
        let y0 = 0.3;
        let fixed = [y0, y0 + v0 * DT, y0 + 2.0 * v0 * DT + a0 * DT * DT];
        let reference: Vec<f64> =
            (0..=horizon).map(|j| target + slope * DT * j as f64).collect();
        let rate = TiltRate { step: step_deg.to_radians(), kappa, gain: 1.0, gravity: G };
        let bounds = AxisBounds {
            acceleration: a_max.map(|a| [-a, a]),
            tilt_rate: Some(rate),
            ..Default::default()
        };
        let smoothness = Smoothness { weight: smooth.unwrap_or(0.0), kappa, gravity: G };
        let sent = Some(a0 + sent_delta);
        let mut reference_solver = ClarabelSolver::with_tuning(
            horizon, (q, r, DT), bounds, f64::INFINITY, smoothness, KktTuning::REFERENCE,
        )
        .unwrap();
        let mut want = vec![0.0; horizon + 1];
        // The reference itself must have solved (clarabel reports
        // AlmostSolved on a few stiff draws): such a case says nothing.
        let solved = reference_solver
            .solve_problem(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut want });
        proptest::prop_assume!(solved.is_ok());
        let mut banded =
            BandedInteriorPointSolver::new(horizon, (q, r, DT), bounds, smoothness).unwrap();
        let mut got = vec![0.0; horizon + 1];
        banded
            .solve_problem(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut got })
            .unwrap();
        // The product's cascade from the fast path's plan, cold: the
        // augmented Lagrangian within its step budget, else the interior
        // point. (Cold, on the narrow rate rows chained over the horizon,
        // the augmented Lagrangian alone can need hundreds of steps.)
        let mut got_alm = vec![0.0; horizon + 1];
        FastBandedSolver::with_smoothness(horizon, q, r, DT, smoothness)
            .unwrap()
            .solve_problem(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut got_alm })
            .unwrap();
        let mut cascade = AxisCascade::new(vec![
            Box::new(BoxAlmSolver::new(horizon, (q, r, DT), bounds, smoothness, true).unwrap()),
            Box::new(BandedInteriorPointSolver::new(horizon, (q, r, DT), bounds, smoothness).unwrap()),
        ])
        .unwrap();
        cascade
            .solve(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut got_alm })
            .unwrap();
        let cw = cost((q, r), &smoothness, sent, &reference, &want);
        for (name, plan) in [("banded", &got), ("cascade", &got_alm)] {
            let cg = cost((q, r), &smoothness, sent, &reference, plan);
            proptest::prop_assert!(cg <= cw + 1e-7 * (1.0 + cw.abs()), "{name} cost {cg} above clarabel's {cw}");
            for (j, (g, w)) in plan.iter().zip(&want).take(11).enumerate() {
                proptest::prop_assert!((g - w).abs() <= 1e-5, "{name} y_{j}: {g} vs {w}");
            }
        }
        let mut steps = Vec::new();
        let mut first = [0.0; 3];
        for (i, plan) in [&want, &got, &got_alm].into_iter().enumerate() {
            proptest::prop_assert!(!rate.violated_by(plan, sent, DT), "rows broken ({i})");
            rate.command_steps(plan, sent, DT, &mut steps);
            proptest::prop_assert!(
                steps[0].abs() <= rate.step + 1e-7,
                "first command step {} > {}", steps[0], rate.step
            );
            first[i] = steps[0];
        }
        proptest::prop_assert!(
            (first[0] - first[1]).abs() <= 1e-4 && (first[0] - first[2]).abs() <= 1e-4,
            "first steps {first:?}"
        );
    }
}

/// Sent command and attitude far outside a 10° acceleration bound (35°):
/// the rate bound cannot bring them inside at once, and the funnel keeps
/// the problem feasible: the plan comes down at the rate bound.
#[test]
fn the_funnel_keeps_rate_and_acceleration_bounds_feasible() {
    let horizon = 100;
    let a0 = G * 35f64.to_radians().tan();
    let fixed = [0.0, 0.1, 0.2 + a0 * DT * DT];
    let reference = vec![0.0; horizon + 1];
    let rate = TiltRate {
        step: 2f64.to_radians(),
        kappa: 10.0,
        gain: 1.0,
        gravity: G,
    };
    let a = G * 10f64.to_radians().tan();
    let bounds = AxisBounds {
        acceleration: Some([-a, a]),
        tilt_rate: Some(rate),
        ..Default::default()
    };
    let sent = Some(a0);
    let mut banded =
        BandedInteriorPointSolver::new(horizon, (1.0, 0.01, DT), bounds, Smoothness::default())
            .unwrap();
    let mut plan = vec![0.0; horizon + 1];
    banded
        .solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference: &reference,
            plan: &mut plan,
        })
        .unwrap();
    let mut steps = Vec::new();
    rate.command_steps(&plan, sent, DT, &mut steps);
    assert!(
        steps[0].abs() <= rate.step + 1e-9,
        "first step {}",
        steps[0]
    );
    assert!(!rate.violated_by(&plan, sent, DT));
    // Inside the acceleration bound by the end of the horizon.
    let acc = |j: usize| (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / (DT * DT);
    assert!(
        acc(horizon - 2).abs() <= a * (1.0 + 1e-6),
        "{}",
        acc(horizon - 2)
    );
    // Without the rate rows the box alone makes the first command jump.
    let mut clarabel = ClarabelSolver::with_tuning(
        horizon,
        (1.0, 0.01, DT),
        AxisBounds {
            tilt_rate: None,
            drag: 0.0,
            offset: None,
            ..bounds
        },
        f64::INFINITY,
        Smoothness::default(),
        KktTuning::SHIPPED,
    )
    .unwrap();
    let mut plain = vec![0.0; horizon + 1];
    clarabel
        .solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference: &reference,
            plan: &mut plain,
        })
        .unwrap();
    rate.command_steps(&plain, sent, DT, &mut steps);
    assert!(
        steps[0].abs() > 5.0 * rate.step,
        "without the rate rows the first command steps {} rad",
        steps[0]
    );
}

/// Horizon and weights `(q, r)` of the rate-limited 10 m step from rest.
const STEP_HORIZON: usize = 100;
const STEP_WEIGHTS: (f64, f64) = (1.0, 0.003);

/// The bounds of the rate-limited step: tilt-rate rows of 2° a step
/// (κ 10), with an acceleration interval `±a_max` when given.
fn step_bounds(a_max: Option<f64>) -> AxisBounds {
    AxisBounds {
        acceleration: a_max.map(|a| [-a, a]),
        tilt_rate: Some(TiltRate {
            step: 2f64.to_radians(),
            kappa: 10.0,
            gain: 1.0,
            gravity: G,
        }),
        ..Default::default()
    }
}

/// The interior point's plan and row multipliers, handed to the
/// augmented Lagrangian ([`BoxAlmSolver::accept_plan`], what the cascade
/// does after a fallback), are a start it finishes from in a few Newton
/// steps, at the same plan: one fallback does not make the next.
#[test]
fn the_interior_points_duals_start_the_augmented_lagrangian() {
    let (horizon, (q, r)) = (STEP_HORIZON, STEP_WEIGHTS);
    for a_max in [None, Some(3.0)] {
        let bounds = step_bounds(a_max);
        let smoothness = Smoothness::default();
        let fixed = [0.0, 0.0, 0.0];
        let reference = vec![10.0; horizon + 1];
        let sent = Some(0.0);
        let mut ip =
            BandedInteriorPointSolver::new(horizon, (q, r, DT), bounds, smoothness).unwrap();
        let mut plan = vec![0.0; horizon + 1];
        ip.solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference: &reference,
            plan: &mut plan,
        })
        .unwrap();
        let mut alm = BoxAlmSolver::new(horizon, (q, r, DT), bounds, smoothness, true).unwrap();
        alm.accept_plan(&plan, ip.row_duals());
        alm.start_from_given();
        let mut again = plan.clone();
        alm.solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference: &reference,
            plan: &mut again,
        })
        .unwrap();
        assert!(
            alm.iterations() <= 10,
            "{a_max:?}: {} Newton steps",
            alm.iterations()
        );
        for (j, (a, b)) in plan.iter().zip(&again).enumerate() {
            assert!((a - b).abs() <= 1e-5, "{a_max:?}: y_{j}: {a} vs {b}");
        }
        // Without the multipliers the same start needs more.
        let mut cold = BoxAlmSolver::new(horizon, (q, r, DT), bounds, smoothness, false).unwrap();
        let mut from_plan = plan.clone();
        let _ = cold.solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference: &reference,
            plan: &mut from_plan,
        });
        assert!(
            cold.iterations() > alm.iterations(),
            "{a_max:?}: {} vs {}",
            cold.iterations(),
            alm.iterations()
        );
    }
}

/// A cold solve on tilt-rate rows whose unconstrained plan leaps (a 10 m
/// step of the reference, from rest) starts the active set from the
/// condensed interior point's working set (`active_set/interior.rs`) and
/// ends at clarabel's plan, every row kept, within a few KKT solves (the
/// augmented Lagrangian alone: no interior point behind it) — with the
/// rows alone and with an acceleration bound too. (From the rollout's set
/// they took 37 and 81; from the unconstrained plan's broken constraints
/// 139.)
#[test]
fn a_cold_rate_limited_solve_ends_in_the_active_set() {
    for a_max in [None, Some(3.0)] {
        let bounds = step_bounds(a_max);
        let mut alm = step_alm(bounds);
        let (got, want) = solve_step(&mut alm, bounds, 10.0);
        assert!(
            alm.iterations() <= 6,
            "{a_max:?}: {} KKT solves",
            alm.iterations()
        );
        check_step(&format!("{a_max:?}"), bounds, &got, &want);
    }
}

/// A warm start whose working set is far from the optimum's goes cold at
/// once (`WARM_DISTANCE` in `active_set/mod.rs`), and the axis's next
/// solve starts cold too: the rate-limited step to +10 m solved, then the
/// step to −10 m from rest warm-started from it (every row of its ramp on
/// the wrong side). Both end at clarabel's plan, every row kept; the
/// mirrored solve within `WARM_SOLVES` KKT solves in all (a warm start
/// run to its `WARM_SOLVES`, then the cold start's, takes more), the one after
/// it from the condensed interior point's set although its guess is good.
#[test]
fn a_warm_start_far_from_the_optimum_goes_cold_at_once() {
    let bounds = step_bounds(None);
    let mut alm = step_alm(bounds);
    for (solve, target) in [10.0, -10.0, -10.0].into_iter().enumerate() {
        let (got, want) = solve_step(&mut alm, bounds, target);
        let work = alm.active_set_work();
        check_step(&format!("solve {solve}"), bounds, &got, &want);
        assert!(work.interior > 0, "solve {solve}: not cold: {work:?}");
        if solve == 1 {
            assert!(work.solves <= 8, "the mirrored solve: {work:?}");
        }
    }
}

/// A burst's first tick whose unconstrained plan breaks a few constraints
/// (a small step of the reference, from rest: at most `COLD_FEW`) is
/// solved by the active set from the rollout of that plan, without the
/// condensed interior point, and ends at clarabel's plan, every row kept;
/// a 10 m step (most of the horizon broken) still goes to the interior
/// point ([`a_cold_rate_limited_solve_ends_in_the_active_set`]).
#[test]
fn a_burst_that_breaks_a_few_constraints_starts_without_the_interior_point() {
    for a_max in [None, Some(3.0)] {
        for target in [0.3, 0.6] {
            let bounds = step_bounds(a_max);
            let mut alm = step_alm(bounds);
            let (got, want) = solve_step(&mut alm, bounds, target);
            let work = alm.active_set_work();
            eprintln!("{a_max:?}, {target} m: {work:?}");
            assert!(
                work.solves > 1,
                "{a_max:?}, {target} m: nothing broken: {work:?}"
            );
            assert_eq!(work.interior, 0, "{a_max:?}, {target} m: {work:?}");
            check_step(&format!("{a_max:?}, {target} m"), bounds, &got, &want);
        }
    }
    let bounds = step_bounds(None);
    let mut alm = step_alm(bounds);
    solve_step(&mut alm, bounds, 10.0);
    assert!(alm.active_set_work().interior > 0);
}

/// A corner entering the horizon's end: the reference still for most of
/// the horizon, then leaving at `speed` [m/s] over its last `ticks`; the
/// vehicle at rest. The unconstrained plan breaks the acceleration box
/// over the last stages, a block about twice the optimum's.
fn solve_corner(
    a_max: f64,
    speed: f64,
    ticks: usize,
) -> (Vec<f64>, Vec<f64>, super::active_set::Work, AxisBounds) {
    let mut bounds = step_bounds(Some(a_max));
    if let Some(rate) = &mut bounds.tilt_rate {
        rate.step = 3f64.to_radians();
    }
    let start = STEP_HORIZON + 1 - ticks;
    let reference: Vec<f64> = (0..=STEP_HORIZON)
        .map(|j| speed * DT * j.saturating_sub(start) as f64)
        .collect();
    let mut alm = step_alm(bounds);
    let (got, want) = solve_from_rest(&mut alm, bounds, &reference);
    (got, want, alm.active_set_work(), bounds)
}

/// A corner entering the horizon's end breaks a block of the acceleration
/// box there, about twice the optimum's: the active set starts from the
/// block's second half (`rollout.rs`, `trim_end_block`) and ends in 6
/// and 8 KKT solves, without the interior point, at clarabel's plan (13
/// and 12 from the whole block, freed one stage per solve).
#[test]
fn a_corner_entering_the_horizons_end_starts_from_its_blocks_second_half() {
    for (a_max, speed, ticks) in [(2.0, 4.0, 20), (3.0, 4.0, 30)] {
        let label = format!("±{a_max} m/s², {speed} m/s over the last {ticks} ticks");
        let (got, want, work, bounds) = solve_corner(a_max, speed, ticks);
        eprintln!("{label}: {work:?}");
        assert_eq!(work.interior, 0, "{label}: {work:?}");
        assert!(work.solves <= 8, "{label}: {work:?}");
        check_step(&label, bounds, &got, &want);
    }
}

/// The augmented Lagrangian alone ([`BoxAlmSolver`] at its cold tuning)
/// of the rate-limited step.
fn step_alm(bounds: AxisBounds) -> BoxAlmSolver {
    let (horizon, (q, r)) = (STEP_HORIZON, STEP_WEIGHTS);
    BoxAlmSolver::with_tuning(
        horizon,
        (q, r, DT),
        bounds,
        Smoothness::default(),
        true,
        crate::optimise::alm::COLD_TUNING,
    )
    .unwrap()
}

/// The rate-limited step from rest (nothing sent but 0) to `target` \[m\]
/// under `bounds`, solved by `alm` from the fast path's unconstrained
/// plan: its plan and clarabel's at its reference tuning.
fn solve_step(alm: &mut BoxAlmSolver, bounds: AxisBounds, target: f64) -> (Vec<f64>, Vec<f64>) {
    solve_from_rest(alm, bounds, &vec![target; STEP_HORIZON + 1])
}

/// The vehicle at rest (nothing sent but 0) planning along `reference`
/// (STEP_HORIZON + 1 outputs \[m\]) under `bounds`, solved by `alm` from
/// the fast path's unconstrained plan: its plan and clarabel's at its
/// reference tuning.
fn solve_from_rest(
    alm: &mut BoxAlmSolver,
    bounds: AxisBounds,
    reference: &[f64],
) -> (Vec<f64>, Vec<f64>) {
    let (horizon, (q, r)) = (STEP_HORIZON, STEP_WEIGHTS);
    let fixed = [0.0, 0.0, 0.0];
    let sent = Some(0.0);
    let mut want = vec![0.0; horizon + 1];
    ClarabelSolver::with_tuning(
        horizon,
        (q, r, DT),
        bounds,
        f64::INFINITY,
        Smoothness::default(),
        KktTuning::REFERENCE,
    )
    .unwrap()
    .solve_problem(AxisProblem {
        fixed: &fixed,
        sent,
        reference,
        plan: &mut want,
    })
    .unwrap();
    let mut got = vec![0.0; horizon + 1];
    FastBandedSolver::new(horizon, q, r, DT)
        .unwrap()
        .solve_problem(AxisProblem {
            fixed: &fixed,
            sent,
            reference,
            plan: &mut got,
        })
        .unwrap();
    alm.solve_problem(AxisProblem {
        fixed: &fixed,
        sent,
        reference,
        plan: &mut got,
    })
    .unwrap();
    (got, want)
}

/// A step's plan `got` at clarabel's `want` over the first ten outputs
/// (1e-5 m) and every tilt-rate row of `bounds` kept.
fn check_step(label: &str, bounds: AxisBounds, got: &[f64], want: &[f64]) {
    for (j, (g, w)) in got.iter().zip(want).take(11).enumerate() {
        assert!((g - w).abs() <= 1e-5, "{label}: y_{j}: {g} vs {w}");
    }
    assert!(
        !bounds.tilt_rate.unwrap().violated_by(got, Some(0.0), DT),
        "{label}: rows broken"
    );
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config::with_cases(100))]
    /// The augmented Lagrangian alone ([`BoxAlmSolver`], no interior point
    /// behind it) on tilt-rate rows: a cold solve, then the next tick's
    /// problem (the window one step on along its own plan, the reference
    /// moved on) warm-started from it — the path of the active-set polish
    /// — each against clarabel to the tolerances of
    /// `banded_tilt_rate_matches_clarabel`: cost no higher than 1e-7
    /// relative, the first ten outputs to 1e-5 m, every row kept. (A
    /// solve that gives up ends the case: the cascade's interior point
    /// takes those ticks.)
    #[test]
    fn alm_tilt_rate_rows_match_clarabel_cold_and_warm(
        horizon in 20usize..=160,
        q in 0.5f64..10.0,
        r in 1e-3f64..0.1,
        step_deg in 0.5f64..5.0,
        kappa in 1.0f64..12.0,
        a_max in proptest::option::of(2.0f64..7.0),
        speed in proptest::option::of(2.0f64..8.0),
        v0 in -5.0f64..5.0,
        a0 in -5.0f64..5.0,
        target in -20.0f64..20.0,
        slope in -3.0f64..3.0,
    ) {
        let rate = TiltRate { step: step_deg.to_radians(), kappa, gain: 1.0, gravity: G };
        let bounds = AxisBounds {
            acceleration: a_max.map(|a| [-a, a]),
            speed,
            tilt_rate: Some(rate),
            ..Default::default()
        };
        let smoothness = Smoothness::default();
        let mut reference_solver = ClarabelSolver::with_tuning(
            horizon, (q, r, DT), bounds, f64::INFINITY, smoothness, KktTuning::REFERENCE,
        )
        .unwrap();
        let mut alm = BoxAlmSolver::with_tuning(
            horizon, (q, r, DT), bounds, smoothness, true, crate::optimise::alm::COLD_TUNING,
        )
        .unwrap();
        let y0 = 0.3;
        let mut fixed = [y0, y0 + v0 * DT, y0 + 2.0 * v0 * DT + a0 * DT * DT];
        let mut sent = Some(a0);
        for tick in 0..2 {
            let reference: Vec<f64> = (0..=horizon)
                .map(|j| target + slope * DT * (j + tick) as f64)
                .collect();
            let mut want = vec![0.0; horizon + 1];
            let solved = reference_solver.solve_problem(AxisProblem {
                fixed: &fixed, sent, reference: &reference, plan: &mut want,
            });
            proptest::prop_assume!(solved.is_ok());
            let mut got = vec![0.0; horizon + 1];
            FastBandedSolver::with_smoothness(horizon, q, r, DT, smoothness)
                .unwrap()
                .solve_problem(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut got })
                .unwrap();
            // Where the augmented Lagrangian gives up, the cascade's
            // interior point solves (`banded_tilt_rate_matches_clarabel`):
            // what it does return is held to clarabel's plan.
            if alm
                .solve_problem(AxisProblem { fixed: &fixed, sent, reference: &reference, plan: &mut got })
                .is_err()
            {
                return Ok(());
            }
            proptest::prop_assert!(alm.warm_started() == (tick > 0));
            let cw = cost((q, r), &smoothness, sent, &reference, &want);
            let cg = cost((q, r), &smoothness, sent, &reference, &got);
            proptest::prop_assert!(
                cg <= cw + 1e-7 * (1.0 + cw.abs()),
                "tick {tick}: cost {cg} above clarabel's {cw}"
            );
            for (j, (g, w)) in got.iter().zip(&want).take(11).enumerate() {
                proptest::prop_assert!((g - w).abs() <= 1e-5, "tick {tick}: y_{j}: {g} vs {w}");
            }
            proptest::prop_assert!(!rate.violated_by(&got, sent, DT), "tick {tick}: rows broken");
            // The next tick: the window one step on along this plan, the
            // command its first stage asks for sent.
            let dt2 = DT * DT;
            let acc = |j: usize| (got[j + 2] - 2.0 * got[j + 1] + got[j]) / dt2;
            sent = Some(acc(0) + kappa * (acc(1) - acc(0)));
            fixed = [got[1], got[2], got[3]];
        }
    }
}
