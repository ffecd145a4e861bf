//! Feed-forward of a flyable reference: the jerk and smoothness terms
//! weigh the plan's departure from the reference's own jerk and command
//! changes, not their absolute size.
//!
//! The per-axis cost is `q·‖y − y_ref‖² + Σ_rows w_row·(σ_row·y)²` (the
//! jerk rows `σ = Δ³` with `w = r/δt⁶`; the smoothness rows, the stencil
//! of `δt²·(c_j − c_{j−1})` with `w = s/(g²δt⁴)`). On a reference that is
//! itself a trajectory (a planner's stream, position, velocity and
//! acceleration), those rows pull the plan away from it: a circle has jerk
//! `v³/r²` everywhere and its tilt turns every tick, so the plan lags (the
//! 4 m/s, 6 m circle by 0.11 m at the daemon's weights). Weighing
//! `(σ_row·(y − y_ref))²` instead tracks such a reference without that
//! lag. The solvers need not change: with
//!
//! ```text
//! y_ref'_m = y_ref,m + (1/q)·Σ_rows w_row·σ_row[m]·(σ_row·y_ref)
//! ```
//!
//! on every free output m, `q·‖y − y_ref'‖² + Σ w(σ·y)²` equals
//! `q·‖y − y_ref‖² + Σ w(σ·(y − y_ref))²` up to a constant. The first
//! smoothness row (tied to the command sent at k−1) is left as it is.

use super::problem::D3;
use super::smoothness::Smoothness;

/// Shifts `reference` (y_ref,k..y_ref,k+N of one axis, N + 1 values; the
/// first three are the fixed outputs' and stay) so that the axis's jerk
/// (`r`) and smoothness terms weigh departures from the reference's own
/// jerk and command changes (module docs). `scratch` needs N + 1 values.
/// `q` > 0 is the tracking weight, `dt` \[s\] the step.
pub fn feed_forward(
    reference: &mut [f64],
    scratch: &mut [f64],
    q: f64,
    r: f64,
    dt: f64,
    smoothness: &Smoothness,
) {
    let len = reference.len();
    if len < 4 || scratch.len() < len || q.is_nan() || q <= 0.0 {
        return;
    }
    let shift = &mut scratch[..len];
    shift.fill(0.0);
    // Jerk rows: Δ³ over y_i..y_{i+3}, i = 0..N−3.
    add_rows(reference, shift, &D3, 0, r / dt.powi(6));
    // Smoothness rows 1..: over y_{i−1}..y_{i+3} (row 0 is tied to the
    // sent command and has no reference).
    if smoothness.weight > 0.0 {
        let w = smoothness.weight / smoothness.gravity.powi(2) / dt.powi(4);
        add_rows(reference, shift, &smoothness.stencil(), 0, w);
    }
    for (m, (y, s)) in reference.iter_mut().zip(shift.iter()).enumerate() {
        if m >= 3 {
            *y += s / q;
        }
    }
}

/// `shift[m] += w·σ[m − start]·(σ·y_ref)` for every row (window start
/// `start + i`, i = 0..) that lies inside the reference.
fn add_rows(reference: &[f64], shift: &mut [f64], stencil: &[f64], start: usize, w: f64) {
    if w == 0.0 {
        return;
    }
    let width = stencil.len();
    for i in start..=reference.len().saturating_sub(width) {
        let window = &reference[i..i + width];
        let value: f64 = stencil.iter().zip(window).map(|(c, y)| c * y).sum();
        for (a, c) in stencil.iter().enumerate() {
            shift[i + a] += w * c * value;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shifted cost equals the feed-forward cost up to a constant: its
    /// gradient in the free outputs matches at random points.
    #[test]
    fn the_shift_turns_the_cost_into_the_feed_forward_cost() {
        let n = 12;
        let (q, r, dt) = (2.0, 0.003, 0.02);
        let sm = Smoothness {
            weight: 50.0,
            kappa: 10.0,
            gravity: 9.81,
        };
        let reference: Vec<f64> = (0..=n).map(|j| (0.3 * j as f64).sin() * 4.0).collect();
        let mut shifted = reference.clone();
        let mut scratch = vec![0.0; n + 1];
        feed_forward(&mut shifted, &mut scratch, q, r, dt, &sm);
        let wj = r / dt.powi(6);
        let ws = sm.weight / sm.gravity.powi(2) / dt.powi(4);
        let rows = |y: &[f64], st: &[f64], w: f64, e: &[f64]| -> f64 {
            (0..=y.len() - st.len())
                .map(|i| {
                    let v: f64 = st
                        .iter()
                        .enumerate()
                        .map(|(a, c)| c * (y[i + a] - e[i + a]))
                        .sum();
                    w * v * v
                })
                .sum()
        };
        let zero = vec![0.0; n + 1];
        let cost_shifted = |y: &[f64]| {
            let t: f64 = (3..=n).map(|m| q * (y[m] - shifted[m]).powi(2)).sum();
            t + rows(y, &D3, wj, &zero) + rows(y, &sm.stencil(), ws, &zero)
        };
        let cost_ff = |y: &[f64]| {
            let t: f64 = (3..=n).map(|m| q * (y[m] - reference[m]).powi(2)).sum();
            t + rows(y, &D3, wj, &reference) + rows(y, &sm.stencil(), ws, &reference)
        };
        // Differences of the two costs are the same constant everywhere
        // the fixed outputs are the reference's.
        let mut y: Vec<f64> = reference.clone();
        let c0 = cost_shifted(&y) - cost_ff(&y);
        for k in 0..5 {
            for m in 3..=n {
                y[m] = reference[m] + ((k * 7 + m * 3) % 11) as f64 * 0.01 - 0.05;
            }
            let c = cost_shifted(&y) - cost_ff(&y);
            assert!((c - c0).abs() <= 1e-9 * c0.abs().max(1.0), "{c} vs {c0}");
        }
    }
}
