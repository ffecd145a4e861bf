//! The disturbance estimator's window fit (module docs of [`super`]): the
//! least-squares weights, the fits of the window's ticks or samples, and
//! the low-pass's noise gain.

use nalgebra::{Matrix3, Vector3};

use super::DisturbanceEstimator;

/// The least-squares weights h (see the module docs) for a window of `l`
/// samples at step `dt` \[s\]: δ̂ = Σ h_j r_j fits `r_j = p + v·jδt + δ·c_j`.
pub(super) fn fit_weights(l: usize, dt: f64) -> Option<Vec<f64>> {
    // Scaled regressors [1, j/n, j(j−1)/n²] keep the normal matrix O(1).
    let n = (l - 1) as f64;
    weights_of_rows(l, dt, |j: usize| {
        let jf = j as f64;
        Vector3::new(1.0, jf / n, jf * (jf - 1.0) / (n * n))
    })
}

/// The weights h_j of the third coefficient of the least-squares fit of
/// `l` samples on the regressors `row(j)` (the third scaled by n²/2),
/// scaled to an acceleration at step `dt` \[s\]: δ·c_j = β₂·(row's third)
/// ⇒ δ = 2β₂/(δt²·n²), n = l − 1.
pub(super) fn weights_of_rows(
    l: usize,
    dt: f64,
    row: impl Fn(usize) -> Vector3<f64>,
) -> Option<Vec<f64>> {
    let n = (l - 1) as f64;
    let mut ata = Matrix3::zeros();
    for j in 0..l {
        let a = row(j);
        ata += a * a.transpose();
    }
    let inv = ata.try_inverse()?;
    let scale = 2.0 / (dt * dt * n * n);
    let r2 = inv.row(2).transpose();
    Some((0..l).map(|j| scale * r2.dot(&row(j))).collect())
}

/// std(d̂)/σ of the low-passed fit (module docs) for weights `h` and α.
pub(super) fn low_pass_noise_gain(h: &[f64], alpha: f64) -> f64 {
    let beta = 1.0 - alpha;
    let mut var = 0.0;
    let mut b = 1.0;
    for s in 0..h.len() {
        let r: f64 = h.iter().zip(&h[s..]).map(|(a, c)| a * c).sum();
        var += if s == 0 { r } else { 2.0 * b * r };
        b *= beta;
    }
    (var * alpha * alpha / (1.0 - beta * beta)).sqrt()
}

impl DisturbanceEstimator {
    /// Classic mode: δ̂ from the measured outputs at the window's ticks with
    /// the precomputed weights h (module docs).
    pub(super) fn tick_fit(&self) -> Vector3<f64> {
        let l = self.settings.fit_span;
        let dt = self.model.dt();
        let kappa = self.estimate.thrust_scale;
        let y0 = self.outputs[self.head];
        let (mut s, mut w) = (Vector3::zeros(), Vector3::<f64>::zeros());
        let mut delta = Vector3::zeros();
        if !self.drag.is_free() {
            let decay = self.drag.decay;
            for j in 0..l {
                let i = (self.head + j) % l;
                let r = (self.outputs[i] - y0) - s;
                for axis in 0..3 {
                    delta[axis] += self.drag.h[axis][j] * r[axis];
                }
                s += dt * w;
                w = w.component_mul(&decay) + dt * (self.accel_g[i] + kappa * self.accel_t[i]);
            }
            return delta;
        }
        for (j, h) in self.weights.iter().enumerate() {
            let i = (self.head + j) % l;
            delta += *h * ((self.outputs[i] - y0) - s);
            s += dt * w;
            w += dt * (self.accel_g[i] + kappa * self.accel_t[i]);
        }
        delta
    }

    /// Multi-rate mode: δ̂ from the timestamped samples in the window's span
    /// of tick times (module docs); `None` when they do not determine it
    /// (fewer than three, or none in the first or the last third).
    pub(super) fn sample_fit(&mut self) -> Option<Vector3<f64>> {
        let l = self.settings.fit_span;
        let dt = self.model.dt();
        let kappa = self.estimate.thrust_scale;
        let (mut s, mut w) = (Vector3::zeros(), Vector3::<f64>::zeros());
        let free = self.drag.is_free();
        let decay = self.drag.decay;
        for j in 0..l {
            let i = (self.head + j) % l;
            self.integral[j] = s;
            s += dt * w;
            if free {
                w += dt * (self.accel_g[i] + kappa * self.accel_t[i]);
            } else {
                w = w.component_mul(&decay) + dt * (self.accel_g[i] + kappa * self.accel_t[i]);
            }
        }
        if !free {
            return self.sample_fit_drag(dt);
        }
        let n = (l - 1) as f64;
        let mut ata = Matrix3::zeros();
        let mut atb = [Vector3::<f64>::zeros(); 3];
        let mut spread = Spread::default();
        for (tau, j, a, r) in self.window_residuals(dt) {
            let jf = j as f64;
            let c = (jf * (jf - 1.0) + a * 2.0 * jf) / (n * n);
            let row = Vector3::new(1.0, tau / n, c);
            ata += row * row.transpose();
            for (axis, b) in atb.iter_mut().enumerate() {
                *b += r[axis] * row;
            }
            spread.add(tau);
        }
        if !spread.covers(n) {
            return None;
        }
        let inv = ata.try_inverse()?;
        let scale = 2.0 / (dt * dt * n * n);
        let delta = Vector3::new(
            scale * inv.row(2).dot(&atb[0].transpose()),
            scale * inv.row(2).dot(&atb[1].transpose()),
            scale * inv.row(2).dot(&atb[2].transpose()),
        );
        delta.iter().all(|v| v.is_finite()).then_some(delta)
    }

    /// The samples in the fit window's span of tick times: each one's
    /// fractional tick τ ∈ \[0, L − 1\], the tick j it follows with the
    /// fraction a past it, and its position less the newest sample and the
    /// double integral interpolated at τ \[m\].
    fn window_residuals(
        &self,
        dt: f64,
    ) -> impl Iterator<Item = (f64, usize, f64, Vector3<f64>)> + '_ {
        let l = self.settings.fit_span;
        let t0 = self.tick_times[self.head];
        let n = (l - 1) as f64;
        let reference = self.last_sample.map_or(Vector3::zeros(), |(_, y)| y);
        let cap = self.samples.len();
        (0..self.sample_len).filter_map(move |k| {
            let (ts, y) = self.samples[(self.sample_head + k) % cap];
            let tau = (ts - t0) / dt;
            if !(-1e-6..=n + 1e-6).contains(&tau) {
                return None;
            }
            let tau = tau.clamp(0.0, n);
            let j = (tau.floor() as usize).min(l - 2);
            let a = tau - j as f64;
            let integral = self.integral[j] + a * (self.integral[j + 1] - self.integral[j]);
            Some((tau, j, a, y - reference - integral))
        })
    }

    /// [`Self::sample_fit`] with the model's drag: the per-axis basis of
    /// [`DragBasis`] at the samples' fractional ticks, one 3×3 normal system
    /// per axis. `integral` holds the decayed double integral.
    fn sample_fit_drag(&self, dt: f64) -> Option<Vector3<f64>> {
        let n = (self.settings.fit_span - 1) as f64;
        let mut ata = [Matrix3::zeros(); 3];
        let mut atb = [Vector3::<f64>::zeros(); 3];
        let mut spread = Spread::default();
        for (tau, _, _, r) in self.window_residuals(dt) {
            for axis in 0..3 {
                let (b, c) = self.drag.at(axis, tau);
                let row = Vector3::new(1.0, b / n, 2.0 * c / (n * n));
                ata[axis] += row * row.transpose();
                atb[axis] += r[axis] * row;
            }
            spread.add(tau);
        }
        if !spread.covers(n) {
            return None;
        }
        let scale = 2.0 / (dt * dt * n * n);
        let mut delta = Vector3::zeros();
        for axis in 0..3 {
            let inv = ata[axis].try_inverse()?;
            delta[axis] = scale * inv.row(2).dot(&atb[axis].transpose());
        }
        delta.iter().all(|v| v.is_finite()).then_some(delta)
    }
}

/// How the samples of a window fit spread over its ticks.
#[derive(Debug, Clone, Copy)]
struct Spread {
    /// Samples counted.
    count: usize,
    /// The earliest fractional tick.
    first: f64,
    /// The latest fractional tick.
    last: f64,
}

impl Default for Spread {
    fn default() -> Self {
        Self {
            count: 0,
            first: f64::INFINITY,
            last: f64::NEG_INFINITY,
        }
    }
}

impl Spread {
    /// Counts a sample at fractional tick `tau`.
    fn add(&mut self, tau: f64) {
        self.count += 1;
        self.first = self.first.min(tau);
        self.last = self.last.max(tau);
    }

    /// Whether the samples determine a fit over ticks 0..=n: at least
    /// three, one in the first third and one in the last.
    fn covers(&self, n: f64) -> bool {
        self.count >= 3 && self.first <= n / 3.0 && self.last >= 2.0 * n / 3.0
    }
}
