//! The cone's fallback: the two-axis stage QP with the tilt cone
//! ([`super::cone`]) on the banded interior point of
//! [`super::banded_ip`], both horizontal axes in one KKT system,
//! interleaved per stage so that it stays banded ([`ConeQp`]).
//!
//! Per free output f = 0..n−1 and axis i ∈ {x, y}: the deviation `p_{i,f}`,
//! the relative acceleration `ã_{i,f}` and the multiplier `λ_{i,f}` of
//! `Δ²p_{i,f}/δt² − ã_{i,f} = 0`, as [`StageQp`](super::interior_point::StageQp)
//! per axis. Stage order `[λ_x, λ_y, ã_x, ã_y, p_x, p_y]`: λ_f reaches back
//! to p_{f−2} (distance 8), the jerk couples ã_f with ã_{f−1} (6), the
//! smoothness term with ã_{f−2} (12), the cone ã_x with ã_y (1): the KKT
//! matrix has half-bandwidth 8 (12 with smoothness) over 6n rows.
//!
//! The cone is a disc per stage, the speed rows are soft interval rows
//! (or hard, with an infinite penalty), the tilt-rate rows hard interval
//! rows on three ã entries of one axis (distance 12: the band then is
//! 12 wide).
//!
//! Always started cold: the warm path of
//! [`BandedConeSolver`](super::BandedConeSolver) is the
//! augmented Lagrangian ([`super::alm`]), this its fallback.

use super::banded_ip::{AxisCost, BandedIp, Stages};
use super::bounds::{Row, check_solve_data};
use crate::ControlError;

/// Iteration limit: as with the tilt-rate rows
/// ([`super::interior_point::MAX_ITERATIONS_TILT_RATE`]). At 50 a random
/// draw (`cone_centre_tests`: N = 187, a start at 6.1 m/s against a soft
/// 2.9 m/s speed bound, cones about moving centres) stalled for 40
/// iterations and was three short of converging.
pub const MAX_ITERATIONS: usize = 100;
/// The horizontal pair: stage `[λ_x, λ_y, ã_x, ã_y, p_x, p_y]`.
const STAGES: Stages = Stages { axes: 2 };
/// Variables per stage.
pub(super) const STAGE: usize = STAGES.width();

/// KKT index of ã_{axis, f}.
pub(super) fn a_at(axis: usize, f: usize) -> usize {
    STAGES.accel(axis, f)
}
/// KKT index of p_{axis, f}.
pub(super) fn p_at(axis: usize, f: usize) -> usize {
    STAGES.output(axis, f)
}

/// The two-axis cone QP's interior-point solver (module docs).
#[derive(Debug, Clone)]
pub struct ConeQp {
    /// The interior point (its iterate, radius and start are set on it).
    pub(super) ip: BandedIp,
}

impl ConeQp {
    /// A solver for n ≥ 1 free outputs per axis at step δt, cone radius
    /// `limit` = A [m/s²], speed rows with exact penalty ρ when
    /// `speed_penalty` is given (soft: `Some`; `f64::INFINITY`: hard), and
    /// hard tilt-rate rows on ã per axis with `tilt_rate = Some([κ_x,
    /// κ_y])` (`Row::tilt_rate`), in [`ConeBounds::rows`]'s order.
    ///
    /// [`ConeBounds::rows`]: super::cone::ConeBounds
    pub fn new(
        n: usize,
        dt: f64,
        axes: [&AxisCost; 2],
        limit: f64,
        speed_penalty: Option<f64>,
        tilt_rate: Option<[f64; 2]>,
    ) -> Self {
        let mut rows = Vec::new();
        let mut penalty = Vec::new();
        if let Some(rho) = speed_penalty {
            rows.extend(Row::speed_pair(n, dt, p_at));
            penalty.resize(rows.len(), rho);
        }
        if let Some(kappa) = tilt_rate {
            for (axis, k) in kappa.into_iter().enumerate() {
                rows.extend((0..n).map(|f| Row::tilt_rate(f, k, |s| a_at(axis, s))));
            }
            penalty.resize(rows.len(), f64::INFINITY);
        }
        let max_iterations = if tilt_rate.is_some() {
            super::interior_point::MAX_ITERATIONS_TILT_RATE
        } else {
            MAX_ITERATIONS
        };
        let ip = BandedIp::new(n, dt, &axes, rows, penalty, Some(limit), max_iterations);
        Self { ip }
    }

    /// Solves for the linear term `c` (full KKT length: on p and ã; zero on
    /// λ), relative fixed accelerations `a0` [m/s²] (u = ã + a0) and speed
    /// row bounds `lo ≤ g·x ≤ hi`. The primal start must be set
    /// ([`BandedIp::set_start`]); slacks and multipliers start cold. Returns
    /// the iterations.
    pub fn solve(
        &mut self,
        c: &[f64],
        a0: [f64; 2],
        (lo, hi): (&[f64], &[f64]),
    ) -> Result<usize, ControlError> {
        check_solve_data(
            "cone QP",
            (c, STAGE * self.ip.n()),
            self.ip.rows(),
            self.ip.iterate(),
            &a0,
            (lo, hi),
            "c needs 6n entries, lo and hi one per row",
        )?;
        self.ip.linear_mut().copy_from_slice(c);
        self.ip.set_bounds(lo, hi, a0);
        self.ip.solve()
    }
}
