//! The exit path, written once: the controller's command with its thrust
//! mapped and through the [`CommandGuard`](crate::guard::CommandGuard),
//! the fallback of a failed or late tick, and the controller's update with
//! a panic caught.

use dflat_control::reference::Reference;
use dflat_control::{Controller, Measurement};
use dflat_link::AttitudeCommand;
use dflat_link::dialect::MavSeverity;
use tracing::warn;

use super::ControlCore;
use crate::guard::FallbackKind;
use crate::records::CsvRow;

impl ControlCore {
    /// The exit path, once per command: the controller's command with its
    /// thrust mapped to [0, 1] units and through the
    /// [`CommandGuard`](crate::guard::CommandGuard).
    pub(super) fn guarded(
        &mut self,
        command: &dflat_control::AttitudeCommand,
    ) -> Result<AttitudeCommand, String> {
        let thrust = self
            .mapping
            .normalized(command.thrust)
            .map_err(|e| e.to_string())?;
        // The controller's tilt is a world-frame one (its model flies the
        // fixed heading ψ⋆): the same thrust axis at the commanded heading.
        let (pitch, roll, yaw) = self.tilt_to_command(command.pitch, command.roll);
        self.guard
            .check(
                AttitudeCommand {
                    roll,
                    pitch,
                    yaw,
                    thrust,
                },
                &mut self.counts.guards,
            )
            .map_err(|e| e.to_string())
    }

    /// A failed or late tick's command at `t`: the previous plan one step
    /// further (DF-MPC; recorded in its window), guarded like any command;
    /// else the held command, then level hover — for at most
    /// `safety.level_hover_max_ms`, after which the daemon lets go (`None`:
    /// nothing is sent). Counts and announces the kind.
    pub(super) fn fallback_command(
        &mut self,
        t: f64,
        measurement: &Measurement,
        failed: Result<(dflat_control::TickOutput, AttitudeCommand), String>,
        solve_us: u32,
        row: &mut CsvRow,
    ) -> Option<AttitudeCommand> {
        match failed {
            Ok(_) => {
                self.counts.guards.deadline_overruns += 1;
                if self.error_streak == 0 {
                    warn!(solve_us, "deadline overrun: fallback command");
                }
            }
            Err(e) => {
                self.counts.control_errors += 1;
                self.counts.guards.controller_failures += 1;
                if self.error_streak == 0 {
                    warn!(error = %e, "controller failed: fallback command");
                }
            }
        }
        self.error_streak += 1;
        let planned = self
            .controller
            .plan_fallback(measurement, self.fallback.hold_ticks as usize)
            .and_then(|out| {
                let command = self.guarded(&out.command).ok()?;
                Some((command, out.plan[1]))
            });
        match planned {
            Some((_, next)) => self.residual.predict([next.x, next.y, next.z]),
            None => self.residual.forget(),
        }
        let (command, kind) = self.fallback.command(planned.map(|(c, _)| c));
        if kind == FallbackKind::LevelHover {
            // Each tick stands for one period (half a period of margin
            // against wake-up jitter): at most max / period ticks are sent.
            let since = *self.level_hover_since.get_or_insert(t);
            if t - since + 0.5 * self.period >= self.config.safety.level_hover_max_ms / 1000.0 {
                // Let go: stop the stream so the autopilot's own failsafe
                // takes over.
                self.let_go(t);
                row.guard = Some("let_go");
                return None;
            }
        } else {
            self.level_hover_since = None;
        }
        let (counter, note, text) = match kind {
            FallbackKind::Plan => (
                &mut self.counts.guards.plan_steps,
                "plan",
                "dflat: control failed, flying the previous plan",
            ),
            FallbackKind::Held => (
                &mut self.counts.guards.held,
                "held",
                "dflat: control failed, holding last command",
            ),
            FallbackKind::LevelHover => (
                &mut self.counts.guards.level_hover,
                "level",
                "dflat: control failed, level hover",
            ),
        };
        *counter += 1;
        row.guard = Some(note);
        if self.fallback_kind != Some(kind) {
            self.fallback_kind = Some(kind);
            self.text(MavSeverity::MAV_SEVERITY_CRITICAL, text);
        }
        Some(command)
    }
}

/// [`Controller::update`] with a panic caught: a panicking controller is
/// a bug, but it must not take the loop down with it — the tick fails and
/// the controller is reset.
pub(super) fn update_caught(
    controller: &mut dyn Controller,
    measurement: &Measurement,
    reference: &mut Reference,
) -> Result<dflat_control::TickOutput, dflat_control::ControlError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        controller.update(measurement, reference)
    }))
    .unwrap_or_else(|_| {
        controller.reset();
        Err(dflat_control::ControlError::Solver(
            "controller panicked (reset)".into(),
        ))
    })
}
