//! The problem's shared pieces: the axis problem handed to every solver
//! ([`AxisProblem`]), the checks of its settings and data, the zero-jerk
//! baseline and the warm start's shifted plan. Every solver module takes
//! them from here (not through `optimise`'s re-exports).

use crate::ControlError;

/// Largest horizon accepted \[steps\].
pub const MAX_HORIZON: usize = 100_000;
/// Coefficients of the third difference `Δ³y_j` on `y_j..y_{j+3}`.
pub(crate) const D3: [f64; 4] = [-1.0, 3.0, -3.0, 1.0];

/// A [`ControlError::InvalidSetting`] naming `field`.
pub(crate) fn invalid(field: &'static str, reason: &str) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.to_string(),
    }
}

/// The problem's scalar settings, checked in one place (by the solvers'
/// constructors and by [`crate::dfmpc::DfMpcSettings::validate`]): horizon
/// N in 3..=[`MAX_HORIZON`] \[steps\], tracking weights q ≥ 0 [1/m²], jerk
/// weights r > 0 [s⁶/m²], smoothness weights s ≥ 0 [1/rad²], step δt > 0
/// \[s\] (`None`: not checked here).
pub(crate) fn check_problem(
    horizon: usize,
    q: &[f64],
    r: &[f64],
    s: &[f64],
    dt: Option<f64>,
) -> Result<(), ControlError> {
    if !(3..=MAX_HORIZON).contains(&horizon) {
        return Err(invalid("horizon", "an integer in 3..=100000 (steps)"));
    }
    if !q.iter().all(|q| q.is_finite() && *q >= 0.0) {
        return Err(invalid("tracking_weight", "finite and >= 0 (1/m²)"));
    }
    if !r.iter().all(|r| r.is_finite() && *r > 0.0) {
        return Err(invalid("jerk_weight", "finite and > 0 (s⁶/m²)"));
    }
    if !s.iter().all(|s| s.is_finite() && *s >= 0.0) {
        return Err(invalid("smoothness_weight", "finite and >= 0 (1/rad²)"));
    }
    if let Some(dt) = dt
        && !(dt.is_finite() && dt > 0.0)
    {
        return Err(invalid("dt", "finite and > 0 (s)"));
    }
    Ok(())
}

pub(crate) fn check_lengths(
    horizon: usize,
    reference: &[f64],
    plan: &[f64],
) -> Result<(), ControlError> {
    if reference.len() != horizon + 1 {
        return Err(invalid("reference", "length must be horizon + 1"));
    }
    if plan.len() != horizon + 1 {
        return Err(invalid("plan", "length must be horizon + 1"));
    }
    Ok(())
}

/// The baseline `b_j`, j = 0..=N: the fixed outputs continued with zero
/// third difference (constant second difference).
#[inline]
pub(crate) fn baseline(fixed: &[f64; 3], j: usize) -> f64 {
    let d1 = fixed[1] - fixed[0];
    let d2 = fixed[2] - 2.0 * fixed[1] + fixed[0];
    let jf = j as f64;
    fixed[0] + jf * d1 + 0.5 * jf * (jf - 1.0) * d2
}

/// The next tick's start for its free output f (`y_{f+3}` then): the
/// previous plan `y*_0..y*_N` \[m\] one step on, `y*_{f+4}` (the warm
/// starts of the augmented Lagrangian's solvers). Past the horizon it
/// goes on at its last velocity, or with `hold_acceleration` at its last
/// acceleration. With tilt-rate rows the start holds the acceleration: at
/// its last velocity the plan's acceleration would drop to 0 in one step
/// and break the last tilt-rate row by up to its whole acceleration, and
/// the warm solve's first Newton step would spend itself there
/// (docs/performance-log.md, "The warm start's last output").
#[inline]
pub(crate) fn shifted_plan(previous: &[f64], f: usize, hold_acceleration: bool) -> f64 {
    let horizon = previous.len() - 1;
    let j = f + 4;
    if j <= horizon {
        previous[j]
    } else {
        let (a, b) = (previous[horizon], previous[horizon - 1]);
        if hold_acceleration {
            3.0 * (a - b) + previous[horizon - 2]
        } else {
            2.0 * a - b
        }
    }
}

/// One axis's data for a solver (e.g. [`super::FastBandedSolver::solve_pair`]):
/// `fixed` = `[y_0, y_1, y_2]` \[m\], `reference` = `ref_0..ref_N` \[m\],
/// `plan` receives `y*_0..y*_N`.
#[derive(Debug)]
pub struct AxisProblem<'a> {
    /// The fixed outputs `[y_0, y_1, y_2]` \[m\].
    pub fixed: &'a [f64; 3],
    /// `c_{−1}` [m/s²]: the acceleration the command sent at the previous
    /// tick asks for on this axis (used only with a smoothness weight;
    /// `None`: the fixed window's acceleration, i.e. the first change is
    /// free).
    pub sent: Option<f64>,
    /// The reference `ref_0..ref_N` \[m\] (length N + 1).
    pub reference: &'a [f64],
    /// Output: the optimal `y*_0..y*_N` \[m\] (length N + 1).
    pub plan: &'a mut [f64],
}

impl<'a> AxisProblem<'a> {
    /// The problem without a previously sent command (`sent: None`).
    pub fn new(fixed: &'a [f64; 3], reference: &'a [f64], plan: &'a mut [f64]) -> Self {
        Self {
            fixed,
            sent: None,
            reference,
            plan,
        }
    }

    /// Its parts `(fixed, sent, reference, plan)`, once the reference and
    /// the plan are checked to have `horizon + 1` entries.
    pub(crate) fn checked(self, horizon: usize) -> Result<Parts<'a>, ControlError> {
        check_lengths(horizon, self.reference, self.plan)?;
        Ok((self.fixed, self.sent, self.reference, self.plan))
    }
}

/// Both axes' lengths checked (the pair's solvers).
pub(crate) fn check_pair(
    horizon: usize,
    x: &AxisProblem<'_>,
    y: &AxisProblem<'_>,
) -> Result<(), ControlError> {
    check_lengths(horizon, x.reference, x.plan)?;
    check_lengths(horizon, y.reference, y.plan)
}

/// `Debug` for a solver holding a foreign solver that has none: its
/// name and the fields listed (`debug_without!(Type: field, …)`).
macro_rules! debug_without {
    ($ty:ident: $($field:ident),+) => {
        impl std::fmt::Debug for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.debug_struct(stringify!($ty))
                    $(.field(stringify!($field), &self.$field))+
                    .finish_non_exhaustive()
            }
        }
    };
}
pub(crate) use debug_without;

/// A one-axis solve's parts: `(fixed, sent, reference, plan)`.
pub(crate) type Parts<'a> = (&'a [f64; 3], Option<f64>, &'a [f64], &'a mut [f64]);

impl AxisProblem<'_> {
    /// The same problem, borrowed again (for a solver taking it by value).
    pub fn reborrow(&mut self) -> AxisProblem<'_> {
        AxisProblem {
            fixed: self.fixed,
            sent: self.sent,
            reference: self.reference,
            plan: &mut *self.plan,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::shifted_plan;

    /// The warm start past the horizon: at the last velocity, or at the
    /// last acceleration (a plan at constant acceleration goes on exactly,
    /// and its last change of acceleration, what a tilt-rate row bounds,
    /// stays 0).
    #[test]
    fn the_shifted_plan_goes_on_at_its_last_velocity_or_acceleration() {
        let n = 10;
        let (y0, v, a) = (1.5, -0.3, 0.7);
        let at = |j: f64| y0 + v * j + 0.5 * a * j * j;
        let previous: Vec<f64> = (0..=n).map(|j| at(j as f64)).collect();
        // Inside the horizon: the plan one step on, either way.
        for f in 0..n - 3 {
            for hold in [false, true] {
                assert_eq!(shifted_plan(&previous, f, hold), previous[f + 4]);
            }
        }
        let f = n - 3; // output N + 1
        let held = shifted_plan(&previous, f, true);
        assert!((held - at((n + 1) as f64)).abs() < 1e-12, "{held}");
        let linear = shifted_plan(&previous, f, false);
        let last_velocity = previous[n] - previous[n - 1];
        assert!((linear - (previous[n] + last_velocity)).abs() < 1e-12);
        // The second difference at the end: held, the plan's; at the last
        // velocity, 0 (a drop of the whole acceleration in one step).
        let second = |next: f64| next - 2.0 * previous[n] + previous[n - 1];
        assert!((second(held) - a).abs() < 1e-12);
        assert!(second(linear).abs() < 1e-12);
    }
}
