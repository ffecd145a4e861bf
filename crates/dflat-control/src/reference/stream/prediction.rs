//! The prediction from one sample: a coordinated turn in closed form, or
//! with the stream's jerk, tabulated (the module docs of `stream`).

use nalgebra::Vector3;

use super::TURN_MIN_SPEED;

/// Nodes of the jerk prediction's table (over `σ ∈ [0, σ_max]`).
const JERK_NODES: usize = 256;

/// The prediction from one sample.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Prediction {
    pub(super) t: f64,
    pub(super) p: Vector3<f64>,
    pub(super) v: Vector3<f64>,
    pub(super) a: Vector3<f64>,
    /// The horizontal prediction with the stream's jerk, tabulated (module
    /// docs, "The jerk"); `None`: the closed-form turn.
    pub(super) jerk: Option<JerkTable>,
}

/// Positions and velocities of the jerk prediction at `σ = k·step`.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct JerkTable {
    step: f64,
    p: [[f64; 2]; JERK_NODES + 1],
    v: [[f64; 2]; JERK_NODES + 1],
}

impl JerkTable {
    /// Integrates the horizontal motion from `p`, `v`, `a` with jerk `j`
    /// over `[0, sigma_max]`: speed and heading rate move at their rates
    /// (from `j`) for `horizon` \[s\], then stay (a turn at the curvature
    /// reached); below [`TURN_MIN_SPEED`], acceleration moves at `j` for
    /// `horizon`, then stays.
    pub(super) fn new(
        p: Vector3<f64>,
        v: Vector3<f64>,
        a: Vector3<f64>,
        j: Vector3<f64>,
        horizon: f64,
        sigma_max: f64,
    ) -> Self {
        let step = (sigma_max / JERK_NODES as f64).max(1e-9);
        // The planar velocity at σ.
        let speed = v.x.hypot(v.y);
        // ∫₀^σ min(σ', T) dσ': how far a rate held for T moves the motion.
        let g = |s: f64| -> f64 {
            let sj = s.min(horizon);
            0.5 * sj * sj + sj * (s - sj)
        };
        let vel = |s: f64| -> [f64; 2] {
            if speed < TURN_MIN_SPEED {
                // a(σ) = a + j·min(σ, T): v = v + a σ + j (σ_j²/2 + σ_j (σ − σ_j)).
                let jj = g(s);
                return [v.x + a.x * s + j.x * jj, v.y + a.y * s + j.y * jj];
            }
            let at = (v.x * a.x + v.y * a.y) / speed;
            let omega = (v.x * a.y - v.y * a.x) / (speed * speed);
            // Rates of the tangential acceleration and the turn rate.
            let a2 = a.x * a.x + a.y * a.y;
            let at_dot = (v.x * j.x + v.y * j.y + a2 - at * at) / speed;
            let omega_dot = (v.x * j.y - v.y * j.x) / (speed * speed) - 2.0 * omega * at / speed;
            let spd = speed + at * s + at_dot * g(s);
            let th = v.y.atan2(v.x) + omega * s + omega_dot * g(s);
            let spd = spd.max(0.0);
            [spd * th.cos(), spd * th.sin()]
        };
        let mut t = Self {
            step,
            p: [[0.0; 2]; JERK_NODES + 1],
            v: [[0.0; 2]; JERK_NODES + 1],
        };
        t.p[0] = [p.x, p.y];
        t.v[0] = vel(0.0);
        for k in 1..=JERK_NODES {
            let s0 = (k - 1) as f64 * step;
            // Simpson over the interval.
            let (va, vm, vb) = (vel(s0), vel(s0 + 0.5 * step), vel(s0 + step));
            for i in 0..2 {
                t.p[k][i] = t.p[k - 1][i] + step / 6.0 * (va[i] + 4.0 * vm[i] + vb[i]);
            }
            t.v[k] = vb;
        }
        t
    }

    /// Position and velocity at `sigma` (cubic Hermite between nodes; held
    /// at the last node's motion beyond it).
    fn at(&self, sigma: f64) -> ([f64; 2], [f64; 2]) {
        let x = (sigma / self.step).max(0.0);
        if x >= JERK_NODES as f64 {
            let extra = (x - JERK_NODES as f64) * self.step;
            let (p, v) = (self.p[JERK_NODES], self.v[JERK_NODES]);
            return ([p[0] + v[0] * extra, p[1] + v[1] * extra], v);
        }
        let k = x.floor() as usize;
        let u = x - k as f64;
        let h = self.step;
        let (p0, p1, v0, v1) = (self.p[k], self.p[k + 1], self.v[k], self.v[k + 1]);
        let (h00, h10, h01, h11) = (
            2.0 * u * u * u - 3.0 * u * u + 1.0,
            u * u * u - 2.0 * u * u + u,
            -2.0 * u * u * u + 3.0 * u * u,
            u * u * u - u * u,
        );
        let (d00, d10, d01, d11) = (
            (6.0 * u * u - 6.0 * u) / h,
            3.0 * u * u - 4.0 * u + 1.0,
            (-6.0 * u * u + 6.0 * u) / h,
            3.0 * u * u - 2.0 * u,
        );
        let mut p = [0.0; 2];
        let mut v = [0.0; 2];
        for i in 0..2 {
            p[i] = h00 * p0[i] + h10 * h * v0[i] + h01 * p1[i] + h11 * h * v1[i];
            v[i] = d00 * p0[i] + d10 * v0[i] + d01 * p1[i] + d11 * v1[i];
        }
        (p, v)
    }
}

impl Prediction {
    /// Position and velocity `sigma` \[s\] along the extrapolation.
    pub(super) fn at(&self, sigma: f64) -> (Vector3<f64>, Vector3<f64>) {
        if let Some(table) = &self.jerk {
            let s = sigma;
            let z = self.p.z + self.v.z * s + 0.5 * self.a.z * s * s;
            let vz = self.v.z + self.a.z * s;
            let (p, v) = table.at(s);
            return (Vector3::new(p[0], p[1], z), Vector3::new(v[0], v[1], vz));
        }
        self.closed_form(sigma)
    }

    /// The coordinated turn (or constant acceleration) in closed form.
    fn closed_form(&self, sigma: f64) -> (Vector3<f64>, Vector3<f64>) {
        let s = sigma;
        let z = self.p.z + self.v.z * s + 0.5 * self.a.z * s * s;
        let vz = self.v.z + self.a.z * s;
        let speed = self.v.x.hypot(self.v.y);
        if speed < TURN_MIN_SPEED {
            let x = self.p.x + self.v.x * s + 0.5 * self.a.x * s * s;
            let y = self.p.y + self.v.y * s + 0.5 * self.a.y * s * s;
            return (
                Vector3::new(x, y, z),
                Vector3::new(self.v.x + self.a.x * s, self.v.y + self.a.y * s, vz),
            );
        }
        let omega = (self.v.x * self.a.y - self.v.y * self.a.x) / (speed * speed);
        let at = (self.v.x * self.a.x + self.v.y * self.a.y) / speed;
        let th0 = self.v.y.atan2(self.v.x);
        let th = th0 + omega * s;
        let spd = speed + at * s;
        let (c0, s0) = (th0.cos(), th0.sin());
        let (c1, s1) = (th.cos(), th.sin());
        // U(σ) = ∫₀^σ u(θ0 + ωσ') dσ', IU = ∫₀^σ U; small ω: series.
        let (ux, uy, iux, iuy) = if (omega * s).abs() < 1e-4 {
            let w = omega;
            (
                s * c0 - 0.5 * w * s * s * s0,
                s * s0 + 0.5 * w * s * s * c0,
                0.5 * s * s * c0 - w * s * s * s / 6.0 * s0,
                0.5 * s * s * s0 + w * s * s * s / 6.0 * c0,
            )
        } else {
            let w = omega;
            let ux = (s1 - s0) / w;
            let uy = (c0 - c1) / w;
            let iux = (-(c1 - c0) / w - s * s0) / w;
            let iuy = (s * c0 - (s1 - s0) / w) / w;
            (ux, uy, iux, iuy)
        };
        // ∫ (speed + a_t σ') u dσ' = speed·U + a_t (σU − IU).
        let x = self.p.x + speed * ux + at * (s * ux - iux);
        let y = self.p.y + speed * uy + at * (s * uy - iuy);
        (Vector3::new(x, y, z), Vector3::new(spd * c1, spd * s1, vz))
    }
}
