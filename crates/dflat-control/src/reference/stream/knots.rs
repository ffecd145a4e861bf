//! The trajectory a planner has sent, between its samples (the knots):
//! quintic Hermite where both knots give position, velocity and
//! acceleration (exact for a quintic, continuous in acceleration across
//! knots), cubic Hermite where they give position and velocity, and for
//! position-only knots the velocity of the quadratic through each knot and
//! its neighbours (a Catmull–Rom-like cubic, continuous in velocity).

use nalgebra::Vector3;

use super::StreamSample;

/// The velocity at knot `k` [m/s]: the sample's, else the derivative at
/// `t_k` of the quadratic through it and its neighbours (one-sided at the
/// ends; zero for a lone knot).
pub(super) fn velocity_at(knots: &[StreamSample], k: usize) -> Vector3<f64> {
    if let Some(v) = knots[k].velocity {
        return v;
    }
    let n = knots.len();
    let slope = |i: usize, j: usize| {
        let h = knots[j].t - knots[i].t;
        if h > 0.0 {
            (knots[j].position - knots[i].position) / h
        } else {
            Vector3::zeros()
        }
    };
    match (k > 0, k + 1 < n) {
        (true, true) => {
            let (h1, h2) = (knots[k].t - knots[k - 1].t, knots[k + 1].t - knots[k].t);
            if h1 + h2 <= 0.0 {
                return Vector3::zeros();
            }
            slope(k - 1, k) * (h2 / (h1 + h2)) + slope(k, k + 1) * (h1 / (h1 + h2))
        }
        (true, false) => slope(k - 1, k),
        (false, true) => slope(k, k + 1),
        (false, false) => Vector3::zeros(),
    }
}

/// Position and velocity at `t` between knots `k` and `k + 1`
/// (`t_k ≤ t ≤ t_{k+1}`, `t_k < t_{k+1}`).
pub(super) fn between(knots: &[StreamSample], k: usize, t: f64) -> (Vector3<f64>, Vector3<f64>) {
    let (k0, k1) = (&knots[k], &knots[k + 1]);
    let h = k1.t - k0.t;
    let u = ((t - k0.t) / h).clamp(0.0, 1.0);
    let (v0, v1) = (velocity_at(knots, k), velocity_at(knots, k + 1));
    let (p0, p1) = (k0.position, k1.position);
    if let (Some(a0), Some(a1)) = (k0.acceleration, k1.acceleration) {
        let [h0, h1, h2, h3, h4, h5] = quintic(u);
        let [d0, d1, d2, d3, d4, d5] = quintic_d(u);
        let p = p0 * h0
            + v0 * (h * h1)
            + a0 * (h * h * h2)
            + a1 * (h * h * h3)
            + v1 * (h * h4)
            + p1 * h5;
        let v = (p0 * d0
            + v0 * (h * d1)
            + a0 * (h * h * d2)
            + a1 * (h * h * d3)
            + v1 * (h * d4)
            + p1 * d5)
            / h;
        return (p, v);
    }
    let (u2, u3) = (u * u, u * u * u);
    let (h00, h10, h01, h11) = (
        2.0 * u3 - 3.0 * u2 + 1.0,
        u3 - 2.0 * u2 + u,
        -2.0 * u3 + 3.0 * u2,
        u3 - u2,
    );
    let (d00, d10, d01, d11) = (
        6.0 * u2 - 6.0 * u,
        3.0 * u2 - 4.0 * u + 1.0,
        -6.0 * u2 + 6.0 * u,
        3.0 * u2 - 2.0 * u,
    );
    let p = p0 * h00 + v0 * (h * h10) + p1 * h01 + v1 * (h * h11);
    let v = (p0 * d00 + v0 * (h * d10) + p1 * d01 + v1 * (h * d11)) / h;
    (p, v)
}

/// The quintic Hermite basis at `u ∈ [0, 1]`: weights of p0, h·v0, h²·a0,
/// h²·a1, h·v1, p1.
fn quintic(u: f64) -> [f64; 6] {
    let (u2, u3) = (u * u, u * u * u);
    let (u4, u5) = (u3 * u, u3 * u2);
    [
        1.0 - 10.0 * u3 + 15.0 * u4 - 6.0 * u5,
        u - 6.0 * u3 + 8.0 * u4 - 3.0 * u5,
        0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5,
        0.5 * u3 - u4 + 0.5 * u5,
        -4.0 * u3 + 7.0 * u4 - 3.0 * u5,
        10.0 * u3 - 15.0 * u4 + 6.0 * u5,
    ]
}

/// The derivatives in `u` of [`quintic`].
fn quintic_d(u: f64) -> [f64; 6] {
    let (u2, u3, u4) = (u * u, u * u * u, u * u * u * u);
    [
        -30.0 * u2 + 60.0 * u3 - 30.0 * u4,
        1.0 - 18.0 * u2 + 32.0 * u3 - 15.0 * u4,
        u - 4.5 * u2 + 6.0 * u3 - 2.5 * u4,
        1.5 * u2 - 4.0 * u3 + 2.5 * u4,
        -12.0 * u2 + 28.0 * u3 - 15.0 * u4,
        30.0 * u2 - 60.0 * u3 + 30.0 * u4,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn knot(t: f64, p: f64, v: Option<f64>, a: Option<f64>) -> StreamSample {
        StreamSample {
            t,
            position: Vector3::new(p, 0.0, 0.0),
            velocity: v.map(|v| Vector3::new(v, 0.0, 0.0)),
            acceleration: a.map(|a| Vector3::new(a, 0.0, 0.0)),
            yaw: None,
            yaw_rate: None,
        }
    }

    /// A quintic is reproduced exactly from p/v/a knots, a cubic from p/v
    /// knots, a quadratic from position-only knots (the velocity of the
    /// quadratic through neighbours), at uneven spacing.
    #[test]
    fn the_hermite_forms_reproduce_their_polynomials() {
        let ts = [0.0, 0.05, 0.12, 0.2, 0.31];
        let quint = |t: f64| {
            (
                1.0 + 2.0 * t - t * t + 3.0 * t.powi(3) - 4.0 * t.powi(4) + t.powi(5),
                2.0 - 2.0 * t + 9.0 * t * t - 16.0 * t.powi(3) + 5.0 * t.powi(4),
                -2.0 + 18.0 * t - 48.0 * t * t + 20.0 * t.powi(3),
            )
        };
        let cubic = |t: f64| {
            (
                1.0 + 2.0 * t - t * t + 3.0 * t.powi(3),
                2.0 - 2.0 * t + 9.0 * t * t,
            )
        };
        let quad = |t: f64| (1.0 + 2.0 * t - 5.0 * t * t, 2.0 - 10.0 * t);
        let k5: Vec<_> = ts
            .iter()
            .map(|&t| {
                let (p, v, a) = quint(t);
                knot(t, p, Some(v), Some(a))
            })
            .collect();
        let k3: Vec<_> = ts
            .iter()
            .map(|&t| {
                let (p, v) = cubic(t);
                knot(t, p, Some(v), None)
            })
            .collect();
        let k2: Vec<_> = ts.iter().map(|&t| knot(t, quad(t).0, None, None)).collect();
        for k in 0..ts.len() - 1 {
            for i in 0..=10 {
                let t = ts[k] + (ts[k + 1] - ts[k]) * i as f64 / 10.0;
                let (p, v) = between(&k5, k, t);
                assert!(
                    (p.x - quint(t).0).abs() < 1e-12 && (v.x - quint(t).1).abs() < 1e-10,
                    "quintic at {t}"
                );
                let (p, v) = between(&k3, k, t);
                assert!(
                    (p.x - cubic(t).0).abs() < 1e-12 && (v.x - cubic(t).1).abs() < 1e-10,
                    "cubic at {t}"
                );
                if k > 0 && k + 2 < ts.len() {
                    let (p, v) = between(&k2, k, t);
                    assert!(
                        (p.x - quad(t).0).abs() < 1e-12 && (v.x - quad(t).1).abs() < 1e-10,
                        "quadratic at {t}"
                    );
                }
            }
        }
    }
}
