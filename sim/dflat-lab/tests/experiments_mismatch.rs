//! The mismatch study: a reduced run (noise-free, two scenarios,
//! one trial) shows the estimator removing the offsets that DF-MPC alone
//! leaves, writes its JSON, table and plots, and the noise check runs.

use std::path::PathBuf;

use dflat_lab::experiments::OutputPaths;
use dflat_lab::experiments::mismatch::{
    MismatchConfig, MismatchController, NOISE_RATIO_BUDGET, run_mismatch, write_mismatch,
};

#[test]
fn estimator_removes_wind_and_hover_thrust_offsets() {
    let mut config = MismatchConfig {
        trials: 1,
        sigmas: vec![0.0],
        noise_check: false,
        controllers: vec![MismatchController::Df, MismatchController::DfEstimator],
        airframe: None,
        ..MismatchConfig::default()
    };
    config
        .scenarios
        .retain(|s| s.name == "wind" || s.name == "hover");
    assert_eq!(config.scenarios.len(), 2);
    let result = run_mismatch(&config, false).expect("runs");
    for scenario in ["wind", "hover"] {
        let df = result.row(0.0, scenario, MismatchController::Df).unwrap();
        let est = result
            .row(0.0, scenario, MismatchController::DfEstimator)
            .unwrap();
        assert!(df.steady_error > 0.2, "{scenario}: DF {}", df.steady_error);
        assert!(
            est.steady_error < 0.05,
            "{scenario}: DF+est {}",
            est.steady_error
        );
    }
    let hover = result
        .row(0.0, "hover", MismatchController::DfEstimator)
        .unwrap();
    assert!((hover.thrust_scale - 1.25).abs() < 0.01, "{hover:?}");
    let wind = result
        .row(0.0, "wind", MismatchController::DfEstimator)
        .unwrap();
    // 3 m/s on 0.3 1/s of drag towards east (+y).
    assert!((wind.acceleration[1] - 0.9).abs() < 0.02, "{wind:?}");
    assert!(result.budgets.steady[0].pass);
    let table = result.table();
    assert!(
        table.contains("| wind |") && table.contains("PASS"),
        "{table}"
    );

    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("experiments/mismatch");
    let out = OutputPaths::resolve(&dir, "mismatch", None, None);
    let files = write_mismatch(&result, &out).expect("written");
    assert_eq!(files.len(), 5, "{files:?}");
    for f in &files {
        assert!(std::fs::metadata(f).unwrap().len() > 0, "{}", f.display());
    }
}

/// The noise check at its stated budget: over the noise sweep's σ (0 …
/// 1 cm), DF-MPC with the estimator within 10 % of DF-MPC without it, for
/// the classic and the multi-rate window (full run: ≤ 1.003,
/// docs/figures/mismatch.json). The main study is one PD scenario at σ = 0
/// only to keep the run short; the check flies DF on its own.
#[test]
fn noise_check_meets_its_budget_with_df() {
    let config = MismatchConfig {
        trials: 1,
        sigmas: vec![0.0],
        scenarios: Vec::new(),
        airframe: None,
        ..MismatchConfig::default()
    };
    // No scenarios is invalid for the main study …
    assert!(run_mismatch(&config, false).is_err());
    // … so fly one scenario with one controller and the noise check.
    let mut config = MismatchConfig {
        trials: 1,
        sigmas: vec![0.0],
        controllers: vec![MismatchController::Pd],
        airframe: None,
        ..MismatchConfig::default()
    };
    config.scenarios.truncate(1);
    let result = run_mismatch(&config, false).expect("runs");
    let check = result.noise_check.as_ref().expect("flown");
    assert_eq!(check.rows.len(), check.sweep.sigmas.len());
    assert!(
        check.sweep.sigmas.iter().any(|s| *s >= 1e-2),
        "{:?}",
        check.sweep.sigmas
    );
    for r in &check.rows {
        assert!(r.df_error > 0.0 && r.mr_error > 0.0, "{r:?}");
        assert!(
            r.ratio <= NOISE_RATIO_BUDGET && r.ratio >= 0.9,
            "classic DF: {r:?}"
        );
        assert!(
            r.mr_ratio <= NOISE_RATIO_BUDGET && r.mr_ratio >= 0.9,
            "multi-rate DF: {r:?}"
        );
    }
    assert_eq!(result.budgets.noise_pass, Some(true));
    // No DF + estimator row: the steady budget has nothing to pass.
    assert!(!result.budgets.steady[0].pass);
}

#[test]
fn multi_rate_df_with_estimator_meets_the_budget_at_1cm() {
    // The study's noise (σ = 1 cm at 50 Hz), the thrust and wind scenarios,
    // one trial: the classic DF diverges, the multi-rate DF keeps the
    // offsets, with the estimator it settles within the 5 cm budget.
    let sigma = 0.01;
    let mut config = MismatchConfig {
        trials: 1,
        sigmas: vec![sigma],
        noise_check: false,
        controllers: vec![
            MismatchController::DfEstimator,
            MismatchController::DfMultiRate,
            MismatchController::DfMultiRateEstimator,
        ],
        airframe: None,
        ..MismatchConfig::default()
    };
    config
        .scenarios
        .retain(|s| s.name == "wind" || s.name == "hover");
    let result = run_mismatch(&config, false).expect("runs");
    for scenario in ["wind", "hover"] {
        let classic = result
            .row(sigma, scenario, MismatchController::DfEstimator)
            .unwrap();
        assert!(classic.diverged > 0, "{scenario}: {classic:?}");
        let mr = result
            .row(sigma, scenario, MismatchController::DfMultiRate)
            .unwrap();
        assert!(mr.steady_error > 0.2, "{scenario}: MR {}", mr.steady_error);
        let est = result
            .row(sigma, scenario, MismatchController::DfMultiRateEstimator)
            .unwrap();
        assert_eq!(est.diverged, 0);
        assert!(
            est.steady_error < 0.05,
            "{scenario}: MR+est {}",
            est.steady_error
        );
    }
    let hover = result
        .row(sigma, "hover", MismatchController::DfMultiRateEstimator)
        .unwrap();
    assert!((hover.thrust_scale - 1.25).abs() < 0.01, "{hover:?}");
    // Budget rows: classic DF + estimator fails (diverged), multi-rate passes.
    let b = &result.budgets.steady;
    assert_eq!(b.len(), 2);
    assert!(!b[0].pass && b[1].pass, "{b:?}");
    assert_eq!(b[1].controller, "df-mr-smooth+est");
}
