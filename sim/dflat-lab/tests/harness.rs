//! Harness tests: closed loops with a test PD, determinism, parallel ==
//! sequential, controller errors, divergence, stop conditions, metrics on
//! hand-made logs, CSV shape.

mod common;

use std::sync::Arc;

use common::{Constant, Flaky, G, TestPd, close, fixed_ref, pd_factory};
use dflat_control::{AttitudeCommand, Measurement};
use dflat_lab::harness::{
    ErrorStats, FixedTarget, PlantSample, StopCondition, StopReason, TICKS_HEADER, TickRecord,
    TickStatus, TrialSpec, command_smoothness, fixed_target_error, max_tilt_deg, path_error_stats,
    polyline_distance, polyline_path_distance, quantile, run_trial, run_trials, saturation_share,
};
use dflat_sim::SimError;
use dflat_sim::plant::{PlantKind, PlantOptions, PlantState};
use dflat_sim::sensing::{GaussianOptions, SensorSpec, VisionOptions};
use nalgebra::Vector3;

fn hover_spec(name: &str) -> TrialSpec {
    let target = Vector3::new(10.0, 0.0, 0.0);
    let mut spec = TrialSpec::new(name, pd_factory(1.0, 1.6), fixed_ref(target));
    spec.target = Some(FixedTarget {
        target,
        axes: [true, false, false],
        after: 5.0,
    });
    spec
}

/// A noisy, gusty, vision-fed trial: every random source in play.
fn busy_spec(kind: PlantKind) -> TrialSpec {
    let target = Vector3::new(5.0, -3.0, -2.0);
    let mut spec = TrialSpec::new(
        format!("busy {kind:?}"),
        pd_factory(1.0, 1.6),
        fixed_ref(target),
    );
    spec.plant = kind;
    spec.plant_options = PlantOptions {
        drag: 0.2,
        wind: [1.0, 0.5, 0.0],
        gust_std: [0.5, 0.5, 0.2],
        ..PlantOptions::default()
    };
    spec.sensor = SensorSpec::Vision(VisionOptions {
        dropout: 0.1,
        burst_len: 2.0,
        ..VisionOptions::default()
    });
    spec.stop = StopCondition::Duration(8.0);
    spec.path_distance = Some(polyline_path_distance(
        vec![Vector3::zeros(), target],
        false,
    ));
    spec
}

#[test]
fn pd_flies_to_a_fixed_target_on_every_plant() {
    for kind in [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody] {
        let mut spec = hover_spec("pd");
        spec.plant = kind;
        spec.stop = StopCondition::Duration(15.0);
        let r = run_trial(&spec, 0).expect("valid spec");
        assert_eq!(r.ticks.len(), 750);
        assert_eq!(r.trace.len(), 3000);
        assert_eq!(r.controller, "pd");
        assert_eq!(r.stop_reason, StopReason::Duration);
        let last = r.ticks.last().expect("ticks").truth.position;
        assert!(
            (last - Vector3::new(10.0, 0.0, 0.0)).norm() < 0.05,
            "{kind:?}: {last}"
        );
        let m = &r.metrics;
        assert!(!m.diverged && m.controller_errors == 0 && m.no_measurement_ticks == 0);
        let mae = m.mae.expect("target set");
        assert!(mae > 1.0 && mae < 5.0, "{kind:?}: mae {mae}");
        assert!(m.mae_after.expect("late window") < mae);
        assert!(
            m.max_tilt_deg > 5.0 && m.max_tilt_deg < 35.0,
            "{}",
            m.max_tilt_deg
        );
        assert!(m.smoothness_deg > 0.0);
        // Ticks are at k·δt and log the truth before the command acts.
        assert_eq!(r.ticks[3].t, 0.06);
        assert_eq!(r.ticks[0].truth.position, Vector3::zeros());
        assert_eq!(r.trace[4].t, 0.02);
    }
}

#[test]
fn same_seed_gives_bit_identical_results() {
    for kind in [PlantKind::Planar, PlantKind::RigidBody] {
        let spec = busy_spec(kind);
        let a = run_trial(&spec, 42).expect("valid");
        let b = run_trial(&spec, 42).expect("valid");
        assert_eq!(a.ticks_csv(), b.ticks_csv());
        assert_eq!(a.trace_csv(), b.trace_csv());
        assert_eq!(a.samples, b.samples);
        assert_eq!(a.metrics, b.metrics);
        let c = run_trial(&spec, 43).expect("valid");
        assert_ne!(a.ticks_csv(), c.ticks_csv(), "another seed differs");
    }
}

#[test]
fn parallel_equals_sequential_whatever_the_thread_count() {
    let trials: Vec<(TrialSpec, u64)> = (0..8)
        .map(|i| {
            let kind = [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody][i % 3];
            let mut spec = busy_spec(kind);
            spec.stop = StopCondition::Duration(3.0);
            (spec, 100 + i as u64)
        })
        .collect();
    let sequential: Vec<String> = trials
        .iter()
        .map(|(s, seed)| run_trial(s, *seed).expect("valid").ticks_csv())
        .collect();
    for threads in [1, 3, 8] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let parallel = pool.install(|| run_trials(&trials, false));
        let csv: Vec<String> = parallel
            .into_iter()
            .map(|r| r.expect("valid").ticks_csv())
            .collect();
        assert_eq!(csv, sequential, "{threads} threads");
    }
}

#[test]
fn controller_errors_are_counted_and_the_command_held() {
    let target = Vector3::new(3.0, 0.0, 0.0);
    let mut spec = TrialSpec::new(
        "flaky",
        Arc::new(|| {
            Box::new(Flaky {
                inner: TestPd::new(1.0, 1.6),
                every: 5,
                count: 0,
            })
        }),
        fixed_ref(target),
    );
    spec.stop = StopCondition::Duration(2.0);
    let r = run_trial(&spec, 0).expect("valid");
    assert_eq!(r.metrics.controller_errors, 20);
    assert_eq!(r.errors.len(), 20);
    assert_eq!(r.errors[0].0, 4);
    for w in r.ticks.windows(2) {
        if w[1].status == TickStatus::ControllerError {
            assert_eq!(w[1].command, w[0].command, "held at tick {}", w[1].k);
            assert_eq!(w[1].reference, w[0].reference);
        }
    }
    assert!(r.ticks_csv().contains(",error,"));
}

#[test]
fn divergence_is_flagged_and_stops_the_trial() {
    let tilt = AttitudeCommand {
        pitch: -1.0,
        roll: 0.0,
        yaw: 0.0,
        thrust: G,
    };
    let mut spec = TrialSpec::new(
        "runaway",
        Arc::new(move || Box::new(Constant(tilt))),
        fixed_ref(Vector3::zeros()),
    );
    spec.target = Some(FixedTarget {
        target: Vector3::zeros(),
        axes: [true; 3],
        after: 0.0,
    });
    spec.divergence_bound = 20.0;
    spec.stop = StopCondition::Duration(30.0);
    let r = run_trial(&spec, 0).expect("valid");
    assert!(r.metrics.diverged);
    assert_eq!(r.stop_reason, StopReason::Diverged);
    let t = r.metrics.diverged_at.expect("time");
    // The command saturates at 35°; with the τ = 0.2 s attitude lag
    // x ≈ a·(t²/2 − τ·t + τ²), a = g·tan 35°, passes 20 m at ≈ 2.61 s.
    let a = G * 35f64.to_radians().tan();
    let expect = 0.2 + (0.04 - 0.08 + 40.0 / a).sqrt();
    assert!((t - expect).abs() < 0.05, "{t} vs {expect}");
    assert!(r.ticks.iter().all(|k| k.plant_saturated));
    close(r.metrics.saturation_share, 1.0, 0.0, "all ticks saturated");
    // Without stopping, the trial runs its course and stays flagged.
    spec.stop_on_divergence = false;
    spec.stop = StopCondition::Duration(4.0);
    let r = run_trial(&spec, 0).expect("valid");
    assert_eq!(r.ticks.len(), 200);
    assert!(r.metrics.diverged);
}

#[test]
fn path_end_stops_after_the_settle_time() {
    let end = Vector3::new(4.0, 3.0, 0.0);
    let mut spec = TrialSpec::new("to end", pd_factory(1.0, 1.6), fixed_ref(end));
    spec.stop = StopCondition::PathEnd {
        end,
        radius: 0.5,
        settle: 2.0,
        max_duration: 60.0,
    };
    spec.path_distance = Some(polyline_path_distance(vec![Vector3::zeros(), end], true));
    let r = run_trial(&spec, 0).expect("valid");
    assert_eq!(r.stop_reason, StopReason::PathEnd);
    let arrived = r
        .ticks
        .iter()
        .find(|k| (k.truth.position - end).norm() <= 0.5)
        .expect("arrives")
        .t;
    close(r.metrics.duration, arrived + 2.0, 0.021, "duration");
    let stats = r.metrics.path_error.expect("path distance set");
    assert!(
        stats.max < 0.5 && stats.median <= stats.p95 && stats.p95 <= stats.max,
        "{stats:?}"
    );
    // Unreachable end: stops at max_duration.
    spec.stop = StopCondition::PathEnd {
        end: end * 100.0,
        radius: 0.5,
        settle: 2.0,
        max_duration: 3.0,
    };
    spec.divergence_bound = 1e6;
    let r = run_trial(&spec, 0).expect("valid");
    assert_eq!(r.stop_reason, StopReason::MaxDuration);
    assert_eq!(r.ticks.len(), 150);
}

#[test]
fn delayed_vision_holds_nothing_back_and_logs_samples() {
    let mut spec = hover_spec("vision");
    spec.sensor = SensorSpec::Vision(VisionOptions::default());
    spec.stop = StopCondition::Duration(5.0);
    let r = run_trial(&spec, 1).expect("valid");
    assert_eq!(
        r.metrics.no_measurement_ticks, 0,
        "the sensor is primed at reset"
    );
    let delivered: usize = r.ticks.iter().map(|k| k.new_samples).sum();
    assert_eq!(delivered, r.samples.len());
    assert!(
        (r.samples.len() as f64 - 5.0 * 15.0).abs() < 4.0,
        "{}",
        r.samples.len()
    );
    // Noisy measurements, true positions logged separately.
    let m: Measurement = r.ticks[100].measurement.expect("measured");
    assert_ne!(m.position, r.ticks[100].truth.position);
}

#[test]
fn invalid_specs_are_errors_not_panics() {
    let mut spec = hover_spec("bad");
    spec.ctrl_dt = 0.017;
    assert!(matches!(
        run_trial(&spec, 0),
        Err(SimError::InvalidOption {
            field: "ctrl_dt",
            ..
        })
    ));
    let mut spec = hover_spec("bad");
    spec.sensor = SensorSpec::Gaussian(GaussianOptions {
        sigma: [-1.0, 0.0, 0.0],
        yaw_sigma: 0.0,
    });
    assert!(run_trial(&spec, 0).is_err());
    let mut spec = hover_spec("bad");
    spec.initial = PlantState {
        pitch: f64::NAN,
        ..PlantState::default()
    };
    assert!(run_trial(&spec, 0).is_err());
    let results = run_trials(&[(spec, 0), (hover_spec("ok"), 0)], false);
    assert!(results[0].is_err() && results[1].is_ok());
}

#[test]
fn csv_rows_match_the_header() {
    let mut spec = busy_spec(PlantKind::Spatial);
    spec.stop = StopCondition::Duration(1.0);
    let r = run_trial(&spec, 5).expect("valid");
    let csv = r.ticks_csv();
    let mut lines = csv.lines();
    let header = lines.next().expect("header");
    assert_eq!(header, TICKS_HEADER);
    let cols = header.split(',').count();
    assert_eq!(cols, 45);
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 50);
    assert!(rows.iter().all(|l| l.split(',').count() == cols));
    // Floats round-trip exactly.
    let x: f64 = rows[10]
        .split(',')
        .nth(2)
        .expect("x")
        .parse()
        .expect("float");
    assert_eq!(x, r.ticks[10].truth.position.x);
    assert_eq!(r.trace_csv().lines().count(), 1 + 200);
    let json: serde_json::Value = serde_json::from_str(&r.metrics_json()).expect("json");
    assert!(json["path_error"]["p95"].is_number());
    assert!(json["mae"].is_null());
}

// ---- metric functions on hand-made logs -------------------------------

fn record(k: usize, pitch: f64, roll: f64, path_error: f64, sat: bool) -> TickRecord {
    TickRecord {
        k,
        t: k as f64 * 0.02,
        truth: PlantState::default(),
        measurement: None,
        new_samples: 0,
        reference: Vector3::zeros(),
        plan: [Vector3::zeros(); 4],
        command: AttitudeCommand {
            pitch,
            roll,
            yaw: 0.0,
            thrust: G,
        },
        applied: AttitudeCommand {
            pitch,
            roll,
            yaw: 0.0,
            thrust: G,
        },
        ctrl_saturated: sat,
        plant_saturated: false,
        constrained: false,
        status: TickStatus::Ok,
        path_error,
    }
}

fn sample(t: f64, x: f64, pitch: f64, roll: f64) -> PlantSample {
    PlantSample {
        t,
        position: Vector3::new(x, 7.0, -1.0),
        velocity: Vector3::zeros(),
        roll,
        pitch,
    }
}

#[test]
fn quantiles_and_error_stats() {
    let v = [1.0, 2.0, 3.0, 4.0, 5.0];
    close(quantile(&v, 0.5), 3.0, 0.0, "median");
    close(quantile(&v, 0.95), 4.8, 1e-12, "p95");
    close(quantile(&v, 0.25), 2.0, 0.0, "q1");
    close(quantile(&[2.0], 0.95), 2.0, 0.0, "single");
    assert!(quantile(&[], 0.5).is_nan());
    let s = ErrorStats::from_values([5.0, 1.0, f64::NAN, 3.0, 2.0, 4.0]).expect("values");
    assert_eq!(s.count, 5);
    close(s.mean, 3.0, 0.0, "mean");
    close(s.median, 3.0, 0.0, "median");
    close(s.max, 5.0, 0.0, "max");
    assert!(ErrorStats::from_values([f64::NAN]).is_none());
    let ticks: Vec<TickRecord> = (0..5)
        .map(|k| record(k, 0.0, 0.0, v[4 - k], false))
        .collect();
    assert_eq!(
        path_error_stats(&ticks),
        Some(ErrorStats::from_values(v).expect("v"))
    );
}

#[test]
fn fixed_target_errors_on_a_hand_made_trace() {
    // x = 8, 9, 10, 11 at t = 0, 1, 2, 3 against x_ref = 10 (x only).
    let trace: Vec<PlantSample> = (0..4)
        .map(|i| sample(i as f64, 8.0 + i as f64, 0.0, 0.0))
        .collect();
    let target = FixedTarget {
        target: Vector3::new(10.0, 0.0, 0.0),
        axes: [true, false, false],
        after: 2.0,
    };
    let (mae, rms, after) = fixed_target_error(&trace, &target);
    close(
        mae.expect("mae"),
        (2.0 + 1.0 + 0.0 + 1.0) / 4.0,
        1e-15,
        "mae",
    );
    close(rms.expect("rms"), (6.0f64 / 4.0).sqrt(), 1e-15, "rms");
    close(after.expect("after"), 0.5, 1e-15, "mae_after");
    let (mae, _, after) = fixed_target_error(
        &trace,
        &FixedTarget {
            after: 10.0,
            ..target
        },
    );
    assert!(mae.is_some() && after.is_none());
    assert_eq!(fixed_target_error(&[], &target), (None, None, None));
}

#[test]
fn smoothness_saturation_and_tilt_on_hand_made_logs() {
    let d = 1f64.to_radians();
    // Δ(pitch, roll) per tick: (3°, 4°) → 5 (euclid) / 4 (axis max); then (0, 0); then (−1°, 0).
    let ticks = vec![
        record(0, 0.0, 0.0, 0.0, false),
        record(1, 3.0 * d, 4.0 * d, 0.0, true),
        record(2, 3.0 * d, 4.0 * d, 0.0, false),
        record(3, 2.0 * d, 4.0 * d, 0.0, true),
    ];
    let (euclid, axis) = command_smoothness(&ticks);
    close(euclid, (5.0 + 0.0 + 1.0) / 3.0, 1e-12, "euclidean");
    close(axis, (4.0 + 0.0 + 1.0) / 3.0, 1e-12, "axis max");
    assert_eq!(command_smoothness(&ticks[..1]), (0.0, 0.0));
    close(saturation_share(&ticks), 0.5, 0.0, "share");
    assert_eq!(saturation_share(&[]), 0.0);
    // Tilt = acos(cosθ·cosφ).
    let trace = vec![
        sample(0.0, 0.0, 0.1, 0.0),
        sample(0.1, 0.0, -0.3, 0.4),
        sample(0.2, 0.0, 0.0, 0.2),
    ];
    let expect = ((-0.3f64).cos() * 0.4f64.cos()).acos().to_degrees();
    close(max_tilt_deg(&trace), expect, 1e-12, "max tilt");
}

#[test]
fn polyline_distance_cases() {
    let l = [
        Vector3::new(-20.0, -30.0, 0.0),
        Vector3::new(-20.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 0.0),
    ];
    close(
        polyline_distance(&l, &Vector3::new(-21.0, -10.0, 0.0), true),
        1.0,
        1e-12,
        "first leg",
    );
    close(
        polyline_distance(&l, &Vector3::new(-10.0, 2.0, 5.0), true),
        2.0,
        1e-12,
        "second leg, z ignored",
    );
    close(
        polyline_distance(&l, &Vector3::new(-10.0, 2.0, 5.0), false),
        29f64.sqrt(),
        1e-12,
        "3-D",
    );
    close(
        polyline_distance(&l, &Vector3::new(-19.0, 1.0, 0.0), true),
        1.0,
        1e-12,
        "corner",
    );
    close(
        polyline_distance(&l, &Vector3::new(3.0, 4.0, 0.0), true),
        5.0,
        1e-12,
        "past the end",
    );
    close(
        polyline_distance(&l[..1], &Vector3::new(-20.0, -27.0, 4.0), false),
        5.0,
        1e-12,
        "point",
    );
    assert!(polyline_distance(&[], &Vector3::zeros(), true).is_nan());
}
