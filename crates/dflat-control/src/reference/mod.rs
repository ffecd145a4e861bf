//! Reference generation: every goal becomes a reference over the horizon
//! that a vehicle can fly.
//!
//! * [`Reference::setpoint`] — a fixed point.
//! * [`Reference::path`] — the paper's path (§VII-C): closest point, then
//!   δt·speed along the polyline.
//! * [`Reference::braking`] — a stop along the current velocity.
//! * [`Reference::route`] / [`Reference::setpoint_route`] — a polyline on a
//!   smooth speed profile in time (routes, below).
//! * [`Reference::stream`] — a planner's streamed samples, extrapolated
//!   (streams, below).
//!
//! # Routes
//!
//! How to build one: a [`RouteSpec`] with the vehicle's position and
//! velocity, the [`Waypoint`]s (position, optional leg speed, hold time,
//! optional yaw), the cruise speed and the ramps' peak acceleration.
//!
//! ```
//! use dflat_control::reference::{Reference, RouteSpec, Waypoint};
//! use nalgebra::Vector3;
//!
//! let spec = RouteSpec {
//!     start: Vector3::new(0.0, 0.0, -10.0),       // the vehicle, NED m
//!     start_velocity: Vector3::zeros(),           // its velocity, NED m/s
//!     waypoints: vec![
//!         Waypoint::at(Vector3::new(20.0, 0.0, -10.0)), // cruise speed, fly through
//!         Waypoint {
//!             speed: Some(2.0),                   // the leg *to* it, m/s
//!             hold_s: 3.0,                        // stop and wait 3 s
//!             yaw: Some(std::f64::consts::FRAC_PI_2), // face east there
//!             ..Waypoint::at(Vector3::new(20.0, 10.0, -10.0))
//!         },
//!     ],
//!     cruise_speed: 5.0,                          // m/s
//!     acceleration: 1.5,                          // peak of every ramp, m/s²
//! };
//! let mut reference = Reference::route(&spec).unwrap();
//! assert!((reference.path_length() - 30.0).abs() < 1e-9);
//! reference.set_time(12.0); // the controller's clock: the route starts now
//! assert_eq!(reference.last_reached(), None);
//! ```
//!
//! Each tick the shell calls [`Reference::set_time`] with the measurement's
//! time before the controller's update. The profile: every speed change
//! (start, leg speeds, stops at holds and the end) is a cosine ramp
//! `v(τ) = v_a + (v_b − v_a)(1 − cos(πτ/T))/2`, `T = π|v_b − v_a|/(2a)`,
//! so neither the reference velocity nor its acceleration steps; legs too
//! short for their speed fly the fastest speed that fits. A start with the
//! vehicle moving keeps the along-track speed as the start ramp's first
//! speed and blends the rest `w` out as `e(τ) = w·τ·exp(−τ/T_b)`,
//! `T_b = max(2|w|/a, 0.5 s)`: the reference starts at the vehicle with
//! its velocity and merges onto the line.
//!
//! # Streams
//!
//! A [`StreamSample`] (time on the controller's clock, position, optional
//! velocity, acceleration, yaw, yaw rate) is extrapolated as a coordinated
//! turn (exact on a circle flown at constant speed) with its own jerk for
//! [`StreamSettings::jerk_horizon_s`], for
//! [`StreamSettings::extrapolation_s`], then slowed to a stop over
//! [`StreamSettings::decay_s`] with a cosine on the prediction's clock,
//! so the horizon's tail stops smoothly and a stream that goes silent
//! becomes a smooth stop and hold. [`Reference::push_sample`] refreshes it.
//! Samples stamped ahead of the controller's time are the trajectory sent
//! ahead: flown as sent up to the newest, predicted beyond it.
//!
//! # Paths and stops
//!
//! For a path, the reference at tick k is the point of the path closest to
//! the measured position, `y_ref,k = y_closest`; the reference over the
//! horizon advances δt·speed per step *along* the path,
//! `y_ref,k+j = point(s_k + j·δt·speed)` with `s` the arc length, so a step
//! that passes a corner carries on along the next segment (the paper: "the
//! reference velocity changes as the output reference moves to the next
//! straight line segment"), and the reference holds at the path end.
//!
//! The progress `s_k` is monotone: the closest point is searched from the
//! current progress forward, within a bounded look-ahead (arc length), so a
//! later leg that passes near the vehicle (the second leg of an L, the legs
//! of an S) is not grabbed early, and the reference never moves backwards.
//!
//! A stop ([`Reference::braking`]) brakes at constant deceleration along
//! the current velocity, for the moment the autopilot hands control to the
//! controller while the vehicle moves.
//!
//! All positions are local NED \[m\]; speeds [m/s]. Nothing here allocates
//! after construction.

use nalgebra::Vector3;

use crate::{ControlError, ReferenceSource};

mod brake;
mod path;
mod route;
mod stream;

use brake::Brake;
use path::{Path, Ramp};
use route::Route;
pub use route::{MIN_BLEND_TIME, RouteSpec, Waypoint};
mod bounds;
pub use bounds::Bounds;
use stream::Stream;
pub use stream::{IMPLIED_MIN_GAP, StreamSample, StreamSettings, TURN_MIN_SPEED};

/// Look-ahead time of the closest-point search \[s\]: the search window is
/// `max(MIN_LOOKAHEAD, LOOKAHEAD_TIME·speed)` of arc length.
pub const LOOKAHEAD_TIME: f64 = 1.0;
/// Smallest default look-ahead of the closest-point search \[m\].
pub const MIN_LOOKAHEAD: f64 = 5.0;

/// A reference for the controllers: a fixed setpoint or a path with a speed.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    kind: Kind,
    /// The flight envelope's box (`None`: unbounded).
    bounds: Option<Bounds>,
    /// The last horizon was clamped into `bounds` somewhere.
    clipped: bool,
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    Setpoint(Vector3<f64>),
    Path(Path),
    Brake(Brake),
    Route(Route),
    /// Boxed: its prediction carries a table of the jerk's motion (8 KiB).
    Stream(Box<Stream>),
}

fn invalid(field: &'static str, reason: impl Into<String>) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.into(),
    }
}

fn is_finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|c| c.is_finite())
}

impl Reference {
    fn of(kind: Kind) -> Self {
        Self {
            kind,
            bounds: None,
            clipped: false,
        }
    }

    /// The same reference with every position it hands out (horizon,
    /// closest point, current point, rest point) clamped into `bounds`:
    /// the flight envelope's fence ([`Bounds`]).
    pub fn with_bounds(mut self, bounds: Bounds) -> Self {
        self.bounds = Some(bounds);
        self
    }

    /// Sets (or with `None` removes) the box every position is clamped into.
    pub fn set_bounds(&mut self, bounds: Option<Bounds>) {
        self.bounds = bounds;
    }

    /// The envelope's box, if one bounds this reference.
    pub fn bounds(&self) -> Option<&Bounds> {
        self.bounds.as_ref()
    }

    /// True when the last horizon was clamped into the bounds somewhere.
    pub fn clipped(&self) -> bool {
        self.clipped
    }

    fn bounded(&self, p: Vector3<f64>) -> Vector3<f64> {
        self.bounds.map_or(p, |b| b.clamp(&p).0)
    }
    /// A fixed setpoint `p` (NED \[m\]); every horizon step is `p`, the
    /// reference velocity zero. Errors when `p` is not finite.
    pub fn setpoint(p: Vector3<f64>) -> Result<Self, ControlError> {
        if !is_finite3(&p) {
            return Err(invalid("setpoint", "all components must be finite"));
        }
        Ok(Self::of(Kind::Setpoint(p)))
    }

    /// A path through `waypoints` (NED \[m\]; at least two, consecutive ones
    /// distinct, all finite) flown at `speed` [m/s] (finite, > 0). The
    /// look-ahead of the closest-point search defaults to
    /// `max(MIN_LOOKAHEAD, LOOKAHEAD_TIME·speed)` \[m\]; see
    /// [`Reference::with_lookahead`].
    pub fn path(waypoints: &[Vector3<f64>], speed: f64) -> Result<Self, ControlError> {
        if waypoints.len() < 2 {
            return Err(invalid(
                "waypoints",
                format!("need at least 2 waypoints, got {}", waypoints.len()),
            ));
        }
        if let Some(i) = waypoints.iter().position(|w| !is_finite3(w)) {
            return Err(invalid("waypoints", format!("waypoint {i} is not finite")));
        }
        if !(speed.is_finite() && speed > 0.0) {
            return Err(invalid(
                "speed",
                format!("must be finite and > 0 m/s, got {speed}"),
            ));
        }
        let mut cum = Vec::with_capacity(waypoints.len());
        let mut dirs = Vec::with_capacity(waypoints.len() - 1);
        cum.push(0.0);
        for (i, w) in waypoints.windows(2).enumerate() {
            let d = w[1] - w[0];
            let len = d.norm();
            // Relative tolerance: a segment shorter than 1e-9 of the
            // waypoints' magnitude has no usable direction (all finite here).
            let scale = w[0].norm().max(w[1].norm()).max(1.0);
            if len <= 1e-9 * scale {
                return Err(invalid(
                    "waypoints",
                    format!(
                        "waypoints {i} and {} coincide (consecutive waypoints must be distinct)",
                        i + 1
                    ),
                ));
            }
            dirs.push(d / len);
            cum.push(cum[i] + len);
        }
        Ok(Self::of(Kind::Path(Path {
            points: waypoints.to_vec(),
            cum,
            dirs,
            speed,
            lookahead: MIN_LOOKAHEAD.max(LOOKAHEAD_TIME * speed),
            progress: 0.0,
            seg: 0,
            ramp: None,
        })))
    }

    /// A stop: from `start` (NED \[m\]) moving at `velocity` (NED [m/s]),
    /// coasting for `lag` \[s\] (the attitude loop's response: a vehicle
    /// cannot decelerate before it tilts) and then braking at `decel`
    /// [m/s²] along the velocity until it stops at
    /// `start + v·lag + v·|v| / (2·decel)`, then holding there. Like a
    /// path, the reference at tick k is the closest point of the stop line
    /// to the measured position (never backwards), and the horizon follows
    /// the profile from there, so a vehicle that brakes late is asked to
    /// brake harder; one that overshoots the stop point moves the stop on
    /// with it instead of being flown back, by at most one more stopping
    /// distance (a drift along the braking direction, such as a thrust
    /// offset not yet learnt, cannot carry the stop away). A (near) zero
    /// velocity is a
    /// setpoint at `start`. Errors on non-finite input, a deceleration
    /// that is not > 0 or a negative lag.
    pub fn braking(
        start: Vector3<f64>,
        velocity: Vector3<f64>,
        decel: f64,
        lag: f64,
    ) -> Result<Self, ControlError> {
        if !is_finite3(&start) || !is_finite3(&velocity) {
            return Err(invalid("braking", "start and velocity must be finite"));
        }
        if !(decel.is_finite() && decel > 0.0) {
            return Err(invalid(
                "braking",
                format!("deceleration must be finite and > 0 m/s², got {decel}"),
            ));
        }
        if !(lag.is_finite() && lag >= 0.0) {
            return Err(invalid(
                "braking",
                format!("lag must be finite and ≥ 0 s, got {lag}"),
            ));
        }
        let speed = velocity.norm();
        if speed < 1e-6 {
            return Self::setpoint(start);
        }
        let length = speed * lag + speed * speed / (2.0 * decel);
        Ok(Self::of(Kind::Brake(Brake {
            start,
            dir: velocity / speed,
            speed,
            decel,
            coast: speed * lag,
            length,
            max_length: 2.0 * length,
            progress: 0.0,
        })))
    }

    /// A smooth start for a path: the reference speed rises from `v0`
    /// [m/s] (the vehicle's speed; clamped to \[0, speed\]) to the path
    /// speed with a peak acceleration `accel` [m/s²] (finite, > 0), with no
    /// step in the reference acceleration — so a path started or resumed
    /// from rest does not ask for the tilt limit in one tick. No effect on
    /// a setpoint or a stop.
    pub fn with_ramp(mut self, v0: f64, accel: f64) -> Result<Self, ControlError> {
        if !(accel.is_finite() && accel > 0.0 && v0.is_finite()) {
            return Err(invalid(
                "ramp",
                format!("need finite v0 and accel > 0, got v0 = {v0}, accel = {accel} m/s²"),
            ));
        }
        if let Kind::Path(p) = &mut self.kind {
            let v0 = v0.clamp(0.0, p.speed);
            let duration = std::f64::consts::PI * (p.speed - v0) / (2.0 * accel);
            p.ramp = (duration > 0.0).then_some(Ramp {
                v0,
                duration,
                elapsed: 0.0,
            });
        }
        Ok(self)
    }

    /// Moves a path's progress to the point of the *whole* path closest to
    /// `q` (NED \[m\]; the earliest on a tie), e.g. to resume a path from
    /// where the vehicle is after a pilot override. No effect on a
    /// setpoint, a stop, or a non-finite `q`.
    pub fn seek(&mut self, q: &Vector3<f64>) {
        if !is_finite3(q) {
            return;
        }
        if let Kind::Path(p) = &mut self.kind {
            let mut best = (0.0, f64::INFINITY);
            for i in 0..p.segments() {
                let (s, d2) = p.project(i, q, p.cum[i], p.cum[i + 1]);
                if d2 < best.1 {
                    best = (s, d2);
                }
            }
            p.progress = best.0;
            p.seg = p.segment_from(0, p.progress);
        }
    }

    /// Sets the look-ahead of the closest-point search \[m\] (arc length
    /// ahead of the current progress; finite, > 0). No effect on a setpoint.
    pub fn with_lookahead(mut self, lookahead: f64) -> Result<Self, ControlError> {
        if !(lookahead.is_finite() && lookahead > 0.0) {
            return Err(invalid(
                "lookahead",
                format!("must be finite and > 0 m, got {lookahead}"),
            ));
        }
        if let Kind::Path(p) = &mut self.kind {
            p.lookahead = lookahead;
        }
        Ok(self)
    }

    /// Progress along the path \[m\] (arc length of the current closest
    /// point); 0 for a setpoint.
    pub fn progress(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.progress,
            Kind::Brake(b) => b.progress,
            Kind::Route(r) => r.progress(),
            Kind::Stream(_) => 0.0,
        }
    }

    /// Total length of the path \[m\]; 0 for a setpoint; the stopping
    /// distance of a stop.
    pub fn path_length(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.length(),
            Kind::Brake(b) => b.length,
            Kind::Route(r) => r.length(),
            Kind::Stream(_) => 0.0,
        }
    }

    /// True once the closest point has reached the path end. A setpoint is
    /// held forever and never finishes, nor does a stop (it holds its end).
    pub fn is_finished(&self) -> bool {
        match &self.kind {
            Kind::Setpoint(_) | Kind::Brake(_) | Kind::Stream(_) => false,
            Kind::Path(p) => p.progress >= p.length() - 1e-9 * p.length().max(1.0),
            Kind::Route(r) => r.elapsed >= r.duration(),
        }
    }

    /// Desired speed along the path [m/s]; 0 for a setpoint; the initial
    /// speed of a stop.
    pub fn speed(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.speed,
            Kind::Brake(b) => b.speed,
            Kind::Route(r) => r.cruise(),
            Kind::Stream(s) => s.closest().1.norm(),
        }
    }

    /// The path error metric of the experiments: Euclidean distance \[m\]
    /// from `point` (NED) to the nearest point of the whole polyline
    /// (or to the setpoint). Pure: ignores and keeps the progress. Planar
    /// experiments should pass the point at the path's altitude.
    pub fn distance_to_path(&self, point: &Vector3<f64>) -> f64 {
        match &self.kind {
            Kind::Setpoint(p) => (point - p).norm(),
            Kind::Route(r) => r.distance(point),
            Kind::Stream(s) => (point - s.closest().0).norm(),
            Kind::Brake(b) => {
                let s = (point - b.start).dot(&b.dir);
                (point - b.point(s)).norm()
            }
            Kind::Path(p) => (0..p.dirs.len())
                .map(|i| {
                    let (_, d2) = p.project(i, point, p.cum[i], p.cum[i + 1]);
                    d2
                })
                .fold(f64::INFINITY, f64::min)
                .sqrt(),
        }
    }

    /// A route (see the module docs, "Routes", and [`RouteSpec`]): the
    /// polyline from `spec.start` through the waypoints on a smooth,
    /// time-parametrised speed profile (start ramp from the vehicle's
    /// velocity, per-leg speeds, stops at holds and at the end, then a
    /// hold). Errors name the offending field.
    pub fn route(spec: &RouteSpec) -> Result<Self, ControlError> {
        Ok(Self::of(Kind::Route(Route::new(spec)?)))
    }

    /// A setpoint flown as a route: a straight line from `from` (NED \[m\],
    /// the vehicle) moving at `velocity` (NED [m/s]) to `target`, cruising
    /// at `speed` [m/s] with ramps of peak `acceleration` [m/s²], stopping
    /// at the target and holding it. A target at `from` holds it (the
    /// vehicle's velocity blended out).
    pub fn setpoint_route(
        from: Vector3<f64>,
        velocity: Vector3<f64>,
        target: Vector3<f64>,
        speed: f64,
        acceleration: f64,
    ) -> Result<Self, ControlError> {
        Self::route(&RouteSpec {
            start: from,
            start_velocity: velocity,
            waypoints: vec![Waypoint::at(target)],
            cruise_speed: speed,
            acceleration,
        })
    }

    /// A streamed trajectory from its first `sample` (see the
    /// module docs, "Streams"). Errors on non-finite sample fields or
    /// settings out of range.
    pub fn stream(settings: StreamSettings, sample: &StreamSample) -> Result<Self, ControlError> {
        Ok(Self::of(Kind::Stream(Box::new(Stream::new(
            settings, sample,
        )?))))
    }

    /// A new sample for a stream: it replaces the stream's samples at or
    /// after its time, and the prediction restarts from the newest. Errors
    /// (and changes nothing) on a non-finite sample, one that would rewrite
    /// the past (older than the newest and than the reference's time), one
    /// further ahead than `max_ahead_s`, or a reference that is not a
    /// stream.
    pub fn push_sample(&mut self, sample: &StreamSample) -> Result<(), ControlError> {
        match &mut self.kind {
            Kind::Stream(s) => s.push(sample),
            _ => Err(invalid("stream sample", "the reference is not a stream")),
        }
    }

    /// A stream's predicted position at controller time `t` \[s\] (NED
    /// \[m\]; `None` for other references). Pure: moves no clock.
    pub fn stream_position_at(&self, t: f64) -> Option<Vector3<f64>> {
        match &self.kind {
            Kind::Stream(s) => Some(s.state(t).0),
            _ => None,
        }
    }

    /// True for a streamed trajectory.
    pub fn is_stream(&self) -> bool {
        matches!(self.kind, Kind::Stream(_))
    }

    /// A stream's newest sample (`None` for other references).
    pub fn last_sample(&self) -> Option<&StreamSample> {
        match &self.kind {
            Kind::Stream(s) => Some(s.last()),
            _ => None,
        }
    }

    /// A stream's time since its newest sample \[s\] at the reference's
    /// current time (`None` for other references).
    pub fn sample_age(&self) -> Option<f64> {
        match &self.kind {
            Kind::Stream(s) => Some(s.age()),
            _ => None,
        }
    }

    /// Where the reference comes to rest, NED \[m\]: a stream's stop
    /// point after its decay, a route's end, a stop's stop point, a
    /// setpoint; a path's end.
    pub fn rest_point(&self) -> Vector3<f64> {
        self.bounded(self.rest_point_unbounded())
    }

    fn rest_point_unbounded(&self) -> Vector3<f64> {
        match &self.kind {
            Kind::Setpoint(p) => *p,
            Kind::Stream(s) => s.stop_point(),
            Kind::Route(r) => r.state(r.duration() + 1.0, &mut (0, 0)).0,
            Kind::Brake(b) => b.point(b.length),
            Kind::Path(p) => p.point_on(p.segments() - 1, p.length()),
        }
    }

    /// The reference's position and velocity now (NED \[m\], [m/s]) without
    /// moving any progress: a route's or a stream's at its clock; a
    /// path's or a stop's at its current progress.
    pub fn current(&self) -> (Vector3<f64>, Vector3<f64>) {
        let (p, v) = self.current_unbounded();
        (self.bounded(p), v)
    }

    fn current_unbounded(&self) -> (Vector3<f64>, Vector3<f64>) {
        match &self.kind {
            Kind::Setpoint(p) => (*p, Vector3::zeros()),
            Kind::Stream(s) => s.closest(),
            Kind::Route(r) => r.state(r.elapsed, &mut (0, 0)),
            Kind::Brake(b) => (b.point(b.progress), b.dir * b.speed_at(b.progress)),
            Kind::Path(p) => p.closest(),
        }
    }

    /// Sets the reference's clock to the controller's time `t` \[s\] (the
    /// time of the measurement the next update uses). Routes and streams
    /// are trajectories in time: a route starts at its first `set_time`; a
    /// stream predicts from its newest sample to `t`. Without calls they
    /// advance one control step per horizon. No effect on setpoints, paths
    /// and stops, nor for a non-finite `t`.
    pub fn set_time(&mut self, t: f64) {
        match &mut self.kind {
            Kind::Route(r) => r.set_time(t),
            Kind::Stream(s) => s.set_time(t),
            _ => {}
        }
    }

    /// Index (into the spec's waypoints) of the last waypoint the route's
    /// profile has reached (for MISSION_ITEM_REACHED; an acceptance radius
    /// is the caller's to check). `None` before the first, and for other
    /// references.
    pub fn last_reached(&self) -> Option<usize> {
        match &self.kind {
            Kind::Route(r) => r.last_reached(),
            _ => None,
        }
    }

    /// The heading to fly \[rad\], NED: a route's waypoint being flown to
    /// (the last one once reached), a stream's newest sample; `None` when
    /// it has none, and for other references.
    pub fn yaw_target(&self) -> Option<f64> {
        match &self.kind {
            Kind::Route(r) => r.yaw_target(),
            Kind::Stream(s) => s.yaw(0.0).map(|(yaw, _)| yaw),
            _ => None,
        }
    }

    /// A stream's heading \[rad\] (NED) and its rate [rad/s] `ahead` \[s\]
    /// after the reference's current time: interpolated between samples
    /// that give a heading (the trajectory sent ahead), else the newest
    /// sample's carried on at its rate (0 when not given) for at most
    /// `extrapolation_s`. `None` for other references and streams without
    /// a heading.
    pub fn yaw_reference(&self, ahead: f64) -> Option<(f64, f64)> {
        match &self.kind {
            Kind::Stream(s) => s.yaw(ahead),
            _ => None,
        }
    }

    /// Restarts the progress at the path start (a setpoint is unchanged).
    pub fn reset(&mut self) {
        match &mut self.kind {
            Kind::Path(p) => {
                p.progress = 0.0;
                p.seg = 0;
                if let Some(r) = &mut p.ramp {
                    r.elapsed = 0.0;
                }
            }
            Kind::Brake(b) => b.progress = 0.0,
            Kind::Route(r) => r.reset(),
            Kind::Setpoint(_) | Kind::Stream(_) => {}
        }
    }
}

impl ReferenceSource for Reference {
    /// A stream (position, velocity and acceleration extrapolated as a
    /// coordinated turn) is flyable as it is; paths (corners), routes
    /// (corners between legs), setpoints and stops are not.
    fn flyable(&self) -> bool {
        self.is_stream() && !self.clipped
    }

    /// `out[0]` is the closest point (advancing the progress); `out[j]` lies
    /// `j·δt·speed` further along the path, held at the end. A non-positive
    /// or non-finite `dt` \[s\] holds the closest point over the horizon.
    fn horizon(&mut self, measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        self.horizon_unbounded(measured, dt, out);
        self.clipped = false;
        if let Some(b) = self.bounds {
            for o in out.iter_mut() {
                let (q, moved) = b.clamp(o);
                *o = q;
                self.clipped |= moved;
            }
        }
    }

    /// A path's corner speed at its progress (`Path::corner_speed`);
    /// no limit for every other kind (their profiles are their own).
    fn corner_speed(&self, radius: f64, acceleration: f64) -> Option<(f64, f64)> {
        self.corner_speed_of(radius, acceleration)
    }

    /// The closest point (advancing the progress, clamped into the
    /// bounds) and the reference velocity there, speed × direction of the
    /// segment toward the next waypoint [m/s]; zero at the path end and
    /// for a setpoint.
    fn closest(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        let (p, v) = self.closest_unbounded(measured);
        (self.bounded(p), v)
    }
}

impl Reference {
    fn horizon_unbounded(&mut self, measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        match &mut self.kind {
            Kind::Setpoint(p) => out.fill(*p),
            Kind::Route(r) => r.horizon(dt, out),
            Kind::Stream(s) => s.horizon(dt, out),
            Kind::Brake(b) => {
                b.update(measured);
                let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
                for (j, o) in out.iter_mut().enumerate() {
                    *o = b.point(b.advance(b.progress, j as f64 * dt));
                }
            }
            Kind::Path(path) => {
                path.update(measured);
                let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
                let (speed, ramp) = (path.speed, path.ramp);
                // Distance j steps ahead: constant speed, or the ramp's.
                let ahead = |j: usize| match ramp {
                    Some(r) => {
                        r.distance(speed, r.elapsed + j as f64 * dt) - r.distance(speed, r.elapsed)
                    }
                    None => j as f64 * dt * speed,
                };
                let mut seg = path.seg;
                for (j, o) in out.iter_mut().enumerate() {
                    let s = (path.progress + ahead(j)).min(path.length());
                    seg = path.segment_from(seg, s);
                    *o = path.point_on(seg, s);
                }
                // One control step per call.
                if let Some(r) = &mut path.ramp {
                    r.elapsed += dt;
                }
            }
        }
    }

    fn corner_speed_of(&self, radius: f64, acceleration: f64) -> Option<(f64, f64)> {
        match &self.kind {
            Kind::Path(p) if radius.is_finite() && radius >= 0.0 && acceleration > 0.0 => {
                Some(p.corner_speed(radius, acceleration))
            }
            _ => None,
        }
    }

    fn closest_unbounded(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        match &mut self.kind {
            Kind::Setpoint(p) => (*p, Vector3::zeros()),
            Kind::Route(r) => r.state(r.elapsed, &mut (0, 0)),
            Kind::Stream(s) => s.closest(),
            Kind::Path(path) => {
                path.update(measured);
                path.closest()
            }
            Kind::Brake(b) => {
                b.update(measured);
                (b.point(b.progress), b.dir * b.speed_at(b.progress))
            }
        }
    }
}

pub mod paths;
