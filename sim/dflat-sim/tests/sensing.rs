//! Sensor tests: vision rate, latency, extrapolation, dropouts (binomial
//! bounds), noise statistics, determinism.

use dflat_sim::plant::PlantState;
use dflat_sim::sensing::{
    GaussianOptions, GaussianSensor, PoseSample, Sensor, SensorSpec, VisionMode, VisionOptions,
    VisionSensor, build_sensor,
};
use nalgebra::Vector3;

const PLANT_DT: f64 = 0.005;
const TICK: usize = 4; // plant steps per 50 Hz tick

/// A vehicle moving at constant velocity `v` from `p0` (NED).
fn truth(p0: Vector3<f64>, v: Vector3<f64>, t: f64) -> PlantState {
    PlantState {
        position: p0 + v * t,
        velocity: v,
        ..PlantState::default()
    }
}

/// Drives `sensor` over `seconds` like the harness does; returns the tick
/// times, measurements and all delivered samples.
fn drive(
    sensor: &mut dyn Sensor,
    v: Vector3<f64>,
    seconds: f64,
) -> (
    Vec<(f64, Option<dflat_control::Measurement>)>,
    Vec<PoseSample>,
) {
    let p0 = Vector3::new(1.0, 2.0, -3.0);
    sensor.reset(0.0, &truth(p0, v, 0.0));
    let ticks = (seconds / (PLANT_DT * TICK as f64)).round() as usize;
    let mut out = Vec::new();
    let mut samples = Vec::new();
    for k in 0..ticks {
        let t = (k * TICK) as f64 * PLANT_DT;
        let m = sensor.measure(t);
        samples.extend_from_slice(sensor.new_samples());
        out.push((t, m));
        for i in 1..=TICK {
            let ti = (k * TICK + i) as f64 * PLANT_DT;
            sensor.observe(ti, &truth(p0, v, ti));
        }
    }
    (out, samples)
}

fn exact_vision(mode: VisionMode) -> VisionOptions {
    VisionOptions {
        sigma: 0.0,
        timing_jitter: 0.0,
        mode,
        ..VisionOptions::default()
    }
}

#[test]
fn vision_sample_rate_over_60_s_matches_the_configuration() {
    for (rate, jitter) in [(15.0, 0.005), (15.0, 0.0), (10.0, 0.02), (30.0, 0.001)] {
        let o = VisionOptions {
            rate_hz: rate,
            timing_jitter: jitter,
            ..VisionOptions::default()
        };
        let mut s = VisionSensor::new(o, 11).expect("valid");
        let (_, samples) = drive(&mut s, Vector3::new(1.0, 0.0, 0.0), 60.0);
        // Samples captured in [0, 60 s − latency) plus the two primed ones.
        let in_window = samples.iter().filter(|s| s.t_measured >= 0.0).count() as f64;
        let expect = (60.0 - 0.06) * rate;
        assert!(
            (in_window - expect).abs() <= 2.0,
            "rate {rate}: {in_window} vs {expect}"
        );
        // Intervals stay within the jitter band.
        for w in samples.windows(2) {
            let dt = w[1].t_measured - w[0].t_measured;
            assert!(
                (dt - 1.0 / rate).abs() <= 2.0 * jitter + 1e-9,
                "interval {dt}"
            );
        }
    }
}

#[test]
fn vision_latency_is_applied_exactly() {
    let v = Vector3::new(3.0, -1.0, 0.5);
    let p0 = Vector3::new(1.0, 2.0, -3.0);
    let mut s = VisionSensor::new(exact_vision(VisionMode::Hold), 1).expect("valid");
    let (ticks, samples) = drive(&mut s, v, 10.0);
    assert!(samples.len() > 140);
    for smp in &samples {
        assert!(
            (smp.t_arrival - smp.t_measured - 0.06).abs() < 1e-12,
            "{smp:?}"
        );
        // The pose is the truth at the capture time.
        assert!(
            (smp.position - (p0 + v * smp.t_measured)).norm() < 1e-12,
            "{smp:?}"
        );
    }
    // Hold: the tick's measurement is the newest sample that has arrived.
    for (t, m) in &ticks {
        let m = m.expect("primed at reset");
        let newest = samples
            .iter()
            .rfind(|s| s.t_arrival <= t + 1e-9)
            .expect("some sample");
        assert_eq!(m.position, newest.position, "t = {t}");
        assert_eq!(m.t, *t, "hold stamps the tick time");
        // Its age is between the latency and latency + one period.
        let age = t - newest.t_measured;
        assert!(
            (0.06 - 1e-9..=0.06 + 1.0 / 15.0 + 1e-9).contains(&age),
            "age {age}"
        );
    }
}

#[test]
fn vision_raw_mode_stamps_the_capture_time() {
    let mut s = VisionSensor::new(exact_vision(VisionMode::Raw), 1).expect("valid");
    let v = Vector3::new(3.0, 0.0, 0.0);
    let (ticks, samples) = drive(&mut s, v, 2.0);
    for (t, m) in &ticks {
        let m = m.expect("primed");
        assert!(m.t <= t - 0.06 + 1e-9);
        assert!(
            samples
                .iter()
                .any(|s| s.t_measured == m.t && s.position == m.position)
        );
    }
    // Arrivals are in capture order.
    assert!(
        samples
            .windows(2)
            .all(|w| w[0].t_measured < w[1].t_measured)
    );
}

#[test]
fn vision_extrapolation_is_exact_at_constant_velocity() {
    let v = Vector3::new(9.0, -4.0, 1.0);
    let p0 = Vector3::new(1.0, 2.0, -3.0);
    let o = VisionOptions {
        timing_jitter: 0.01,
        ..exact_vision(VisionMode::Extrapolate)
    };
    let mut s = VisionSensor::new(o, 5).expect("valid");
    let (ticks, _) = drive(&mut s, v, 5.0);
    for (t, m) in ticks {
        let m = m.expect("primed");
        assert!(
            (m.position - (p0 + v * t)).norm() < 1e-9,
            "t = {t}: {}",
            m.position
        );
        assert_eq!(m.t, t);
    }
}

#[test]
fn vision_dropouts_are_binomial() {
    let p = 0.2;
    let o = VisionOptions {
        dropout: p,
        ..VisionOptions::default()
    };
    let mut s = VisionSensor::new(o, 2024).expect("valid");
    let (_, samples) = drive(&mut s, Vector3::zeros(), 600.0);
    let st = s.stats();
    let n = st.captured as f64;
    assert!(n > 8900.0, "{st:?}");
    let sd = (n * p * (1.0 - p)).sqrt();
    assert!((st.dropped as f64 - n * p).abs() < 4.0 * sd, "{st:?}");
    assert_eq!(st.delivered as usize, samples.len());
    assert!(st.captured - st.dropped >= st.delivered);
}

#[test]
fn vision_burst_dropouts_keep_the_share_and_the_burst_length() {
    let (p, len) = (0.2, 5.0);
    let o = VisionOptions {
        dropout: p,
        burst_len: len,
        timing_jitter: 0.0,
        ..VisionOptions::default()
    };
    let mut s = VisionSensor::new(o, 99).expect("valid");
    let (_, samples) = drive(&mut s, Vector3::zeros(), 3000.0);
    let st = s.stats();
    let share = st.dropped as f64 / st.captured as f64;
    assert!((share - p).abs() < 0.03, "share {share}");
    // Burst lengths from the gaps between delivered samples.
    let runs: Vec<f64> = samples
        .windows(2)
        .map(|w| ((w[1].t_measured - w[0].t_measured) * 15.0).round() - 1.0)
        .filter(|r| *r > 0.0)
        .collect();
    let mean = runs.iter().sum::<f64>() / runs.len() as f64;
    assert!(
        (mean - len).abs() < 0.1 * len,
        "mean burst {mean} over {} bursts",
        runs.len()
    );
}

#[test]
fn gaussian_noise_has_the_configured_std() {
    let sigma = [0.01, 0.002, 0.0];
    let o = GaussianOptions {
        sigma,
        yaw_sigma: 0.0,
    };
    let mut s = GaussianSensor::new(o, 8).expect("valid");
    let (ticks, samples) = drive(&mut s, Vector3::zeros(), 400.0);
    assert_eq!(samples.len(), ticks.len(), "one sample per tick");
    let p0 = Vector3::new(1.0, 2.0, -3.0);
    let n = ticks.len() as f64;
    for (axis, sd) in sigma.iter().enumerate() {
        let e: Vec<f64> = ticks
            .iter()
            .map(|(_, m)| m.expect("m").position[axis] - p0[axis])
            .collect();
        let mean = e.iter().sum::<f64>() / n;
        let std = (e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        // 20 000 samples: the std's relative standard error is 0.5 %.
        assert!(
            (std - sd).abs() <= 0.03 * sd + 1e-15,
            "axis {axis}: {std} vs {sd}"
        );
        assert!(
            mean.abs() <= 4.0 * sd / n.sqrt() + 1e-15,
            "axis {axis}: mean {mean}"
        );
    }
    // No delay: the measurement is stamped with the tick time.
    assert!(ticks.iter().all(|(t, m)| m.expect("m").t == *t));
}

#[test]
fn vision_noise_has_the_configured_std() {
    let o = VisionOptions {
        sigma: 0.02,
        rate_hz: 50.0,
        mode: VisionMode::Raw,
        ..VisionOptions::default()
    };
    let mut s = VisionSensor::new(o, 4).expect("valid");
    let (_, samples) = drive(&mut s, Vector3::zeros(), 200.0);
    let p0 = Vector3::new(1.0, 2.0, -3.0);
    let e: Vec<f64> = samples
        .iter()
        .flat_map(|s| (s.position - p0).iter().copied().collect::<Vec<_>>())
        .collect();
    let n = e.len() as f64;
    let std = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
    assert!((std - 0.02).abs() < 0.03 * 0.02, "std {std} over {n}");
}

#[test]
fn same_seed_same_noise_other_seed_other_noise() {
    let spec = SensorSpec::Vision(VisionOptions {
        dropout: 0.1,
        ..VisionOptions::default()
    });
    let run = |seed| {
        let mut s = build_sensor(&spec, seed).expect("valid");
        drive(s.as_mut(), Vector3::new(2.0, 1.0, 0.0), 20.0).1
    };
    assert_eq!(run(1), run(1));
    assert_ne!(run(1), run(2));
    let g = SensorSpec::Gaussian(GaussianOptions::x_only(0.01));
    let run = |seed| {
        let mut s = build_sensor(&g, seed).expect("valid");
        drive(s.as_mut(), Vector3::zeros(), 2.0).1
    };
    assert_eq!(run(3), run(3));
    // x only: y and z are exact.
    assert!(
        run(3)
            .iter()
            .all(|s| s.position.y == 2.0 && s.position.z == -3.0)
    );
}

#[test]
fn invalid_vision_options_are_rejected() {
    let bad = [
        VisionOptions {
            rate_hz: 0.0,
            ..VisionOptions::default()
        },
        VisionOptions {
            dropout: 1.0,
            ..VisionOptions::default()
        },
        VisionOptions {
            timing_jitter: 0.04,
            ..VisionOptions::default()
        },
        VisionOptions {
            dropout: 0.9,
            burst_len: 2.0,
            ..VisionOptions::default()
        },
    ];
    for o in bad {
        assert!(VisionSensor::new(o.clone(), 0).is_err(), "{o:?}");
    }
    let spec: SensorSpec =
        serde_json::from_str(r#"{"kind": "vision", "latency": 0.1}"#).expect("parses");
    match spec {
        SensorSpec::Vision(o) => assert_eq!(o.latency, 0.1),
        other => panic!("{other:?}"),
    }
}
