//! Wind: a constant mean plus first-order Gauss–Markov gusts.
//!
//! Each NED axis of the gust is an Ornstein–Uhlenbeck process with standard
//! deviation σ and correlation time T (Dryden's longitudinal form
//! `H(s) = σ·√(2T)/(1 + T·s)` with T = L/V, used for all three axes),
//! discretised exactly: `g_{n+1} = a·g_n + σ·√(1 − a²)·w_n`, `a = e^{−h/T}`,
//! `w_n ~ N(0, 1)`. The gust is held constant over each integration step.
//! Its statistics do not depend on the step, and for a fixed seed and step the
//! sequence is reproducible.

use nalgebra::Vector3;
use rand_chacha::ChaCha8Rng;

use crate::rng::{STREAM_PLANT, normal, stream};

/// Mean wind plus seeded gusts, local NED [m/s].
#[derive(Debug, Clone)]
pub struct Wind {
    mean: Vector3<f64>,
    std: Vector3<f64>,
    tau: f64,
    gust: Vector3<f64>,
    rng: ChaCha8Rng,
}

impl Wind {
    /// Mean wind `mean` [m/s], gust std `std` [m/s] per axis, correlation
    /// time `tau` \[s\] (> 0), gusts seeded by `seed`. The gust starts at a draw
    /// from its stationary distribution.
    pub fn new(mean: [f64; 3], std: [f64; 3], tau: f64, seed: u64) -> Self {
        let mut w = Self {
            mean: Vector3::from(mean),
            std: Vector3::from(std),
            tau,
            gust: Vector3::zeros(),
            rng: stream(seed, STREAM_PLANT),
        };
        w.restart();
        w
    }

    /// Draws a fresh gust from the stationary distribution (continuing the
    /// random stream).
    pub fn restart(&mut self) {
        for i in 0..3 {
            self.gust[i] = if self.std[i] > 0.0 {
                self.std[i] * normal(&mut self.rng)
            } else {
                0.0
            };
        }
    }

    /// Advances the gust by `h` \[s\].
    pub fn step(&mut self, h: f64) {
        let a = (-h / self.tau).exp();
        let b = (1.0 - a * a).max(0.0).sqrt();
        for i in 0..3 {
            if self.std[i] > 0.0 {
                self.gust[i] = a * self.gust[i] + self.std[i] * b * normal(&mut self.rng);
            }
        }
    }

    /// Air-mass velocity now: mean + gust, local NED [m/s].
    pub fn velocity(&self) -> Vector3<f64> {
        self.mean + self.gust
    }
}
