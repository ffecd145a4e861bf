//! Goals as references, end to end on a synthetic clock: the daemon's own
//! control core (supervisor, references, DF-MPC, guard — `ControlCore::step`,
//! exactly what the control thread runs) against the lab's planar plant
//! (the SITL's plant, RK4 at 200 Hz, first-order attitude τ = 0.2 s),
//! poses at 50 Hz, the autopilot's heartbeat and attitude as events.
//! Deterministic and fast: no wall clock, no sockets.
//!
//! * Command steps after a 10 m setpoint from hover, a setpoint change
//!   mid-flight and a setpoint after a hand-back: ≤ 5°/tick, judged on the
//!   commands the core sent (and, across the hand-back, the command the
//!   autopilot applied before).
//! * The streamed 4 m/s circle of radius 6 m with p, v, a at 20 Hz, 10 Hz
//!   and 50 Hz: the horizontal error p95 ≤ 0.098 m and below the anchor
//!   (PD with velocity and acceleration feed-forward: the SITL's position loop, `dflat_sitl::position_control`)
//!   on the same stream and plant; position-only streams are printed.
//!
//! Run with `--nocapture` to see the figures:
//! `cargo test -p dflat-e2e --test goals_closed_loop -- --nocapture`.

#[path = "support/circle.rs"]
mod circle;

use dflat_control::AttitudeCommand;
use dflat_daemon::config::Config;
use dflat_daemon::control::{build_controller, thrust_mapping};
use dflat_daemon::tick::{ControlCore, Event, TickTime};
use dflat_link::{AutopilotFamily, AutopilotMode};
use dflat_sim::plant::{Plant, PlantKind, PlantOptions, PlantState, build_plant};
use dflat_sim::trajectory::Trajectory;
use dflat_sitl::position_control::{self, PositionGains, PositionTarget};
use nalgebra::Vector3;

const DT: f64 = 0.02;
const START: [f64; 3] = [0.0, 0.0, -10.0];
/// The budget of the issue: the largest command step per tick \[deg\].
const STEP_BUDGET_DEG: f64 = 5.0;
/// The budget of the issue: the streamed circle's horizontal error p95 \[m\].
const CIRCLE_BUDGET_M: f64 = 0.098;

fn mode(main: u8) -> AutopilotMode {
    AutopilotMode {
        family: AutopilotFamily::Px4,
        custom_mode: u32::from(main) << 16,
        armed: true,
    }
}
/// PX4 OFFBOARD (main mode 6) and POSCTL (3).
const OFFBOARD: u8 = 6;
const POSCTL: u8 = 3;

/// A scripted setpoint: at `t`, position, and optionally velocity and
/// acceleration, with the sender's time stamp.
#[derive(Clone, Copy)]
struct Goal {
    t: f64,
    position: [f64; 3],
    velocity: Option<[f64; 3]>,
    acceleration: Option<[f64; 3]>,
}

/// What a flight recorded per tick.
struct Tick {
    t: f64,
    /// The plant's true position at the tick.
    position: Vector3<f64>,
    /// The command the autopilot applied over the tick (pitch, roll) \[rad\].
    applied: (f64, f64),
    /// The core sent a command this tick.
    sent: bool,
}

/// Flies `seconds` of the core against the planar plant. `goals` are
/// delivered at their time (arrival 2 ms later, `time_boot_ms` on the
/// sender's clock 5 s ahead of ours); `pilot(t)` is `Some(velocity)`
/// while the pilot has the vehicle in POSCTL (flown by the anchor loop).
fn fly(
    cfg: &Config,
    seconds: f64,
    goals: &[Goal],
    pilot: &dyn Fn(f64) -> Option<[f64; 3]>,
) -> Vec<Tick> {
    let controller = build_controller(cfg).expect("controller");
    let mut core = ControlCore::new(cfg, controller, thrust_mapping(cfg));
    let options = PlantOptions::default();
    let mut plant: Box<dyn Plant> =
        build_plant(PlantKind::Planar, &options, 1).expect("planar plant");
    plant.reset(&PlantState::hover(Vector3::from(START), options.g));
    let mut next_goal = 0;
    let mut ticks = Vec::new();
    let mut clock = 0.0;
    let mut stopwatch = move || {
        clock += 1e-5;
        clock
    };
    let n = (seconds / DT).round() as u64;
    for k in 0..n {
        let t = k as f64 * DT;
        let pilot_velocity = pilot(t);
        let (roll, pitch, yaw) = plant.attitude();
        let mut events = vec![
            Event::Heartbeat {
                arrival: t - 0.004,
                mode: mode(if pilot_velocity.is_some() {
                    POSCTL
                } else {
                    OFFBOARD
                }),
            },
            Event::Attitude {
                arrival: t - 0.002,
                roll,
                pitch,
                yaw,
            },
            Event::Pose {
                arrival: t - 0.001,
                source_time: Some(100.0 + t),
                position: plant.position().into(),
                yaw: None,
                reset_counter: None,
            },
        ];
        while next_goal < goals.len() && goals[next_goal].t <= t - 0.002 {
            let g = goals[next_goal];
            events.push(Event::Setpoint {
                arrival: g.t + 0.002,
                position: g.position,
                yaw: None,
                yaw_rate: None,
                source_time: Some(5.0 + g.t),
                velocity: g.velocity,
                acceleration: g.acceleration,
            });
            next_goal += 1;
        }
        let time = TickTime {
            tick: k,
            t,
            scheduled: t,
            jitter_us: 0,
        };
        let out = core.step(&time, events, &mut stopwatch);
        let sent = out.command.map(|c| c.command);
        let applied = match pilot_velocity {
            // The autopilot's own position mode flies the pilot's stick.
            Some(v) => {
                let target = PositionTarget {
                    velocity: v,
                    ..PositionTarget::hold(plant.position().into())
                };
                let c = anchor_command(&target, plant.position(), plant.velocity(), yaw);
                (c.pitch, c.roll)
            }
            None => match sent {
                Some(c) => (c.pitch, c.roll),
                None => (pitch, roll),
            },
        };
        ticks.push(Tick {
            t,
            position: plant.position(),
            applied,
            sent: sent.is_some(),
        });
        plant.apply(&AttitudeCommand {
            pitch: applied.0,
            roll: applied.1,
            yaw: 0.0,
            thrust: options.g,
        });
        plant.advance(DT);
    }
    ticks
}

/// The largest step per tick \[deg\] of the applied command in `[from, to)`.
fn largest_step(ticks: &[Tick], from: f64, to: f64) -> f64 {
    ticks
        .windows(2)
        .filter(|w| w[1].t >= from && w[1].t < to)
        .map(|w| {
            let dp = w[1].applied.0 - w[0].applied.0;
            let dr = w[1].applied.1 - w[0].applied.1;
            dp.hypot(dr).to_degrees()
        })
        .fold(0.0, f64::max)
}

fn setpoint(t: f64, p: [f64; 3]) -> Goal {
    Goal {
        t,
        position: p,
        velocity: None,
        acceleration: None,
    }
}

fn p95(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * 0.95).round() as usize]
}

#[test]
fn setpoints_mid_flight_changes_and_hand_backs_do_not_jump_the_command() {
    let cfg = Config::default();
    let north = [10.0, 0.0, -10.0];
    // 1. A 10 m step from hover.
    let ticks = fly(&cfg, 12.0, &[setpoint(2.0, north)], &|_| None);
    assert!(ticks.iter().all(|t| t.sent), "the core streamed every tick");
    let step = largest_step(&ticks, 2.0, 12.0);
    let end = (ticks.last().unwrap().position - Vector3::from(north)).norm();
    eprintln!("10 m step from hover: largest command step {step:.2}°/tick, final error {end:.3} m");
    assert!(step <= STEP_BUDGET_DEG, "step {step:.2}°/tick");
    assert!(end < 0.05, "did not arrive: {end:.3} m");

    // 2. A setpoint change mid-flight (2 s into the first, at speed).
    let ne = [10.0, 10.0, -10.0];
    let ticks = fly(
        &cfg,
        18.0,
        &[setpoint(2.0, north), setpoint(4.0, ne)],
        &|_| None,
    );
    let step = largest_step(&ticks, 4.0, 18.0);
    let end = (ticks.last().unwrap().position - Vector3::from(ne)).norm();
    eprintln!(
        "setpoint change mid-flight: largest command step {step:.2}°/tick, final error {end:.3} m"
    );
    assert!(step <= STEP_BUDGET_DEG, "step {step:.2}°/tick");
    assert!(end < 0.05, "did not arrive: {end:.3} m");

    // 3. The pilot takes over (POSCTL, 3 m/s east) and hands back at 4 s;
    //    a setpoint arrives 1 s later, while the core still brakes.
    let ticks = fly(&cfg, 14.0, &[setpoint(5.0, north)], &|t| {
        (1.0..4.0).contains(&t).then_some([0.0, 3.0, 0.0])
    });
    let step = largest_step(&ticks, 4.0, 18.0);
    let end = (ticks.last().unwrap().position - Vector3::from(north)).norm();
    eprintln!(
        "setpoint after a hand-back: largest command step {step:.2}°/tick, final error {end:.3} m"
    );
    let (at_engage, after) = (
        largest_step(&ticks, 4.0, 5.0),
        largest_step(&ticks, 5.0, 18.0),
    );
    eprintln!(
        "  of which at the hand-back (4–5 s) {at_engage:.2}°/tick, after the setpoint (5–18 s) {after:.2}°/tick"
    );
    assert!(
        after <= STEP_BUDGET_DEG,
        "step {after:.2}°/tick after the setpoint"
    );
    assert!(step <= STEP_BUDGET_DEG, "step {step:.2}°/tick");
    assert!(end < 0.1, "did not arrive: {end:.3} m");
}

/// Which fields a stream sends.
#[derive(Clone, Copy, PartialEq)]
enum Fields {
    Pva,
    PositionOnly,
}

/// The circle streamed at `rate_hz` from t = 1 s: its samples as goals.
fn circle_stream(circle: &Trajectory, rate_hz: f64, seconds: f64, fields: Fields) -> Vec<Goal> {
    let t0 = 1.0;
    let n = ((seconds - t0) * rate_hz) as usize;
    (0..n)
        .map(|i| {
            let t = t0 + i as f64 / rate_hz;
            let p = circle.at(t - t0);
            Goal {
                t,
                position: p.position.into(),
                velocity: (fields == Fields::Pva).then(|| p.velocity.into()),
                acceleration: (fields == Fields::Pva).then(|| p.acceleration.into()),
            }
        })
        .collect()
}

/// The anchor's gains: PD with velocity and acceleration feed-forward, as
/// PX4's position loop is in effect (kp 4 /s², kd 3.5 /s: stable with the
/// 0.2 s attitude lag, kp < kd/τ), 35° of tilt.
const ANCHOR: PositionGains = PositionGains {
    kp_xy: 4.0,
    kd_xy: 3.5,
    kp_z: 4.0,
    kd_z: 3.5,
    max_tilt_deg: 35.0,
};

/// The anchor's pitch and roll at heading `yaw` (the SITL's position loop,
/// [`position_control`], with [`ANCHOR`]'s gains; the planar plant holds
/// altitude, so its thrust is not used).
fn anchor_command(
    target: &PositionTarget,
    position: Vector3<f64>,
    velocity: Vector3<f64>,
    yaw: f64,
) -> AttitudeCommand {
    let options = PlantOptions::default();
    let a = position_control::acceleration(
        &ANCHOR,
        options.g,
        target,
        position.into(),
        velocity.into(),
    );
    position_control::attitude_for(&options, options.g, a, yaw)
}

/// Horizontal error p95 \[m\] against the circle at the tick's time, over
/// the full-speed part (2 s after the ramp).
fn circle_error(ticks: &[Tick], circle: &Trajectory, from: f64) -> f64 {
    p95(ticks
        .iter()
        .filter(|t| t.t >= from)
        .map(|t| {
            let d = t.position - circle.at(t.t - 1.0).position;
            d.x.hypot(d.y)
        })
        .collect())
}

/// The anchor on the same stream and plant: PD with feed-forward from the
/// newest sample (held between samples, as PX4 holds a setpoint), the
/// plant's true velocity, 50 Hz.
fn anchor(circle: &Trajectory, goals: &[Goal], seconds: f64) -> Vec<Tick> {
    let options = PlantOptions::default();
    let mut plant = build_plant(PlantKind::Planar, &options, 1).expect("plant");
    plant.reset(&PlantState::hover(Vector3::from(START), options.g));
    let mut newest: Option<Goal> = None;
    let mut next = 0;
    let mut ticks = Vec::new();
    let _ = circle;
    for k in 0..(seconds / DT).round() as u64 {
        let t = k as f64 * DT;
        while next < goals.len() && goals[next].t <= t - 0.002 {
            newest = Some(goals[next]);
            next += 1;
        }
        let reference = match newest {
            Some(g) => PositionTarget {
                position: g.position,
                velocity: g.velocity.unwrap_or([0.0; 3]),
                acceleration: g.acceleration.unwrap_or([0.0; 3]),
                yaw: None,
            },
            None => PositionTarget::hold(START),
        };
        let c = anchor_command(&reference, plant.position(), plant.velocity(), 0.0);
        ticks.push(Tick {
            t,
            position: plant.position(),
            applied: (c.pitch, c.roll),
            sent: true,
        });
        plant.apply(&AttitudeCommand {
            pitch: c.pitch,
            roll: c.roll,
            yaw: 0.0,
            thrust: options.g,
        });
        plant.advance(DT);
    }
    ticks
}

#[test]
fn a_streamed_circle_is_tracked_within_the_anchor_budget() {
    let circle = circle::circle(4.0, 3.0, START);
    let seconds = 16.0;
    // Full speed from 1 + 3 s; judged from 6 s (one lap ≈ 9.4 s).
    let from = 6.0;
    let cfg = Config::default();
    let goals = circle_stream(&circle, 20.0, seconds, Fields::Pva);
    let ticks = fly(&cfg, seconds, &goals, &|_| None);
    let df = circle_error(&ticks, &circle, from);
    let step = largest_step(&ticks, 0.0, seconds);
    let anchor_err = circle_error(&anchor(&circle, &goals, seconds), &circle, from);
    eprintln!(
        "circle r 6 m, 4 m/s, 20 Hz p/v/a: DF-MPC p95 {df:.4} m (largest command step {step:.2}°/tick); \
         anchor PD+FF p95 {anchor_err:.4} m"
    );
    for rate in [10.0, 50.0] {
        let g = circle_stream(&circle, rate, seconds, Fields::Pva);
        let e = circle_error(&fly(&cfg, seconds, &g, &|_| None), &circle, from);
        let a = circle_error(&anchor(&circle, &g, seconds), &circle, from);
        eprintln!("circle at {rate} Hz p/v/a: DF-MPC p95 {e:.4} m; anchor p95 {a:.4} m");
        assert!(e <= CIRCLE_BUDGET_M, "{rate} Hz: p95 {e:.4} m");
    }
    let g = circle_stream(&circle, 20.0, seconds, Fields::PositionOnly);
    let mut implied = cfg.clone();
    implied.stream.implied_velocity = true;
    let e_implied = circle_error(&fly(&implied, seconds, &g, &|_| None), &circle, from);
    let e_routes = circle_error(&fly(&cfg, seconds, &g, &|_| None), &circle, from);
    eprintln!(
        "circle at 20 Hz position only: implied velocity p95 {e_implied:.4} m; as routes (option off) p95 {e_routes:.4} m"
    );
    // Variants of the tuning, for the record (before the stream's jerk
    // was fed forward the shipped weights lagged the circle by 0.109 m).
    for (name, smooth, r) in [
        ("smoothness 0", 0.0, 0.003),
        ("r_jerk 0.0003", 50.0, 0.0003),
        ("smoothness 0, r_jerk 0.0003", 0.0, 0.0003),
    ] {
        let mut c = cfg.clone();
        c.controller.dfmpc.smoothness_weight = [smooth, smooth, 0.0];
        c.controller.dfmpc.r_jerk = [r; 3];
        let t = fly(&c, seconds, &goals, &|_| None);
        let e = circle_error(&t, &circle, from);
        let st = largest_step(&t, 0.0, seconds);
        eprintln!("circle at 20 Hz p/v/a, {name}: DF-MPC p95 {e:.4} m, largest step {st:.2}°/tick");
    }
    // The shipped weights meet the budget and beat the anchor on the same
    // stream and plant (measured 0.0064 m vs 0.069 m, 0.66°/tick).
    assert!(df <= CIRCLE_BUDGET_M, "p95 {df:.4} m");
    assert!(df < anchor_err, "{df:.4} m vs anchor {anchor_err:.4} m");
    assert!(
        step <= STEP_BUDGET_DEG,
        "step {step:.2}°/tick on the stream"
    );
    assert!(e_implied < e_routes, "the implied velocity helps");
}

#[test]
fn a_stream_that_stops_becomes_a_smooth_stop_and_hold() {
    let circle = circle::circle(3.0, 2.0, START);
    let cfg = Config::default();
    // The stream stops at 6 s (at speed); flown until 12 s.
    let goals = circle_stream(&circle, 20.0, 6.0, Fields::Pva);
    let ticks = fly(&cfg, 12.0, &goals, &|_| None);
    let step = largest_step(&ticks, 5.0, 12.0);
    let last = ticks.last().unwrap();
    let before = &ticks[ticks.len() - 50];
    let drift = (last.position - before.position).norm();
    eprintln!(
        "stream stopped at speed: largest command step {step:.2}°/tick, drift over the last 1 s {drift:.4} m"
    );
    assert!(step <= STEP_BUDGET_DEG, "step {step:.2}°/tick");
    assert!(drift < 0.02, "not holding: moved {drift:.3} m in 1 s");
    // A jump in the stream is refused: the hold is kept.
    let mut goals = circle_stream(&circle, 20.0, 6.0, Fields::Pva);
    let jump = Goal {
        t: 7.5,
        position: [40.0, 0.0, -10.0],
        velocity: Some([1.0, 0.0, 0.0]),
        acceleration: None,
    };
    goals.push(jump);
    let ticks = fly(&cfg, 12.0, &goals, &|_| None);
    let end = (ticks.last().unwrap().position - last.position).norm();
    assert!(
        end < 0.01,
        "the jumped sample moved the vehicle: {end:.3} m from the hold"
    );
}
