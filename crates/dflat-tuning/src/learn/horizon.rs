//! The held-out prediction of the input-to-output map: from a window of
//! poses before each start, the model (and, with it, the residual) rolled
//! out over the horizon and compared with the poses that followed
//! ([`rollouts`], [`Errors`]).

use dflat_control::learned::LearnedResidual;
use nalgebra::Vector3;

use super::fit::{Part, Prepared, parabola_weights, part};
use super::parametric::Parametric;

/// Sums of squared prediction errors over held-out starts.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Errors {
    /// Σ |y_next − ŷ_next|² \[m²\].
    pub one_step: f64,
    /// Σ |y_H − ŷ_H|² \[m²\].
    pub horizon: f64,
    /// Starts.
    pub count: usize,
    /// Σ |y*_H − ŷ_H|² against the true positions y* where the poses
    /// carry them ([`Pose::truth`](super::data::Pose::truth)) \[m²\], and over how many starts.
    pub horizon_truth: f64,
    /// Starts whose horizon pose carries its true position.
    pub truth_count: usize,
}

impl Errors {
    /// RMS one-step error \[m\] (NaN without starts).
    pub fn one_step_rms(&self) -> f64 {
        (self.one_step / self.count as f64).sqrt()
    }

    /// RMS horizon error \[m\] (NaN without starts).
    pub fn horizon_rms(&self) -> f64 {
        (self.horizon / self.count as f64).sqrt()
    }

    /// RMS horizon error against the true positions \[m\] (NaN without
    /// starts that carry them).
    pub fn horizon_truth_rms(&self) -> f64 {
        (self.horizon_truth / self.truth_count as f64).sqrt()
    }
}

/// The model's acceleration besides the thrust's at velocity `v` in tick
/// `j`: its drag and, with `residual`, the residual.
fn extra_acceleration(
    p: &Prepared,
    model: &Parametric,
    residual: Option<&LearnedResidual>,
    j: usize,
    v: &Vector3<f64>,
) -> Vector3<f64> {
    let mut a = -model.drag(&p.inputs.axis[j], v);
    if let Some(m) = residual {
        a += m.acceleration(v, &p.inputs.axis[j], p.inputs.thrust[j]);
    }
    if !model.spatial {
        a.z = 0.0;
    }
    a
}

/// The state (position \[m\], velocity [m/s]) at pose `i`'s time from the
/// poses of the last `start_s` \[s\] (at least five) through the model itself
/// (the input-to-output map from a window): a parabola on top of the
/// thrust's trajectory gives the velocity along the window, the model's
/// drag and residual there are integrated, and the position and velocity
/// fitted to the poses through all of it.
fn start_state(
    p: &Prepared,
    model: &Parametric,
    residual: Option<&LearnedResidual>,
    i: usize,
    start_s: f64,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let s = p.poses[i].t;
    let mut first = i;
    while first > 0 && (s - p.poses[first - 1].t <= start_s || i - first < 4) {
        first -= 1;
    }
    let w = &p.poses[first..=i];
    if w.len() < 3 || s - w[0].t > 3.0 * start_s || p.tick_at(w[0].t).is_none() {
        return None;
    }
    let times: Vec<f64> = w.iter().map(|q| q.t).collect();
    let [_, wv, wa] = parabola_weights(&times, s)?;
    let (vp, vv) = p.virtual_position(s);
    // Pass 1: the velocity along the window (thrust's trajectory plus a
    // parabola).
    let (mut v1, mut c) = (Vector3::zeros(), Vector3::zeros());
    for (l, q) in w.iter().enumerate() {
        let off = q.y - p.virtual_position(q.t).0;
        v1 += off * wv[l];
        c += off * wa[l];
    }
    // Pass 2: the model's other accelerations along it, integrated back
    // from s: E(s_l) = ∫_{s_l}^{s} (τ − s_l)·e(τ) dτ (E(s) = E'(s) = 0),
    // e held per segment between the poses' times and the ticks' ends
    // (at its midpoint), in one backward pass: with τ' = τ − s,
    // E(s_l) = Σ_{segments after s_l} ∫ τ'·e − s'_l·∫ e.
    let velocity_at = |t: f64| v1 + p.virtual_position(t).1 + c * (t - s);
    let mut cuts = times;
    let mut j = p.tick_at(w[0].t)?;
    loop {
        let end = p.t0 + (j + 1) as f64 * p.dt;
        if end >= s - 1e-12 {
            break;
        }
        cuts.push(end);
        j += 1;
    }
    cuts.sort_by(f64::total_cmp);
    cuts.dedup_by(|a, b| (*a - *b).abs() <= 1e-12);
    // Suffix sums of ∫ τ'·e and ∫ e over the segments from cut k on.
    let mut first_moment = vec![Vector3::zeros(); cuts.len()];
    let mut integral = vec![Vector3::zeros(); cuts.len()];
    for k in (0..cuts.len().saturating_sub(1)).rev() {
        let (a, b) = (cuts[k], cuts[k + 1]);
        let mid = 0.5 * (a + b);
        let e = extra_acceleration(p, model, residual, p.tick_at(mid)?, &velocity_at(mid));
        let (a, b) = (a - s, b - s);
        first_moment[k] = first_moment[k + 1] + e * (0.5 * (b * b - a * a));
        integral[k] = integral[k + 1] + e * (b - a);
    }
    let mut rows: Vec<(f64, Vector3<f64>)> = Vec::with_capacity(w.len());
    let mut k = 0;
    for q in w {
        while k + 1 < cuts.len() && cuts[k] < q.t - 1e-12 {
            k += 1;
        }
        let e_int = first_moment[k] - integral[k] * (q.t - s);
        rows.push((q.t - s, q.y - p.virtual_position(q.t).0 - e_int));
    }
    // Position and velocity (a line) through the rest.
    let n = rows.len() as f64;
    let mt = rows.iter().map(|(t, _)| t).sum::<f64>() / n;
    let my = rows.iter().fold(Vector3::zeros(), |a, (_, y)| a + y) / n;
    let stt = rows.iter().map(|(t, _)| (t - mt).powi(2)).sum::<f64>();
    if stt <= 0.0 {
        return None;
    }
    let slope = rows
        .iter()
        .fold(Vector3::zeros(), |a, (t, y)| a + (y - my) * (t - mt))
        / stt;
    let at_s = my - slope * mt;
    Some((at_s + vp, slope + vv))
}

/// Rolls `(pos, vel)` from `from` to `to` \[s\] through the ticks' thrust
/// acceleration, the model's drag and, with `residual`, the residual at
/// the rolled velocity (each piece within a tick: a midpoint step).
fn roll(
    p: &Prepared,
    model: &Parametric,
    residual: Option<&LearnedResidual>,
    (mut pos, mut vel): (Vector3<f64>, Vector3<f64>),
    from: f64,
    to: f64,
) -> Option<Vector3<f64>> {
    let mut t = from;
    while t < to - 1e-12 {
        let mut j = p.tick_at(t)?;
        if p.t0 + (j + 1) as f64 * p.dt <= t + 1e-12 {
            // On a tick's end (rounding): the next tick.
            j += 1;
            if j >= p.thrust_acc.len() {
                return None;
            }
        }
        let end = (p.t0 + (j + 1) as f64 * p.dt).min(to);
        let h = end - t;
        let acc = |v: &Vector3<f64>| {
            let mut a = p.thrust_acc[j] + extra_acceleration(p, model, residual, j, v);
            if !model.spatial {
                a.z = 0.0;
            }
            a
        };
        let a0 = acc(&vel);
        let a = acc(&(vel + a0 * (0.5 * h)));
        pos += vel * h + a * (0.5 * h * h);
        vel += a * h;
        t = end;
    }
    Some(pos)
}

/// Prediction errors on `which`: from every `stride`-th pose with its
/// start window (`start_s` \[s\] of poses), the model rolled through the commands sent to the next
/// pose and to the last pose within `horizon_s` (at least 80 % of it on);
/// `residual = None`: the parametric model alone.
pub fn rollouts(
    runs: &[Prepared],
    model: &Parametric,
    residual: Option<&LearnedResidual>,
    which: Part,
    horizon_s: f64,
    stride: usize,
    start_s: f64,
) -> Errors {
    let mut errors = Errors::default();
    for p in runs {
        let mut i = 2;
        while i + 1 < p.poses.len() {
            let s = p.poses[i].t;
            let last = p.poses[i + 1..]
                .iter()
                .take_while(|q| q.t <= s + horizon_s + 1e-9)
                .last()
                .copied();
            let judged = last
                .filter(|q| q.t >= s + 0.8 * horizon_s && part(s) == which && part(q.t) == which);
            let start = judged.and_then(|_| start_state(p, model, residual, i, start_s));
            if let (Some(h), Some(start)) = (judged, start) {
                let next = p.poses[i + 1];
                let one = roll(p, model, residual, start, s, next.t);
                let far = roll(p, model, residual, start, s, h.t);
                if let (Some(one), Some(far)) = (one, far) {
                    errors.one_step += (next.y - one).norm_squared();
                    errors.horizon += (h.y - far).norm_squared();
                    errors.count += 1;
                    if let Some(truth) = h.truth {
                        errors.horizon_truth += (truth - far).norm_squared();
                        errors.truth_count += 1;
                    }
                }
            }
            i += stride;
        }
    }
    errors
}
