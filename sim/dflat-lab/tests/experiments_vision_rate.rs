//! The vision-rate study, reduced, and the harness hook that
//! feeds raw timestamped samples to a multi-rate controller.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::reference::Reference;
use dflat_control::window::MultiRateSettings;
use dflat_control::{
    ControlError, ControlModel, Controller, Measurement, ReferenceSource, TickOutput,
};
use dflat_lab::experiments::vision_rate::{
    BUDGET_RATE, VisionRateConfig, run_vision_rate, write_vision_rate,
};
use dflat_lab::experiments::{OutputPaths, TrialSetup};
use dflat_lab::harness::{ControllerFactory, ReferenceFactory, TrialSpec, run_trial};
use dflat_model::{PlanarModel, PlanarParams};
use dflat_sim::sensing::{SensorSpec, VisionMode, VisionOptions};

fn out_dir(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .join("experiments")
        .join(name)
}

/// One speed, 15 Hz, one trial, capped at 6 s.
fn reduced() -> VisionRateConfig {
    let default = VisionRateConfig::default();
    VisionRateConfig {
        speeds: vec![5.0],
        rates: vec![BUDGET_RATE],
        trials: 1,
        setup: TrialSetup {
            max_duration: Some(6.0),
            ..default.setup.clone()
        },
        ..default
    }
}

#[test]
fn reduced_vision_rate_runs_and_writes() {
    let config = reduced();
    let result = run_vision_rate(&config, false).expect("runs");
    assert_eq!(result.rows.len(), config.controllers.len());
    let keys: Vec<&str> = result.rows.iter().map(|r| r.controller.as_str()).collect();
    assert_eq!(
        keys,
        [
            "df-paper",
            "df-multirate",
            "df-mr-smooth",
            "fmpc-est",
            "pd-est"
        ]
    );
    for r in &result.rows {
        assert_eq!(r.trials, 1);
        assert_eq!(r.controller_errors, 0, "{}", r.controller);
        assert!(r.path_error.is_some(), "{}", r.controller);
    }
    // The multi-rate windows remove the chatter of the extrapolated stream.
    let paper = result.row("df-paper", BUDGET_RATE, 5.0).unwrap();
    let mr = result.row("df-multirate", BUDGET_RATE, 5.0).unwrap();
    assert!(
        mr.smoothness_deg < 0.25 * paper.smoothness_deg,
        "{} vs {}",
        mr.smoothness_deg,
        paper.smoothness_deg
    );
    // The baselines fed by their estimator fly smoothly too (finite
    // differences of 15 Hz poses gave 20–55°/tick).
    for key in ["fmpc-est", "pd-est"] {
        let row = result.row(key, BUDGET_RATE, 5.0).unwrap();
        assert!(
            row.smoothness_deg < 5.0,
            "{key}: {}°/tick",
            row.smoothness_deg
        );
    }
    assert_eq!(result.budgets.len(), 1);
    let table = result.table();
    assert!(table.contains("| 5 | df-mr-smooth |"), "{table}");
    assert!(table.contains("Budgets at 15 Hz"), "{table}");

    let dir = out_dir("vision_rate");
    let out = OutputPaths::resolve(&dir, "vision_rate", None, None);
    let files = write_vision_rate(&result, &out).expect("writes");
    assert_eq!(files.len(), 1 + 3 * 2);
    for f in &files {
        assert!(f.exists(), "{}", f.display());
    }
    // Deterministic: the same seed gives the same JSON.
    let again = run_vision_rate(&config, false).expect("runs");
    assert_eq!(
        serde_json::to_string(&result).unwrap(),
        serde_json::to_string(&again).unwrap()
    );
}

/// Records what the harness hands to a controller, and flies a multi-rate
/// DF-MPC underneath.
struct Spy {
    inner: DfMpc,
    log: Arc<Mutex<Vec<(char, f64)>>>,
}

impl Controller for Spy {
    fn name(&self) -> &'static str {
        "spy"
    }
    fn multi_rate(&self) -> bool {
        self.inner.multi_rate()
    }
    fn observe(&mut self, sample: &Measurement) {
        self.log.lock().unwrap().push(('o', sample.t));
        self.inner.observe(sample);
    }
    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        self.log.lock().unwrap().push(('u', measurement.t));
        self.inner.update(measurement, reference)
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
}

/// The harness hands every sample to `observe` with its capture time before
/// the tick's `update`, which gets the tick time; the multi-rate DF-MPC on
/// raw 15 Hz samples flies the L path at 5 m/s without error.
#[test]
fn harness_feeds_raw_samples_to_multirate_controller() {
    let log = Arc::new(Mutex::new(Vec::new()));
    let spy_log = Arc::clone(&log);
    let controller: ControllerFactory = Arc::new(move || {
        let model = ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap());
        let settings = DfMpcSettings {
            tracking_weight: [1.0; 3],
            jerk_weight: [0.003; 3],
            multi_rate: Some(MultiRateSettings::default()),
            ..DfMpcSettings::default()
        };
        Box::new(Spy {
            inner: DfMpc::new(model, settings).unwrap(),
            log: Arc::clone(&spy_log),
        })
    });
    let w =
        dflat_control::reference::paths::waypoints(&dflat_control::reference::paths::L_XY, -10.0);
    let reference = Reference::path(&w, 5.0).unwrap();
    let reference: ReferenceFactory = Arc::new(move || Box::new(reference.clone()));
    let mut spec = TrialSpec::new("multi-rate", controller, reference);
    spec.initial = dflat_sim::plant::PlantState::hover(w[0], 9.81);
    spec.sensor = SensorSpec::Vision(VisionOptions {
        mode: VisionMode::Raw,
        ..VisionOptions::default()
    });
    spec.stop = dflat_lab::harness::StopCondition::Duration(8.0);
    spec.path_distance = Some(dflat_lab::harness::polyline_path_distance(w.clone(), true));
    let r = run_trial(&spec, 3).unwrap();
    assert!(
        r.errors.is_empty(),
        "{:?}",
        &r.errors[..r.errors.len().min(3)]
    );
    let e = r.metrics.path_error.unwrap();
    assert!(e.p95 < 0.5, "{e:?}");
    assert!(
        r.metrics.smoothness_deg < 3.0,
        "{}",
        r.metrics.smoothness_deg
    );

    let log = log.lock().unwrap();
    let observed: Vec<f64> = log.iter().filter(|e| e.0 == 'o').map(|e| e.1).collect();
    let samples: Vec<f64> = r.samples.iter().map(|s| s.t_measured).collect();
    assert_eq!(
        observed, samples,
        "every delivered sample, with its capture time"
    );
    let ticks: Vec<f64> = log.iter().filter(|e| e.0 == 'u').map(|e| e.1).collect();
    let measured: Vec<f64> = r
        .ticks
        .iter()
        .filter(|t| t.measurement.is_some())
        .map(|t| t.t)
        .collect();
    assert!(measured.len() > 390);
    assert_eq!(
        ticks, measured,
        "one update per tick with a sample, at the tick time"
    );
}
