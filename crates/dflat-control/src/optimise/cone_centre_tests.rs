//! Tests of the tilt cone about a centre per stage
//! ([`BandedConeSolver::set_centre`]): the disc bounds `a_f − o_f`, the
//! thrust's acceleration where the model adds `o_f` to it (the drag, a
//! learned residual). Each of the pair's methods against clarabel's SOCP
//! about the same centres, with and without the tilt-rate rows, and the
//! funnel's witness about them. The instances are `cone_tests`'s and
//! `cone_rate_tests`'s.

use super::cone::FUNNEL_RATE;
use super::cone_rate_tests::{
    COST_TOLERANCE, instance_axes, instance_weights, plans_of, rate_bounds, window,
};
use super::cone_tests::{
    Axis, DT, G, Plans, banded_start, clarabel_plans_centred, objective_centred, try_banded_plans,
};
use super::*;
use crate::ControlError;

/// Centres per stage f = 0..n−1 [m/s²]: `start` (a share of the radius
/// `a` per axis) moving by `slope` [m/s² per stage], as the drag's offset
/// along a plan that speeds up or slows down.
fn centres(n: usize, a: f64, start: [f64; 2], slope: [f64; 2]) -> Vec<[f64; 2]> {
    (0..n)
        .map(|f| [0, 1].map(|i| a * start[i] + slope[i] * f as f64))
        .collect()
}

/// One method of [`BandedConeSolver`] (`[ALM, interior point]`) on an
/// instance about `centre`, cold; `Err` when it fails.
fn centred_method(
    horizon: usize,
    weights: [AxisWeights; 2],
    bounds: ConeBounds,
    axes: &[Axis; 2],
    centre: &[[f64; 2]],
    methods: [bool; 2],
) -> Result<Plans, ControlError> {
    let mut solver =
        BandedConeSolver::with_methods(horizon, DT, weights, bounds, false, methods).unwrap();
    if let Some(alm) = solver.alm_mut() {
        alm.set_max_newton_steps(1000);
    }
    solver.set_centre(centre)?;
    try_banded_plans(&mut solver, weights, axes)
}

/// Whether the plans' thrust (each stage's acceleration less its
/// centre) keeps `radius` ([`ConeBounds::violated_within`]).
fn thrust_within(a: f64, plans: &Plans, centre: &[[f64; 2]], radius: &[f64]) -> bool {
    !ConeBounds::new(a, None).violated_within(&plans[0], &plans[1], DT, (radius, centre))
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config::with_cases(64))]
    /// The cone about a centre per stage (start up to ±0.8 of the radius
    /// per axis, moving up to ±0.02 m/s² a stage), without rows and with
    /// soft speed bounds: the cascade (augmented Lagrangian, interior
    /// point) gives clarabel's SOCP solution
    /// about the same centres — cost no higher (1e-7 relative), the first
    /// ten outputs to 1e-5 m — and every stage's acceleration less its
    /// centre keeps the radius.
    #[test]
    fn centred_cones_match_clarabel_socp(
        horizon in 20usize..=200,
        q in proptest::array::uniform2(0.5f64..10.0),
        r in proptest::array::uniform2(1e-3f64..0.1),
        tilt_deg in 5.0f64..35.0,
        speed in proptest::option::of(2.0f64..8.0),
        v0 in proptest::array::uniform2(-6.0f64..6.0),
        a0_frac in proptest::array::uniform2(-0.6f64..0.6),
        target in proptest::array::uniform2(-20.0f64..20.0),
        slope in proptest::array::uniform2(-3.0f64..3.0),
        start in proptest::array::uniform2(-0.8f64..0.8),
        drift in proptest::array::uniform2(-0.02f64..0.02),
    ) {
        let a = G * tilt_deg.to_radians().tan();
        let bounds = ConeBounds::new(a, speed);
        let weights = instance_weights(q, r, [1.0; 2], None);
        let axes = instance_axes(horizon, a, v0, a0_frac, [0.0; 2], target, slope);
        let n = horizon - 2;
        let centre = centres(n, a, start, drift);
        let want = clarabel_plans_centred(horizon, weights, bounds, &axes, None, Some(&centre));
        proptest::prop_assume!(want.is_some(), "clarabel did not solve");
        let want = want.unwrap();
        let obj = |p: &Plans| {
            objective_centred(horizon, &weights, &bounds, &axes, [&p[0], &p[1]], (&[], &centre))
        };
        let ow = obj(&want);
        for (name, methods) in [("cascade", [true, true])] {
            let got = centred_method(horizon, weights, bounds, &axes, &centre, methods);
            proptest::prop_assert!(got.is_ok(), "{name}: {:?}", got.err());
            let got = got.unwrap();
            let og = obj(&got);
            proptest::prop_assert!(og <= ow + 1e-7 * (1.0 + ow.abs()), "{name}: cost {og} vs clarabel {ow}");
            for i in 0..2 {
                for j in 0..=10 {
                    proptest::prop_assert!(
                        (got[i][j] - want[i][j]).abs() <= 1e-5,
                        "{name} axis {i} y_{j}: {} vs {}", got[i][j], want[i][j]
                    );
                }
            }
            proptest::prop_assert!(thrust_within(a, &got, &centre, &vec![a; n]), "{name}: outside the cone");
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::test_runner::Config::with_cases(48))]
    /// The same with the tilt-rate rows (the funnel about the centres):
    /// the witness keeps every row and its stage's funnel about its
    /// centre; the cascade and the interior point alone give clarabel's SOCP
    /// solution about the same centres (cost [`COST_TOLERANCE`], the
    /// first ten outputs to 1e-5 m), keep the rate rows and the funnel
    /// about the centres.
    #[test]
    fn centred_cones_with_tilt_rate_match_clarabel_socp(
        horizon in 20usize..=160,
        q in proptest::array::uniform2(0.5f64..10.0),
        r in proptest::array::uniform2(1e-3f64..0.1),
        tilt_deg in 8.0f64..35.0,
        step_deg in 0.5f64..5.0,
        kappa in proptest::array::uniform2(1.0f64..12.0),
        speed in proptest::option::of(2.0f64..8.0),
        v0 in proptest::array::uniform2(-6.0f64..6.0),
        a0_frac in proptest::array::uniform2(-0.8f64..0.8),
        sent_delta in proptest::array::uniform2(-3.0f64..3.0),
        target in proptest::array::uniform2(-20.0f64..20.0),
        slope in proptest::array::uniform2(-3.0f64..3.0),
        smooth in proptest::option::of(1.0f64..50.0),
        start in proptest::array::uniform2(-0.8f64..0.8),
        drift in proptest::array::uniform2(-0.02f64..0.02),
    ) {
        let (a, rates, bounds) = rate_bounds(tilt_deg, step_deg, kappa, speed);
        let weights = instance_weights(q, r, kappa, smooth);
        let axes = instance_axes(horizon, a, v0, a0_frac, sent_delta, target, slope);
        let n = horizon - 2;
        let centre = centres(n, a, start, drift);
        let fixed = [&axes[0].fixed, &axes[1].fixed];
        let sent = [axes[0].sent, axes[1].sent];
        let radius = vec![a; n];
        let mut funnel = vec![0.0; n];
        bounds.funnel_radius((&radius, &centre), fixed, sent, DT, &mut funnel);
        // The witness: a feasible point about the centres.
        let (mut px, mut py) = (vec![0.0; n], vec![0.0; n]);
        bounds.witness_start((&radius, &centre), fixed, sent, DT, FUNNEL_RATE, [&mut px, &mut py]);
        let witness = plans_of(fixed, [&px, &py], horizon);
        proptest::prop_assert!(thrust_within(a, &witness, &centre, &funnel), "witness: outside the funnel");
        for i in 0..2 {
            proptest::prop_assert!(!rates[i].violated_by(&witness[i], sent[i], DT), "witness axis {i}: rate rows");
        }
        let want = clarabel_plans_centred(horizon, weights, bounds, &axes, None, Some(&centre));
        proptest::prop_assume!(want.is_some(), "clarabel did not solve");
        let want = want.unwrap();
        let obj = |p: &Plans| {
            objective_centred(horizon, &weights, &bounds, &axes, [&p[0], &p[1]], (&[], &centre))
        };
        let ow = obj(&want);
        for (name, methods) in [("cascade", [true, true]), ("interior point", [false, true])] {
            let got = centred_method(horizon, weights, bounds, &axes, &centre, methods);
            proptest::prop_assert!(got.is_ok(), "{name}: {:?}", got.err());
            let got = got.unwrap();
            let og = obj(&got);
            proptest::prop_assert!(
                og <= ow + COST_TOLERANCE * (1.0 + ow.abs()),
                "{name}: cost {og} vs clarabel {ow}"
            );
            for i in 0..2 {
                for j in 0..=10 {
                    proptest::prop_assert!(
                        (got[i][j] - want[i][j]).abs() <= 1e-5,
                        "{name} axis {i} y_{j}: {} vs {}", got[i][j], want[i][j]
                    );
                }
                proptest::prop_assert!(!rates[i].violated_by(&got[i], sent[i], DT), "{name} axis {i}: rate rows");
            }
            proptest::prop_assert!(thrust_within(a, &got, &centre, &funnel), "{name}: outside the funnel");
        }
    }
}

/// A plan whose accelerations lie inside the cone about its centre is
/// the unconstrained one: with both axes accelerating at 1.2·A (outside
/// the cone about 0) and the centre there, the banded solver returns the
/// fast path's plan (1e-9 m), and without the centre it does not.
#[test]
fn a_plan_inside_the_centred_cone_is_the_unconstrained_plan() {
    let (horizon, a) = (80, G * 20f64.to_radians().tan());
    let weights = instance_weights([5.0; 2], [0.01; 2], [1.0; 2], None);
    let acc = 1.2 * a / std::f64::consts::SQRT_2;
    // Each axis's reference the window's own accelerating trajectory: the
    // unconstrained plan follows it, at acc on both axes.
    let axes: [Axis; 2] = std::array::from_fn(|_| {
        let fixed = window(2.0, acc);
        Axis {
            fixed,
            sent: None,
            reference: (0..=horizon)
                .map(|j| {
                    let t = (j as f64 - 2.0) * DT;
                    fixed[2] + (2.0 + 2.0 * acc * DT) * t + 0.5 * acc * t * t
                })
                .collect(),
        }
    });
    let n = horizon - 2;
    let bounds = ConeBounds::new(a, None);
    let fast = banded_start(horizon, weights, &axes);
    let peak = ConeBounds::peak_acceleration(&fast[0], &fast[1], DT);
    assert!(
        peak > 1.1 * a,
        "the unconstrained plan leaves the cone about 0: {peak}"
    );
    let centre = vec![[acc, acc]; n];
    let got = centred_method(horizon, weights, bounds, &axes, &centre, [true, true]).unwrap();
    for i in 0..2 {
        for (j, (g, w)) in got[i].iter().zip(&fast[i]).enumerate() {
            assert!(
                (g - w).abs() < 1e-9,
                "axis {i} y_{j}: {g} vs the fast plan's {w}"
            );
        }
    }
    let uncentred = centred_method(
        horizon,
        weights,
        bounds,
        &axes,
        &vec![[0.0; 2]; n],
        [true, true],
    )
    .unwrap();
    assert!(!bounds.violated_by(&uncentred[0], &uncentred[1], DT));
    assert!(
        (0..2).any(|i| (uncentred[i][5] - fast[i][5]).abs() > 1e-6),
        "about 0 the cone binds"
    );
}

/// The centre is checked: a wrong length or a value that is not finite
/// is refused in words, and the solver keeps its centre.
#[test]
fn a_bad_centre_is_refused_and_changes_nothing() {
    let (horizon, a) = (30, 3.0);
    let weights = instance_weights([5.0; 2], [0.01; 2], [1.0; 2], None);
    let mut solver =
        BandedConeSolver::new(horizon, DT, weights, ConeBounds::new(a, None), true).unwrap();
    solver.set_centre(&vec![[0.5, -0.5]; horizon - 2]).unwrap();
    for bad in [vec![[0.0; 2]; horizon - 3], {
        let mut c = vec![[0.0; 2]; horizon - 2];
        c[7][1] = f64::NAN;
        c
    }] {
        let err = solver.set_centre(&bad).unwrap_err().to_string();
        assert!(err.contains("centre"), "{err}");
    }
    let alm = solver.alm_mut().unwrap();
    assert!(alm.centre().iter().all(|c| *c == [0.5, -0.5]));
}
