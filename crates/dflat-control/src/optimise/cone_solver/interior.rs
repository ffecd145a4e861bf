//! The interior point's part in the pair's solve: the condensed
//! interior point's start (cold) and restart (after a warm attempt that
//! did not end), the stage interior point as the last banded method, and
//! what they report.

use super::{BandedConeSolver, LATE_ARC_SHARE};
use crate::ControlError;
use crate::optimise::cascade::{Restart, SolverFault};
#[cfg(test)]
use crate::optimise::problem::AxisProblem;

impl BandedConeSolver {
    /// Whether the start held breaks no disc or row before
    /// [`LATE_ARC_SHARE`] of the horizon (a burst's first tick mid-flight,
    /// its arc entering late): its cold solve then tries the augmented
    /// Lagrangian before the interior point.
    pub(super) fn breaks_late(&mut self, a0: [f64; 2]) -> bool {
        self.alm.as_mut().is_some_and(|alm| {
            let first = alm.first_broken_stage(a0, &self.lo, &self.hi);
            first as f64 >= LATE_ARC_SHARE * (self.horizon - 2) as f64
        })
    }

    /// The augmented Lagrangian's start from the condensed interior point,
    /// itself started from the funnel's witness at half the rate (strictly
    /// inside the rate rows); whether it converged (its iterations are
    /// counted in [`BandedConeSolver::iterations`]).
    pub(super) fn interior_start(&mut self, a0: [f64; 2]) -> bool {
        if self.alm.is_none() {
            return false;
        }
        self.start_from_witness();
        let Some(alm) = &mut self.alm else {
            return false;
        };
        alm.set_start(&[&self.p[0], &self.p[1]]);
        match alm.interior_start(&self.c_alm, a0, &self.lo, &self.hi) {
            Ok(Some(iterations)) => {
                self.interior_iterations += iterations;
                true
            }
            _ => {
                // Its iterate is unspecified: the witness is the start.
                alm.set_start(&[&self.p[0], &self.p[1]]);
                false
            }
        }
    }

    /// The condensed interior point restarted from the iterate and the
    /// multipliers a warm solve that did not end left
    /// ([`BandedAlm::interior_restart`]); whether it converged (its
    /// iterations are counted in [`BandedConeSolver::iterations`]; when it
    /// does not, the cold start follows).
    pub(super) fn interior_restart(&mut self, a0: [f64; 2]) -> bool {
        let Some(alm) = &mut self.alm else {
            return false;
        };
        match alm.interior_restart(&self.c_alm, a0, &self.lo, &self.hi) {
            Ok(Some(iterations)) => {
                self.interior_iterations += iterations;
                self.restarted = true;
                true
            }
            _ => false,
        }
    }

    /// Whether the last solve's condensed interior point was restarted
    /// from where its warm attempt stopped (else, if it ran, it started
    /// cold from the funnel's witness).
    pub fn interior_restarted(&self) -> bool {
        self.restarted
    }

    /// The Newton steps of the warm attempt the last solve's interior
    /// point was restarted after (0 when it was not): at most
    /// [`WARM_STEPS_BEFORE_START`](super::WARM_STEPS_BEFORE_START); its first inner solve gives up after
    /// [`WARM_FIRST_INNER_STEPS`](super::WARM_FIRST_INNER_STEPS), or sooner at a blocked line search
    /// (`alm/mod.rs`, `BLOCKED_STEP`).
    pub fn restarted_after(&self) -> usize {
        if self.restarted {
            self.attempt_steps
        } else {
            0
        }
    }

    /// The last solve's counts where its interior point was restarted
    /// from its warm attempt ([`BandedConeSolver::interior_restarted`])
    /// and the augmented Lagrangian ended after it: the attempt's Newton
    /// steps, the interior point's iterations and the Newton steps after
    /// it (`None` otherwise, also where the stage interior point solved).
    pub fn restart_counts(&self) -> Option<Restart> {
        let ended = self.method == super::ConeMethod::Alm;
        (self.restarted && ended).then_some(Restart {
            attempt_steps: self.attempt_steps,
            interior_iterations: self.interior_iterations,
            steps_after: self.steps_after,
        })
    }

    /// Sets the Newton steps a warm solve with tilt-rate rows gets before
    /// the interior point (tests: every warm tick restarted).
    #[cfg(test)]
    pub(crate) fn set_warm_steps_before_start(&mut self, steps: usize) {
        self.warm_steps_before_start = steps;
    }

    /// Loads a tick, runs the augmented Lagrangian from the plan given and
    /// zero multipliers for at most `steps` Newton steps, and restarts the
    /// condensed interior point from where it stopped (tests): whether the
    /// restart converged.
    #[cfg(test)]
    pub(crate) fn interior_restart_after(
        &mut self,
        x: AxisProblem<'_>,
        y: AxisProblem<'_>,
        steps: usize,
    ) -> bool {
        let Ok(a0) = self.load(&x, &y) else {
            return false;
        };
        let Some(alm) = &mut self.alm else {
            return false;
        };
        alm.reset_multipliers();
        alm.set_start(&[&self.p[0], &self.p[1]]);
        alm.set_max_newton_steps(steps);
        let _ = alm.solve(&self.c_alm, a0, &self.lo, &self.hi);
        self.interior_restart(a0)
    }

    /// Loads a tick and runs the condensed interior point's start alone
    /// (tests): whether it converged.
    #[cfg(test)]
    pub(crate) fn interior_start_only(&mut self, x: AxisProblem<'_>, y: AxisProblem<'_>) -> bool {
        match self.load(&x, &y) {
            Ok(a0) => self.interior_start(a0),
            Err(_) => false,
        }
    }

    /// The condensed interior point's iterations in the last solve (the
    /// augmented Lagrangian's start with the tilt-rate rows; 0: none ran).
    pub fn interior_iterations(&self) -> usize {
        self.interior_iterations
    }

    /// The interior point's attempt, from the plan given; on success the
    /// augmented Lagrangian's next start takes its multipliers.
    pub(super) fn try_interior_point(&mut self, a0: [f64; 2]) -> Result<(), ControlError> {
        if self.qp.is_none() {
            return Err(SolverFault::NotConverged {
                iterations: self.iterations,
            }
            .into());
        }
        if self.bounds.tilt_rate.is_some() {
            // As the box's interior point: from the witness, strictly
            // inside the rate rows (the plan given breaks those narrow
            // rows by many times their width).
            self.start_from_witness();
        }
        let Some(qp) = &mut self.qp else {
            return Err(SolverFault::NotConverged {
                iterations: self.iterations,
            }
            .into());
        };
        qp.ip.set_start(&[&self.p[0], &self.p[1]], self.dt);
        let result = qp.solve(&self.c, a0, (&self.lo, &self.hi));
        self.iterations += qp.ip.iterations();
        result?;
        // The next tick's augmented Lagrangian starts from its multipliers
        // (shifted with the plan), not from zero.
        if let Some(alm) = &mut self.alm {
            qp.ip.disc_duals(&mut self.ip_stage_duals);
            qp.ip.duals(&mut self.ip_row_duals);
            let stage = &self.ip_stage_duals;
            alm.set_multipliers(|f| stage[f], &self.ip_row_duals);
        }
        Ok(())
    }

    /// The start `p` (both axes' deviations) from the funnel's witness
    /// at half the rate: strictly inside the rate rows and the discs.
    fn start_from_witness(&mut self) {
        let [px, py] = &mut self.p;
        let fixed = [&self.window[0], &self.window[1]];
        self.bounds.witness_start(
            (&self.radius, &self.centre),
            fixed,
            self.sent,
            self.dt,
            0.5,
            [px, py],
        );
    }
}
