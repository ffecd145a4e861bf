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

/// A straight stop at constant deceleration, with its monotone progress.
#[derive(Debug, Clone, PartialEq)]
struct Brake {
    /// Where the braking starts, NED \[m\].
    start: Vector3<f64>,
    /// Unit direction of the motion.
    dir: Vector3<f64>,
    /// Speed at the start [m/s] (> 0).
    speed: f64,
    /// Deceleration [m/s²] (> 0).
    decel: f64,
    /// Distance coasted at the initial speed before the deceleration
    /// starts (`speed · lag`: the attitude loop's response) \[m\].
    coast: f64,
    /// Stopping distance `coast + speed² / (2·decel)` \[m\]; moves on with
    /// a vehicle that overshoots it (never back).
    length: f64,
    /// Distance of the current closest point from the start \[m\].
    progress: f64,
}

impl Brake {
    fn point(&self, s: f64) -> Vector3<f64> {
        self.start + self.dir * s.clamp(0.0, self.length)
    }

    /// Speed on the braking profile at distance `s` [m/s].
    fn speed_at(&self, s: f64) -> f64 {
        if s < self.coast {
            return self.speed;
        }
        (self.speed * self.speed - 2.0 * self.decel * (s - self.coast))
            .max(0.0)
            .sqrt()
    }

    /// Distance along the profile `tau` \[s\] after passing `s`.
    fn advance(&self, s: f64, tau: f64) -> f64 {
        let coast_left = if self.speed > 0.0 {
            ((self.coast - s) / self.speed).max(0.0)
        } else {
            0.0
        };
        if tau <= coast_left {
            return s + self.speed * tau;
        }
        let s0 = s.max(self.coast);
        let v = self.speed_at(s0);
        let t = (tau - coast_left).min(v / self.decel);
        (s0 + v * t - 0.5 * self.decel * t * t).min(self.length)
    }

    fn update(&mut self, q: &Vector3<f64>) {
        if is_finite3(q) {
            let s = (q - self.start).dot(&self.dir);
            // Past the stop point: the stop moves on with the vehicle.
            self.length = self.length.max(s);
            self.progress = s.clamp(self.progress, self.length);
        }
    }
}

/// A polyline flown at constant speed, with its monotone progress.
#[derive(Debug, Clone, PartialEq)]
struct Path {
    /// Waypoints, NED \[m\]; at least two, consecutive ones distinct.
    points: Vec<Vector3<f64>>,
    /// Arc length at each waypoint \[m\]; `cum[0] = 0`.
    cum: Vec<f64>,
    /// Unit direction of each segment (one fewer than `points`).
    dirs: Vec<Vector3<f64>>,
    /// Desired speed along the path [m/s].
    speed: f64,
    /// Arc length searched ahead of the progress for the closest point \[m\].
    lookahead: f64,
    /// Arc length of the current closest point \[m\].
    progress: f64,
    /// Segment holding `progress` (a corner belongs to the next segment).
    seg: usize,
    /// The speed ramp at the start, if any ([`Reference::with_ramp`]).
    ramp: Option<Ramp>,
}

/// A smooth start: the reference speed rises from `v0` to the path speed
/// as `v(τ) = v0 + (V − v0)·(1 − cos(πτ/T))/2` over `T` (zero acceleration
/// at both ends, peak acceleration `π(V − v0)/(2T)`).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ramp {
    /// Speed at the start [m/s].
    v0: f64,
    /// Duration \[s\].
    duration: f64,
    /// Time since the start \[s\] (one control step per horizon call).
    elapsed: f64,
}

impl Ramp {
    /// Speed at time `tau` \[s\] since the start, for path speed `speed`.
    fn speed(&self, speed: f64, tau: f64) -> f64 {
        if tau >= self.duration {
            return speed;
        }
        let x = std::f64::consts::PI * tau.max(0.0) / self.duration;
        self.v0 + (speed - self.v0) * 0.5 * (1.0 - x.cos())
    }

    /// Distance covered from time 0 to `tau` \[s\].
    fn distance(&self, speed: f64, tau: f64) -> f64 {
        let t = tau.clamp(0.0, self.duration);
        let k = std::f64::consts::PI / self.duration;
        let ramp = self.v0 * t + (speed - self.v0) * 0.5 * (t - (k * t).sin() / k);
        ramp + speed * (tau - self.duration).max(0.0)
    }
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

impl Path {
    fn length(&self) -> f64 {
        self.cum[self.cum.len() - 1]
    }

    fn segments(&self) -> usize {
        self.dirs.len()
    }

    /// Closest point of segment `i` to `q`, restricted to arc lengths
    /// `[lo, hi]` within the segment: its arc length and squared distance.
    fn project(&self, i: usize, q: &Vector3<f64>, lo: f64, hi: f64) -> (f64, f64) {
        let along = (q - self.points[i]).dot(&self.dirs[i]);
        let s = (self.cum[i] + along).clamp(lo, hi);
        let p = self.points[i] + self.dirs[i] * (s - self.cum[i]);
        (s, (q - p).norm_squared())
    }

    /// Segment holding arc length `s`, searching forward from `hint`. A
    /// corner belongs to the segment that leaves it (direction of the next
    /// waypoint); the path end to the last segment.
    fn segment_from(&self, mut hint: usize, s: f64) -> usize {
        let last = self.segments() - 1;
        hint = hint.min(last);
        while hint < last && s >= self.cum[hint + 1] {
            hint += 1;
        }
        hint
    }

    /// Point at arc length `s` (clamped to the path) on segment `seg`.
    fn point_on(&self, seg: usize, s: f64) -> Vector3<f64> {
        let s = s.clamp(0.0, self.length());
        self.points[seg] + self.dirs[seg] * (s - self.cum[seg])
    }

    /// Moves the progress to the closest point to `q` within
    /// `[progress, progress + lookahead]` (never backwards).
    fn update(&mut self, q: &Vector3<f64>) {
        if !is_finite3(q) {
            return;
        }
        let lo = self.progress;
        let hi = (self.progress + self.lookahead).min(self.length());
        let mut best_s = lo;
        let mut best_d2 = f64::INFINITY;
        let mut i = self.seg;
        while i < self.segments() && self.cum[i] <= hi {
            let a = self.cum[i].max(lo);
            let b = self.cum[i + 1].min(hi);
            if a <= b {
                let (s, d2) = self.project(i, q, a, b);
                if d2 < best_d2 {
                    best_d2 = d2;
                    best_s = s;
                }
            }
            i += 1;
        }
        self.progress = best_s.max(lo);
        self.seg = self.segment_from(self.seg, self.progress);
    }

    fn closest(&self) -> (Vector3<f64>, Vector3<f64>) {
        let p = self.point_on(self.seg, self.progress);
        let speed = match self.ramp {
            Some(r) => r.speed(self.speed, r.elapsed),
            None => self.speed,
        };
        let v = if self.progress >= self.length() {
            Vector3::zeros()
        } else {
            self.dirs[self.seg] * speed
        };
        (p, v)
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

/// The paths flown in the paper, as NED waypoints at a caller-given
/// altitude z (NED, so z = −10 is 10 m above the origin).
///
/// Waypoints are `(x, y)` = (north, east) \[m\]. The paper gives the
/// coordinates of the L path only; the DSL letters are our reconstruction
/// of Fig. 8 (sizes 20–30 m, placed side by side along east so that they
/// read "DSL").
pub mod paths {
    use nalgebra::Vector3;

    use super::Reference;
    use crate::ControlError;

    /// The L-shaped teach path of the controller comparison (§VII-C,
    /// Figs. 6–7): (x, y) = (−20, −30) → (0, −30) → (0, 0) \[m\].
    pub const L_XY: [[f64; 2]; 3] = [[-20.0, -30.0], [0.0, -30.0], [0.0, 0.0]];
    /// Speeds of the controller comparison on the L path [m/s].
    pub const L_SPEEDS: [f64; 4] = [3.0, 5.0, 7.0, 9.0];

    /// "D" of the DSL demonstration: a 30 m stem north, then a bowl of
    /// radius 15 m bulging east (polyline, 30° steps), closed back at the
    /// start.
    pub const D_XY: [[f64; 2]; 10] = [
        [0.0, 0.0],
        [30.0, 0.0],
        [30.0, 5.0],
        [27.990_381_056_766_58, 12.5],
        [22.5, 17.990_381_056_766_58],
        [15.0, 20.0],
        [7.5, 17.990_381_056_766_58],
        [2.009_618_943_233_42, 12.5],
        [0.0, 5.0],
        [0.0, 0.0],
    ];
    /// Speed of the "D" flight [m/s].
    pub const D_SPEED: f64 = 10.0;

    /// "S" of the DSL demonstration: 20 m wide, 30 m tall, drawn from the
    /// top right to the bottom left in three east–west legs.
    pub const S_XY: [[f64; 2]; 6] = [
        [30.0, 50.0],
        [30.0, 30.0],
        [15.0, 30.0],
        [15.0, 50.0],
        [0.0, 50.0],
        [0.0, 30.0],
    ];
    /// Speed of the "S" flight [m/s].
    pub const S_SPEED: f64 = 3.0;

    /// "L" of the DSL demonstration: 30 m south along the stem, then 20 m
    /// east.
    pub const DSL_L_XY: [[f64; 2]; 3] = [[30.0, 60.0], [0.0, 60.0], [0.0, 80.0]];
    /// Speed of the DSL "L" flight [m/s].
    pub const DSL_L_SPEED: f64 = 8.0;

    /// NED waypoints `(x, y, z)` \[m\] from `(x, y)` pairs at altitude `z`.
    pub fn waypoints(xy: &[[f64; 2]], z: f64) -> Vec<Vector3<f64>> {
        xy.iter().map(|p| Vector3::new(p[0], p[1], z)).collect()
    }

    /// The comparison's L path at altitude `z` (NED \[m\]) flown at `speed` [m/s].
    pub fn l(z: f64, speed: f64) -> Result<Reference, ControlError> {
        Reference::path(&waypoints(&L_XY, z), speed)
    }

    /// The DSL "D" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
    /// (the paper: [`D_SPEED`]).
    pub fn d(z: f64, speed: f64) -> Result<Reference, ControlError> {
        Reference::path(&waypoints(&D_XY, z), speed)
    }

    /// The DSL "S" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
    /// (the paper: [`S_SPEED`]).
    pub fn s(z: f64, speed: f64) -> Result<Reference, ControlError> {
        Reference::path(&waypoints(&S_XY, z), speed)
    }

    /// The DSL "L" at altitude `z` (NED \[m\]) flown at `speed` [m/s]
    /// (the paper: [`DSL_L_SPEED`]).
    pub fn dsl_l(z: f64, speed: f64) -> Result<Reference, ControlError> {
        Reference::path(&waypoints(&DSL_L_XY, z), speed)
    }
}
