//! The one place a failsafe [`Action`] becomes behaviour: the control core
//! feeds an event to the failsafe machine (`tick/failsafe.rs`) and carries
//! out what it decides — which fallback command to send, the brake and
//! level command, letting go, what is said and logged, what the record
//! notes.

use dflat_link::AttitudeCommand;
use dflat_link::dialect::MavSeverity;
use tracing::{debug, info};

use super::ControlCore;
use super::failsafe::{self, Action, Event, FallbackKind};

impl ControlCore {
    /// Feeds `event` at tick time `t` \[s\] to the failsafe machine and
    /// carries out its action. `planned` is the controller's previous
    /// plan's next command, guarded, when it offered one (a failed tick).
    /// Returns the command the action sends, if any: a fallback's (guarded)
    /// or the failsafe's brake or level command (before the guard, ramped
    /// during the stop). `note` receives the record's guard note.
    pub(super) fn failsafe_on(
        &mut self,
        t: f64,
        event: Event,
        planned: Option<AttitudeCommand>,
        note: &mut Option<&'static str>,
    ) -> Option<AttitudeCommand> {
        let limits = self.failsafe_limits();
        let (state, action) = failsafe::next(self.failsafe.state, event, &limits);
        if state.name() != self.failsafe.state.name() {
            debug!(
                from = self.failsafe.state.name(),
                to = state.name(),
                "failsafe state"
            );
        }
        self.failsafe.state = state;
        match action {
            Action::None => None,
            Action::Recovered { failed } => {
                info!(ticks = failed, "controller recovered");
                self.text(
                    MavSeverity::MAV_SEVERITY_INFO,
                    &format!("dflat: controller recovered ({failed} failed ticks)"),
                );
                None
            }
            Action::Fallback { kind, announce } => self.fallback_of(kind, announce, planned, note),
            Action::Enter { cause, level } => {
                self.enter_failsafe(t, cause, level, note);
                None
            }
            Action::Recover => {
                self.recover(t);
                None
            }
            Action::SendLevel { command, braking } => {
                *note = Some(if braking { "brake" } else { "level" });
                Some(self.stop_ramp(command))
            }
            Action::LevelOver { announce } => {
                if announce {
                    info!(
                        "failsafe level hover over: attitude stream off, the autopilot's failsafe takes over"
                    );
                    self.text(
                        MavSeverity::MAV_SEVERITY_CRITICAL,
                        "dflat: level hover over, stream off",
                    );
                }
                *note = Some("let_go");
                None
            }
            Action::FliesAgain => {
                info!("controller solves again: the stream may resume");
                self.text(
                    MavSeverity::MAV_SEVERITY_NOTICE,
                    "dflat: controller flies again",
                );
                None
            }
        }
    }

    /// The fallback command of `kind` (`planned`: the plan's step), counted,
    /// noted and said when `announce`.
    fn fallback_of(
        &mut self,
        kind: FallbackKind,
        announce: bool,
        planned: Option<AttitudeCommand>,
        note: &mut Option<&'static str>,
    ) -> Option<AttitudeCommand> {
        let command = match kind {
            FallbackKind::Plan => {
                let command = planned?;
                self.failsafe.fallback.planned(command);
                command
            }
            FallbackKind::Held => self.failsafe.fallback.held()?,
            FallbackKind::LevelHover => self.failsafe.fallback.level_command(),
        };
        let guards = &mut self.counts.guards;
        let (counter, kind_note, text) = match kind {
            FallbackKind::Plan => (
                &mut guards.plan_steps,
                "plan",
                "dflat: control failed, flying the previous plan",
            ),
            FallbackKind::Held => (
                &mut guards.held,
                "held",
                "dflat: control failed, holding last command",
            ),
            FallbackKind::LevelHover => (
                &mut guards.level_hover,
                "level",
                "dflat: control failed, level hover",
            ),
        };
        *counter += 1;
        *note = Some(kind_note);
        if announce {
            self.text(MavSeverity::MAV_SEVERITY_CRITICAL, text);
        }
        Some(command)
    }
}
