//! The fair comparison of the paths study: the paper's outdoor
//! set-up (§VII) fed the baselines from a state estimator (STEAM), not
//! from finite differences of the poses (its §VI simulation set-up). The
//! paths study ([`super::paths`]) therefore flies, beside the paper-form
//! controllers on the extrapolated vision stream:
//!
//! * `df-mr-smooth` — DF-MPC as the daemon ships it: every pose sample at
//!   its capture time in the multi-rate window, smoothness weight 50, plan
//!   tilt bound 30° per axis, r = 0.003 (not tuned here: the shipped
//!   weights, `dflat experiment vision-rate`);
//! * `fmpc-est`, `pd-est` — Flatness MPC and PD on the state of a
//!   [`dflat_control::estimator::StateEstimator`] fed with every sample at
//!   its capture time and predicted to the tick through the sent commands
//!   ([`EstimatorSettings::default`]: σ = 2 cm, 15 Hz, the vision
//!   sensor's), with their own weight search ([`estimator_candidates`]).

use dflat_control::estimator::EstimatorSettings;

use super::ControllerSpec;

/// The estimator the lab's baselines use: the default rule at the vision
/// sensor's σ = 2 cm and 15 Hz, input lag τ = 0.2 s (the plant's).
pub(crate) fn lab_estimator() -> EstimatorSettings {
    EstimatorSettings::for_sensor(0.02, 15.0)
}

/// The fairly fed controllers with their weights (the estimator-fed
/// baselines' are the weight search's choice on this set-up; the search
/// replaces them when it runs).
pub(crate) fn fair_controllers(tilt: f64) -> Vec<ControllerSpec> {
    vec![
        ControllerSpec::shipped_dfmpc(tilt),
        ControllerSpec::Fmpc {
            horizon: 75,
            q: 1.0,
            r: FMPC_EST_R,
            max_tilt_deg: tilt,
            estimator: Some(lab_estimator()),
        },
        ControllerSpec::Pd {
            kp: PD_EST_GAINS.0,
            kd: PD_EST_GAINS.1,
            max_tilt_deg: tilt,
            estimator: Some(lab_estimator()),
        },
    ]
}

/// Flatness MPC (estimator) jerk weight chosen by the search.
const FMPC_EST_R: f64 = 0.01;
/// PD (estimator) gains (k_p, k_d) chosen by the search.
const PD_EST_GAINS: (f64, f64) = (6.0, 5.0);

/// The weight search's candidates for the estimator-fed baselines: the
/// finite-difference ones' grids, widened by one step each way (the
/// estimator's smoother state may bear other weights). Flatness MPC
/// (N = 75, q = 1) r ∈ {0.001, 0.003, 0.01, 0.03, 0.1}; PD (k_p, k_d) ∈
/// {(1, 1.6), (2, 2.5), (3, 3), (4, 4), (6, 5)}.
pub(crate) fn estimator_candidates(tilt: f64) -> Vec<ControllerSpec> {
    let mut c = Vec::new();
    for r in [0.001, 0.003, 0.01, 0.03, 0.1] {
        c.push(ControllerSpec::Fmpc {
            horizon: 75,
            q: 1.0,
            r,
            max_tilt_deg: tilt,
            estimator: Some(lab_estimator()),
        });
    }
    for (kp, kd) in [(1.0, 1.6), (2.0, 2.5), (3.0, 3.0), (4.0, 4.0), (6.0, 5.0)] {
        c.push(ControllerSpec::Pd {
            kp,
            kd,
            max_tilt_deg: tilt,
            estimator: Some(lab_estimator()),
        });
    }
    c
}
