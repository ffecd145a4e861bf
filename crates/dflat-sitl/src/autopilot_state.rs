//! The state of the SITL's PX4 face shared between its threads: armed,
//! the position setpoint stream to the autopilot, the goal of hold / goto
//! / RTL, the message intervals, home, and the rate limit of refusals.
//! The receive threads write it ([`super::services`]), the plant loop
//! reads it.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dflat_link::refusal::RefusalLimiter;

use super::lock;
use super::position_control::PositionTarget;
use super::px4_face::{GeoOrigin, Streams};
use super::routing::Link;

/// Which setpoint stream flies in OFFBOARD (the latest type wins, as PX4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Flown<C> {
    /// The attitude target (the daemon's SET_ATTITUDE_TARGET).
    Attitude(C),
    /// A position setpoint to the autopilot, flown by its position loop.
    Position(PositionTarget),
}

/// What the SITL's PX4 face shares between threads.
pub(super) struct Px4State {
    /// Armed (HEARTBEAT); disarm is accepted, arm re-arms.
    pub(super) armed: AtomicBool,
    /// The latest position setpoint addressed to the autopilot.
    pub(super) setpoint: Mutex<Option<(Instant, PositionTarget)>>,
    /// Position setpoints accepted.
    pub(super) setpoints_accepted: AtomicU64,
    /// A goal for hold / goto / RTL, taken by the plant loop.
    pub(super) goal: Mutex<Option<[f64; 3]>>,
    /// Stream intervals (SET_MESSAGE_INTERVAL).
    pub(super) streams: Mutex<Streams>,
    /// Refusal texts, per link and reason.
    pub(super) refusals: Mutex<RefusalLimiter<Link>>,
    /// Home: the start point, local NED \[m\].
    pub(super) home: [f64; 3],
    /// The local frame's geodetic origin.
    pub(super) origin: GeoOrigin,
}

impl Px4State {
    /// Armed, home at `home`, default streams.
    pub(super) fn new(home: [f64; 3]) -> Self {
        Self {
            armed: AtomicBool::new(true),
            setpoint: Mutex::new(None),
            setpoints_accepted: AtomicU64::new(0),
            goal: Mutex::new(None),
            streams: Mutex::new(Streams::default()),
            refusals: Mutex::new(RefusalLimiter::default()),
            home,
            origin: GeoOrigin::PX4_SITL,
        }
    }

    /// Whether the vehicle is armed.
    pub(super) fn armed(&self) -> bool {
        self.armed.load(Ordering::Relaxed)
    }

    /// Stores a position setpoint received at `at`.
    pub(super) fn set_setpoint(&self, at: Instant, t: PositionTarget) {
        *lock(&self.setpoint) = Some((at, t));
        self.setpoints_accepted.fetch_add(1, Ordering::Relaxed);
    }

    /// The position setpoint younger than `timeout`, with its arrival.
    pub(super) fn fresh_setpoint(&self, timeout: Duration) -> Option<(Instant, PositionTarget)> {
        (*lock(&self.setpoint)).filter(|(at, _)| at.elapsed() < timeout)
    }
}

/// The stream that flies in OFFBOARD: the one whose latest message is the
/// newer; `both` when both are alive.
pub(super) fn latest_wins<C: Copy>(
    attitude: Option<(Instant, C)>,
    position: Option<(Instant, PositionTarget)>,
) -> (Option<Flown<C>>, bool) {
    match (attitude, position) {
        (Some((ta, c)), Some((tp, p))) => (
            Some(if tp > ta {
                Flown::Position(p)
            } else {
                Flown::Attitude(c)
            }),
            true,
        ),
        (Some((_, c)), None) => (Some(Flown::Attitude(c)), false),
        (None, Some((_, p))) => (Some(Flown::Position(p)), false),
        (None, None) => (None, false),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_latest_setpoint_type_wins() {
        let t0 = Instant::now();
        let t1 = t0 + Duration::from_millis(10);
        let p = PositionTarget::hold([1.0, 0.0, 0.0]);
        assert_eq!(
            latest_wins(Some((t0, 7u8)), Some((t1, p))),
            (Some(Flown::Position(p)), true)
        );
        assert_eq!(
            latest_wins(Some((t1, 7u8)), Some((t0, p))),
            (Some(Flown::Attitude(7)), true)
        );
        assert_eq!(
            latest_wins(None::<(Instant, u8)>, Some((t0, p))),
            (Some(Flown::Position(p)), false)
        );
        assert_eq!(latest_wins(None::<(Instant, u8)>, None), (None, false));
    }
}
