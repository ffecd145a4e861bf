//! The control core's side of the failsafe machine (`tick/failsafe.rs`):
//! it reports what happened — each tick's health, a cause it found, a
//! trial solve, a tick without the controller — and carries out what the
//! machine decides: enter the failsafe and clear it (the supervisor
//! follows), say that the controller flies again, stream a failsafe's
//! brake and level hover (`tick/failsafe_level.rs`) and stop.

use dflat_link::dialect::MavSeverity;
use dflat_link::{AttitudeCommand, set_attitude_target};
use tracing::{error, info};

use super::exit::update_caught;
use super::failsafe::{Event, Failsafe, Health, LevelPlan, Limits};
use super::failsafe_level::{TiltSincePose, brake_command};
use super::{ControlCore, SentCommand};
use crate::guard::{Fallback, ResidualMonitor};
use crate::records::CsvRow;
use crate::supervisor::Cause;

/// The failsafe: the core's part that owns the failsafe machine's state
/// and what its fallbacks and its brake need.
#[derive(Debug)]
pub(super) struct FailsafePart {
    /// The failsafe machine's state (`tick/failsafe.rs`).
    pub(super) state: Failsafe,
    /// The fallback commands: the plan's step, the held command, level.
    pub(super) fallback: Fallback,
    /// The model-consistency residual.
    pub(super) residual: ResidualMonitor,
    /// The autopilot's tilt integrated since the newest pose (the brake).
    pub(super) tilt_since_pose: TiltSincePose,
}

impl ControlCore {
    /// The failsafe machine's settings, from the configuration.
    pub(super) fn failsafe_limits(&self) -> Limits {
        // The stop's level lasts `safety.stop_level_ms` (its own setting),
        // whatever `level_hover_max_ms` says of failures; the stop ends it
        // (`stop_done`), two ticks before the machine would let go, so the
        // stream has no silent tick before it stops.
        let f = &self.settings.failsafe;
        let level_hover_max = if self.engagement.stop.is_some() {
            f.stop_level + 2.0 * self.settings.period
        } else {
            f.level_hover_max
        };
        Limits {
            hold_ticks: self.failsafe.fallback.hold_ticks,
            level_hover_max,
            period: self.settings.period,
        }
    }

    /// Reports the tick's facts at `t` to the failsafe machine — fresh
    /// pose, a live autopilot, the flight state — before the flight state
    /// moves on; the machine enters or clears the failsafe. `level` is the
    /// level command a failsafe would leave, taken before anything reset
    /// the controller.
    pub(super) fn report_health(&mut self, t: f64, level: AttitudeCommand) {
        let health = Health::of(
            t,
            self.supervisor.links(t),
            self.supervisor.state(),
            self.supervisor.stopping(),
            self.level_plan(t, level),
        );
        self.failsafe_on(t, Event::Health(health), None, &mut None);
    }

    /// The failsafe machine entered its failsafe at `t` for `cause`: the
    /// flight state follows (said), the controller is reset, and a
    /// levelling failsafe starts (`level`: `Some(announce)`). `note`
    /// receives the record's guard note.
    pub(super) fn enter_failsafe(
        &mut self,
        t: f64,
        cause: Cause,
        level: Option<bool>,
        note: &mut Option<&'static str>,
    ) {
        if cause == Cause::ControlFailed {
            *note = Some("let_go");
        }
        let Some(tr) = self.supervisor.enter_failsafe(t, cause) else {
            return;
        };
        match cause {
            Cause::ResidualDiverged => {
                self.counts.guards.residual_failsafes += 1;
                *note = Some("residual");
            }
            Cause::ControlFailed => {
                // Stop the stream so the autopilot's own failsafe takes over.
                self.counts.guards.control_failsafes += 1;
                error!(
                    level_hover_s = self.settings.failsafe.level_hover_max,
                    "controller cannot fly: stream stopped, the autopilot's failsafe takes over"
                );
            }
            _ => {}
        }
        self.reset_controller();
        self.poses.last_used_arrival = None;
        self.announce(tr);
        if let Some(announce) = level {
            self.start_level(announce);
        }
    }

    /// The failsafe cleared at `t`: the flight state streams again (said).
    pub(super) fn recover(&mut self, t: f64) {
        if let Some(tr) = self.supervisor.recover(t) {
            self.announce(tr);
        }
    }

    /// The level command a failsafe would leave now: the fallback's level
    /// attitude (yaw of the last command sent) at the hover thrust — the
    /// disturbance estimate's when it has a usable one, else the
    /// configured one. Taken before a failsafe resets the controller.
    pub(super) fn failsafe_level_command(&self) -> AttitudeCommand {
        let mut command = self.failsafe.fallback.level_command();
        if let Some(hover) = self
            .controller
            .disturbance()
            .and_then(|d| self.mapping.normalized(d.hover_thrust).ok())
            .filter(|h| h.is_finite() && (0.0..=1.0).contains(h))
        {
            command.thrust = hover;
        }
        command
    }

    /// What a failsafe entered at `t` streams: `command`, after the brake
    /// that cancels the velocity gained since the newest pose.
    pub(super) fn level_plan(&self, t: f64, command: AttitudeCommand) -> LevelPlan {
        let v = &self.settings.vehicle;
        let brake = self
            .failsafe
            .tilt_since_pose
            .at(t)
            .and_then(|(integral, attitude)| {
                brake_command(
                    integral,
                    attitude,
                    v.tau,
                    v.k,
                    self.guard.max_tilt,
                    0.5 * self.settings.failsafe.level_hover_max,
                )
            });
        LevelPlan { command, brake }
    }

    /// A levelling failsafe started: logged, and said unless level hover
    /// is off (`announce`).
    fn start_level(&mut self, announce: bool) {
        if let Failsafe::FailsafeLevel {
            plan:
                LevelPlan {
                    brake: Some((c, time)),
                    ..
                },
            ..
        } = self.failsafe.state
        {
            info!(
                pitch_deg = c[0].to_degrees(),
                roll_deg = c[1].to_degrees(),
                time_s = time,
                "failsafe brake: cancelling the velocity gained since the last pose"
            );
        }
        if announce {
            info!(
                max_s = self.settings.failsafe.level_hover_max,
                "failsafe: level hover, then the attitude stream stops"
            );
            self.text(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "dflat: failsafe, level hover then stream off",
            );
        }
    }

    /// In a control failsafe: one solve on the newest pose, not sent
    /// (the controller is reset afterwards, so nothing unsent stays in its
    /// window). After [`super::failsafe::TRIAL_TICKS`] good ones in a row the
    /// latch is lifted and the stream resumes at the next tick.
    pub(super) fn trial(&mut self, t: f64) {
        let (Some(pose), Some(reference)) = (self.poses.newest, self.goals.reference.as_ref())
        else {
            return;
        };
        // On a copy: a trial must not move a path's progress.
        let mut reference = reference.clone();
        let measurement = self.tick_measurement(t, &pose);
        let ok = update_caught(self.controller.as_mut(), &measurement, &mut reference).is_ok();
        self.reset_controller();
        self.failsafe_on(t, Event::TrialSolve { ok }, None, &mut None);
    }

    /// A tick on which the controller does not fly: a failsafe's brake or
    /// level-hover command, if one is due (and `None` once
    /// `safety.level_hover_max_ms` has run out: the stream stops). Guarded
    /// like every command; counted as level hover.
    pub(super) fn idle_tick(&mut self, t: f64, row: &mut CsvRow) -> Option<SentCommand> {
        // The record's note before this tick's brake or level.
        let before = row.guard;
        let wanted = self.failsafe_on(t, Event::Idle { t }, None, &mut row.guard)?;
        let command = match self.guard.check(wanted, &mut self.counts.guards) {
            Ok(c) => c,
            Err(e) => {
                // Level at a configured hover thrust always passes; if not,
                // silence is the only safe answer.
                error!(error = %e, "failsafe level command refused by the guard: stream off");
                row.guard = before;
                self.failsafe_on(t, Event::LevelRefused, None, &mut row.guard);
                return None;
            }
        };
        let time_boot_ms = (t * 1000.0) as u64 as u32;
        let message = match set_attitude_target(self.settings.target, time_boot_ms, &command) {
            Ok(m) => m,
            Err(e) => {
                error!(error = %e, "failsafe level command not encodable: stream off");
                row.guard = before;
                self.failsafe_on(t, Event::LevelRefused, None, &mut row.guard);
                return None;
            }
        };
        // The stop's own level (SIGTERM) is not a fallback: the summary's
        // `stop` counts it.
        if self.engagement.stop.is_none() {
            self.counts.guards.level_hover += 1;
        }
        self.counts.commands += 1;
        row.command = Some([command.roll, command.pitch, command.yaw, command.thrust]);
        Some(SentCommand {
            message,
            command,
            pose_arrival: None,
        })
    }
}
