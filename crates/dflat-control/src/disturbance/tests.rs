//! Tests of the disturbance estimator.

use super::*;
use dflat_model::{PlanarModel, PlanarParams};

fn planar() -> ControlModel {
    ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap())
}

#[test]
fn fit_weights_are_blind_to_position_and_velocity() {
    let dt = 0.02;
    let h = fit_weights(50, dt).unwrap();
    let s0: f64 = h.iter().sum();
    let s1: f64 = h.iter().enumerate().map(|(j, h)| h * j as f64).sum();
    let s2: f64 = h
        .iter()
        .enumerate()
        .map(|(j, h)| h * dt * dt * (j * j.saturating_sub(1)) as f64 / 2.0)
        .sum();
    assert!(s0.abs() < 1e-9 && s1.abs() < 1e-7, "{s0} {s1}");
    assert!((s2 - 1.0).abs() < 1e-9, "{s2}");
}

#[test]
fn noise_gain_matches_monte_carlo() {
    // Feed pure noise through the fit and the low-pass; compare the
    // sample std of d̂ with the formula.
    let est = DisturbanceEstimator::new(planar(), DisturbanceSettings::default()).unwrap();
    let (h, alpha) = (&est.weights, est.alpha);
    let l = h.len();
    // xorshift + Box–Muller: deterministic, no dependency.
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let n = 200_000;
    let mut noise = Vec::with_capacity(n);
    while noise.len() < n {
        let (u1, u2) = (uniform().max(1e-300), uniform());
        noise.push((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos());
    }
    let (mut d, mut sum2, mut count) = (0.0, 0.0, 0usize);
    for k in l..n {
        let delta: f64 = h.iter().zip(&noise[k - l..k]).map(|(h, y)| h * y).sum();
        d += alpha * (delta - d);
        if k > l + 2000 {
            sum2 += d * d;
            count += 1;
        }
    }
    let sample = (sum2 / count as f64).sqrt();
    let g = est.noise_gain();
    assert!((sample / g - 1.0).abs() < 0.1, "sample {sample} vs {g}");
    // The documented numbers for the defaults.
    assert!(
        (est.fit_noise_gain() - 3.8).abs() < 0.2,
        "{}",
        est.fit_noise_gain()
    );
    assert!((g - 0.364).abs() < 0.001, "{g}");
}

#[test]
fn settings_are_validated() {
    let d = DisturbanceSettings::default();
    assert!(d.validate().is_ok());
    let field = |s: DisturbanceSettings| match DisturbanceEstimator::new(planar(), s) {
        Err(ControlError::InvalidSetting { field, .. }) => field,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        field(DisturbanceSettings {
            bandwidth_hz: 0.0,
            ..d
        }),
        "disturbance.bandwidth_hz"
    );
    assert_eq!(
        field(DisturbanceSettings {
            bandwidth_hz: 30.0,
            ..d
        }),
        "disturbance.bandwidth_hz"
    );
    assert_eq!(
        field(DisturbanceSettings { fit_span: 3, ..d }),
        "disturbance.fit_span"
    );
    assert_eq!(
        field(DisturbanceSettings {
            max_acceleration: f64::NAN,
            ..d
        }),
        "disturbance.max_acceleration"
    );
    assert_eq!(
        field(DisturbanceSettings {
            thrust_scale_range: [1.2, 2.0],
            ..d
        }),
        "disturbance.thrust_scale_range"
    );
    assert_eq!(
        field(DisturbanceSettings { max_step: 0.0, ..d }),
        "disturbance.max_step"
    );
}

/// Multi-rate mode: ticks whose times jitter within half a step of the
/// grid (late poses' deadline ticks under load) keep the fit window, so a
/// constant offset is still learned; under the old rule (a restart beyond
/// a quarter step) a tick every fifth 6 ms late kept the window from ever
/// filling. A missed tick (two steps) still restarts it.
#[test]
fn jittered_ticks_keep_the_window() {
    let d = 0.5;
    let est = |jitter: f64| {
        let mut e = DisturbanceEstimator::new(planar(), DisturbanceSettings::default()).unwrap();
        let dt = 0.02;
        // Level attitude, zero inputs: the plant's only acceleration is d on x.
        for k in 0..2000 {
            let late = if k % 5 == 2 { jitter } else { 0.0 };
            let t = k as f64 * dt + late;
            e.observe(t, &Vector3::new(0.5 * d * t * t, 0.0, 0.0));
            e.begin_tick();
            e.record_input(t, &Vector3::zeros(), false);
        }
        e
    };
    let e = est(0.006);
    assert_eq!(e.status(), EstimatorStatus::Tracking);
    let got = e.estimate().acceleration.x;
    assert!((got - d).abs() < 0.02 * d, "d̂ {got} against {d}");
    // A missed tick restarts the window: not tracking right after it.
    let mut e = est(0.0);
    e.observe(40.04, &Vector3::new(0.5 * d * 40.04f64.powi(2), 0.0, 0.0));
    e.begin_tick();
    e.record_input(40.04, &Vector3::zeros(), false);
    assert_ne!(e.status(), EstimatorStatus::Tracking);
}
