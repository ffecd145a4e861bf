//! A polyline flown at a speed, with its monotone progress, and the smooth start ramp.

use nalgebra::Vector3;

use super::is_finite3;

/// A polyline flown at constant speed, with its monotone progress.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Path {
    /// Waypoints, NED \[m\]; at least two, consecutive ones distinct.
    pub(super) points: Vec<Vector3<f64>>,
    /// Arc length at each waypoint \[m\]; `cum[0] = 0`.
    pub(super) cum: Vec<f64>,
    /// Unit direction of each segment (one fewer than `points`).
    pub(super) dirs: Vec<Vector3<f64>>,
    /// Desired speed along the path [m/s].
    pub(super) speed: f64,
    /// Arc length searched ahead of the progress for the closest point \[m\].
    pub(super) lookahead: f64,
    /// Arc length of the current closest point \[m\].
    pub(super) progress: f64,
    /// Segment holding `progress` (a corner belongs to the next segment).
    pub(super) seg: usize,
    /// The speed ramp at the start, if any ([`Reference::with_ramp`]).
    pub(super) ramp: Option<Ramp>,
}

/// A smooth start: the reference speed rises from `v0` to the path speed
/// as `v(τ) = v0 + (V − v0)·(1 − cos(πτ/T))/2` over `T` (zero acceleration
/// at both ends, peak acceleration `π(V − v0)/(2T)`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Ramp {
    /// Speed at the start [m/s].
    pub(super) v0: f64,
    /// Duration \[s\].
    pub(super) duration: f64,
    /// Time since the start \[s\] (one control step per horizon call).
    pub(super) elapsed: f64,
}

impl Ramp {
    /// Speed at time `tau` \[s\] since the start, for path speed `speed`.
    pub(super) fn speed(&self, speed: f64, tau: f64) -> f64 {
        if tau >= self.duration {
            return speed;
        }
        let x = std::f64::consts::PI * tau.max(0.0) / self.duration;
        self.v0 + (speed - self.v0) * 0.5 * (1.0 - x.cos())
    }

    /// Distance covered from time 0 to `tau` \[s\].
    pub(super) fn distance(&self, speed: f64, tau: f64) -> f64 {
        let t = tau.clamp(0.0, self.duration);
        let k = std::f64::consts::PI / self.duration;
        let ramp = self.v0 * t + (speed - self.v0) * 0.5 * (t - (k * t).sin() / k);
        ramp + speed * (tau - self.duration).max(0.0)
    }
}

impl Path {
    pub(super) fn length(&self) -> f64 {
        self.cum[self.cum.len() - 1]
    }

    pub(super) fn segments(&self) -> usize {
        self.dirs.len()
    }

    /// Closest point of segment `i` to `q`, restricted to arc lengths
    /// `[lo, hi]` within the segment: its arc length and squared distance.
    pub(super) fn project(&self, i: usize, q: &Vector3<f64>, lo: f64, hi: f64) -> (f64, f64) {
        let along = (q - self.points[i]).dot(&self.dirs[i]);
        let s = (self.cum[i] + along).clamp(lo, hi);
        let p = self.points[i] + self.dirs[i] * (s - self.cum[i]);
        (s, (q - p).norm_squared())
    }

    /// Segment holding arc length `s`, searching forward from `hint`. A
    /// corner belongs to the segment that leaves it (direction of the next
    /// waypoint); the path end to the last segment.
    pub(super) fn segment_from(&self, mut hint: usize, s: f64) -> usize {
        let last = self.segments() - 1;
        hint = hint.min(last);
        while hint < last && s >= self.cum[hint + 1] {
            hint += 1;
        }
        hint
    }

    /// Point at arc length `s` (clamped to the path) on segment `seg`.
    pub(super) fn point_on(&self, seg: usize, s: f64) -> Vector3<f64> {
        let s = s.clamp(0.0, self.length());
        self.points[seg] + self.dirs[seg] * (s - self.cum[seg])
    }

    /// Moves the progress to the closest point to `q` within
    /// `[progress, progress + lookahead]` (never backwards).
    pub(super) fn update(&mut self, q: &Vector3<f64>) {
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

    /// The highest speed [m/s] at the current progress from which a vehicle
    /// accelerating at most `acceleration` [m/s²] along the path reaches
    /// every corner at its corner speed and the end at rest (backward), and
    /// has reached it no faster than that from the corner behind
    /// (forward): `v ≤ √(v_c² + 2·a·d)` for each waypoint at arc distance
    /// `d`; with that profile's rate of change `dv/dt` there (−a braking
    /// toward a waypoint ahead, +a speeding up from one behind) [m/s²]. A
    /// corner deflecting the path by β is rounded by an arc of radius
    /// `R = r·cot(β/2)` with its tangent points `r = radius` \[m\] from the
    /// waypoint — PX4's mission corner (acceptance radius `r`) — flown at
    /// lateral acceleration `a`: `v_c = √(a·R)`. The start has no limit
    /// (its ramp is the start's).
    pub(super) fn corner_speed(&self, radius: f64, acceleration: f64) -> (f64, f64) {
        let n = self.points.len();
        let a = acceleration;
        let mut limit = (f64::INFINITY, 0.0);
        for i in 1..n {
            // v_c² = a·r·cot(β/2); the end is a stop.
            let corner_sq = if i == n - 1 {
                0.0
            } else {
                let cos_beta = self.dirs[i - 1].dot(&self.dirs[i]).clamp(-1.0, 1.0);
                // cot(β/2) = sin β / (1 − cos β); straight on: no limit.
                if 1.0 - cos_beta < 1e-12 {
                    continue;
                }
                let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt();
                a * radius * sin_beta / (1.0 - cos_beta)
            };
            let d = self.cum[i] - self.progress;
            let v = (corner_sq + 2.0 * a * d.abs()).sqrt();
            if v < limit.0 {
                limit = (v, if d > 0.0 { -a } else { a });
            }
        }
        limit
    }

    pub(super) fn closest(&self) -> (Vector3<f64>, Vector3<f64>) {
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
