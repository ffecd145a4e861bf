//! ZYX quaternion ⇄ Euler conversions.

use std::f64::consts::{FRAC_PI_2, PI};

use dflat_link::math::{quaternion_norm, wrap_pi, yaw_from_quaternion};
use dflat_link::{euler_from_quaternion, quaternion_from_euler};
use proptest::prelude::*;

fn angle_diff(a: f64, b: f64) -> f64 {
    wrap_pi(a - b).abs()
}

/// Hamilton product a ⊗ b, [w, x, y, z].
fn mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

#[test]
fn matches_product_of_axis_rotations() {
    let (r, p, y): (f64, f64, f64) = (0.3, -0.4, 2.0);
    let qx = [(r / 2.0).cos(), (r / 2.0).sin(), 0.0, 0.0];
    let qy = [(p / 2.0).cos(), 0.0, (p / 2.0).sin(), 0.0];
    let qz = [(y / 2.0).cos(), 0.0, 0.0, (y / 2.0).sin()];
    let expected = mul(qz, mul(qy, qx));
    let q = quaternion_from_euler(r, p, y);
    for i in 0..4 {
        assert!((q[i] - expected[i]).abs() < 1e-15, "{q:?} vs {expected:?}");
    }
}

#[test]
fn pitch_near_gimbal_lock_keeps_precision() {
    let pitch = FRAC_PI_2 - 1e-6;
    let e = euler_from_quaternion(quaternion_from_euler(0.0, pitch, 0.3));
    assert!((e[1] - pitch).abs() < 1e-9);
}

proptest! {
    #[test]
    fn euler_quaternion_euler_round_trip(
        roll in -PI + 1e-9..PI,
        pitch in -(FRAC_PI_2 - 1e-3)..(FRAC_PI_2 - 1e-3),
        yaw in -PI + 1e-9..PI,
    ) {
        let q = quaternion_from_euler(roll, pitch, yaw);
        prop_assert!((quaternion_norm(q) - 1.0).abs() < 1e-12);
        let [r, p, y] = euler_from_quaternion(q);
        prop_assert!(angle_diff(r, roll) < 1e-9, "roll {} vs {}", r, roll);
        prop_assert!((p - pitch).abs() < 1e-9, "pitch {} vs {}", p, pitch);
        prop_assert!(angle_diff(y, yaw) < 1e-9, "yaw {} vs {}", y, yaw);
        prop_assert!(angle_diff(yaw_from_quaternion(q), yaw) < 1e-9);
    }

    #[test]
    fn quaternion_euler_quaternion_round_trip(
        w in -1.0f64..1.0, x in -1.0f64..1.0, y in -1.0f64..1.0, z in -1.0f64..1.0,
    ) {
        let n = quaternion_norm([w, x, y, z]);
        prop_assume!(n > 1e-3);
        let q = [w / n, x / n, y / n, z / n];
        let [r, p, yw] = euler_from_quaternion(q);
        let back = quaternion_from_euler(r, p, yw);
        prop_assert!((quaternion_norm(back) - 1.0).abs() < 1e-12);
        // Same rotation: q and −q are equivalent.
        let dot: f64 = (0..4).map(|i| q[i] * back[i]).sum();
        prop_assert!((dot.abs() - 1.0).abs() < 1e-9, "q {:?} back {:?}", q, back);
    }

    #[test]
    fn any_finite_angles_give_unit_quaternion(
        roll in -100.0f64..100.0, pitch in -100.0f64..100.0, yaw in -100.0f64..100.0,
    ) {
        let q = quaternion_from_euler(roll, pitch, yaw);
        prop_assert!((quaternion_norm(q) - 1.0).abs() < 1e-12);
    }
}
