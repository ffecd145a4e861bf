//! `dflat experiment learned`: the flat maps' residual learned from flight
//! records, flown, against the parametric identify and the matched plant.
//!
//! Set-up: the lab's planar, spatial and rigid plants with aerodynamics no
//! parametric term has — parasitic drag quadratic in speed (0.03 |v|v) and
//! rotor drag in the body plane (0.2 /s) — flown by the shipped DF-MPC
//! (`df-mr-smooth`: multi-rate windows, smoothness, 30° plan tilt, 35°
//! command) on the planar model (planar plant) or the spatial model, on the
//! L (a path at a fixed speed) and two planner streams (figure eight,
//! racing line; 20 Hz p/v/a, 60 s each) at 5, 7 and 9 m/s (each stream's
//! top speed, as the L's legs: `LearnedShape::trajectory`), under vision
//! poses at 50 and 15 Hz (60 ms latency, 2 cm noise). Per plant and pose
//! rate, in the order a user would (the records learn is given: the stock
//! and identified flights, about 13 minutes):
//!
//! 1. **matched**: the plant without the aerodynamics, the stock
//!    `[vehicle]` (the anchor every ratio is taken against);
//! 2. **stock**: the aerodynamic plant, the stock `[vehicle]`;
//! 3. **identify**: `dflat identify` on the stock flights' records (what
//!    it recommends: excited, outside its interval and more than 5 % off);
//!    those flown;
//! 4. **learned**: `dflat learn` on the stock and identified flights'
//!    records over the identified `[vehicle]`, its window fixed at 3 poses;
//! 5. **learned, r from data**: the same with the window chosen on
//!    held-out data;
//! 6. **exact**: the plant's own aerodynamics written as the residual
//!    (`−c_q·|v|·v − d·(v − n·(n·v))`, everywhere in support) over the
//!    identified `[vehicle]` without its linear drag: what a perfectly
//!    learned residual flies in this controller, so a gap to matched is
//!    split into what learning misses and what the residual's place in
//!    the controller misses (`--exact-scale` gives the controller a share
//!    of it instead, [`LearnedConfig::exact_scale`]: the flights'
//!    sensitivity to a drag the model under- or over-predicts);
//!
//! and how many seconds of those records the learning needs: the
//! residual learned from their first T seconds, flown on every cell of the
//! first plant at the first pose rate.
//!
//! Budgets (issue 42): learned p95 ≤ 1.1× matched at every speed and never
//! above identify's; no axis worse after identify or learn.

mod flights;
mod records;
mod report;

pub use flights::{
    AeroPlant, Flight, Judged, LearnedShape, SMOOTHNESS, VISION_SIGMA, control_model,
};

use dflat_control::dfmpc::PlanTiltBound;
use dflat_control::learned::{Feature, LearnedResidual, Support, Validation};
use dflat_tuning::identify::{self, FlownVehicle};
use dflat_tuning::learn::parametric::Parametric;
use dflat_tuning::learn::{self, LearnOptions, VehicleTable, data::Run};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{ExperimentError, invalid};
use crate::harness::{TrialResult, run_trials};

/// The `[vehicle]` values a flight is flown with (the lab's plants take
/// specific thrust; the records carry it normalised at
/// [`Vehicle::HOVER_THRUST`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Vehicle {
    /// Attitude time constant τ \[s\].
    pub tau: f64,
    /// Attitude gain k̃.
    pub k: f64,
    /// Pure delay \[ms\].
    pub delay_ms: f64,
    /// Horizontal linear drag \[1/s\].
    pub drag_h: f64,
    /// Thrust time constant \[s\].
    pub tau_thrust: f64,
    /// Rotor drag \[1/s\] (spatial plants).
    #[serde(default)]
    pub drag_rotor: f64,
}

impl Vehicle {
    /// The shipped defaults (the lab's nominal plant).
    pub const STOCK: Self = Self {
        tau: 0.2,
        k: 1.0,
        delay_ms: 0.0,
        drag_h: 0.0,
        tau_thrust: 0.04,
        drag_rotor: 0.0,
    };
    /// Normalised thrust at hover in the lab's records.
    pub const HOVER_THRUST: f64 = 0.5;

    fn flown(&self, spatial: bool) -> FlownVehicle {
        FlownVehicle {
            tau: self.tau,
            k: self.k,
            tau_thrust: self.tau_thrust,
            hover_thrust: Self::HOVER_THRUST,
            spatial,
            delay_ms: self.delay_ms,
            drag_h: self.drag_h,
            drag_rotor: self.drag_rotor,
        }
    }

    /// The table `dflat learn` learns over.
    fn table(&self, spatial: bool, g: f64) -> VehicleTable {
        VehicleTable {
            model: if spatial { "spatial" } else { "planar" }.into(),
            fields: vec![
                ("tau".into(), self.tau),
                ("k".into(), self.k),
                ("delay_ms".into(), self.delay_ms),
                ("drag_h".into(), self.drag_h),
                ("tau_thrust".into(), self.tau_thrust),
                ("drag_rotor".into(), self.drag_rotor),
            ],
            parametric: Parametric {
                spatial,
                g,
                tau: self.tau,
                k: self.k,
                delay: self.delay_ms / 1e3,
                tau_thrust: self.tau_thrust,
                hover_thrust: Self::HOVER_THRUST,
                drag_h: self.drag_h,
                drag_v: 0.0,
                drag_rotor: if spatial { self.drag_rotor } else { 0.0 },
                dt: flights::DT,
            },
        }
    }
}

/// The noise seed the study's tables fly ([`LearnedConfig::seed`]'s
/// default; `docs/figures/learned.json`).
pub const TABLE_SEED: u64 = 1;

/// `dflat experiment learned`'s settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LearnedConfig {
    /// Plants.
    pub plants: Vec<AeroPlant>,
    /// Paths and streams.
    pub shapes: Vec<LearnedShape>,
    /// Speeds \[m/s\].
    pub speeds: Vec<f64>,
    /// Vision rates \[Hz\].
    pub vision_rates: Vec<f64>,
    /// The poses' noise, standard deviation per axis \[m\] (the lab's
    /// vision: 0.02).
    pub vision_sigma: f64,
    /// Parasitic drag of the aerodynamic plants \[1/m\].
    pub quadratic_drag: f64,
    /// Rotor drag \[1/s\].
    pub rotor_drag: f64,
    /// A stream's length \[s\], its ramp included (judged from the ramp's
    /// end plus 2 s: `judged_from`).
    pub stream_s: f64,
    /// DF-MPC's command-smoothness weight on x and y \[1/rad²\] (the
    /// shipped `df-mr-smooth`'s: 50).
    pub smoothness: f64,
    /// The plan's tilt bound of every flight (the shipped configs': a box
    /// per axis).
    pub plan_tilt_bound: PlanTiltBound,
    /// Seconds of records the learning is given in the seconds study (an
    /// empty list: no study).
    pub seconds: Vec<f64>,
    /// The noise seed of every flight (the plant's and the poses' noise;
    /// the records learned from follow): [`TABLE_SEED`] in the study's
    /// tables.
    pub seed: u64,
    /// The exact aerodynamics' share in the *exact* flights' residual: the
    /// controller is given `exact_scale × (c_q, d)`, the plants keep
    /// theirs (1: the exact aerodynamics; below 1, a drag the model
    /// under-predicts). A sensitivity study of the flights to the sign of
    /// the model's error (docs/results.md, "What the L's corner
    /// rewards"); the other flights do not change.
    pub exact_scale: f64,
}

impl Default for LearnedConfig {
    fn default() -> Self {
        Self {
            plants: vec![AeroPlant::Planar, AeroPlant::Spatial, AeroPlant::Rigid],
            shapes: vec![
                LearnedShape::L,
                LearnedShape::Eight,
                LearnedShape::RacingLine,
            ],
            speeds: vec![5.0, 7.0, 9.0],
            vision_rates: vec![50.0, 15.0],
            vision_sigma: flights::VISION_SIGMA,
            quadratic_drag: 0.03,
            rotor_drag: 0.2,
            stream_s: 60.0,
            smoothness: SMOOTHNESS,
            plan_tilt_bound: PlanTiltBound::Box,
            seconds: vec![20.0, 40.0, 80.0, 160.0, 320.0, 600.0],
            seed: TABLE_SEED,
            exact_scale: 1.0,
        }
    }
}

impl LearnedConfig {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), ExperimentError> {
        if self.plants.is_empty() || self.shapes.is_empty() {
            return Err(invalid("plants, shapes", "at least one each"));
        }
        if self.speeds.is_empty() || self.speeds.iter().any(|v| !(*v > 0.0 && *v <= 20.0)) {
            return Err(invalid("speeds", "at least one, each in (0, 20] m/s"));
        }
        if self.vision_rates.is_empty()
            || self
                .vision_rates
                .iter()
                .any(|v| !(*v >= 5.0 && *v <= 200.0))
        {
            return Err(invalid("vision_rates", "at least one, each 5 ..= 200 Hz"));
        }
        if !(0.0..=1.0).contains(&self.quadratic_drag) || !(0.0..=2.0).contains(&self.rotor_drag) {
            return Err(invalid(
                "quadratic_drag, rotor_drag",
                "0 ..= 1 1/m, 0 ..= 2 1/s",
            ));
        }
        if !(0.0..=0.5).contains(&self.vision_sigma) {
            return Err(invalid("vision_sigma", "0 ..= 0.5 m"));
        }
        if !(5.0..=120.0).contains(&self.stream_s) {
            return Err(invalid("stream_s", "5 ..= 120 s"));
        }
        let fastest = self.speeds.iter().copied().fold(0.0, f64::max);
        if self.stream_s < flights::judged_from(fastest) + 5.0 {
            return Err(invalid(
                "stream_s",
                "at least 5 s beyond the fastest stream's ramp (3 s × speed / 4 m/s, 3 s at least) and 2 s of settling",
            ));
        }
        if !(0.0..=2.0).contains(&self.exact_scale) {
            return Err(invalid("exact_scale", "0 ..= 2"));
        }
        if !(0.0..=1e4).contains(&self.smoothness) {
            return Err(invalid("smoothness", "0 ..= 1e4 1/rad²"));
        }
        if self
            .seconds
            .iter()
            .any(|s| s.is_nan() || *s < learn::MIN_SECONDS)
        {
            return Err(invalid("seconds", "each at least dflat learn's 20 s"));
        }
        Ok(())
    }
}

/// One cell: a plant, pose rate, shape and speed, flown five ways.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearnedRow {
    /// Plant.
    pub plant: &'static str,
    /// Vision rate \[Hz\].
    pub vision_hz: f64,
    /// Path or stream.
    pub shape: &'static str,
    /// Speed \[m/s\].
    pub speed: f64,
    /// The plant without the aerodynamics, stock `[vehicle]`.
    pub matched: Judged,
    /// With them, stock.
    pub stock: Judged,
    /// Identified.
    pub identified: Judged,
    /// Learned, window 3.
    pub learned: Judged,
    /// Learned, window chosen from data.
    pub learned_window: Judged,
    /// The plant's exact aerodynamics as the residual ([`exact_residual`]).
    pub exact: Judged,
}

/// What identify and learn gave one plant at one pose rate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupModels {
    /// Plant.
    pub plant: &'static str,
    /// Vision rate \[Hz\].
    pub vision_hz: f64,
    /// The identified `[vehicle]` values flown.
    pub identified: Vehicle,
    /// The identify report's changes, in words.
    pub identify_changes: Vec<String>,
    /// The residual with its window fixed at 3 (None: refused, why in
    /// `refusals`).
    pub learned: Option<LearnedResidual>,
    /// The residual with the window chosen from data.
    pub learned_window: Option<LearnedResidual>,
    /// The held-out 0.5 s prediction error against the plant's true
    /// positions \[m\], parametric and with the residual (window 3; each
    /// model from its own start window, as in its `validation`, which is
    /// judged against the noisy poses).
    pub learned_truth_m: Option<[f64; 2]>,
    /// The same for the residual with the window chosen from data.
    pub learned_window_truth_m: Option<[f64; 2]>,
    /// Why a residual was not learned.
    pub refusals: Vec<String>,
    /// The basis groups the records did not determine, and why.
    pub unexcited: Vec<String>,
}

/// The seconds study: p95 over the cells of one group against seconds of
/// records.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SecondsRow {
    /// Seconds of records learned from.
    pub seconds: f64,
    /// Held-out 0.5 s prediction error, parametric / learned \[m\].
    pub horizon_parametric_m: f64,
    /// With the residual \[m\].
    pub horizon_learned_m: f64,
    /// Worst ratio of the learned p95 to the matched p95 over the cells
    /// (nothing learned: the identified flights', which the daemon then
    /// keeps).
    pub worst_ratio: f64,
    /// Mean of that ratio.
    pub mean_ratio: f64,
    /// Why nothing was learned from these seconds (`dflat learn`'s
    /// refusal); `None`: a model was learned and flown.
    pub refused: Option<String>,
}

/// The study's results.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearnedResult {
    /// The settings flown.
    pub config: LearnedConfig,
    /// Per plant and rate: the identified and learned models.
    pub models: Vec<GroupModels>,
    /// The cells.
    pub rows: Vec<LearnedRow>,
    /// The seconds study (first plant, first rate).
    pub seconds: Vec<SecondsRow>,
}

/// A plant at a pose rate, and its cells.
#[derive(Debug, Clone, Copy)]
struct Group {
    plant: AeroPlant,
    vision_hz: f64,
}

/// Flies `flights` with the noise of `seed`, in parallel: the results in
/// order.
fn fly_all(
    flights: &[Flight],
    seed: u64,
    progress: bool,
) -> Result<Vec<TrialResult>, ExperimentError> {
    let specs = flights
        .iter()
        .map(|f| Ok((f.spec()?, seed)))
        .collect::<Result<Vec<_>, ExperimentError>>()?;
    run_trials(&specs, progress)
        .into_iter()
        .map(|r| r.map_err(ExperimentError::from))
        .collect()
}

/// Runs of the records of `results`, the first `seconds` of them (each run
/// cut in turn) when given.
fn records(results: &[&TrialResult], g: f64, seconds: Option<f64>) -> Vec<Run> {
    let mut runs: Vec<Run> = results.iter().flat_map(|r| records::runs(r, g)).collect();
    if let Some(limit) = seconds {
        let mut left = limit;
        runs.retain_mut(|r| {
            if left <= 0.0 {
                return false;
            }
            let n = ((left / flights::DT).floor() as usize).min(r.ticks.len());
            r.ticks.truncate(n);
            let end = r.ticks.last().map_or(0.0, |t| t.t);
            r.poses.retain(|p| p.t <= end);
            left -= n as f64 * flights::DT;
            n > 0
        });
    }
    runs
}

/// What `dflat identify` recommends from `results`, applied to `flown`
/// (the changes said in words).
fn identified(
    results: &[&TrialResult],
    flown: Vehicle,
    spatial: bool,
    g: f64,
) -> (Vehicle, Vec<String>) {
    let log = records::flight_log(results, g);
    let found = match identify::identify(&log) {
        Ok(f) => f,
        Err(e) => return (flown, vec![format!("refused: {e}")]),
    };
    let mut v = flown;
    let mut said = Vec::new();
    for c in found.compare(&flown.flown(spatial)) {
        if !c.change {
            continue;
        }
        let value = match c.field {
            "tau" => &mut v.tau,
            "k" => &mut v.k,
            "delay_ms" => &mut v.delay_ms,
            "drag_h" => &mut v.drag_h,
            "drag_rotor" if spatial => &mut v.drag_rotor,
            "tau_thrust" if spatial => &mut v.tau_thrust,
            // The lab's plants hover at HOVER_THRUST: reported, not applied.
            _ => {
                said.push(format!("{} {:.3} (not applied)", c.field, c.identified));
                continue;
            }
        };
        *value = match c.field {
            "delay_ms" => (c.identified / (1e3 * flights::DT)).round().max(0.0) * 1e3 * flights::DT,
            "drag_h" | "drag_rotor" => c.identified.clamp(0.0, 2.0),
            _ => c.identified,
        };
        if *value != c.flown {
            said.push(format!("{} {:.3} → {:.3}", c.field, c.flown, *value));
        }
    }
    (v, said)
}

/// A learned residual, the basis groups and axes it left (in words), and
/// its held-out error against the true positions (parametric, learned)
/// \[m\].
type LearnedModel = (LearnedResidual, Vec<String>, Option<[f64; 2]>);

/// Learns over `vehicle` from `runs` (window fixed or chosen); the model or
/// why not.
fn learned(
    runs: &[Run],
    vehicle: &Vehicle,
    spatial: bool,
    g: f64,
    window: Option<usize>,
) -> Result<LearnedModel, String> {
    learn::learn_with(runs, &vehicle.table(spatial, g), LearnOptions { window })
        .map(|l| {
            let axis = |a: &usize| ["x", "y", "z"].get(*a).copied().unwrap_or("?");
            let why = l
                .unexcited
                .iter()
                .map(|(f, w)| format!("{} ({w})", f.name()))
                .chain(
                    l.parametric_axes
                        .iter()
                        .map(|(a, w)| format!("axis {}: parametric ({w})", axis(a))),
                )
                .collect();
            (l.residual, why, l.horizon_truth_m)
        })
        .map_err(|e| e.to_string())
}

/// The plant's own aerodynamics — parasitic drag `c_q·|v|·v` and rotor
/// drag `d·(v − n·(n·v))`, `drag = (c_q, d)` — written as a learned
/// residual over `vehicle` (whose linear drag should be 0: the residual is
/// the whole of the aerodynamics), acting everywhere (its support covers
/// any flight). Planar: no z.
pub fn exact_residual(
    vehicle: &Vehicle,
    spatial: bool,
    g: f64,
    drag: (f64, f64),
) -> LearnedResidual {
    let table = vehicle.table(spatial, g);
    let (cq, d) = drag;
    let weights = std::array::from_fn(|axis| {
        let mut w = vec![0.0; 6];
        if spatial || axis < 2 {
            w[axis] = -cq;
            w[3 + axis] = -d;
        }
        w
    });
    LearnedResidual {
        format: dflat_control::learned::FORMAT.into(),
        version: dflat_control::learned::VERSION,
        vehicle_model: table.model,
        vehicle: table.fields.into_iter().collect(),
        dt: flights::DT,
        window: 3,
        features: vec![Feature::Quadratic, Feature::RotorPlane],
        lambda: 0.0,
        weights,
        support: Support {
            speed_max: 1e3,
            tilt_max: std::f64::consts::FRAC_PI_2,
            thrust_min: 1e-3,
            thrust_max: 1e3,
        },
        validation: Validation {
            one_step_parametric_m: f64::NAN,
            one_step_learned_m: f64::NAN,
            horizon_s: learn::HORIZON_S,
            horizon_parametric_m: f64::NAN,
            horizon_learned_m: f64::NAN,
            samples: 0,
            start_parametric_s: f64::NAN,
            start_learned_s: f64::NAN,
            acceleration_parametric: f64::NAN,
            acceleration_learned: f64::NAN,
        },
        seconds: 0.0,
    }
}

/// Flies the study.
pub fn run_learned(
    config: &LearnedConfig,
    progress: bool,
) -> Result<LearnedResult, ExperimentError> {
    config.validate()?;
    let g = 9.81;
    let drag = (config.quadratic_drag, config.rotor_drag);
    let groups: Vec<Group> = config
        .plants
        .iter()
        .flat_map(|&plant| {
            config
                .vision_rates
                .iter()
                .map(move |&vision_hz| Group { plant, vision_hz })
        })
        .collect();
    let cells: Vec<(LearnedShape, f64)> = config
        .shapes
        .iter()
        .flat_map(|&s| config.speeds.iter().map(move |&v| (s, v)))
        .collect();
    let flight = |gr: &Group, cell: &(LearnedShape, f64), aero, vehicle, learned| Flight {
        plant: gr.plant,
        aero,
        drag,
        shape: cell.0,
        speed: cell.1,
        vision_hz: gr.vision_hz,
        vision_sigma: config.vision_sigma,
        vehicle,
        learned,
        stream_s: config.stream_s,
        smoothness: config.smoothness,
        plan_tilt_bound: config.plan_tilt_bound,
    };
    // 1–2. Matched and stock.
    let mut first = Vec::new();
    for gr in &groups {
        for c in &cells {
            first.push(flight(gr, c, false, Vehicle::STOCK, None));
            first.push(flight(gr, c, true, Vehicle::STOCK, None));
        }
    }
    let first_results = fly_all(&first, config.seed, progress)?;
    let per_group = 2 * cells.len();
    // 3. Identify on each group's stock flights; fly it.
    let ids: Vec<(Vehicle, Vec<String>)> = groups
        .par_iter()
        .enumerate()
        .map(|(i, gr)| {
            let stock: Vec<&TrialResult> = (0..cells.len())
                .map(|c| &first_results[i * per_group + 2 * c + 1])
                .collect();
            identified(&stock, Vehicle::STOCK, gr.plant.spatial(), g)
        })
        .collect();
    let mut second = Vec::new();
    for (i, gr) in groups.iter().enumerate() {
        for c in &cells {
            second.push(flight(gr, c, true, ids[i].0, None));
        }
    }
    let second_results = fly_all(&second, config.seed, progress)?;
    // 4. Learn on each group's stock and identified records.
    let group_records = |i: usize, seconds: Option<f64>| {
        let mut rs: Vec<&TrialResult> = (0..cells.len())
            .map(|c| &first_results[i * per_group + 2 * c + 1])
            .collect();
        rs.extend((0..cells.len()).map(|c| &second_results[i * cells.len() + c]));
        records(&rs, g, seconds)
    };
    let models: Vec<GroupModels> = groups
        .par_iter()
        .enumerate()
        .map(|(i, gr)| {
            let runs = group_records(i, None);
            let spatial = gr.plant.spatial();
            let fixed = learned(&runs, &ids[i].0, spatial, g, Some(3));
            let chosen = learned(&runs, &ids[i].0, spatial, g, None);
            let refusals = [&fixed, &chosen]
                .iter()
                .filter_map(|r| r.as_ref().err().cloned())
                .collect();
            let mut unexcited: Vec<String> = Vec::new();
            for (label, r) in [("window 3", &fixed), ("window from data", &chosen)] {
                if let Ok((_, why, _)) = r {
                    unexcited.extend(why.iter().map(|w| format!("{label}: {w}")));
                }
            }
            let truth = |r: &Result<LearnedModel, String>| r.as_ref().ok().and_then(|m| m.2);
            let (learned_truth_m, learned_window_truth_m) = (truth(&fixed), truth(&chosen));
            let (fixed, chosen) = (fixed.map(|m| m.0), chosen.map(|m| m.0));
            GroupModels {
                plant: gr.plant.name(),
                vision_hz: gr.vision_hz,
                identified: ids[i].0,
                identify_changes: ids[i].1.clone(),
                learned: fixed.ok(),
                learned_window: chosen.ok(),
                learned_truth_m,
                learned_window_truth_m,
                refusals,
                unexcited,
            }
        })
        .collect();
    // 5. Fly both residuals (a refused one is not flown), and the exact
    // aerodynamics over the identified table without its linear drag.
    let mut third = Vec::new();
    let mut third_index = Vec::new();
    for (i, gr) in groups.iter().enumerate() {
        let bare = Vehicle {
            drag_h: 0.0,
            drag_rotor: 0.0,
            ..ids[i].0
        };
        let scaled = (config.exact_scale * drag.0, config.exact_scale * drag.1);
        let exact = exact_residual(&bare, gr.plant.spatial(), g, scaled);
        for c in &cells {
            for m in [&models[i].learned, &models[i].learned_window] {
                third_index.push(m.is_some().then_some(third.len()));
                if let Some(m) = m {
                    third.push(flight(gr, c, true, ids[i].0, Some(m.clone())));
                }
            }
            third_index.push(Some(third.len()));
            third.push(flight(gr, c, true, bare, Some(exact.clone())));
        }
    }
    let third_results = fly_all(&third, config.seed, progress)?;
    let mut rows = Vec::new();
    for (i, gr) in groups.iter().enumerate() {
        for (c, cell) in cells.iter().enumerate() {
            let f = flight(gr, cell, true, Vehicle::STOCK, None);
            let judge = |r: &TrialResult| f.judge(r);
            let learned_of = |k: usize| {
                third_index[(i * cells.len() + c) * 3 + k]
                    .map_or(Judged::NONE, |j| judge(&third_results[j]))
            };
            rows.push(LearnedRow {
                plant: gr.plant.name(),
                vision_hz: gr.vision_hz,
                shape: cell.0.name(),
                speed: cell.1,
                matched: judge(&first_results[i * per_group + 2 * c]),
                stock: judge(&first_results[i * per_group + 2 * c + 1]),
                identified: judge(&second_results[i * cells.len() + c]),
                learned: learned_of(0),
                learned_window: learned_of(1),
                exact: learned_of(2),
            });
        }
    }
    // 6. Seconds of records (the first group), window chosen from data.
    let mut seconds = Vec::new();
    if let Some(gr) = groups.first() {
        for &s in &config.seconds {
            let runs = group_records(0, Some(s));
            let m = match learned(&runs, &ids[0].0, gr.plant.spatial(), g, None) {
                Ok((m, _, _)) => m,
                Err(why) => {
                    // Nothing learned: the daemon keeps the identified model.
                    // (The first group's rows are the first cells.len().)
                    let ratios: Vec<f64> = (0..cells.len())
                        .map(|c| rows[c].identified.p95 / rows[c].matched.p95)
                        .collect();
                    seconds.push(SecondsRow {
                        seconds: s,
                        horizon_parametric_m: f64::NAN,
                        horizon_learned_m: f64::NAN,
                        worst_ratio: ratios.iter().copied().fold(0.0, f64::max),
                        mean_ratio: ratios.iter().sum::<f64>() / ratios.len().max(1) as f64,
                        refused: Some(why),
                    });
                    continue;
                }
            };
            let fl: Vec<Flight> = cells
                .iter()
                .map(|c| flight(gr, c, true, ids[0].0, Some(m.clone())))
                .collect();
            let res = fly_all(&fl, config.seed, progress)?;
            let ratios: Vec<f64> = res
                .iter()
                .zip(&fl)
                .enumerate()
                .map(|(c, (r, f))| f.judge(r).p95 / rows[c].matched.p95)
                .collect();
            seconds.push(SecondsRow {
                seconds: s,
                horizon_parametric_m: m.validation.horizon_parametric_m,
                horizon_learned_m: m.validation.horizon_learned_m,
                worst_ratio: ratios.iter().copied().fold(0.0, f64::max),
                mean_ratio: ratios.iter().sum::<f64>() / ratios.len().max(1) as f64,
                refused: None,
            });
        }
    }
    Ok(LearnedResult {
        config: config.clone(),
        models,
        rows,
        seconds,
    })
}

/// Writes the study's JSON to `json`.
pub fn write_learned(
    result: &LearnedResult,
    json: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>, ExperimentError> {
    super::write_json(json, result)?;
    Ok(vec![json.to_path_buf()])
}

#[cfg(test)]
mod tests;
