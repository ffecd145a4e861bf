//! Bad data is an error value, never a panic or a NaN: free fall, tilt at
//! or beyond 90°, gimbal lock, non-finite numbers, wrong window lengths, and
//! arbitrary (huge, tiny, NaN, infinite) windows.

use dflat_model::attitude::{euler_rates, wrap_angle_difference};
use dflat_model::full::{FullInput, FullOutput, FullState};
use dflat_model::planar::{PlanarInput, PlanarOutput};
use dflat_model::spatial::{SpatialInput, SpatialOutput};
use dflat_model::{
    FlatError, FlatModel, Frame, FullModel, FullParams, PlanarModel, PlanarParams, SpatialModel,
    SpatialParams,
};
use proptest::prelude::*;

fn planar() -> PlanarModel {
    PlanarModel::new(PlanarParams::default()).unwrap()
}

fn spatial(frame: Frame) -> SpatialModel {
    SpatialModel::new(SpatialParams {
        frame,
        ..Default::default()
    })
    .unwrap()
}

fn full(frame: Frame) -> FullModel {
    FullModel::new(FullParams {
        frame,
        ..Default::default()
    })
    .unwrap()
}

/// Outputs y_i = y_0 + ½·a·(i·δt)²: constant world acceleration `a`.
fn parabola(a: [f64; 3], dt: f64, n: usize) -> Vec<[f64; 3]> {
    (0..n)
        .map(|i| {
            let t = i as f64 * dt;
            [
                1.0 + 0.5 * a[0] * t * t,
                -2.0 + 0.5 * a[1] * t * t,
                3.0 + 0.5 * a[2] * t * t,
            ]
        })
        .collect()
}

/// World acceleration of free fall in each frame.
fn gravity(frame: Frame, g: f64) -> [f64; 3] {
    match frame {
        Frame::Ned => [0.0, 0.0, g],
        Frame::Zup => [0.0, 0.0, -g],
    }
}

/// World accelerations that need a thrust no multirotor gives in `frame`:
/// free fall (no thrust direction), gravity plus 5 m/s² sideways along
/// horizontal `axis` (tilt 90°) and twice gravity (inverted, tilt 180°).
fn beyond_thrust(frame: Frame, g: f64, axis: usize) -> [[f64; 3]; 3] {
    let down = gravity(frame, g);
    let mut sideways = down;
    sideways[axis] = 5.0;
    [down, sideways, [0.0, 0.0, 2.0 * down[2]]]
}

#[test]
fn spatial_free_fall_and_tilt_beyond_90_are_errors() {
    for frame in [Frame::Ned, Frame::Zup] {
        let m = spatial(frame);
        let (g, dt) = (m.params().g, m.params().dt);
        for a in beyond_thrust(frame, g, 0) {
            let y: Vec<SpatialOutput> = parabola(a, dt, 4)
                .into_iter()
                .map(SpatialOutput::from)
                .collect();
            assert_eq!(
                m.state_from_outputs(&y[..3]),
                Err(FlatError::FreeFall),
                "{frame:?} {a:?}"
            );
            assert_eq!(m.input_from_outputs(&y), Err(FlatError::FreeFall));
            assert_eq!(
                m.next_output(&y[..3], &SpatialInput::new(0.0, 0.0, g)),
                Err(FlatError::FreeFall)
            );
            assert_eq!(m.attitude_thrust(&a.into()), Err(FlatError::FreeFall));
        }
    }
}

#[test]
fn full_free_fall_tilt_and_gimbal_lock_are_errors() {
    for frame in [Frame::Ned, Frame::Zup] {
        let m = full(frame);
        for a in beyond_thrust(frame, m.params().g, 1) {
            let dt = m.params().dt;
            let y: Vec<FullOutput> = parabola(a, dt, 6)
                .into_iter()
                .enumerate()
                .map(|(i, p)| FullOutput::new(p[0], p[1], p[2], 0.1 * i as f64))
                .collect();
            assert_eq!(
                m.state_from_outputs(&y[..4]),
                Err(FlatError::FreeFall),
                "{frame:?} {a:?}"
            );
            assert_eq!(m.input_from_outputs(&y[..5]), Err(FlatError::FreeFall));
            let mut out = [FullOutput::zeros(); 1];
            assert_eq!(
                m.predict_outputs(&y[..4], &[FullInput::zeros(); 3], &mut out),
                Err(FlatError::FreeFall)
            );
        }
    }
    // Pitch ±90°: W is singular, the Euler rates are undefined.
    let half_pi = std::f64::consts::FRAC_PI_2;
    assert_eq!(
        euler_rates(half_pi, 0.3, [0.1, 0.2, 0.3]),
        Err(FlatError::Singular)
    );
    assert_eq!(
        euler_rates(-half_pi, 0.0, [0.0; 3]),
        Err(FlatError::Singular)
    );
    // …and the step holds the angles instead of producing ±∞.
    let m = full(Frame::Ned);
    let mut x = FullState::zeros();
    x[6] = half_pi;
    x[9] = 0.5;
    x[11] = 0.7;
    let next = m.step(&x, &FullInput::new(20.0, 0.0, 0.0, 0.0));
    assert!(next.iter().all(|v| v.is_finite()));
    assert_eq!((next[6], next[7], next[8]), (x[6], x[7], x[8]));
}

#[test]
fn non_finite_windows_are_errors() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut yp = [PlanarOutput::new(1.0, 2.0); 4];
        yp[2].y = bad;
        let m = planar();
        assert!(matches!(
            m.state_from_outputs(&yp[..3]),
            Err(FlatError::NonFinite(_))
        ));
        assert!(matches!(
            m.input_from_outputs(&yp),
            Err(FlatError::NonFinite(_))
        ));
        assert!(matches!(
            m.next_output(&yp[..3], &PlanarInput::zeros()),
            Err(FlatError::NonFinite(_))
        ));
        let good = [PlanarOutput::new(1.0, 2.0); 3];
        assert!(matches!(
            m.next_output(&good, &PlanarInput::new(bad, 0.0)),
            Err(FlatError::NonFinite(_))
        ));

        let mut ys = [SpatialOutput::new(1.0, 2.0, 3.0); 4];
        ys[1].z = bad;
        let m = spatial(Frame::Ned);
        assert!(matches!(
            m.state_from_outputs(&ys[..3]),
            Err(FlatError::NonFinite(_))
        ));
        assert!(matches!(
            m.input_from_outputs(&ys),
            Err(FlatError::NonFinite(_))
        ));
        let good = [SpatialOutput::new(1.0, 2.0, 3.0); 3];
        assert!(matches!(
            m.next_output(&good, &SpatialInput::new(0.0, 0.0, bad)),
            Err(FlatError::NonFinite(_))
        ));

        let mut yf = [FullOutput::new(1.0, 2.0, 3.0, 0.5); 5];
        yf[4].w = bad;
        let m = full(Frame::Ned);
        assert!(matches!(
            m.input_from_outputs(&yf),
            Err(FlatError::NonFinite(_))
        ));
        yf[0].x = bad;
        assert!(matches!(
            m.state_from_outputs(&yf[..4]),
            Err(FlatError::NonFinite(_))
        ));
        let good = [FullOutput::new(1.0, 2.0, 3.0, 0.5); 4];
        let mut out = [FullOutput::zeros(); 1];
        let inputs = [
            FullInput::zeros(),
            FullInput::new(bad, 0.0, 0.0, 0.0),
            FullInput::zeros(),
        ];
        assert!(matches!(
            m.predict_outputs(&good, &inputs, &mut out),
            Err(FlatError::NonFinite(_))
        ));
    }
}

/// The error of a window of `got` outputs where `expected` are needed.
fn window(expected: usize, got: usize) -> FlatError {
    FlatError::WindowLength { expected, got }
}

#[test]
fn wrong_window_lengths_are_errors() {
    let m = planar();
    let y = [PlanarOutput::zeros(); 5];
    for n in [0, 2, 4, 5] {
        assert_eq!(m.state_from_outputs(&y[..n]), Err(window(3, n)));
        assert_eq!(
            m.next_output(&y[..n], &PlanarInput::zeros()),
            Err(window(3, n))
        );
    }
    assert_eq!(m.input_from_outputs(&y[..3]), Err(window(4, 3)));

    let m = spatial(Frame::Zup);
    let y = [SpatialOutput::zeros(); 5];
    for n in [0, 2, 4, 5] {
        assert_eq!(m.state_from_outputs(&y[..n]), Err(window(3, n)));
        assert_eq!(
            m.next_output(&y[..n], &SpatialInput::zeros()),
            Err(window(3, n))
        );
    }
    assert_eq!(m.input_from_outputs(&y), Err(window(4, 5)));

    let m = full(Frame::Ned);
    let y = [FullOutput::zeros(); 6];
    for n in [0, 3, 5] {
        assert_eq!(m.state_from_outputs(&y[..n]), Err(window(4, n)));
    }
    for n in [0, 4, 6] {
        assert_eq!(m.input_from_outputs(&y[..n]), Err(window(5, n)));
    }
    // predict_outputs needs out.len() + 2 inputs.
    let mut out = [FullOutput::zeros(); 2];
    assert_eq!(
        m.predict_outputs(&y[..4], &[FullInput::zeros(); 3], &mut out),
        Err(window(4, 3))
    );
    assert_eq!(
        m.predict_outputs(&y[..3], &[FullInput::zeros(); 4], &mut out),
        Err(window(4, 3))
    );
}

#[test]
fn full_model_treats_yaw_modulo_two_pi() {
    // A trajectory crossing ψ = π, once unwrapped and once wrapped to (−π, π].
    let m = full(Frame::Ned);
    let mut x = FullState::zeros();
    x[8] = 3.1;
    x[11] = 2.0;
    x[9] = 0.3;
    let u = FullInput::new(m.hover_thrust(), 0.01, -0.02, 0.01);
    let mut ys = vec![m.output(&x)];
    for _ in 0..4 {
        x = m.step(&x, &u);
        ys.push(m.output(&x));
    }
    assert!(ys[4].w > std::f64::consts::PI);
    let wrapped: Vec<FullOutput> = ys
        .iter()
        .map(|y| FullOutput::new(y.x, y.y, y.z, wrap_angle_difference(y.w)))
        .collect();
    assert!(wrapped[4].w < 0.0);
    let (a, b) = (
        m.input_from_outputs(&ys).unwrap(),
        m.input_from_outputs(&wrapped).unwrap(),
    );
    assert!((a - b).abs().max() < 1e-6, "{a} vs {b}");
    let (a, b) = (
        m.state_from_outputs(&ys[1..]).unwrap(),
        m.state_from_outputs(&wrapped[1..]).unwrap(),
    );
    assert!((a.fixed_rows::<3>(9) - b.fixed_rows::<3>(9)).abs().max() < 1e-9);
}

/// Any f64: NaN, ±∞, huge, subnormal, zero, ordinary.
fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        proptest::num::f64::ANY,
        -1e308..1e308f64,
        -100.0..100.0f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::MAX),
        Just(-f64::MAX),
        Just(0.0),
    ]
}

/// Finite but possibly huge: exercises overflow inside the maps.
fn finite_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -1e308..1e308f64,
        -1e160..1e160f64,
        -100.0..100.0f64,
        Just(f64::MAX),
        Just(-f64::MAX),
        Just(f64::MIN_POSITIVE),
    ]
}

fn all_finite<const N: usize>(r: &Result<nalgebra::SVector<f64, N>, FlatError>) -> bool {
    match r {
        Ok(v) => v.iter().all(|c| c.is_finite()),
        Err(_) => true,
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]

    #[test]
    fn arbitrary_windows_give_errors_or_finite_values(
        v in prop_oneof![
            proptest::collection::vec(any_f64(), 32),
            proptest::collection::vec(finite_f64(), 32),
        ],
        ned in any::<bool>(),
    ) {
        let frame = if ned { Frame::Ned } else { Frame::Zup };
        let m = planar();
        let yp: Vec<PlanarOutput> = v.chunks(2).take(4).map(PlanarOutput::from_column_slice).collect();
        let up = PlanarInput::new(v[8], v[9]);
        prop_assert!(all_finite(&m.state_from_outputs(&yp[..3])));
        prop_assert!(all_finite(&m.input_from_outputs(&yp)));
        prop_assert!(all_finite(&m.next_output(&yp[..3], &up)));

        let m = spatial(frame);
        let ys: Vec<SpatialOutput> = v.chunks(3).take(4).map(SpatialOutput::from_column_slice).collect();
        let us = SpatialInput::new(v[12], v[13], v[14]);
        prop_assert!(all_finite(&m.state_from_outputs(&ys[..3])));
        prop_assert!(all_finite(&m.input_from_outputs(&ys)));
        prop_assert!(all_finite(&m.next_output(&ys[..3], &us)));

        let m = full(frame);
        let yf: Vec<FullOutput> = v.chunks(4).take(5).map(FullOutput::from_column_slice).collect();
        prop_assert!(all_finite(&m.state_from_outputs(&yf[..4])));
        prop_assert!(all_finite(&m.input_from_outputs(&yf)));
        let uf: Vec<FullInput> = v[20..32].chunks(4).map(FullInput::from_column_slice).collect();
        let mut out = [FullOutput::zeros(); 1];
        if m.predict_outputs(&yf[..4], &uf, &mut out).is_ok() {
            prop_assert!(out.iter().all(|o| o.iter().all(|c| c.is_finite())));
        }
    }
}
