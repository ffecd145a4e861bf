//! The noise check (module docs of [`super`]): the noise sweep's set-up
//! flown by DF-MPC with and without the estimator.

use super::*;

/// One σ of the noise check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseCheckRow {
    /// Noise standard deviation on x \[m\].
    pub sigma: f64,
    /// DF-MPC: mean output error \[m\] (paper metric, 0–10 s).
    pub df_error: f64,
    /// DF-MPC with the estimator: mean output error \[m\].
    pub df_est_error: f64,
    /// df_est_error / df_error.
    pub ratio: f64,
    /// DF-MPC: mean output error after 5 s \[m\].
    pub df_late: f64,
    /// DF-MPC with the estimator: mean output error after 5 s \[m\].
    pub df_est_late: f64,
    /// df_est_late / df_late.
    pub ratio_late: f64,
    /// Multi-rate DF ([`MultiRateDf`]): mean output error \[m\].
    pub mr_error: f64,
    /// Multi-rate DF with the estimator: mean output error \[m\].
    pub mr_est_error: f64,
    /// mr_est_error / mr_error.
    pub mr_ratio: f64,
    /// Multi-rate DF: mean output error after 5 s \[m\].
    pub mr_late: f64,
    /// Multi-rate DF with the estimator: mean output error after 5 s \[m\].
    pub mr_est_late: f64,
    /// mr_est_late / mr_late.
    pub mr_ratio_late: f64,
}

/// The noise check's results.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseCheck {
    /// The noise sweep configuration flown (the DF-MPC spec is its first
    /// controller).
    pub sweep: NoiseSweepConfig,
    /// One row per σ.
    pub rows: Vec<NoiseCheckRow>,
    /// Largest `ratio` over σ.
    pub worst_ratio: f64,
    /// Largest `mr_ratio` over σ.
    pub mr_worst_ratio: f64,
    /// `worst_ratio ≤ 1.10` and `mr_worst_ratio ≤ 1.10`.
    pub pass: bool,
}

/// The noise check (module docs): the noise sweep's set-up flown by DF-MPC
/// with and without the estimator.
pub(super) fn run_noise_check(
    config: &MismatchConfig,
    progress: bool,
) -> Result<NoiseCheck, ExperimentError> {
    let sweep = NoiseSweepConfig {
        trials: config.trials,
        seed_base: config.seed_base,
        ..NoiseSweepConfig::default()
    };
    sweep.validate()?;
    let (horizon, q, r, tilt_deg) = match sweep.controllers.first() {
        Some(ControllerSpec::DfMpc {
            horizon,
            q,
            r,
            max_tilt_deg,
        }) => (*horizon, *q, *r, *max_tilt_deg),
        _ => (200, 1.0, 0.08, sweep.tilt_limit_deg),
    };
    let settings = |disturbance| DfMpcSettings {
        horizon,
        tracking_weight: [q; 3],
        jerk_weight: [r; 3],
        saturation: Some(InputSaturation {
            max_tilt: tilt_deg.to_radians(),
            ..InputSaturation::default()
        }),
        disturbance,
        ..DfMpcSettings::default()
    };
    let tilt = tilt_deg.to_radians();
    let mr = |disturbance| config.df_multi_rate.settings(tilt, 20.0, disturbance);
    // Classic DF without / with the estimator, multi-rate DF without / with.
    let variants = [
        settings(None),
        settings(Some(config.estimator)),
        mr(None),
        mr(Some(config.estimator)),
    ];
    let target = Vector3::new(sweep.target, 0.0, 0.0);
    let reference = Reference::setpoint(target).map_err(ExperimentError::Reference)?;
    let plant = sweep.plant_options();
    let mut specs = Vec::new();
    let mut keys = Vec::new();
    for (v, s) in variants.into_iter().enumerate() {
        let build = move || -> Result<Box<dyn Controller>, ControlError> {
            let model = ControlModel::Planar(PlanarModel::new(PlanarParams::default())?);
            Ok(Box::new(DfMpc::new(model, s)?))
        };
        build().map_err(|source| ExperimentError::Controller {
            controller: "df-mpc",
            source,
        })?;
        let factory: ControllerFactory = Arc::new(move || match build() {
            Ok(c) => c,
            Err(e) => Box::new(Unbuildable::new("df-mpc", &e)),
        });
        for (i, &sigma) in sweep.sigmas.iter().enumerate() {
            let r = reference.clone();
            let mut spec = TrialSpec::new(
                format!("noise-check v{v} sigma={sigma}"),
                factory.clone(),
                Arc::new(move || Box::new(r.clone())),
            );
            spec.plant_options = plant.clone();
            spec.initial = PlantState::hover(Vector3::zeros(), plant.g);
            spec.sensor = SensorSpec::Gaussian(GaussianOptions::x_only(sigma));
            spec.stop = StopCondition::Duration(sweep.duration);
            spec.target = Some(FixedTarget {
                target,
                axes: [true, false, false],
                after: sweep.after,
            });
            spec.stop_on_divergence = false;
            spec.validate()?;
            for t in 0..sweep.trials {
                specs.push((spec.clone(), sweep.seed(i, t)));
                keys.push((v, i));
            }
        }
    }
    let results = run_trials(&specs, progress);
    let n_sigma = sweep.sigmas.len();
    let mut err = vec![[const { Vec::new() }; 4]; n_sigma];
    let mut late = vec![[const { Vec::new() }; 4]; n_sigma];
    for (r, (v, i)) in results.into_iter().zip(keys) {
        let r = r?;
        err[i][v].push(r.metrics.mae.unwrap_or(f64::NAN));
        late[i][v].push(r.metrics.mae_after.unwrap_or(f64::NAN));
    }
    let rows: Vec<NoiseCheckRow> = sweep
        .sigmas
        .iter()
        .enumerate()
        .map(|(i, &sigma)| {
            let m = |x: &Vec<f64>| mean(x.iter().copied());
            let (e0, e1) = (m(&err[i][0]), m(&err[i][1]));
            let (l0, l1) = (m(&late[i][0]), m(&late[i][1]));
            let (e2, e3) = (m(&err[i][2]), m(&err[i][3]));
            let (l2, l3) = (m(&late[i][2]), m(&late[i][3]));
            NoiseCheckRow {
                mr_error: e2,
                mr_est_error: e3,
                mr_ratio: e3 / e2,
                mr_late: l2,
                mr_est_late: l3,
                mr_ratio_late: l3 / l2,
                sigma,
                df_error: e0,
                df_est_error: e1,
                ratio: e1 / e0,
                df_late: l0,
                df_est_late: l1,
                ratio_late: l1 / l0,
            }
        })
        .collect();
    let worst_ratio = worst(rows.iter().map(|r| r.ratio));
    let mr_worst_ratio = worst(rows.iter().map(|r| r.mr_ratio));
    Ok(NoiseCheck {
        sweep,
        rows,
        worst_ratio,
        mr_worst_ratio,
        pass: worst_ratio <= NOISE_RATIO_BUDGET && mr_worst_ratio <= NOISE_RATIO_BUDGET,
    })
}
