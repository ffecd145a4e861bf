//! The failsafe machine's transition table, checked as a table: every
//! (state, event) pair is listed with the state and action it must give.

use std::collections::BTreeSet;

use super::*;

const LIMITS: Limits = Limits {
    hold_ticks: 2,
    level_hover_max: 0.1,
    period: 0.02,
};

const LEVEL: AttitudeCommand = AttitudeCommand {
    roll: 0.0,
    pitch: 0.0,
    yaw: 0.5,
    thrust: 0.45,
};

/// Brake (pitch, roll) for 40 ms, then level.
const PLAN: LevelPlan = LevelPlan {
    command: LEVEL,
    brake: Some(([0.1, -0.05], 0.04)),
};

const BRAKE: AttitudeCommand = AttitudeCommand {
    roll: -0.05,
    pitch: 0.1,
    yaw: 0.5,
    thrust: 0.45,
};

use Failsafe as S;

const N: S = S::Nominal;
const P: S = S::PlanFallback { failed: 3 };
const H: S = S::HeldCommand { failed: 1, held: 1 };
/// Held as long as allowed (`hold_ticks` = 2).
const H_OUT: S = S::HeldCommand { failed: 2, held: 2 };
const L: S = S::LevelHover {
    failed: 4,
    since: 1.0,
};
const FL: S = S::FailsafeLevel {
    since: 1.0,
    plan: PLAN,
    clear: Clear::WhenCauseClears,
};
const FL_LATCHED: S = S::FailsafeLevel {
    since: 1.0,
    plan: PLAN,
    clear: Clear::NotBefore(3.0),
};
const G: S = S::LetGo {
    clear: Clear::WhenCauseClears,
};
const G_LATCHED: S = S::LetGo {
    clear: Clear::NotBefore(3.0),
};
/// Two good ticks after a streak of three failed ticks that held.
const R: S = S::Recovering {
    failed: 3,
    from: FallbackKind::Held,
    good: 2,
};
/// One good tick short of [`RECOVERY_S`] (50 ticks at 0.02 s).
const R_LAST: S = S::Recovering {
    failed: 3,
    from: FallbackKind::Held,
    good: 49,
};
const T: S = S::Trial { good: 2 };
const T_LAST: S = S::Trial {
    good: TRIAL_TICKS - 1,
};

const fn failed(t: f64, planned: bool, can_hold: bool) -> Event {
    Event::Failed {
        t,
        planned,
        can_hold,
    }
}

const fn tripped(cause: Cause, engaged: bool) -> Event {
    Event::Tripped {
        t: 1.04,
        cause,
        engaged,
        level: PLAN,
    }
}

/// The facts of a tick at 1.04 s.
const fn health(pose_fresh: bool, autopilot_alive: bool, streaming: bool, engaged: bool) -> Event {
    Event::Health(Health {
        t: 1.04,
        pose_fresh,
        autopilot_alive,
        streaming,
        engaged,
        stopping: false,
        level: PLAN,
    })
}

/// Engaged, the pose stale.
const STALE: Event = health(false, true, true, true);
/// Standing by (streaming, not engaged), the pose stale.
const STALE_STANDBY: Event = health(false, true, true, false);
/// Engaged, the autopilot silent.
const SILENT: Event = health(true, false, true, true);
/// Not streaming (waiting, or in the failsafe), the pose stale.
const OFF_STALE: Event = health(false, true, false, false);
/// Fresh pose, the autopilot alive, not streaming (in the failsafe).
const FINE: Event = health(true, true, false, false);
/// As [`FINE`], the daemon stopping.
const STOPPING: Event = Event::Health(Health {
    t: 1.04,
    pose_fresh: true,
    autopilot_alive: true,
    streaming: false,
    engaged: false,
    stopping: true,
    level: PLAN,
});

/// The kind of an event, for the coverage check: the facts of a tick by
/// what they say.
fn event_name(e: &Event) -> &'static str {
    match e {
        Event::Solved => "solved",
        Event::Failed { .. } => "failed",
        Event::Tripped { .. } => "tripped",
        Event::Health(h) => match (h.cause(), h.streaming, h.stopping) {
            (Some(Cause::PoseStale), true, _) => "pose_stale",
            (Some(_), true, _) => "autopilot_silent",
            (Some(_), false, _) => "stale_not_streaming",
            (None, _, true) => "fine_stopping",
            (None, _, false) => "fine",
        },
        Event::Idle { .. } => "idle",
        Event::TrialSolve { .. } => "trial_solve",
        Event::LevelRefused => "level_refused",
    }
}

/// Enter the failsafe for `cause`, levelling (announced) or not.
const fn enter(cause: Cause, level: bool) -> Action {
    Action::Enter {
        cause,
        level: if level { Some(true) } else { None },
    }
}

/// The fallback ladder ran out: let go.
const LET_GO: Action = Action::Enter {
    cause: Cause::ControlFailed,
    level: None,
};

const fn fallback(kind: FallbackKind, announce: bool) -> Action {
    Action::Fallback { kind, announce }
}

use Action as A;
use FallbackKind::{Held, LevelHover, Plan};

/// A residual failsafe entered at 1.04 s.
const LATCH: Clear = Clear::NotBefore(1.04 + RESIDUAL_FAILSAFE_LATCH);
const FL_AT: S = S::FailsafeLevel {
    since: 1.04,
    plan: PLAN,
    clear: Clear::WhenCauseClears,
};
const FL_AT_LATCHED: S = S::FailsafeLevel {
    since: 1.04,
    plan: PLAN,
    clear: LATCH,
};
const PLAN_FAIL: Event = failed(1.04, true, true);
const HOLD_FAIL: Event = failed(1.04, false, true);
const BARE_FAIL: Event = failed(1.04, false, false);
const LATE_FAIL: Event = failed(1.09, false, true);

/// (state, event, next state, action).
const TABLE: &[(S, Event, S, Action)] = &[
    // A good tick starts a fallback streak's recovery; RECOVERY_S of
    // good ticks in a row end it.
    (N, Event::Solved, N, A::None),
    (
        P,
        Event::Solved,
        S::Recovering {
            failed: 3,
            from: Plan,
            good: 1,
        },
        A::None,
    ),
    (
        H,
        Event::Solved,
        S::Recovering {
            failed: 1,
            from: Held,
            good: 1,
        },
        A::None,
    ),
    (
        L,
        Event::Solved,
        S::Recovering {
            failed: 4,
            from: LevelHover,
            good: 1,
        },
        A::None,
    ),
    (
        R,
        Event::Solved,
        S::Recovering {
            failed: 3,
            from: Held,
            good: 3,
        },
        A::None,
    ),
    (R_LAST, Event::Solved, N, A::Recovered { failed: 3 }),
    // A failure in the recovery continues the streak: its fallback as
    // from nominal, said only when its kind changes.
    (
        R,
        PLAN_FAIL,
        S::PlanFallback { failed: 4 },
        fallback(Plan, true),
    ),
    (
        R,
        HOLD_FAIL,
        S::HeldCommand { failed: 4, held: 1 },
        fallback(Held, false),
    ),
    (
        R,
        BARE_FAIL,
        S::LevelHover {
            failed: 4,
            since: 1.04,
        },
        fallback(LevelHover, true),
    ),
    (
        R,
        tripped(Cause::ResidualDiverged, true),
        FL_AT_LATCHED,
        enter(Cause::ResidualDiverged, true),
    ),
    (R, STALE, FL_AT, enter(Cause::PoseStale, true)),
    (R, SILENT, FL_AT, enter(Cause::AutopilotSilent, true)),
    (R, OFF_STALE, R, A::None),
    (R, FINE, R, A::None),
    (R, STOPPING, R, A::None),
    (R, Event::Idle { t: 1.04 }, R, A::None),
    (R, Event::TrialSolve { ok: true }, R, A::None),
    (R, Event::LevelRefused, R, A::None),
    (FL, Event::Solved, FL, A::None),
    (G, Event::Solved, G, A::None),
    (T, Event::Solved, T, A::None),
    // A failed tick with a plan to fly: the plan.
    (
        N,
        PLAN_FAIL,
        S::PlanFallback { failed: 1 },
        fallback(Plan, true),
    ),
    (
        P,
        PLAN_FAIL,
        S::PlanFallback { failed: 4 },
        fallback(Plan, false),
    ),
    (
        H,
        PLAN_FAIL,
        S::PlanFallback { failed: 2 },
        fallback(Plan, true),
    ),
    (
        L,
        PLAN_FAIL,
        S::PlanFallback { failed: 5 },
        fallback(Plan, true),
    ),
    (FL, PLAN_FAIL, FL, A::None),
    (G, PLAN_FAIL, G, A::None),
    (T, PLAN_FAIL, T, A::None),
    // No plan, a good command remembered: held (never after a plan),
    // for at most hold_ticks, then level hover.
    (
        N,
        HOLD_FAIL,
        S::HeldCommand { failed: 1, held: 1 },
        fallback(Held, true),
    ),
    (
        H,
        HOLD_FAIL,
        S::HeldCommand { failed: 2, held: 2 },
        fallback(Held, false),
    ),
    (
        H_OUT,
        HOLD_FAIL,
        S::LevelHover {
            failed: 3,
            since: 1.04,
        },
        fallback(LevelHover, true),
    ),
    (
        P,
        HOLD_FAIL,
        S::LevelHover {
            failed: 4,
            since: 1.04,
        },
        fallback(LevelHover, true),
    ),
    (
        L,
        HOLD_FAIL,
        S::LevelHover {
            failed: 5,
            since: 1.0,
        },
        fallback(LevelHover, false),
    ),
    (FL, HOLD_FAIL, FL, A::None),
    (G, HOLD_FAIL, G, A::None),
    (T, HOLD_FAIL, T, A::None),
    // Nothing to hold: level hover at once.
    (
        N,
        BARE_FAIL,
        S::LevelHover {
            failed: 1,
            since: 1.04,
        },
        fallback(LevelHover, true),
    ),
    (
        H,
        BARE_FAIL,
        S::LevelHover {
            failed: 2,
            since: 1.04,
        },
        fallback(LevelHover, true),
    ),
    // Level hover ran out (1.09 − 1.0 + half a period ≥ 0.1 s): let go.
    (L, LATE_FAIL, S::Trial { good: 0 }, LET_GO),
    // A cause the core found (residual, the stop's level): level (brake
    // first) when engaged; latched 2 s after a residual; a control
    // failure goes to the trial. A failsafe is never entered twice.
    (
        N,
        tripped(Cause::ResidualDiverged, true),
        FL_AT_LATCHED,
        enter(Cause::ResidualDiverged, true),
    ),
    (
        H,
        tripped(Cause::ResidualDiverged, true),
        FL_AT_LATCHED,
        enter(Cause::ResidualDiverged, true),
    ),
    (
        L,
        tripped(Cause::ResidualDiverged, false),
        S::LetGo { clear: LATCH },
        enter(Cause::ResidualDiverged, false),
    ),
    (
        P,
        tripped(Cause::ShutdownLevel, true),
        FL_AT,
        enter(Cause::ShutdownLevel, true),
    ),
    (
        N,
        tripped(Cause::ControlFailed, true),
        S::Trial { good: 0 },
        LET_GO,
    ),
    (FL, tripped(Cause::ResidualDiverged, true), FL, A::None),
    (G, tripped(Cause::ResidualDiverged, true), G, A::None),
    (T, tripped(Cause::ResidualDiverged, true), T, A::None),
    // Stale pose while streaming: level (brake first) when engaged, else
    // let go at once. The supervisor's failsafe is not entered twice.
    (N, STALE, FL_AT, enter(Cause::PoseStale, true)),
    (N, STALE_STANDBY, G, enter(Cause::PoseStale, false)),
    (P, STALE, FL_AT, enter(Cause::PoseStale, true)),
    (H, STALE, FL_AT, enter(Cause::PoseStale, true)),
    (L, STALE, FL_AT, enter(Cause::PoseStale, true)),
    (FL, STALE, FL, A::None),
    (G, STALE, G, A::None),
    (T, STALE, T, A::None),
    // A silent autopilot: the same.
    (N, SILENT, FL_AT, enter(Cause::AutopilotSilent, true)),
    (P, SILENT, FL_AT, enter(Cause::AutopilotSilent, true)),
    (H, SILENT, FL_AT, enter(Cause::AutopilotSilent, true)),
    (L, SILENT, FL_AT, enter(Cause::AutopilotSilent, true)),
    (FL, SILENT, FL, A::None),
    (G, SILENT, G, A::None),
    (T, SILENT, T, A::None),
    // Not streaming (waiting for pose): nothing to enter; in the failsafe
    // a stale pose does not clear it.
    (N, OFF_STALE, N, A::None),
    (P, OFF_STALE, P, A::None),
    (H, OFF_STALE, H, A::None),
    (L, OFF_STALE, L, A::None),
    (FL, OFF_STALE, FL, A::None),
    (G, OFF_STALE, G, A::None),
    (T, OFF_STALE, T, A::None),
    // The causes cleared: the failsafe clears unless its clear condition
    // latches it (a residual's first 2 s, the trial).
    (N, FINE, N, A::None),
    (P, FINE, P, A::None),
    (H, FINE, H, A::None),
    (L, FINE, L, A::None),
    (FL, FINE, N, A::Recover),
    (FL_LATCHED, FINE, FL_LATCHED, A::None),
    (G, FINE, N, A::Recover),
    (G_LATCHED, FINE, G_LATCHED, A::None),
    (T, FINE, T, A::None),
    // Stopping: no failsafe clears.
    (N, STOPPING, N, A::None),
    (P, STOPPING, P, A::None),
    (H, STOPPING, H, A::None),
    (L, STOPPING, L, A::None),
    (FL, STOPPING, FL, A::None),
    (G, STOPPING, G, A::None),
    (T, STOPPING, T, A::None),
    // A tick without the controller: the failsafe's brake, its level
    // hover, then stream off.
    (
        FL,
        Event::Idle { t: 1.02 },
        FL,
        A::SendLevel {
            command: BRAKE,
            braking: true,
        },
    ),
    (
        FL,
        Event::Idle { t: 1.04 },
        FL,
        A::SendLevel {
            command: LEVEL,
            braking: false,
        },
    ),
    (
        FL,
        Event::Idle { t: 1.09 },
        G,
        A::LevelOver { announce: true },
    ),
    (
        FL_LATCHED,
        Event::Idle { t: 1.09 },
        G_LATCHED,
        A::LevelOver { announce: true },
    ),
    (N, Event::Idle { t: 1.04 }, N, A::None),
    (P, Event::Idle { t: 1.04 }, P, A::None),
    (H, Event::Idle { t: 1.04 }, H, A::None),
    (L, Event::Idle { t: 1.04 }, L, A::None),
    (G, Event::Idle { t: 1.04 }, G, A::None),
    (T, Event::Idle { t: 1.04 }, T, A::None),
    // Trial solves: TRIAL_TICKS good ones in a row lift the latch.
    (
        T,
        Event::TrialSolve { ok: true },
        S::Trial { good: 3 },
        A::None,
    ),
    (
        T,
        Event::TrialSolve { ok: false },
        S::Trial { good: 0 },
        A::None,
    ),
    (T_LAST, Event::TrialSolve { ok: true }, G, A::FliesAgain),
    (N, Event::TrialSolve { ok: true }, N, A::None),
    (P, Event::TrialSolve { ok: true }, P, A::None),
    (H, Event::TrialSolve { ok: true }, H, A::None),
    (L, Event::TrialSolve { ok: true }, L, A::None),
    (FL, Event::TrialSolve { ok: true }, FL, A::None),
    (G, Event::TrialSolve { ok: true }, G, A::None),
    // The level command could not be sent: stream off (latch kept).
    (FL, Event::LevelRefused, G, A::None),
    (FL_LATCHED, Event::LevelRefused, G_LATCHED, A::None),
    (N, Event::LevelRefused, N, A::None),
    (P, Event::LevelRefused, P, A::None),
    (H, Event::LevelRefused, H, A::None),
    (L, Event::LevelRefused, L, A::None),
    (G, Event::LevelRefused, G, A::None),
    (T, Event::LevelRefused, T, A::None),
];

#[test]
fn the_transition_table() {
    let table = TABLE;
    for (i, (state, event, want_state, want_action)) in table.iter().enumerate() {
        let (got_state, got_action) = next(*state, *event, &LIMITS);
        assert_eq!(
            (got_state, got_action),
            (*want_state, *want_action),
            "row {i}: {} on {event:?}",
            state.name()
        );
    }
    // Every state meets every event at least once.
    let states = [N, R, P, H, L, FL, G, T];
    let events = [
        Event::Solved,
        failed(1.0, false, false),
        tripped(Cause::ResidualDiverged, true),
        STALE,
        SILENT,
        OFF_STALE,
        FINE,
        STOPPING,
        Event::Idle { t: 1.0 },
        Event::TrialSolve { ok: true },
        Event::LevelRefused,
    ];
    let listed: BTreeSet<_> = table
        .iter()
        .map(|(s, e, _, _)| (s.name(), event_name(e)))
        .collect();
    for s in &states {
        for e in &events {
            assert!(
                listed.contains(&(s.name(), event_name(e))),
                "({}, {}) not in the table",
                s.name(),
                event_name(e)
            );
        }
    }
    assert_eq!(listed.len(), states.len() * events.len());
}

#[test]
fn level_hover_off_lets_go_at_the_first_level_tick() {
    let off = Limits {
        level_hover_max: 0.0,
        ..LIMITS
    };
    assert_eq!(
        next(N, failed(1.0, false, false), &off),
        (S::Trial { good: 0 }, LET_GO)
    );
    // A plan still flies.
    assert_eq!(
        next(N, failed(1.0, true, false), &off).1,
        fallback(FallbackKind::Plan, true)
    );
    // A levelling failsafe is entered silently and over at its first tick.
    assert_eq!(
        next(N, STALE, &off).1,
        Action::Enter {
            cause: Cause::PoseStale,
            level: Some(false)
        }
    );
    assert_eq!(
        next(FL, Event::Idle { t: 1.0 }, &off),
        (G, Action::LevelOver { announce: false })
    );
}

#[test]
fn holding_is_off_with_zero_hold_ticks() {
    let none = Limits {
        hold_ticks: 0,
        ..LIMITS
    };
    assert_eq!(
        next(N, failed(1.0, false, true), &none).0,
        S::LevelHover {
            failed: 1,
            since: 1.0
        }
    );
}

#[test]
fn latches() {
    assert!(!N.latched(0.0) && !P.latched(0.0) && !H.latched(0.0) && !L.latched(0.0));
    assert!(!FL.latched(2.0) && !G.latched(2.0));
    assert!(FL_LATCHED.latched(2.99) && !FL_LATCHED.latched(3.0));
    assert!(G_LATCHED.latched(2.99) && !G_LATCHED.latched(3.0));
    assert!(T.latched(1e9));
}

#[test]
fn a_long_streak_walks_the_ladder() {
    // Held twice, level hover until it runs out, let go, trials, recovery.
    let mut s = N;
    let mut actions = Vec::new();
    let mut t = 1.0;
    for _ in 0..12 {
        let (n, a) = next(s, failed(t, false, true), &LIMITS);
        s = n;
        actions.push(a);
        t += 0.02;
        if a == LET_GO {
            break;
        }
    }
    let kinds: Vec<_> = actions
        .iter()
        .map(|a| match a {
            Action::Fallback { kind, .. } => format!("{kind:?}"),
            &LET_GO => "LetGo".to_string(),
            other => format!("{other:?}"),
        })
        .collect();
    // 2 held, level hover from 1.04: 1.04, 1.06, 1.08, 1.10, 1.12 (< 0.1 s
    // with half a period), let go at 1.14.
    assert_eq!(
        kinds,
        [
            "Held",
            "Held",
            "LevelHover",
            "LevelHover",
            "LevelHover",
            "LevelHover",
            "LevelHover",
            "LetGo"
        ]
    );
    assert!(s.latched(t));
    for i in 0..TRIAL_TICKS {
        let (n, a) = next(s, Event::TrialSolve { ok: true }, &LIMITS);
        s = n;
        assert_eq!(a == Action::FliesAgain, i + 1 == TRIAL_TICKS);
    }
    assert!(!s.latched(t));
    assert_eq!(next(s, FINE, &LIMITS), (N, Action::Recover));
}

#[test]
fn a_second_cause_never_lowers_a_failsafe() {
    // Severity orders the states as the ladder climbs.
    let order = [N, P, H, L, FL, G, T].map(|s| s.severity());
    assert!(order.windows(2).all(|w| w[0] < w[1]));
    // In the failsafe or beyond, a failed tick or another active cause
    // leaves the state as severe as it was: the most severe wins.
    for (state, event, after, _) in TABLE {
        let cause = match event {
            Event::Failed { .. } | Event::Tripped { .. } => true,
            Event::Health(h) => h.cause().is_some(),
            _ => false,
        };
        if cause && state.severity() >= Severity::FailsafeLevel {
            assert!(
                after.severity() >= state.severity(),
                "{state:?} on {event:?}"
            );
        }
    }
}

#[test]
fn clear_conditions() {
    assert!(!Clear::for_cause(Cause::PoseStale, 1.0).latched(1.0));
    let residual = Clear::for_cause(Cause::ResidualDiverged, 1.0);
    assert!(residual.latched(1.0 + RESIDUAL_FAILSAFE_LATCH - 1e-9));
    assert!(!residual.latched(1.0 + RESIDUAL_FAILSAFE_LATCH));
}
