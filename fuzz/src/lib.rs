//! Shared harness of the fuzz targets: the daemon's receive path without
//! sockets or threads.
//!
//! bytes → [`FrameParser`] (fed in chunks, like a serial/TCP stream) →
//! [`LinkRx`] (source filter, decode, counters) → the daemon's own event
//! mapping ([`event_from`]) → the daemon's pure control step
//! ([`ControlCore::apply`] per event, [`ControlCore::step`] at 50 Hz on a
//! synthetic clock) with the configured controller: the same code the
//! control thread runs, not a copy. Every command it produces is checked
//! finite and within the tilt limit; the supervisor's goal is checked too.
//!
//! Every invariant is an `assert!`: a violation is a crash libFuzzer keeps.

use dflat_daemon::config::{Config, MissionStart, PoseSourceKind, PoseTime};
use dflat_daemon::control::{build_controller, thrust_mapping};
use dflat_daemon::supervisor::{FlightState, Goal};
use dflat_daemon::tick::{ControlCore, TickTime, event_from, pose_source, source_filter};
use dflat_link::{
    Frame, FrameError, FrameParser, Inbound, LinkRx, MAX_FRAME_LEN, PoseSource, RxOutcome, frames,
};

/// Control period \[s\] of the synthetic tick.
pub const DT: f64 = 0.02;

/// A daemon configuration picked by the bits of `flags`.
pub fn config(flags: u8) -> Config {
    let mut c = Config::default();
    c.link.pose_source = match flags % 3 {
        0 => PoseSourceKind::LocalPositionNed,
        1 => PoseSourceKind::Odometry,
        _ => PoseSourceKind::VisionPositionEstimate,
    };
    c.link.vehicle_setpoints = flags & 0x04 != 0;
    if flags & 0x08 != 0 {
        c.link.pose_components = vec![197];
    }
    c.link.pose_time = if flags & 0x10 != 0 {
        PoseTime::Arrival
    } else {
        PoseTime::Source
    };
    if flags & 0x20 != 0 {
        c.mission.start = MissionStart::Path;
    }
    if flags & 0x40 != 0 {
        c.mission.geofence = [5.0, 5.0, 5.0];
        c.mission.path = vec![[-1.0, -1.0, -1.0], [1.0, 1.0, -1.0]];
    }
    c.validate(std::path::Path::new("fuzz.toml"))
        .expect("harness config is valid");
    c
}

/// The receive path and state machine of one daemon.
pub struct Harness {
    /// The stream parser.
    pub parser: FrameParser,
    /// Filter, decoder and counters.
    pub link: LinkRx,
    pose_source: PoseSource,
    /// The daemon's control step (supervisor, pose clock, controller, guard).
    pub core: ControlCore,
    geofence: [f64; 3],
    max_tilt: f64,
    tick: u64,
    /// Synthetic monotonic time \[s\].
    pub now: f64,
    next_tick: f64,
    handled: u64,
    accepted: u64,
    ignored: u64,
    rejected: u64,
    /// Framing errors seen.
    pub frame_errors: u64,
}

impl Harness {
    /// A daemon in `WaitingForPose` with the configuration `cfg`, built as
    /// `dflat_daemon::daemon::spawn` builds it.
    pub fn new(cfg: &Config) -> Self {
        let l = &cfg.link;
        Self {
            parser: FrameParser::new(),
            link: LinkRx::new(source_filter(l)),
            pose_source: pose_source(l.pose_source),
            core: ControlCore::new(
                cfg,
                build_controller(cfg).expect("harness config builds"),
                thrust_mapping(cfg),
            ),
            geofence: cfg.mission.geofence,
            max_tilt: cfg.vehicle.max_tilt_deg.to_radians(),
            tick: 0,
            now: 0.0,
            next_tick: 0.0,
            handled: 0,
            accepted: 0,
            ignored: 0,
            rejected: 0,
            frame_errors: 0,
        }
    }

    /// Advances the synthetic clock by `dt` \[s\], running the control
    /// step at 50 Hz on the way (solves take no synthetic time).
    pub fn advance(&mut self, dt: f64) {
        assert!(dt.is_finite() && dt >= 0.0);
        self.now += dt;
        while self.next_tick <= self.now {
            let t = self.next_tick;
            let time = TickTime {
                tick: self.tick,
                t,
                scheduled: t,
                jitter_us: 0,
            };
            let out = self.core.step(&time, std::iter::empty(), &mut || t);
            assert_eq!(out.row.state, self.core.state());
            for tr in &out.transitions {
                assert!(tr.text().len() <= 50, "{}", tr.text());
            }
            if let Some(sent) = &out.command {
                let c = sent.command;
                assert!(self.core.state().streams(), "a command outside streaming");
                assert!(
                    [c.roll, c.pitch, c.yaw, c.thrust]
                        .iter()
                        .all(|v| v.is_finite()),
                    "{c:?}"
                );
                assert!(
                    dflat_control::tilt::tilt(c.pitch, c.roll) <= self.max_tilt + 1e-9,
                    "{c:?}"
                );
                assert!((0.0..=1.0).contains(&c.thrust), "{c:?}");
            }
            self.tick += 1;
            self.next_tick += DT;
        }
        self.check_supervisor();
    }

    /// Pushes received bytes and handles every complete frame, advancing the
    /// clock by `frame_dt(frame)` before each one (its arrival time).
    pub fn push(&mut self, bytes: &[u8], frame_dt: &mut dyn FnMut(&Frame) -> f64) {
        self.parser.push(bytes);
        while let Some(item) = self.parser.next_frame() {
            match item {
                Ok(frame) => {
                    self.advance(frame_dt(&frame));
                    self.on_frame(&frame);
                }
                Err(e) => self.on_frame_error(&e),
            }
        }
        // Only an incomplete candidate frame is held back.
        assert!(
            self.parser.pending() < MAX_FRAME_LEN,
            "parser holds {} bytes",
            self.parser.pending()
        );
    }

    /// End of stream.
    pub fn finish(&mut self) {
        for item in self.parser.finish() {
            match item {
                Ok(frame) => self.on_frame(&frame),
                Err(e) => self.on_frame_error(&e),
            }
        }
        assert_eq!(self.parser.pending(), 0);
        self.check_counters();
    }

    /// A framing error, counted as the receive task counts it.
    pub fn on_frame_error(&mut self, e: &FrameError) {
        let _ = e.to_string();
        self.frame_errors += 1;
        self.link.frame_error(e);
    }

    /// One parsed frame through filter, decoder, event mapping and supervisor.
    pub fn on_frame(&mut self, frame: &Frame) {
        assert!(frame.header.system_id <= 255);
        assert!(frame.len <= MAX_FRAME_LEN);
        self.handled += 1;
        let arrival = self.now;
        match self.link.handle(&frame.header, &frame.message) {
            RxOutcome::Accepted(inbound) => {
                self.accepted += 1;
                check_inbound(&inbound);
                self.apply(inbound, arrival);
            }
            RxOutcome::Ignored(_) => self.ignored += 1,
            RxOutcome::Rejected(e) => {
                self.rejected += 1;
                let _ = e.to_string();
            }
        }
        self.check_supervisor();
    }

    /// The receive task's event mapping, then the control step's `apply`.
    fn apply(&mut self, inbound: Inbound, arrival: f64) {
        if let Some(event) = event_from(&inbound, self.pose_source, arrival) {
            self.core.apply(event);
        }
    }

    /// The supervisor never holds or tracks a non-finite or fenced-out goal.
    fn check_supervisor(&self) {
        let s = self.core.supervisor();
        match (s.state(), s.goal()) {
            (FlightState::WaitingForPose, Goal::None) => {}
            (FlightState::WaitingForPose, g) => panic!("waiting with goal {g:?}"),
            (_, Goal::None) => panic!("{:?} without a goal", s.state()),
            (_, Goal::Hold(p)) => assert!(p.iter().all(|v| v.is_finite()), "hold {p:?}"),
            (_, Goal::Setpoint(p)) => {
                assert!(p.iter().all(|v| v.is_finite()), "setpoint {p:?}");
                assert!(
                    p.iter().zip(&self.geofence).all(|(v, f)| v.abs() <= *f),
                    "setpoint {p:?} outside the fence"
                );
            }
            (_, Goal::Path | Goal::Mission | Goal::Stream) => {}
            (_, Goal::Brake { from, velocity }) => assert!(
                from.iter().chain(&velocity).all(|v| v.is_finite()),
                "brake {from:?} {velocity:?}"
            ),
        }
        if s.state() == FlightState::Tracking {
            assert!(matches!(
                s.goal(),
                Goal::Setpoint(_) | Goal::Path | Goal::Mission | Goal::Stream
            ));
        }
        let t = s.time_in_states(self.now);
        assert!(t.iter().all(|v| v.is_finite() && *v >= 0.0), "{t:?}");
    }

    /// Every message and error is counted exactly once.
    pub fn check_counters(&self) {
        let st = &self.link.stats;
        assert_eq!(st.received.total(), self.handled);
        assert_eq!(
            self.accepted + self.ignored + self.rejected,
            self.handled,
            "outcomes"
        );
        assert_eq!(
            st.ignored_wrong_source + st.ignored_not_addressed,
            self.ignored
        );
        assert_eq!(
            st.inbound_errors() + st.send_errors,
            self.rejected + self.frame_errors,
            "{}",
            st.summary()
        );
        assert_eq!(st.send_errors, 0);
    }
}

/// Everything the decoder accepts is finite (and quaternions are unit).
pub fn check_inbound(inbound: &Inbound) {
    let finite = |v: f64| v.is_finite();
    match inbound {
        Inbound::Pose(p) => {
            assert!(p.position.iter().copied().all(finite), "{p:?}");
            assert!(p.yaw.is_none_or(finite), "{p:?}");
        }
        Inbound::PositionSetpoint(s) => {
            assert!(s.position.iter().copied().all(finite), "{s:?}");
            assert!(s.yaw.is_none_or(finite), "{s:?}");
            assert!(
                s.velocity.is_none_or(|v| v.iter().copied().all(finite))
                    && s.acceleration.is_none_or(|a| a.iter().copied().all(finite)),
                "{s:?}"
            );
        }
        Inbound::Attitude(a) => {
            assert!(
                [a.roll, a.pitch, a.yaw].into_iter().all(finite)
                    && a.rates.iter().copied().all(finite),
                "{a:?}"
            );
        }
        Inbound::AttitudeTarget(a) => {
            if let Some(q) = a.q {
                assert!(q.iter().copied().all(finite), "{a:?}");
                let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
                assert!((n - 1.0).abs() < 1e-9, "{a:?}");
            }
            assert!(a.body_rates.iter().all(|r| r.is_none_or(finite)), "{a:?}");
            assert!(a.thrust.is_none_or(finite), "{a:?}");
        }
        Inbound::ParamValue(p) => {
            assert!(p.value.is_finite() && p.name.len() <= 16, "{p:?}");
        }
        Inbound::Heartbeat(_) | Inbound::CommandAck(_) | Inbound::Other(_) => {}
    }
}

/// Differential check: the whole buffer through [`frames`] gives the same
/// results, in the same order, as the stream parser fed in chunks.
pub fn check_chunked_equals_whole(bytes: &[u8], chunk_lens: &mut dyn FnMut() -> usize) {
    let whole: Vec<_> = frames(bytes).collect();
    let mut parser = FrameParser::new();
    let mut chunked = Vec::new();
    let mut rest = bytes;
    while !rest.is_empty() {
        let n = chunk_lens().clamp(1, rest.len());
        parser.push(&rest[..n]);
        rest = &rest[n..];
        while let Some(item) = parser.next_frame() {
            chunked.push(item);
        }
    }
    chunked.extend(parser.finish());
    assert_eq!(whole.len(), chunked.len(), "event counts differ");
    for (a, b) in whole.iter().zip(&chunked) {
        match (a, b) {
            // Messages with NaN fields are not `==` themselves: compare ids.
            (Ok(a), Ok(b)) => {
                assert_eq!((a.header, a.len, a.version), (b.header, b.len, b.version));
                assert_eq!(
                    mavlink::Message::message_id(&a.message),
                    mavlink::Message::message_id(&b.message)
                );
            }
            (a, b) => assert_eq!(a.as_ref().err(), b.as_ref().err()),
        }
    }
}

/// A small deterministic generator for chunk lengths and time steps.
pub struct Lcg(pub u64);

impl Lcg {
    /// Next 32 pseudo-random bits.
    pub fn next_u32(&mut self) -> u32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) as u32
    }
}

pub use dflat_link::mavlink;

pub mod link_bodies;

#[cfg(test)]
mod tests {
    use super::*;

    fn run(seed: &[u8]) -> Harness {
        let mut h = Harness::new(&config(seed[0]));
        h.push(&seed[2..], &mut |f| f64::from(f.header.sequence) * 1e-3);
        h.finish();
        assert_eq!(h.frame_errors, 0, "{}", h.link.stats.summary());
        h
    }

    /// The seeds (written by `seeds.py`) reach tracking: the harness and
    /// the hand-computed CRCs are right.
    #[test]
    fn seeds_reach_tracking() {
        for seed in [
            &include_bytes!("../seeds/decode_bytes/lpn_hold_setpoint")[..],
            &include_bytes!("../seeds/decode_bytes/odom")[..],
            &include_bytes!("../seeds/decode_bytes/vpe")[..],
        ] {
            let h = run(seed);
            assert_eq!(h.core.state(), FlightState::Tracking);
            assert_eq!(
                h.core.supervisor().goal(),
                Goal::Setpoint([5.0, 1.0, -10.0])
            );
        }
    }
}
