//! Routes: a polyline flown on a time-parametrised speed profile.
//!
//! How to build a route: see the `reference` module docs ("Routes").
//!
//! # The profile
//!
//! The polyline is `start → waypoints[0] → …`; leg `i` ends at waypoint
//! `i` and is flown at that waypoint's `speed` (or `cruise_speed`). The
//! route stops (speed 0) at every waypoint with `hold_s > 0`, waits there
//! `hold_s`, and stops at the last waypoint, then holds it forever. Every
//! speed change — start, between legs of different speeds, stops — is a
//! cosine ramp `v(τ) = v_a + (v_b − v_a)(1 − cos(πτ/T))/2` with
//! `T = π|v_b − v_a|/(2·acceleration)`: no step in the reference velocity
//! or acceleration, peak acceleration `acceleration`. A leg too short for
//! its ramps at its speed is flown at the highest speed that fits
//! (forward and backward passes over the boundary speeds, as a
//! velocity planner does). Speeds rise after a corner and fall before it.
//!
//! Where the route starts with the vehicle moving (a setpoint mid-path),
//! the along-track part of `start_velocity` (≥ 0) is the start ramp's
//! initial speed — braked harder than `acceleration` only if the first
//! leg is too short to stop otherwise — and the rest `w` (across the
//! line, or backwards) is a blend added to the line:
//! `e(τ) = w·τ·exp(−τ/T_b)`, `T_b = max(2|w|/acceleration, 0.5 s)`, so the
//! reference starts at the vehicle with the vehicle's velocity
//! (`e(0) = 0`, `ė(0) = w`) and merges onto the line (its peak
//! acceleration `2|w|/T_b ≤ acceleration`, the overshoot across the line
//! `|w|·T_b/e`).
//!
//! Unlike [`Reference::path`] (the paper's closest-point progress), a
//! route is a trajectory in time: the reference at tick k is where the
//! profile is at that time, so the MPC sees every ramp, stop and hold
//! over its whole horizon.

use nalgebra::Vector3;

use super::{invalid, is_finite3};
use crate::ControlError;

/// Shortest blend time constant \[s\].
pub const MIN_BLEND_TIME: f64 = 0.5;

/// One waypoint of a route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// Position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Speed of the leg flown *to* this waypoint [m/s] (finite, > 0);
    /// `None`: the route's cruise speed.
    pub speed: Option<f64>,
    /// Stop here and wait this long \[s\] (finite, ≥ 0; 0: fly through).
    /// The last waypoint is always a stop (held forever).
    pub hold_s: f64,
    /// Heading to fly at this waypoint \[rad\], NED (0 north, π/2 east);
    /// carried for the yaw controller, not used by the profile.
    pub yaw: Option<f64>,
}

impl Waypoint {
    /// A waypoint at `position` (NED \[m\]) at cruise speed, no hold, no yaw.
    pub fn at(position: Vector3<f64>) -> Self {
        Self {
            position,
            speed: None,
            hold_s: 0.0,
            yaw: None,
        }
    }
}

/// What a route is built from (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct RouteSpec {
    /// Where the route starts (the vehicle's position), NED \[m\].
    pub start: Vector3<f64>,
    /// The vehicle's velocity at the start, NED [m/s].
    pub start_velocity: Vector3<f64>,
    /// The waypoints, in order (at least one).
    pub waypoints: Vec<Waypoint>,
    /// Speed of legs whose waypoint has none [m/s] (finite, > 0).
    pub cruise_speed: f64,
    /// Peak acceleration of the speed ramps [m/s²] (finite, > 0).
    pub acceleration: f64,
}

/// One piece of the speed profile: a cosine ramp from `va` to `vb` (a
/// cruise when equal, a hold when both are 0).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Piece {
    /// Start time on the route's clock \[s\].
    t0: f64,
    /// Duration \[s\] (> 0).
    dur: f64,
    /// Arc length at the start \[m\].
    s0: f64,
    va: f64,
    vb: f64,
}

impl Piece {
    /// Arc length, speed and acceleration `x` \[s\] into the piece.
    fn eval(&self, x: f64) -> (f64, f64, f64) {
        let x = x.clamp(0.0, self.dur);
        let k = std::f64::consts::PI / self.dur;
        let dv = self.vb - self.va;
        let s = self.s0 + self.va * x + 0.5 * dv * (x - (k * x).sin() / k);
        let v = self.va + 0.5 * dv * (1.0 - (k * x).cos());
        let a = 0.5 * dv * k * (k * x).sin();
        (s, v, a)
    }
}

/// A route: polyline, profile, blend and clock.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Route {
    /// Vertices: the start, then the waypoints (zero-length legs merged).
    points: Vec<Vector3<f64>>,
    /// Arc length at each vertex \[m\].
    cum: Vec<f64>,
    /// Unit direction of each leg.
    dirs: Vec<Vector3<f64>>,
    /// The speed profile, in time order.
    pieces: Vec<Piece>,
    /// For each waypoint of the spec: the time the profile reaches it \[s\].
    arrivals: Vec<f64>,
    /// For each waypoint of the spec: its yaw.
    yaws: Vec<Option<f64>>,
    /// The blend's initial velocity `w` [m/s] and time constant \[s\].
    blend: (Vector3<f64>, f64),
    /// Cruise speed [m/s].
    cruise: f64,
    /// Time since the start on the route's clock \[s\].
    pub(super) elapsed: f64,
    /// Controller time of the start \[s\] (set by the first `set_time`).
    origin: Option<f64>,
}

fn check_speed(field: &'static str, v: f64) -> Result<(), ControlError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            field,
            format!("must be finite and > 0 m/s, got {v}"),
        ))
    }
}

/// A route's vertices: the start, then each waypoint that does not stand
/// where the previous vertex does.
struct Vertices {
    /// Positions \[m\].
    points: Vec<Vector3<f64>>,
    /// The speed of the leg arriving at each vertex after the first \[m/s\].
    leg_speed: Vec<f64>,
    /// The hold at each vertex \[s\].
    hold: Vec<f64>,
    /// Each waypoint's vertex.
    vertex_of: Vec<usize>,
}

impl Vertices {
    /// Checks `spec` and merges its zero-length legs.
    fn of(spec: &RouteSpec) -> Result<Self, ControlError> {
        check_speed("cruise_speed", spec.cruise_speed)?;
        let acc = spec.acceleration;
        if !(acc.is_finite() && acc > 0.0) {
            return Err(invalid(
                "acceleration",
                format!("must be finite and > 0 m/s², got {acc}"),
            ));
        }
        if !is_finite3(&spec.start) || !is_finite3(&spec.start_velocity) {
            return Err(invalid("start", "position and velocity must be finite"));
        }
        if spec.waypoints.is_empty() {
            return Err(invalid("waypoints", "need at least 1 waypoint"));
        }
        // Vertices with their leg speed (of the leg arriving) and hold.
        let mut points = vec![spec.start];
        let mut leg_speed: Vec<f64> = Vec::new();
        let mut hold: Vec<f64> = vec![0.0];
        let mut vertex_of = Vec::with_capacity(spec.waypoints.len());
        for (i, w) in spec.waypoints.iter().enumerate() {
            if !is_finite3(&w.position) {
                return Err(invalid("waypoints", format!("waypoint {i} is not finite")));
            }
            if let Some(v) = w.speed {
                check_speed("waypoint speed", v)?;
            }
            if !(w.hold_s.is_finite() && w.hold_s >= 0.0) {
                return Err(invalid(
                    "hold_s",
                    format!("waypoint {i}: must be finite and ≥ 0 s, got {}", w.hold_s),
                ));
            }
            if w.yaw.is_some_and(|y| !y.is_finite()) {
                return Err(invalid("yaw", format!("waypoint {i}: yaw is not finite")));
            }
            let last = points[points.len() - 1];
            let scale = last.norm().max(w.position.norm()).max(1.0);
            if (w.position - last).norm() <= 1e-9 * scale {
                // Zero-length leg: the waypoint is the previous vertex.
                let h = hold.len() - 1;
                hold[h] = hold[h].max(w.hold_s);
            } else {
                points.push(w.position);
                leg_speed.push(w.speed.unwrap_or(spec.cruise_speed));
                hold.push(w.hold_s);
            }
            vertex_of.push(points.len() - 1);
        }
        Ok(Self {
            points,
            leg_speed,
            hold,
            vertex_of,
        })
    }
}

/// The speeds at the vertices \[m/s\] (0 at stops and the end, the lower
/// leg speed at corners, `along` at the start, each reachable from its
/// neighbours at the acceleration) and each leg's acceleration \[m/s²\]
/// (`acc`, more on a first leg too short to brake the start speed).
fn boundary_speeds(
    along: f64,
    hold: &[f64],
    leg_speed: &[f64],
    cum: &[f64],
    acc: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = leg_speed.len();
    // Boundary speeds: 0 at stops and the end, the lower leg speed at
    // corners, the along-track speed at the start.
    let mut b = vec![0.0; n + 1];
    b[0] = along;
    for j in 1..n {
        b[j] = if hold[j] > 0.0 {
            0.0
        } else {
            leg_speed[j - 1].min(leg_speed[j])
        };
    }
    // A first leg too short to brake the start speed brakes harder.
    let mut leg_acc = vec![acc; n];
    let reach = |u: f64, len: f64, a: f64| (u * u + 4.0 * a * len / std::f64::consts::PI).sqrt();
    for j in (1..n).rev() {
        b[j] = b[j].min(reach(b[j + 1], cum[j + 1] - cum[j], acc));
    }
    if n > 0 {
        let need = std::f64::consts::PI * (b[0] * b[0] - b[1] * b[1]) / (4.0 * cum[1]);
        leg_acc[0] = acc.max(need);
    }
    for j in 1..n {
        b[j] = b[j].min(reach(b[j - 1], cum[j] - cum[j - 1], leg_acc[j - 1]));
    }
    (b, leg_acc)
}

impl Route {
    pub(super) fn new(spec: &RouteSpec) -> Result<Self, ControlError> {
        let acc = spec.acceleration;
        let Vertices {
            points,
            leg_speed,
            hold,
            vertex_of,
        } = Vertices::of(spec)?;
        let n = points.len() - 1; // legs
        let mut cum = vec![0.0];
        let mut dirs = Vec::with_capacity(n);
        for i in 0..n {
            let d = points[i + 1] - points[i];
            let len = d.norm();
            dirs.push(d / len);
            cum.push(cum[i] + len);
        }
        let v_start = spec.start_velocity;
        let (along, blend_w) = if n > 0 {
            let a = v_start.dot(&dirs[0]).max(0.0);
            (a, v_start - dirs[0] * a)
        } else {
            (0.0, v_start)
        };
        let w_norm = blend_w.norm();
        let blend = (blend_w, (2.0 * w_norm / acc).max(MIN_BLEND_TIME));

        let (b, leg_acc) = boundary_speeds(along, &hold, &leg_speed, &cum, acc);
        // Pieces, leg by leg.
        let mut pieces = Vec::new();
        let mut vertex_time = vec![0.0; n + 1];
        let mut t = 0.0;
        let push = |pieces: &mut Vec<Piece>, t: &mut f64, s0: f64, va: f64, vb: f64, dur: f64| {
            if dur > 1e-12 {
                pieces.push(Piece {
                    t0: *t,
                    dur,
                    s0,
                    va,
                    vb,
                });
                *t += dur;
            }
        };
        if hold[0] > 0.0 {
            push(&mut pieces, &mut t, 0.0, 0.0, 0.0, hold[0]);
        }
        for i in 0..n {
            let (u, w, a, len) = (b[i], b[i + 1], leg_acc[i], cum[i + 1] - cum[i]);
            let ramp = |x: f64, y: f64| std::f64::consts::PI * (y * y - x * x).abs() / (4.0 * a);
            let fit = ((4.0 * a * len / std::f64::consts::PI + u * u + w * w) / 2.0).sqrt();
            let p = leg_speed[i].min(fit).max(w);
            let cruise = (len - ramp(u, p) - ramp(p, w)).max(0.0);
            let mut s = cum[i];
            let t_up = std::f64::consts::PI * (p - u).abs() / (2.0 * a);
            push(&mut pieces, &mut t, s, u, p, t_up);
            s += ramp(u, p);
            if p > 0.0 {
                push(&mut pieces, &mut t, s, p, p, cruise / p);
            }
            s += cruise;
            let t_down = std::f64::consts::PI * (p - w).abs() / (2.0 * a);
            push(&mut pieces, &mut t, s, p, w, t_down);
            // Rounding: the leg ends exactly at its vertex.
            if let Some(last) = pieces.last_mut() {
                let (s_end, _, _) = last.eval(last.dur);
                let err = cum[i + 1] - s_end;
                if err.abs() > 1e-9 {
                    last.s0 += err;
                }
            }
            vertex_time[i + 1] = t;
            if hold[i + 1] > 0.0 {
                push(&mut pieces, &mut t, cum[i + 1], 0.0, 0.0, hold[i + 1]);
            }
        }
        let arrivals = vertex_of.iter().map(|&v| vertex_time[v]).collect();
        Ok(Self {
            points,
            cum,
            dirs,
            pieces,
            arrivals,
            yaws: spec.waypoints.iter().map(|w| w.yaw).collect(),
            blend,
            cruise: spec.cruise_speed,
            elapsed: 0.0,
            origin: None,
        })
    }

    /// Total arc length \[m\].
    pub(super) fn length(&self) -> f64 {
        self.cum[self.cum.len() - 1]
    }

    /// Cruise speed [m/s].
    pub(super) fn cruise(&self) -> f64 {
        self.cruise
    }

    /// Duration of the profile \[s\] (then the end is held).
    pub(super) fn duration(&self) -> f64 {
        self.pieces.last().map_or(0.0, |p| p.t0 + p.dur)
    }

    /// Sets the clock from the controller's time `t` \[s\]: the first call
    /// is the start. Non-finite or earlier times are ignored.
    pub(super) fn set_time(&mut self, t: f64) {
        if !t.is_finite() {
            return;
        }
        match self.origin {
            None => {
                self.origin = Some(t);
                self.elapsed = 0.0;
            }
            Some(o) => self.elapsed = self.elapsed.max(t - o),
        }
    }

    /// True when the clock is driven by [`Route::set_time`].
    pub(super) fn driven(&self) -> bool {
        self.origin.is_some()
    }

    pub(super) fn reset(&mut self) {
        self.elapsed = 0.0;
        self.origin = None;
    }

    /// Arc length, speed and acceleration along the line at time `tau`,
    /// searching the pieces from `hint` (returned updated).
    fn profile(&self, tau: f64, hint: &mut usize) -> (f64, f64, f64) {
        if self.pieces.is_empty() || tau <= 0.0 {
            let v0 = self.pieces.first().map_or(0.0, |p| p.va);
            return (0.0, if tau < 0.0 { 0.0 } else { v0 }, 0.0);
        }
        while *hint + 1 < self.pieces.len() && tau >= self.pieces[*hint + 1].t0 {
            *hint += 1;
        }
        let p = &self.pieces[*hint];
        if tau >= p.t0 + p.dur {
            let (s, v, _) = p.eval(p.dur);
            return (s.min(self.length()), v, 0.0);
        }
        let (s, v, a) = p.eval(tau - p.t0);
        (s.clamp(0.0, self.length()), v, a)
    }

    /// Leg holding arc length `s`, searching from `hint`.
    fn leg(&self, s: f64, hint: &mut usize) -> usize {
        let last = self.dirs.len().saturating_sub(1);
        while *hint < last && s >= self.cum[*hint + 1] {
            *hint += 1;
        }
        *hint
    }

    fn blend_at(&self, tau: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (w, tb) = self.blend;
        let tau = tau.max(0.0);
        let e = (-tau / tb).exp();
        (w * (tau * e), w * ((1.0 - tau / tb) * e))
    }

    /// Position and velocity at time `tau` on the route's clock, with the
    /// search hints `(piece, leg)`.
    pub(super) fn state(
        &self,
        tau: f64,
        hints: &mut (usize, usize),
    ) -> (Vector3<f64>, Vector3<f64>) {
        let (s, v, _) = self.profile(tau, &mut hints.0);
        let (eb, vb) = self.blend_at(tau);
        if self.dirs.is_empty() {
            return (self.points[0] + eb, vb);
        }
        let leg = self.leg(s, &mut hints.1);
        let p = self.points[leg] + self.dirs[leg] * (s - self.cum[leg]);
        (p + eb, self.dirs[leg] * v + vb)
    }

    /// Fills the horizon from the current clock, then advances the clock by
    /// `dt` unless it is driven.
    pub(super) fn horizon(&mut self, dt: f64, out: &mut [Vector3<f64>]) {
        let dt = if dt.is_finite() && dt > 0.0 { dt } else { 0.0 };
        let mut hints = (0, 0);
        for (j, o) in out.iter_mut().enumerate() {
            *o = self.state(self.elapsed + j as f64 * dt, &mut hints).0;
        }
        if !self.driven() {
            self.elapsed += dt;
        }
    }

    /// Arc length of the profile now \[m\].
    pub(super) fn progress(&self) -> f64 {
        self.profile(self.elapsed, &mut 0).0
    }

    /// Index of the last waypoint the profile has reached.
    pub(super) fn last_reached(&self) -> Option<usize> {
        self.arrivals
            .iter()
            .rposition(|&t| t <= self.elapsed + 1e-9)
    }

    /// Yaw of the waypoint being flown to (the last one once reached).
    pub(super) fn yaw_target(&self) -> Option<f64> {
        let next = self.last_reached().map_or(0, |i| i + 1);
        self.yaws[next.min(self.yaws.len() - 1)]
    }

    /// Distance \[m\] from `q` to the nearest point of the polyline.
    pub(super) fn distance(&self, q: &Vector3<f64>) -> f64 {
        if self.dirs.is_empty() {
            return (q - self.points[0]).norm();
        }
        (0..self.dirs.len())
            .map(|i| {
                let along = (q - self.points[i]).dot(&self.dirs[i]);
                let s = along.clamp(0.0, self.cum[i + 1] - self.cum[i]);
                (q - (self.points[i] + self.dirs[i] * s)).norm()
            })
            .fold(f64::INFINITY, f64::min)
    }
}
