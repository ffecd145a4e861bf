//! Reference generation: setpoint, path progress, corners, end hold,
//! monotone progress, closest point, the named paths and validation.

use dflat_control::reference::{Reference, paths};
use dflat_control::{ControlError, ReferenceSource};
use nalgebra::Vector3;

const DT: f64 = 0.02;

fn v(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

fn close(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64) -> bool {
    (a - b).norm() <= tol
}

fn field_of(e: ControlError) -> &'static str {
    match e {
        ControlError::InvalidSetting { field, .. } => field,
        other => panic!("expected InvalidSetting, got {other:?}"),
    }
}

#[test]
fn reference_setpoint_is_constant() {
    let p = v(1.0, -2.0, -10.0);
    let mut r = Reference::setpoint(p).unwrap();
    let mut out = [Vector3::zeros(); 5];
    r.horizon(&v(50.0, 3.0, 0.0), DT, &mut out);
    assert_eq!(out, [p; 5]);
    assert_eq!(r.closest(&v(9.0, 9.0, 9.0)), (p, Vector3::zeros()));
    assert!(!r.is_finished());
    assert_eq!((r.progress(), r.path_length()), (0.0, 0.0));
    assert!((r.distance_to_path(&v(4.0, 2.0, -10.0)) - 5.0).abs() < 1e-12);
}

#[test]
fn reference_closest_point_and_velocity_on_a_segment() {
    let mut r = Reference::path(&[v(0.0, 0.0, -5.0), v(10.0, 0.0, -5.0)], 2.0).unwrap();
    let (p, vel) = r.closest(&v(3.0, 4.0, -5.0));
    assert!(close(&p, &v(3.0, 0.0, -5.0), 1e-12));
    assert!(close(&vel, &v(2.0, 0.0, 0.0), 1e-12));
    assert!((r.progress() - 3.0).abs() < 1e-12);
    assert!((r.distance_to_path(&v(3.0, 4.0, -5.0)) - 4.0).abs() < 1e-12);
    // Before the start: the start, moving.
    let mut r2 = Reference::path(&[v(0.0, 0.0, -5.0), v(10.0, 0.0, -5.0)], 2.0).unwrap();
    let (p, vel) = r2.closest(&v(-3.0, 1.0, -5.0));
    assert_eq!(p, v(0.0, 0.0, -5.0));
    assert_eq!(vel, v(2.0, 0.0, 0.0));
}

#[test]
fn reference_horizon_advances_along_the_path_across_corners() {
    // L path: 20 m north, then 30 m east (NED at 10 m altitude).
    // A wide look-ahead so the first call finds the point near the corner.
    let mut r = paths::l(-10.0, 5.0).unwrap().with_lookahead(100.0).unwrap();
    assert!((r.path_length() - 50.0).abs() < 1e-12);
    // Measured 1 m before the corner (and 0.5 m off): closest (−1, −30).
    let mut out = [Vector3::zeros(); 51];
    r.horizon(&v(-1.0, -30.5, -10.0), DT, &mut out);
    assert!(close(&out[0], &v(-1.0, -30.0, -10.0), 1e-12));
    // δt·speed = 0.1 m per step: the corner at j = 10, then east.
    assert!(close(&out[5], &v(-0.5, -30.0, -10.0), 1e-12));
    assert!(close(&out[10], &v(0.0, -30.0, -10.0), 1e-12));
    assert!(close(&out[15], &v(0.0, -29.5, -10.0), 1e-12));
    assert!(close(&out[50], &v(0.0, -26.0, -10.0), 1e-12));
    // Every step is δt·speed of arc length, the corner step included.
    for j in 1..out.len() {
        let d = (out[j] - out[j - 1]).norm();
        assert!(
            (d - 0.1).abs() < 1e-9 || j == 10 || j == 11,
            "step {j}: {d}"
        );
    }
    // Reference velocity: along the first leg before the corner, the
    // second leg's direction at and after it.
    let (_, vel) = r.closest(&v(-1.0, -30.5, -10.0));
    assert!(close(&vel, &v(5.0, 0.0, 0.0), 1e-12));
    let (p, vel) = r.closest(&v(0.0, -30.0, -10.0));
    assert!(close(&p, &v(0.0, -30.0, -10.0), 1e-12));
    assert!(close(&vel, &v(0.0, 5.0, 0.0), 1e-12));
}

#[test]
fn reference_holds_at_the_path_end() {
    let mut r = Reference::path(&[v(0.0, 0.0, 0.0), v(3.0, 4.0, 0.0)], 10.0).unwrap();
    let mut out = [Vector3::zeros(); 100];
    r.horizon(&v(2.4, 3.2, 0.0), DT, &mut out);
    assert!((r.progress() - 4.0).abs() < 1e-12);
    assert!(!r.is_finished());
    // 1 m left at 0.2 m per step: the end from j = 5 on.
    for o in &out[5..] {
        assert!(close(o, &v(3.0, 4.0, 0.0), 1e-12));
    }
    // Past the end: finished, the end point, zero velocity.
    let (p, vel) = r.closest(&v(6.0, 8.0, 0.0));
    assert!(close(&p, &v(3.0, 4.0, 0.0), 1e-12));
    assert_eq!(vel, Vector3::zeros());
    assert!(r.is_finished());
    r.horizon(&v(6.0, 8.0, 0.0), DT, &mut out);
    assert!(out.iter().all(|o| close(o, &v(3.0, 4.0, 0.0), 1e-12)));
}

#[test]
fn reference_progress_is_monotone() {
    let mut r = Reference::path(&[v(0.0, 0.0, 0.0), v(10.0, 0.0, 0.0)], 1.0).unwrap();
    r.closest(&v(4.0, 0.0, 0.0));
    assert!((r.progress() - 4.0).abs() < 1e-12);
    // Measured behind: the reference stays where it was.
    let (p, _) = r.closest(&v(1.0, 0.0, 0.0));
    assert!((r.progress() - 4.0).abs() < 1e-12);
    assert!(close(&p, &v(4.0, 0.0, 0.0), 1e-12));
    // Non-finite measurement: unchanged.
    r.closest(&v(f64::NAN, 0.0, 0.0));
    assert!((r.progress() - 4.0).abs() < 1e-12);
    r.reset();
    assert_eq!(r.progress(), 0.0);
}

#[test]
fn reference_does_not_grab_a_later_leg_early() {
    // S-like path whose third leg passes 2 m from the first leg's start.
    let w = [
        v(0.0, 0.0, 0.0),
        v(0.0, 20.0, 0.0),
        v(2.0, 20.0, 0.0),
        v(2.0, 0.0, 0.0),
    ];
    let mut r = Reference::path(&w, 3.0).unwrap();
    // Near the start, slightly toward the third leg: still the first leg.
    let (p, vel) = r.closest(&v(1.2, 0.5, 0.0));
    assert!(close(&p, &v(0.0, 0.5, 0.0), 1e-12), "{p}");
    assert!(close(&vel, &v(0.0, 3.0, 0.0), 1e-12));
    // Whereas the pure distance metric sees the third leg.
    assert!((r.distance_to_path(&v(1.2, 0.5, 0.0)) - 0.8).abs() < 1e-12);
    // Walking along the first leg (0.6 m off it, 1.4 m from the third),
    // progress tracks without jumping ahead to the third leg.
    let mut last = r.progress();
    for i in 1..=38 {
        let y = 0.5 * i as f64;
        r.closest(&v(0.6, y, 0.0));
        assert!(r.progress() >= last);
        assert!(
            r.progress() <= y + 1e-9,
            "jumped to {} at y = {y}",
            r.progress()
        );
        last = r.progress();
    }
    // Around the U-turn and down the third leg.
    r.closest(&v(2.0, 19.0, 0.0));
    assert!(r.progress() > 22.0, "{}", r.progress());
    for y in (11..=18).rev() {
        r.closest(&v(2.5, y as f64, 0.0));
    }
    let (p, vel) = r.closest(&v(2.5, 10.0, 0.0));
    assert!(close(&p, &v(2.0, 10.0, 0.0), 1e-12));
    assert!(close(&vel, &v(0.0, -3.0, 0.0), 1e-12));
}

#[test]
fn reference_lookahead_bounds_the_search() {
    let w = [v(0.0, 0.0, 0.0), v(100.0, 0.0, 0.0)];
    let mut r = Reference::path(&w, 1.0)
        .unwrap()
        .with_lookahead(2.0)
        .unwrap();
    r.closest(&v(50.0, 0.0, 0.0));
    assert!((r.progress() - 2.0).abs() < 1e-12);
    r.closest(&v(50.0, 0.0, 0.0));
    assert!((r.progress() - 4.0).abs() < 1e-12);
    // Default: max(5 m, 1 s · speed).
    let mut r = Reference::path(&w, 8.0).unwrap();
    r.closest(&v(50.0, 0.0, 0.0));
    assert!((r.progress() - 8.0).abs() < 1e-12);
}

#[test]
fn reference_distance_to_path_uses_the_whole_polyline() {
    let r = paths::l(0.0, 3.0).unwrap();
    assert!((r.distance_to_path(&v(-10.0, -28.0, 0.0)) - 2.0).abs() < 1e-12);
    assert!((r.distance_to_path(&v(1.0, -10.0, 0.0)) - 1.0).abs() < 1e-12);
    // Outside the corner: distance to the corner point.
    assert!((r.distance_to_path(&v(3.0, -34.0, 0.0)) - 5.0).abs() < 1e-12);
    assert_eq!(r.distance_to_path(&v(0.0, -30.0, 0.0)), 0.0);
}

#[test]
fn reference_named_paths() {
    let l = paths::waypoints(&paths::L_XY, -10.0);
    assert_eq!(
        l,
        vec![
            v(-20.0, -30.0, -10.0),
            v(0.0, -30.0, -10.0),
            v(0.0, 0.0, -10.0)
        ]
    );
    for (r, speed) in [
        (paths::d(-20.0, paths::D_SPEED).unwrap(), 10.0),
        (paths::s(-20.0, paths::S_SPEED).unwrap(), 3.0),
        (paths::dsl_l(-20.0, paths::DSL_L_SPEED).unwrap(), 8.0),
        (paths::l(-10.0, 9.0).unwrap(), 9.0),
    ] {
        assert_eq!(r.speed(), speed);
        assert!(
            r.path_length() > 40.0 && r.path_length() < 120.0,
            "{}",
            r.path_length()
        );
    }
    // The D bowl is a polyline on a 15 m circle.
    for p in &paths::D_XY[2..9] {
        let d = ((p[0] - 15.0).powi(2) + (p[1] - 5.0).powi(2)).sqrt();
        assert!((d - 15.0).abs() < 1e-9);
    }
    // Flying each letter's horizon from its start ends at its end.
    for mut r in [
        paths::d(-20.0, 10.0).unwrap(),
        paths::s(-20.0, 3.0).unwrap(),
        paths::dsl_l(-20.0, 8.0).unwrap(),
    ] {
        let mut out = [Vector3::zeros(); 2];
        let mut y = {
            r.horizon(&Vector3::new(f64::NAN, 0.0, 0.0), DT, &mut out);
            out[0]
        };
        for _ in 0..10_000 {
            r.horizon(&y, DT, &mut out);
            y = out[1];
        }
        assert!(
            r.is_finished(),
            "progress {} of {}",
            r.progress(),
            r.path_length()
        );
    }
}

#[test]
fn reference_validation_names_the_field() {
    let a = v(0.0, 0.0, 0.0);
    let b = v(1.0, 0.0, 0.0);
    assert_eq!(
        field_of(Reference::setpoint(v(f64::NAN, 0.0, 0.0)).unwrap_err()),
        "setpoint"
    );
    assert_eq!(
        field_of(Reference::path(&[a], 1.0).unwrap_err()),
        "waypoints"
    );
    assert_eq!(
        field_of(Reference::path(&[], 1.0).unwrap_err()),
        "waypoints"
    );
    assert_eq!(
        field_of(Reference::path(&[a, a, b], 1.0).unwrap_err()),
        "waypoints"
    );
    assert_eq!(
        field_of(Reference::path(&[a, v(f64::INFINITY, 0.0, 0.0)], 1.0).unwrap_err()),
        "waypoints"
    );
    assert_eq!(
        field_of(Reference::path(&[a, b], 0.0).unwrap_err()),
        "speed"
    );
    assert_eq!(
        field_of(Reference::path(&[a, b], f64::NAN).unwrap_err()),
        "speed"
    );
    let r = Reference::path(&[a, b], 1.0).unwrap();
    assert_eq!(field_of(r.with_lookahead(-1.0).unwrap_err()), "lookahead");
    // A closed path (end = start, not consecutive) is fine.
    assert!(Reference::path(&[a, b, v(1.0, 1.0, 0.0), a], 1.0).is_ok());
}

#[test]
fn braking_follows_the_deceleration_profile_to_the_stop_point() {
    // 2 m/s north at 4 m/s²: stops 0.5 m on, after 0.5 s.
    let start = v(1.0, 2.0, -10.0);
    let mut r = Reference::braking(start, v(2.0, 0.0, 0.0), 4.0, 0.0).unwrap();
    assert!((r.path_length() - 0.5).abs() < 1e-12);
    assert!(!r.is_finished());
    let mut out = [Vector3::zeros(); 40];
    r.horizon(&start, DT, &mut out);
    assert_eq!(out[0], start);
    for (j, o) in out.iter().enumerate() {
        let t = (j as f64 * DT).min(0.5);
        let s = 2.0 * t - 0.5 * 4.0 * t * t;
        assert!(close(o, &v(1.0 + s, 2.0, -10.0), 1e-12), "step {j}: {o:?}");
    }
    assert!(close(&out[39], &v(1.5, 2.0, -10.0), 1e-12));
    // The reference velocity at the closest point is the profile's.
    let (p, vel) = r.closest(&v(1.375, 2.3, -10.0));
    assert!(close(&p, &v(1.375, 2.0, -10.0), 1e-12));
    assert!(close(&vel, &v(1.0, 0.0, 0.0), 1e-12), "{vel:?}");
    // Never backwards; at the end it holds the stop point.
    let (p, _) = r.closest(&v(0.0, 2.0, -10.0));
    assert!(close(&p, &v(1.375, 2.0, -10.0), 1e-12));
    r.horizon(&v(1.5, 2.1, -10.0), DT, &mut out);
    assert!(out.iter().all(|o| close(o, &v(1.5, 2.0, -10.0), 1e-12)));
    assert!((r.progress() - 0.5).abs() < 1e-12);
    assert!((r.distance_to_path(&v(1.2, 3.0, -10.0)) - 1.0).abs() < 1e-12);
    // A vehicle past the stop point moves the stop on: not flown back.
    r.horizon(&v(1.7, 2.0, -10.0), DT, &mut out);
    assert!(out.iter().all(|o| close(o, &v(1.7, 2.0, -10.0), 1e-12)));
    assert!((r.path_length() - 0.7).abs() < 1e-12);
    // At most one more stopping distance: a vehicle drifting on (a thrust
    // offset along the braking direction) is flown back to 1.0 m on.
    r.horizon(&v(6.0, 2.0, -10.0), DT, &mut out);
    assert!((r.path_length() - 1.0).abs() < 1e-12);
    assert!(
        out.iter().all(|o| close(o, &v(2.0, 2.0, -10.0), 1e-12)),
        "{:?}",
        out[0]
    );
}

#[test]
fn braking_coasts_for_the_lag_first() {
    // 2 m/s, 0.2 s of lag (0.4 m), then 4 m/s² (0.5 m): 0.9 m.
    let start = v(0.0, 0.0, -10.0);
    let mut r = Reference::braking(start, v(0.0, -2.0, 0.0), 4.0, 0.2).unwrap();
    assert!((r.path_length() - 0.9).abs() < 1e-12);
    let mut out = [Vector3::zeros(); 60];
    r.horizon(&start, DT, &mut out);
    for (j, o) in out.iter().enumerate() {
        let t = j as f64 * DT;
        let s = if t <= 0.2 {
            2.0 * t
        } else {
            let tb = (t - 0.2).min(0.5);
            0.4 + 2.0 * tb - 2.0 * tb * tb
        };
        assert!(
            close(o, &v(0.0, -s, -10.0), 1e-12),
            "step {j}: {o:?} vs {s}"
        );
    }
    // From the middle of the coast: the rest of it (0.05 s), then the
    // braking: 0.1 s on, 0.4 + 2·0.05 − 2·0.05² = 0.495 m.
    r.horizon(&v(0.0, -0.3, -10.0), DT, &mut out);
    assert!(
        close(&out[5], &v(0.0, -0.495, -10.0), 1e-12),
        "{:?}",
        out[5]
    );
    let (_, vel) = r.closest(&v(0.0, -0.65, -10.0));
    // 0.25 m into the braking: v² = 4 − 2·4·0.25 = 2.
    assert!(close(&vel, &v(0.0, -(2f64.sqrt()), 0.0), 1e-12), "{vel:?}");
}

#[test]
fn braking_at_rest_is_a_setpoint_and_bad_input_is_refused() {
    let p = v(1.0, 2.0, -3.0);
    let r = Reference::braking(p, Vector3::zeros(), 4.0, 0.2).unwrap();
    assert_eq!(r, Reference::setpoint(p).unwrap());
    for (start, vel, a, lag) in [
        (v(f64::NAN, 0.0, 0.0), v(1.0, 0.0, 0.0), 4.0, 0.0),
        (p, v(1.0, f64::INFINITY, 0.0), 4.0, 0.0),
        (p, v(1.0, 0.0, 0.0), 0.0, 0.0),
        (p, v(1.0, 0.0, 0.0), f64::NAN, 0.0),
        (p, v(1.0, 0.0, 0.0), 4.0, -0.1),
    ] {
        assert_eq!(
            field_of(Reference::braking(start, vel, a, lag).unwrap_err()),
            "braking"
        );
    }
}

#[test]
fn a_ramped_path_starts_without_a_step_in_acceleration() {
    // 5 m/s with a 2.5 m/s² peak: T = π·5/(2·2.5) = π s.
    let w = [v(0.0, 0.0, -10.0), v(100.0, 0.0, -10.0)];
    let mut r = Reference::path(&w, 5.0)
        .unwrap()
        .with_ramp(0.0, 2.5)
        .unwrap();
    let mut out = [Vector3::zeros(); 400];
    r.horizon(&w[0], DT, &mut out);
    // Second differences: the reference acceleration, starting at 0,
    // never above the peak, and 0 once at speed.
    let acc: Vec<f64> = out
        .windows(3)
        .map(|t| (t[2].x - 2.0 * t[1].x + t[0].x) / (DT * DT))
        .collect();
    assert!(acc[0].abs() < 0.05, "{}", acc[0]);
    assert!(acc.iter().all(|a| *a <= 2.5 + 1e-6 && *a >= -1e-6));
    assert!(acc[200..].iter().all(|a| a.abs() < 1e-6));
    // After the ramp: 5 m/s, having covered V·T/2.
    let t_end = std::f64::consts::PI;
    let j = (t_end / DT).ceil() as usize + 1;
    let speed = (out[j + 1].x - out[j].x) / DT;
    assert!((speed - 5.0).abs() < 1e-9, "{speed}");
    let ramp_dist = 5.0 * t_end / 2.0;
    let expected = ramp_dist + 5.0 * (j as f64 * DT - t_end);
    assert!(
        (out[j].x - expected).abs() < 1e-9,
        "{} vs {expected}",
        out[j].x
    );
    // Time goes on per call: the reference velocity rises.
    let (_, v0) = r.closest(&w[0]);
    assert!(v0.x > 0.0 && v0.x < 0.01, "{v0:?}");
    for _ in 0..200 {
        r.horizon(&w[0], DT, &mut out);
    }
    let (_, v1) = r.closest(&w[0]);
    assert!((v1.x - 5.0).abs() < 1e-9, "{v1:?}");
    assert!(
        Reference::path(&w, 5.0)
            .unwrap()
            .with_ramp(0.0, 0.0)
            .is_err()
    );
}

#[test]
fn seek_resumes_from_the_closest_point_of_the_whole_path() {
    let w = [
        v(-20.0, -30.0, -10.0),
        v(0.0, -30.0, -10.0),
        v(0.0, 0.0, -10.0),
    ];
    let mut r = Reference::path(&w, 5.0).unwrap();
    // 1.7 m past the corner, a little east: on the second leg.
    r.seek(&v(1.7, -29.6, -10.0));
    assert!((r.progress() - 20.4).abs() < 1e-9, "{}", r.progress());
    let (p, vel) = r.closest(&v(1.7, -29.6, -10.0));
    assert!(close(&p, &v(0.0, -29.6, -10.0), 1e-9));
    assert!(close(&vel, &v(0.0, 5.0, 0.0), 1e-9));
    // Without seek the search looks 5 m ahead of the start only.
    let mut fresh = Reference::path(&w, 5.0).unwrap();
    let (p, _) = fresh.closest(&v(1.7, -29.6, -10.0));
    assert!(p.x < -14.0, "{p:?}");
    r.seek(&v(f64::NAN, 0.0, 0.0));
    assert!((r.progress() - 20.4).abs() < 1e-9);
}

#[test]
fn corner_speed_rounds_each_corner_at_its_radius_and_stops_at_the_end() {
    // North 20 m, then east 30 m (90°), then back west 10 m (180°).
    let pts = [
        v(0.0, 0.0, -5.0),
        v(20.0, 0.0, -5.0),
        v(20.0, 30.0, -5.0),
        v(20.0, 20.0, -5.0),
    ];
    let (r, a) = (1.0, 3.0);
    let mut path = Reference::path(&pts, 5.0).unwrap();
    // Walks the vehicle to `q` in 0.5 m steps from the closest point (the
    // progress search looks only a few metres ahead).
    let limit = |path: &mut Reference, q: Vector3<f64>| {
        let from = path.closest(&q).0;
        let steps = ((q - from).norm() / 0.5).ceil().max(1.0) as usize;
        for i in 1..=steps {
            path.closest(&(from + (q - from) * (i as f64 / steps as f64)));
        }
        path.corner_speed(r, a).unwrap().0
    };
    // At the start, the 90° corner 20 m ahead: √(a·r·cot 45° + 2·a·20).
    let want = (a * r + 2.0 * a * 20.0).sqrt();
    assert!((limit(&mut path, v(0.0, 0.0, -5.0)) - want).abs() < 1e-9);
    // At the 90° corner: √(a·r) (the arc of radius r·cot 45° = r).
    assert!((limit(&mut path, v(20.0, 0.0, -5.0)) - (a * r).sqrt()).abs() < 1e-9);
    // 2 m past it the speed has risen as from the corner speed, at +a.
    let want = (a * r + 2.0 * a * 2.0).sqrt();
    assert!((limit(&mut path, v(20.0, 2.0, -5.0)) - want).abs() < 1e-9);
    assert_eq!(path.corner_speed(r, a).unwrap().1, a);
    // Nearer the reversal ahead than the corner behind: braking, at −a.
    limit(&mut path, v(20.0, 25.0, -5.0));
    assert_eq!(path.corner_speed(r, a).unwrap().1, -a);
    // Approaching the reversal (cot 90° = 0): the speed falls to 0 there.
    let want = (2.0 * a * 1.0).sqrt();
    assert!((limit(&mut path, v(20.0, 29.0, -5.0)) - want).abs() < 1e-9);
    // The end is a stop.
    assert!(limit(&mut path, v(20.0, 20.0, -5.0)).abs() < 1e-9);
    // A shallow corner (deflection 30°) is taken faster than a right angle.
    let mut shallow = Reference::path(
        &[
            v(0.0, 0.0, -5.0),
            v(20.0, 0.0, -5.0),
            v(20.0 + 20.0 * 30f64.to_radians().cos(), 20.0 * 0.5, -5.0),
        ],
        5.0,
    )
    .unwrap();
    let cot15 = 1.0 / 15f64.to_radians().tan();
    let got = limit(&mut shallow, v(20.0, 0.0, -5.0));
    assert!((got - (a * r * cot15).sqrt()).abs() < 1e-9, "{got}");
    // Other references have no such limit, and nonsense has none either.
    let mut setpoint = Reference::setpoint(v(1.0, 2.0, 3.0)).unwrap();
    setpoint.closest(&v(0.0, 0.0, 0.0));
    assert_eq!(setpoint.corner_speed(r, a), None);
    assert_eq!(path.corner_speed(f64::NAN, a), None);
    assert_eq!(path.corner_speed(r, 0.0), None);
}
