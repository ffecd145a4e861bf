//! The noise-sweep study (paper §VI): a reduced run has the expected JSON
//! shape, both MPCs reach the target without noise (and agree with the
//! independent reference trace), and a seed gives identical JSON.

use std::path::PathBuf;

use dflat_lab::experiments::noise_sweep::{
    NoiseSweepConfig, NoiseSweepResult, run_noise_sweep, write_noise_sweep,
};
use dflat_lab::experiments::{ControllerSpec, OutputPaths};

fn out_dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("experiments")
        .join(name)
}

/// Two σ (0 and 2 mm), two trials, 6 s.
fn reduced() -> NoiseSweepConfig {
    NoiseSweepConfig {
        sigmas: vec![0.0, 2e-3],
        trials: 2,
        duration: 6.0,
        ..NoiseSweepConfig::default()
    }
}

fn json(r: &NoiseSweepResult) -> String {
    serde_json::to_string(r).expect("serialisable")
}

#[test]
fn reduced_sweep_writes_json_and_plots_of_the_expected_shape() {
    let config = reduced();
    let result = run_noise_sweep(&config, false).expect("runs");
    // The paper's claim (§VI, Fig. "simcom_noise"): Flatness MPC, whose
    // flat state is finite differences of the measured positions, degrades
    // with position noise; DF-MPC, which never differences them, barely.
    let after = |name: &str, i: usize| result.row(name, i).expect("row").mean_error_after;
    let smooth = |name: &str, i: usize| result.row(name, i).expect("row").smoothness_deg;
    let (f0, f1) = (after("fmpc", 0), after("fmpc", 1));
    let (d0, d1) = (after("df-mpc", 0), after("df-mpc", 1));
    println!(
        "mean error after settling, σ = 0 → 2 mm: fmpc {f0:.4} → {f1:.4} m, df-mpc {d0:.4} → {d1:.4} m; \
         smoothness fmpc {:.1} → {:.1}°, df-mpc {:.1} → {:.1}°",
        smooth("fmpc", 0),
        smooth("fmpc", 1),
        smooth("df-mpc", 0),
        smooth("df-mpc", 1)
    );
    // Full study (docs/figures/noise_sweep.json, 10 s): fmpc 0.080 → 0.465 m,
    // df-mpc 0.043 → 0.104 m at 2 mm.
    assert!(f1 > 1.5 * f0, "fmpc does not degrade: {f0} → {f1}");
    assert!(
        d1 - d0 < 0.5 * (f1 - f0),
        "df-mpc degrades like fmpc: {d0} → {d1} vs {f0} → {f1}"
    );
    let dir = out_dir("noise");
    let out = OutputPaths::resolve(&dir, "noise_sweep", None, None);
    let files = write_noise_sweep(&result, &out).expect("written");
    assert_eq!(files.len(), 7, "{files:?}");
    for f in &files {
        assert!(std::fs::metadata(f).expect("exists").len() > 100, "{f:?}");
    }
    for stem in ["noise_sweep", "noise_sweep_late", "noise_sweep_smoothness"] {
        assert!(dir.join(format!("{stem}.svg")).exists());
        assert!(dir.join(format!("{stem}.png")).exists());
    }

    let text = std::fs::read_to_string(&out.json).expect("json");
    let v: serde_json::Value = serde_json::from_str(&text).expect("valid json");
    assert_eq!(v["experiment"], "noise-sweep");
    assert_eq!(v["config"]["sigmas"].as_array().map(Vec::len), Some(2));
    assert_eq!(v["config"]["controllers"][0]["kind"], "df_mpc");
    assert_eq!(v["config"]["controllers"][0]["horizon"], 200);
    assert_eq!(v["config"]["controllers"][0]["r"], 0.08);
    assert_eq!(v["config"]["controllers"][1]["r"], 0.1);
    assert!((v["plant"]["tilt_limit"].as_f64().expect("tilt") - 60f64.to_radians()).abs() < 1e-12);
    let summary = v["summary"].as_array().expect("summary");
    assert_eq!(summary.len(), 3 * 2);
    for row in summary {
        for key in [
            "mean_error",
            "std_error",
            "mean_error_after",
            "smoothness_deg",
            "saturation_share",
            "max_tilt_deg",
        ] {
            assert!(row[key].is_number(), "{key} in {row}");
        }
        assert_eq!(row["trials"], 2);
        assert_eq!(row["diverged"], 0);
    }
    let trials = v["trials"].as_array().expect("trials");
    assert_eq!(trials.len(), 3 * 2 * 2);
    // Seeds 1000·σ_index + trial, shared by the controllers.
    let seeds: Vec<u64> = trials.iter().filter_map(|t| t["seed"].as_u64()).collect();
    assert_eq!(&seeds[..4], &[0, 1, 1000, 1001]);
    assert_eq!(&seeds[4..8], &[0, 1, 1000, 1001]);
    for t in trials {
        assert!(t["metrics"]["mae"].is_number());
        assert_eq!(t["metrics"]["ticks"], 300);
        assert_eq!(t["stop_reason"], "duration");
    }
    // The round trip through serde gives the same result.
    let back: NoiseSweepResult = serde_json::from_str(&text).expect("deserialises");
    assert_eq!(json(&back), json(&result));
    assert!(result.table().contains("df-mpc"));
}

#[test]
fn without_noise_both_mpcs_reach_the_target_as_the_reference_trace_does() {
    let config = NoiseSweepConfig {
        sigmas: vec![0.0],
        trials: 1,
        ..NoiseSweepConfig::default()
    };
    let result = run_noise_sweep(&config, false).expect("runs");
    for name in ["df-mpc", "fmpc", "pd"] {
        let row = result.row(name, 0).expect("row");
        assert!(row.mean_error_after < 0.1, "{name}: {row:?}");
        assert_eq!(row.controller_errors, 0, "{name}");
    }
    // The independent trace (reference/trace_1d.json, Euler plant at
    // 200 Hz, 50 Hz samples): mae 1.569 m (DF) and 1.633 m (FMPC). The lab
    // integrates with RK4 and averages at 200 Hz: within 1 %.
    let df = result.row("df-mpc", 0).expect("df").mean_error;
    let fmpc = result.row("fmpc", 0).expect("fmpc").mean_error;
    assert!((df - 1.569).abs() < 0.016, "df {df}");
    assert!((fmpc - 1.633).abs() < 0.016, "fmpc {fmpc}");
    // No noise: smooth commands, below the raised 60° limit.
    let r = result.row("df-mpc", 0).expect("df");
    assert!(r.smoothness_deg < 0.5 && r.saturation_share == 0.0, "{r:?}");
}

#[test]
fn same_seed_gives_identical_json_and_another_seed_does_not() {
    let a = run_noise_sweep(&reduced(), false).expect("runs");
    let b = run_noise_sweep(&reduced(), false).expect("runs");
    assert_eq!(json(&a), json(&b));
    let other = NoiseSweepConfig {
        seed_base: 7,
        ..reduced()
    };
    let c = run_noise_sweep(&other, false).expect("runs");
    assert_ne!(json(&a), json(&c));
}

#[test]
fn invalid_options_are_errors() {
    for bad in [
        NoiseSweepConfig {
            sigmas: vec![-1.0],
            ..reduced()
        },
        NoiseSweepConfig {
            trials: 0,
            ..reduced()
        },
        NoiseSweepConfig {
            duration: f64::NAN,
            ..reduced()
        },
        NoiseSweepConfig {
            controllers: vec![],
            ..reduced()
        },
        NoiseSweepConfig {
            controllers: vec![ControllerSpec::DfMpc {
                horizon: 1,
                q: 1.0,
                r: 0.08,
                max_tilt_deg: 60.0,
            }],
            ..reduced()
        },
        NoiseSweepConfig {
            controllers: vec![ControllerSpec::Fmpc {
                horizon: 200,
                q: 1.0,
                r: -1.0,
                max_tilt_deg: 60.0,
                estimator: None,
            }],
            ..reduced()
        },
    ] {
        assert!(run_noise_sweep(&bad, false).is_err(), "{bad:?}");
    }
}
