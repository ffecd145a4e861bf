//! The parametric model the residual is learned over: the `[vehicle]`
//! table's first-order attitude (τ, k̃), pure delay, collective thrust (τ_T,
//! hover thrust) and linear drag, driven by the commands sent (the input
//! window) — no state estimate.

use nalgebra::Vector3;

use super::data::Run;

/// The `[vehicle]` values of the parametric model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parametric {
    /// The spatial model (thrust flown); false: planar (the autopilot holds
    /// the altitude, the vertical acceleration is 0).
    pub spatial: bool,
    /// Gravity [m/s²].
    pub g: f64,
    /// Attitude time constant τ \[s\].
    pub tau: f64,
    /// Attitude gain k̃.
    pub k: f64,
    /// Pure delay of the commands \[s\].
    pub delay: f64,
    /// Thrust time constant τ_T \[s\].
    pub tau_thrust: f64,
    /// Normalised hover thrust.
    pub hover_thrust: f64,
    /// Horizontal linear drag \[1/s\].
    pub drag_h: f64,
    /// Vertical linear drag \[1/s\].
    pub drag_v: f64,
    /// Rotor drag \[1/s\] in the body plane (spatial model): the step
    /// loses `drag_rotor·(v − n·(n·v))`.
    pub drag_rotor: f64,
    /// Control step δt \[s\].
    pub dt: f64,
}

/// The model's attitude and thrust at each tick of a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inputs {
    /// Thrust axis `R·e3` (unit, NED) per tick.
    pub axis: Vec<Vector3<f64>>,
    /// Specific thrust [m/s²] per tick.
    pub thrust: Vec<f64>,
}

/// Unit thrust axis `R·e3` (NED) of ZYX angles.
pub fn thrust_axis(roll: f64, pitch: f64, yaw: f64) -> Vector3<f64> {
    let (sp, cp) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (ss, cs) = yaw.sin_cos();
    Vector3::new(cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp)
}

impl Parametric {
    /// The model's thrust axis and specific thrust along a run: roll and
    /// pitch each `x ← x + (1 − e^(−δt/τ))·(k̃·cmd(t − delay) − x)` (the
    /// first-order lag held over a tick, exactly: the airframe's lag is
    /// continuous), the heading as commanded, the normalised thrust
    /// likewise through τ_T and `T = g·c/hover` (planar: `T = g/n_z`, the
    /// thrust that holds the altitude). Starts at rest on the first
    /// command.
    pub fn inputs(&self, run: &Run) -> Inputs {
        let d = (self.delay / self.dt).round().max(0.0) as usize;
        let cmd = |k: usize| run.ticks[k.saturating_sub(d)];
        let Some(first) = run.ticks.first() else {
            return Inputs::default();
        };
        let (mut roll, mut pitch) = (self.k * first.euler[0], self.k * first.euler[1]);
        let mut c = first.thrust;
        let mut out = Inputs {
            axis: Vec::with_capacity(run.ticks.len()),
            thrust: Vec::with_capacity(run.ticks.len()),
        };
        // The lags held over a tick, exactly (the airframe's are continuous).
        let a = -(-self.dt / self.tau).exp_m1();
        let at = -(-self.dt / self.tau_thrust).exp_m1();
        for k in 0..run.ticks.len() {
            let n = thrust_axis(roll, pitch, cmd(k).euler[2]);
            let thrust = if self.spatial {
                self.g * c / self.hover_thrust
            } else {
                self.g / n.z.max(0.1)
            };
            out.axis.push(n);
            out.thrust.push(thrust);
            let u = cmd(k);
            roll += a * (self.k * u.euler[0] - roll);
            pitch += a * (self.k * u.euler[1] - pitch);
            c += at * (u.thrust - c);
        }
        out
    }

    /// The model's acceleration [m/s², NED] at thrust axis `n`, specific
    /// thrust `thrust` and velocity `v` (NED [m/s]): `g·e3 − T·n` less
    /// [`Parametric::drag`] (planar: the vertical component 0).
    pub fn acceleration(&self, n: &Vector3<f64>, thrust: f64, v: &Vector3<f64>) -> Vector3<f64> {
        let mut a = Vector3::new(0.0, 0.0, self.g) - n * thrust - self.drag(n, v);
        if !self.spatial {
            a.z = 0.0;
        }
        a
    }
}

impl Parametric {
    /// The deceleration of the model's drag [m/s², NED] at velocity `v`
    /// (NED [m/s]) and thrust axis `n` (unit): `D·v` and, spatial, the
    /// rotor drag `d_r·(v − n·(n·v))`.
    pub fn drag(&self, n: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        let mut d = Vector3::new(self.drag_h * v.x, self.drag_h * v.y, self.drag_v * v.z);
        if self.spatial && self.drag_rotor != 0.0 {
            d += self.drag_rotor * (v - n * n.dot(v));
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::data::Tick;
    use proptest::prelude::*;

    fn model() -> Parametric {
        Parametric {
            spatial: true,
            g: 9.81,
            tau: 0.2,
            k: 1.0,
            delay: 0.04,
            tau_thrust: 0.05,
            hover_thrust: 0.5,
            drag_h: 0.0,
            drag_v: 0.0,
            drag_rotor: 0.0,
            dt: 0.02,
        }
    }

    proptest! {
        /// A held command: the attitude settles at k̃·command, the thrust at
        /// g·c/hover, and the model's acceleration is then the tilt's pull
        /// at that thrust (forward model: `g·e3 − T·R·e3`).
        #[test]
        fn a_held_command_settles_on_the_forward_model(
            roll in -0.4f64..0.4, pitch in -0.4f64..0.4, yaw in -3.0f64..3.0, c in 0.3f64..0.7,
        ) {
            let m = model();
            let run = Run {
                ticks: (0..400)
                    .map(|i| Tick {
                        t: i as f64 * m.dt,
                        euler: if i < 5 { [0.0, 0.0, yaw] } else { [roll, pitch, yaw] },
                        thrust: if i < 5 { 0.5 } else { c },
                    })
                    .collect(),
                poses: Vec::new(),
            };
            let inputs = m.inputs(&run);
            let n = *inputs.axis.last().unwrap();
            let t = *inputs.thrust.last().unwrap();
            prop_assert!((n - thrust_axis(roll, pitch, yaw)).norm() < 1e-9);
            prop_assert!((t - 9.81 * c / 0.5).abs() < 1e-9);
            let a = m.acceleration(&n, t, &Vector3::zeros());
            let want = Vector3::new(0.0, 0.0, 9.81) - thrust_axis(roll, pitch, yaw) * t;
            prop_assert!((a - want).norm() < 1e-9);
        }
    }
}
