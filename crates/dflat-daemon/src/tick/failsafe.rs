//! What happens after a failure, as one state machine: [`Failsafe`] and
//! its transitions in one pure function, [`next`]. It is the one owner of
//! every failure cause.
//!
//! ```text
//!            failed / late tick                    level hover ran out
//! Nominal ─────────────────────► PlanFallback ─┐  (safety.level_hover_max_ms)
//!    ▲   │  (no plan, a good     HeldCommand ──┼──► LevelHover ──────────────► Trial
//!    │   │   command to hold)                  │     (ControlFailed)          │ TRIAL_TICKS good
//!    │   └─────────────────────────────────────┘                              │ trial solves
//!    │ RECOVERY_S of good ticks in a row (Recovering; a failure               │
//!    │ there continues the streak, said if its fallback changes)              ▼
//!    │                                                                      LetGo
//!    │   a cause while streaming (stale pose, silent autopilot, residual,     │
//!    │   the stop's level):                                                 │
//!    │     engaged → FailsafeLevel (brake, level) ──► LetGo                   │
//!    │     else    → LetGo                                                    │
//!    └──────── the causes cleared and the clear condition met (Recover) ──────┘
//! ```
//!
//! The control core reports every fact here as an [`Event`]: each tick's
//! [`Health`] (fresh pose, a live autopilot, the flight state), a failed
//! or good tick, a cause it found ([`Event::Tripped`]: the model residual,
//! the stop's level), a trial solve. [`next`] alone decides the next state
//! and what the core does ([`Action`]), and `tick/act.rs` alone carries it
//! out: which fallback command to send, when to say so, when the flight
//! state enters `FAILSAFE` ([`Action::Enter`]) and when it leaves it
//! ([`Action::Recover`]). The supervisor ([`crate::supervisor`]) follows.
//!
//! The states are ordered by [`Severity`]: a second cause never lowers the
//! state (the most severe wins, as in PX4's `commander/failsafe`
//! framework). When a failsafe may clear is its [`Clear`] condition.
//!
//! Counters that belong to a state live in its variant: the failed ticks
//! of a fallback streak, the ticks a command has been held, since when
//! level hover has been streamed, the good trial solves in a row.

use dflat_link::AttitudeCommand;

use crate::supervisor::{Cause, FlightState, Links};

/// After a control failsafe, consecutive successful trial solves (not
/// sent) before the stream may resume.
pub const TRIAL_TICKS: u32 = 5;
/// How long a residual failsafe lasts before pose may re-engage \[s\].
pub const RESIDUAL_FAILSAFE_LATCH: f64 = 2.0;
/// How long the controller must solve every tick after a fallback streak
/// before the streak is over \[s\] ([`Failsafe::Recovering`]): a failure
/// before then continues it, said again only when its fallback changes
/// kind. Ending a streak at the first good tick, a controller failing
/// three ticks in five announced a new streak twice in every five ticks:
/// 20 STATUSTEXTs a second.
pub const RECOVERY_S: f64 = 1.0;

/// What a failsafe that levels streams: the level command, and the brake
/// before it (see `tick/failsafe_level.rs`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelPlan {
    /// The level command (yaw of the last command sent, hover thrust).
    pub command: AttitudeCommand,
    /// The brake first: (pitch, roll) \[rad\] for this long \[s\].
    pub brake: Option<([f64; 2], f64)>,
}

/// When a failsafe that stopped the controller may clear once its cause
/// has (as PX4's failsafe framework's clear conditions); never while the
/// daemon stops, never in the trial.
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

impl LevelPlan {
    /// Nothing to stream (a failsafe that does not level).
    pub const NONE: LevelPlan = LevelPlan {
        command: AttitudeCommand {
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0,
            thrust: 0.0,
        },
        brake: None,
    };
}

/// The failsafe states by severity, least first: when two causes are
/// active the more severe state wins (a failed tick never lowers a
/// supervisor's failsafe; a second failsafe never lowers the first).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The controller flies.
    Nominal,
    /// The controller flies again after a fallback streak, not long
    /// enough to end it.
    Recovering,
    /// Its previous plan.
    PlanFallback,
    /// The last good command, held.
    HeldCommand,
    /// Level attitude at hover thrust.
    LevelHover,
    /// The failsafe, engaged: brake, then level.
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
    /// The controller's own commands are sent again after a fallback
    /// streak, for less than [`RECOVERY_S`] so far: a failure now
    /// continues the streak (its failed ticks counted on; its fallback
    /// chosen as from [`Failsafe::Nominal`], so the same commands are
    /// sent; said only when its kind differs from `from`'s).
    Recovering {
        /// Failed ticks in the streak.
        failed: u64,
        /// The streak's last fallback.
        from: FallbackKind,
        /// Good ticks in a row since.
        good: u32,
    },
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
    /// The facts of the tick at `t`, reported before the flight state
    /// moves on: stale pose and a silent autopilot are causes the machine
    /// detects here, and a failsafe clears here.
    Health(Health),
    /// The core found a cause at `t` \[s\] while streaming: the model
    /// residual diverged, or the stop's level is due.
    Tripped {
        /// Tick time \[s\].
        t: f64,
        /// Why.
        cause: Cause,
        /// The flight state is engaged (the autopilot applies our commands).
        engaged: bool,
        /// What a levelling failsafe would stream.
        level: LevelPlan,
    },
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

/// The facts a tick reports to the failsafe machine ([`Event::Health`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Health {
    /// Tick time \[s\].
    pub t: f64,
    /// A pose arrived within `safety.pose_timeout_ms`.
    pub pose_fresh: bool,
    /// An autopilot HEARTBEAT arrived within its timeout.
    pub autopilot_alive: bool,
    /// The flight state streams (standby, holding, tracking): only then
    /// can a failsafe be entered.
    pub streaming: bool,
    /// The flight state is engaged (a failsafe levels first).
    pub engaged: bool,
    /// The daemon is stopping: no failsafe clears.
    pub stopping: bool,
    /// What a levelling failsafe would stream.
    pub level: LevelPlan,
}

impl Health {
    /// The facts of the tick at `t` \[s\]: what the arrivals say
    /// (`links`), the flight state, whether the daemon stops, and what a
    /// levelling failsafe would stream.
    pub fn of(t: f64, links: Links, state: FlightState, stopping: bool, level: LevelPlan) -> Self {
        Health {
            t,
            pose_fresh: links.pose_fresh,
            autopilot_alive: links.autopilot_alive,
            streaming: state.streams(),
            engaged: state.engaged(),
            stopping,
            level,
        }
    }

    /// The cause these facts make active, the most severe first: stale
    /// pose, then a silent autopilot.
    pub fn cause(&self) -> Option<Cause> {
        if !self.pose_fresh {
            Some(Cause::PoseStale)
        } else if !self.autopilot_alive {
            Some(Cause::AutopilotSilent)
        } else {
            None
        }
    }
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
    /// Enter the failsafe for `cause`: the flight state goes to
    /// `FAILSAFE` (said), the controller is reset, the stream stops —
    /// after a brake and level hover when `level` is `Some(announce)`
    /// (`announce` unless level hover is off). A control failure
    /// (`Cause::ControlFailed`) lets go: the autopilot's failsafe flies.
    Enter {
        /// Why.
        cause: Cause,
        /// `Some(announce)` when it levels first.
        level: Option<bool>,
    },
    /// The failsafe cleared: the flight state streams again (standby, or
    /// braking to a hold when engaged).
    Recover,
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
            Failsafe::Recovering { .. } => "recovering",
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
            Failsafe::Recovering { .. } => Severity::Recovering,
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

    /// True when `h` clears this failsafe: fresh pose, the autopilot alive,
    /// not stopping, and the clear condition met (never in the trial).
    fn clears(&self, h: &Health) -> bool {
        !self.flying() && h.cause().is_none() && !h.stopping && !self.latched(h.t)
    }

    /// Failed ticks of the current fallback streak (0 outside one).
    fn failed(&self) -> u64 {
        match *self {
            Failsafe::PlanFallback { failed }
            | Failsafe::Recovering { failed, .. }
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
        (s, Event::Solved) if s.flying() => recovering(s, limits),
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
            Event::Tripped {
                t,
                cause,
                engaged,
                level,
            },
        ) if s.flying() => enter(t, cause, engaged, level, limits),
        (s, Event::Health(h)) if s.flying() => match h.cause() {
            Some(cause) if h.streaming => enter(h.t, cause, h.engaged, h.level, limits),
            _ => (s, Action::None),
        },
        (s, Event::Health(h)) if s.clears(&h) => (S::Nominal, Action::Recover),
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

/// The failsafe for `cause` entered at `t` \[s\] (from a state the
/// controller flies in): a control failure goes to the trial; a cause that
/// leaves an engaged state levels first (a brake, then level hover); any
/// other lets go. Its clear condition follows the cause.
fn enter(
    t: f64,
    cause: Cause,
    engaged: bool,
    level: LevelPlan,
    limits: &Limits,
) -> (Failsafe, Action) {
    let clear = Clear::for_cause(cause, t);
    match cause {
        Cause::ControlFailed => (
            Failsafe::Trial { good: 0 },
            Action::Enter { cause, level: None },
        ),
        Cause::PoseStale
        | Cause::AutopilotSilent
        | Cause::ResidualDiverged
        | Cause::ShutdownLevel
            if engaged =>
        {
            (
                Failsafe::FailsafeLevel {
                    since: t,
                    plan: level,
                    clear,
                },
                Action::Enter {
                    cause,
                    level: Some(limits.level_hover_max > 0.0),
                },
            )
        }
        _ => (
            Failsafe::LetGo { clear },
            Action::Enter { cause, level: None },
        ),
    }
}

/// A good tick in a fallback streak `s` (or in its recovery): the streak
/// ends once the good ticks in a row span [`RECOVERY_S`].
fn recovering(s: Failsafe, limits: &Limits) -> (Failsafe, Action) {
    let (from, good) = match s {
        Failsafe::Recovering { from, good, .. } => (from, good + 1),
        Failsafe::PlanFallback { .. } => (FallbackKind::Plan, 1),
        Failsafe::HeldCommand { .. } => (FallbackKind::Held, 1),
        _ => (FallbackKind::LevelHover, 1),
    };
    let failed = s.failed();
    let needed = (RECOVERY_S / limits.period).round().max(1.0);
    if f64::from(good) >= needed {
        (Failsafe::Nominal, Action::Recovered { failed })
    } else {
        (Failsafe::Recovering { failed, from, good }, Action::None)
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
        Failsafe::Nominal | Failsafe::Recovering { .. } => Some(0),
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
            return enter(t, Cause::ControlFailed, false, LevelPlan::NONE, limits);
        }
        (
            Failsafe::LevelHover { failed, since },
            FallbackKind::LevelHover,
        )
    };
    let announce = match s {
        Failsafe::Recovering { from, .. } => from != kind,
        _ => std::mem::discriminant(&next) != std::mem::discriminant(&s),
    };
    (next, Action::Fallback { kind, announce })
}

#[cfg(test)]
#[path = "failsafe_tests.rs"]
mod tests;
