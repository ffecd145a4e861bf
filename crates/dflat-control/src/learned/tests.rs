use super::*;
use nalgebra::Matrix3;
use proptest::prelude::*;

/// Body→world rotation `Rz(ψ)·Ry(θ)·Rx(φ)` (ZYX), written out here as the
/// forward model's frame convention.
fn rotation(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let rx = Matrix3::new(
        1.0,
        0.0,
        0.0,
        0.0,
        roll.cos(),
        -roll.sin(),
        0.0,
        roll.sin(),
        roll.cos(),
    );
    let ry = Matrix3::new(
        pitch.cos(),
        0.0,
        pitch.sin(),
        0.0,
        1.0,
        0.0,
        -pitch.sin(),
        0.0,
        pitch.cos(),
    );
    let rz = Matrix3::new(
        yaw.cos(),
        -yaw.sin(),
        0.0,
        yaw.sin(),
        yaw.cos(),
        0.0,
        0.0,
        0.0,
        1.0,
    );
    rz * ry * rx
}

/// A residual with the weights of an airframe's aerodynamics: parasitic
/// drag `cq` [1/m] and rotor drag `d` [1/s] (and nothing else).
pub(crate) fn aero_residual(cq: f64, d: f64, speed_max: f64) -> LearnedResidual {
    let features = vec![Feature::Bias, Feature::Quadratic, Feature::RotorPlane];
    let m = columns(&features);
    let weights = std::array::from_fn(|axis| {
        let mut row = vec![0.0; m];
        row[1 + axis] = -cq;
        row[4 + axis] = -d;
        row
    });
    LearnedResidual {
        format: FORMAT.into(),
        version: VERSION,
        vehicle_model: "spatial".into(),
        vehicle: BTreeMap::from([("tau".into(), 0.2), ("hover_thrust".into(), 0.5)]),
        dt: 0.02,
        window: 3,
        features,
        lambda: 1e-6,
        weights,
        support: Support {
            speed_max,
            tilt_max: 0.5,
            thrust_min: 8.0,
            thrust_max: 12.0,
        },
        validation: Validation {
            one_step_parametric_m: 1e-3,
            one_step_learned_m: 1e-4,
            horizon_s: 0.5,
            horizon_parametric_m: 0.1,
            horizon_learned_m: 0.01,
            samples: 100,
            start_parametric_s: 0.4,
            start_learned_s: 1.2,
            acceleration_parametric: 1.0,
            acceleration_learned: 0.1,
        },
        seconds: 60.0,
    }
}

proptest! {
    /// The basis spans the aerodynamics of the forward model: with the
    /// weights −c_q and −d the residual is `−c_q·|v|·v − d·R·diag(1,1,0)·Rᵀ·v`
    /// for any attitude (heading included).
    #[test]
    fn the_basis_spans_parasitic_and_rotor_drag(
        roll in -0.6f64..0.6, pitch in -0.6f64..0.6, yaw in -3.1f64..3.1,
        vx in -12.0f64..12.0, vy in -12.0f64..12.0, vz in -4.0f64..4.0,
        cq in 0.0f64..0.1, d in 0.0f64..0.5,
    ) {
        let r = rotation(roll, pitch, yaw);
        let n = r * Vector3::z();
        let v = Vector3::new(vx, vy, vz);
        let plane = r * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)) * r.transpose();
        let want = -v * (cq * v.norm()) - plane * v * d;
        let got = aero_residual(cq, d, 20.0).residual(&v, &n);
        prop_assert!((got - want).norm() < 1e-9 * (1.0 + want.norm()), "{got} vs {want}");
    }

    /// The support's weight is 1 inside, in [0, 1] everywhere and
    /// non-increasing away from the support.
    #[test]
    fn the_support_weight_fades_monotonically(speed in 0.0f64..20.0, step in 0.0f64..5.0) {
        let m = aero_residual(0.03, 0.2, 3.0);
        let w = m.support_weight(speed, 0.2, 10.0);
        prop_assert!((0.0..=1.0).contains(&w));
        if speed <= 3.0 {
            prop_assert_eq!(w, 1.0);
        }
        prop_assert!(m.support_weight(speed + step, 0.2, 10.0) <= w);
    }
}

/// Learned at up to 3 m/s, flown at 9 m/s: the residual is 0 there (the
/// parametric model alone), full at 3 m/s, and never non-finite.
#[test]
fn out_of_support_the_residual_is_the_parametric_model() {
    let m = aero_residual(0.03, 0.2, 3.0);
    let n = Vector3::z();
    assert_eq!(
        m.acceleration(&Vector3::new(9.0, 0.0, 0.0), &n, 10.0),
        Vector3::zeros()
    );
    let inside = m.acceleration(&Vector3::new(3.0, 0.0, 0.0), &n, 10.0);
    assert!(
        (inside.x - (-0.03 * 9.0 - 0.2 * 3.0)).abs() < 1e-12,
        "{inside}"
    );
    // Tilt or thrust outside: faded too.
    let tilted = Vector3::new(0.8f64.sin(), 0.0, 0.8f64.cos());
    assert_eq!(
        m.acceleration(&Vector3::new(2.0, 0.0, 0.0), &tilted, 10.0),
        Vector3::zeros()
    );
    assert_eq!(
        m.acceleration(&Vector3::new(2.0, 0.0, 0.0), &n, 20.0),
        Vector3::zeros()
    );
    let nan = Vector3::new(f64::NAN, 0.0, 0.0);
    assert_eq!(m.acceleration(&nan, &n, 10.0), Vector3::zeros());
}

/// Another airframe's model is refused in words naming the field; the
/// table it was learned with is accepted.
#[test]
fn another_vehicle_table_is_refused() {
    let m = aero_residual(0.03, 0.2, 3.0);
    m.validate().unwrap();
    m.check_vehicle(
        "spatial",
        &[("tau", 0.2), ("hover_thrust", 0.5), ("k", 1.0)],
    )
    .unwrap();
    let err = m
        .check_vehicle("spatial", &[("tau", 0.25), ("hover_thrust", 0.5)])
        .unwrap_err();
    assert!(err.to_string().contains("vehicle.tau = 0.2"), "{err}");
    assert!(err.to_string().contains("0.25"), "{err}");
    let err = m
        .check_vehicle("planar", &[("tau", 0.2), ("hover_thrust", 0.5)])
        .unwrap_err();
    assert!(err.to_string().contains("vehicle.model"), "{err}");
    let err = m.check_vehicle("spatial", &[("tau", 0.2)]).unwrap_err();
    assert!(
        err.to_string().contains("hover_thrust") && err.to_string().contains("nothing"),
        "{err}"
    );
    // A file from before `drag_rotor` existed was learned without it: it
    // loads at 0 and is refused against a rotor drag.
    assert!(!m.vehicle.contains_key("drag_rotor"));
    let table = [("tau", 0.2), ("hover_thrust", 0.5), ("drag_rotor", 0.0)];
    m.check_vehicle("spatial", &table).unwrap();
    let err = m
        .check_vehicle(
            "spatial",
            &[("tau", 0.2), ("hover_thrust", 0.5), ("drag_rotor", 0.2)],
        )
        .unwrap_err();
    assert!(
        err.to_string().contains("drag_rotor") && err.to_string().contains("0.2"),
        "{err}"
    );
}

/// Bad files are refused naming the field.
#[test]
fn a_bad_file_names_its_field() {
    let good = aero_residual(0.03, 0.2, 3.0);
    let mut m = good.clone();
    m.weights[1].pop();
    assert!(
        m.validate()
            .unwrap_err()
            .to_string()
            .starts_with("weights[1]")
    );
    let mut m = good.clone();
    m.weights[2][0] = f64::NAN;
    assert!(
        m.validate()
            .unwrap_err()
            .to_string()
            .starts_with("weights[2]")
    );
    let mut m = good.clone();
    m.version = 1;
    assert!(matches!(
        m.validate(),
        Err(LearnedError::Version { found: 1 })
    ));
    let mut m = good.clone();
    m.format = "x".into();
    assert!(matches!(m.validate(), Err(LearnedError::Format { .. })));
    let mut m = good.clone();
    m.features.push(Feature::Bias);
    assert!(
        m.validate()
            .unwrap_err()
            .to_string()
            .starts_with("features")
    );
    let mut m = good;
    m.support.thrust_max = 1.0;
    assert!(
        m.validate()
            .unwrap_err()
            .to_string()
            .starts_with("support.thrust_max")
    );
}
