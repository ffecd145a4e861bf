//! `dflat learn`: the flat maps' residual over the parametric model,
//! learned from flight records alone (the commands sent and the poses
//! measured; no state estimate).
//!
//! For each window size r and basis (see [`dflat_control::learned`]):
//!
//! 1. the parametric model's thrust axis and thrust at every tick, from the
//!    commands sent ([`parametric`]);
//! 2. the residual acceleration at every pose: the acceleration of a
//!    least-squares parabola through the window of r poses centred on it,
//!    minus the model's acceleration through the same weights, at the
//!    parabola's velocity ([`fit`]: poses at their capture times, any rate,
//!    noisy or not);
//! 3. ridge regression of that residual on the basis ([`fit::ridge`]: one
//!    weight per group, shared by x and y; z its own).
//!
//! The data are cut into blocks of [`fit::BLOCK_S`]: three of every five
//! train, one chooses r, the basis and λ by the acceleration left
//! unexplained on it (taken through one window of [`REFERENCE_S`] for
//! every candidate), one tests. The report gives the test blocks'
//! unexplained acceleration and the one-step and horizon prediction errors
//! of the learned model against the parametric one.
//!
//! What the flight did not excite is not learned: the velocity terms need
//! the speed to vary ([`MIN_SPEED_STD`]); with a steady speed nothing is
//! offered ([`LearnError::NothingDetermined`]). A residual that does not
//! beat the parametric model on held-out data is refused
//! ([`LearnError::NoImprovement`]).
//!
//! **No constant.** The bases are the velocity terms alone
//! ([`Feature::Velocity`], [`Feature::Quadratic`], [`Feature::RotorPlane`]);
//! a constant acceleration ([`Feature::Bias`], which model files may still
//! carry) is not learned. A constant is the day's wind or a trim, not the
//! airframe's maps, and the disturbance estimator (`[controller.disturbance]`)
//! estimates it in flight; learned from one flight it takes whatever the
//! records' dynamics leave on average. From 38 s of one racing line in the
//! SITL it learned a lateral −0.019 m/s² from a single turn, and the
//! learned flight was 9.8× the matched one; without the constant
//! 2.6–2.9× (`tests/e2e_learned.rs`, 2026-11-29, the weights shared by x
//! and y in both).
//!
//! **Axis by axis** ([`Learned::parametric_axes`]): an axis whose learned
//! weights are all undetermined (no weight's 95 % interval within
//! [`MAX_RELATIVE_INTERVAL`] of it; x and y share theirs), or on which
//! the residual does not lower the validation blocks' unexplained
//! acceleration, keeps the parametric
//! model: its weights are set to 0 and the report says why. Every
//! candidate is scored on the validation blocks so, as it would fly: a
//! window that determines both axes wins over one that scores lower on
//! weights it cannot keep (a 38 s record chose r = 5 for its full-weight
//! score, then lost y to its interval, and flew y worse than identify's,
//! `tests/e2e_learned.rs`, 2026-11-29; the shared horizontal weights end
//! that case). Under pose noise a short record could determine a constant
//! on one axis and not on the other; learned on both, it made the first
//! axis worse in flight (vision poses in `tests/e2e_learned.rs`,
//! 2026-11-28).

pub mod data;
pub mod fit;
mod horizon;
pub mod parametric;

use std::collections::BTreeMap;

use dflat_control::learned::{FORMAT, Feature, LearnedResidual, Support, VERSION, Validation};
use thiserror::Error;

use data::Run;
use fit::{Errors, Part, Prepared, Sample};
use parametric::Parametric;

/// The span \[s\] of the window the validation blocks' accelerations are
/// taken through, the same for every candidate (at least five poses): wide
/// enough that the pose noise does not drown the residual (2 cm at 50 Hz
/// is about 8 m/s² through 9 poses, 0.6 m/s² through 25, 0.1 m/s² through
/// 51), the residual compared through the same kernel.
pub const REFERENCE_S: f64 = 1.0;

/// The reference window \[poses\] of the records: [`REFERENCE_S`] at their
/// median pose rate, odd, at least 5.
fn reference_window(runs: &[Prepared]) -> usize {
    let mut gaps: Vec<f64> = runs
        .iter()
        .flat_map(|p| p.poses.windows(2).map(|w| w[1].t - w[0].t))
        .filter(|d| *d > 0.0)
        .collect();
    gaps.sort_by(f64::total_cmp);
    let spacing = gaps.get(gaps.len() / 2).copied().unwrap_or(0.02);
    let half = (0.5 * REFERENCE_S / spacing).round().max(2.0) as usize;
    2 * half + 1
}
/// Window sizes tried (poses, odd: the window is centred on the sample).
pub const WINDOWS: [usize; 6] = [3, 5, 9, 15, 25, 51];
/// Ridge λ tried.
pub const LAMBDAS: [f64; 3] = [1e-6, 1e-3, 1e-1];
/// Horizon of the horizon error \[s\].
pub const HORIZON_S: f64 = 0.5;
/// Largest 95 % half-width of a basis group's weights against their size
/// (on the axis where it is largest) for the group to count as determined
/// by the flight: as `identify`, no term with a wider interval is learned.
pub const MAX_RELATIVE_INTERVAL: f64 = 0.3;
/// Least standard deviation of the speed [m/s] for the velocity terms.
pub const MIN_SPEED_STD: f64 = 0.5;
/// Least engaged time \[s\] to learn from.
pub const MIN_SECONDS: f64 = 20.0;
/// Every how many ticks a held-out rollout starts.
const STRIDE: usize = 5;

/// Why nothing was learned.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LearnError {
    /// A record is not usable.
    #[error("{file}: {message}")]
    Record {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Too little engaged flight.
    #[error(
        "only {seconds:.1} s engaged in the records (need at least {MIN_SECONDS} s): fly longer"
    )]
    TooShort {
        /// Engaged time \[s\].
        seconds: f64,
    },
    /// No basis could be fitted.
    #[error("no fit: the normal equations are singular for every window and basis")]
    NoFit,
    /// No term is determined by the records: none offered (the speed did
    /// not vary) or each candidate's weights undetermined.
    #[error(
        "no term is determined by the records ({why}): nothing learned, keep the parametric model"
    )]
    NothingDetermined {
        /// What was not excited or not determined.
        why: String,
    },
    /// No axis keeps a learned term (module docs, "Axis by axis").
    #[error("no axis keeps a learned term ({why}): nothing learned, keep the parametric model")]
    EveryAxisParametric {
        /// Each axis's reason.
        why: String,
    },
    /// The records leave no held-out block to choose or judge a residual
    /// on (runs too short for the validation and test blocks).
    #[error(
        "the records leave no {part} block to judge a residual on ({seconds:.1} s in runs of \
         at most {longest:.1} s; of every five {block} s blocks of a run the fourth validates \
         and the fifth tests): fly longer runs"
    )]
    NoHeldOut {
        /// Which part is empty ("validation" or "test").
        part: &'static str,
        /// Engaged time \[s\].
        seconds: f64,
        /// The longest run \[s\].
        longest: f64,
        /// Block length \[s\].
        block: f64,
    },
    /// The best residual does not beat the parametric model held out.
    #[error(
        "the residual does not explain the held-out acceleration better than the parametric \
         model (RMS left: parametric {parametric:.4} m/s², learned {learned:.4} m/s²): nothing \
         learned, keep the parametric model"
    )]
    NoImprovement {
        /// RMS acceleration the parametric model leaves on the validation
        /// blocks [m/s²].
        parametric: f64,
        /// The best residual's [m/s²].
        learned: f64,
    },
}

/// The `[vehicle]` table the residual is learned over.
#[derive(Debug, Clone, PartialEq)]
pub struct VehicleTable {
    /// `vehicle.model` (`planar`, `spatial`).
    pub model: String,
    /// Its numeric fields (name, value), stored in the file.
    pub fields: Vec<(String, f64)>,
    /// The parametric model they make.
    pub parametric: Parametric,
}

/// How [`learn_with`] chooses.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LearnOptions {
    /// The window r \[poses\] (odd, 3 ..= 51); `None`: chosen on held-out
    /// data among [`WINDOWS`].
    pub window: Option<usize>,
}

/// What [`learn`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Learned {
    /// The residual, ready to write.
    pub residual: LearnedResidual,
    /// Basis groups the flight did not excite (with why), not offered.
    pub unexcited: Vec<(Feature, String)>,
    /// NED axes (0 x, 1 y, 2 z) left to the parametric model (their
    /// weights 0), with why (module docs, "Axis by axis").
    pub parametric_axes: Vec<(usize, String)>,
    /// Candidates tried (window × basis × λ).
    pub candidates: usize,
    /// The test blocks' held-out horizon error against the true positions
    /// \[m\], parametric and with the residual (each from its own start
    /// window), when the records carry them (a simulator's: the lab);
    /// `None` for a flight's records. Not written to the model file.
    pub horizon_truth_m: Option<[f64; 2]>,
}

/// NED axes left to the parametric model, with why.
type ParametricAxes = Vec<(usize, String)>;

/// The bases tried, before the excitation check.
fn bases() -> Vec<Vec<Feature>> {
    use Feature::*;
    vec![
        vec![Velocity],
        vec![Quadratic],
        vec![Velocity, Quadratic],
        vec![Quadratic, RotorPlane],
        vec![Velocity, Quadratic, RotorPlane],
    ]
}

fn support_of(samples: &[Sample]) -> Support {
    let mut s = Support {
        speed_max: 0.0,
        tilt_max: 0.0,
        thrust_min: f64::INFINITY,
        thrust_max: 0.0,
    };
    for x in samples {
        s.speed_max = s.speed_max.max(x.speed);
        s.tilt_max = s.tilt_max.max(x.tilt);
        s.thrust_min = s.thrust_min.min(x.thrust);
        s.thrust_max = s.thrust_max.max(x.thrust);
    }
    s.thrust_min = s.thrust_min.min(s.thrust_max);
    s
}

fn std_of(v: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = v.clone().count().max(1) as f64;
    let m = v.clone().sum::<f64>() / n;
    (v.map(|x| (x - m).powi(2)).sum::<f64>() / n).sqrt()
}

/// Learns the residual of `vehicle`'s parametric model from the engaged
/// runs of one or more records, the window chosen on held-out data.
pub fn learn(runs: &[Run], vehicle: &VehicleTable) -> Result<Learned, LearnError> {
    learn_with(runs, vehicle, LearnOptions::default())
}

/// [`learn`] with `options` (a fixed window).
pub fn learn_with(
    runs: &[Run],
    vehicle: &VehicleTable,
    options: LearnOptions,
) -> Result<Learned, LearnError> {
    let model = &vehicle.parametric;
    let seconds: f64 = runs.iter().map(|r| r.ticks.len() as f64 * model.dt).sum();
    if seconds < MIN_SECONDS {
        return Err(LearnError::TooShort { seconds });
    }
    let prepared: Vec<Prepared> = runs
        .iter()
        .filter(|r| r.poses.len() >= 3 && r.ticks.len() as f64 * model.dt >= 2.0 * HORIZON_S)
        .map(|r| Prepared::new(r, model))
        .collect();
    let windows: Vec<usize> = match options.window {
        Some(r) => vec![2 * fit::half_width(r) + 1],
        None => WINDOWS.to_vec(),
    };
    let horizon = HORIZON_S;
    // Held-out targets: the validation blocks through one window for every
    // candidate, so they are judged on the same accelerations.
    let reference = reference_window(&prepared);
    let held_out: Vec<fit::Smoothed> = prepared
        .iter()
        .flat_map(|p| fit::smoothed(p, model, reference, Part::Validate))
        .collect();
    let longest = runs
        .iter()
        .map(|r| r.ticks.len() as f64 * model.dt)
        .fold(0.0, f64::max);
    let no_held_out = |part| LearnError::NoHeldOut {
        part,
        seconds,
        longest,
        block: fit::BLOCK_S,
    };
    if held_out.is_empty() {
        return Err(no_held_out("validation"));
    }
    let base = fit::acceleration_error(&held_out, None, model.spatial);
    let probe = fit::samples(
        &prepared,
        model,
        windows[0],
        &[Feature::Velocity],
        Part::Train,
    );
    let speed_std = std_of(probe.iter().map(|s| s.speed));
    let mut unexcited = Vec::new();
    if speed_std < MIN_SPEED_STD {
        for f in [Feature::Velocity, Feature::Quadratic, Feature::RotorPlane] {
            unexcited.push((
                f,
                format!("speed std {speed_std:.2} m/s < {MIN_SPEED_STD} m/s"),
            ));
        }
    }
    let offered: Vec<Vec<Feature>> = bases()
        .into_iter()
        .filter(|b| b.iter().all(|f| !unexcited.iter().any(|(u, _)| u == f)))
        .collect();
    let axes = if model.spatial { 3 } else { 2 };
    let base_axes = fit::acceleration_error_per_axis(&held_out, None, model.spatial);
    // Each candidate is judged as it would fly: the axes it leaves to the
    // parametric model (module docs, "Axis by axis") zeroed before its
    // held-out score, so a window that determines every axis is not lost
    // to one that scores lower on weights it cannot keep.
    let mut best: Option<(f64, LearnedResidual, ParametricAxes)> = None;
    // The refusal's words when every candidate keeps no axis: those of the
    // one whose full weights scored best.
    let mut every_axis_parametric: Option<(f64, String)> = None;
    let mut undetermined: Vec<(usize, Feature, String)> = Vec::new();
    let mut candidates = 0;
    for &r in &windows {
        for features in &offered {
            let train = fit::samples(&prepared, model, r, features, Part::Train);
            let support = support_of(&train);
            for lambda in LAMBDAS {
                candidates += 1;
                let Some(fitted) = fit::ridge(&train, features, lambda, r) else {
                    continue;
                };
                if let Some((f, why)) = undetermined_group(features, &fitted) {
                    if !undetermined.iter().any(|(w, u, _)| *w == r && *u == f) {
                        undetermined.push((r, f, why));
                    }
                    continue;
                }
                let mut candidate =
                    residual_file(vehicle, r, features, lambda, fitted.weights, support);
                // The residual acts on each axis through that axis's weights
                // alone: one pass over the held-out blocks gives every
                // axis's error, flown with its weights or at 0.
                let full_axes =
                    fit::acceleration_error_per_axis(&held_out, Some(&candidate), model.spatial);
                // The full weights' score names the closest refusal.
                let full = fit::combined(&full_axes);
                let (kept, flown_axes) = keep_parametric_axes(
                    &mut candidate,
                    &fitted.half_width,
                    &full_axes,
                    &base_axes,
                    model.spatial,
                );
                if kept.len() == axes {
                    if every_axis_parametric
                        .as_ref()
                        .is_none_or(|(b, _)| full < *b)
                    {
                        let why = kept
                            .iter()
                            .map(|(a, w)| format!("{}: {w}", ["x", "y", "z"][*a]))
                            .collect::<Vec<_>>()
                            .join("; ");
                        every_axis_parametric = Some((full, why));
                    }
                    continue;
                }
                let score = fit::combined(&flown_axes);
                if score.is_finite() && best.as_ref().is_none_or(|(b, _, _)| score < *b) {
                    best = Some((score, candidate, kept));
                }
            }
        }
    }
    let Some((score, mut residual, parametric_axes)) = best else {
        let not_determined = || {
            unexcited
                .iter()
                .map(|(f, why)| format!("{}: {why}", f.name()))
                .chain(
                    // Each group once (the first window it failed at).
                    undetermined
                        .iter()
                        .enumerate()
                        .filter(|(i, (_, f, _))| !undetermined[..*i].iter().any(|(_, g, _)| g == f))
                        .map(|(_, (r, f, why))| format!("{} (window {r}): {why}", f.name())),
                )
                .collect::<Vec<_>>()
        };
        return Err(match every_axis_parametric {
            Some((_, why)) => LearnError::EveryAxisParametric { why },
            None if offered.is_empty() || !undetermined.is_empty() => {
                LearnError::NothingDetermined {
                    why: not_determined().join("; "),
                }
            }
            None => LearnError::NoFit,
        });
    };
    for (r, f, why) in undetermined {
        if r == residual.window
            && !residual.features.contains(&f)
            && !unexcited.iter().any(|(u, _)| *u == f)
        {
            unexcited.push((f, format!("window {r}: {why}")));
        }
    }
    if score >= base {
        return Err(LearnError::NoImprovement {
            parametric: base,
            learned: score,
        });
    }
    // Each model's input-to-output map from its own window of poses,
    // chosen on the validation blocks, judged on the test blocks.
    let start_p = best_start(&prepared, model, None).ok_or_else(|| no_held_out("validation"))?;
    let start_l =
        best_start(&prepared, model, Some(&residual)).ok_or_else(|| no_held_out("validation"))?;
    let test_p = fit::rollouts(&prepared, model, None, Part::Test, horizon, STRIDE, start_p);
    let test_l = fit::rollouts(
        &prepared,
        model,
        Some(&residual),
        Part::Test,
        horizon,
        STRIDE,
        start_l,
    );
    let test: Vec<fit::Smoothed> = prepared
        .iter()
        .flat_map(|p| fit::smoothed(p, model, reference, Part::Test))
        .collect();
    if test_l.count == 0 || test.is_empty() {
        return Err(no_held_out("test"));
    }
    residual.validation = validation((&test_p, start_p), (&test_l, start_l));
    residual.validation.acceleration_parametric =
        fit::acceleration_error(&test, None, model.spatial);
    residual.validation.acceleration_learned =
        fit::acceleration_error(&test, Some(&residual), model.spatial);
    residual.seconds = seconds;
    let horizon_truth_m = (test_p.truth_count > 0 && test_l.truth_count > 0)
        .then(|| [test_p.horizon_truth_rms(), test_l.horizon_truth_rms()]);
    Ok(Learned {
        residual,
        unexcited,
        parametric_axes,
        candidates,
        horizon_truth_m,
    })
}

/// Sets to 0 the weights of each axis the residual should not act on
/// (module docs, "Axis by axis"): all its weights undetermined by the
/// fit (`half_width`, the 95 % half-widths), or its held-out unexplained
/// acceleration not lowered (`learned`: per axis with the residual's
/// weights, `base`: without; `learn_with` refuses records without
/// validation blocks). Returns those axes with why, and each axis's
/// held-out error as flown (`base` where its weights are 0: an axis's
/// residual is its own weights' alone).
fn keep_parametric_axes(
    residual: &mut LearnedResidual,
    half_width: &[Vec<f64>; 3],
    learned: &[f64; 3],
    base: &[f64; 3],
    spatial: bool,
) -> (ParametricAxes, [f64; 3]) {
    let axes = if spatial { 3 } else { 2 };
    let mut kept = Vec::new();
    for (axis, (w, hw)) in residual
        .weights
        .iter()
        .zip(half_width)
        .enumerate()
        .take(axes)
    {
        let determined = w
            .iter()
            .zip(hw)
            .any(|(w, h)| *w != 0.0 && h.is_finite() && *h <= MAX_RELATIVE_INTERVAL * w.abs());
        if !determined {
            let (w, h) = best_determined(w.iter().copied().zip(hw.iter().copied()))
                .unwrap_or((0.0, f64::NAN));
            kept.push((
                axis,
                format!(
                    "no weight determined (the best {w:.4} ± {h:.4}, 95 %: more than {:.0} % of it)",
                    100.0 * MAX_RELATIVE_INTERVAL
                ),
            ));
        }
    }
    for axis in 0..axes {
        if kept.iter().any(|(a, _)| *a == axis) {
            continue;
        }
        if learned[axis].is_nan() || learned[axis] >= base[axis] {
            kept.push((
                axis,
                format!(
                    "held-out unexplained acceleration not lowered ({:.4} → {:.4} m/s² RMS)",
                    base[axis], learned[axis]
                ),
            ));
        }
    }
    let mut flown = *learned;
    for (axis, _) in &kept {
        residual.weights[*axis].iter_mut().for_each(|w| *w = 0.0);
        flown[*axis] = base[*axis];
    }
    kept.sort_by_key(|(a, _)| *a);
    (kept, flown)
}

/// The first group of `features` (the constant excepted) whose weights the
/// data did not determine: none of its weights (any column, any axis) has a
/// 95 % half-width of at most [`MAX_RELATIVE_INTERVAL`] of its value. With
/// the reason.
fn undetermined_group(features: &[Feature], fitted: &fit::Ridge) -> Option<(Feature, String)> {
    let mut col = 0;
    for f in features {
        let cols = col..col + f.columns();
        col += f.columns();
        if *f == Feature::Bias {
            continue;
        }
        // The best-determined weight of the group.
        let best = best_determined(
            cols.clone()
                .flat_map(|i| (0..3).map(move |axis| (axis, i)))
                .map(|(axis, i)| (fitted.weights[axis][i], fitted.half_width[axis][i])),
        )?;
        if best.1.is_nan() || best.1 > MAX_RELATIVE_INTERVAL * best.0.abs() {
            return Some((
                *f,
                format!(
                    "its best-determined weight {:.4} ± {:.4} (95 %): more than {:.0} % of it",
                    best.0,
                    best.1,
                    100.0 * MAX_RELATIVE_INTERVAL
                ),
            ));
        }
    }
    None
}

/// Of `(weight, 95 % half-width)` pairs, the best-determined: the
/// largest `|weight| / half-width`.
fn best_determined(pairs: impl Iterator<Item = (f64, f64)>) -> Option<(f64, f64)> {
    pairs.max_by(|a, b| (a.0.abs() / a.1).total_cmp(&(b.0.abs() / b.1)))
}

/// The start window (of [`fit::START_WINDOWS_S`]) with the least
/// held-out horizon error on the validation blocks for the parametric
/// model with `residual` (`None`: alone); `None` when no window gives a
/// validation rollout.
fn best_start(
    prepared: &[Prepared],
    model: &Parametric,
    residual: Option<&LearnedResidual>,
) -> Option<f64> {
    fit::START_WINDOWS_S
        .iter()
        .map(|&s| {
            let e = fit::rollouts(
                prepared,
                model,
                residual,
                Part::Validate,
                HORIZON_S,
                STRIDE,
                s,
            );
            (s, e.horizon_rms())
        })
        .filter(|(_, e)| e.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(s, _)| s)
}

/// The test blocks' errors of the parametric model and with the residual,
/// each with the start window it was judged from \[s\].
fn validation(
    (parametric, start_parametric_s): (&Errors, f64),
    (learned, start_learned_s): (&Errors, f64),
) -> Validation {
    Validation {
        one_step_parametric_m: parametric.one_step_rms(),
        one_step_learned_m: learned.one_step_rms(),
        horizon_s: HORIZON_S,
        horizon_parametric_m: parametric.horizon_rms(),
        horizon_learned_m: learned.horizon_rms(),
        samples: learned.count,
        start_parametric_s,
        start_learned_s,
        acceleration_parametric: f64::NAN,
        acceleration_learned: f64::NAN,
    }
}

fn residual_file(
    vehicle: &VehicleTable,
    window: usize,
    features: &[Feature],
    lambda: f64,
    weights: [Vec<f64>; 3],
    support: Support,
) -> LearnedResidual {
    LearnedResidual {
        format: FORMAT.into(),
        version: VERSION,
        vehicle_model: vehicle.model.clone(),
        vehicle: vehicle.fields.iter().cloned().collect::<BTreeMap<_, _>>(),
        dt: vehicle.parametric.dt,
        window,
        features: features.to_vec(),
        lambda,
        weights,
        support,
        validation: Validation::unmeasured(HORIZON_S),
        seconds: 0.0,
    }
}

#[cfg(test)]
mod tests;
