//! The tilt-rate bound: the command's change per tick, bounded in the plan
//! (derivation and what it costs in exactness: `docs/controllers.md`,
//! "The tilt-rate bound").
//!
//! Per horizontal axis, with `a_j = Δ²y_j/δt²` the planned accelerations
//! (a_0 fixed by the window), κ = τ/δt, k̃ the attitude gain and the
//! per-axis tilt `t(a) = atan(a/g)` (the pitch of the x axis up to its
//! sign at zero yaw, the roll of the y axis up to `1/cos θ`), the planar
//! model's F gives the command of stage j as
//!
//! ```text
//! k̃·θ_cmd,j = t(a_j) + κ·(t(a_{j+1}) − t(a_j))
//! ```
//!
//! and the acceleration the command asks for is `c = g·tan(k̃·θ_cmd)`.
//! The bound `|θ_cmd,j − θ_cmd,j−1| ≤ ω·δt` becomes:
//!
//! * **stage 0, exact in t:** θ_cmd,−1 is the command SENT at k−1 (after
//!   saturation), a constant, and t(a_0) is fixed, so the bound is an
//!   interval on t(a_1) alone, mapped through the monotone `g·tan`: one
//!   single-entry row on a_1 ([`TiltRate::first_stage`]).
//! * **stages j ≥ 1, linearised about hover:** t(a) ≈ a/g, so
//!   `|c_j − c_{j−1}| ≤ B = g·k̃·ω·δt` with `c_j = a_j + κ·(a_{j+1} − a_j)`,
//!   i.e. `|κ·a_{j+1} + (1 − 2κ)·a_j − (1 − κ)·a_{j−1}| ≤ B`: three entries.
//!   At tilt θ the true step of these stages is about cos²θ times the
//!   linearised one (0.67 at 35°): conservative there. Only stage 0 is
//!   sent; the later stages shape the plan.
//!
//! **Funnel.** With an acceleration (tilt) bound as well, a window whose
//! attitude or sent command lies outside it cannot be brought inside at
//! once by a rate-limited command, and the two bounds together would be
//! infeasible. A witness trajectory — the command moved from the sent one
//! towards the nearest value in the acceleration bound at the rate bound,
//! the accelerations its first-order response `a_{j+1} = a_j + (c_j −
//! a_j)/κ` — satisfies every tilt-rate row by construction; the
//! acceleration bound of stage j is widened to contain it
//! (`TiltRate::funnel`), so the problem stays feasible (the witness is a
//! feasible point) and the bound is the plain one once the witness is in.

use super::problem::invalid;
use crate::ControlError;

/// Largest per-axis tilt the first-stage interval maps through `tan`
/// \[rad\] (80°): beyond it the interval is clipped.
const MAX_AXIS_TILT: f64 = 1.396;

/// The tilt-rate bound of one horizontal axis (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TiltRate {
    /// Largest change of the command per tick \[rad\]: `max_tilt_rate·δt`.
    pub step: f64,
    /// κ = τ/δt > 0: the attitude lag in steps.
    pub kappa: f64,
    /// The attitude gain k̃ > 0 (the attitude settles to k̃·θ_cmd).
    pub gain: f64,
    /// Gravity g > 0 \[m/s²\].
    pub gravity: f64,
}

impl TiltRate {
    /// Checks the fields (finite and > 0); the error names `max_tilt_rate`.
    pub fn check(&self) -> Result<(), ControlError> {
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(self.step) && ok(self.kappa) && ok(self.gain) && ok(self.gravity)) {
            return Err(invalid(
                "max_tilt_rate",
                "rate·δt, κ, k̃ and g finite and > 0",
            ));
        }
        Ok(())
    }

    /// B = g·k̃·ω·δt [m/s²]: the linearised bound on `|c_j − c_{j−1}|`,
    /// stages j ≥ 1.
    pub fn accel_step(&self) -> f64 {
        self.gravity * self.gain * self.step
    }

    /// The per-axis tilt `atan(a/g)` \[rad\] of acceleration `a` [m/s²].
    fn tilt(&self, a: f64) -> f64 {
        (a / self.gravity).atan()
    }

    /// The interval `[lo, hi]` [m/s²] of the first planned acceleration
    /// a_1 that keeps the first command within `step` of the sent one:
    /// `a0` the window's acceleration, `sent` the acceleration the command
    /// sent at k−1 asks for (`None`: the command holding a0) [m/s²].
    pub fn first_stage(&self, a0: f64, sent: Option<f64>) -> (f64, f64) {
        let t0 = self.tilt(a0);
        let ts = sent.map_or(t0, |c| self.tilt(c));
        let k = self.kappa;
        let w = self.gain * self.step;
        let at = |t: f64| {
            let t1 = (t - (1.0 - k) * t0) / k;
            self.gravity * t1.clamp(-MAX_AXIS_TILT, MAX_AXIS_TILT).tan()
        };
        (at(ts - w), at(ts + w))
    }

    /// The tilt-rate rows' bounds `(lo, hi)` in row order f = 0..N−3 on the
    /// deviation accelerations ã_f = a_{f+1} − a_0 ([`super::bounds`]'s
    /// row layout): f = 0 the first-stage interval, f ≥ 1 `±B`.
    pub(crate) fn rows(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        sent: Option<f64>,
        dt: f64,
        mut out: impl FnMut(f64, f64),
    ) {
        let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        let (lo, hi) = self.first_stage(a0, sent);
        out(lo - a0, hi - a0);
        let b = self.accel_step();
        for _ in 1..horizon - 2 {
            out(-b, b);
        }
    }

    /// The witness trajectory's accelerations a_1..a_{N−2} [m/s²] that
    /// widen the stages' bounds (module docs): each stage's interval, `[lo,
    /// hi]` as the caller moves it per stage, widened to include it.
    pub(crate) fn funnel(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        sent: Option<f64>,
        [lo, hi]: [f64; 2],
        dt: f64,
        out: impl FnMut(f64),
    ) {
        self.witness(horizon, fixed, sent, Some([lo, hi]), dt, 1.0, out);
    }

    /// The witness trajectory's accelerations a_1..a_{N−2} [m/s²] into
    /// `out` (module docs): the command moved from the sent one towards
    /// the nearest value in `bound` (none: the sent one) at `shrink`·B per
    /// tick, the first acceleration in the middle `shrink` share of the
    /// first-stage interval. `shrink` = 1: the funnel's witness, on the
    /// rows' boundary while it ramps; < 1: strictly inside the rate rows
    /// (the interior point's start).
    #[allow(clippy::too_many_arguments)] // the problem's data, as `funnel`
    pub(crate) fn witness(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        sent: Option<f64>,
        bound: Option<[f64; 2]>,
        dt: f64,
        shrink: f64,
        out: impl FnMut(f64),
    ) {
        let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        let c_prev = sent.unwrap_or(a0);
        let target = bound.map_or(c_prev, |[lo, hi]| c_prev.clamp(lo, hi));
        self.witness_toward(horizon, fixed, sent, dt, shrink, |_| target, out);
    }

    /// As [`TiltRate::witness`], the command moved towards `target(v)`
    /// [m/s²], v the witness's speed [m/s] before the stage (v_1 = (y_2 −
    /// y_1)/δt, then `v_{j+1} = v_j + a_j·δt`): a target that brakes
    /// while the speed is above a bound (the cone's speed funnel).
    #[allow(clippy::too_many_arguments)] // the problem's data, as `funnel`
    pub(crate) fn witness_toward(
        &self,
        horizon: usize,
        fixed: &[f64; 3],
        sent: Option<f64>,
        dt: f64,
        shrink: f64,
        mut target: impl FnMut(f64) -> f64,
        mut out: impl FnMut(f64),
    ) {
        let a0 = (fixed[2] - 2.0 * fixed[1] + fixed[0]) / (dt * dt);
        let mut v = (fixed[2] - fixed[1]) / dt;
        let c_prev = sent.unwrap_or(a0);
        let b = shrink * self.accel_step();
        let k = self.kappa;
        let toward = |c: f64, t: f64| c + (t - c).clamp(-b, b);
        let (l1, h1) = self.first_stage(a0, sent);
        let (mid, half) = (0.5 * (l1 + h1), 0.5 * shrink * (h1 - l1));
        let mut a = (a0 + (toward(c_prev, target(v)) - a0) / k).clamp(mid - half, mid + half);
        let mut c = a0 + k * (a - a0);
        out(a);
        for _ in 1..horizon - 2 {
            v += a * dt;
            c = toward(c, target(v));
            a += (c - a) / k;
            out(a);
        }
    }

    /// True when `plan` (`y_0..y_N` \[m\], step δt \[s\]; `sent` as in
    /// [`TiltRate::first_stage`]) breaks a tilt-rate row by more than a
    /// relative 1e-6 (absolute 1e-9).
    pub fn violated_by(&self, plan: &[f64], sent: Option<f64>, dt: f64) -> bool {
        let n = plan.len();
        if n < 4 {
            return false;
        }
        let dt2 = dt * dt;
        let a = |j: usize| (plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / dt2;
        let tol = |b: f64| 1e-6 * b.abs() + 1e-9;
        let (lo, hi) = self.first_stage(a(0), sent);
        let a1 = a(1);
        if a1 > hi + tol(hi) || a1 < lo - tol(lo) {
            return true;
        }
        let b = self.accel_step();
        let k = self.kappa;
        (1..n - 3).any(|j| {
            let dc = k * a(j + 1) + (1.0 - 2.0 * k) * a(j) - (1.0 - k) * a(j - 1);
            dc.abs() > b + tol(b)
        })
    }

    /// The command's change per tick \[rad\] through the per-axis tilt, as
    /// F computes it: stage j's command `(t(a_j) + κ·(t(a_{j+1}) −
    /// t(a_j)))/k̃` minus the previous one (stage 0: minus the sent one),
    /// j = 0..N−3, into `out` (the exactness check of tests and docs).
    pub fn command_steps(&self, plan: &[f64], sent: Option<f64>, dt: f64, out: &mut Vec<f64>) {
        out.clear();
        let n = plan.len();
        if n < 4 {
            return;
        }
        let dt2 = dt * dt;
        let t = |j: usize| self.tilt((plan[j + 2] - 2.0 * plan[j + 1] + plan[j]) / dt2);
        let cmd = |j: usize| (t(j) + self.kappa * (t(j + 1) - t(j))) / self.gain;
        let mut prev = sent.map_or(t(0) / self.gain, |c| self.tilt(c) / self.gain);
        for j in 0..n - 3 {
            let c = cmd(j);
            out.push(c - prev);
            prev = c;
        }
    }
}
