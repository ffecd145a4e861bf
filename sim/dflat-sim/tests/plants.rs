//! Plant tests: steady states, NED signs, RK4 against closed forms, the
//! rigid body's attitude loop, saturation, drag, wind and gusts.

use dflat_control::AttitudeCommand;
use dflat_sim::plant::{
    Integrator, Plant, PlantKind, PlantOptions, PlantState, build_plant, thrust_axis,
};
use nalgebra::Vector3;
use std::f64::consts::FRAC_PI_2;

/// Gravity [m/s²].
const G: f64 = 9.81;

fn close(a: f64, b: f64, tol: f64, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: {a} vs {b} (tol {tol})");
}

const KINDS: [PlantKind; 3] = [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody];

fn plant(kind: PlantKind, o: &PlantOptions) -> Box<dyn Plant> {
    build_plant(kind, o, 7).expect("valid options")
}

fn cmd(pitch: f64, roll: f64, yaw: f64, thrust: f64) -> AttitudeCommand {
    AttitudeCommand {
        pitch,
        roll,
        yaw,
        thrust,
    }
}

fn run(p: &mut dyn Plant, seconds: f64) {
    let steps = (seconds / 0.005).round() as usize;
    for _ in 0..steps {
        p.advance(0.005);
    }
}

#[test]
fn hover_stays_put_for_every_plant() {
    let o = PlantOptions::default();
    let start = PlantState::hover(Vector3::new(1.0, -2.0, -10.0), G);
    for kind in KINDS {
        let mut p = plant(kind, &o);
        p.reset(&start);
        p.apply(&cmd(0.0, 0.0, 0.0, G));
        run(p.as_mut(), 10.0);
        assert!(
            (p.position() - start.position).norm() < 1e-9,
            "{kind:?}: {}",
            p.position()
        );
        assert!(p.velocity().norm() < 1e-9, "{kind:?}");
        let (r, th, y) = p.attitude();
        assert!(
            r.abs() < 1e-12 && th.abs() < 1e-12 && y.abs() < 1e-12,
            "{kind:?}"
        );
        close(p.time(), 10.0, 1e-9, "time");
    }
}

#[test]
fn constant_tilt_gives_constant_ned_acceleration() {
    // Attitude already at the command (k̃ = 1), so it stays constant: then
    // x(t) = ½·a·t² exactly (RK4 is exact for polynomials).
    let o = PlantOptions::default();
    for (pitch, roll, yaw) in [
        (-0.1f64, 0.0f64, 0.0),
        (0.0, 0.15, 0.0),
        (-0.2, 0.1, 0.0),
        (-0.1, 0.0, FRAC_PI_2),
    ] {
        for kind in [PlantKind::Planar, PlantKind::Spatial] {
            let mut p = plant(kind, &o);
            let thrust = G / (pitch.cos() * roll.cos());
            let s = PlantState {
                pitch,
                roll,
                yaw,
                thrust,
                ..PlantState::hover(Vector3::zeros(), G)
            };
            p.reset(&s);
            p.apply(&cmd(pitch, roll, yaw, thrust));
            run(p.as_mut(), 2.0);
            // NED: a = g·e3 − T·R·e3 with T·R33 = g.
            let axis = thrust_axis(roll, pitch, yaw);
            let a = Vector3::new(-G * axis.x / axis.z, -G * axis.y / axis.z, 0.0);
            let expect = a * 0.5 * 4.0;
            assert!(
                (p.position() - expect).norm() < 1e-9,
                "{kind:?} {pitch} {roll}: {} vs {expect}",
                p.position()
            );
            assert!((p.velocity() - a * 2.0).norm() < 1e-9);
        }
    }
    // Signs at ψ = 0: nose down → north, right wing down → east.
    let mut p = plant(PlantKind::Planar, &o);
    p.reset(&PlantState {
        pitch: -0.1,
        ..Default::default()
    });
    p.apply(&cmd(-0.1, 0.0, 0.0, G));
    run(p.as_mut(), 1.0);
    close(p.velocity().x, -G * (-0.1f64).tan(), 1e-9, "ẍ = −g·tanθ");
    assert!(p.velocity().x > 0.0);
    let mut p = plant(PlantKind::Planar, &o);
    p.reset(&PlantState {
        roll: 0.1,
        ..Default::default()
    });
    p.apply(&cmd(0.0, 0.1, 0.0, G));
    run(p.as_mut(), 1.0);
    close(p.velocity().y, G * 0.1f64.tan(), 1e-9, "ÿ = g·tanφ");
    // Yaw 90°: nose down accelerates east.
    let mut p = plant(PlantKind::Planar, &o);
    p.reset(&PlantState {
        pitch: -0.1,
        yaw: FRAC_PI_2,
        ..Default::default()
    });
    p.apply(&cmd(-0.1, 0.0, FRAC_PI_2, G));
    run(p.as_mut(), 1.0);
    assert!(
        p.velocity().y > 0.9 && p.velocity().x.abs() < 1e-9,
        "{}",
        p.velocity()
    );
}

#[test]
fn first_order_attitude_step_matches_closed_form() {
    let o = PlantOptions {
        attitude_tau: 0.25,
        attitude_gain: 0.9,
        ..Default::default()
    };
    let (tc, rc): (f64, f64) = (0.2, -0.3);
    for kind in [PlantKind::Planar, PlantKind::Spatial] {
        let mut p = plant(kind, &o);
        p.reset(&PlantState::default());
        p.apply(&cmd(tc, rc, 0.0, G / ((0.9 * tc).cos() * (0.9 * rc).cos())));
        let mut worst: f64 = 0.0;
        for i in 1..=600 {
            p.advance(0.005);
            let t = i as f64 * 0.005;
            let f = 1.0 - (-t / 0.25).exp();
            let (roll, pitch, _) = p.attitude();
            worst = worst
                .max((pitch - 0.9 * tc * f).abs())
                .max((roll - 0.9 * rc * f).abs());
        }
        assert!(worst <= 1e-8, "{kind:?}: worst {worst:e}");
    }
}

#[test]
fn spatial_thrust_step_matches_closed_form() {
    let o = PlantOptions {
        thrust_tau: 0.05,
        thrust_gain: 1.1,
        mass_factor: 1.2,
        ..Default::default()
    };
    let mut p = plant(PlantKind::Spatial, &o);
    p.reset(&PlantState::default());
    p.apply(&cmd(0.0, 0.0, 0.0, 12.0));
    let k_t = 1.1 / 1.2;
    let mut worst: f64 = 0.0;
    for i in 1..=200 {
        p.advance(0.005);
        let t = i as f64 * 0.005;
        let expect = k_t * 12.0 + (G - k_t * 12.0) * (-t / 0.05).exp();
        worst = worst.max((p.true_state().thrust - expect).abs());
    }
    assert!(worst <= 1e-6, "worst {worst:e}");
    // Hover command under mismatch: g·mass_factor/thrust_gain holds altitude.
    let mut p = plant(PlantKind::Spatial, &o);
    p.reset(&PlantState::default());
    p.apply(&cmd(0.0, 0.0, 0.0, o.thrust_command_for(G)));
    run(p.as_mut(), 5.0);
    assert!(p.position().norm() < 1e-9);
    // The nominal hover command g is too weak for a heavier vehicle: it sinks (z grows, NED).
    let o = PlantOptions {
        mass_factor: 1.2,
        ..Default::default()
    };
    let mut p = plant(PlantKind::Spatial, &o);
    p.reset(&PlantState::default());
    p.apply(&cmd(0.0, 0.0, 0.0, G));
    run(p.as_mut(), 1.0);
    assert!(
        p.position().z > 0.5 && p.velocity().z > 0.0,
        "{}",
        p.position()
    );
}

#[test]
fn rk4_is_far_more_accurate_than_euler() {
    // Attitude step: Euler's error is O(h), RK4's O(h⁴).
    let err = |integrator| {
        let o = PlantOptions {
            integrator,
            ..Default::default()
        };
        let mut p = plant(PlantKind::Planar, &o);
        p.reset(&PlantState::default());
        p.apply(&cmd(0.3, 0.0, 0.0, G));
        run(p.as_mut(), 0.5);
        (p.attitude().1 - 0.3 * (1.0 - (-0.5f64 / 0.2).exp())).abs()
    };
    let (rk4, euler) = (err(Integrator::Rk4), err(Integrator::Euler));
    assert!(rk4 < 1e-9 && euler > 1e-4, "rk4 {rk4:e}, euler {euler:e}");
}

#[test]
fn euler_plant_replays_the_reference_trace() {
    // The reference trace (paper §VI: planar, x only, z-up frame, Euler at
    // 200 Hz, command held 4 steps). Our NED plant with θ_cmd = −u and
    // θ = −θ_zup reproduces x_true tick by tick.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../reference/trace_1d.json");
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {path}: {e} (the repository's reference/)"));
    let json: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    let o = PlantOptions {
        integrator: Integrator::Euler,
        tilt_limit: 80f64.to_radians(),
        ..Default::default()
    };
    for run_name in ["DF_sigma0", "FMPC_sigma0.001"] {
        let ticks = json["runs"][run_name]["ticks"].as_array().expect("ticks");
        let mut p = plant(PlantKind::Planar, &o);
        p.reset(&PlantState::default());
        let mut worst: f64 = 0.0;
        for tick in ticks {
            let x = tick["x_true"].as_array().expect("x_true");
            let x0 = x[0].as_f64().unwrap_or(f64::NAN);
            let x1 = x[1].as_f64().unwrap_or(f64::NAN);
            let th = x[4].as_f64().unwrap_or(f64::NAN);
            let s = p.true_state();
            let scale = 1.0 + x0.abs();
            worst = worst
                .max((s.position.x - x0).abs() / scale)
                .max((s.velocity.x - x1).abs() / scale)
                .max((s.pitch + th).abs());
            let u = tick["u"].as_f64().unwrap_or(f64::NAN);
            p.apply(&cmd(-u, 0.0, 0.0, G));
            for _ in 0..4 {
                p.advance(0.005);
            }
        }
        eprintln!("{run_name}: {} ticks, worst {worst:e}", ticks.len());
        assert!(
            worst < 1e-9,
            "{run_name}: worst relative deviation {worst:e}"
        );
    }
}

#[test]
fn rigid_body_attitude_loop_settles_like_first_order() {
    let o = PlantOptions::default();
    let mut p = plant(PlantKind::RigidBody, &o);
    p.reset(&PlantState::hover(Vector3::new(0.0, 0.0, -20.0), G));
    let (pc, rc, yc): (f64, f64, f64) = (-0.2, 0.15, 0.3);
    p.apply(&cmd(pc, rc, yc, G / (pc.cos() * rc.cos())));
    let mut t63 = None;
    for i in 1..=800 {
        p.advance(0.005);
        let (_, pitch, _) = p.attitude();
        if t63.is_none() && pitch <= 0.632 * pc {
            t63 = Some(i as f64 * 0.005);
        }
    }
    let t63 = t63.expect("reaches 63 %");
    eprintln!("rigid body 63 % rise time {t63} s");
    assert!((0.15..=0.25).contains(&t63), "63 % rise time {t63}");
    let (roll, pitch, yaw) = p.attitude();
    close(pitch, pc, 1e-3, "pitch");
    close(roll, rc, 1e-3, "roll");
    close(yaw, yc, 1e-3, "yaw");
    assert!(p.true_state().body_rates.norm() < 1e-3);
    // Altitude roughly held by the tilt-compensated thrust.
    assert!((p.position().z + 20.0).abs() < 0.5, "{}", p.position());
    // Horizontal acceleration in the commanded direction: north (θ < 0) and east (φ > 0 at ψ small).
    assert!(
        p.velocity().x > 0.0 && p.velocity().y > 0.0,
        "{}",
        p.velocity()
    );
}

/// The autopilot's rate limit: a 20° pitch step under a 30°/s limit slews
/// at that rate (a ramp: 90 % in ~0.68 s), where the unlimited loop gets
/// there in ~0.4 s (τ ≈ 0.18 s) at a peak of ~76°/s.
#[test]
fn rigid_body_rate_limit_slews_a_step_at_the_limit() {
    let limit = 30f64.to_radians();
    let step = -20f64.to_radians();
    let rise = |max_rate: [f64; 3]| {
        let mut o = PlantOptions::default();
        o.rigid.max_rate = max_rate;
        let mut p = plant(PlantKind::RigidBody, &o);
        p.reset(&PlantState::hover(Vector3::new(0.0, 0.0, -20.0), G));
        p.apply(&cmd(step, 0.0, 0.0, G / step.cos()));
        let (mut t90, mut peak_rate) = (None, 0.0f64);
        for i in 1..=600 {
            p.advance(0.005);
            peak_rate = peak_rate.max(p.true_state().body_rates.y.abs());
            if t90.is_none() && p.attitude().1 <= 0.9 * step {
                t90 = Some(i as f64 * 0.005);
            }
        }
        close(p.attitude().1, step, 1e-3, "pitch settles");
        (t90.expect("reaches 90 %"), peak_rate)
    };
    let (free_t90, free_rate) = rise([0.0; 3]);
    let (t90, rate) = rise([limit, limit, 0.0]);
    eprintln!(
        "20° step: unlimited 90 % in {free_t90:.3} s (peak {:.0}°/s); limited to 30°/s: \
         {t90:.3} s (peak {:.1}°/s)",
        free_rate.to_degrees(),
        rate.to_degrees()
    );
    assert!(free_rate > 2.0 * limit, "unlimited peak {free_rate}");
    // The rate loop tracks the clamped setpoint with a small overshoot.
    assert!(
        rate <= 1.05 * limit,
        "limited peak {}°/s",
        rate.to_degrees()
    );
    // 90 % of 20° at 30°/s is 0.6 s, plus the rate loop's rise.
    assert!((0.6..0.75).contains(&t90), "limited 90 % in {t90} s");
    assert!(free_t90 + 0.2 < t90, "{free_t90} vs {t90}");
}

#[test]
fn saturation_clips_tilt_and_thrust() {
    let o = PlantOptions::default();
    for kind in KINDS {
        let mut p = plant(kind, &o);
        p.reset(&PlantState::default());
        p.apply(&cmd(-1.0, 0.2, 0.0, 100.0));
        let a = p.applied_command();
        assert!(p.saturated());
        close(a.pitch, -35f64.to_radians(), 1e-15, "pitch clipped");
        close(a.roll, 0.2, 0.0, "roll kept");
        if kind == PlantKind::Planar {
            // Altitude held by the autopilot: thrust plays no part.
            close(a.thrust, G, 0.0, "planar ignores thrust");
            p.apply(&cmd(0.1, 0.1, 0.0, 1e6));
            assert!(!p.saturated());
        } else {
            close(a.thrust, o.thrust_max, 0.0, "thrust clipped");
            p.apply(&cmd(0.0, 0.0, 0.0, 1e6));
            assert!(p.saturated());
        }
        p.apply(&cmd(0.1, 0.1, 0.0, G));
        assert!(!p.saturated());
        // Non-finite commands are ignored.
        p.apply(&cmd(f64::NAN, 0.0, 0.0, G));
        close(p.applied_command().pitch, 0.1, 0.0, "previous command kept");
    }
}

#[test]
fn drag_and_wind_carry_the_vehicle_at_wind_speed() {
    let o = PlantOptions {
        drag: 0.5,
        wind: [2.0, -1.0, 0.0],
        ..Default::default()
    };
    for kind in KINDS {
        let mut p = plant(kind, &o);
        p.reset(&PlantState::default());
        p.apply(&cmd(0.0, 0.0, 0.0, G));
        run(p.as_mut(), 30.0);
        let v = p.velocity();
        assert!(
            (v - Vector3::new(2.0, -1.0, 0.0)).norm() < 1e-4,
            "{kind:?}: {v}"
        );
    }
}

#[test]
fn gusts_are_seeded_and_have_the_configured_spread() {
    let o = PlantOptions {
        gust_std: [1.0, 0.5, 0.0],
        gust_tau: 0.5,
        ..Default::default()
    };
    let sample = |seed| {
        let mut p = build_plant(PlantKind::Planar, &o, seed).expect("valid");
        p.reset(&PlantState::default());
        (0..200_000)
            .map(|_| {
                p.advance(0.005);
                p.wind()
            })
            .collect::<Vec<_>>()
    };
    let a = sample(3);
    assert_eq!(a, sample(3), "same seed, same gusts");
    assert_ne!(a[..100], sample(4)[..100], "other seed, other gusts");
    let n = a.len() as f64;
    for (axis, sigma) in [(0, 1.0), (1, 0.5)] {
        let mean = a.iter().map(|w| w[axis]).sum::<f64>() / n;
        let var = a.iter().map(|w| (w[axis] - mean).powi(2)).sum::<f64>() / n;
        // 1000 s / 0.5 s correlation time: about 1000 independent samples.
        close(var.sqrt(), sigma, 0.1 * sigma, "gust std");
        close(mean, 0.0, 0.15 * sigma, "gust mean");
    }
    assert!(a.iter().all(|w| w.z == 0.0));
}

#[test]
fn invalid_options_name_the_field() {
    let o = PlantOptions {
        attitude_tau: 0.0,
        ..Default::default()
    };
    let e = build_plant(PlantKind::Planar, &o, 0)
        .err()
        .expect("rejected");
    assert!(e.to_string().contains("attitude_tau"), "{e}");
    let o = PlantOptions {
        tilt_limit: 2.0,
        ..Default::default()
    };
    assert!(o.validate().is_err());
}

#[test]
fn options_round_trip_through_json_with_defaults() {
    let o: PlantOptions =
        serde_json::from_str(r#"{"drag": 0.3, "wind": [1, 0, 0]}"#).expect("parses");
    assert_eq!(o.drag, 0.3);
    assert_eq!(o.plant_dt, 0.005);
    let back: PlantOptions =
        serde_json::from_str(&serde_json::to_string(&o).expect("ser")).expect("de");
    assert_eq!(back, o);
    assert!(serde_json::from_str::<PlantOptions>(r#"{"dragg": 0.3}"#).is_err());
}
