//! The command-smoothness term (module docs of [`crate::optimise`], "Command
//! smoothness"): its stencil in the outputs and its blocks in the bounded
//! solvers' variables.

use super::problem::invalid;
use crate::ControlError;

/// The command-smoothness term of one axis: weight s on
/// `((c_j − c_{j−1})/g)²`, `c_j = a_j + κ·(a_{j+1} − a_j)` (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Smoothness {
    /// Weight s ≥ 0 [1/rad²]; 0 turns the term off.
    pub weight: f64,
    /// κ = τ/δt > 0: the input lag (attitude τ, thrust τ_T) in steps.
    pub kappa: f64,
    /// Gravity g > 0 [m/s²]: accelerations over g are tilts \[rad\].
    pub gravity: f64,
}

impl Smoothness {
    /// Coefficients of `δt²·(c_j − c_{j−1})` on `y_{j−1}..y_{j+3}`.
    pub(crate) fn stencil(&self) -> [f64; 5] {
        let k = self.kappa;
        [k - 1.0, 3.0 - 4.0 * k, 6.0 * k - 3.0, 1.0 - 4.0 * k, k]
    }

    pub(crate) fn check(&self) -> Result<(), ControlError> {
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(invalid("smoothness_weight", "finite and >= 0 (1/rad²)"));
        }
        if self.weight > 0.0
            && !(self.kappa.is_finite()
                && self.kappa > 0.0
                && self.gravity.is_finite()
                && self.gravity > 0.0)
        {
            return Err(invalid("smoothness", "κ and g finite and > 0"));
        }
        Ok(())
    }
}

/// The ã block of the doubled Hessian `P` (objective `½xᵀPx`) in the
/// variables of [`ClarabelSolver`]: the jerk term `(r/δt²)·Σ_j
/// (ã_j − ã_{j−1})²` (ã_{−1} = 0) and the smoothness term (band 2), as
/// `[diagonal, (k−1, k), (k−2, k)]` per column k.
pub(crate) fn accel_block(n: usize, r: f64, dt: f64, smoothness: &Smoothness) -> Vec<[f64; 3]> {
    let ja = 2.0 * r / (dt * dt);
    let mut band = vec![[0.0f64; 3]; n];
    for (k, col) in band.iter_mut().enumerate() {
        col[0] = if k + 1 < n { 2.0 * ja } else { ja };
        if k > 0 {
            col[1] = -ja;
        }
    }
    if smoothness.weight > 0.0 {
        let sg = 2.0 * smoothness.weight / smoothness.gravity.powi(2);
        let kp = smoothness.kappa;
        let coeffs = [kp, 1.0 - 2.0 * kp, -(1.0 - kp)]; // on ã_j, ã_{j−1}, ã_{j−2}
        for j in 0..n {
            for (da, &ca) in coeffs.iter().enumerate() {
                let Some(a) = j.checked_sub(da) else { continue };
                for (db, &cb) in coeffs.iter().enumerate().skip(da) {
                    let Some(b) = j.checked_sub(db) else { continue };
                    // a ≥ b: entry (b, a) of the upper triangle.
                    band[a][a - b] += sg * ca * cb;
                }
            }
        }
    }
    band
}

/// The smoothness term's linear coefficient on ã_0 (objective `½xᵀPx +
/// cᵀx`, [`ClarabelSolver`]'s variables): `2s/g²·κ·(a_0 − c_{−1})`
/// with the sent command's acceleration c_{−1}; 0 without either.
pub(crate) fn sent_linear_term(
    sm: &Smoothness,
    fixed: &[f64; 3],
    sent: Option<f64>,
    dt: f64,
) -> f64 {
    match sent {
        Some(c) if sm.weight > 0.0 => {
            let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
            2.0 * sm.weight / sm.gravity.powi(2) * sm.kappa * (a0 - c)
        }
        _ => 0.0,
    }
}
