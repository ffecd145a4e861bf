//! The pure step on a synthetic clock: no sockets, no sleeps.

use dflat_link::dialect::{COMMAND_LONG_DATA, MavCmd, MavParamType, MavResult, PARAM_SET_DATA};
use dflat_link::mavlink::Message as _;

use super::*;
use crate::planner::PlannerConfig;

/// `[sitl]` defaults (200 Hz plant, 50 Hz telemetry, 0.5 s timeout),
/// starting 10 m up.
fn config() -> SitlSettings {
    let mut cfg = SitlSettings::default();
    cfg.sitl.start = [0.0, 0.0, -10.0];
    cfg
}

/// An attitude command arrived at `at` \[s\]: `pitch` \[rad\], hover thrust.
fn command(cfg: &SitlSettings, at: f64, pitch: f64) -> SitlInput {
    SitlInput::Command {
        at,
        command: ReceivedCommand {
            roll: 0.0,
            pitch,
            yaw: 0.0,
            thrust: cfg.sitl.hover_thrust,
        },
    }
}

/// A frame from the ground station (255/190) on its port at `at`.
fn from_gcs(at: f64, message: MavMessage) -> SitlInput {
    SitlInput::Frame {
        at,
        link: Link::Gcs,
        header: dflat_link::header(255, 190, 0),
        message: Box::new(message),
    }
}

/// Steps `core` on time (each step at its plant step's time) for
/// `seconds`, feeding `inputs(clock)` at every step; the outputs.
fn run(
    core: &mut SitlCore,
    seconds: f64,
    mut inputs: impl FnMut(f64) -> Vec<SitlInput>,
) -> Vec<SitlOutput> {
    let end = core.time() + seconds + 1e-9;
    let mut outs = Vec::new();
    while core.next_step_time() <= end {
        let clock = core.next_step_time();
        outs.push(core.step(clock, inputs(clock)));
    }
    outs
}

/// An attitude command every 20 ms (at 50 Hz, as the daemon).
fn streaming(cfg: &SitlSettings, pitch: f64) -> impl FnMut(f64) -> Vec<SitlInput> {
    let cfg = cfg.clone();
    let mut next = 0.0;
    move |clock| {
        if clock + 1e-9 >= next {
            next = clock + 0.02;
            vec![command(&cfg, clock, pitch)]
        } else {
            vec![]
        }
    }
}

/// `input` at the first step, nothing after.
fn once(input: SitlInput) -> impl FnMut(f64) -> Vec<SitlInput> {
    let mut input = Some(input);
    move |_| input.take().into_iter().collect()
}

fn silence(_: f64) -> Vec<SitlInput> {
    vec![]
}

/// The names of the messages of `out`, in order.
fn names(out: &SitlOutput) -> Vec<&'static str> {
    out.messages
        .iter()
        .map(|m| m.message.message_name())
        .collect()
}

fn all_names(outs: &[SitlOutput]) -> Vec<&'static str> {
    outs.iter().flat_map(names).collect()
}

/// The COMMAND_ACK of `out`: where it goes and its result (panics
/// without one).
fn ack_of(out: &SitlOutput) -> (Dest, MavResult) {
    out.messages
        .iter()
        .find_map(|m| match &m.message {
            MavMessage::COMMAND_ACK(a) => Some((m.to, a.result)),
            _ => None,
        })
        .expect("no ack")
}

#[test]
fn without_commands_it_holds_where_it_started() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let outs = run(&mut core, 2.0, silence);
    assert!(outs.iter().all(|o| o.status.mode == SitlMode::Hold));
    let truth = core.truth();
    assert!((truth.t - 2.0).abs() < 0.03, "{truth:?}");
    let p = truth.position;
    assert!(p[0].abs() < 1e-6 && p[1].abs() < 1e-6 && (p[2] + 10.0).abs() < 1e-6);
    assert!(truth.command.is_none());
    let counts = outs.iter().fold(0, |n, o| n + o.counts.plant_steps);
    assert_eq!(counts, 400, "200 Hz for 2 s");
}

#[test]
fn an_attitude_target_in_offboard_tilts_the_plant() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let outs = run(&mut core, 0.6, streaming(&cfg, -0.2));
    // Auto engagement at the first step with a live stream.
    assert_eq!(
        outs[0].events,
        vec![SitlEvent::ModeChanged {
            from: SitlMode::Hold,
            to: SitlMode::Offboard
        }]
    );
    let truth = core.truth();
    assert_eq!(truth.mode, SitlMode::Offboard);
    assert!(truth.command.is_some_and(|c| (c.pitch + 0.2).abs() < 1e-12));
    // Nose down: pitched towards −0.2 rad and accelerating north.
    assert!(truth.euler[1] < -0.15, "{truth:?}");
    assert!(truth.velocity[0] > 0.3, "{truth:?}");
}

#[test]
fn no_command_for_the_timeout_and_the_autopilot_holds() {
    let mut cfg = config();
    cfg.sitl.command_timeout_s = 0.2;
    let mut core = SitlCore::new(&cfg).unwrap();
    run(&mut core, 0.6, streaming(&cfg, -0.2));
    let last_command = core.command.expect("no command").0;
    let moving = core.truth();
    let t0 = core.time();
    assert!(moving.velocity[0] > 0.3, "{moving:?}");
    // Silence: offboard until the timeout runs out, then position mode.
    let outs = run(&mut core, 0.4, silence);
    let switch = outs
        .iter()
        .position(|o| o.status.mode == SitlMode::Hold)
        .expect("never held");
    let dt = core.step_period();
    let at = t0 + (switch + 1) as f64 * dt;
    assert!(
        at - last_command >= 0.2 - 1e-9 && at - last_command < 0.2 + dt + 1e-9,
        "held at {at}, last command {last_command}"
    );
    assert_eq!(outs[switch].counts.hold_entries, 1);
    assert_eq!(
        outs[switch].events,
        vec![SitlEvent::ModeChanged {
            from: SitlMode::Offboard,
            to: SitlMode::Hold
        }]
    );
    // A heartbeat tells the new mode at once.
    assert!(names(&outs[switch]).contains(&"HEARTBEAT"));
    // It brakes: slower a second later, no command in force.
    let outs = run(&mut core, 1.5, silence);
    assert!(outs.iter().all(|o| o.status.mode == SitlMode::Hold));
    let held = core.truth();
    assert!(held.command.is_none());
    assert!(held.velocity[0].abs() < moving.velocity[0], "{held:?}");
}

#[test]
fn attitude_goes_before_the_local_position_on_a_telemetry_step() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let outs = run(&mut core, 0.1, silence);
    let telemetry: Vec<_> = outs.iter().filter(|o| o.truth.is_some()).collect();
    // 50 Hz of a 200 Hz plant: every fourth step.
    assert_eq!(telemetry.len(), 5);
    for o in telemetry {
        let n = names(o);
        let att = n.iter().position(|m| *m == "ATTITUDE").expect("ATTITUDE");
        let pos = n
            .iter()
            .position(|m| *m == "LOCAL_POSITION_NED")
            .expect("LOCAL_POSITION_NED");
        assert!(att < pos, "{n:?}");
        let p = &o.messages[pos];
        assert_eq!(p.to, Dest::Both);
        assert!(p.measured_pose, "without vision the pose is measured");
        assert!(!o.messages[att].measured_pose);
    }
    for o in outs.iter().filter(|o| o.truth.is_none()) {
        assert!(!names(o).contains(&"LOCAL_POSITION_NED"), "{:?}", names(o));
    }
}

#[test]
fn a_paused_pose_stream_sends_heartbeats_but_no_pose() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let outs = run(&mut core, 2.5, once(SitlInput::PausePose(true)));
    assert!(outs.iter().all(|o| o.status.pose_paused));
    let sent = all_names(&outs);
    let heartbeats = sent.iter().filter(|m| **m == "HEARTBEAT").count();
    assert_eq!(heartbeats, 3, "at 0 s, 1 s and 2 s: {sent:?}");
    for pose in [
        "ATTITUDE",
        "LOCAL_POSITION_NED",
        "ATTITUDE_QUATERNION",
        "GLOBAL_POSITION_INT",
    ] {
        assert!(!sent.contains(&pose), "{pose} sent while paused");
    }
    // The plant and its truth go on.
    assert!(outs.iter().filter(|o| o.truth.is_some()).count() > 100);
    let outs = run(&mut core, 0.1, |_| vec![SitlInput::PausePose(false)]);
    assert!(all_names(&outs).contains(&"LOCAL_POSITION_NED"));
}

#[test]
fn the_planner_streams_once_offboard() {
    let mut cfg = config();
    cfg.sitl.planner = Some(PlannerConfig {
        start_after_s: 0.5,
        ..PlannerConfig::default()
    });
    let mut core = SitlCore::new(&cfg).unwrap();
    let planned = |outs: &[SitlOutput]| -> Vec<Outgoing> {
        outs.iter()
            .flat_map(|o| o.messages.iter())
            .filter(|m| matches!(m.origin, Origin::Planner(_)))
            .cloned()
            .collect()
    };
    // In position mode: nothing, however long.
    let outs = run(&mut core, 3.0, silence);
    assert!(planned(&outs).is_empty());
    assert_eq!(core.status().planner_start, None);
    // Offboard from 3 s: the stream starts 0.5 s later, at 20 Hz, from
    // the planner's ids to the daemon on the vehicle link.
    let outs = run(&mut core, 2.0, streaming(&cfg, 0.0));
    let start = core.status().planner_start.expect("never started");
    assert!((start - 3.5).abs() < 0.01, "{start}");
    let samples = planned(&outs);
    assert!((29..=31).contains(&samples.len()), "{}", samples.len());
    let first = &samples[0];
    assert_eq!(first.to, Dest::Only(Link::Vehicle));
    let Origin::Planner(h) = first.origin else {
        unreachable!()
    };
    assert_eq!((h.system_id, h.component_id), (255, 190));
    assert!(matches!(
        first.message,
        MavMessage::SET_POSITION_TARGET_LOCAL_NED(ref d)
            if (d.target_system, d.target_component) == (1, 191)
    ));
}

#[test]
fn the_same_inputs_fly_the_same_flight() {
    let mut cfg = config();
    cfg.sitl.noise_sigma = 0.05;
    let flight = || {
        let mut core = SitlCore::new(&cfg).unwrap();
        let mut outs = run(&mut core, 1.0, streaming(&cfg, -0.1));
        outs.extend(run(&mut core, 1.0, silence));
        outs.iter()
            .filter_map(|o| o.truth)
            .zip(outs.iter().filter(|o| o.truth.is_some()).map(|o| {
                o.messages
                    .iter()
                    .find_map(|m| match &m.message {
                        MavMessage::LOCAL_POSITION_NED(d) => Some([d.x, d.y, d.z]),
                        _ => None,
                    })
                    .unwrap()
            }))
            .collect::<Vec<_>>()
    };
    let (a, b) = (flight(), flight());
    assert_eq!(a.len(), 100);
    assert_eq!(a, b);
    // The reported position is noisy (σ = sitl.noise_sigma), the truth not.
    assert!(
        a.iter()
            .any(|(t, p)| (f64::from(p[0]) - t.position[0]).abs() > 1e-4)
    );
}

#[test]
fn a_late_clock_catches_up_in_one_step_and_counts_it() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let dt = core.step_period();
    let out = core.step(10.0 * dt + 1e-9, []);
    assert_eq!((out.counts.plant_steps, out.counts.late_steps), (10, 9));
    assert!((core.time() - 10.0 * dt).abs() < 1e-12);
    // Early or on time: one step, none late.
    let out = core.step(core.time(), []);
    assert_eq!((out.counts.plant_steps, out.counts.late_steps), (1, 0));
}

#[test]
fn a_parameter_set_changes_the_offboard_loss_timeout() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    run(&mut core, 0.2, streaming(&cfg, 0.0));
    let set = MavMessage::PARAM_SET(PARAM_SET_DATA {
        param_value: 1.0,
        target_system: 1,
        target_component: 1,
        param_id: dflat_link::params::param_id("COM_OF_LOSS_T"),
        param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
    });
    let out = core.step(core.next_step_time(), [from_gcs(core.time(), set)]);
    assert_eq!(out.counts.params_set, 1);
    let echo = out
        .messages
        .iter()
        .find(|m| matches!(m.message, MavMessage::PARAM_VALUE(_)))
        .expect("no PARAM_VALUE");
    assert_eq!(echo.to, Dest::Only(Link::Gcs));
    // Silence: still offboard after the old 0.5 s, held after 1 s.
    let outs = run(&mut core, 0.8, silence);
    assert!(outs.iter().all(|o| o.status.mode == SitlMode::Offboard));
    let outs = run(&mut core, 0.3, silence);
    assert_eq!(outs.last().unwrap().status.mode, SitlMode::Hold);
}

#[test]
fn a_disarm_is_acked_on_its_link_and_heard_in_the_status() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    run(&mut core, 0.1, silence);
    let disarm = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
        target_system: 1,
        target_component: 1,
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        param1: 0.0,
        ..Default::default()
    });
    let out = core.step(core.next_step_time(), [from_gcs(core.time(), disarm)]);
    assert!(!out.status.armed);
    assert_eq!(out.events, vec![SitlEvent::ArmedChanged(false)]);
    assert_eq!(out.counts.commands_acked, 1);
    let ack = ack_of(&out);
    assert_eq!(ack, (Dest::Only(Link::Gcs), MavResult::MAV_RESULT_ACCEPTED));
    // Disarmed, a stream is not flown.
    let outs = run(&mut core, 0.3, streaming(&cfg, -0.3));
    assert!(
        outs.iter()
            .filter_map(|o| o.truth)
            .all(|t| t.command.is_none())
    );
}

#[test]
fn an_offboard_request_without_a_stream_is_refused_in_words() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let out = core.step(
        core.next_step_time(),
        [SitlInput::ModeRequest(SitlMode::Offboard)],
    );
    assert_eq!(out.counts.offboard_refused, 1);
    assert_eq!(out.status.mode, SitlMode::Hold);
    assert!(out.messages.iter().any(|m| m.to == Dest::Both
        && matches!(&m.message, MavMessage::STATUSTEXT(t)
            if t.text.to_str().is_ok_and(|s| s.contains("offboard refused")))));
}

#[test]
fn one_shot_pose_faults_drop_and_delay_the_next_poses() {
    let cfg = config();
    let mut core = SitlCore::new(&cfg).unwrap();
    let positions = |outs: &[SitlOutput]| {
        all_names(outs)
            .iter()
            .filter(|m| **m == "LOCAL_POSITION_NED")
            .count()
    };
    let outs = run(&mut core, 0.2, once(SitlInput::DropNextPoses(3)));
    // 10 telemetry steps in 0.2 s, the first 3 poses dropped.
    assert_eq!(positions(&outs), 7);
    let dropped: u64 = outs
        .iter()
        .map(|o| o.counts.pose_latency.poses_dropped)
        .sum();
    assert_eq!(dropped, 3);
    // A pose 12 ms late goes out 3 plant steps after its telemetry step.
    let outs = run(&mut core, 0.04, once(SitlInput::DelayNextPose(0.012)));
    let with_truth = outs.iter().position(|o| o.truth.is_some()).unwrap();
    assert_eq!(outs[with_truth].counts.pose_latency.poses_delayed, 1);
    assert!(!names(&outs[with_truth]).contains(&"LOCAL_POSITION_NED"));
    let late = outs
        .iter()
        .position(|o| names(o).contains(&"LOCAL_POSITION_NED"))
        .expect("the delayed pose never left");
    assert_eq!(late, with_truth + 3);
}

/// SET_MESSAGE_INTERVAL from the daemon's link sets how often ATTITUDE
/// and LOCAL_POSITION_NED go out (from 5 Hz to 50 Hz, each on its own),
/// ACKed on that link; with `sitl.fixed_telemetry_rate` it is DENIED and
/// the rate stays.
#[test]
fn the_daemon_sets_the_pose_and_attitude_rates_unless_fixed() {
    let count = |outs: &[SitlOutput], name: &str| {
        all_names(outs).into_iter().filter(|n| *n == name).count()
    };
    let from_daemon = |at: f64, id: u32| SitlInput::Frame {
        at,
        link: Link::Vehicle,
        header: dflat_link::header(1, 191, 0),
        message: Box::new(dflat_link::command::set_message_interval(
            (1, 1),
            id,
            20_000.0,
            0,
        )),
    };
    for fixed in [false, true] {
        let mut cfg = config();
        cfg.sitl.telemetry_rate_hz = 5.0;
        cfg.sitl.fixed_telemetry_rate = fixed;
        let mut core = SitlCore::new(&cfg).unwrap();
        // The ground station's request is refused: the rate is the
        // vehicle link's.
        let gcs = dflat_link::command::set_message_interval((1, 1), 32, 20_000.0, 0);
        let out = core.step(core.next_step_time(), [from_gcs(core.time(), gcs)]);
        assert_eq!(
            ack_of(&out),
            (Dest::Only(Link::Gcs), MavResult::MAV_RESULT_DENIED)
        );
        let outs = run(&mut core, 1.0, silence);
        assert_eq!(count(&outs, "LOCAL_POSITION_NED"), 5);
        assert_eq!(count(&outs, "ATTITUDE"), 5);
        let out = core.step(core.next_step_time(), [from_daemon(core.time(), 32)]);
        let ack = ack_of(&out);
        let want = if fixed {
            MavResult::MAV_RESULT_DENIED
        } else {
            MavResult::MAV_RESULT_ACCEPTED
        };
        assert_eq!(ack, (Dest::Only(Link::Vehicle), want));
        let outs = run(&mut core, 2.0, silence);
        let (position, attitude) = (count(&outs, "LOCAL_POSITION_NED"), count(&outs, "ATTITUDE"));
        if fixed {
            assert_eq!((position, attitude), (10, 10), "fixed");
        } else {
            assert!((99..=101).contains(&position), "{position} at 50 Hz");
            assert_eq!(attitude, 10, "ATTITUDE not asked yet");
            core.step(core.next_step_time(), [from_daemon(core.time(), 30)]);
            let outs = run(&mut core, 1.0, silence);
            let attitude = count(&outs, "ATTITUDE");
            assert!((49..=51).contains(&attitude), "{attitude} at 50 Hz");
        }
    }
}
