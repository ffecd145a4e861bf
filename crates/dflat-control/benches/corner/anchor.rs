//! OSQP on the same QPs (feature `osqp-bench`): the box's per-axis QP
//! (stage intervals and tilt-rate rows; either may be absent), as
//! clarabel is given it, solved by OSQP warm-started (module docs of
//! `dflat_control::optimise::osqp_anchor`). OSQP is inserted first in the
//! cascade of each bounded axis of our solver's replay and returns its
//! plan to no one: it is timed on the problem the cascade is handed, the
//! cascade then solves as without it (its commands fly the replay), and
//! OSQP's plan is compared with the one the cascade accepted.
//! `OSQP_EPS` (eps_abs = eps_rel, default [`EPS`]), `OSQP_WARM`
//! (`shifted`, the default; `previous`; `cold`) and `OSQP_MAX_ITER`
//! (default 4000, OSQP's) change its settings.

use std::sync::{Arc, Mutex};
use std::time::Instant;

use dflat_control::optimise::osqp_anchor::{OsqpBoxSolver, OsqpOutcome, OsqpTuning, OsqpWarm};
use dflat_control::optimise::{AxisProblem, AxisSolver, Carry, SolveFailure};

use super::common::DT;
use super::*;

/// eps_abs = eps_rel: the loosest power of ten at which OSQP's plan
/// matches ours within the accuracy proptests' tolerances against
/// clarabel (the first ten outputs 1e-5 m, the first jerk 1e-3
/// relative) with margin on the corner's ticks at N = 200: 1e-6 gave
/// 1.6e-6 m and 1e-4; 1e-5 gave 1.3e-6 m but 1.0e-3 on the jerk, 1e-4
/// 1.1e-5 m (`docs/performance.md`).
pub const EPS: f64 = 1e-6;
/// The accuracy proptests' tolerance on the first ten outputs \[m\].
const NEAR_TOL: f64 = 1e-5;

/// What OSQP did over a replay.
#[derive(Default)]
struct Log {
    /// OSQP's time on this tick so far (both axes) \[s\].
    tick: f64,
    /// Solves, those not `Solved`, the first such status.
    solves: usize,
    unsolved: usize,
    first_unsolved: Option<&'static str>,
    iterations: Vec<f64>,
    /// Solved and compared with the accepted plan: the largest
    /// |Δy_0..y_10| \[m\], first-jerk difference relative to
    /// max(|jerk|, 1), and how many were above [`NEAR_TOL`].
    compared: usize,
    max_near: f64,
    max_jerk_rel: f64,
    over_tol: usize,
}

struct Observer {
    osqp: OsqpBoxSolver,
    log: Arc<Mutex<Log>>,
    scratch: Vec<f64>,
    solved: bool,
}

impl std::fmt::Debug for Observer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("OSQP observer")
    }
}

impl AxisSolver for Observer {
    fn solve(&mut self, a: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure> {
        self.scratch.copy_from_slice(a.plan);
        let start = Instant::now();
        let r = self.osqp.solve_axis(AxisProblem {
            fixed: a.fixed,
            sent: a.sent,
            reference: a.reference,
            plan: &mut self.scratch,
        });
        let t = start.elapsed().as_secs_f64();
        let mut log = self.log.lock().unwrap();
        log.tick += t;
        log.solves += 1;
        log.iterations.push(f64::from(self.osqp.iterations()));
        self.solved = r.is_ok();
        if let OsqpOutcome::Not(status) = self.osqp.outcome() {
            log.unsolved += 1;
            log.first_unsolved.get_or_insert(status);
        }
        Err(SolveFailure::Observer)
    }

    fn carry(&mut self, event: Carry<'_>) {
        match event {
            Carry::Accepted { plans: [ours], .. } if self.solved => self.compare(ours),
            Carry::Accepted { .. } => {}
            Carry::Skipped | Carry::Reset => self.osqp.forget(),
        }
    }

    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }

    fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.osqp.set_offset(offset, slope);
    }
}

impl Observer {
    /// OSQP's plan against the accepted one (the log's accuracy).
    fn compare(&self, ours: &[f64]) {
        let osqp = &self.scratch;
        let near = ours
            .iter()
            .zip(osqp)
            .take(11)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        let jerk = |p: &[f64]| (p[3] - 3.0 * p[2] + 3.0 * p[1] - p[0]) / DT.powi(3);
        let jerk_rel = (jerk(ours) - jerk(osqp)).abs() / jerk(ours).abs().max(1.0);
        let mut log = self.log.lock().unwrap();
        log.compared += 1;
        log.max_near = log.max_near.max(near);
        log.max_jerk_rel = log.max_jerk_rel.max(jerk_rel);
        log.over_tol += usize::from(near > NEAR_TOL);
    }
}

fn tuning() -> OsqpTuning {
    let eps = std::env::var("OSQP_EPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(EPS);
    let max_iter = std::env::var("OSQP_MAX_ITER")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4000);
    let warm = match std::env::var("OSQP_WARM").as_deref() {
        Ok("previous") => OsqpWarm::Previous,
        Ok("cold") => OsqpWarm::Cold,
        _ => OsqpWarm::Shifted,
    };
    OsqpTuning {
        eps,
        max_iter,
        warm,
    }
}

/// Our solver's replay of `config` with OSQP observing each bounded
/// axis: per constrained tick our time (the tick less OSQP's) and
/// OSQP's (both axes), and OSQP's log.
fn replay(
    config: Config,
    n: usize,
    flight: &[Measurement],
    repeats: usize,
    tuning: OsqpTuning,
) -> (Vec<f64>, Vec<f64>, Log) {
    let log = Arc::new(Mutex::new(Log::default()));
    let (mut ours, mut theirs) = (Vec::new(), Vec::new());
    let plant = plant();
    for _ in 0..repeats {
        let settings = config.settings(n);
        let mut ctrl = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
        for axis in 0..2 {
            let bounds = *ctrl.bounds(axis).unwrap();
            let smoothness = dflat_control::optimise::Smoothness {
                weight: settings.smoothness_weight[axis],
                kappa: plant.params().tau / DT,
                gravity: plant.params().g,
            };
            let weights = (
                settings.tracking_weight[axis],
                settings.jerk_weight[axis],
                DT,
            );
            let osqp = OsqpBoxSolver::new(n, weights, bounds, smoothness, tuning).unwrap();
            let observer = Observer {
                osqp,
                log: Arc::clone(&log),
                scratch: vec![0.0; n + 1],
                solved: false,
            };
            ctrl.box_cascade_mut(axis)
                .unwrap()
                .insert(0, Box::new(observer))
                .unwrap();
        }
        let mut reference = Course::Corner.reference();
        for m in flight {
            log.lock().unwrap().tick = 0.0;
            let start = Instant::now();
            let out = std::hint::black_box(ctrl.update(std::hint::black_box(m), &mut reference));
            let t = start.elapsed().as_secs_f64();
            let osqp = log.lock().unwrap().tick;
            if out.is_ok_and(|o| o.constrained) {
                ours.push(t - osqp);
                theirs.push(osqp);
            }
        }
    }
    let log = Arc::try_unwrap(log).ok().unwrap().into_inner().unwrap();
    (ours, theirs, log)
}

/// The OSQP table of horizon `n`: the configurations the daemon can
/// ship whose QPs are linear (the box, with and without the tilt rate,
/// and the tilt rate alone).
pub fn table(n: usize, flight: &[Measurement], repeats: usize, chosen: &dyn Fn(Config) -> bool) {
    let tuning = tuning();
    let configs = [Config::BoxBanded, Config::BoxRate, Config::RateAlone];
    if !configs.iter().any(|&c| chosen(c)) {
        return;
    }
    println!(
        "OSQP on the same QPs (eps_abs = eps_rel = {:e}, polishing off, warm start {:?}, \
         max_iter {}); constrained ticks, µs; OSQP's time is both axes' solves",
        tuning.eps, tuning.warm, tuning.max_iter
    );
    println!(
        "| configuration | constrained ticks | ours: median | p99 | OSQP: median | p99 | \
         OSQP / ours: median | p99 | OSQP iterations: median | p99 | not Solved | \
         max |Δy_0..10| m | over 1e-5 m | max first-jerk Δ (rel.) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for config in configs.into_iter().filter(|&c| chosen(c)) {
        let (mut ours, mut theirs, mut log) = replay(config, n, flight, repeats, tuning);
        let (om, op) = (percentile(&mut ours, 50.0), percentile(&mut ours, 99.0));
        let (tm, tp) = (percentile(&mut theirs, 50.0), percentile(&mut theirs, 99.0));
        let unsolved = match log.first_unsolved {
            Some(s) => format!(
                "{} of {} ({:.1} %; {s})",
                log.unsolved,
                log.solves,
                100.0 * log.unsolved as f64 / log.solves.max(1) as f64
            ),
            None => format!("0 of {}", log.solves),
        };
        println!(
            "| {} | {} | {} | {} | {} | {} | {:.1}× | {:.1}× | {} | {} | {unsolved} | {:.1e} | {} of {} | {:.1e} |",
            config
                .name()
                .replace(", ALM, warm", "")
                .replace(", ALM", ""),
            ours.len() / repeats,
            us(om),
            us(op),
            us(tm),
            us(tp),
            tm / om,
            tp / op,
            percentile(&mut log.iterations, 50.0),
            percentile(&mut log.iterations, 99.0),
            log.max_near,
            log.over_tol,
            log.compared,
            log.max_jerk_rel,
        );
    }
}
