//! The controller's tick: the measurement it gets, the solve with a
//! panic caught, and the one exit (a guarded command, or the fallback the
//! failsafe machine chooses: `tick/exit.rs`).

use dflat_control::Measurement;
use dflat_link::dialect::MavSeverity;
use dflat_link::set_attitude_target;
use nalgebra::Vector3;
use tracing::{error, info};

use super::exit::{TickError, update_caught};
use super::failsafe::Event;
use super::pose::PoseSample;
use super::{ControlCore, SentCommand, TickTime};
use crate::records::{CsvDisturbance, CsvRow};
use crate::summary::DisturbanceSummary;
use crate::supervisor::{FlightState, Goal};

impl ControlCore {
    /// Runs the controller on `pose` towards the reference and produces the
    /// tick's command (or none when it cannot be encoded); returns it and
    /// the solve time. `None`: no reference, the controller did not run.
    pub(super) fn control(
        &mut self,
        time: &TickTime,
        pose: PoseSample,
        stopwatch: &mut dyn FnMut() -> f64,
        row: &mut CsvRow,
    ) -> Option<(Option<SentCommand>, u32)> {
        let t = time.t;
        let mut reference = self.goals.reference.take()?;
        self.tell_skipped(time.tick);
        let multi_rate = self.settings.multi_rate;
        let measurement = self.tick_measurement(t, &pose);
        // Standby: the tick before sent a command the autopilot did not
        // apply; record the input its attitude shows instead, before this
        // tick's update uses the window.
        self.correct_standby_input();
        let t0 = stopwatch();
        // Routes and streams are trajectories in time: at the tick's, as the
        // controller takes it (multi-rate: the tick time; from the poses:
        // the pose's, or a step after the last tick on a tick without a
        // new pose, where its state is).
        reference.set_time(self.controller.tick_time(&measurement));
        let result = update_caught(self.controller.as_mut(), &measurement, &mut reference);
        self.goals.reference = Some(reference);
        if result.is_err() && multi_rate {
            // After a reset (panic) the window needs a sample again (a
            // repeated sample replaces the one held).
            self.observe(&pose);
        }
        let solve = (stopwatch() - t0).max(0.0);
        let solve_us = (solve * 1e6).min(f64::from(u32::MAX)) as u32;
        row.solve_us = Some(solve_us);
        let path_done = matches!(self.supervisor.goal(), Goal::Path)
            && self
                .goals
                .reference
                .as_ref()
                .is_some_and(|r| r.is_finished());
        let produced = result.and_then(|out| {
            let command = self.guarded(&out.command)?;
            if solve > self.settings.period {
                return Err(TickError::DeadlineOverrun { solve_us });
            }
            Ok((out, command))
        });
        // The one exit point: a guarded controller command, or the fallback
        // (the previous plan, the held command, then level hover).
        let (command, out) = match produced {
            Ok((out, command)) => {
                self.failsafe_on(t, Event::Solved, None, &mut row.guard);
                self.counts.solves.record(&out);
                self.failsafe.fallback.good(command);
                self.failsafe
                    .residual
                    .predict([out.plan[1].x, out.plan[1].y, out.plan[1].z]);
                (command, Some(out))
            }
            Err(failure) => match self.fallback_command(t, &measurement, &failure, row) {
                Some(command) => (command, None),
                None => return Some((None, solve_us)),
            },
        };
        // This tick's command is not applied in standby: correct it at the
        // next tick from the attitude then.
        self.engagement.standby_attitude = if self.supervisor.state() == FlightState::Standby {
            self.poses.attitude
        } else {
            None
        };
        let time_boot_ms = (t * 1000.0) as u64 as u32;
        // Every path above is guarded (or is the fallback's own finite
        // hover); the encoder refuses a non-finite field all the same.
        let sent = match set_attitude_target(self.settings.target, time_boot_ms, &command) {
            Ok(message) => {
                let fresh = self.poses.last_used_arrival != Some(pose.arrival);
                self.poses.last_used_arrival = Some(pose.arrival);
                self.counts.commands += 1;
                row.command = Some([command.roll, command.pitch, command.yaw, command.thrust]);
                Some(SentCommand {
                    message,
                    command,
                    pose_arrival: fresh.then_some(pose.arrival),
                })
            }
            Err(e) => {
                error!(error = %e, "guarded command not encodable: nothing sent");
                None
            }
        };
        if let Some(out) = out {
            self.say_learned();
            row.plan = Some(out.plan.map(|p| [p.x, p.y, p.z]));
            row.reference = Some([out.reference.x, out.reference.y, out.reference.z]);
            if let Some(report) = self.controller.disturbance() {
                let hover = self.mapping.normalized(report.hover_thrust).ok();
                row.disturbance = Some(CsvDisturbance {
                    acceleration: report.acceleration,
                    thrust_scale: report.thrust_scale,
                    hover_thrust: hover,
                    status: report.status,
                });
                self.counts.disturbance = Some(DisturbanceSummary {
                    report,
                    hover_thrust_normalized: hover,
                });
            }
        }
        if path_done {
            if let Some(tr) = self.supervisor.on_path_finished(t) {
                self.announce(tr);
            }
            // Holding the end, or the path again (`mission.repeat`).
            self.refresh_reference();
        }
        Some((sent, solve_us))
    }

    /// Says in words when the learned residual starts acting, fades (out of
    /// its data's support, or its running error grew) or comes back.
    fn say_learned(&mut self) {
        use dflat_control::learned::LearnedStatus;
        let status = self.controller.learned_status();
        if status == self.learned_said {
            return;
        }
        if let Some(s) = status {
            let words = match s {
                LearnedStatus::Active => "learned residual: acting",
                LearnedStatus::OutOfSupport => {
                    "learned residual: outside its data's speed, tilt or thrust: fading to the parametric model"
                }
                LearnedStatus::ErrorGrew => {
                    "learned residual: it explains the flight worse than the parametric model: fading to the parametric model"
                }
            };
            info!(status = ?s, "{words}");
            // To the ground station too (STATUSTEXT holds 50 characters).
            let (severity, text) = match s {
                LearnedStatus::Active => {
                    (MavSeverity::MAV_SEVERITY_INFO, "learned residual acting")
                }
                LearnedStatus::OutOfSupport => (
                    MavSeverity::MAV_SEVERITY_NOTICE,
                    "learned residual faded: outside its data",
                ),
                LearnedStatus::ErrorGrew => (
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "learned residual faded: its error grew",
                ),
            };
            self.text(severity, text);
        }
        self.learned_said = status;
    }

    /// Tells the controller the ticks since its last update without one
    /// (the loop stalled, or did not fly it), before the update of `tick`:
    /// a controller that takes its clock from the poses counts them
    /// (`Controller::skipped`).
    fn tell_skipped(&mut self, tick: u64) {
        if let Some(last) = self.last_update_tick.replace(tick) {
            let skipped = tick.saturating_sub(last).saturating_sub(1);
            if skipped > 0 {
                self.controller
                    .skipped(u32::try_from(skipped).unwrap_or(u32::MAX));
            }
        }
    }

    /// The measurement a tick at `t` hands the controller: multi-rate, the
    /// tick's own time (the samples were observed as they arrived);
    /// otherwise the newest pose at its capture time (not newer than the
    /// last: no new pose).
    pub(super) fn tick_measurement(&self, t: f64, pose: &PoseSample) -> Measurement {
        Measurement {
            t: if self.settings.multi_rate {
                t
            } else {
                pose.capture
            },
            position: Vector3::from(pose.position),
            yaw: self.yaw_of(pose.yaw, self.poses.attitude_yaw),
        }
    }
}
