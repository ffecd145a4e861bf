//! The baselines' finite-difference state ([`StateSource::FiniteDifference`],
//! the paper's §VI definition) taken at the poses' own capture times.
//!
//! The paper differences one pose per tick, each a tick after the last:
//! `[y_k, (y_k − y_{k−1})/δt, (y_k − 2y_{k−1} + y_{k−2})/δt²]`. On a starved
//! machine that stops being true: a tick finds no new pose, the pose of the
//! tick before arrives late, the shell skips ticks, a starved sender's
//! capture times fall between the ticks. Differenced as if a tick apart,
//! a repeated pose reads at 4 m/s as a 200 m/s² stop and the late one after
//! it as a doubled speed (Flatness MPC then asks for negative thrust; PD
//! stepped its tilt by 1 rad in one tick).
//!
//! [`PoseDifferences`] keeps the three newest poses with their times and
//! differences them at those times: the quadratic through them, read on the
//! tick grid (the velocity at half a step before, as the paper's backward
//! difference is, and the second difference), then carried to the tick's
//! own time along that quadratic. With one pose per tick on time it is the
//! paper's formula bit for bit.
//!
//! The ticks lie on a grid a step apart from the first pose's time, as the
//! classic window's slots do: a pose taken off it (capture jitter) is
//! carried onto it, up to half a step either way, and one more than half a
//! step past the next tick moves the tick on by whole steps (ticks the
//! shell skipped without saying). Taking each later pose's time as the
//! tick's instead let one pose stamped late move every tick after it: the
//! state was extrapolated by the largest capture delay seen, for good.
//!
//! [`StateSource::FiniteDifference`]: super::StateSource::FiniteDifference

use nalgebra::Vector3;

/// A pose less than this share of a step newer than the newest held is not
/// a new pose (two poses in one tick: a first difference over a sliver of
/// a step amplifies noise).
const NEWER: f64 = 0.5;
/// Spacings within this share of a step of one step are one step: the
/// paper's formula, bit for bit.
const ON_GRID: f64 = 1e-9;
/// The longest extrapolation from the newest pose to the tick \[steps\];
/// longer gaps hold it (the daemon's pose timeout acts long before).
pub const MAX_EXTRAPOLATION: f64 = 10.0;

/// The flat state of the tick from finite differences, per axis (model
/// frame, NED).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DifferencedState {
    /// Position at the tick \[m\].
    pub position: Vector3<f64>,
    /// The first difference: velocity half a step before the tick [m/s]
    /// (the paper's backward difference).
    pub velocity: Vector3<f64>,
    /// The second difference: acceleration [m/s²].
    pub acceleration: Vector3<f64>,
    /// How far the tick is past the newest pose \[s\] (0 with a pose on
    /// time; down to −δt/2 for a pose taken after the tick's grid time).
    pub extrapolated: f64,
}

/// The three newest poses at their capture times and the tick's time (see
/// the module docs).
#[derive(Debug, Clone)]
pub struct PoseDifferences {
    /// Control step δt \[s\].
    dt: f64,
    /// The newest poses, newest first: (capture time \[s\], position \[m\]).
    poses: [(f64, Vector3<f64>); 3],
    /// How many of `poses` are measured (the rest pad with the first).
    held: usize,
    /// The current tick's time on the poses' clock \[s\]; None before the
    /// first pose.
    tick: Option<f64>,
    /// Ticks the shell skipped since the last tick ([`Self::skip`]), taken
    /// by the next one.
    skipped: u32,
}

impl PoseDifferences {
    /// Empty, for control step `dt` \[s\] (finite, > 0: the caller's model
    /// checked it).
    pub fn new(dt: f64) -> Self {
        Self {
            dt,
            poses: [(0.0, Vector3::zeros()); 3],
            held: 0,
            tick: None,
            skipped: 0,
        }
    }

    /// Forgets every pose.
    pub fn reset(&mut self) {
        *self = Self::new(self.dt);
    }

    /// Whether a pose has been taken.
    pub fn started(&self) -> bool {
        self.tick.is_some()
    }

    /// One tick with the newest pose the shell has, `(t, position)`
    /// (capture time \[s\], position \[m\]; finite, checked by the caller).
    /// Returns whether it was a new pose: at least half a step newer than
    /// the newest held (an older or repeated one, or one in the same step,
    /// changes nothing but the tick's time).
    ///
    /// The tick's time is a step after the last tick's (plus the ticks
    /// the shell said it skipped, [`Self::skip`]), or, for a new pose more
    /// than half a step past that, the grid time nearest the pose's (ticks
    /// skipped unsaid): each call is one tick, on a grid a step apart from
    /// the first pose's time.
    pub fn tick(&mut self, t: f64, position: &Vector3<f64>) -> bool {
        let next = self.tick_time(t);
        self.skipped = 0;
        if self.tick.is_none() {
            // The first pose pads the history a step apart (the paper's
            // window padded with the first measurement).
            let dt = self.dt;
            self.poses = [
                (t, *position),
                (t - dt, *position),
                (t - 2.0 * dt, *position),
            ];
            self.held = 1;
            self.tick = Some(t);
            return true;
        }
        let new = self.is_new(t);
        if new {
            self.poses = [(t, *position), self.poses[0], self.poses[1]];
            self.held = (self.held + 1).min(3);
        }
        self.tick = Some(next);
        new
    }

    /// Whether a pose taken at `t` \[s\] is new: at least half a step newer
    /// than the newest held.
    fn is_new(&self, t: f64) -> bool {
        t >= self.poses[0].0 + NEWER * self.dt
    }

    /// The time \[s\] the next [`Self::tick`] with the newest pose taken at
    /// `t` will take the tick to be, without taking it: `t` for the first
    /// pose.
    pub fn tick_time(&self, t: f64) -> f64 {
        let Some(tick) = self.tick else {
            return t;
        };
        let next = tick + (1.0 + f64::from(self.skipped)) * self.dt;
        if self.is_new(t) {
            next + ((t - next) / self.dt).round().max(0.0) * self.dt
        } else {
            next
        }
    }

    /// The shell skipped `ticks` ticks (no call, the last command held):
    /// the next [`Self::tick`] is that many steps later than a step after
    /// the last, with or without a new pose. Nothing before the first
    /// pose.
    pub fn skip(&mut self, ticks: u32) {
        if self.tick.is_some() {
            self.skipped = self.skipped.saturating_add(ticks);
        }
    }

    /// How far the tick is past the newest pose \[s\]: 0 for a pose on
    /// time (within 1e-9 of a step), at most [`MAX_EXTRAPOLATION`] steps,
    /// down to −δt/2 for a pose taken after the tick's grid time; None
    /// before the first pose.
    pub fn extrapolation(&self) -> Option<f64> {
        let tau = self.tick? - self.poses[0].0;
        Some(if tau.abs() <= ON_GRID * self.dt {
            0.0
        } else {
            tau.clamp(-0.5 * self.dt, MAX_EXTRAPOLATION * self.dt)
        })
    }

    /// The newest pose: (capture time \[s\], position \[m\]); None before
    /// the first.
    pub fn newest(&self) -> Option<(f64, Vector3<f64>)> {
        self.tick.map(|_| self.poses[0])
    }

    /// The first difference of the two newest poses over their own spacing
    /// [m/s] (the velocity half that spacing before the newest; the paper's
    /// `(y_k − y_{k−1})/δt` for poses a step apart); None before the first
    /// pose.
    pub fn first_difference(&self) -> Option<Vector3<f64>> {
        self.tick?;
        let [(t0, y0), (t1, y1), _] = self.poses;
        Some((y0 - y1) / self.spacing(t0 - t1))
    }

    /// `h`, or exactly δt when within 1e-9 of it.
    fn spacing(&self, h: f64) -> f64 {
        if (h - self.dt).abs() <= ON_GRID * self.dt {
            self.dt
        } else {
            h
        }
    }

    /// The tick's flat state from the three newest poses (see the module
    /// docs); None before the first pose.
    pub fn state(&self) -> Option<DifferencedState> {
        let tau = self.extrapolation()?;
        let dt = self.dt;
        let [(t0, y0), (t1, y1), (t2, y2)] = self.poses;
        let (h1, h2) = (self.spacing(t0 - t1), self.spacing(t1 - t2));
        let d1 = (y0 - y1) / h1;
        let (mut velocity, acceleration) = if h1 == dt && h2 == dt {
            (d1, (y0 - y1 * 2.0 + y2) / (dt * dt))
        } else {
            let d2 = (y1 - y2) / h2;
            let a = (d1 - d2) * (2.0 / (h1 + h2));
            // The quadratic's slope half a step before t0.
            (d1 + a * (0.5 * (h1 - dt)), a)
        };
        let mut position = y0;
        if tau != 0.0 {
            // Along the quadratic: its slope at t0 is d1 + a·h1/2.
            position += (d1 + acceleration * (0.5 * h1)) * tau + acceleration * (0.5 * tau * tau);
            velocity += acceleration * tau;
        }
        Some(DifferencedState {
            position,
            velocity,
            acceleration,
            extrapolated: tau,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f64 = 0.02;

    /// A quadratic motion per axis: p(t) = p0 + v0·t + a·t²/2.
    fn quadratic(t: f64) -> Vector3<f64> {
        let (p0, v0, a) = (
            Vector3::new(1.0, -2.0, -10.0),
            Vector3::new(4.0, 3.0, -0.5),
            Vector3::new(-2.0, 1.5, 0.3),
        );
        p0 + v0 * t + a * (0.5 * t * t)
    }

    fn assert_close(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64, what: &str) {
        assert!((a - b).norm() <= tol, "{what}: {a:?} against {b:?}");
    }

    /// On time, one pose per tick: the paper's formula bit for bit.
    #[test]
    fn poses_a_tick_apart_are_the_papers_differences() {
        let mut d = PoseDifferences::new(DT);
        let ys: Vec<_> = (0..6).map(|k| quadratic(k as f64 * DT)).collect();
        for (k, y) in ys.iter().enumerate() {
            assert!(d.tick(k as f64 * DT, y));
            let s = d.state().unwrap();
            let (y1, y2) = match k {
                0 => (ys[0], ys[0]),
                1 => (ys[0], ys[0]),
                _ => (ys[k - 1], ys[k - 2]),
            };
            assert_eq!(s.position, *y);
            assert_eq!(s.velocity, (y - y1) / DT);
            assert_eq!(s.acceleration, (y - y1 * 2.0 + y2) / (DT * DT));
            assert_eq!(s.extrapolated, 0.0);
        }
    }

    /// The paper's state of a quadratic motion at tick time `t`: the
    /// position, the slope half a step before, the acceleration.
    fn paper_state(t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let y = quadratic(t);
        (y, (y - quadratic(t - DT)) / DT)
    }

    /// A tick without a new pose: the state carried a step along the
    /// quadratic, not read as a stop.
    #[test]
    fn a_tick_without_a_pose_is_carried_forward() {
        let mut d = PoseDifferences::new(DT);
        for k in 0..4 {
            d.tick(k as f64 * DT, &quadratic(k as f64 * DT));
        }
        let last = 3.0 * DT;
        assert!(!d.tick(last, &quadratic(last)));
        let s = d.state().unwrap();
        let (y, v) = paper_state(4.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position");
        assert_close(&s.velocity, &v, 1e-7, "velocity");
        assert!((s.extrapolated - DT).abs() < 1e-12);
        // The pose of that tick arrives late: the state is on time again.
        assert!(d.tick(4.0 * DT, &quadratic(4.0 * DT)));
        let s = d.state().unwrap();
        let (y, v) = paper_state(5.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position after the late pose");
        assert_close(&s.velocity, &v, 1e-7, "velocity after the late pose");
        // And the next on time.
        assert!(d.tick(6.0 * DT, &quadratic(6.0 * DT)));
        assert_eq!(d.state().unwrap().extrapolated, 0.0);
    }

    /// Skipped ticks: the next pose is two or three steps after the last.
    #[test]
    fn skipped_ticks_take_the_pose_at_its_time() {
        let mut d = PoseDifferences::new(DT);
        for k in [0, 1, 2, 5, 6, 9] {
            let t = k as f64 * DT;
            assert!(d.tick(t, &quadratic(t)));
            let s = d.state().unwrap();
            let (y, v) = paper_state(t);
            assert_close(&s.position, &y, 1e-12, "position");
            if k >= 2 {
                assert_close(&s.velocity, &v, 1e-9, "velocity");
                assert_close(
                    &s.acceleration,
                    &Vector3::new(-2.0, 1.5, 0.3),
                    1e-6,
                    "acceleration",
                );
            }
            assert_eq!(s.extrapolated, 0.0);
        }
    }

    /// Skipped ticks the shell says: a tick after them without a new pose
    /// is at its own time, not a step after the last; one with a late
    /// pose too.
    #[test]
    fn skipped_ticks_said_move_the_tick_without_a_pose() {
        let mut d = PoseDifferences::new(DT);
        for k in 0..4 {
            d.tick(k as f64 * DT, &quadratic(k as f64 * DT));
        }
        // Ticks 4 and 5 skipped, tick 6 finds the pose of tick 3 again.
        d.skip(2);
        assert!(!d.tick(3.0 * DT, &quadratic(3.0 * DT)));
        let s = d.state().unwrap();
        assert!((s.extrapolated - 3.0 * DT).abs() < 1e-12);
        let (y, v) = paper_state(6.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position");
        assert_close(&s.velocity, &v, 1e-7, "velocity");
        // Taken once: tick 7 is a step later, with tick 5's pose (late).
        assert!(d.tick(5.0 * DT, &quadratic(5.0 * DT)));
        let s = d.state().unwrap();
        assert!((s.extrapolated - 2.0 * DT).abs() < 1e-12);
        let (y, v) = paper_state(7.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position after the late pose");
        assert_close(&s.velocity, &v, 1e-7, "velocity after the late pose");
        // Said before the first pose: nothing.
        let mut fresh = PoseDifferences::new(DT);
        fresh.skip(3);
        assert!(fresh.tick(0.0, &quadratic(0.0)));
        assert!(fresh.tick(DT, &quadratic(DT)));
        assert_eq!(fresh.state().unwrap().extrapolated, 0.0);
    }

    /// One pose stamped late (capture jitter) is carried back onto its
    /// tick; the poses on time after it are the paper's differences again
    /// (the tick did not move to the late stamp).
    #[test]
    fn a_pose_stamped_late_does_not_move_the_ticks_after_it() {
        let mut d = PoseDifferences::new(DT);
        for k in 0..3 {
            d.tick(k as f64 * DT, &quadratic(k as f64 * DT));
        }
        let late = 3.4 * DT;
        assert!(d.tick(late, &quadratic(late)));
        let s = d.state().unwrap();
        assert!((s.extrapolated + 0.4 * DT).abs() < 1e-12);
        let (y, v) = paper_state(3.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position moved back");
        assert_close(&s.velocity, &v, 1e-7, "velocity moved back");
        for k in 4..7 {
            let t = k as f64 * DT;
            assert!(d.tick(t, &quadratic(t)));
            assert_eq!(d.state().unwrap().extrapolated, 0.0, "tick {k}");
        }
    }

    /// Repeated, older and same-step poses change nothing but the tick.
    #[test]
    fn older_and_repeated_poses_are_not_new() {
        let mut d = PoseDifferences::new(DT);
        for k in 0..3 {
            d.tick(k as f64 * DT, &quadratic(k as f64 * DT));
        }
        assert!(!d.tick(2.0 * DT, &Vector3::repeat(99.0)));
        assert!(!d.tick(1.0 * DT, &Vector3::repeat(99.0)));
        assert!(!d.tick(2.3 * DT, &Vector3::repeat(99.0)));
        assert_eq!(d.newest().map(|(t, _)| t), Some(2.0 * DT));
        // Three ticks have passed since the pose of tick 2.
        let s = d.state().unwrap();
        assert!((s.extrapolated - 3.0 * DT).abs() < 1e-12);
        let (y, _) = paper_state(5.0 * DT);
        assert_close(&s.position, &y, 1e-9, "position");
    }

    /// A long gap holds the extrapolation at its cap.
    #[test]
    fn a_long_gap_extrapolates_at_most_the_cap() {
        let mut d = PoseDifferences::new(DT);
        for k in 0..3 {
            d.tick(k as f64 * DT, &quadratic(k as f64 * DT));
        }
        for _ in 0..40 {
            d.tick(2.0 * DT, &quadratic(2.0 * DT));
        }
        let s = d.state().unwrap();
        assert!((s.extrapolated - MAX_EXTRAPOLATION * DT).abs() < 1e-12);
    }

    proptest! {
        /// Any capture times and any ticks between them (each pose from
        /// half a step before to two steps after the tick it arrives at,
        /// up to two ticks without a pose after it): on a quadratic motion
        /// the state is the paper's at the tick's time, the ticks a step
        /// apart from the first pose's.
        #[test]
        fn quadratic_motion_is_read_exactly_at_any_capture_times(
            arrivals in prop::collection::vec((-0.45f64..2.0, 0usize..3), 3..30),
        ) {
            let mut d = PoseDifferences::new(DT);
            for k in 0..3 {
                let t = k as f64 * DT;
                d.tick(t, &quadratic(t));
            }
            let (mut tick, mut newest) = (2.0 * DT, 2.0 * DT);
            for (offset, idle) in arrivals {
                let t = tick + DT + offset * DT;
                // New when half a step newer than the newest held (a pose
                // stamped late, then one stamped early, can be closer).
                let new = t >= newest + 0.5 * DT;
                let ahead = d.tick_time(t);
                prop_assert_eq!(d.tick(t, &quadratic(t)), new);
                // On the grid: a new pose more than half a step late moves
                // the tick on by whole steps.
                tick += DT * (1.0 + if new { offset.round().max(0.0) } else { 0.0 });
                if new {
                    newest = t;
                }
                // The tick's time, told before the tick.
                prop_assert!((ahead - tick).abs() < 1e-9, "{} {}", ahead, tick);
                for i in 0..=idle {
                    if i > 0 {
                        prop_assert!(!d.tick(t, &quadratic(t)));
                        tick += DT;
                    }
                    let s = d.state().unwrap();
                    prop_assert!((s.extrapolated - (tick - newest)).abs() < 1e-9);
                    let (y, v) = paper_state(tick);
                    prop_assert!((s.position - y).norm() < 1e-9, "{:?} {:?}", s.position, y);
                    prop_assert!((s.velocity - v).norm() < 1e-6, "{:?} {:?}", s.velocity, v);
                }
            }
        }
    }
}
