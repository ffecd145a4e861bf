//! The pure step on a synthetic clock, with a scripted controller.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use dflat_control::optimise::SolverFault;
use dflat_control::{
    AttitudeCommand as ControlCommand, ControlError, Controller, Measurement, ReferenceSource,
    TickOutput,
};

use super::*;
use crate::control::thrust_mapping;

/// PX4 in OFFBOARD, armed: the autopilot applies the commands.
const OFFBOARD: dflat_link::AutopilotMode = dflat_link::AutopilotMode {
    family: dflat_link::AutopilotFamily::Px4,
    custom_mode: 6 << 16,
    armed: true,
};

const DT: f64 = 0.02;
const G: f64 = 9.81;

/// What the scripted controller returns on a tick.
#[derive(Debug, Clone, Copy)]
pub(super) enum Script {
    /// This command (roll, pitch in rad).
    Command(f64, f64),
    /// This command with a NaN pitch.
    Nan,
    /// A solver failure.
    Fail,
}

/// A controller that replays a script and counts its calls and the ticks
/// it is told were skipped.
struct Scripted {
    script: Vec<Script>,
    tick: usize,
    updates: Arc<AtomicUsize>,
    skipped: Arc<AtomicUsize>,
}

impl Controller for Scripted {
    fn name(&self) -> &'static str {
        "scripted"
    }

    fn update(
        &mut self,
        m: &Measurement,
        _reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        self.updates.fetch_add(1, Ordering::Relaxed);
        let step = self.script[self.tick.min(self.script.len() - 1)];
        self.tick += 1;
        let (roll, pitch) = match step {
            Script::Command(r, p) => (r, p),
            Script::Nan => (0.0, f64::NAN),
            Script::Fail => return Err(SolverFault::NotConverged { iterations: 0 }.into()),
        };
        Ok(TickOutput {
            command: ControlCommand {
                pitch,
                roll,
                yaw: 0.0,
                thrust: G,
            },
            plan: [m.position; 4],
            reference: m.position,
            saturated: false,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }

    fn skipped(&mut self, ticks: u32) {
        self.skipped.fetch_add(ticks as usize, Ordering::Relaxed);
    }

    fn reset(&mut self) {}
}

pub(super) fn core(script: Vec<Script>) -> (ControlCore, Arc<AtomicUsize>) {
    let (core, updates, _) = core_counting_skipped(script);
    (core, updates)
}

/// [`core`], with the count of ticks the controller was told were skipped.
fn core_counting_skipped(script: Vec<Script>) -> (ControlCore, Arc<AtomicUsize>, Arc<AtomicUsize>) {
    core_with(&Config::default(), script)
}

/// [`core_counting_skipped`] on the configuration `cfg`.
pub(super) fn core_with(
    cfg: &Config,
    script: Vec<Script>,
) -> (ControlCore, Arc<AtomicUsize>, Arc<AtomicUsize>) {
    let updates = Arc::new(AtomicUsize::new(0));
    let skipped = Arc::new(AtomicUsize::new(0));
    let controller = Scripted {
        script,
        tick: 0,
        updates: updates.clone(),
        skipped: skipped.clone(),
    };
    let mapping = thrust_mapping(cfg);
    (
        ControlCore::new(cfg, Box::new(controller), mapping),
        updates,
        skipped,
    )
}

/// Tick `k` (at k·δt) after an autopilot heartbeat (PX4 OFFBOARD) and a
/// fresh pose stamped `source_time` (`None`: arrival) 1 ms before it, then
/// `extra`; the stopwatch advances 0.1 ms per reading.
pub(super) fn step_at(
    core: &mut ControlCore,
    k: u64,
    source_time: Option<f64>,
    extra: Vec<Event>,
) -> StepOutput {
    let t = k as f64 * DT;
    let mut events = vec![
        Event::Heartbeat {
            arrival: t - 0.001,
            mode: OFFBOARD,
        },
        Event::Pose {
            arrival: t - 0.001,
            source_time,
            position: [0.0, 0.0, -10.0],
            yaw: Some(0.0),
            reset_counter: None,
        },
    ];
    events.extend(extra);
    step_events(core, k, events)
}

/// Tick `k` at `k·δt` (no jitter) with `events`; the stopwatch advances
/// 0.1 ms per reading (also the heading tests' driver).
pub(super) fn step_events(
    core: &mut ControlCore,
    k: u64,
    events: impl IntoIterator<Item = Event>,
) -> StepOutput {
    let t = k as f64 * DT;
    let time = TickTime {
        tick: k,
        t,
        scheduled: t,
        jitter_us: 0,
    };
    let mut clock = t;
    core.step(&time, events, &mut || {
        clock += 1e-4;
        clock
    })
}

/// Runs `ticks` ticks from t = 0 with a fresh pose and an autopilot
/// heartbeat before each; returns every step's output.
pub(super) fn fly(core: &mut ControlCore, ticks: u64) -> Vec<StepOutput> {
    (0..ticks).map(|k| step_at(core, k, None, vec![])).collect()
}

#[test]
fn a_good_tick_sends_the_guarded_command_and_records_it() {
    let (mut core, updates) = core(vec![Script::Command(0.1, -0.05)]);
    let out = fly(&mut core, 5);
    assert!(
        out[0].transitions.iter().any(|t| t.to.streams()),
        "streams at once with pose"
    );
    let last = out.last().unwrap();
    let sent = last.command.as_ref().expect("a command");
    assert_eq!(sent.command.roll, 0.1);
    assert_eq!(sent.command.pitch, -0.05);
    assert!(
        (sent.command.thrust - 0.5).abs() < 1e-12,
        "hover = 0.5 normalised"
    );
    assert_eq!(
        last.row.command,
        Some([0.1, -0.05, 0.0, sent.command.thrust])
    );
    assert!(last.row.solve_us.is_some());
    assert_eq!(updates.load(Ordering::Relaxed), 5);
    assert_eq!(core.counts().commands, 5);
    assert!(matches!(sent.message, MavMessage::SET_ATTITUDE_TARGET(_)));
}

/// The loop stalls over ticks 3–4 and 7–9 (the schedule's tick numbers
/// jump): the controller is told, before its next update, how many ticks
/// passed without one.
#[test]
fn ticks_the_loop_skipped_are_told_to_the_controller() {
    let (mut core, updates, skipped) = core_counting_skipped(vec![Script::Command(0.0, 0.0)]);
    for k in [0, 1, 2, 5, 6, 10, 11] {
        let out = step_at(&mut core, k, None, vec![]);
        assert!(out.command.is_some(), "tick {k}");
    }
    assert_eq!(updates.load(Ordering::Relaxed), 7);
    assert_eq!(skipped.load(Ordering::Relaxed), 2 + 3);
}

#[test]
fn the_guard_counts_each_command_once() {
    // 40° of roll against the 35° vehicle limit: cut on every tick.
    let (mut core, _) = core(vec![Script::Command(40f64.to_radians(), 0.0)]);
    let out = fly(&mut core, 10);
    let sent = out.iter().filter(|o| o.command.is_some()).count() as u64;
    assert_eq!(sent, 10);
    assert_eq!(
        core.counts().guards.tilt_saturated,
        sent,
        "once per command"
    );
    for o in &out {
        let c = o.command.as_ref().unwrap().command;
        assert!(dflat_control::tilt::tilt(c.pitch, c.roll) <= 35f64.to_radians() + 1e-9);
    }
}

#[test]
fn a_nan_never_leaves_the_step_and_the_fallback_flies() {
    let mut script = vec![Script::Command(0.02, 0.0); 3];
    script.extend([Script::Nan, Script::Fail, Script::Nan]);
    script.extend(vec![Script::Command(0.02, 0.0); 4]);
    let (mut core, _) = core(script);
    let out = fly(&mut core, 10);
    for o in &out {
        if let Some(s) = &o.command {
            let c = s.command;
            assert!(
                [c.roll, c.pitch, c.yaw, c.thrust]
                    .iter()
                    .all(|v| v.is_finite())
            );
        }
    }
    // Ticks 3–5 failed: the held command, said once.
    for o in &out[3..6] {
        assert_eq!(o.row.guard, Some("held"));
        assert_eq!(o.command.as_ref().unwrap().command.roll, 0.02);
    }
    let texts: usize = out[3..6].iter().map(|o| o.texts.len()).sum();
    assert_eq!(texts, 1, "the fallback kind is announced once");
    assert_eq!(core.counts().guards.non_finite, 2);
    assert_eq!(core.counts().guards.controller_failures, 3);
    assert_eq!(core.counts().guards.held, 3);
    assert_eq!(out[6].row.guard, None, "recovered");
}

#[test]
fn an_overrun_sends_the_fallback() {
    let (mut core, _) = core(vec![Script::Command(0.02, 0.0)]);
    fly(&mut core, 3);
    // A stopwatch whose solve takes 30 ms (> 20 ms period).
    let mut clock = 0.0;
    let time = TickTime {
        tick: 3,
        t: 0.06,
        scheduled: 0.06,
        jitter_us: 0,
    };
    let events = [Event::Pose {
        arrival: 0.059,
        source_time: None,
        position: [0.0, 0.0, -10.0],
        yaw: Some(0.0),
        reset_counter: None,
    }];
    let out = core.step(&time, events, &mut || {
        clock += 0.03;
        clock
    });
    assert_eq!(core.counts().guards.deadline_overruns, 1);
    assert_eq!(out.row.guard, Some("held"));
    assert!(out.command.is_some());
}

#[test]
fn without_pose_nothing_is_sent() {
    let (mut core, updates) = core(vec![Script::Command(0.0, 0.0)]);
    let time = TickTime {
        tick: 0,
        t: 0.0,
        scheduled: 0.0,
        jitter_us: 0,
    };
    let out = core.step(
        &time,
        [Event::Heartbeat {
            arrival: 0.0,
            mode: OFFBOARD,
        }],
        &mut || 0.0,
    );
    assert!(out.command.is_none());
    assert_eq!(updates.load(Ordering::Relaxed), 0);
    assert_eq!(out.row.tick, 0);
}

#[test]
fn events_map_from_inbound_messages() {
    use dflat_link::{Inbound, Pose, PoseSource};
    let pose = Inbound::Pose(Pose {
        source: PoseSource::LocalPositionNed,
        time_usec: 2_000_000,
        position: [1.0, 2.0, -3.0],
        yaw: None,
        reset_counter: None,
    });
    assert_eq!(
        event_from(&pose, PoseSource::LocalPositionNed, 5.0),
        Some(Event::Pose {
            arrival: 5.0,
            source_time: Some(2.0),
            position: [1.0, 2.0, -3.0],
            yaw: None,
            reset_counter: None,
        })
    );
    assert_eq!(event_from(&pose, PoseSource::Odometry, 5.0), None);
    let attitude = Inbound::Other(30);
    assert_eq!(event_from(&attitude, PoseSource::Odometry, 1.5), None);
}

#[test]
fn a_controller_that_cannot_fly_lets_go_after_the_level_hover_period_and_resumes() {
    // Good for 10 ticks, failing for 200, good again. The script index
    // counts every update (trials included).
    let mut script = vec![Script::Command(0.05, 0.0); 10];
    script.extend(vec![Script::Fail; 200]);
    script.push(Script::Command(0.02, 0.0));
    let (mut core, _) = core(script);
    let max_level_ticks =
        (Config::default().safety.level_hover_max_ms / 1000.0 / DT).round() as usize;
    let out = fly(&mut core, 300);
    // Streamed: 10 good, the fallback (5 plan steps or held, then level
    // hover for at most the configured period), then nothing.
    let level = out.iter().filter(|o| o.row.guard == Some("level")).count();
    assert!(level <= max_level_ticks, "{level} level-hover ticks");
    assert!(level >= max_level_ticks - 1, "{level} level-hover ticks");
    let let_go = out
        .iter()
        .position(|o| o.row.guard == Some("let_go"))
        .expect("the stream stops");
    assert!(out[let_go].command.is_none());
    let texts: Vec<String> = out
        .iter()
        .flat_map(|o| o.texts.iter())
        .filter_map(|m| match m {
            MavMessage::STATUSTEXT(d) => Some(d.text.to_str().unwrap_or("").to_owned()),
            _ => None,
        })
        .collect();
    assert!(
        texts
            .iter()
            .any(|t| t.contains("control failed, stream off")),
        "{texts:?}"
    );
    assert_eq!(core.counts().guards.control_failsafes, 1);
    // Silent while the controller fails (trials are not sent) …
    let resumed = out[let_go..]
        .iter()
        .position(|o| o.command.is_some())
        .map(|i| i + let_go)
        .expect("resumes once the controller solves");
    assert!(
        out[let_go..resumed].iter().all(|o| o.command.is_none()),
        "nothing sent in between"
    );
    assert!(texts.iter().any(|t| t.contains("controller flies again")));
    // … and streams its commands again afterwards.
    let last = out.last().unwrap().command.as_ref().unwrap();
    assert_eq!(last.command.roll, 0.02);
}

#[test]
fn the_core_walks_the_failsafe_ladder_and_back() {
    // No plan (the scripted controller has none): held, level hover, let
    // go with trials, then flying again.
    let mut script = vec![Script::Command(0.05, 0.0); 10];
    script.extend(vec![Script::Fail; 200]);
    script.push(Script::Command(0.02, 0.0));
    let (mut core, _) = core(script);
    let mut names: Vec<&'static str> = vec![core.failsafe().name()];
    let mut held = 0;
    for k in 0..300 {
        step_at(&mut core, k, None, vec![]);
        let state = core.failsafe();
        if let failsafe::Failsafe::HeldCommand { held: h, .. } = state {
            held = held.max(h);
        }
        if names.last() != Some(&state.name()) {
            names.push(state.name());
        }
    }
    assert_eq!(
        names,
        [
            "nominal",
            "held_command",
            "level_hover",
            "trial",
            "let_go",
            "nominal"
        ]
    );
    assert_eq!(held, Config::default().safety.hold_last_ticks);
    assert_eq!(core.state(), FlightState::Holding);
}

#[test]
fn a_pose_clock_running_slow_is_replaced_by_arrival_times() {
    let (mut core, _) = core(vec![Script::Command(0.0, 0.0)]);
    // The source clock runs at 0.6× ours: the mapped capture times fall
    // ever further behind the arrivals.
    let outs: Vec<StepOutput> = (0..200u64)
        .map(|k| {
            step_at(
                &mut core,
                k,
                Some(100.0 + 0.6 * (k as f64 * DT - 0.001)),
                vec![],
            )
        })
        .collect();
    assert_eq!(core.counts().guards.pose_clock_faults, 1);
    // Lag 0.4·t exceeds 0.5 s from t = 1.25 s, for 1 s: found by 2.3 s.
    let found = outs
        .iter()
        .position(|o| {
            o.texts.iter().any(|m| {
                matches!(m, MavMessage::STATUSTEXT(d) if d.text.to_str().unwrap_or("").contains("pose clock lags"))
            })
        })
        .unwrap();
    let t_found = found as f64 * DT;
    assert!((2.2..2.4).contains(&t_found), "{t_found}");
    // Afterwards the pose age in the record is the arrival's (≈ 1 ms).
    let age = outs.last().unwrap().row.pose_age_ms.unwrap();
    assert!(age < 5.0, "{age} ms");
}

#[test]
fn reads_the_autopilots_parameters_and_refuses_to_engage_above_its_tilt_limit() {
    let (mut core, _) = core(vec![Script::Command(0.0, 0.0)]);
    let step = |core: &mut ControlCore, k: u64, extra: Vec<Event>| step_at(core, k, None, extra);
    // The PX4 family is known: both parameters are requested.
    let out = step(&mut core, 0, vec![]);
    let requested: Vec<String> = out
        .texts
        .iter()
        .filter_map(|m| match m {
            MavMessage::PARAM_REQUEST_READ(d) => Some(d.param_id.to_str().unwrap().to_owned()),
            _ => None,
        })
        .collect();
    assert_eq!(requested, ["MPC_THR_HOVER", "MPC_TILTMAX_AIR"]);
    // The autopilot allows 30°, the configuration asks 35°: not engaged.
    let param = |name: &str, value: f64| Event::Param {
        arrival: 0.0,
        name: ParamName::new(name),
        value,
    };
    let mut out = step(&mut core, 1, vec![param("MPC_TILTMAX_AIR", 30.0)]);
    for k in 2..10 {
        out.texts.extend(step(&mut core, k, vec![]).texts);
    }
    assert_eq!(core.state(), FlightState::Standby);
    let said = out.texts.iter().any(|m| {
        matches!(m, MavMessage::STATUSTEXT(d) if d.text.to_str().unwrap_or("").contains("not engaging, tilt 35 > MPC_TILTMAX_AIR 30"))
    });
    assert!(said);
    // Allowed 45°: engaged at the next heartbeat.
    step(&mut core, 10, vec![param("MPC_TILTMAX_AIR", 45.0)]);
    step(&mut core, 11, vec![]);
    assert!(core.state().engaged(), "{:?}", core.state());
}

/// Tick `k` with only an autopilot heartbeat (the pose stream stopped).
fn step_without_pose(core: &mut ControlCore, k: u64) -> StepOutput {
    let t = k as f64 * DT;
    let events = [Event::Heartbeat {
        arrival: t - 0.001,
        mode: OFFBOARD,
    }];
    step_events(core, k, events)
}

#[test]
fn losing_pose_while_engaged_streams_level_hover_then_stops() {
    // The controller commands 20° of roll: the vehicle accelerates.
    let tilt = 20f64.to_radians();
    let (mut core, _) = core(vec![Script::Command(tilt, 0.0)]);
    let out = fly(&mut core, 50);
    assert!(core.state().engaged(), "{:?}", core.state());
    assert_eq!(out[49].command.as_ref().unwrap().command.roll, tilt);
    let cfg = Config::default();
    let timeout_ticks = (cfg.safety.pose_timeout_ms / 1000.0 / DT).round() as u64;
    let level_ticks = (cfg.safety.level_hover_max_ms / 1000.0 / DT).round() as usize;
    // The pose stops after tick 49.
    let lost: Vec<StepOutput> = (50..50 + 120)
        .map(|k| step_without_pose(&mut core, k))
        .collect();
    let failsafe_at = lost
        .iter()
        .position(|o| o.transitions.iter().any(|t| t.to == FlightState::Failsafe))
        .expect("failsafe on stale pose");
    assert!(
        failsafe_at as u64 <= timeout_ticks,
        "failsafe at {failsafe_at}"
    );
    // From the failsafe tick on: level, at hover thrust, yaw kept, then silence.
    let level: Vec<&StepOutput> = lost[failsafe_at..]
        .iter()
        .take_while(|o| o.command.is_some())
        .collect();
    assert_eq!(
        level.len(),
        level_ticks,
        "one level command per tick for level_hover_max_ms"
    );
    for o in &level {
        let c = o.command.as_ref().unwrap().command;
        assert_eq!((c.roll, c.pitch, c.yaw), (0.0, 0.0, 0.0));
        assert!((c.thrust - 0.5).abs() < 1e-12, "hover thrust {}", c.thrust);
        assert_eq!(o.row.guard, Some("level"));
        assert_eq!(o.row.state, FlightState::Failsafe);
    }
    assert!(
        lost[failsafe_at + level_ticks..]
            .iter()
            .all(|o| o.command.is_none()),
        "the stream stops after the level hover"
    );
    assert_eq!(lost[failsafe_at + level_ticks].row.guard, Some("let_go"));
    assert_eq!(core.counts().guards.level_hover, level_ticks as u64);
    // Said once when it starts and once when it ends.
    let texts = |o: &StepOutput| {
        o.texts
            .iter()
            .filter_map(|m| match m {
                MavMessage::STATUSTEXT(s) => Some(s.text.to_str().unwrap_or("").to_owned()),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
    let all: Vec<String> = lost.iter().flat_map(texts).collect();
    assert_eq!(
        all.iter()
            .filter(|t| t.contains("level hover then stream off"))
            .count(),
        1
    );
    assert_eq!(
        all.iter()
            .filter(|t| t.contains("level hover over"))
            .count(),
        1
    );
    // The pose returns: streaming again.
    let back = fly_from(&mut core, 170, 5);
    assert!(back.iter().any(|o| o.command.is_some()));
}

#[test]
fn without_level_hover_pose_loss_goes_silent_at_once() {
    let tilt = 20f64.to_radians();
    let mut cfg = Config::default();
    cfg.safety.level_hover_max_ms = 0.0;
    let (mut core, _, _) = core_with(&cfg, vec![Script::Command(tilt, 0.0)]);
    fly(&mut core, 50);
    let lost: Vec<StepOutput> = (50..80).map(|k| step_without_pose(&mut core, k)).collect();
    let failsafe_at = lost
        .iter()
        .position(|o| o.row.state == FlightState::Failsafe)
        .expect("failsafe");
    assert!(lost[failsafe_at..].iter().all(|o| o.command.is_none()));
    assert_eq!(core.counts().guards.level_hover, 0);
}

/// Ticks `from..from + n` with fresh poses.
fn fly_from(core: &mut ControlCore, from: u64, n: u64) -> Vec<StepOutput> {
    (from..from + n)
        .map(|k| step_at(core, k, None, vec![]))
        .collect()
}

/// `vehicle.hover_thrust_from_autopilot`: the autopilot's MPC_THR_HOVER
/// (0.42) answered in standby is flown as the hover thrust (the scripted
/// controller asks for g: normalised, that is the hover thrust); answered
/// after the engagement it is not (the thrust would step), and without
/// the option the configuration's 0.5 is flown.
#[test]
fn flies_the_autopilots_hover_thrust_only_when_asked_and_before_engaging() {
    use crate::config::ThrustMode;
    let run = |from_autopilot: bool, answer_tick: u64| -> (f64, Vec<String>) {
        let mut cfg = Config::default();
        cfg.vehicle.thrust_mode = ThrustMode::Normalized;
        cfg.vehicle.hover_thrust_from_autopilot = from_autopilot;
        let (mut core, _, _) = core_with(&cfg, vec![Script::Command(0.0, 0.0)]);
        let posctl = dflat_link::AutopilotMode {
            custom_mode: 3 << 16,
            ..OFFBOARD
        };
        let mut texts = Vec::new();
        let mut thrust = f64::NAN;
        for k in 0..40u64 {
            let t = k as f64 * DT;
            let mut events = vec![
                Event::Heartbeat {
                    arrival: t - 0.001,
                    mode: if k < 10 { posctl } else { OFFBOARD },
                },
                Event::Pose {
                    arrival: t - 0.001,
                    source_time: None,
                    position: [0.0, 0.0, -10.0],
                    yaw: Some(0.0),
                    reset_counter: None,
                },
            ];
            if k == answer_tick {
                events.push(Event::Param {
                    arrival: t - 0.0005,
                    name: ParamName::new("MPC_THR_HOVER"),
                    value: 0.42,
                });
            }
            let out = step_events(&mut core, k, events);
            for m in &out.texts {
                if let MavMessage::STATUSTEXT(d) = m {
                    texts.push(d.text.to_str().unwrap_or("").to_owned());
                }
            }
            if let Some(c) = &out.command {
                thrust = c.command.thrust;
            }
        }
        assert!(core.state().engaged(), "{:?}", core.state());
        (thrust, texts)
    };
    let (thrust, texts) = run(true, 3);
    assert!((thrust - 0.42).abs() < 1e-9, "{thrust}");
    assert!(
        texts
            .iter()
            .any(|t| t.contains("flying MPC_THR_HOVER 0.42")),
        "{texts:?}"
    );
    let (thrust, texts) = run(true, 20);
    assert!((thrust - 0.5).abs() < 1e-9, "{thrust}");
    assert!(
        texts.iter().any(|t| t.contains("MPC_THR_HOVER 0.42 late")),
        "{texts:?}"
    );
    let (thrust, _) = run(false, 3);
    assert!((thrust - 0.5).abs() < 1e-9, "{thrust}");
}

/// The stop (SIGTERM): asked while engaged with 20° of roll commanded, at
/// rest (braked at once): the autopilot is asked for its own hold
/// (`safety.stop_requests_hold`), the level phase ramps to level at
/// [`envelope::STOP_LEVEL_RAMP`] per tick and lasts `stop_level_ms`, no
/// setpoint is taken meanwhile, and the stop is done after it; the
/// summary's figures stop at the stop.
#[test]
fn the_stop_asks_for_a_hold_ramps_to_level_and_ends() {
    let tilt = 20f64.to_radians();
    let mut cfg = Config::default();
    cfg.safety.stop_requests_hold = true;
    let (mut core, _, _) = core_with(&cfg, vec![Script::Command(tilt, 0.0)]);
    let out = fly(&mut core, 50);
    assert!(core.state().engaged());
    assert_eq!(out[49].command.as_ref().unwrap().command.roll, tilt);
    let transitions = core.supervisor().transitions();
    core.begin_stop(50.0 * DT);
    assert!(!core.stop_done(50.0 * DT));
    let first = step_at(&mut core, 50, None, vec![]);
    // The hold request, to the autopilot, PX4 AUTO.LOITER.
    let request = first.texts.iter().find_map(|m| match m {
        MavMessage::COMMAND_LONG(c) => Some(c.clone()),
        _ => None,
    });
    let c = request.expect("no MAV_CMD_DO_SET_MODE");
    assert_eq!(c.command, dflat_link::dialect::MavCmd::MAV_CMD_DO_SET_MODE);
    assert_eq!((c.target_system, c.target_component), (1, 1));
    assert_eq!((c.param2, c.param3), (4.0, 3.0));
    assert_eq!(first.row.guard, Some(envelope::STOP_GUARD));
    // A setpoint during the stop is refused.
    let refused = core.counts().setpoints_refused;
    let sp = Event::Setpoint {
        arrival: 51.0 * DT - 0.001,
        position: [5.0, 0.0, -10.0],
        yaw: None,
        yaw_rate: None,
        source_time: None,
        velocity: None,
        acceleration: None,
    };
    let mut outs = vec![first, step_at(&mut core, 51, None, vec![sp])];
    assert_eq!(core.counts().setpoints_refused, refused + 1);
    let mut k = 52;
    while !core.stop_done(k as f64 * DT) && k < 200 {
        outs.push(step_at(&mut core, k, None, vec![]));
        k += 1;
    }
    let rolls: Vec<f64> = outs
        .iter()
        .filter_map(|o| o.command.as_ref().map(|c| c.command.roll))
        .collect();
    // From 20°: no step larger than the ramp, level at the end.
    let mut last = tilt;
    for r in &rolls {
        assert!(
            (r - last).abs() <= envelope::STOP_LEVEL_RAMP + 1e-12,
            "{r} after {last}"
        );
        last = *r;
    }
    assert_eq!(*rolls.last().unwrap(), 0.0);
    let level_ticks = (cfg.safety.stop_level_ms / 1000.0 / DT).round() as usize;
    assert!(
        (level_ticks..=level_ticks + 2).contains(&rolls.len()),
        "{} commands for {level_ticks} level ticks",
        rolls.len()
    );
    assert_eq!(core.state_at_stop(), Some(FlightState::Holding));
    assert_eq!(core.transitions_before_stop(), transitions);
    let stop = core.stop_summary().unwrap();
    assert_eq!(stop.commands, rolls.len() as u64);
    // The stop's level is not a level-hover fallback.
    assert_eq!(core.counts().guards.level_hover, 0);
}
