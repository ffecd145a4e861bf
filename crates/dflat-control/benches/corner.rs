//! Percentiles of the DF-MPC tick over a recorded corner manoeuvre: the
//! tilt cone's constrained tick against clarabel solving the same cone
//! problem and against the unconstrained fast tick, same run.
//!
//! A planar vehicle (ψ = 0) flies the L path (0, 0) → (20, 0) → (20, 20) m
//! at 8 m/s under DF-MPC with a 20° tilt cone in the plan (the start, the
//! corner and the stop bind it); its measurements are recorded once. Each
//! configuration then replays the recording tick by tick (its own
//! commands enter its window), every tick timed; `REPEATS` replays per
//! configuration. Reported per horizon N: median, p99 and max over all
//! timed ticks, over the ticks that solved a constrained QP, the ratios
//! the budgets are stated in (`docs/performance.md`), and the cascades'
//! work (Newton steps, factorisations, fallbacks).
//!
//! The tilt-rate bound (`max_tilt_rate`, [`RATE_DEG_S`]) is timed with the
//! box (the daemon's set-up: box + tilt rate), alone, with the cone, and
//! with clarabel solving the same box + tilt-rate, tilt-rate-alone and
//! cone + tilt-rate QPs; with the box its banded rows run the box's cascade (the
//! augmented Lagrangian with its active-set polish, then the interior
//! point), with the cone the cone's (the augmented Lagrangian, then the
//! interior point, both with the rate rows).
//!
//! Each banded configuration runs DF-MPC's cascade (`optimise/cascade.rs`);
//! the work line per configuration gives what its augmented Lagrangian did
//! (Newton steps, factorisations), how many solves fell to the interior
//! point or clarabel, and the times of the first ticks of constrained
//! bursts. `CORNER_ONLY="box, ALM|cone, ALM, warm"` limits the configurations
//! to those whose names contain one of the `|`-separated parts.
//!
//! A second flight, the course of corners (five 60 m legs), has each
//! corner bind in a burst of its own: its table gives, per horizon, the
//! first ticks of the bursts (each a cold solve: the unconstrained plan
//! and, the last burst's having aged out, no multipliers), their Newton
//! steps, and the other constrained ticks, for the warm cone, the cone
//! with warm starts off, the box, and with the tilt-rate bound the box
//! (the shipped default), the rate alone and the cone.
//! `CORNER_ONLY` runs the course only when one of its parts is `course`.
//! A third flight, the L started from rest as the daemon starts a path
//! (its speed ramped up, `Reference::with_ramp`, at the daemon's default
//! `mission.start_acceleration`), gives the same table as the course:
//! what the tick from rest is in the daemon's own start, where the
//! corner's first tick meets a reference already at 8 m/s. `CORNER_ONLY`
//! runs it when one of its parts is `ramp`.
//!
//! With the feature `osqp-bench` (off by default: the `osqp` crate builds
//! OSQP's C through cmake), a table per horizon gives OSQP on the same
//! linear QPs as clarabel's (the box, with and without the tilt rate, and
//! the tilt rate alone), warm-started, beside our solver of the same ticks:
//! its times, iterations, the share of solves it did not finish
//! (`Solved`) and its plan's distance from ours (module `anchor` below;
//! `docs/performance.md`, "OSQP beside clarabel"). The row "box,
//! clarabel" is clarabel alone on the box (no tilt rate).
//!
//! `CORNER_SLOW=500` prints every tick slower than 500 µs (its index in
//! the flight and its time): the ticks behind a p99.
//!
//! `CORNER_FLIGHT=own` replays, per configuration, the flight that
//! configuration flies itself (its closed loop on the model plant)
//! instead of the warm cone's: the rate-limited configurations then meet
//! only states their own commands lead to.
//!
//! Run: `cargo bench -p dflat-control --bench corner` (a horizon list as
//! argument, e.g. `-- 200`, limits the run); with OSQP: `eval "$(bash
//! crates/dflat-control/benches/osqp-qdldl.sh)"` (offline, OSQP's cmake
//! cannot fetch its QDLDL: the script points it at PyPI's copy), then
//! `cargo bench -p dflat-control --features osqp-bench --bench corner`.

#![allow(missing_docs)]

#[path = "common/mod.rs"]
mod common;

use std::time::Instant;

use dflat_control::dfmpc::{DfMpc, DfMpcSettings, OutputConstraints, PlanTiltBound, QpSolver};
use dflat_control::optimise::{SolveInfo, SolverMethod};
use dflat_control::reference::Reference;
use dflat_control::{ControlModel, Controller, Measurement};
use nalgebra::Vector3;

use common::plant;

const TICKS: usize = 400;
const SPEED: f64 = 8.0;
const TILT_DEG: f64 = 20.0;
/// The tilt-rate bound of the tilt-rate configurations \[deg/s\] (the
/// daemon's default).
const RATE_DEG_S: f64 = 150.0;

/// The flown course: the L of the corner (from rest with the reference
/// already at speed, or ramped up as the daemon starts a path), or the
/// course of corners (five 60 m legs, [`COURSE_TICKS`]), whose corners
/// the horizon meets one at a time, so that each binds in a burst of its
/// own.
#[derive(Clone, Copy, PartialEq)]
enum Course {
    Corner,
    Corners,
    /// The L of the corner started as the daemon starts a path from rest:
    /// its speed ramped up with a peak acceleration of
    /// [`START_ACCELERATION`] (`Reference::with_ramp`).
    RampedCorner,
}

/// The daemon's default start ramp's peak acceleration \[m/s²\]
/// (`mission.start_acceleration`), below this bench's 20° bound
/// (g·tan 20° = 3.57 m/s²).
const START_ACCELERATION: f64 = 3.0;

/// Ticks of the course of corners (40 s: 300 m at 8 m/s and the stop).
const COURSE_TICKS: usize = 2000;

impl Course {
    fn reference(self) -> Reference {
        let corners: &[[f64; 2]] = match self {
            Self::Corner | Self::RampedCorner => &[[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]],
            Self::Corners => &[
                [0.0, 0.0],
                [60.0, 0.0],
                [60.0, 60.0],
                [120.0, 60.0],
                [120.0, 120.0],
                [180.0, 120.0],
            ],
        };
        let w: Vec<Vector3<f64>> = corners
            .iter()
            .map(|[x, y]| Vector3::new(*x, *y, -2.0))
            .collect();
        let path = Reference::path(&w, SPEED).unwrap();
        match self {
            Self::RampedCorner => path.with_ramp(0.0, START_ACCELERATION).unwrap(),
            _ => path,
        }
    }

    fn ticks(self) -> usize {
        match self {
            Self::Corner | Self::RampedCorner => TICKS,
            Self::Corners => COURSE_TICKS,
        }
    }
}

#[derive(Clone, Copy)]
enum Config {
    Fast,
    ConeWarm,
    ConeCold,
    ConeClarabel,
    BoxBanded,
    BoxRate,
    RateAlone,
    BoxRateClarabel,
    RateAloneClarabel,
    BoxClarabel,
    ConeRate,
    ConeRateClarabel,
}

impl Config {
    const ALL: [Self; 12] = [
        Self::Fast,
        Self::ConeWarm,
        Self::ConeCold,
        Self::ConeClarabel,
        Self::BoxBanded,
        Self::BoxRate,
        Self::RateAlone,
        Self::BoxRateClarabel,
        Self::RateAloneClarabel,
        Self::BoxClarabel,
        Self::ConeRate,
        Self::ConeRateClarabel,
    ];
    fn name(self) -> &'static str {
        match self {
            Self::Fast => "fast (no bound)",
            Self::ConeWarm => "cone, ALM, warm",
            Self::ConeCold => "cone, ALM, cold (warm starts off)",
            Self::ConeClarabel => "cone, clarabel SOCP",
            Self::BoxBanded => "box, ALM, warm",
            Self::BoxRate => "box + tilt rate, ALM",
            Self::RateAlone => "tilt rate alone, ALM",
            Self::BoxRateClarabel => "box + tilt rate, clarabel",
            Self::RateAloneClarabel => "tilt rate alone, clarabel",
            Self::BoxClarabel => "box, clarabel",
            Self::ConeRate => "cone + tilt rate, ALM",
            Self::ConeRateClarabel => "cone + tilt rate, clarabel",
        }
    }
    fn settings(self, n: usize) -> DfMpcSettings {
        let constraints = OutputConstraints {
            max_tilt: Some(TILT_DEG.to_radians()),
            ..Default::default()
        };
        let rate = Some(RATE_DEG_S.to_radians());
        DfMpcSettings {
            horizon: n,
            constraints: match self {
                Self::Fast => OutputConstraints::default(),
                Self::BoxRate | Self::BoxRateClarabel | Self::ConeRate | Self::ConeRateClarabel => {
                    OutputConstraints {
                        max_tilt_rate: rate,
                        ..constraints
                    }
                }
                Self::RateAlone | Self::RateAloneClarabel => OutputConstraints {
                    max_tilt_rate: rate,
                    ..Default::default()
                },
                _ => constraints,
            },
            qp_solver: match self {
                Self::ConeClarabel
                | Self::BoxRateClarabel
                | Self::RateAloneClarabel
                | Self::BoxClarabel
                | Self::ConeRateClarabel => QpSolver::Clarabel,
                _ => QpSolver::Banded,
            },
            plan_tilt_bound: match self {
                Self::BoxBanded
                | Self::BoxRate
                | Self::RateAlone
                | Self::BoxRateClarabel
                | Self::RateAloneClarabel
                | Self::BoxClarabel => PlanTiltBound::Box,
                _ => PlanTiltBound::Cone,
            },
            warm_start: !matches!(self, Self::ConeCold),
            solver_time_limit: f64::INFINITY,
            ..Default::default()
        }
    }
}

/// The measurements of one closed-loop flight of the course with the warm
/// cone.
fn record(n: usize, course: Course) -> Vec<Measurement> {
    record_with(Config::ConeWarm, n, course)
}

/// The measurements of one closed-loop flight of the course under
/// `config`.
fn record_with(config: Config, n: usize, course: Course) -> Vec<Measurement> {
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant()), config.settings(n)).unwrap();
    common::record(&mut ctrl, &mut course.reference(), course.ticks())
}

/// What the cascades' first solver (the augmented Lagrangian) did on the
/// constrained ticks of a replay, and the times of the first ticks of
/// constrained bursts.
#[derive(Default)]
struct ConeWork {
    /// Newton steps per solve it converged on.
    iterations: Vec<f64>,
    /// Factorisations per solve it converged on.
    factorisations: Vec<f64>,
    /// Solves it did not converge on: an interior point solved.
    interior_point: usize,
    /// Solves clarabel finished (after the banded solvers).
    clarabel: usize,
    /// Cascade solves in all, and those a relaxation's optimum gave (the
    /// cone with the tilt rate solved without its rows first).
    solves: usize,
    relaxed: usize,
    /// Per solve whose interior point restarted from its warm attempt:
    /// the attempt's Newton steps, the interior point's iterations, the
    /// Newton steps after it.
    restarts: Vec<[f64; 3]>,
    /// Times of the first constrained tick after an unconstrained one \[s\].
    burst_starts: Vec<f64>,
    /// The tick (of the flight) each burst began at.
    burst_ticks: Vec<usize>,
    /// Times of the other constrained ticks \[s\].
    burst_rest: Vec<f64>,
    /// Newton steps of the first ticks' augmented Lagrangians (all axes).
    burst_steps: Vec<f64>,
    /// Ticks whose update failed (every solver of the cascade; the
    /// daemon's plan fallback flies them), and the first one's error.
    failed: usize,
    first_failure: Option<String>,
    /// Per tick of the flight that was constrained, its fastest time over
    /// the replays \[s\] (the replays take the same solver path: what is
    /// left is the code's cost without the host's interruptions).
    best: std::collections::BTreeMap<usize, f64>,
    /// Per constrained tick of the flight, its solvers' Newton steps (or
    /// KKT solves) in the first replay, and how many ticks of the later
    /// replays took others (0: every replay took the same solves).
    steps: std::collections::BTreeMap<usize, f64>,
    differing: usize,
}

impl ConeWork {
    /// Notes what a cascade did on its last tick, if it ran (its
    /// solver's place and what it did).
    fn note(&mut self, solved_by: Option<(usize, SolveInfo)>) {
        let Some((place, info)) = solved_by else {
            return;
        };
        self.solves += 1;
        self.relaxed += usize::from(info.relaxed);
        if let Some(r) = info.restart {
            self.restarts.push([
                r.attempt_steps as f64,
                r.interior_iterations as f64,
                r.steps_after as f64,
            ]);
        }
        match info.method {
            SolverMethod::Alm | SolverMethod::ActiveSet => {
                self.iterations.push(info.iterations as f64);
                self.factorisations.push(info.factorisations as f64);
            }
            SolverMethod::InteriorPoint => self.interior_point += 1,
            SolverMethod::Clarabel => self.clarabel += usize::from(place > 0),
        }
    }
}

/// Tick times \[s\] of `repeats` replays, which ticks were constrained,
/// and the cascades' work on them.
fn replay(
    config: Config,
    n: usize,
    (course, flight): (Course, &[Measurement]),
    repeats: usize,
) -> (Vec<f64>, Vec<f64>, ConeWork) {
    let (mut all, mut constrained) = (Vec::new(), Vec::new());
    let mut work = ConeWork::default();
    let slow = slow_us();
    for _ in 0..repeats {
        let mut ctrl = DfMpc::new(ControlModel::Planar(plant()), config.settings(n)).unwrap();
        let mut reference = course.reference();
        let mut was_constrained = false;
        for m in flight {
            let start = Instant::now();
            let out = std::hint::black_box(ctrl.update(std::hint::black_box(m), &mut reference));
            let t = start.elapsed().as_secs_f64();
            if let Some(slow) = slow
                && t * 1e6 > slow
            {
                // What each axis's box cascade did (its solver's place and
                // method, Newton steps plus KKT solves).
                let axes: Vec<String> = (0..2)
                    .filter_map(|a| ctrl.box_cascade(a).and_then(|c| c.solved_by()))
                    .map(|(place, i)| format!("{:?}@{place} {}", i.method, i.iterations))
                    .collect();
                eprintln!(
                    "slow tick {} of {}: {:.0} µs {}",
                    all.len() % flight.len(),
                    config.name(),
                    t * 1e6,
                    axes.join(", ")
                );
            }
            all.push(t);
            let out = match out {
                Ok(out) => out,
                Err(e) => {
                    work.failed += 1;
                    work.first_failure.get_or_insert_with(|| e.to_string());
                    was_constrained = false;
                    continue;
                }
            };
            if out.constrained {
                constrained.push(t);
                let tick = (all.len() - 1) % flight.len();
                let best = work.best.entry(tick).or_insert(t);
                *best = best.min(t);
                if was_constrained {
                    work.burst_rest.push(t);
                } else {
                    work.burst_starts.push(t);
                    work.burst_ticks.push((all.len() - 1) % flight.len());
                }
                let before = work.iterations.len();
                work.note(ctrl.cone_cascade().and_then(|c| c.solved_by()));
                for axis in 0..2 {
                    work.note(ctrl.box_cascade(axis).and_then(|c| c.solved_by()));
                }
                let steps: f64 = work.iterations[before..].iter().sum();
                if !was_constrained {
                    work.burst_steps.push(steps);
                }
                let first = *work.steps.entry(tick).or_insert(steps);
                work.differing += usize::from(first != steps);
            }
            was_constrained = out.constrained;
        }
    }
    (all, constrained, work)
}

/// `CORNER_SLOW` [µs]: ticks slower than it are printed (their index and
/// time), to find the ticks behind a p99.
fn slow_us() -> Option<f64> {
    std::env::var("CORNER_SLOW")
        .ok()
        .and_then(|v| v.parse().ok())
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let i = ((p / 100.0) * (v.len() - 1) as f64).round() as usize;
    v[i]
}

fn us(v: f64) -> String {
    format!("{:.1}", v * 1e6)
}

fn main() {
    let horizons: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let horizons = if horizons.is_empty() {
        vec![50, 100, 200, 400, 800]
    } else {
        horizons
    };
    println!(
        "corner manoeuvre: L path at {SPEED} m/s, {TILT_DEG}° cone, {TICKS} ticks; times in µs"
    );
    let only: Option<Vec<String>> = std::env::var("CORNER_ONLY")
        .ok()
        .map(|v| v.split('|').map(String::from).collect());
    let chosen = |config: Config| {
        only.as_ref()
            .is_none_or(|o| o.iter().any(|o| config.name().contains(o.as_str())))
    };
    for &n in &horizons {
        corner_table(n, &chosen);
    }
    // The course runs unfiltered, or when the filter names it
    // (`CORNER_ONLY="course|cone, ALM, warm"`).
    if only
        .as_ref()
        .is_none_or(|o| o.iter().any(|o| o == "course"))
    {
        course_of_corners(&horizons, &chosen, Course::Corners);
    }
    // So does the L started as the daemon starts a path (`ramp`).
    if only.as_ref().is_none_or(|o| o.iter().any(|o| o == "ramp")) {
        course_of_corners(&horizons, &chosen, Course::RampedCorner);
    }
}

/// The corner's table at horizon `n` for the configurations `chosen`,
/// the work lines, the ratios (all configurations run) and, with the
/// feature, OSQP's table.
fn corner_table(n: usize, chosen: &dyn Fn(Config) -> bool) {
    let flight = record(n, Course::Corner);
    // `CORNER_FLIGHT=own`: each configuration replays the flight it flies
    // itself (its closed loop on the model plant) instead of the warm
    // cone's.
    let own = std::env::var("CORNER_FLIGHT").is_ok_and(|v| v == "own");
    if own {
        println!("(each configuration replays its own flight: CORNER_FLIGHT=own)");
    }
    let repeats = if n >= 800 { 2 } else { 5 };
    println!("\nN = {n} ({repeats} replays)");
    println!(
        "| configuration | all: median | p99 | max | constrained ticks | constrained: median | p99 | max |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut stats = Vec::new();
    let mut lines = Vec::new();
    for config in Config::ALL {
        if !chosen(config) {
            continue;
        }
        let own_flight;
        let flight = if own {
            own_flight = record_with(config, n, Course::Corner);
            &own_flight
        } else {
            &flight
        };
        let (mut all, mut con, work) = replay(config, n, (Course::Corner, flight), repeats);
        lines.extend(work_lines(config, &work, all.len(), repeats));
        let s = [
            percentile(&mut all, 50.0),
            percentile(&mut all, 99.0),
            percentile(&mut all, 100.0),
            percentile(&mut con, 50.0),
            percentile(&mut con, 99.0),
            percentile(&mut con, 100.0),
        ];
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            config.name(),
            us(s[0]),
            us(s[1]),
            us(s[2]),
            con.len() / repeats,
            us(s[3]),
            us(s[4]),
            us(s[5])
        );
        stats.push(s);
    }
    #[cfg(feature = "osqp-bench")]
    anchor::table(n, &flight, repeats, chosen);
    if stats.len() == Config::ALL.len() {
        print_ratios(&stats);
    }
    lines.iter().for_each(|l| println!("{l}"));
}

/// The restarts' counts for the work line (none: empty): how many,
/// and the median (max) of the warm attempt's Newton steps, the interior
/// point's iterations and the Newton steps after it.
fn restart_counts(work: &ConeWork) -> String {
    if work.restarts.is_empty() {
        return String::new();
    }
    let column = |i: usize| {
        let mut v: Vec<f64> = work.restarts.iter().map(|r| r[i]).collect();
        (percentile(&mut v, 50.0), percentile(&mut v, 100.0))
    };
    let [(a, a_max), (ip, ip_max), (after, after_max)] = [0, 1, 2].map(column);
    format!(
        "; the interior point restarted from the warm attempt on {}: the attempt's Newton \
         steps median {a} (max {a_max}), the interior point's iterations {ip} ({ip_max}), \
         Newton steps after it {after} ({after_max})",
        work.restarts.len()
    )
}

/// A configuration's work line (its augmented Lagrangian's or active
/// set's work, the fallbacks, the bursts' first ticks) and its first
/// failure, if any.
fn work_lines(config: Config, work: &ConeWork, ticks: usize, repeats: usize) -> Vec<String> {
    let mut lines = Vec::new();
    if let Some(e) = &work.first_failure {
        lines.push(format!(
            "{}: {} of {ticks} ticks failed (the first: {e})",
            config.name(),
            work.failed,
        ));
    }
    if matches!(
        config,
        Config::Fast
            | Config::ConeClarabel
            | Config::BoxRateClarabel
            | Config::RateAloneClarabel
            | Config::BoxClarabel
            | Config::ConeRateClarabel
    ) {
        return lines;
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let (mut iterations, mut starts) = (work.iterations.clone(), work.burst_starts.clone());
    let relaxed = if work.relaxed > 0 {
        format!(
            " (the relaxation without the tilt-rate rows held on {})",
            work.relaxed
        )
    } else {
        String::new()
    };
    let restarts = restart_counts(work);
    lines.push(format!(
        "{}: per solve: Newton steps (the active set's: KKT solves) mean {:.2}, p99 {}, max {}; \
         factorisations mean {:.2}; interior point solved {} and clarabel {} \
         of {} solves{relaxed}{restarts}; first ticks of {} bursts: median {} µs, max {} µs",
        config.name(),
        mean(&iterations),
        percentile(&mut iterations, 99.0),
        percentile(&mut iterations, 100.0),
        mean(&work.factorisations),
        work.interior_point,
        work.clarabel,
        work.solves,
        starts.len() / repeats,
        us(percentile(&mut starts, 50.0)),
        us(percentile(&mut starts, 100.0)),
    ));
    if repeats > 1 {
        let mut best: Vec<f64> = work.best.values().copied().collect();
        lines.push(format!(
            "{}: constrained ticks, each at its fastest of the {repeats} replays (the same \
             solves; the host's interruptions left out): median {} µs, p99 {} µs, max {} µs{}",
            config.name(),
            us(percentile(&mut best, 50.0)),
            us(percentile(&mut best, 99.0)),
            us(percentile(&mut best, 100.0)),
            if work.differing > 0 {
                format!(
                    " ({} ticks of later replays took other Newton steps)",
                    work.differing
                )
            } else {
                String::new()
            },
        ));
    }
    lines
}

/// The ratios the budgets are stated in (every configuration ran, in
/// [`Config::ALL`]'s order).
fn print_ratios(stats: &[[f64; 6]]) {
    let of = |c: Config| {
        stats[Config::ALL
            .iter()
            .position(|&a| a as usize == c as usize)
            .unwrap()]
    };
    let (fast, warm, clarabel) = (
        of(Config::Fast),
        of(Config::ConeWarm),
        of(Config::ConeClarabel),
    );
    println!(
        "ratios (constrained ticks): clarabel / warm cone: median {:.1}×, p99 {:.1}×; \
         warm cone / fast tick median: median {:.1}×, p99 {:.1}×",
        clarabel[3] / warm[3],
        clarabel[4] / warm[4],
        warm[3] / fast[0],
        warm[4] / fast[0],
    );
    for (name, banded, by_clarabel) in [
        ("box + rate", Config::BoxRate, Config::BoxRateClarabel),
        ("rate alone", Config::RateAlone, Config::RateAloneClarabel),
    ] {
        let (rate, rate_clarabel) = (of(banded), of(by_clarabel));
        println!(
            "tilt rate (constrained ticks): {name} banded median {} µs, p99 {} µs; \
             clarabel / banded: median {:.1}×, p99 {:.1}×; banded / fast tick median: {:.1}×",
            us(rate[3]),
            us(rate[4]),
            rate_clarabel[3] / rate[3],
            rate_clarabel[4] / rate[4],
            rate[3] / fast[0],
        );
    }
    let (cone_rate, cone_rate_clarabel) = (of(Config::ConeRate), of(Config::ConeRateClarabel));
    println!(
        "cone + tilt rate (constrained ticks): banded median {} µs, p99 {} µs; \
         clarabel / banded: median {:.1}×, p99 {:.1}×",
        us(cone_rate[3]),
        us(cone_rate[4]),
        cone_rate_clarabel[3] / cone_rate[3],
        cone_rate_clarabel[4] / cone_rate[4],
    );
}

/// The course of corners (`course`: [`Course::Corners`]): each corner
/// binds in a burst of its own, whose first tick starts from the plan
/// given (the multipliers aged over the unconstrained ticks before it) —
/// the cold solves of a flight, which the corner's single burst shows
/// only once. With [`Course::RampedCorner`], the same table for the L
/// started from rest as the daemon starts a path, whose first tick does
/// not see the whole horizon saturated as the corner's does. Reported
/// per horizon and configuration: the bursts per flight, their first
/// ticks and the other constrained ticks (median / p99 / max µs).
fn course_of_corners(horizons: &[usize], chosen: &dyn Fn(Config) -> bool, course: Course) {
    const REPEATS: usize = 3;
    let configs = [
        Config::ConeWarm,
        Config::ConeCold,
        Config::BoxBanded,
        Config::BoxRate,
        Config::RateAlone,
        Config::ConeRate,
    ];
    if !configs.iter().any(|&c| chosen(c)) {
        return;
    }
    match course {
        Course::RampedCorner => println!(
            "\nthe L from rest as the daemon starts a path: speed ramped up at \
             {START_ACCELERATION} m/s² peak, {SPEED} m/s, {TILT_DEG}° cone, {TICKS} ticks, \
             {REPEATS} replays; constrained ticks, µs"
        ),
        _ => println!(
            "\ncourse of corners: five 60 m legs at {SPEED} m/s, {TILT_DEG}° cone, \
             {COURSE_TICKS} ticks, {REPEATS} replays; constrained ticks, µs"
        ),
    }
    println!(
        "| N | configuration | bursts per flight | the first begins at tick | first ticks: median | p99 | max | \
         their Newton steps: median | max | other constrained ticks: median | p99 | max |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for &n in horizons {
        let flight = record(n, course);
        for config in configs.into_iter().filter(|&c| chosen(c)) {
            let (_, _, mut work) = replay(config, n, (course, &flight), REPEATS);
            let bursts = work.burst_starts.len() / REPEATS;
            let (first, rest) = (&mut work.burst_starts, &mut work.burst_rest);
            let steps = &mut work.burst_steps;
            let first_at = work
                .burst_ticks
                .first()
                .map_or("–".to_string(), |k| k.to_string());
            println!(
                "| {n} | {} | {bursts} | {first_at} | {} | {} | {} | {} | {} | {} | {} | {} |",
                config.name(),
                us(percentile(first, 50.0)),
                us(percentile(first, 99.0)),
                us(percentile(first, 100.0)),
                percentile(steps, 50.0),
                percentile(steps, 100.0),
                us(percentile(rest, 50.0)),
                us(percentile(rest, 99.0)),
                us(percentile(rest, 100.0)),
            );
            if let Some(e) = &work.first_failure {
                println!(
                    "({}: {} ticks failed, the first: {e})",
                    config.name(),
                    work.failed
                );
            }
        }
    }
}

/// OSQP on the same QPs beside ours (feature `osqp-bench`; module docs
/// in `corner/anchor.rs`).
#[cfg(feature = "osqp-bench")]
#[path = "corner/anchor.rs"]
mod anchor;
