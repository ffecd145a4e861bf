//! What the step sends on its own after the plant moved: a delayed pose
//! come due, the vision stand-in's samples, HEARTBEAT and SYS_STATUS, the
//! PX4 face's streams, the planner's sample, and ATTITUDE then
//! LOCAL_POSITION_NED at their rates (`sitl.telemetry_rate_hz`, or what
//! SET_MESSAGE_INTERVAL set) with the truth sample.

use dflat_link::dialect::{MavAutopilot, MavLandedState, MavState};
use dflat_sim::plant::PlantState;
use dflat_sim::sensing::Sensor;

use super::{Dest, Link, Origin, Outgoing, SitlCore, SitlOutput, VISION_QUEUE};
use crate::counters::SentKind;
use crate::latency::PoseFate;
use crate::px4_face::{self, Stream};
use crate::{ReceivedCommand, SitlAutopilot, SitlMode, TruthSample};

impl SitlCore {
    /// Sends what is due now that the plant stepped from `before` plant
    /// steps to `self.steps`; `fresh` is the attitude command that flew.
    pub(super) fn send_due(
        &mut self,
        before: u64,
        fresh: Option<ReceivedCommand>,
        out: &mut SitlOutput,
    ) {
        let state = self.plant.true_state();
        let t = self.time();
        if let Some(msg) = self.faults.due_delayed(t) {
            let measured_pose = self.vision.is_none();
            self.push_pose(out, msg, SentKind::Position, measured_pose);
        }
        self.sensor.observe(t, &state);
        self.vision(t, &state, out);
        if before / self.heartbeat_every != self.steps / self.heartbeat_every {
            self.heartbeat_due = true;
        }
        if self.heartbeat_due {
            self.heartbeat(out);
        }
        self.px4_streams(t, &state, out);
        self.planner_sample(t, &state, out);
        let steps = self.steps;
        let crossed = |every: u64| before / every != steps / every;
        let rates = self.telemetry_rates;
        let attitude = rates.attitude_every.is_some_and(crossed);
        let position = rates.position_every.is_some_and(crossed);
        if crossed(rates.default_every) || attitude || position {
            let sample = TruthSample {
                t,
                position: state.position.into(),
                velocity: state.velocity.into(),
                euler: [state.roll, state.pitch, state.yaw],
                command: fresh,
                mode: self.mode,
            };
            self.telemetry(&sample, &state, [attitude, position], out);
            self.truth = sample;
            out.truth = Some(sample);
        }
    }

    /// `msg`, a pose, to both links; `measured_pose` when it is one of the
    /// stream the latency probe measures.
    fn push_pose(
        &self,
        out: &mut SitlOutput,
        message: dflat_link::MavMessage,
        kind: SentKind,
        measured_pose: bool,
    ) {
        out.messages.push(Outgoing {
            message,
            to: Dest::Both,
            origin: Origin::Own(kind),
            measured_pose,
        });
    }

    /// The position as reported: `p` plus the pose offset, NED \[m\].
    fn reported(&self, p: [f64; 3]) -> [f64; 3] {
        let o = self.pose_offset;
        [p[0] + o[0], p[1] + o[1], p[2] + o[2]]
    }

    /// `t` \[s\] on the autopilot's `time_boot_ms` clock.
    fn boot_ms(&self, t: f64) -> u32 {
        (t * self.pose_clock_rate * 1000.0).round() as u32
    }

    /// HEARTBEAT and SYS_STATUS, to both links.
    fn heartbeat(&mut self, out: &mut SitlOutput) {
        let autopilot = match self.autopilot {
            SitlAutopilot::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
            SitlAutopilot::Ardupilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        };
        let armed = self.px4.armed;
        let hb = dflat_link::heartbeat_autopilot(
            autopilot,
            armed,
            self.mode.custom_mode(self.autopilot),
            if armed {
                MavState::MAV_STATE_ACTIVE
            } else {
                MavState::MAV_STATE_STANDBY
            },
        );
        self.latest.heartbeat = Some(hb.clone());
        out.send(hb, Dest::Both, SentKind::Heartbeat);
        let status = px4_face::sys_status();
        self.latest.sys_status = Some(status.clone());
        out.send(status, Dest::Both, SentKind::SysStatus);
        // Due once per slot, whoever listens: a ground station alone on
        // the GCS port gets 1 Hz, not the plant rate.
        self.heartbeat_due = false;
    }

    /// The planner's sample due at SITL time `t` \[s\], to the daemon on
    /// the vehicle link from the planner's ids.
    fn planner_sample(&mut self, t: f64, state: &PlantState, out: &mut SitlOutput) {
        let time_boot_ms = self.boot_ms(t);
        let offboard = self.mode == SitlMode::Offboard;
        let system = self.own.0;
        let Some(planner) = self.planner.as_mut() else {
            return;
        };
        let anchor = planner.anchor();
        let messages = planner.due(t, offboard || anchor, state.position, time_boot_ms, system);
        if anchor {
            // Flown by the autopilot's own position loop, as received: the
            // present sample (a position loop has no use for the future).
            if let Some(Ok(target)) = messages
                .first()
                .and_then(crate::position_control::position_target)
            {
                self.px4.set_setpoint(self.clock, target);
            }
            return;
        }
        for message in messages {
            let (sys, comp) = planner.ids();
            let header = dflat_link::header(sys, comp, planner.sequence());
            out.messages.push(Outgoing {
                message,
                to: Dest::Only(Link::Vehicle),
                origin: Origin::Planner(header),
                measured_pose: false,
            });
        }
    }

    /// The vision stand-in at SITL time `t`: capture when due, send what
    /// has waited its latency.
    fn vision(&mut self, t: f64, state: &PlantState, out: &mut SitlOutput) {
        let paused = self.pose_paused;
        let offset = self.pose_offset;
        let clock_rate = self.pose_clock_rate;
        let Some(v) = &mut self.vision else {
            return;
        };
        if t + 1e-9 >= v.next_capture {
            // Skip captures missed by a late step rather than bunching them.
            while v.next_capture <= t + 1e-9 {
                v.next_capture += v.period;
            }
            v.sensor.observe(t, state);
            if !paused && let Some(m) = v.sensor.measure(t) {
                let p = [
                    m.position.x + offset[0],
                    m.position.y + offset[1],
                    m.position.z + offset[2],
                ];
                if v.pending.len() == VISION_QUEUE {
                    v.pending.pop_front();
                }
                v.pending
                    .push_back((t, p, [state.roll, state.pitch, state.yaw]));
            }
        }
        while let Some(&(capture, p, euler)) = v.pending.front() {
            if capture + v.latency > t + 1e-9 {
                break;
            }
            v.pending.pop_front();
            let usec = (capture * clock_rate * 1e6).round() as u64;
            if let Ok(message) = dflat_link::vision_position_estimate(usec, p, euler, 0, None) {
                out.messages.push(Outgoing {
                    message,
                    to: Dest::Both,
                    origin: Origin::Own(SentKind::Vision),
                    measured_pose: true,
                });
            }
        }
    }

    /// ATTITUDE then LOCAL_POSITION_NED of `sample`, each when `due`
    /// (their intervals: [`px4_face::TelemetryRates`]; unless the pose is
    /// paused; the position through the one-shot faults).
    fn telemetry(
        &mut self,
        sample: &TruthSample,
        state: &PlantState,
        [attitude_due, position_due]: [bool; 2],
        out: &mut SitlOutput,
    ) {
        if self.pose_paused {
            return;
        }
        let time_boot_ms = self.boot_ms(sample.t);
        // ATTITUDE first: the daemon's tick that takes this pose then has
        // the attitude of the same instant too (it was one tick late when
        // the pose went first and a tick's cutoff fell between them).
        let rates = state.body_rates.into();
        if attitude_due && let Ok(msg) = dflat_link::attitude(time_boot_ms, sample.euler, rates) {
            self.latest.attitude = Some(msg.clone());
            out.send(msg, Dest::Both, SentKind::Attitude);
        }
        if !position_due {
            return;
        }
        let measured = self.sensor.measure(sample.t);
        let p = measured.map_or(state.position, |m| m.position);
        let position = self.reported(p.into());
        if let Ok(msg) = dflat_link::local_position_ned(time_boot_ms, position, sample.velocity) {
            self.latest.position = Some(msg.clone());
            match self.faults.pose_fate(sample.t, &msg) {
                PoseFate::Send => {
                    let measured_pose = self.vision.is_none();
                    self.push_pose(out, msg, SentKind::Position, measured_pose);
                }
                PoseFate::Drop => out.counts.pose_latency.poses_dropped += 1,
                PoseFate::Delay => out.counts.pose_latency.poses_delayed += 1,
            }
        }
    }

    /// The streams of the PX4 face that are due at SITL time `t` \[s\]
    /// (HOME_POSITION, EXTENDED_SYS_STATE, ATTITUDE_QUATERNION,
    /// GLOBAL_POSITION_INT, BATTERY_STATUS; their intervals set by
    /// SET_MESSAGE_INTERVAL). The pose-like ones pause with the pose.
    fn px4_streams(&mut self, t: f64, state: &PlantState, out: &mut SitlOutput) {
        let due = self.px4.streams.due(t);
        if due.is_empty() {
            return;
        }
        let time_boot_ms = self.boot_ms(t);
        let paused = self.pose_paused;
        let p = self.reported(state.position.into());
        let px4 = &self.px4;
        for stream in due {
            let msg = match stream {
                Stream::AttitudeQuaternion if !paused => px4_face::attitude_quaternion(
                    time_boot_ms,
                    [state.roll, state.pitch, state.yaw],
                    state.body_rates.into(),
                ),
                Stream::GlobalPosition if !paused => px4_face::global_position_int(
                    &px4.origin,
                    px4.home,
                    time_boot_ms,
                    p,
                    state.velocity.into(),
                    state.yaw,
                ),
                Stream::Home => px4_face::home_position(&px4.origin, px4.home, (t * 1e6) as u64),
                Stream::ExtendedSysState => {
                    px4_face::extended_sys_state(MavLandedState::MAV_LANDED_STATE_IN_AIR)
                }
                Stream::Battery => px4_face::battery_status(),
                _ => continue,
            };
            out.send(msg, Dest::Both, SentKind::Reply);
        }
    }
}
