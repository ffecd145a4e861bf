//! Flying an uploaded mission (pure): the navigation items become legs
//! with their speed, hold time, acceptance radius and yaw; the legs are
//! flown in *sections* — a path through every waypoint up to the next hold
//! (a waypoint with a hold time, a loiter) or speed change, so the MPC has
//! the whole section as preview, corners included — and each waypoint is
//! reported reached (MISSION_ITEM_REACHED) when the vehicle is within its
//! acceptance radius or has passed abeam of it (its closest point on the
//! path is beyond the waypoint).
//!
//! A section starts where the vehicle is, at its speed, and ramps up to
//! the section's speed ([`dflat_control::reference::Reference::with_ramp`]),
//! so neither a start, a continue after a pause, nor a speed change makes
//! the reference (or the command) jump. Until the route reference lands
//! (per-leg speeds and stop ramps in one reference), a speed change or a
//! hold ends a section: the vehicle slows to the section's last waypoint.

use dflat_control::ControlError;
use dflat_control::reference::Reference;
use nalgebra::Vector3;

use super::items::{Mission, MissionItem};

/// A section's end is taken as reached once the reference has finished for
/// this long \[s\], even outside a (tight) acceptance radius.
pub const END_SETTLE: f64 = 3.0;

/// One navigation item, as flown.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Leg {
    /// The item's sequence number.
    seq: u16,
    /// Where it flies to, local NED \[m\].
    position: [f64; 3],
    /// Speed of the leg to it [m/s] (the DO_CHANGE_SPEED before it, else
    /// `mission.speed`).
    speed: f64,
    /// Hold time there \[s\].
    hold: f64,
    /// Acceptance radius \[m\].
    acceptance: f64,
    /// Heading \[rad\] from here on, if the item sets one.
    yaw: Option<f64>,
}

/// Where the mission stands (MISSION_CURRENT's `mission_state`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissionStatus {
    /// Uploaded, not started.
    NotStarted,
    /// Being flown.
    Active,
    /// Paused (MAV_CMD_DO_PAUSE_CONTINUE 0): holding.
    Paused,
    /// The last item was reached.
    Complete,
}

/// What one [`MissionRunner::update`] found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunnerUpdate {
    /// Items reached at this tick (MISSION_ITEM_REACHED), in order.
    pub reached: Vec<u16>,
    /// A new section begins: build its reference ([`MissionRunner::section`]).
    pub new_section: bool,
    /// The last item was reached (and held): the mission is complete.
    pub finished: bool,
}

/// A mission being flown (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct MissionRunner {
    legs: Vec<Leg>,
    total: u16,
    current: usize,
    section_start: usize,
    section_end: usize,
    /// Arc length \[m\] of the legs `current..=section_end` along the
    /// section's path.
    section_s: Vec<f64>,
    hold_until: Option<f64>,
    finished_since: Option<f64>,
    speed_override: Option<f64>,
    /// The envelope's speed limit [m/s] ([`MissionRunner::with_speed_limit`]).
    max_speed: f64,
    status: MissionStatus,
    yaw: Option<f64>,
}

impl MissionRunner {
    /// The flight of `mission` at `default_speed` [m/s] where no
    /// DO_CHANGE_SPEED says otherwise; `None` without a navigation item.
    pub fn new(mission: &Mission, default_speed: f64) -> Option<Self> {
        let mut speed = default_speed;
        let mut legs = Vec::new();
        for (seq, item) in mission.items.iter().enumerate() {
            let seq = seq as u16;
            match *item {
                MissionItem::ChangeSpeed { speed: s } => speed = s.unwrap_or(speed),
                MissionItem::Waypoint {
                    position,
                    hold,
                    acceptance,
                    yaw,
                } => legs.push(Leg {
                    seq,
                    position,
                    speed,
                    hold,
                    acceptance,
                    yaw,
                }),
                MissionItem::LoiterTime {
                    position,
                    time,
                    acceptance,
                } => legs.push(Leg {
                    seq,
                    position,
                    speed,
                    hold: time,
                    acceptance,
                    yaw: None,
                }),
            }
        }
        (!legs.is_empty()).then(|| Self {
            legs,
            total: mission.len() as u16,
            current: 0,
            section_start: 0,
            section_end: 0,
            section_s: Vec::new(),
            hold_until: None,
            finished_since: None,
            speed_override: None,
            max_speed: f64::INFINITY,
            status: MissionStatus::NotStarted,
            yaw: None,
        })
    }

    /// Starts (or restarts) the mission at the first navigation item at
    /// or after `first` (MAV_CMD_MISSION_START param1).
    pub fn start(&mut self, first: u16) {
        self.current = self.legs.iter().position(|l| l.seq >= first).unwrap_or(0);
        self.hold_until = None;
        self.finished_since = None;
        self.status = MissionStatus::Active;
        self.take_yaw();
    }

    /// Pauses (holding wherever the vehicle stops).
    pub fn pause(&mut self) {
        if self.status == MissionStatus::Active {
            self.status = MissionStatus::Paused;
        }
    }

    /// Continues after a pause (build the section again from where the
    /// vehicle is: [`MissionRunner::section`]). False when not paused.
    pub fn resume(&mut self) -> bool {
        let paused = self.status == MissionStatus::Paused;
        if paused {
            self.status = MissionStatus::Active;
        }
        paused
    }

    /// Flies the rest of the mission at `speed` [m/s] (MAV_CMD_DO_CHANGE_SPEED).
    pub fn set_speed(&mut self, speed: f64) {
        self.speed_override = Some(speed);
    }

    /// Where the mission stands.
    pub fn status(&self) -> MissionStatus {
        self.status
    }

    /// MISSION_CURRENT's item: the item being flown to (the last one when
    /// complete), and the number of items.
    pub fn current_item(&self) -> (u16, u16) {
        (self.legs[self.current].seq, self.total)
    }

    /// The heading the mission asks for \[rad\] (the latest waypoint yaw
    /// flown to), if any.
    pub fn yaw(&self) -> Option<f64> {
        self.yaw
    }

    /// The last navigation item's position (held after the mission).
    pub fn end(&self) -> [f64; 3] {
        self.legs[self.legs.len() - 1].position
    }

    /// The flight envelope's speed limit [m/s]: every leg, and every
    /// DO_CHANGE_SPEED, is flown at most this fast.
    pub fn with_speed_limit(mut self, max_speed: f64) -> Self {
        self.max_speed = max_speed;
        self
    }

    fn speed_of(&self, leg: usize) -> f64 {
        self.speed_override
            .unwrap_or(self.legs[leg].speed)
            .min(self.max_speed)
    }

    fn take_yaw(&mut self) {
        if let Some(y) = self.legs[self.current].yaw {
            self.yaw = Some(y);
        }
    }

    /// The reference of the section that begins at the current item, from
    /// `from` (the vehicle, local NED \[m\]) moving at `v0` [m/s], its speed
    /// ramped up at `accel` [m/s²] (0: no ramp).
    pub fn section(
        &mut self,
        from: [f64; 3],
        v0: f64,
        accel: f64,
    ) -> Result<Reference, ControlError> {
        let speed = self.speed_of(self.current);
        let mut end = self.current;
        while end + 1 < self.legs.len()
            && self.legs[end].hold <= 0.0
            && (self.speed_of(end + 1) - speed).abs() < 1e-9
        {
            end += 1;
        }
        self.section_start = self.current;
        self.section_end = end;
        self.finished_since = None;
        let mut points = vec![Vector3::from(from)];
        self.section_s.clear();
        let mut s = 0.0;
        for leg in &self.legs[self.current..=end] {
            let p = Vector3::from(leg.position);
            let last = points[points.len() - 1];
            let d = (p - last).norm();
            if d > 1e-3 {
                s += d;
                points.push(p);
            }
            self.section_s.push(s);
        }
        if points.len() < 2 {
            return Reference::setpoint(points[0]);
        }
        let path = Reference::path(&points, speed)?;
        if accel > 0.0 {
            path.with_ramp(v0, accel)
        } else {
            Ok(path)
        }
    }

    /// One tick at `t` \[s\]: the vehicle at `position` (local NED \[m\]),
    /// the section reference's `progress` \[m\] and whether it `finished`.
    pub fn update(
        &mut self,
        t: f64,
        position: [f64; 3],
        progress: f64,
        finished: bool,
    ) -> RunnerUpdate {
        let mut up = RunnerUpdate::default();
        if self.status != MissionStatus::Active {
            return up;
        }
        self.finished_since = if finished {
            Some(self.finished_since.unwrap_or(t))
        } else {
            None
        };
        // Each leg at most once per tick: a section has finitely many.
        for _ in 0..self.legs.len() + 1 {
            if let Some(until) = self.hold_until {
                if t < until {
                    break;
                }
                self.hold_until = None;
                if self.advance(&mut up) {
                    continue;
                }
                break;
            }
            let leg = self.legs[self.current];
            let d = distance(&leg.position, &position);
            let k = self.current.saturating_sub(self.section_start);
            let passed = self.current < self.section_end
                && self.section_s.get(k).is_some_and(|s| progress >= *s);
            let settled = self.current == self.section_end
                && self.finished_since.is_some_and(|f| t - f >= END_SETTLE);
            let reached = d <= leg.acceptance || passed || settled;
            if !reached {
                break;
            }
            up.reached.push(leg.seq);
            if leg.hold > 0.0 {
                self.hold_until = Some(t + leg.hold);
                continue;
            }
            if !self.advance(&mut up) {
                break;
            }
        }
        up
    }

    /// The current leg is done: the next one (a new section after the
    /// section's end), or the mission is complete. True when there is a
    /// next leg in the same section.
    fn advance(&mut self, up: &mut RunnerUpdate) -> bool {
        if self.current + 1 >= self.legs.len() {
            self.status = MissionStatus::Complete;
            up.finished = true;
            return false;
        }
        let section_done = self.current >= self.section_end;
        self.current += 1;
        self.take_yaw();
        if section_done {
            up.new_section = true;
            return false;
        }
        true
    }
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dflat_control::ReferenceSource;

    fn wp(x: f64, hold: f64, yaw: Option<f64>) -> MissionItem {
        MissionItem::Waypoint {
            position: [x, 0.0, -10.0],
            hold,
            acceptance: 0.5,
            yaw,
        }
    }

    fn mission(items: Vec<MissionItem>) -> Mission {
        Mission {
            raw: Vec::new(),
            items,
        }
    }

    #[test]
    fn sections_end_at_holds_and_speed_changes() {
        let m = mission(vec![
            wp(5.0, 0.0, None),
            wp(10.0, 2.0, Some(1.0)),
            MissionItem::ChangeSpeed { speed: Some(2.0) },
            wp(15.0, 0.0, None),
            wp(20.0, 0.0, None),
        ]);
        let mut r = MissionRunner::new(&m, 4.0).unwrap();
        r.start(0);
        let reference = r.section([0.0, 0.0, -10.0], 0.0, 0.0).unwrap();
        assert_eq!((r.section_end, r.section_s.clone()), (1, vec![5.0, 10.0]));
        assert!((reference.speed() - 4.0).abs() < 1e-12);
        assert_eq!(r.yaw(), None);
        // Passing abeam of item 0 reaches it; item 1 is reached within its
        // radius and held for 2 s.
        let up = r.update(1.0, [5.2, 1.0, -10.0], 5.2, false);
        assert_eq!(up.reached, vec![0]);
        assert_eq!(r.current_item(), (1, 5));
        assert_eq!(r.yaw(), Some(1.0));
        let up = r.update(2.0, [9.8, 0.0, -10.0], 9.8, false);
        assert_eq!((up.reached.clone(), up.new_section), (vec![1], false));
        assert!(!r.update(3.9, [10.0, 0.0, -10.0], 10.0, true).new_section);
        let up = r.update(4.0, [10.0, 0.0, -10.0], 10.0, true);
        assert!(up.new_section && up.reached.is_empty());
        // The next section flies at the new speed, to the end.
        let reference = r.section([10.0, 0.0, -10.0], 0.0, 3.0).unwrap();
        assert!((reference.speed() - 2.0).abs() < 1e-12);
        assert_eq!(r.current_item(), (3, 5));
        let up = r.update(9.0, [20.0, 0.0, -10.0], 10.0, true);
        assert_eq!(up.reached, vec![3, 4]);
        assert!(up.finished);
        assert_eq!(r.status(), MissionStatus::Complete);
        assert_eq!(r.end(), [20.0, 0.0, -10.0]);
    }

    #[test]
    fn pause_continue_and_a_tight_radius() {
        let mut w = wp(6.0, 0.0, None);
        if let MissionItem::Waypoint { acceptance, .. } = &mut w {
            *acceptance = 0.01;
        }
        let mut r = MissionRunner::new(&mission(vec![w]), 3.0).unwrap();
        assert_eq!(r.status(), MissionStatus::NotStarted);
        r.start(0);
        let mut reference = r.section([0.0, 0.0, -10.0], 0.0, 3.0).unwrap();
        // The reference starts where the vehicle is, at rest.
        let mut out = [Vector3::zeros(); 3];
        reference.horizon(&Vector3::new(0.0, 0.0, -10.0), 0.02, &mut out);
        assert!((out[0] - Vector3::new(0.0, 0.0, -10.0)).norm() < 1e-9);
        r.pause();
        assert!(
            r.update(1.0, [6.0, 0.0, -10.0], 6.0, true)
                .reached
                .is_empty()
        );
        assert!(r.resume() && !r.resume());
        assert!(
            r.update(2.0, [5.9, 0.0, -10.0], 6.0, true)
                .reached
                .is_empty()
        );
        // Outside the tight radius, the end counts once the reference has
        // finished for END_SETTLE.
        let up = r.update(2.0 + END_SETTLE, [5.9, 0.0, -10.0], 6.0, true);
        assert_eq!(up.reached, vec![0]);
        assert!(up.finished);
        assert!(MissionRunner::new(&mission(vec![]), 3.0).is_none());
    }
}
