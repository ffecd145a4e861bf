//! The trajectory sent ahead: samples stamped in the future are the knots
//! of the reference, flown as sent; a new sample replaces the future from
//! its time on (a replan); the past cannot be rewritten; the heading is
//! interpolated with its rate.

use dflat_control::ReferenceSource;
use dflat_control::reference::{Reference, StreamSample, StreamSettings};
use nalgebra::Vector3;
use proptest::prelude::*;

const DT: f64 = 0.02;

/// A circle of radius `r` at speed `v` from the origin: p, v, a at `t`.
fn circle(r: f64, v: f64, t: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let w = v / r;
    let (s, c) = (w * t).sin_cos();
    (
        Vector3::new(r * s, r * (1.0 - c), -10.0),
        Vector3::new(v * c, v * s, 0.0),
        Vector3::new(-v * w * s, v * w * c, 0.0),
    )
}

fn knot(t: f64, (p, v, a): (Vector3<f64>, Vector3<f64>, Vector3<f64>)) -> StreamSample {
    StreamSample {
        t,
        position: p,
        velocity: Some(v),
        acceleration: Some(a),
        yaw: Some(v.y.atan2(v.x)),
        yaw_rate: None,
    }
}

/// Sends, at `t0`, the knots every `h` up to `ahead` \[s\].
fn send(
    r: &mut Reference,
    t0: f64,
    h: f64,
    ahead: f64,
    f: impl Fn(f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>),
) {
    let n = (ahead / h).round() as usize;
    for k in 0..=n {
        let t = t0 + k as f64 * h;
        r.push_sample(&knot(t, f(t))).unwrap();
    }
}

proptest! {
    /// Within the span sent, the horizon is the trajectory (a circle from
    /// p/v/a knots at 20 Hz: the quintic's error is micrometres), at any
    /// time between knots, batch after batch.
    #[test]
    fn the_future_sent_is_flown_as_sent(
        radius in 3.0f64..30.0,
        speed in 1.0f64..10.0,
        start in 0.0f64..0.05,
    ) {
        let f = |t: f64| circle(radius, speed, t);
        let mut r = Reference::stream(StreamSettings::default(), &knot(0.0, f(0.0))).unwrap();
        let mut out = vec![Vector3::zeros(); 50];
        for batch in 0..10 {
            let t0 = batch as f64 * 0.1;
            r.set_time(t0);
            send(&mut r, t0, 0.05, 1.5, f);
            let now = t0 + start;
            r.set_time(now);
            r.horizon(&Vector3::zeros(), DT, &mut out);
            for (j, p) in out.iter().enumerate() {
                let want = f(now + j as f64 * DT).0;
                prop_assert!((p - want).norm() < 2e-4, "batch {batch}, stage {j}: {p} vs {want}");
            }
        }
    }
}

/// A replan replaces the future from its first sample on: the old future
/// after it is gone, the past before it stays, and the reference is
/// continuous at the seam when the new plan starts on the old one.
#[test]
fn a_replan_replaces_the_future_from_its_time_on() {
    let old = |t: f64| circle(10.0, 5.0, t);
    let new = |t: f64| {
        let (p, v, a) = circle(10.0, 5.0, t);
        // Bends away after t = 1: same point, velocity and acceleration at 1.
        let d = (t - 1.0).max(0.0);
        (
            p + Vector3::new(0.0, 0.0, -d * d * d),
            v + Vector3::new(0.0, 0.0, -3.0 * d * d),
            a + Vector3::new(0.0, 0.0, -6.0 * d),
        )
    };
    let mut r = Reference::stream(StreamSettings::default(), &knot(0.0, old(0.0))).unwrap();
    send(&mut r, 0.0, 0.05, 2.0, old);
    r.set_time(0.5);
    // The replan from t = 1 on.
    send(&mut r, 1.0, 0.05, 1.0, new);
    for k in 0..50 {
        let t = 0.5 + k as f64 * 0.03;
        let p = r.stream_position_at(t).unwrap();
        let want = if t <= 1.0 { old(t).0 } else { new(t).0 };
        assert!((p - want).norm() < 2e-4, "at {t}: {p} vs {want}");
    }
    // Rewriting the past is refused and changes nothing.
    let before = r.clone();
    assert!(r.push_sample(&knot(0.2, old(0.2))).is_err());
    assert_eq!(r, before);
    // So is a sample further ahead than max_ahead_s (10 s).
    assert!(r.push_sample(&knot(11.0, old(11.0))).is_err());
    assert_eq!(r, before);
}

/// Past the end of what was sent, the prediction from the newest sample
/// takes over: a trajectory that ends at rest holds there.
#[test]
fn a_trajectory_that_ends_at_rest_holds_its_end() {
    // A minimum-jerk move of 10 m north in 4 s, sent whole at once.
    let mj = |t: f64| {
        let u = (t / 4.0).clamp(0.0, 1.0);
        let s = 10.0 * (10.0 * u.powi(3) - 15.0 * u.powi(4) + 6.0 * u.powi(5));
        let ds = 10.0 / 4.0 * (30.0 * u * u - 60.0 * u.powi(3) + 30.0 * u.powi(4));
        let dds = 10.0 / 16.0 * (60.0 * u - 180.0 * u * u + 120.0 * u.powi(3));
        (
            Vector3::new(s, 0.0, -10.0),
            Vector3::new(ds, 0.0, 0.0),
            Vector3::new(dds, 0.0, 0.0),
        )
    };
    let mut r = Reference::stream(StreamSettings::default(), &knot(0.0, mj(0.0))).unwrap();
    send(&mut r, 0.0, 0.1, 4.0, mj);
    for k in 0..200 {
        let t = k as f64 * 0.05;
        let p = r.stream_position_at(t).unwrap();
        assert!((p - mj(t).0).norm() < 1e-3, "at {t}: {p}");
    }
    assert!((r.rest_point() - Vector3::new(10.0, 0.0, -10.0)).norm() < 1e-9);
}

/// The heading between samples is interpolated the short way round, and
/// commanded ahead it leads by its rate.
#[test]
fn the_heading_is_interpolated_and_led_by_its_rate() {
    let turn = |t: f64| circle(5.0, 5.0, t); // 1 rad/s
    let mut r = Reference::stream(StreamSettings::default(), &knot(0.0, turn(0.0))).unwrap();
    send(&mut r, 0.0, 0.1, 4.0, turn);
    for k in 0..30 {
        let t = 0.013 + k as f64 * 0.1;
        r.set_time(t);
        let want = |t: f64| {
            let v = turn(t).1;
            v.y.atan2(v.x)
        };
        let (yaw, rate) = r.yaw_reference(0.0).unwrap();
        let wrap = |a: f64| {
            (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
        };
        assert!(
            wrap(yaw - want(t)).abs() < 2e-3,
            "at {t}: {yaw} vs {}",
            want(t)
        );
        assert!((rate - 1.0).abs() < 0.05, "rate {rate}");
        let (ahead, _) = r.yaw_reference(0.1).unwrap();
        assert!(wrap(ahead - want(t + 0.1)).abs() < 2e-3, "ahead at {t}");
    }
}

/// Samples without an acceleration imply it (and the jerk) from their
/// velocities; positions alone (implied velocity) all three from their
/// positions: a circle from 20 Hz p/v samples, or from positions alone,
/// is predicted to millimetres half a second ahead (a straight line
/// would be 0.4 m off).
#[test]
fn samples_imply_what_they_do_not_give() {
    let f = |t: f64| circle(6.0, 4.0, t);
    for (name, velocity, implied) in [("p/v", true, false), ("p", false, true)] {
        let settings = StreamSettings {
            implied_velocity: implied,
            ..StreamSettings::default()
        };
        let sample = |t: f64| {
            let (p, v, _) = f(t);
            StreamSample {
                t,
                position: p,
                velocity: velocity.then_some(v),
                acceleration: None,
                yaw: None,
                yaw_rate: None,
            }
        };
        let mut r = Reference::stream(settings, &sample(0.0)).unwrap();
        for k in 1..=20 {
            r.push_sample(&sample(k as f64 * 0.05)).unwrap();
        }
        let err = (r.stream_position_at(1.5).unwrap() - f(1.5).0).norm();
        assert!(err < 5e-3, "{name}: 0.5 s ahead off by {err} m");
    }
}
