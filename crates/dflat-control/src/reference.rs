//! Reference generation (paper §VII-C): a fixed setpoint, or a path of
//! straight segments between waypoints flown at a desired speed.
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
            }),
        })
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
        }
    }

    /// Total length of the path \[m\]; 0 for a setpoint.
    pub fn path_length(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.length(),
        }
    }

    /// True once the closest point has reached the path end. A setpoint is
    /// held forever and never finishes.
    pub fn is_finished(&self) -> bool {
        match &self.kind {
            Kind::Setpoint(_) => false,
            Kind::Path(p) => p.progress >= p.length() - 1e-9 * p.length().max(1.0),
        }
    }

    /// Desired speed along the path [m/s]; 0 for a setpoint.
    pub fn speed(&self) -> f64 {
        match &self.kind {
            Kind::Setpoint(_) => 0.0,
            Kind::Path(p) => p.speed,
        }
    }

    /// The path error metric of the experiments: Euclidean distance \[m\]
    /// from `point` (NED) to the nearest point of the whole polyline
    /// (or to the setpoint). Pure: ignores and keeps the progress. Planar
    /// experiments should pass the point at the path's altitude.
    pub fn distance_to_path(&self, point: &Vector3<f64>) -> f64 {
        match &self.kind {
            Kind::Setpoint(p) => (point - p).norm(),
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
        if let Kind::Path(p) = &mut self.kind {
            p.progress = 0.0;
            p.seg = 0;
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
        let v = if self.progress >= self.length() {
            Vector3::zeros()
        } else {
            self.dirs[self.seg] * self.speed
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
            Kind::Path(path) => {
                path.update(measured);
                let step = if dt.is_finite() && dt > 0.0 {
                    dt * path.speed
                } else {
                    0.0
                };
                let mut seg = path.seg;
                for (j, o) in out.iter_mut().enumerate() {
                    let s = (path.progress + j as f64 * step).min(path.length());
                    seg = path.segment_from(seg, s);
                    *o = path.point_on(seg, s);
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
