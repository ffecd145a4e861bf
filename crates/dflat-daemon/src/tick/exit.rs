//! The exit path, written once: the controller's command with its thrust
//! mapped and through the [`CommandGuard`](crate::guard::CommandGuard),
//! the fallback of a failed or late tick (chosen by the failsafe machine,
//! `tick/failsafe.rs`), the controller's update with a panic caught, and
//! why a tick failed ([`TickError`]).

use dflat_control::reference::Reference;
use dflat_control::{ControlError, Controller, Measurement};
use dflat_link::{AttitudeCommand, LinkError};
use tracing::warn;

use super::ControlCore;
use super::failsafe::{Event, Failsafe};
use crate::guard::NonFinite;
use crate::records::CsvRow;

/// Why a tick's controller command was not sent (the fallback was). The
/// text is for the log only.
#[derive(Debug, thiserror::Error)]
pub enum TickError {
    /// The controller's update failed.
    #[error(transparent)]
    Control(#[from] ControlError),
    /// The controller panicked; it was reset.
    #[error("controller panicked (reset)")]
    Panicked,
    /// The command's thrust could not be mapped to \[0, 1\].
    #[error(transparent)]
    Thrust(#[from] LinkError),
    /// The guard refused the command (a field is NaN or infinite).
    #[error(transparent)]
    Guard(#[from] NonFinite),
    /// The solve took longer than the tick period.
    #[error("deadline overrun: solve took {solve_us} µs")]
    DeadlineOverrun {
        /// The solve time \[µs\].
        solve_us: u32,
    },
}

impl ControlCore {
    /// The exit path, once per command: the controller's command with its
    /// thrust mapped to [0, 1] units and through the
    /// [`CommandGuard`](crate::guard::CommandGuard).
    pub(super) fn guarded(
        &mut self,
        command: &dflat_control::AttitudeCommand,
    ) -> Result<AttitudeCommand, TickError> {
        let thrust = self.mapping.normalized(command.thrust)?;
        // The controller's tilt is a world-frame one (its model flies the
        // fixed heading ψ⋆): the same thrust axis at the commanded heading.
        let (pitch, roll, yaw) = self.tilt_to_command(command.pitch, command.roll);
        Ok(self.guard.check(
            AttitudeCommand {
                roll,
                pitch,
                yaw,
                thrust,
            },
            &mut self.counts.guards,
        )?)
    }

    /// A failed or late tick's command at `t`: the previous plan one step
    /// further (DF-MPC; recorded in its window), guarded like any command;
    /// else the held command, then level hover — for at most
    /// `safety.level_hover_max_ms`, after which the daemon lets go (`None`:
    /// nothing is sent). The failsafe machine chooses; this counts,
    /// announces and records the kind.
    pub(super) fn fallback_command(
        &mut self,
        t: f64,
        measurement: &Measurement,
        failure: &TickError,
        row: &mut CsvRow,
    ) -> Option<AttitudeCommand> {
        let first = self.failsafe.state == Failsafe::Nominal;
        match failure {
            TickError::DeadlineOverrun { solve_us } => {
                self.counts.guards.deadline_overruns += 1;
                if first {
                    warn!(solve_us, "deadline overrun: fallback command");
                }
            }
            e => {
                self.counts.control_errors += 1;
                self.counts.guards.controller_failures += 1;
                if first {
                    warn!(error = %e, "controller failed: fallback command");
                }
            }
        }
        let planned = self
            .controller
            .plan_fallback(measurement, self.failsafe.fallback.hold_ticks as usize)
            .and_then(|out| {
                let command = self.guarded(&out.command).ok()?;
                Some((command, out.plan[1]))
            });
        match planned {
            Some((_, next)) => self.failsafe.residual.predict([next.x, next.y, next.z]),
            None => self.failsafe.residual.forget(),
        }
        let event = Event::Failed {
            t,
            planned: planned.is_some(),
            can_hold: self.failsafe.fallback.held().is_some(),
        };
        self.failsafe_on(t, event, planned.map(|(c, _)| c), &mut row.guard)
    }
}

/// [`Controller::update`] with a panic caught: a panicking controller is
/// a bug, but it must not take the loop down with it — the tick fails and
/// the controller is reset.
pub(super) fn update_caught(
    controller: &mut dyn Controller,
    measurement: &Measurement,
    reference: &mut Reference,
) -> Result<dflat_control::TickOutput, TickError> {
    let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        controller.update(measurement, reference)
    }));
    match caught {
        Ok(result) => Ok(result?),
        Err(_) => {
            controller.reset();
            Err(TickError::Panicked)
        }
    }
}

#[cfg(test)]
mod tests {
    use dflat_control::{ReferenceSource, TickOutput};
    use nalgebra::Vector3;

    use super::*;

    /// A controller whose update panics (a bug), counting its resets.
    struct Panicking {
        resets: usize,
    }

    impl Controller for Panicking {
        fn name(&self) -> &'static str {
            "panicking"
        }
        fn update(
            &mut self,
            _: &Measurement,
            _: &mut dyn ReferenceSource,
        ) -> Result<TickOutput, ControlError> {
            panic!("a controller bug")
        }
        fn reset(&mut self) {
            self.resets += 1;
        }
    }

    /// A panic in the controller's update fails the tick (the fallback
    /// flies it) and resets the controller, instead of taking the control
    /// loop down; the next tick calls it again.
    #[test]
    fn a_panicking_controller_fails_its_tick_and_is_reset() {
        let mut controller = Panicking { resets: 0 };
        let measurement = Measurement {
            t: 0.0,
            position: Vector3::new(0.0, 0.0, -2.0),
            yaw: 0.0,
        };
        let mut reference = Reference::setpoint(Vector3::new(1.0, 0.0, -2.0)).unwrap();
        for tick in 1..=2 {
            let got = update_caught(&mut controller, &measurement, &mut reference);
            assert!(matches!(got, Err(TickError::Panicked)), "{got:?}");
            assert_eq!(controller.resets, tick);
        }
    }
}
