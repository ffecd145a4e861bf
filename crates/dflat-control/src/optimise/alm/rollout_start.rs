//! The start of a cold solve whose plan leaves its discs at once: the
//! unconstrained plan flown by a saturated tracking law, and the stage
//! multipliers that hold that plan stationary, projected onto each
//! saturated stage's outward normal.
//!
//! A cold solve whose unconstrained plan leaves its disc within the first
//! four stages while the vehicle's present acceleration is within half the
//! first disc (the flight's first tick, from rest; an engagement far from
//! the reference) starts instead from a
//! feasible plan and multipliers that hold it: the unconstrained plan
//! tracked stage by stage by a saturated law (its acceleration, plus
//! ω = 3 rad/s, ζ = 1 feedback towards it, clipped to the disc), and
//! `y = −G⁻ᵀ(P·x + c)` — the multipliers for which that plan is stationary
//! — kept on the stages at their disc's edge, along the outward normal
//! only. σ starts at the cold σ and grows only when the residual stalls.
//! The soft phase from the unconstrained plan leaves multipliers 0.2–0.5
//! of the final ones and the plan far from the constrained one; this
//! start is near both. On the course of corners at N = 200 the flight's
//! first tick went from 26 to 14 Newton steps (the L corner's from 31 to
//! 24). Over 1000 random cold instances in motion it applied to 881: the
//! interior point finished 29 of them instead of 106, and where the
//! augmented Lagrangian solved both ways, 28.6 Newton steps instead of
//! 34.7 (test `the_rollout_start_saves_newton_steps_on_random_cold_instances`
//! prints them).

use super::{BandedAlm, StageSet, lagrangian::Vector};

/// Stages within which the unconstrained plan must leave its disc for the
/// rollout start (the plan binds at once: the flight's first tick, from
/// rest, or an engagement far from the reference).
pub(super) const ROLLOUT_EARLY: usize = 4;
/// Share of the first stage's radius that the vehicle's present
/// acceleration a_0 must stay within. At its disc's edge (a manoeuvre
/// under way) the rollout saturates the whole horizon and starts further
/// from the constrained plan than the unconstrained plan does: on the
/// corner bench at N = 200 with warm starts off, 18.7 → 24.1 Newton steps
/// per solve without this condition, 18.6 with it.
pub(super) const ROLLOUT_A0_SHARE: f64 = 0.5;
/// The tracking law's position gain ω² \[1/s²\] (ω = 3 rad/s).
const ROLLOUT_KP: f64 = 9.0;
/// The tracking law's velocity gain 2ζω \[1/s\] (ζ = 1).
const ROLLOUT_KD: f64 = 6.0;

impl BandedAlm {
    /// Sets the rollout start when the plan held (the unconstrained
    /// optimum, every multiplier 0) leaves its disc within the first
    /// [`ROLLOUT_EARLY`] stages and `‖a_0‖` \[m/s²\] is within
    /// [`ROLLOUT_A0_SHARE`] of the first stage's radius; returns whether
    /// it did. Discs only (intervals: false, nothing changed).
    ///
    /// The plan: stage by stage, the unconstrained plan's acceleration plus
    /// `k_p·(position error) + k_d·(velocity error)` towards it (at the
    /// stage before), clipped to the disc, integrated into the outputs —
    /// feasible, on the disc's edge wherever it lags. The multipliers:
    /// `y = −G⁻ᵀ(P·x + c)` (stationarity at that plan, `Gᵀ` upper
    /// triangular: a backward recursion), on each stage at its edge the
    /// outward part `max(0, ⟨y_f, û_f⟩)·û_f`, 0 elsewhere.
    pub(super) fn rollout_start(&mut self, a0: [f64; 2]) -> bool {
        if !matches!(self.stages, StageSet::Disc(_)) {
            return false;
        }
        // The radii are lent out for the pass (no allocation: an empty
        // Vec in their place).
        let StageSet::Disc(radius) =
            std::mem::replace(&mut self.stages, StageSet::Disc(Vec::new()))
        else {
            unreachable!("the placeholder is a disc")
        };
        let started = self.rollout_pass(a0, &radius);
        self.stages = StageSet::Disc(radius);
        started
    }

    fn rollout_pass(&mut self, a0: [f64; 2], radius: &[f64]) -> bool {
        let n = self.n;
        let o = &self.centre;
        if n == 0 || (a0[0] - o[0][0]).hypot(a0[1] - o[0][1]) > ROLLOUT_A0_SHARE * radius[0] {
            return false;
        }
        let dt2 = 1.0 / self.inv_dt2;
        let dt = dt2.sqrt();
        // Accelerations relative to the disc's centre.
        let outside =
            |u: [f64; 2], o: [f64; 2], r: f64| (u[0] + a0[0] - o[0]).hypot(u[1] + a0[1] - o[1]) > r;
        Self::accelerations(2, self.inv_dt2, &self.ws.x, &mut self.ws.u, 0);
        if !(0..n.min(ROLLOUT_EARLY)).any(|f| outside(self.ws.u[f], self.centre[f], radius[f])) {
            return false;
        }
        // The rollout into d (scratch until the solve's first step), its
        // P·d and multipliers into pd and y_next: x, P·x and y take them
        // only when all are finite.
        let (mut q1, mut q2) = ([0.0; 2], [0.0; 2]);
        let (mut p1, mut p2) = ([0.0; 2], [0.0; 2]);
        for (f, &r) in radius.iter().enumerate().take(n) {
            let q0 = [self.ws.x[2 * f], self.ws.x[2 * f + 1]];
            let mut w = [0.0; 2];
            for i in 0..2 {
                let free = (q0[i] - 2.0 * q1[i] + q2[i]) * self.inv_dt2 + a0[i];
                let position = q1[i] - p1[i];
                let velocity = ((q1[i] - q2[i]) - (p1[i] - p2[i])) / dt;
                w[i] = free + ROLLOUT_KP * position + ROLLOUT_KD * velocity;
            }
            let o = self.centre[f];
            let norm = (w[0] - o[0]).hypot(w[1] - o[1]);
            if norm > r {
                w = [
                    o[0] + (w[0] - o[0]) * r / norm,
                    o[1] + (w[1] - o[1]) * r / norm,
                ];
            }
            let mut p0 = [0.0; 2];
            for i in 0..2 {
                p0[i] = 2.0 * p1[i] - p2[i] + dt2 * (w[i] - a0[i]);
                self.ws.d[2 * f + i] = p0[i];
            }
            (p2, p1, q2, q1) = (p1, p0, q1, q0);
        }
        self.apply_p(Vector::D);
        Self::accelerations(2, self.inv_dt2, &self.ws.d, &mut self.ws.u, 0);
        // Gᵀy = −(P·x + c), (Gᵀy)_f = (y_f − 2y_{f+1} + y_{f+2})/δt².
        let (mut y1, mut y2) = ([0.0; 2], [0.0; 2]);
        for f in (0..n).rev() {
            let mut y = [0.0; 2];
            for i in 0..2 {
                let j = 2 * f + i;
                y[i] = -dt2 * (self.ws.pd[j] + self.ws.c[j]) + 2.0 * y1[i] - y2[i];
            }
            y2 = y1;
            y1 = y;
            let o = self.centre[f];
            let u = [
                self.ws.u[f][0] + a0[0] - o[0],
                self.ws.u[f][1] + a0[1] - o[1],
            ];
            let norm = u[0].hypot(u[1]);
            self.ws.y_next[f] = if norm >= radius[f] * (1.0 - 1e-9) && norm > 0.0 {
                let m = ((y[0] * u[0] + y[1] * u[1]) / norm).max(0.0);
                [m * u[0] / norm, m * u[1] / norm]
            } else {
                [0.0; 2]
            };
        }
        let finite = |v: &[f64]| v.iter().all(|v| v.is_finite());
        if !(finite(&self.ws.d) && finite(&self.ws.pd) && finite(self.ws.y_next.as_flattened())) {
            return false;
        }
        self.ws.x.copy_from_slice(&self.ws.d);
        self.ws.px.copy_from_slice(&self.ws.pd);
        self.ws.px_current = true;
        self.warm.y.copy_from_slice(&self.ws.y_next);
        true
    }
}
