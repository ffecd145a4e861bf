//! What happens after a failure, as one state machine: [`Failsafe`] and
//! its transitions in one pure function, [`next`].
//!
//! ```text
//!            failed / late tick                    level hover ran out
//! Nominal ─────────────────────► PlanFallback ─┐  (safety.level_hover_max_ms)
//!    ▲   │  (no plan, a good     HeldCommand ──┼──► LevelHover ──────────────► Trial
//!    │   │   command to hold)                  │                              │ TRIAL_TICKS good
//!    │   └─────────────────────────────────────┘                              │ trial solves
//!    │ good tick (from any of the three)                                      ▼
//!    │                                                                      LetGo
//!    │   supervisor's failsafe (pose stale, autopilot silent, residual):      │
//!    │     left an engaged state → FailsafeLevel (brake, level) ──► LetGo     │
//!    │     else                  → LetGo                                      │
//!    └────────────────── supervisor recovers (fresh pose, not latched) ───────┘
//! ```
//!
//! The supervisor ([`crate::supervisor`]) detects stale pose and a silent
//! autopilot and owns the engagement state (`FlightState`); the control
//! core detects failed ticks, the model residual and trial results. Both
//! report here as [`Event`]s, and [`next`] alone decides the next state and
//! what the core does about it ([`Action`]): which fallback command to
//! send, when to say so, when to let go, how long recovery is latched
//! ([`Failsafe::latched`]) and when the controller may fly again.
//!
//! Counters that belong to a state live in its variant: the failed ticks
//! of a fallback streak, the ticks a command has been held, since when
//! level hover has been streamed, the good trial solves in a row.

use dflat_link::AttitudeCommand;

use crate::supervisor::Cause;

/// After a control failsafe, consecutive successful trial solves (not
/// sent) before the stream may resume.
pub const TRIAL_TICKS: u32 = 5;
/// How long a residual failsafe lasts before pose may re-engage \[s\].
pub const RESIDUAL_FAILSAFE_LATCH: f64 = 2.0;

/// What a failsafe that levels streams: the level command, and the brake
/// before it (see `tick/failsafe_level.rs`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelPlan {
    /// The level command (yaw of the last command sent, hover thrust).
    pub command: AttitudeCommand,
    /// The brake first: (pitch, roll) \[rad\] for this long \[s\].
    pub brake: Option<([f64; 2], f64)>,
}

/// When a failsafe that stopped the controller may clear (as PX4's
/// failsafe framework's clear conditions).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clear {
    /// When its cause clears (fresh pose, the autopilot alive).
    WhenCauseClears,
    /// When its cause clears, not before this time \[s\] (a residual
    /// failsafe: [`RESIDUAL_FAILSAFE_LATCH`] after it began).
    NotBefore(f64),
}

impl Clear {
    /// The clear condition of a failsafe for `cause` entered at `t` \[s\].
    pub fn for_cause(cause: Cause, t: f64) -> Self {
        match cause {
            Cause::ResidualDiverged => Clear::NotBefore(t + RESIDUAL_FAILSAFE_LATCH),
            _ => Clear::WhenCauseClears,
        }
    }

    /// True while it may not clear at `t` \[s\].
    pub fn latched(&self, t: f64) -> bool {
        match *self {
            Clear::WhenCauseClears => false,
            Clear::NotBefore(until) => t < until,
        }
    }
}

/// The failsafe states by severity, least first: when two causes are
/// active the more severe state wins (a failed tick never lowers a
/// supervisor's failsafe; a second failsafe never lowers the first).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The controller flies.
    Nominal,
    /// Its previous plan.
    PlanFallback,
    /// The last good command, held.
    HeldCommand,
    /// Level attitude at hover thrust.
    LevelHover,
    /// The supervisor's failsafe: brake, then level.
    FailsafeLevel,
    /// Stream off.
    LetGo,
    /// Stream off, the controller on trial.
    Trial,
}

/// The failsafe state of the control core.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Failsafe {
    /// The controller's own commands are sent (or nothing has failed).
    Nominal,
    /// Failed or late ticks: the controller's previous plan, one step
    /// further per tick (DF-MPC).
    PlanFallback {
        /// Failed or late ticks in this streak.
        failed: u64,
    },
    /// Failed or late ticks without a plan: the last good command, held.
    HeldCommand {
        /// Failed or late ticks in this streak.
        failed: u64,
        /// Ticks the command has been held (at most `safety.hold_last_ticks`).
        held: u32,
    },
    /// Failed or late ticks, nothing left to fly or hold: level attitude at
    /// hover thrust, for at most `safety.level_hover_max_ms`.
    LevelHover {
        /// Failed or late ticks in this streak.
        failed: u64,
        /// Tick time the level hover started \[s\].
        since: f64,
    },
    /// The supervisor's failsafe entered from an engaged state (pose
    /// stale, autopilot silent, model residual): a brake, then level
    /// hover, streamed for at most `safety.level_hover_max_ms`.
    FailsafeLevel {
        /// Tick time the failsafe was entered \[s\].
        since: f64,
        /// What is streamed.
        plan: LevelPlan,
        /// When it may clear.
        clear: Clear,
    },
    /// Stream off: the autopilot's own failsafe flies. The supervisor
    /// recovers on fresh pose and a live autopilot, once its clear
    /// condition allows.
    LetGo {
        /// When it may clear.
        clear: Clear,
    },
    /// The controller could not fly (level hover ran out): stream off, and
    /// the controller is tried each tick on the newest pose (not sent).
    /// Latched until [`TRIAL_TICKS`] trials in a row have solved.
    Trial {
        /// Good trial solves in a row.
        good: u32,
    },
}

/// A fact reported to the failsafe machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// A tick's controller command was good (guarded) and in time.
    Solved,
    /// A tick at `t` \[s\] failed or overran its deadline.
    Failed {
        /// Tick time \[s\].
        t: f64,
        /// The controller offered its previous plan's next step.
        planned: bool,
        /// A good command is remembered that could be held.
        can_hold: bool,
    },
    /// The supervisor entered its failsafe at `t` \[s\] for `cause`.
    FailsafeEntered {
        /// Tick time \[s\].
        t: f64,
        /// Why.
        cause: Cause,
        /// The state left was engaged (the autopilot applied our commands).
        engaged: bool,
        /// What a levelling failsafe would stream.
        level: LevelPlan,
    },
    /// The supervisor left its failsafe (fresh pose, autopilot alive).
    Recovered,
    /// A tick at `t` \[s\] on which the controller does not fly (not
    /// streaming): a failsafe's brake and level hover, while due.
    Idle {
        /// Tick time \[s\].
        t: f64,
    },
    /// A trial solve in [`Failsafe::Trial`] solved (`ok`) or not.
    TrialSolve {
        /// It solved.
        ok: bool,
    },
    /// The failsafe's level command could not be sent (guard, encoder).
    LevelRefused,
}

/// Which fallback command a failed tick sends.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FallbackKind {
    /// The controller's previous plan, shifted one step per failed tick
    /// ([`dflat_control::Controller::plan_fallback`]).
    Plan,
    /// The last good command, held (controllers without a plan).
    Held,
    /// Level attitude at hover thrust.
    LevelHover,
}

/// What the control core does after a transition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Action {
    /// Nothing.
    None,
    /// The controller flies again after `failed` failed ticks (logged).
    Recovered {
        /// Failed ticks in the streak that ended.
        failed: u64,
    },
    /// Send this fallback command; `announce` when its kind is new in the
    /// streak (STATUSTEXT).
    Fallback {
        /// Which command.
        kind: FallbackKind,
        /// Say it.
        announce: bool,
    },
    /// Let go: nothing is sent; force the supervisor's failsafe
    /// (`Cause::ControlFailed`) so the autopilot's failsafe takes over.
    LetGo,
    /// A levelling failsafe started; `announce` unless level hover is off.
    StartLevel {
        /// Say it.
        announce: bool,
    },
    /// Send the failsafe's brake or level command.
    SendLevel {
        /// The command (before the guard).
        command: AttitudeCommand,
        /// It is the brake.
        braking: bool,
    },
    /// The failsafe's level hover ran out: stream off; `announce` unless
    /// level hover is off.
    LevelOver {
        /// Say it.
        announce: bool,
    },
    /// Enough trial solves: the controller flies again; recovery follows
    /// with fresh pose.
    FliesAgain,
}

/// The machine's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Ticks the last good command may be held (`safety.hold_last_ticks`).
    pub hold_ticks: u32,
    /// Longest level hover \[s\] (`safety.level_hover_max_ms`).
    pub level_hover_max: f64,
    /// The control period \[s\].
    pub period: f64,
}

impl Limits {
    /// True when level hover since `since` has run out at `t`: each tick
    /// stands for one period (half a period of margin against wake-up
    /// jitter), so at most max / period ticks are sent.
    fn ran_out(&self, since: f64, t: f64) -> bool {
        t - since + 0.5 * self.period >= self.level_hover_max
    }
}

impl Failsafe {
    /// Short name (logs, tests).
    pub fn name(&self) -> &'static str {
        match self {
            Failsafe::Nominal => "nominal",
            Failsafe::PlanFallback { .. } => "plan_fallback",
            Failsafe::HeldCommand { .. } => "held_command",
            Failsafe::LevelHover { .. } => "level_hover",
            Failsafe::FailsafeLevel { .. } => "failsafe_level",
            Failsafe::LetGo { .. } => "let_go",
            Failsafe::Trial { .. } => "trial",
        }
    }

    /// Its place in the severity order.
    pub fn severity(&self) -> Severity {
        match self {
            Failsafe::Nominal => Severity::Nominal,
            Failsafe::PlanFallback { .. } => Severity::PlanFallback,
            Failsafe::HeldCommand { .. } => Severity::HeldCommand,
            Failsafe::LevelHover { .. } => Severity::LevelHover,
            Failsafe::FailsafeLevel { .. } => Severity::FailsafeLevel,
            Failsafe::LetGo { .. } => Severity::LetGo,
            Failsafe::Trial { .. } => Severity::Trial,
        }
    }

    /// True while the supervisor may not recover at `t` \[s\] (a residual
    /// failsafe's latch, or the controller not yet trialled).
    pub fn latched(&self, t: f64) -> bool {
        match *self {
            Failsafe::FailsafeLevel { clear, .. } | Failsafe::LetGo { clear } => clear.latched(t),
            Failsafe::Trial { .. } => true,
            _ => false,
        }
    }

    /// Failed ticks of the current fallback streak (0 outside one).
    fn failed(&self) -> u64 {
        match *self {
            Failsafe::PlanFallback { failed }
            | Failsafe::HeldCommand { failed, .. }
            | Failsafe::LevelHover { failed, .. } => failed,
            _ => 0,
        }
    }

    /// True in the states the controller flies in (a failure here starts
    /// or continues a fallback streak): below the supervisor's failsafe,
    /// which a failed tick or a second failsafe never lowers.
    fn flying(&self) -> bool {
        self.severity() < Severity::FailsafeLevel
    }
}

/// The one transition function: the state after `event` in `state`, and
/// what the core does. Pairs that cannot occur (a solve in a failsafe, a
/// second failsafe entry) leave the state unchanged and do nothing.
pub fn next(state: Failsafe, event: Event, limits: &Limits) -> (Failsafe, Action) {
    use Failsafe as S;
    match (state, event) {
        (S::Nominal, Event::Solved) => (S::Nominal, Action::None),
        (s, Event::Solved) if s.flying() => (S::Nominal, Action::Recovered { failed: s.failed() }),
        (
            s,
            Event::Failed {
                t,
                planned,
                can_hold,
            },
        ) if s.flying() => fallback(s, t, planned, can_hold, limits),
        (
            s,
            Event::FailsafeEntered {
                t,
                cause,
                engaged,
                level,
            },
        ) if s.flying() => {
            let clear = Clear::for_cause(cause, t);
            match cause {
                Cause::ControlFailed => (S::Trial { good: 0 }, Action::None),
                Cause::PoseStale
                | Cause::AutopilotSilent
                | Cause::ResidualDiverged
                | Cause::ShutdownLevel
                    if engaged =>
                {
                    (
                        S::FailsafeLevel {
                            since: t,
                            plan: level,
                            clear,
                        },
                        Action::StartLevel {
                            announce: limits.level_hover_max > 0.0,
                        },
                    )
                }
                _ => (S::LetGo { clear }, Action::None),
            }
        }
        (_, Event::Recovered) => (S::Nominal, Action::None),
        (S::FailsafeLevel { since, plan, clear }, Event::Idle { t }) => {
            if limits.ran_out(since, t) {
                (
                    S::LetGo { clear },
                    Action::LevelOver {
                        announce: limits.level_hover_max > 0.0,
                    },
                )
            } else {
                let braking = plan
                    .brake
                    .filter(|(_, time)| t - since + 0.5 * limits.period < *time);
                let mut command = plan.command;
                if let Some(([pitch, roll], _)) = braking {
                    command.pitch = pitch;
                    command.roll = roll;
                }
                (
                    state,
                    Action::SendLevel {
                        command,
                        braking: braking.is_some(),
                    },
                )
            }
        }
        (S::FailsafeLevel { clear, .. }, Event::LevelRefused) => (S::LetGo { clear }, Action::None),
        (S::Trial { good }, Event::TrialSolve { ok }) => {
            let good = if ok { good + 1 } else { 0 };
            if good >= TRIAL_TICKS {
                (
                    S::LetGo {
                        clear: Clear::WhenCauseClears,
                    },
                    Action::FliesAgain,
                )
            } else {
                (S::Trial { good }, Action::None)
            }
        }
        (s, _) => (s, Action::None),
    }
}

/// A failed tick at `t` in a flying state `s`: the plan when offered,
/// else the held command (only from `Nominal` or while holding, for at
/// most `hold_ticks`: once a streak has flown the plan it never falls back
/// to the older last good command), else level hover — and let go when
/// level hover has run out.
fn fallback(
    s: Failsafe,
    t: f64,
    planned: bool,
    can_hold: bool,
    limits: &Limits,
) -> (Failsafe, Action) {
    let failed = s.failed() + 1;
    let held_so_far = match s {
        Failsafe::Nominal => Some(0),
        Failsafe::HeldCommand { held, .. } => Some(held),
        _ => None,
    };
    let (next, kind) = if planned {
        (Failsafe::PlanFallback { failed }, FallbackKind::Plan)
    } else if let Some(held) = held_so_far.filter(|h| can_hold && *h < limits.hold_ticks) {
        (
            Failsafe::HeldCommand {
                failed,
                held: held + 1,
            },
            FallbackKind::Held,
        )
    } else {
        let since = match s {
            Failsafe::LevelHover { since, .. } => since,
            _ => t,
        };
        if limits.ran_out(since, t) {
            return (Failsafe::Trial { good: 0 }, Action::LetGo);
        }
        (
            Failsafe::LevelHover { failed, since },
            FallbackKind::LevelHover,
        )
    };
    let announce = std::mem::discriminant(&next) != std::mem::discriminant(&s);
    (next, Action::Fallback { kind, announce })
}

#[cfg(test)]
#[path = "failsafe_tests.rs"]
mod tests;
