//! The DF-MPC tick with the learned residual against without it, same
//! flight: percentiles over all ticks and over the constrained ones.
//!
//! A planar vehicle with aerodynamics the model has no term for (parasitic
//! drag 0.03 |v|v, rotor drag 0.2 /s in the body plane) flies the L path
//! (0, 0) → (20, 0) → (20, 20) m at 8 m/s under DF-MPC as the daemon ships
//! it — multi-rate windows (M = 25, each pose observed), smoothness 50 on
//! x and y, the plan's tilt box at 20° (so the start, the corner and the
//! stop bind it) and the tilt-rate bound 150°/s — at horizon N (200 by
//! default), with and without the residual (its weights the
//! aerodynamics'). Each configuration flies the path `REPEATS` times in
//! closed loop, every tick timed. The budget (issue 42): p99 ≤ 500 µs on
//! constrained ticks with the residual at N = 200.
//!
//! Each row also gives the constrained ticks' statistics with each tick at
//! its fastest of the flights (the flights take the same solves): the
//! code's cost with the host's interruptions left out.
//!
//! Run: `cargo bench -p dflat-control --bench learned` (horizons as
//! arguments, e.g. `-- 100 200`). `LEARNED_SLOW=450` prints the ticks
//! slower than 450 µs (flight, tick, time, constrained): the ticks behind
//! a p99.

#![allow(missing_docs)]

#[path = "common/mod.rs"]
mod common;
#[path = "common/l_with_drag.rs"]
mod l_with_drag;

use std::collections::BTreeMap;

use dflat_control::ControlModel;
use dflat_control::dfmpc::DfMpc;
use dflat_control::learned::{
    FORMAT, Feature, LearnedResidual, Support, VERSION, Validation, columns,
};

const TICKS: usize = 400;
const REPEATS: usize = 5;

use common::{DT, plant};

fn aero_residual() -> LearnedResidual {
    let features = vec![Feature::Bias, Feature::Quadratic, Feature::RotorPlane];
    let m = columns(&features);
    LearnedResidual {
        format: FORMAT.into(),
        version: VERSION,
        vehicle_model: "planar".into(),
        vehicle: BTreeMap::new(),
        dt: DT,
        window: 25,
        features,
        lambda: 1e-6,
        weights: std::array::from_fn(|axis| {
            let mut row = vec![0.0; m];
            row[1 + axis] = -0.03;
            row[4 + axis] = -0.2;
            row
        }),
        support: Support {
            speed_max: 12.0,
            tilt_max: 0.8,
            thrust_min: 9.0,
            thrust_max: 14.0,
        },
        validation: Validation::unmeasured(0.5),
        seconds: 0.0,
    }
}

/// One closed-loop flight of the L ([`l_with_drag::fly`]): every tick's
/// update time \[µs\], whether it solved a constrained QP, and the axes'
/// solves (method, iterations, warm-started; `LEARNED_SLOW` prints them).
fn fly(n: usize, learned: bool) -> Vec<(f64, bool, String)> {
    let p = plant();
    let mut mpc = DfMpc::new(ControlModel::Planar(p), l_with_drag::settings(n)).unwrap();
    mpc.set_learned(learned.then(aero_residual));
    let mut out = Vec::with_capacity(TICKS);
    l_with_drag::fly(&p, &mut mpc, TICKS, |_, mpc, r, us| {
        let Ok(o) = r else {
            return;
        };
        let solves: Vec<String> = (0..2)
            .filter_map(|axis| mpc.box_cascade(axis).and_then(|c| c.solved_by()))
            .map(|(s, i)| {
                format!(
                    "#{s} {:?} {} {}",
                    i.method,
                    i.iterations,
                    if i.warm_started { "warm" } else { "cold" }
                )
            })
            .collect();
        out.push((us, o.constrained, solves.join(", ")));
    });
    out
}

/// `LEARNED_SLOW` [µs]: ticks slower than it are printed.
fn slow_us() -> Option<f64> {
    std::env::var("LEARNED_SLOW")
        .ok()
        .and_then(|v| v.parse().ok())
}

fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let horizons: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let horizons = if horizons.is_empty() {
        vec![200]
    } else {
        horizons
    };
    println!("DF-MPC tick on the L at 8 m/s with aerodynamics, {REPEATS} flights per row");
    println!(
        "  N  residual   all: median    p99     max   constrained: n  median    p99     max  [µs]"
    );
    for n in horizons {
        for learned in [false, true] {
            let mut all = Vec::new();
            // Per tick: its fastest time over the flights, whether it was
            // constrained, and its solves (the same in every flight: the
            // flights are deterministic, their solves timed, not limited).
            let mut best: Vec<(f64, bool, String)> = Vec::new();
            let mut differing = 0;
            for flight in 0..REPEATS {
                let ticks = fly(n, learned);
                for (k, (t, c, w)) in ticks.iter().enumerate() {
                    match best.get_mut(k) {
                        Some(b) => {
                            b.0 = b.0.min(*t);
                            differing += usize::from(b.1 != *c || b.2 != *w);
                        }
                        None => best.push((*t, *c, w.clone())),
                    }
                }
                if let Some(slow) = slow_us() {
                    for (k, (t, c, w)) in
                        ticks.iter().enumerate().filter(|(_, (t, _, _))| *t > slow)
                    {
                        println!(
                            "slow: N {n}, residual {learned}, flight {flight}, tick {k}: {t:.0} µs, constrained {c}; {w}"
                        );
                    }
                }
                all.extend(ticks.into_iter().map(|(t, c, _)| (t, c)));
            }
            let times: Vec<f64> = all.iter().map(|(t, _)| *t).collect();
            let constrained: Vec<f64> = all.iter().filter(|(_, c)| *c).map(|(t, _)| *t).collect();
            println!(
                "{n:4}  {:8}   {:11.0} {:7.0} {:7.0}   {:13} {:7.0} {:7.0} {:7.0}",
                if learned { "learned" } else { "none" },
                percentile(times.clone(), 0.5),
                percentile(times.clone(), 0.99),
                percentile(times, 1.0),
                constrained.len(),
                percentile(constrained.clone(), 0.5),
                percentile(constrained.clone(), 0.99),
                percentile(constrained, 1.0),
            );
            let fastest: Vec<f64> = best.iter().filter(|b| b.1).map(|b| b.0).collect();
            println!(
                "      constrained ticks, each at its fastest of the {REPEATS} flights (the same \
                 solves; the host's interruptions left out): n {}, median {:.0}, p99 {:.0}, \
                 max {:.0}{}",
                fastest.len(),
                percentile(fastest.clone(), 0.5),
                percentile(fastest.clone(), 0.99),
                percentile(fastest, 1.0),
                if differing > 0 {
                    format!(" ({differing} ticks solved differently in some flight)")
                } else {
                    String::new()
                },
            );
        }
    }
}
