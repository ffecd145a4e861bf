//! The pose-to-tick phase study, reduced: 5 m/s, offsets
//! 0 and 19 ms, one trial.

use dflat_lab::experiments::phase::{PhaseConfig, run_phase, write_phase};

#[test]
fn reduced_phase_study_shows_what_the_lock_buys() {
    let config = PhaseConfig {
        speeds: vec![5.0],
        offsets_ms: vec![0.0, 19.0],
        trials: 1,
        ..PhaseConfig::default()
    };
    let result = run_phase(&config, false).expect("runs");
    assert_eq!(result.rows.len(), 3 * 2);
    for r in &result.rows {
        assert_eq!(r.trials, 1);
        assert_eq!(r.diverged, 0, "{} {} ms", r.window, r.offset_ms);
        assert_eq!(r.controller_errors, 0, "{} {} ms", r.window, r.offset_ms);
        let e = r.path_error.expect("path error");
        assert!(e.median.is_finite() && e.p95.is_finite());
    }
    let stats = |w: &str, o: f64| result.row(w, o, 5.0).unwrap().path_error.unwrap();
    // Measured (seed 0): classic (extrapolated) p95 0.406 m at 0 ms, 0.639 m
    // at 19 ms; classic-hold median 0.034 → 0.048 m, p95 0.295 → 0.365 m;
    // multi-rate median 0.005 m and p95 0.215 m at both offsets.
    let classic = (stats("classic", 0.0), stats("classic", 19.0));
    let hold = (stats("classic-hold", 0.0), stats("classic-hold", 19.0));
    let mr = (stats("multi-rate", 0.0), stats("multi-rate", 19.0));
    // The classic window pays for the phase: locked ticks (0 ms) are better.
    assert!(
        classic.1.p95 > 1.2 * classic.0.p95,
        "classic p95 {} → {}",
        classic.0.p95,
        classic.1.p95
    );
    assert!(
        hold.1.median > 1.15 * hold.0.median && hold.1.p95 > hold.0.p95,
        "classic-hold {:?} → {:?}",
        hold.0,
        hold.1
    );
    // The multi-rate window predicts across the offset: within 3 %.
    assert!(
        (mr.1.p95 - mr.0.p95).abs() < 0.03 * mr.0.p95
            && (mr.1.median - mr.0.median).abs() < 0.03 * mr.0.median,
        "multi-rate {:?} → {:?}",
        mr.0,
        mr.1
    );
    // And beats the classic window at either phase.
    assert!(mr.1.p95 < classic.0.p95 && mr.1.p95 < hold.0.p95);
    let table = result.table();
    assert!(table.contains("| 5 | 19 | multi-rate |"), "{table}");

    let json = std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("experiments")
        .join("phase.json");
    let files = write_phase(&result, &json).expect("writes");
    assert!(files[0].exists());
}

/// The study's knob: at 50 Hz poses and 50 Hz ticks each sample arrives
/// exactly `arrival_lead` before the tick that first sees it.
#[test]
fn arrival_lead_places_arrivals_before_the_tick() {
    use dflat_sim::plant::PlantState;
    use dflat_sim::sensing::{Sensor, VisionMode, VisionOptions, VisionSensor};
    use nalgebra::Vector3;
    for lead in [0.0, 0.005, 0.019] {
        let options = VisionOptions {
            rate_hz: 50.0,
            latency: 0.02,
            timing_jitter: 0.0,
            arrival_lead: lead,
            mode: VisionMode::Raw,
            ..VisionOptions::default()
        };
        let mut s = VisionSensor::new(options, 1).expect("valid");
        let truth = PlantState::hover(Vector3::new(0.0, 0.0, -10.0), 9.81);
        s.reset(0.0, &truth);
        // The first tick takes the samples primed before t0.
        s.measure(0.0);
        let mut seen = 0;
        for k in 1..=100 {
            for i in 1..=4 {
                s.observe((4 * (k - 1) + i) as f64 * 0.005, &truth);
            }
            let t = k as f64 * 0.02;
            s.measure(t);
            for p in s.new_samples() {
                assert!(
                    (t - p.t_arrival - lead).abs() < 1e-9,
                    "lead {lead}: {p:?} at {t}"
                );
                assert!((p.t_arrival - p.t_measured - 0.02).abs() < 1e-9);
                seen += 1;
            }
        }
        assert_eq!(seen, 100, "one sample per tick at lead {lead}");
    }
    let bad = VisionOptions {
        rate_hz: 50.0,
        arrival_lead: 0.02,
        ..VisionOptions::default()
    };
    assert!(bad.validate().is_err());
}
