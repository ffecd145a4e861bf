//! Reference generation (paper §VII-C): a fixed setpoint, or a path of
//! straight segments between waypoints flown at a desired speed; and (ours)
//! a stop: braking at constant deceleration along the current velocity,
//! for the moment the autopilot hands control to the controller while the
//! vehicle moves ([`Reference::braking`]).
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
//! All positions are local NED \[m\]; speeds [m/s]. Nothing here allocates
//! after construction.

use nalgebra::Vector3;

use crate::{ControlError, ReferenceSource};

mod brake;
mod path;

use brake::Brake;
use path::{Path, Ramp};

/// Look-ahead time of the closest-point search \[s\]: the search window is
/// `max(MIN_LOOKAHEAD, LOOKAHEAD_TIME·speed)` of arc length.
pub const LOOKAHEAD_TIME: f64 = 1.0;
/// Smallest default look-ahead of the closest-point search \[m\].
pub const MIN_LOOKAHEAD: f64 = 5.0;

/// A reference for the controllers: a fixed setpoint or a path with a speed.
#[derive(Debug, Clone, PartialEq)]
pub struct Reference {
    kind: Kind,
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    Setpoint(Vector3<f64>),
    Path(Path),
    Brake(Brake),
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
    /// A fixed setpoint `p` (NED \[m\]); every horizon step is `p`, the
    /// reference velocity zero. Errors when `p` is not finite.
    pub fn setpoint(p: Vector3<f64>) -> Result<Self, ControlError> {
        if !is_finite3(&p) {
            return Err(invalid("setpoint", "all components must be finite"));
        }
        Ok(Self {
            kind: Kind::Setpoint(p),
        })
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
        Ok(Self {
            kind: Kind::Path(Path {
                points: waypoints.to_vec(),
                cum,
                dirs,
                speed,
                lookahead: MIN_LOOKAHEAD.max(LOOKAHEAD_TIME * speed),
                progress: 0.0,
                seg: 0,
                ramp: None,
            }),
        })
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
    /// with it instead of being flown back. A (near) zero velocity is a
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
        Ok(Self {
            kind: Kind::Brake(Brake {
                start,
                dir: velocity / speed,
                speed,
                decel,
                coast: speed * lag,
                length: speed * lag + speed * speed / (2.0 * decel),
                progress: 0.0,
            }),
        })
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
        }
    }

    /// Total length of the path \[m\]; 0 for a setpoint; the stopping
    /// distance of a stop.
    pub fn path_length(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.length(),
            Kind::Brake(b) => b.length,
        }
    }

    /// True once the closest point has reached the path end. A setpoint is
    /// held forever and never finishes, nor does a stop (it holds its end).
    pub fn is_finished(&self) -> bool {
        match &self.kind {
            Kind::Setpoint(_) | Kind::Brake(_) => false,
            Kind::Path(p) => p.progress >= p.length() - 1e-9 * p.length().max(1.0),
        }
    }

    /// Desired speed along the path [m/s]; 0 for a setpoint; the initial
    /// speed of a stop.
    pub fn speed(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.speed,
            Kind::Brake(b) => b.speed,
        }
    }

    /// The path error metric of the experiments: Euclidean distance \[m\]
    /// from `point` (NED) to the nearest point of the whole polyline
    /// (or to the setpoint). Pure: ignores and keeps the progress. Planar
    /// experiments should pass the point at the path's altitude.
    pub fn distance_to_path(&self, point: &Vector3<f64>) -> f64 {
        match &self.kind {
            Kind::Setpoint(p) => (point - p).norm(),
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
            Kind::Setpoint(_) => {}
        }
    }
}

impl ReferenceSource for Reference {
    /// `out[0]` is the closest point (advancing the progress); `out[j]` lies
    /// `j·δt·speed` further along the path, held at the end. A non-positive
    /// or non-finite `dt` \[s\] holds the closest point over the horizon.
    fn horizon(&mut self, measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]) {
        match &mut self.kind {
            Kind::Setpoint(p) => out.fill(*p),
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

    /// The closest point (advancing the progress) and the reference velocity
    /// there, speed × direction of the segment toward the next waypoint
    /// [m/s]; zero at the path end and for a setpoint.
    fn closest(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
        match &mut self.kind {
            Kind::Setpoint(p) => (*p, Vector3::zeros()),
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
