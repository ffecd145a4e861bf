//! A failsafe entered while engaged leaves a level command in the
//! autopilot, not the last tilt.
//!
//! When pose goes stale (or the autopilot falls silent, or the model
//! residual trips) while the autopilot applies our commands, going silent
//! at once would leave the last command — possibly a steep tilt — in force
//! for the autopilot's own offboard-loss timeout (PX4 `COM_OF_LOSS_T`,
//! ArduPilot `GUID_TIMEOUT`): the vehicle keeps accelerating. Instead the
//! daemon streams, for at most `safety.level_hover_max_ms`, first a short
//! **brake** and then **level attitude** at hover thrust (yaw kept), and
//! then stops the stream; the autopilot holds the level command until its
//! timeout and takes over a vehicle that is not accelerating.
//!
//! Level alone is not enough: by the time pose is declared stale
//! (`safety.pose_timeout_ms`) the vehicle has flown that long at the old
//! tilt, and the attitude loop's lag (τ) adds the same tilt for another τ
//! after the level command — at 17° and τ = 0.2 s, 0.9 m/s gained. The
//! brake cancels that gain: from the autopilot's ATTITUDE since the newest
//! pose, the tilt integral ∫θ dt (proportional to the velocity gained,
//! g·∫θ dt, small angles) and the attitude now θ₀, the first-order attitude
//! model (θ̇ = (k̃·θ_cmd − θ)/τ) gives, for a command c held for T and then
//! level, a further ∫θ dt = k̃·c·T + θ₀·τ — exactly, whatever T and τ
//! ([`brake_command`]). c is chosen to bring the total to zero, so the
//! vehicle ends at the velocity it had when the last pose arrived. If
//! ATTITUDE stopped with the pose, its newest sample is held for the
//! integral; without any ATTITUDE the brake is skipped (level only). Pose
//! returning in the meantime ends it (the supervisor leaves `Failsafe`).
//! A control failsafe (`ControlFailed`) has already streamed its level
//! hover (`tick/exit.rs`) and is not levelled twice.
//!
//! This module holds the brake's math; when a failsafe levels, for how
//! long and what happens next is the failsafe machine's
//! (`tick/failsafe.rs`), carried out in `tick/ladder.rs`.

/// The braking time the brake aims for \[s\] (longer if the tilt limit
/// needs it, at most half of `safety.level_hover_max_ms`).
pub const BRAKE_TIME: f64 = 0.3;

/// The brake that cancels the velocity gained since the last pose (see
/// the module docs): `integral` ∫(pitch, roll) dt since that pose \[rad·s\],
/// `attitude` (pitch, roll) now \[rad\], the attitude model's `tau` \[s\]
/// and gain `k`, the largest brake tilt \[rad\] and time \[s\]. Returns the
/// command (pitch, roll) \[rad\] and how long to hold it \[s\] (one axis
/// at a time is exact; the tilt limit bounds the pair's norm). `None` when
/// there is nothing to brake or an input is not finite.
pub fn brake_command(
    integral: [f64; 2],
    attitude: [f64; 2],
    tau: f64,
    k: f64,
    max_tilt: f64,
    max_time: f64,
) -> Option<([f64; 2], f64)> {
    let inputs = [integral[0], integral[1], attitude[0], attitude[1], tau, k];
    if !inputs.iter().all(|v| v.is_finite()) || k <= 0.0 || max_tilt <= 0.0 || max_time <= 0.0 {
        return None;
    }
    // The ∫θ dt still to cancel, per axis.
    let need = [
        integral[0] + attitude[0] * tau,
        integral[1] + attitude[1] * tau,
    ];
    let size = need[0].hypot(need[1]);
    if size < 1e-6 {
        return None;
    }
    // k̃·c·T = −need: the shortest T with |c| within the limit, at least
    // BRAKE_TIME, at most max_time (then the brake is partial).
    let time = (size / (k * max_tilt)).max(BRAKE_TIME).min(max_time);
    let scale = -1.0 / (k * time);
    let mut c = [need[0] * scale, need[1] * scale];
    let tilt = c[0].hypot(c[1]);
    if tilt > max_tilt {
        c = [c[0] * max_tilt / tilt, c[1] * max_tilt / tilt];
    }
    Some((c, time))
}

/// The autopilot's attitude integrated since the newest pose (the brake's
/// estimate of the velocity gained since then).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(super) struct TiltSincePose {
    /// Arrival of the newest pose \[s\].
    since: Option<f64>,
    /// The newest ATTITUDE: arrival \[s\], (pitch, roll) \[rad\].
    last: Option<(f64, [f64; 2])>,
    /// ∫(pitch, roll) dt from `since` to `last` \[rad·s\].
    integral: [f64; 2],
}

impl TiltSincePose {
    /// A pose arrived: the integral starts again.
    pub(super) fn on_pose(&mut self, arrival: f64) {
        if self.since.is_none_or(|s| arrival >= s) {
            self.since = Some(arrival);
            self.integral = [0.0; 2];
        }
    }

    /// An ATTITUDE arrived (trapezoids between samples, from the pose on).
    pub(super) fn on_attitude(&mut self, arrival: f64, attitude: [f64; 2]) {
        if !attitude.iter().all(|a| a.is_finite()) {
            return;
        }
        if let (Some(since), Some((t0, a0))) = (self.since, self.last) {
            let from = t0.max(since);
            if arrival > from {
                let dt = arrival - from;
                for (acc, (a, b)) in self.integral.iter_mut().zip(a0.iter().zip(attitude)) {
                    *acc += 0.5 * (a + b) * dt;
                }
            }
        }
        if self.last.is_none_or(|(t, _)| arrival >= t) {
            self.last = Some((arrival, attitude));
        }
    }

    /// The integral up to `t` (the newest attitude held) and the newest
    /// attitude; `None` without a pose or an attitude.
    pub(super) fn at(&self, t: f64) -> Option<([f64; 2], [f64; 2])> {
        let since = self.since?;
        let (t0, a) = self.last?;
        let dt = (t - t0.max(since)).max(0.0);
        Some((
            [self.integral[0] + a[0] * dt, self.integral[1] + a[1] * dt],
            a,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫θ dt of the first-order attitude model from `theta0` under
    /// command `c` for `time`, then 0, until it has settled (fine Euler).
    fn simulated_integral(theta0: f64, c: f64, time: f64, tau: f64, k: f64) -> f64 {
        let h = 1e-5;
        let (mut theta, mut integral, mut t) = (theta0, 0.0, 0.0);
        while t < time + 20.0 * tau {
            let cmd = if t < time { c } else { 0.0 };
            integral += theta * h;
            theta += h * (k * cmd - theta) / tau;
            t += h;
        }
        integral
    }

    #[test]
    fn the_brake_cancels_the_tilt_integral_under_the_attitude_model() {
        for (integral, attitude, tau, k) in [
            ([0.03, 0.0], [0.3, 0.0], 0.2, 1.0),
            ([-0.01, 0.02], [-0.1, 0.2], 0.12, 0.8),
            ([0.0, -0.05], [0.0, -0.35], 0.35, 1.1),
        ] {
            let max_tilt = 35f64.to_radians();
            let (c, time) = brake_command(integral, attitude, tau, k, max_tilt, 0.5).unwrap();
            assert!(c[0].hypot(c[1]) <= max_tilt + 1e-12);
            assert!((BRAKE_TIME..=0.5).contains(&time));
            for (axis, ((theta0, cmd), before)) in attitude.iter().zip(c).zip(integral).enumerate()
            {
                let total = before + simulated_integral(*theta0, cmd, time, tau, k);
                assert!(total.abs() < 1e-3, "axis {axis}: ∫θ dt left {total}");
            }
        }
        // Nothing to brake; bad inputs.
        assert!(brake_command([0.0; 2], [0.0; 2], 0.2, 1.0, 0.6, 0.5).is_none());
        assert!(brake_command([f64::NAN, 0.0], [0.0; 2], 0.2, 1.0, 0.6, 0.5).is_none());
        // A limit too tight for the time: the tilt is capped (partial brake).
        let (c, time) = brake_command([0.5, 0.0], [0.3, 0.0], 0.2, 1.0, 0.2, 0.5).unwrap();
        assert_eq!(time, 0.5);
        assert!((c[0] + 0.2).abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn the_tilt_integral_runs_from_the_newest_pose() {
        let mut s = TiltSincePose::default();
        assert!(s.at(1.0).is_none());
        s.on_attitude(0.0, [0.2, 0.0]);
        s.on_pose(0.0);
        s.on_attitude(0.1, [0.2, -0.1]);
        let (i, a) = s.at(0.2).unwrap();
        // 0.1 s trapezoid (0.2 / −0.05 mean) + 0.1 s held at the newest.
        assert!(
            (i[0] - 0.04).abs() < 1e-12 && (i[1] + 0.015).abs() < 1e-12,
            "{i:?}"
        );
        assert_eq!(a, [0.2, -0.1]);
        s.on_pose(0.15);
        let (i, _) = s.at(0.25).unwrap();
        assert!((i[0] - 0.02).abs() < 1e-12, "{i:?}");
    }
}
