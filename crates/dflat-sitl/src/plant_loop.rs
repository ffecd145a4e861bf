//! The SITL's real-time plant loop: integrate the plant, apply the
//! command or the autopilot's own hold, send telemetry and the vision
//! stand-in's samples.

use super::*;

/// Seed offset of the vision stand-in's noise (independent of the
/// LOCAL_POSITION_NED noise).
pub(super) const VISION_SEED: u64 = 0x5649_5349_4f4e;
/// Vision samples in flight at most (latency × rate; older ones dropped).
pub(super) const VISION_QUEUE: usize = 256;

/// The vision stand-in: captures at its rate, sends after its latency.
pub(super) struct VisionStream {
    pub(super) sensor: GaussianSensor,
    /// Capture period \[s\].
    pub(super) period: f64,
    /// Capture → send delay \[s\].
    pub(super) latency: f64,
    /// SITL time of the next capture \[s\].
    pub(super) next_capture: f64,
    /// Captured, not yet sent: (capture time \[s\], position, ZYX euler).
    pub(super) pending: std::collections::VecDeque<(f64, [f64; 3], [f64; 3])>,
}

/// The real-time plant loop: integrate, command or hold, send telemetry.
pub(super) struct PlantLoop {
    pub(super) shared: Arc<Shared>,
    pub(super) plant: Box<dyn Plant>,
    pub(super) sensor: GaussianSensor,
    pub(super) vision: Option<VisionStream>,
    pub(super) options: PlantOptions,
    pub(super) plant_rate_hz: f64,
    pub(super) telemetry_rate_hz: f64,
    pub(super) hover_thrust: f64,
    pub(super) autopilot: SitlAutopilot,
    pub(super) modes: ModeMachine,
    /// `sitl.pose_clock_rate`.
    pub(super) pose_clock_rate: f64,
    pub(super) record_trace: bool,
    pub(super) truth_file: Option<(PathBuf, BufWriter<File>)>,
    /// `[sitl.planner]`: the stream it sends once offboard.
    pub(super) planner: Option<planner::Planner>,
}

impl PlantLoop {
    pub(super) fn run(mut self) -> Result<(), SitlError> {
        let dt = 1.0 / self.plant_rate_hz;
        let telemetry_every = (self.plant_rate_hz / self.telemetry_rate_hz)
            .round()
            .max(1.0) as u64;
        let heartbeat_every = self.plant_rate_hz.round().max(1.0) as u64;
        let start = self.shared.start;
        let mut steps: u64 = 0;
        let mut mode = SitlMode::Hold;
        let mut hold_target = self.plant.position();
        // The moving target of loiter / RTL (position, velocity) and its goal.
        let mut mover: ([f64; 3], [f64; 3]) = (hold_target.into(), [0.0; 3]);
        let mut goal: [f64; 3] = hold_target.into();
        // When the two-streams warning was last said [s].
        let mut told_both: Option<f64> = None;
        let mut rows: u64 = 0;
        let mut csv_error = None;
        let t0 = self.plant.true_state();
        self.sensor.reset(0.0, &t0);
        // First heartbeat right away (sent once a peer is known).
        let mut heartbeat_due = true;

        while !self.shared.stop.load(Ordering::Relaxed) {
            let next = start + Duration::from_secs_f64((steps + 1) as f64 * dt);
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            let elapsed = start.elapsed().as_secs_f64();
            let due = (elapsed / dt).floor() as u64;
            let n = due.saturating_sub(steps).max(1);
            if n > 1 {
                self.shared
                    .counters
                    .late_steps
                    .fetch_add(n - 1, Ordering::Relaxed);
            }
            let before = steps;

            // The mode (pilot, stream), then the command or the hold.
            let attitude = (*lock(&self.shared.command))
                .filter(|(at, _)| at.elapsed() < self.shared.command_timeout());
            let position_sp = self
                .shared
                .px4
                .fresh_setpoint(self.shared.command_timeout());
            let received = attitude.map(|(_, c)| c);
            if let Some(v) = lock(&self.shared.pilot_velocity).take() {
                self.modes.set_velocity(v);
            }
            let request = lock(&self.shared.mode_request).take();
            let elapsed_t = steps as f64 * dt;
            let step = self.modes.step(
                elapsed_t,
                received.is_some() || position_sp.is_some(),
                request,
            );
            if step.refused {
                bump(&self.shared.counters.offboard_refused);
                tracing::warn!("sitl: offboard refused, no setpoint stream");
                let text = dflat_link::statustext(
                    dflat_link::dialect::MavSeverity::MAV_SEVERITY_WARNING,
                    "SITL: offboard refused, no setpoint stream",
                );
                self.send(&text, Kind::Reply);
            }
            if step.changed {
                mode = self.modes.mode();
                bump(&self.shared.counters.mode_changes);
                heartbeat_due = true;
                if mode != SitlMode::Offboard {
                    // Brake and hold where the vehicle stops.
                    let s = self.plant.true_state();
                    let v = s.velocity;
                    hold_target = s.position + v * (v.norm() / (2.0 * HOLD_BRAKE));
                    mover = (hold_target.into(), [0.0; 3]);
                    goal = match mode {
                        SitlMode::Rtl => self.shared.px4.home,
                        _ => hold_target.into(),
                    };
                    if mode == SitlMode::Hold {
                        bump(&self.shared.counters.hold_entries);
                    }
                    tracing::info!(
                        stream = received.is_some(),
                        mode = mode.as_str(),
                        "sitl: mode"
                    );
                } else {
                    tracing::info!("sitl: offboard");
                }
            }
            if let Some(g) = lock(&self.shared.px4.goal).take() {
                goal = g;
            }
            let armed = self.shared.px4.armed();
            let (flown, both) = autopilot_state::latest_wins(attitude, position_sp);
            let flown = flown.filter(|_| mode == SitlMode::Offboard && armed);
            if both && mode == SitlMode::Offboard {
                let now = self.shared.elapsed();
                if now - told_both.unwrap_or(f64::NEG_INFINITY)
                    >= dflat_link::refusal::REFUSAL_REPEAT_S
                {
                    told_both = Some(now);
                    tracing::warn!(
                        "sitl: attitude and position setpoints both stream; the latest type flies"
                    );
                    let text = dflat_link::statustext(
                        dflat_link::dialect::MavSeverity::MAV_SEVERITY_WARNING,
                        "SITL: 2 setpoint streams, the latest type flies",
                    );
                    self.send(&text, Kind::Reply);
                }
            }
            let fresh = match flown {
                Some(autopilot_state::Flown::Attitude(c)) => Some(c),
                _ => None,
            };
            let command = match flown {
                Some(autopilot_state::Flown::Attitude(c)) => self.plant_command(&c),
                Some(autopilot_state::Flown::Position(t)) => position_control::command(
                    &position_control::PositionGains::OFFBOARD,
                    &self.options,
                    &t,
                    &self.plant.true_state(),
                ),
                None if matches!(mode, SitlMode::Loiter | SitlMode::Rtl) => {
                    mover = position_control::approach(
                        mover.0,
                        mover.1,
                        goal,
                        n as f64 * dt,
                        position_control::CRUISE_SPEED,
                        position_control::CRUISE_ACCEL,
                    );
                    hold_target = Vector3::from(mover.0);
                    let target = position_control::PositionTarget {
                        velocity: mover.1,
                        ..position_control::PositionTarget::hold(mover.0)
                    };
                    position_control::command(
                        &position_control::PositionGains::OFFBOARD,
                        &self.options,
                        &target,
                        &self.plant.true_state(),
                    )
                }
                None => {
                    let v = Vector3::from(self.modes.velocity());
                    hold_target += v * (n as f64 * dt);
                    mover = (hold_target.into(), [0.0; 3]);
                    self.hold_command(&hold_target, &v)
                }
            };
            self.shared.mode.store(mode.as_u8(), Ordering::Relaxed);
            self.plant.apply(&command);
            self.plant.advance(n as f64 * dt);
            steps += n;
            self.shared
                .counters
                .plant_steps
                .fetch_add(n, Ordering::Relaxed);

            let mut state = self.plant.true_state();
            if !state.is_finite() {
                if !self.shared.diverged.swap(true, Ordering::Relaxed) {
                    tracing::error!("sitl: plant state is not finite; resetting to hover");
                }
                self.plant.reset(&PlantState::hover(hold_target, GRAVITY));
                state = self.plant.true_state();
            }
            let t = steps as f64 * dt;
            if let Some(msg) = self.shared.latency.due_delayed(Instant::now()) {
                self.send(&msg, Kind::Position);
                self.pose_sent();
            }
            self.sensor.observe(t, &state);
            self.vision(t, &state);

            if before / heartbeat_every != steps / heartbeat_every {
                heartbeat_due = true;
            }
            if heartbeat_due {
                let autopilot = match self.autopilot {
                    SitlAutopilot::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
                    SitlAutopilot::Ardupilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                };
                let hb = dflat_link::heartbeat_autopilot(
                    autopilot,
                    armed,
                    mode.custom_mode(self.autopilot),
                    if armed {
                        MavState::MAV_STATE_ACTIVE
                    } else {
                        MavState::MAV_STATE_STANDBY
                    },
                );
                lock(&self.shared.latest).heartbeat = Some(hb.clone());
                self.send(&hb, Kind::Heartbeat);
                let status = px4_face::sys_status();
                lock(&self.shared.latest).sys_status = Some(status.clone());
                self.send(&status, Kind::SysStatus);
                // Due once per slot, whoever listens: a ground station
                // alone on the GCS port gets 1 Hz, not the plant rate.
                heartbeat_due = false;
            }
            self.px4_streams(t, &state);
            self.planner_sample(t, mode, &state);
            if before / telemetry_every != steps / telemetry_every {
                let sample = TruthSample {
                    t,
                    position: state.position.into(),
                    velocity: state.velocity.into(),
                    euler: [state.roll, state.pitch, state.yaw],
                    command: fresh,
                    mode,
                };
                self.telemetry(&sample, &state);
                *lock(&self.shared.truth) = sample;
                if self.record_trace {
                    lock(&self.shared.trace).push(sample);
                }
                if let Some((path, w)) = &mut self.truth_file {
                    let r = write_truth_row(w, &sample).and_then(|()| {
                        rows += 1;
                        if rows.is_multiple_of(CSV_FLUSH_ROWS) {
                            w.flush()
                        } else {
                            Ok(())
                        }
                    });
                    if let Err(source) = r {
                        // Keep flying without the record; report at stop.
                        tracing::error!(file = %path.display(), error = %source, "sitl: truth CSV write failed; no more rows");
                        csv_error = Some(SitlError::Truth {
                            file: path.clone(),
                            source,
                        });
                        self.truth_file = None;
                    }
                }
            }
        }
        if let Some((path, w)) = &mut self.truth_file {
            w.flush().map_err(|source| SitlError::Truth {
                file: path.clone(),
                source,
            })?;
        }
        csv_error.map_or(Ok(()), Err)
    }

    /// Sends the SITL's own `msg` to both links, counted as `kind`.
    fn send(&self, msg: &MavMessage, kind: Kind) {
        self.shared.send_own(msg, Dest::Both, kind);
    }

    /// The planner's sample due at SITL time `t` \[s\], sent to the
    /// daemon on the vehicle link from the planner's ids.
    fn planner_sample(&mut self, t: f64, mode: SitlMode, state: &PlantState) {
        let Some(planner) = self.planner.as_mut() else {
            return;
        };
        let time_boot_ms = (t * self.pose_clock_rate * 1000.0).round() as u32;
        let Some(msg) = planner.due(
            t,
            mode == SitlMode::Offboard,
            state.position,
            time_boot_ms,
            self.shared.system_id,
        ) else {
            return;
        };
        if let Some(t0) = planner.started_at() {
            lock(&self.shared.planner_start).get_or_insert(t0);
        }
        let (sys, comp) = planner.ids();
        let header = dflat_link::header(sys, comp, planner.sequence());
        if self.shared.send_to_vehicle_as(header, &msg) {
            bump(&self.shared.counters.planner_samples);
        }
    }

    /// A LOCAL_POSITION_NED left (the latency's pose stream without vision).
    fn pose_sent(&self) {
        if self.vision.is_none() {
            self.shared.latency.pose_sent(Instant::now());
        }
    }

    /// The vision stand-in at SITL time `t`: capture when due, send what
    /// has waited its latency.
    fn vision(&mut self, t: f64, state: &PlantState) {
        let Some(v) = &mut self.vision else {
            return;
        };
        let paused = self.shared.pose_paused.load(Ordering::Relaxed);
        if t + 1e-9 >= v.next_capture {
            // Skip captures missed by a late step rather than bunching them.
            while v.next_capture <= t + 1e-9 {
                v.next_capture += v.period;
            }
            v.sensor.observe(t, state);
            if !paused && let Some(m) = v.sensor.measure(t) {
                let offset = *lock(&self.shared.pose_offset);
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
        let mut due = Vec::new();
        while let Some(&(capture, p, euler)) = v.pending.front() {
            if capture + v.latency > t + 1e-9 {
                break;
            }
            v.pending.pop_front();
            due.push((capture, p, euler));
        }
        for (capture, p, euler) in due {
            let usec = (capture * self.pose_clock_rate * 1e6).round() as u64;
            if let Ok(msg) = dflat_link::vision_position_estimate(usec, p, euler, 0, None) {
                self.send(&msg, Kind::Vision);
                self.shared.latency.pose_sent(Instant::now());
            }
        }
    }

    fn telemetry(&mut self, sample: &TruthSample, state: &PlantState) {
        if self.shared.pose_paused.load(Ordering::Relaxed) {
            return;
        }
        let time_boot_ms = (sample.t * self.pose_clock_rate * 1000.0).round() as u32;
        // ATTITUDE first: the daemon's tick that takes this pose then has
        // the attitude of the same instant too (it was one tick late when
        // the pose went first and a tick's cutoff fell between them).
        let rates = state.body_rates.into();
        if let Ok(msg) = dflat_link::attitude(time_boot_ms, sample.euler, rates) {
            lock(&self.shared.latest).attitude = Some(msg.clone());
            self.send(&msg, Kind::Attitude);
        }
        let measured = self.sensor.measure(sample.t);
        let offset = *lock(&self.shared.pose_offset);
        let p = measured.map_or(state.position, |m| m.position);
        let position = [p.x + offset[0], p.y + offset[1], p.z + offset[2]];
        if let Ok(msg) = dflat_link::local_position_ned(time_boot_ms, position, sample.velocity) {
            lock(&self.shared.latest).position = Some(msg.clone());
            let fate = self.shared.latency.pose_fate(Instant::now(), &msg);
            if fate == latency::PoseFate::Send {
                self.send(&msg, Kind::Position);
                self.pose_sent();
            }
        }
    }

    /// The streams of the PX4 face that are due at SITL time `t` \[s\]
    /// (HOME_POSITION, EXTENDED_SYS_STATE, ATTITUDE_QUATERNION,
    /// GLOBAL_POSITION_INT, BATTERY_STATUS; their intervals set by
    /// SET_MESSAGE_INTERVAL). The pose-like ones pause with the pose.
    fn px4_streams(&self, t: f64, state: &PlantState) {
        let due = lock(&self.shared.px4.streams).due(t);
        if due.is_empty() {
            return;
        }
        let time_boot_ms = (t * self.pose_clock_rate * 1000.0).round() as u32;
        let paused = self.shared.pose_paused.load(Ordering::Relaxed);
        let offset = *lock(&self.shared.pose_offset);
        let p = [
            state.position.x + offset[0],
            state.position.y + offset[1],
            state.position.z + offset[2],
        ];
        let px4 = &self.shared.px4;
        for stream in due {
            let msg = match stream {
                px4_face::Stream::AttitudeQuaternion if !paused => px4_face::attitude_quaternion(
                    time_boot_ms,
                    [state.roll, state.pitch, state.yaw],
                    state.body_rates.into(),
                ),
                px4_face::Stream::GlobalPosition if !paused => px4_face::global_position_int(
                    &px4.origin,
                    px4.home,
                    time_boot_ms,
                    p,
                    state.velocity.into(),
                    state.yaw,
                ),
                px4_face::Stream::Home => {
                    px4_face::home_position(&px4.origin, px4.home, (t * 1e6) as u64)
                }
                px4_face::Stream::ExtendedSysState => px4_face::extended_sys_state(
                    dflat_link::dialect::MavLandedState::MAV_LANDED_STATE_IN_AIR,
                ),
                px4_face::Stream::Battery => px4_face::battery_status(),
                _ => continue,
            };
            self.send(&msg, Kind::Reply);
        }
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

    fn hold_command(&self, target: &Vector3<f64>, velocity: &Vector3<f64>) -> PlantCommand {
        hold_law(&self.options, &self.plant.true_state(), target, velocity)
    }
}

/// The autopilot's own position hold (position mode): PD on the true
/// state towards `target` moving at the pilot's `velocity` → tilt and
/// thrust (the autopilot knows its own hover thrust and mass).
pub(super) fn hold_law(
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
