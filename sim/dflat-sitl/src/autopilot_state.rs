//! The state of the SITL's PX4 face, owned by the pure step
//! ([`super::step::SitlCore`]): armed, the position setpoint stream to the
//! autopilot, the message intervals, home, and the rate limit of refusals.
//! Times are seconds on the SITL clock.

use dflat_link::refusal::RefusalLimiter;

use super::links::Link;
use super::position_control::PositionTarget;
use super::px4_face::{GeoOrigin, Streams};

/// Which setpoint stream flies in OFFBOARD (the latest type wins, as PX4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Flown<C> {
    /// The attitude target (the daemon's SET_ATTITUDE_TARGET).
    Attitude(C),
    /// A position setpoint to the autopilot, flown by its position loop.
    Position(PositionTarget),
}

/// The SITL's PX4 face.
pub(super) struct Px4State {
    /// Armed (HEARTBEAT); disarm is accepted, arm re-arms.
    pub(super) armed: bool,
    /// The latest position setpoint addressed to the autopilot, with its
    /// arrival \[s\].
    setpoint: Option<(f64, PositionTarget)>,
    /// Position setpoints accepted.
    pub(super) setpoints_accepted: u64,
    /// Stream intervals (SET_MESSAGE_INTERVAL).
    pub(super) streams: Streams,
    /// Refusal texts, per link and reason.
    pub(super) refusals: RefusalLimiter<Link>,
    /// Home: the start point, local NED \[m\].
    pub(super) home: [f64; 3],
    /// The local frame's geodetic origin.
    pub(super) origin: GeoOrigin,
}

impl Px4State {
    /// Armed, home at `home`, default streams.
    pub(super) fn new(home: [f64; 3]) -> Self {
        Self {
            armed: true,
            setpoint: None,
            setpoints_accepted: 0,
            streams: Streams::default(),
            refusals: RefusalLimiter::default(),
            home,
            origin: GeoOrigin::PX4_SITL,
        }
    }

    /// Stores a position setpoint received at `at` \[s\].
    pub(super) fn set_setpoint(&mut self, at: f64, t: PositionTarget) {
        self.setpoint = Some((at, t));
        self.setpoints_accepted += 1;
    }

    /// The position setpoint younger than `timeout` \[s\] at `now` \[s\],
    /// with its arrival.
    pub(super) fn fresh_setpoint(&self, now: f64, timeout: f64) -> Option<(f64, PositionTarget)> {
        self.setpoint.filter(|(at, _)| now - at < timeout)
    }
}

/// The stream that flies in OFFBOARD: the one whose latest message is the
/// newer; `both` when both are alive.
pub(super) fn latest_wins<C: Copy>(
    attitude: Option<(f64, C)>,
    position: Option<(f64, PositionTarget)>,
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
        let t0 = 1.0;
        let t1 = t0 + 0.01;
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
            latest_wins(None::<(f64, u8)>, Some((t0, p))),
            (Some(Flown::Position(p)), false)
        );
        assert_eq!(latest_wins(None::<(f64, u8)>, None), (None, false));
    }
}
