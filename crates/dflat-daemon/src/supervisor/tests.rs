//! Supervisor state machine tests: scenarios flown with the failsafe
//! machine beside the supervisor, as the control core drives them
//! ([`Flight`]).
use std::ops::{Deref, DerefMut};

use super::*;
use crate::tick::failsafe::{self, Action, Event, Failsafe, Health, LevelPlan, Limits};
use FlightState::*;

/// The failsafe machine's settings here: no fallback ladder, no level
/// hover streamed (the core's side of it is tested in `tick/`).
const LIMITS: Limits = Limits {
    hold_ticks: 0,
    level_hover_max: 0.0,
    period: 0.02,
};

/// The supervisor and the failsafe machine, driven as the control core
/// drives them: at each tick the machine hears the tick's facts first and
/// enters or clears the failsafe; otherwise the flight state moves on.
struct Flight {
    s: Supervisor,
    failsafe: Failsafe,
}

impl Deref for Flight {
    type Target = Supervisor;
    fn deref(&self) -> &Supervisor {
        &self.s
    }
}

impl DerefMut for Flight {
    fn deref_mut(&mut self) -> &mut Supervisor {
        &mut self.s
    }
}

impl Flight {
    fn new(cfg: SupervisorConfig) -> Self {
        Self {
            s: Supervisor::new(cfg),
            failsafe: Failsafe::Nominal,
        }
    }

    /// Feeds `event` to the machine and carries out its entry or clearing.
    fn feed(&mut self, t: f64, event: Event) -> Option<Transition> {
        let (state, action) = failsafe::next(self.failsafe, event, &LIMITS);
        self.failsafe = state;
        match action {
            Action::Enter { cause, .. } => self.s.enter_failsafe(t, cause),
            Action::Recover => self.s.recover(t),
            _ => None,
        }
    }

    /// The tick at `t`.
    fn tick(&mut self, t: f64) -> TickDecision {
        let (links, state) = (self.s.links(t), self.s.state());
        let health = Health::of(t, links, state, self.s.stopping(), LevelPlan::NONE);
        match self.feed(t, Event::Health(health)) {
            Some(tr) => TickDecision {
                stream: self.s.state().streams(),
                transition: Some(tr),
            },
            None => self.s.tick(t),
        }
    }

    /// A cause the core found at `t` (the residual, the stop's level).
    fn trip(&mut self, t: f64, cause: Cause) -> Option<Transition> {
        let engaged = self.s.state().engaged();
        let tripped = Event::Tripped {
            t,
            cause,
            engaged,
            level: LevelPlan::NONE,
        };
        self.feed(t, tripped)
    }
}

const P0: [f64; 3] = [1.0, 2.0, -10.0];
const START: [f64; 3] = [-20.0, -30.0, -10.0];
const END: [f64; 3] = [0.0, 0.0, -10.0];

fn cfg() -> SupervisorConfig {
    SupervisorConfig {
        pose_timeout: 0.1,
        autopilot_timeout: 3.0,
        envelope: crate::envelope::Envelope::from_config(&crate::config::Config::default()),
        path_ends: Some((START, END)),
        path_trigger_radius: 0.5,
        start_path: false,
        repeat_path: false,
        // The tests below predate engagement: every command applied.
        always_engaged: true,
        resume_on_engage: true,
        brake_acceleration: 4.0,
    }
}

/// Engagement read from the autopilot's mode.
fn cfg_mode() -> SupervisorConfig {
    SupervisorConfig {
        always_engaged: false,
        ..cfg()
    }
}

fn moving(t: f64, x: f64, vx: f64) -> Option<Motion> {
    Some(Motion {
        t,
        position: [x, 0.0, -10.0],
        velocity: [vx, 0.0, 0.0],
    })
}

/// Feeds poses and heartbeats at 50 Hz from `from` to `to` \[s\] and ticks
/// at 50 Hz, returning the decisions.
fn fly(s: &mut Flight, from: f64, to: f64, pose: bool, hb: bool) -> Vec<TickDecision> {
    let mut out = Vec::new();
    let mut t = from;
    while t < to - 1e-9 {
        if pose {
            s.on_pose(t, P0);
            s.set_motion(moving(t, P0[0], 0.0));
        }
        if hb {
            s.on_heartbeat(t);
        }
        out.push(s.tick(t + 0.005));
        t += 0.02;
    }
    out
}

#[test]
fn waits_for_pose_and_heartbeat_then_holds_the_first_position() {
    let mut s = Flight::new(cfg());
    assert_eq!(s.state(), WaitingForPose);
    let d = s.tick(0.0);
    assert!(!d.stream && d.transition.is_none());
    // Pose but no autopilot heartbeat: still waiting, not streaming.
    s.on_pose(0.01, P0);
    assert!(!s.tick(0.02).stream);
    s.on_heartbeat(0.03);
    s.on_pose(0.03, P0);
    let d = s.tick(0.04);
    assert!(d.stream);
    let tr = d.transition.unwrap();
    assert_eq!(
        (tr.from, tr.to, tr.cause),
        (WaitingForPose, Holding, Cause::FoundEngaged)
    );
    assert_eq!(s.goal(), Goal::Hold(P0));
    assert!(tr.text().len() <= 50, "{}", tr.text());
    // Steady: streaming, no further transitions.
    assert!(
        fly(&mut s, 0.06, 1.0, true, true)
            .iter()
            .all(|d| d.stream && d.transition.is_none())
    );
}

#[test]
fn stale_pose_stops_the_stream_and_resets_then_fresh_pose_resumes_holding_here() {
    let mut s = Flight::new(cfg());
    fly(&mut s, 0.0, 1.0, true, true);
    assert_eq!(s.state(), Holding);
    // Poses stop at 0.98; heartbeats continue.
    let d = fly(&mut s, 1.0, 2.0, false, true);
    let first_off = d.iter().position(|d| !d.stream).unwrap();
    // Last pose at 0.98; tick at 1.005 + 0.02 k; stale once t − 0.98 > 0.1.
    assert_eq!(
        first_off, 4,
        "ticks: stream stops within the 100 ms timeout"
    );
    let tr = d[first_off].transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Failsafe, Cause::PoseStale));
    assert!(
        d[first_off + 1..]
            .iter()
            .all(|d| !d.stream && d.transition.is_none())
    );
    assert_eq!(s.state(), Failsafe);
    // A setpoint is refused in failsafe.
    assert_eq!(
        s.on_setpoint(1.5, [0.0; 3]),
        SetpointOutcome::Refused(Refusal::NotInControl(Failsafe))
    );
    // Pose resumes at a new place: hold there.
    let here = [5.0, 5.0, -10.0];
    s.on_pose(2.0, here);
    // One pose after the gap: no motion yet (as the core reports it).
    s.set_motion(None);
    let d = s.tick(2.005);
    assert!(d.stream);
    assert_eq!(d.transition.unwrap().to, Holding);
    assert_eq!(s.goal(), Goal::Hold(here));
}

#[test]
fn pose_jump_re_anchors_and_residual_failsafe_latches() {
    let mut s = Flight::new(cfg());
    // Not streaming: nothing to re-anchor.
    assert!(s.re_anchor(0.0, P0).is_none());
    fly(&mut s, 0.0, 1.0, true, true);
    assert!(matches!(
        s.on_setpoint(1.0, END),
        SetpointOutcome::Accepted { .. }
    ));
    assert_eq!(s.state(), Tracking);
    let jumped = [6.0, 2.0, -10.0];
    let tr = s.re_anchor(1.01, jumped).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::PoseJump));
    assert!(tr.text().len() <= 50, "{}", tr.text());
    assert_eq!(s.goal(), Goal::Hold(jumped));
    // The same setpoint again is accepted after the re-anchor.
    assert!(matches!(
        s.on_setpoint(1.02, END),
        SetpointOutcome::Accepted { .. }
    ));
    // Residual failsafe: no recovery while the failsafe machine latches
    // it, although pose is fresh.
    let tr = s.trip(1.1, Cause::ResidualDiverged).unwrap();
    assert_eq!(tr.to, Failsafe);
    assert!(tr.text().len() <= 50, "{}", tr.text());
    for i in 0..20 {
        let t = 1.1 + 0.02 * f64::from(i);
        s.on_pose(t, P0);
        s.on_heartbeat(t);
        assert!(!s.tick(t + 0.005).stream);
    }
    assert_eq!(s.state(), Failsafe);
    assert!(fly(&mut s, 3.1, 3.2, true, true).iter().any(|d| d.stream));
    assert_eq!(s.state(), Holding);
}

#[test]
fn silent_autopilot_is_a_failsafe_too() {
    let mut s = Flight::new(cfg());
    fly(&mut s, 0.0, 1.0, true, true);
    let d = fly(&mut s, 1.0, 5.0, true, false);
    let off = d.iter().position(|d| !d.stream).unwrap();
    assert_eq!(d[off].transition.unwrap().cause, Cause::AutopilotSilent);
    // Heartbeat back + fresh pose: holding.
    let d = fly(&mut s, 5.0, 5.1, true, true);
    assert_eq!(d[0].transition.unwrap().to, Holding);
}

#[test]
fn setpoints_track_refuse_and_trigger_the_path() {
    let mut s = Flight::new(cfg());
    // Before pose: refused.
    assert!(matches!(
        s.on_setpoint(0.0, [1.0, 1.0, -5.0]),
        SetpointOutcome::Refused(Refusal::NotInControl(WaitingForPose))
    ));
    fly(&mut s, 0.0, 0.5, true, true);
    let g0 = s.goal_generation();
    let SetpointOutcome::Accepted { goal, transition } = s.on_setpoint(0.5, [10.0, 0.0, -10.0])
    else {
        panic!()
    };
    assert_eq!(goal, Goal::Setpoint([10.0, 0.0, -10.0]));
    assert_eq!(transition.unwrap().to, Tracking);
    assert_eq!(s.goal_generation(), g0 + 1);
    // The same setpoint again (a GCS streaming it): unchanged.
    assert_eq!(
        s.on_setpoint(0.6, [10.0, 0.0, -10.0]),
        SetpointOutcome::Unchanged
    );
    assert_eq!(s.goal_generation(), g0 + 1);
    // Outside the fence, or NaN: refused, goal kept.
    let r = s.on_setpoint(0.7, [600.0, 0.0, -10.0]);
    assert!(matches!(
        r,
        SetpointOutcome::Refused(Refusal::Geofence { .. })
    ));
    if let SetpointOutcome::Refused(r) = r {
        assert!(r.text().len() <= 50, "{}", r.text());
    }
    assert_eq!(
        s.on_setpoint(0.7, [f64::NAN, 0.0, 0.0]),
        SetpointOutcome::Refused(Refusal::NonFinite)
    );
    assert_eq!(s.goal(), Goal::Setpoint([10.0, 0.0, -10.0]));
    // Near the first waypoint: the path starts (already tracking: no transition).
    let r = s.on_setpoint(0.8, [-20.2, -30.1, -10.0]);
    assert_eq!(
        r,
        SetpointOutcome::Accepted {
            goal: Goal::Path,
            transition: None
        }
    );
    // Path done: hold its end.
    let tr = s.on_path_finished(5.0).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::PathFinished));
    assert_eq!(s.goal(), Goal::Hold(END));
    assert!(s.on_path_finished(5.1).is_none());
    // The GCS still streams the trigger setpoint: the path does not restart.
    assert_eq!(
        s.on_setpoint(5.2, [-20.2, -30.1, -10.0]),
        SetpointOutcome::Unchanged
    );
    assert_eq!(s.state(), Holding);
}

#[test]
fn mission_start_path_tracks_at_once_and_time_in_states_adds_up() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        ..cfg_mode()
    });
    s.tick(0.0);
    s.on_pose(0.5, P0);
    s.on_heartbeat(0.5);
    s.on_mode(false);
    // At rest, the pilot flying: standby, the path pending.
    s.set_motion(moving(0.5, P0[0], 0.0));
    let tr = s.tick(0.5).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Standby, Cause::PoseFresh));
    assert_eq!(s.pending_goal(), Goal::Path);
    // The engagement the daemon sees: holding, the path at the next tick.
    s.on_mode(true);
    let tr = s.tick(0.52).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::Engaged));
    let tr = s.tick(0.54).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Tracking, Cause::MissionStart));
    assert_eq!(s.goal(), Goal::Path);
    let tr = s.tick(0.7).transition.unwrap(); // pose 0.2 s old
    assert_eq!(tr.to, Failsafe);
    let t = s.time_in_states(1.0);
    assert!((t[WaitingForPose.index()] - 0.5).abs() < 1e-12);
    assert!((t[Standby.index()] - 0.02).abs() < 1e-12);
    assert!((t[Holding.index()] - 0.02).abs() < 1e-12);
    assert!((t[Tracking.index()] - 0.16).abs() < 1e-12);
    assert!((t[Failsafe.index()] - 0.3).abs() < 1e-12);
    assert_eq!(s.transitions(), 4);
    // Recovery holds (does not restart the path).
    s.on_pose(1.0, P0);
    s.on_heartbeat(1.0);
    assert_eq!(s.tick(1.0).transition.unwrap().to, Holding);
}

#[test]
fn standby_follows_the_stop_point_until_the_autopilot_applies_commands() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        ..cfg_mode()
    });
    s.on_heartbeat(0.0);
    s.on_mode(false);
    // The pilot flies north at 2 m/s: standby, the goal a stop from
    // wherever the vehicle is.
    for k in 0..10 {
        let t = k as f64 * 0.02;
        s.on_pose(t, [2.0 * t, 0.0, -10.0]);
        s.set_motion(moving(t, 2.0 * t, 2.0));
        let d = s.tick(t);
        assert!(d.stream, "standby streams");
        assert_eq!(s.state(), Standby);
        assert_eq!(
            s.goal(),
            Goal::Brake {
                from: [2.0 * t, 0.0, -10.0],
                velocity: [2.0, 0.0, 0.0]
            }
        );
    }
    assert_eq!(s.pending_goal(), Goal::Path);
    // A setpoint in standby is kept for after the engagement.
    let sp = [3.0, 1.0, -10.0];
    assert!(matches!(
        s.on_setpoint(0.19, sp),
        SetpointOutcome::Accepted {
            transition: None,
            ..
        }
    ));
    assert_eq!(s.state(), Standby);
    assert_eq!(s.pending_goal(), Goal::Setpoint(sp));
    // The pilot switches to OFFBOARD at x = 0.4 m: brake from there.
    s.on_mode(true);
    s.on_pose(0.2, [0.4, 0.0, -10.0]);
    s.set_motion(moving(0.2, 0.4, 2.0));
    let tr = s.tick(0.2).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::Engaged));
    let brake = Goal::Brake {
        from: [0.4, 0.0, -10.0],
        velocity: [2.0, 0.0, 0.0],
    };
    assert_eq!(s.goal(), brake);
    assert!(s.braking());
    // Still fast: the goal stays; slow: the setpoint is flown.
    s.on_pose(0.4, [0.8, 0.0, -10.0]);
    s.set_motion(moving(0.4, 0.8, 1.0));
    assert!(s.tick(0.4).transition.is_none());
    assert_eq!(s.goal(), brake, "frozen at the engagement");
    s.on_pose(0.7, [0.9, 0.0, -10.0]);
    s.set_motion(moving(0.7, 0.9, 0.1));
    let tr = s.tick(0.7).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Tracking, Cause::Resume));
    assert_eq!(s.goal(), Goal::Setpoint(sp));
    // Pilot override: standby at once, the setpoint kept for later.
    s.on_mode(false);
    s.on_pose(0.72, [1.0, 0.0, -10.0]);
    s.set_motion(moving(0.72, 1.0, 0.0));
    let tr = s.tick(0.72).transition.unwrap();
    assert_eq!((tr.to, tr.cause), (Standby, Cause::PilotControl));
    assert_eq!(s.pending_goal(), Goal::Setpoint(sp));
    assert_eq!(s.goal(), Goal::Hold([1.0, 0.0, -10.0]));
    // Hand-back at rest: holding, then the setpoint again.
    s.on_mode(true);
    s.on_pose(0.74, [1.0, 0.0, -10.0]);
    assert_eq!(s.tick(0.74).transition.unwrap().to, Holding);
    s.on_pose(0.76, [1.0, 0.0, -10.0]);
    assert_eq!(s.tick(0.76).transition.unwrap().to, Tracking);
    assert_eq!(s.goal(), Goal::Setpoint(sp));
    assert_eq!(s.engagement_counts(), (2, 1));
    let t = s.time_in_states(0.76);
    assert!((t[Standby.index()] - (0.2 + 0.02)).abs() < 1e-9, "{t:?}");
}

#[test]
fn hold_on_engage_forgets_the_goal_before_the_override() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        resume_on_engage: false,
        ..cfg_mode()
    });
    s.on_heartbeat(0.0);
    s.on_mode(false);
    s.on_pose(0.0, P0);
    s.set_motion(moving(0.0, P0[0], 0.0));
    assert_eq!(s.tick(0.0).transition.unwrap().to, Standby);
    s.on_mode(true);
    assert_eq!(s.tick(0.0).transition.unwrap().to, Holding);
    // The mission start flies the path at the first engagement.
    assert_eq!(s.tick(0.02).transition.unwrap().to, Tracking);
    assert_eq!(s.goal(), Goal::Path);
    s.on_mode(false);
    assert_eq!(s.tick(0.04).transition.unwrap().to, Standby);
    assert_eq!(s.pending_goal(), Goal::None);
    s.on_mode(true);
    assert_eq!(s.tick(0.06).transition.unwrap().to, Holding);
    // Braked, nothing to resume: holding where it stopped.
    assert!(s.tick(0.08).transition.is_none());
    assert_eq!(s.state(), Holding);
    assert!(!s.braking());
    // (The motion's position: x of P0, y = 0.)
    assert_eq!(s.goal(), Goal::Hold([P0[0], 0.0, -10.0]));
}

#[test]
fn braking_ends_after_its_time_even_if_never_slow() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        ..cfg_mode()
    });
    s.on_heartbeat(0.0);
    s.on_pose(0.0, P0);
    s.on_mode(false);
    // 2 m/s at a = 4 m/s²: 0.5 s of braking, + BRAKE_SETTLE.
    s.set_motion(moving(0.0, P0[0], 2.0));
    assert_eq!(s.tick(0.0).transition.unwrap().to, Standby);
    s.on_mode(true);
    assert_eq!(s.tick(0.0).transition.unwrap().to, Holding);
    let end = 0.5 + BRAKE_SETTLE;
    let mut t = 0.02;
    while t < end - 0.01 {
        s.on_pose(t, P0);
        s.on_heartbeat(t);
        assert!(s.tick(t).transition.is_none(), "at {t}");
        t += 0.02;
    }
    s.on_pose(end, P0);
    s.on_heartbeat(end);
    assert_eq!(s.tick(end + 0.001).transition.unwrap().to, Tracking);
}

#[test]
fn repeated_path_starts_again_instead_of_holding() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        repeat_path: true,
        ..cfg_mode()
    });
    s.on_mode(false);
    fly(&mut s, 0.0, 0.1, true, true);
    s.on_mode(true);
    fly(&mut s, 0.1, 0.2, true, true);
    assert_eq!((s.state(), s.goal()), (Tracking, Goal::Path));
    let g = s.goal_generation();
    assert!(s.on_path_finished(5.0).is_none());
    assert_eq!((s.state(), s.goal()), (Tracking, Goal::Path));
    assert_eq!(s.goal_generation(), g + 1);
}

#[test]
fn out_of_order_arrivals_do_not_refresh() {
    let mut s = Flight::new(cfg());
    fly(&mut s, 0.0, 0.2, true, true);
    s.on_pose(0.1, [9.0; 3]); // older than the newest
    let d = s.tick(0.35);
    assert_eq!(d.transition.unwrap().to, Failsafe);
}

#[test]
fn a_stream_is_tracked_kept_across_a_hand_back_and_held_when_lost() {
    let mut s = Flight::new(cfg_mode());
    s.on_mode(true);
    fly(&mut s, 0.0, 0.5, true, true);
    assert_eq!(s.state(), Holding);
    // Braked (at rest): the first sample starts the stream.
    fly(&mut s, 0.5, 3.0, true, true);
    let g0 = s.goal_generation();
    let out = s.on_stream(3.0, [2.0, 2.0, -10.0]);
    assert!(matches!(
        out,
        SetpointOutcome::Accepted {
            goal: Goal::Stream,
            transition: Some(_)
        }
    ));
    assert_eq!((s.state(), s.goal()), (Tracking, Goal::Stream));
    assert_eq!(s.goal_generation(), g0 + 1);
    // Further samples refresh the reference, not the goal.
    assert_eq!(
        s.on_stream(3.05, [2.1, 2.0, -10.0]),
        SetpointOutcome::Unchanged
    );
    assert_eq!(s.goal_generation(), g0 + 1);
    // Refused like setpoints.
    assert!(matches!(
        s.on_stream(3.1, [f64::NAN, 0.0, -10.0]),
        SetpointOutcome::Refused(Refusal::NonFinite)
    ));
    assert!(matches!(
        s.on_stream(3.1, [900.0, 0.0, -10.0]),
        SetpointOutcome::Refused(Refusal::Geofence { .. })
    ));
    // Pilot override, hand-back: the stream resumes once braked.
    s.on_mode(false);
    fly(&mut s, 3.1, 3.5, true, true);
    assert_eq!((s.state(), s.pending_goal()), (Standby, Goal::Stream));
    s.on_mode(true);
    fly(&mut s, 3.5, 6.0, true, true);
    assert_eq!((s.state(), s.goal()), (Tracking, Goal::Stream));
    // Lost: hold where the stream stops.
    let tr = s.on_stream_timeout(6.0, [3.0, 2.0, -10.0]).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::StreamTimeout));
    assert_eq!(s.goal(), Goal::Hold([3.0, 2.0, -10.0]));
    assert!(s.on_stream_timeout(6.1, [0.0; 3]).is_none(), "once");
    assert!(
        Refusal::StreamJump { distance: 12.34 }
            .text()
            .contains("12.3 m")
    );
}

/// A daemon (re)started while the autopilot already applies its commands
/// (ArduPilot stays in GUIDED; PX4 within COM_OF_LOSS_T) brakes and holds
/// where the vehicle is: `mission.start = "path"` waits for an engagement
/// it sees happen, a setpoint or a mission start.
#[test]
fn a_start_found_engaged_holds_and_the_path_waits_for_an_explicit_start() {
    let mut s = Flight::new(SupervisorConfig {
        start_path: true,
        ..cfg_mode()
    });
    s.on_mode(true);
    let d = fly(&mut s, 0.0, 1.0, true, true);
    let tr = d.iter().find_map(|d| d.transition).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::FoundEngaged));
    assert!(tr.text().len() <= 50, "{}", tr.text());
    // (The motion's position: x of P0, y = 0.)
    assert_eq!(
        (s.state(), s.goal()),
        (Holding, Goal::Hold([P0[0], 0.0, -10.0]))
    );
    assert_eq!(s.pending_goal(), Goal::None);
    // The pilot takes over and hands back: that start is explicit.
    s.on_mode(false);
    fly(&mut s, 1.0, 1.1, true, true);
    assert_eq!(s.state(), Standby);
    s.on_mode(true);
    fly(&mut s, 1.1, 1.2, true, true);
    assert_eq!((s.state(), s.goal()), (Tracking, Goal::Path));
}

/// A vehicle faster than the limit is braked from its motion; a stop
/// refuses every goal after it and, engaged, brakes.
#[test]
fn overspeed_brakes_and_a_stop_refuses_goals() {
    let mut s = Flight::new(cfg());
    fly(&mut s, 0.0, 0.1, true, true);
    assert!(matches!(
        s.on_setpoint(0.1, [5.0, 0.0, -10.0]),
        SetpointOutcome::Accepted { .. }
    ));
    s.set_motion(moving(0.12, 3.0, 20.0));
    let tr = s.overspeed(0.12).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::Overspeed));
    assert!(tr.is_failsafe(), "said as critical");
    assert_eq!(
        s.goal(),
        Goal::Brake {
            from: [3.0, 0.0, -10.0],
            velocity: [20.0, 0.0, 0.0]
        }
    );
    let tr = s.begin_stop(0.2).unwrap();
    assert_eq!((tr.to, tr.cause), (Holding, Cause::Shutdown));
    assert_eq!(
        s.on_setpoint(0.21, [5.0, 0.0, -10.0]),
        SetpointOutcome::Refused(Refusal::Stopping)
    );
    assert_eq!(s.on_mission_start(0.22), Err(Refusal::Stopping));
    // The level phase is a failsafe that does not recover on fresh pose.
    s.trip(0.3, Cause::ShutdownLevel).unwrap();
    fly(&mut s, 0.3, 0.5, true, true);
    assert_eq!(s.state(), Failsafe);
}

/// The fence has a floor apart from its ceiling: 150 m below the origin
/// is refused although a symmetric ±200 m fence would take it.
#[test]
fn a_setpoint_below_the_floor_is_refused() {
    let mut s = Flight::new(cfg());
    fly(&mut s, 0.0, 0.1, true, true);
    let below = [0.0, 0.0, 150.0];
    assert_eq!(
        s.on_setpoint(0.1, below),
        SetpointOutcome::Refused(Refusal::Geofence { position: below })
    );
    assert!(matches!(
        s.on_setpoint(0.1, [0.0, 0.0, -150.0]),
        SetpointOutcome::Accepted { .. }
    ));
}
