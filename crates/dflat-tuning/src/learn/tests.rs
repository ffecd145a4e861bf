use super::data::{Pose, Tick};
use super::parametric::thrust_axis;
use super::*;
use nalgebra::Vector3;

fn vehicle() -> VehicleTable {
    let parametric = Parametric {
        spatial: true,
        g: 9.81,
        tau: 0.2,
        k: 1.0,
        delay: 0.0,
        tau_thrust: 0.05,
        hover_thrust: 0.5,
        drag_h: 0.0,
        drag_v: 0.0,
        drag_rotor: 0.0,
        dt: 0.02,
    };
    VehicleTable {
        model: "spatial".into(),
        fields: vec![("tau".into(), 0.2), ("hover_thrust".into(), 0.5)],
        parametric,
    }
}

/// A flight of `seconds` on the forward model: the parametric model's
/// attitude and thrust lags, and the translation `v̇ = g·e3 − T·n − c_q·|v|·v
/// − d·(v − n·(n·v))` integrated in 10 substeps per tick; tilt commands of
/// an amplitude scaled by `speed` (sums of slow sines; the speeds flown
/// are up to about twice `speed`: the support says), thrust that holds the
/// altitude on average.
fn flight(seconds: f64, cq: f64, d: f64, speed: f64) -> Run {
    flight_sensed(seconds, cq, d, speed, 1, 0.0)
}

/// As [`flight_sensed`], with a constant acceleration `bias` [m/s², NED]
/// no parametric term has (a steady wind's force).
fn flight_sensed(seconds: f64, cq: f64, d: f64, speed: f64, every: usize, sigma: f64) -> Run {
    flight_biased(seconds, (cq, d, speed), every, sigma, Vector3::zeros())
}

/// As [`flight`], the poses every `every` ticks with Gaussian noise
/// `sigma` \[m\] per axis (a fixed pseudo-random sequence), and the
/// constant acceleration `bias`.
fn flight_biased(
    seconds: f64,
    aero: (f64, f64, f64),
    every: usize,
    sigma: f64,
    bias: Vector3<f64>,
) -> Run {
    flight_with(seconds, aero, every, sigma, bias, 0.05)
}

/// As [`flight_biased`], the thrust's slow variation about the hover
/// `wobble` (a fraction; 0.05 in the others: 0 holds the altitude, the
/// vertical speed barely moves).
fn flight_with(
    seconds: f64,
    (cq, d, speed): (f64, f64, f64),
    every: usize,
    sigma: f64,
    bias: Vector3<f64>,
    wobble: f64,
) -> Run {
    let m = vehicle().parametric;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut gauss = move || {
        let (u, v) = (uniform().max(1e-300), uniform());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    };
    let ticks = (seconds / m.dt) as usize;
    let amp = (speed * 0.09).min(0.5);
    let (mut p, mut v) = (Vector3::zeros(), Vector3::<f64>::zeros());
    let (mut roll, mut pitch, mut c) = (0.0f64, 0.0f64, m.hover_thrust);
    let mut out = Vec::with_capacity(ticks);
    let mut poses = Vec::with_capacity(ticks);
    for i in 0..ticks {
        let t = i as f64 * m.dt;
        let cp = amp * ((0.31 * t).sin() + 0.4 * (1.3 * t + 0.5).sin());
        let cr = amp * ((0.23 * t + 1.0).sin() + 0.4 * (1.1 * t).sin());
        let ct =
            m.hover_thrust / (cp.cos() * cr.cos()) * (1.0 + wobble * (0.9 * t).sin()) + 0.02 * v.z;
        out.push(Tick {
            t,
            euler: [cr, cp, 0.0],
            thrust: ct,
        });
        if i % every == 0 {
            let noise = Vector3::new(gauss(), gauss(), gauss()) * sigma;
            poses.push(Pose {
                t,
                y: p + noise,
                truth: Some(p),
            });
        }
        let n = thrust_axis(roll, pitch, 0.0);
        let thrust = m.g * c / m.hover_thrust;
        let h = m.dt / 10.0;
        for _ in 0..10 {
            let a = Vector3::new(0.0, 0.0, m.g) + bias
                - n * thrust
                - v * (cq * v.norm())
                - (v - n * n.dot(&v)) * d;
            p += v * h + a * (0.5 * h * h);
            v += a * h;
        }
        roll += m.dt / m.tau * (m.k * cr - roll);
        pitch += m.dt / m.tau * (m.k * cp - pitch);
        c += m.dt / m.tau_thrust * (ct - c);
    }
    Run { ticks: out, poses }
}

/// On the aerodynamics no parametric term has (0.03 |v|v, rotor drag
/// 0.2 /s), the learned residual halves the held-out horizon error (and
/// the one-step error), and it chose a basis with the quadratic term.
#[test]
fn the_residual_halves_the_held_out_error_on_aerodynamics() {
    let runs = vec![flight(240.0, 0.03, 0.2, 7.0)];
    let learned = learn(&runs, &vehicle()).unwrap();
    let v = learned.residual.validation;
    eprintln!(
        "learned: window {}, basis {:?}, λ {:e}; {:?}; {v:?}",
        learned.residual.window,
        learned.residual.features,
        learned.residual.lambda,
        learned.residual.support
    );
    assert!(v.horizon_learned_m <= 0.5 * v.horizon_parametric_m, "{v:?}");
    assert!(
        v.one_step_learned_m <= 0.5 * v.one_step_parametric_m,
        "{v:?}"
    );
    assert!(v.samples > 100, "{v:?}");
    // A linear term the airframe has not is not determined (its weights
    // are noise about 0): said, not learned.
    assert!(
        learned
            .unexcited
            .iter()
            .all(|(f, _)| *f == Feature::Velocity),
        "{:?}",
        learned.unexcited
    );
    assert!(
        learned.residual.features.contains(&Feature::Quadratic),
        "{:?}",
        learned.residual.features
    );
    learned.residual.validate().unwrap();
    assert!(learned.residual.support.speed_max > 4.0);
}

/// The same from poses at 16.7 Hz with 2 cm of noise (a vision
/// pipeline's): the window averages the noise (√6·σ/δt² is about 120 m/s²
/// in one 50 Hz second difference), and the held-out horizon error is
/// still at most half the parametric model's.
#[test]
fn noisy_slow_poses_are_learned_through_a_wider_window() {
    let runs = vec![flight_sensed(240.0, 0.03, 0.2, 7.0, 3, 0.02)];
    let learned = learn(&runs, &vehicle()).unwrap();
    let v = learned.residual.validation;
    eprintln!(
        "noisy 16.7 Hz: window {}, basis {:?}; {v:?}; weights {:?}",
        learned.residual.window, learned.residual.features, learned.residual.weights
    );
    assert!(v.horizon_learned_m <= 0.5 * v.horizon_parametric_m, "{v:?}");
    assert!(learned.residual.window > 3);
}

/// Each model's held-out prediction starts from its own window of poses,
/// chosen on the validation blocks: under 2 cm of noise at 50 Hz the
/// learned model, which explains the flight, affords a longer window
/// (averaging the noise) than the parametric model, whose unexplained
/// drag bends a long one. The chosen window scores best on the validation
/// blocks, and the reported test errors are those at the chosen windows.
#[test]
fn each_model_predicts_from_its_own_window_of_poses() {
    let runs = vec![flight_sensed(240.0, 0.03, 0.2, 7.0, 1, 0.02)];
    let vehicle = vehicle();
    let learned = learn(&runs, &vehicle).unwrap();
    let v = learned.residual.validation;
    eprintln!("noisy 50 Hz: {v:?}");
    assert!(
        v.start_learned_s > v.start_parametric_s,
        "learned {} s, parametric {} s",
        v.start_learned_s,
        v.start_parametric_s
    );
    let model = &vehicle.parametric;
    let prepared: Vec<Prepared> = runs.iter().map(|r| Prepared::new(r, model)).collect();
    let residual = Some(&learned.residual);
    for (chosen, res) in [(v.start_parametric_s, None), (v.start_learned_s, residual)] {
        let at = |s: f64, part: Part| {
            fit::rollouts(&prepared, model, res, part, HORIZON_S, STRIDE, s).horizon_rms()
        };
        let best = at(chosen, Part::Validate);
        for s in fit::START_WINDOWS_S {
            assert!(best <= at(s, Part::Validate), "{chosen} s against {s} s");
        }
        let test = at(chosen, Part::Test);
        let reported = if res.is_some() {
            v.horizon_learned_m
        } else {
            v.horizon_parametric_m
        };
        assert!(
            (test - reported).abs() <= 1e-12 * reported,
            "{test} vs {reported}"
        );
    }
    // From the fixed 0.4 s of poses the two shared before, the learned
    // model's error was a larger share of the parametric one's.
    let fixed = |res| {
        fit::rollouts(&prepared, model, res, Part::Test, HORIZON_S, STRIDE, 0.4).horizon_rms()
    };
    let shared = fixed(residual) / fixed(None);
    let own = v.horizon_learned_m / v.horizon_parametric_m;
    assert!(
        own < shared,
        "own windows {own:.3}, shared 0.4 s {shared:.3}"
    );
}

/// Where the poses carry their true positions (a simulator's records),
/// the held-out horizon error is also judged against them: without the
/// poses' noise at the horizon, which no model predicts, both errors fall
/// (the learned one by more: it is the nearer to that floor), the
/// noise-judged one is the truth-judged one with ~the noise added in
/// quadrature, and a flight's records (no truth) give `None`.
#[test]
fn the_held_out_error_is_also_judged_against_the_true_positions() {
    let sigma = 0.02;
    let runs = vec![flight_sensed(240.0, 0.03, 0.2, 7.0, 1, sigma)];
    let learned = learn(&runs, &vehicle()).unwrap();
    let v = learned.residual.validation;
    let [truth_p, truth_l] = learned.horizon_truth_m.expect("the poses carry truth");
    eprintln!(
        "noisy 50 Hz: against poses {:.4} → {:.4} m, against truth {truth_p:.4} → {truth_l:.4} m",
        v.horizon_parametric_m, v.horizon_learned_m
    );
    assert!(truth_p < v.horizon_parametric_m && truth_l < v.horizon_learned_m);
    assert!(truth_l / truth_p < v.horizon_learned_m / v.horizon_parametric_m);
    // The pose's noise at the horizon on three axes, in quadrature.
    let floor = 3f64.sqrt() * sigma;
    for (poses, truth) in [
        (v.horizon_parametric_m, truth_p),
        (v.horizon_learned_m, truth_l),
    ] {
        let expected = (truth * truth + floor * floor).sqrt();
        assert!(
            (poses - expected).abs() < 0.2 * expected,
            "against poses {poses:.4} m, truth with the noise {expected:.4} m"
        );
    }
    let mut untruthed = runs;
    for p in &mut untruthed[0].poses {
        p.truth = None;
    }
    assert_eq!(learn(&untruthed, &vehicle()).unwrap().horizon_truth_m, None);
}

/// Without aerodynamics the parametric model is the truth up to its Euler
/// discretisation: whatever is learned does not make the held-out
/// prediction worse (or nothing is learned, said so).
#[test]
fn a_matched_model_is_not_made_worse() {
    let runs = vec![flight(120.0, 0.0, 0.0, 5.0)];
    match learn(&runs, &vehicle()) {
        Err(
            LearnError::NoImprovement { .. }
            | LearnError::EveryAxisParametric { .. }
            | LearnError::NothingDetermined { .. },
        ) => {}
        Ok(l) => {
            let v = l.residual.validation;
            assert!(v.horizon_learned_m <= v.horizon_parametric_m, "{v:?}");
            assert!(v.horizon_parametric_m < 0.01, "{v:?}");
        }
        Err(e) => panic!("{e}"),
    }
}

/// A hover at a steady speed (0) does not excite the velocity terms: they
/// are not offered, nothing else is (no constant: module docs), and the
/// refusal says why.
#[test]
fn a_hover_does_not_learn_velocity_terms() {
    let runs = vec![flight(60.0, 0.03, 0.2, 0.0)];
    match learn(&runs, &vehicle()) {
        Err(e @ LearnError::NothingDetermined { .. }) => {
            let words = e.to_string();
            assert!(words.contains("speed std"), "{words}");
        }
        other => panic!("expected nothing determined, got {other:?}"),
    }
}

/// A steady wind's force (0.4 m/s² on x) is not learned as a constant:
/// the residual learned beside it is the aerodynamics' (the shared
/// horizontal weights within 20 % of the plant's), and the constant is
/// left to the disturbance estimator in flight.
#[test]
fn a_steady_force_is_not_learned_as_a_constant() {
    let runs = vec![flight_biased(
        240.0,
        (0.03, 0.2, 7.0),
        1,
        0.0,
        Vector3::new(0.4, 0.0, 0.0),
    )];
    let l = learn(&runs, &vehicle()).unwrap();
    eprintln!(
        "basis {:?}, weights {:?}, parametric axes {:?}",
        l.residual.features, l.residual.weights, l.parametric_axes
    );
    assert!(!l.residual.features.contains(&Feature::Bias));
    let at = |f: Feature, axis: usize| {
        let mut col = 0;
        for g in &l.residual.features {
            if *g == f {
                return l.residual.weights[axis][col + axis];
            }
            col += g.columns();
        }
        0.0
    };
    for axis in 0..2 {
        let q = at(Feature::Quadratic, axis);
        assert!((q + 0.03).abs() < 0.2 * 0.03, "axis {axis}: quadratic {q}");
    }
    assert_eq!(at(Feature::Quadratic, 0), at(Feature::Quadratic, 1));
}

/// Noisy poses (2 cm, 50 Hz) of a flight at 5 m/s whose thrust holds the
/// altitude, with parasitic drag alone (rotor drag would reach z through
/// the tilt: `(v − n·(n·v))_z`): the horizontal weights are determined and
/// learned, the vertical ones (the vertical speed barely moves) are not,
/// and z keeps the parametric model (weights 0, said). Fails when an
/// undetermined axis's weights are learned anyway (the rule removed), or
/// the horizontal axes are dropped too.
#[test]
fn an_axis_the_records_do_not_determine_keeps_the_parametric_model() {
    let runs = vec![flight_with(
        120.0,
        (0.03, 0.0, 5.0),
        1,
        0.02,
        Vector3::zeros(),
        0.0,
    )];
    let l = learn(&runs, &vehicle()).unwrap();
    eprintln!(
        "basis {:?}, weights {:?}, parametric axes {:?}",
        l.residual.features, l.residual.weights, l.parametric_axes
    );
    let kept: Vec<usize> = l.parametric_axes.iter().map(|(a, _)| *a).collect();
    assert!(
        !kept.contains(&0) && !kept.contains(&1),
        "{:?}",
        l.parametric_axes
    );
    assert!(kept.contains(&2), "{:?}", l.parametric_axes);
    for (axis, _) in &l.parametric_axes {
        assert!(l.residual.weights[*axis].iter().all(|w| *w == 0.0));
    }
}

#[test]
fn too_short_is_refused_in_words() {
    let err = learn(&[flight(5.0, 0.0, 0.0, 1.0)], &vehicle()).unwrap_err();
    assert!(err.to_string().contains("fly longer"), "{err}");
}

/// Enough seconds in all, but in runs too short for a test block (the
/// fifth 4 s block of a run, from 16 s): refused in words, not a model
/// whose held-out errors are NaN (the lab's seconds study at 40 s wrote
/// one, and flew it).
#[test]
fn runs_without_a_held_out_block_are_refused() {
    let runs: Vec<Run> = (0..4)
        .map(|i| flight(15.0, 0.03, 0.2, 4.0 + i as f64))
        .collect();
    let err = learn(&runs, &vehicle()).unwrap_err();
    assert!(
        matches!(err, LearnError::NoHeldOut { part: "test", .. }),
        "{err}"
    );
    assert!(err.to_string().contains("fly longer runs"), "{err}");
    // The same seconds in runs long enough are learned.
    let long = flight(60.0, 0.03, 0.2, 5.0);
    assert!(learn(&[long], &vehicle()).is_ok());
}

/// Ten minutes of flight learned: the time it takes, printed (no timing
/// assertion). `cargo test -p dflat-tuning --lib --release
/// learn::tests::ten_minutes -- --ignored --nocapture`
#[test]
#[ignore = "a measurement: prints how long learning ten minutes takes"]
fn ten_minutes() {
    let runs = vec![flight(600.0, 0.03, 0.2, 7.0)];
    let started = std::time::Instant::now();
    let learned = learn(&runs, &vehicle()).unwrap();
    eprintln!(
        "learned from {:.0} s of flight in {:.2} s ({} candidates): {:?}",
        learned.residual.seconds,
        started.elapsed().as_secs_f64(),
        learned.candidates,
        learned.residual.validation
    );
}

/// A slow, short, noisy flight (30 s at about 2 m/s, 1 cm poses): the
/// candidate with the lowest held-out error on its full weights cannot
/// keep z (its interval) and, flown without z, leaves more of the
/// held-out acceleration than one that keeps every axis. Candidates are
/// judged as they fly, so the second is chosen. Fails when the choice is
/// made on full weights and the undetermined axis dropped afterwards (z
/// left parametric: seen on this flight).
#[test]
fn candidates_are_judged_with_the_axes_they_keep() {
    let runs = vec![flight_sensed(30.0, 0.03, 0.2, 2.0, 1, 0.01)];
    let l = learn(&runs, &vehicle()).unwrap();
    eprintln!(
        "window {}, basis {:?}, λ {:e}, parametric axes {:?}",
        l.residual.window, l.residual.features, l.residual.lambda, l.parametric_axes
    );
    assert!(l.parametric_axes.is_empty(), "{:?}", l.parametric_axes);
    let v = l.residual.validation;
    assert!(v.acceleration_learned < v.acceleration_parametric, "{v:?}");
}
