//! The step's flight: the mode (pilot, stream), then the command or the
//! autopilot's own hold, loiter or RTL, and the plant integrated.

use std::f64::consts::PI;

use dflat_control::AttitudeCommand as PlantCommand;
use dflat_link::dialect::MavSeverity;
use dflat_sim::plant::{PlantOptions, PlantState};
use nalgebra::Vector3;

use super::{Dest, SitlCore, SitlEvent, SitlOutput};
use crate::autopilot_state::{Flown, latest_wins};
use crate::counters::SentKind;
use crate::position_control::{self, PositionGains, PositionTarget};
use crate::{GRAVITY, ReceivedCommand, SitlMode};

/// Deceleration the position mode brakes at when it takes over \[m/s²\]
/// (its stop point is held, not the point where it took over).
const HOLD_BRAKE: f64 = 2.5;
/// Horizontal gains of the hold loop: `a = KP·(p_hold − p) − KD·v`. With the
/// 0.2 s attitude lag the closed loop is well damped (≈ 1 rad/s).
const HOLD_KP: f64 = 1.0;
const HOLD_KD: f64 = 1.6;
/// Vertical gains of the hold loop (spatial and full plants).
const HOLD_KP_Z: f64 = 2.0;
const HOLD_KD_Z: f64 = 2.5;
/// Tilt the hold loop asks for at most \[deg\].
const HOLD_MAX_TILT_DEG: f64 = 20.0;

impl SitlCore {
    /// Switches modes, flies `n` plant steps on the command in force (or
    /// the autopilot's own loop) and returns the attitude command that
    /// flew (`None` while the autopilot flies itself).
    pub(super) fn fly(&mut self, n: u64, out: &mut SitlOutput) -> Option<ReceivedCommand> {
        let dt = self.dt;
        let timeout = self.command_timeout;
        let clock = self.clock;
        let attitude = self.command.filter(|(at, _)| clock - at < timeout);
        let position_sp = self.px4.fresh_setpoint(clock, timeout);
        let received = attitude.map(|(_, c)| c);
        let request = self.request.take();
        let step = self.modes.step(
            self.time(),
            received.is_some() || position_sp.is_some(),
            request,
        );
        if step.refused {
            out.counts.offboard_refused += 1;
            tracing::warn!("sitl: offboard refused, no setpoint stream");
            let text = dflat_link::statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "SITL: offboard refused, no setpoint stream",
            );
            out.send(text, Dest::Both, SentKind::Reply);
        }
        if step.changed {
            let from = self.mode;
            self.mode = self.modes.mode();
            out.counts.mode_changes += 1;
            out.events.push(SitlEvent::ModeChanged {
                from,
                to: self.mode,
            });
            self.heartbeat_due = true;
            if self.mode != SitlMode::Offboard {
                // Brake and hold where the vehicle stops.
                let s = self.plant.true_state();
                let v = s.velocity;
                self.hold_target = s.position + v * (v.norm() / (2.0 * HOLD_BRAKE));
                self.mover = (self.hold_target.into(), [0.0; 3]);
                self.goal = match self.mode {
                    SitlMode::Rtl => self.px4.home,
                    _ => self.hold_target.into(),
                };
                if self.mode == SitlMode::Hold {
                    out.counts.hold_entries += 1;
                }
                tracing::info!(
                    stream = received.is_some(),
                    mode = self.mode.as_str(),
                    "sitl: mode"
                );
            } else {
                tracing::info!("sitl: offboard");
            }
        }
        if let Some(g) = self.pending_goal.take() {
            self.goal = g;
        }
        let (flown, both) = latest_wins(attitude, position_sp);
        let flown = flown.filter(|_| self.mode == SitlMode::Offboard && self.px4.armed);
        if both && self.mode == SitlMode::Offboard {
            self.tell_both(out);
        }
        let fresh = match flown {
            Some(Flown::Attitude(c)) => Some(c),
            _ => None,
        };
        let span = n as f64 * dt;
        let command = match flown {
            Some(Flown::Attitude(c)) => self.plant_command(&c),
            Some(Flown::Position(t)) => position_control::command(
                &PositionGains::OFFBOARD,
                &self.options,
                &t,
                &self.plant.true_state(),
            ),
            None if matches!(self.mode, SitlMode::Loiter | SitlMode::Rtl) => {
                self.mover = position_control::approach(
                    self.mover.0,
                    self.mover.1,
                    self.goal,
                    span,
                    position_control::CRUISE_SPEED,
                    position_control::CRUISE_ACCEL,
                );
                self.hold_target = Vector3::from(self.mover.0);
                let target = PositionTarget {
                    velocity: self.mover.1,
                    ..PositionTarget::hold(self.mover.0)
                };
                position_control::command(
                    &PositionGains::OFFBOARD,
                    &self.options,
                    &target,
                    &self.plant.true_state(),
                )
            }
            // Offboard without a live stream (`sitl.stays_offboard`,
            // ArduPilot's GUIDED after GUID_TIMEOUT): level at hover thrust.
            None if self.mode == SitlMode::Offboard => PlantCommand {
                pitch: 0.0,
                roll: 0.0,
                yaw: self.plant.true_state().yaw,
                thrust: GRAVITY,
            },
            None => {
                let v = Vector3::from(self.modes.velocity());
                self.hold_target += v * span;
                self.mover = (self.hold_target.into(), [0.0; 3]);
                hold_law(
                    &self.options,
                    &self.plant.true_state(),
                    &self.hold_target,
                    &v,
                )
            }
        };
        if let Some((at, dv)) = self.gust
            && self.time() >= at
        {
            self.gust = None;
            let mut s = self.plant.true_state();
            s.velocity += dv;
            self.plant.reset(&s);
            tracing::info!(velocity = ?dv, "sitl: gust");
        }
        self.plant.apply(&command);
        self.plant.advance(span);
        self.steps += n;
        out.counts.plant_steps += n;
        if !self.plant.true_state().is_finite() {
            if !self.diverged {
                self.diverged = true;
                out.events.push(SitlEvent::Diverged);
                tracing::error!("sitl: plant state is not finite; resetting to hover");
            }
            self.plant
                .reset(&PlantState::hover(self.hold_target, GRAVITY));
        }
        fresh
    }

    /// Says that both setpoint streams are alive (the latest type flies),
    /// at most every [`dflat_link::refusal::REFUSAL_REPEAT_S`].
    fn tell_both(&mut self, out: &mut SitlOutput) {
        let now = self.clock;
        if now - self.told_both.unwrap_or(f64::NEG_INFINITY) < dflat_link::refusal::REFUSAL_REPEAT_S
        {
            return;
        }
        self.told_both = Some(now);
        tracing::warn!("sitl: attitude and position setpoints both stream; the latest type flies");
        let text = dflat_link::statustext(
            MavSeverity::MAV_SEVERITY_WARNING,
            "SITL: 2 setpoint streams, the latest type flies",
        );
        out.send(text, Dest::Both, SentKind::Reply);
    }

    /// The plant command for a received one: angles as sent, normalised
    /// thrust → specific thrust via the plant's hover value.
    fn plant_command(&self, c: &ReceivedCommand) -> PlantCommand {
        PlantCommand {
            pitch: c.pitch,
            roll: c.roll,
            yaw: c.yaw,
            thrust: c.thrust / self.hover_thrust * GRAVITY,
        }
    }
}

/// The autopilot's own position hold (position mode): PD on the true
/// state towards `target` moving at the pilot's `velocity` → tilt and
/// thrust (the autopilot knows its own hover thrust and mass).
pub(crate) fn hold_law(
    options: &PlantOptions,
    s: &PlantState,
    target: &Vector3<f64>,
    velocity: &Vector3<f64>,
) -> PlantCommand {
    let e = target - s.position;
    let max_a = GRAVITY * HOLD_MAX_TILT_DEG.to_radians().tan();
    let limit = |a: f64| a.clamp(-max_a, max_a);
    let ax = limit(HOLD_KP * e.x + HOLD_KD * (velocity.x - s.velocity.x));
    let ay = limit(HOLD_KP * e.y + HOLD_KD * (velocity.y - s.velocity.y));
    let az = limit(HOLD_KP_Z * e.z + HOLD_KD_Z * (velocity.z - s.velocity.z));
    // Into the yaw frame: forward / right accelerations.
    let (sy, cy) = s.yaw.sin_cos();
    let a_fwd = cy * ax + sy * ay;
    let a_right = -sy * ax + cy * ay;
    let pitch = (-a_fwd / GRAVITY).atan();
    let roll = (a_right * pitch.cos() / GRAVITY).atan();
    let specific = (GRAVITY - az) / (pitch.cos() * roll.cos()).max(0.5);
    PlantCommand {
        pitch,
        roll,
        yaw: wrap(s.yaw),
        thrust: options.thrust_command_for(specific),
    }
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}
