//! The constrained plan's solvers behind two narrow interfaces — one
//! axis's problem ([`AxisSolver`]: the box, its rows) and the horizontal
//! pair's ([`PairSolver`]: the tilt cone) — and the fallback cascade as
//! data ([`Cascade`]): an ordered list of solvers of one problem, tried
//! in turn until one converges. A solve reports what it did
//! ([`SolveInfo`]) or why it gave no plan ([`SolveFailure`]).
//!
//! DF-MPC builds two kinds of cascade (`dfmpc/solve.rs`): per axis with
//! box bounds `[BoxAlmSolver, BandedInteriorPointSolver, ClarabelSolver]`,
//! and for the horizontal pair with the tilt cone `[BandedConeSolver
//! (augmented Lagrangian), BandedConeSolver (interior point),
//! ClarabelConeSolver]` (with `qp_solver = clarabel`, clarabel alone).
//! Each solver implements its interface in its own module.

use super::problem::AxisProblem;
use crate::ControlError;

/// The method of a constrained solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolverMethod {
    /// The augmented Lagrangian on the banded free outputs ([`super::alm`]).
    Alm,
    /// The active-set method on the compact KKT system
    /// ([`super::active_set`]: one axis with rows, the tilt rate's).
    ActiveSet,
    /// A banded primal-dual interior point.
    InteriorPoint,
    /// clarabel (a general conic interior point).
    Clarabel,
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SolveInfo {
    /// The method that solved.
    pub method: SolverMethod,
    /// Its iterations (Newton steps, KKT solves of the active set, or
    /// interior-point iterations; 0 where it does not count them).
    pub iterations: usize,
    /// Its factorisations (0 where it does not count them).
    pub factorisations: usize,
    /// Whether it started from the previous tick's solution.
    pub warm_started: bool,
    /// Whether its solution was a relaxation's optimum that kept the
    /// dropped constraints (the cone with the tilt rate: the pair solved
    /// without its tilt-rate rows first, `cone_solver/relaxation.rs`).
    pub relaxed: bool,
    /// Where a warm attempt that did not end was followed by the
    /// condensed interior point restarted from it, and the augmented
    /// Lagrangian after it (the cone with the tilt rate): their counts.
    pub restart: Option<Restart>,
}

/// The counts of a solve whose warm attempt gave up, whose condensed
/// interior point restarted from where it stopped, and whose augmented
/// Lagrangian then ended from the interior point's solution
/// (`cone_solver/interior.rs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Restart {
    /// Newton steps of the warm attempt given up.
    pub attempt_steps: usize,
    /// The interior point's iterations.
    pub interior_iterations: usize,
    /// Newton steps of the augmented Lagrangian after it.
    pub steps_after: usize,
}

impl SolveInfo {
    /// A solve by `method` that counts nothing.
    pub fn of(method: SolverMethod) -> Self {
        Self {
            method,
            iterations: 0,
            factorisations: 0,
            warm_started: false,
            relaxed: false,
            restart: None,
        }
    }
}

impl std::fmt::Display for SolverMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Alm => "augmented Lagrangian",
            Self::ActiveSet => "active set",
            Self::InteriorPoint => "interior point",
            Self::Clarabel => "clarabel",
        })
    }
}

/// Why a constrained solver gave no plan: its outcome as a value (never
/// a string), carried by [`ControlError::Solver`] and
/// [`SolveFailure::Failed`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SolverFault {
    /// No convergence within the method's budget of iterations (Newton
    /// steps, KKT solves, interior-point iterations, multiplier updates).
    #[error("no convergence in {iterations} iterations")]
    NotConverged {
        /// The iterations spent when it gave up.
        iterations: usize,
    },
    /// The line search found no descent along the Newton direction
    /// (`slope`: the directional derivative, ≥ 0).
    #[error("no descent (slope {slope:.1e})")]
    NoDescent {
        /// The merit's directional derivative along the step.
        slope: f64,
    },
    /// A warm start's step was cut to `alpha` by the line search: the
    /// warm start is given up for a cold one.
    #[error("the warm start's step is blocked (step length {alpha:.1e})")]
    WarmStepBlocked {
        /// The step length the line search reached.
        alpha: f64,
    },
    /// A warm start's active set was far from the optimum's: the warm
    /// start is given up for a cold one.
    #[error("the warm start's set is far from the optimum's")]
    WarmSetFar,
    /// The active set met a constraint dependent on those already active
    /// that cannot be met with them.
    #[error("a dependent constraint cannot be met")]
    DependentConstraint,
    /// The active set's refined solution broke a bound.
    #[error("the refined solution breaks a bound")]
    BoundBroken,
    /// An iterate or the solution held NaN or infinite values.
    #[error("non-finite iterate or solution")]
    NonFinite,
    /// A factorisation met a pivot not of its sign, or not finite.
    #[error("a factorisation failed")]
    Factorisation,
    /// clarabel ended with another status than `Solved`.
    #[error("status {0:?}")]
    Clarabel(clarabel::solver::SolverStatus),
    /// OSQP (the corner bench's anchor, feature `osqp-bench`) ended with
    /// another status than `Solved`, named.
    #[error("OSQP status {0}")]
    Osqp(&'static str),
    /// An external solver (clarabel; OSQP on the bench) refused its
    /// set-up or an update of its data.
    #[error("the solver refused its set-up")]
    SetupRefused,
    /// No solver of the cascade tried the problem (each passed it on).
    #[error("no solver of the cascade solved")]
    NoSolver,
}

impl From<SolverFault> for ControlError {
    /// The fault of a solver whose method its caller names
    /// ([`SolveFailure::from_error`]).
    fn from(fault: SolverFault) -> Self {
        ControlError::Solver {
            method: None,
            fault,
        }
    }
}

/// Why a solve gave no plan.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveFailure {
    /// The method failed after `iterations`, for `fault`.
    #[error("{method}: {fault}")]
    Failed {
        /// The method.
        method: SolverMethod,
        /// Its iterations when it gave up (0 where it does not count).
        iterations: usize,
        /// Why.
        fault: SolverFault,
    },
    /// The problem's data or the solver's set-up are invalid.
    #[error(transparent)]
    Invalid(ControlError),
    /// A solver placed to observe the problem only (the corner bench's
    /// OSQP anchor): the cascade goes on.
    #[error("an observer: passes the problem on")]
    Observer,
}

impl SolveFailure {
    /// The failure of `method` after `iterations` from the error its own
    /// code returned: a solver's fault stays that fault, a failed
    /// factorisation ([`ControlError::NotPositiveDefinite`]) is
    /// [`SolverFault::Factorisation`], and any other error (an invalid
    /// setting, data the problem refused) is [`SolveFailure::Invalid`].
    pub fn from_error(method: SolverMethod, iterations: usize, e: ControlError) -> Self {
        let fault = match e {
            ControlError::Solver { fault, .. } => fault,
            ControlError::NotPositiveDefinite => SolverFault::Factorisation,
            e => return Self::Invalid(e),
        };
        Self::Failed {
            method,
            iterations,
            fault,
        }
    }
}

/// What carries between ticks, told to each solver of a cascade.
#[derive(Debug, Clone, Copy)]
pub enum Carry<'a> {
    /// A later solver of the cascade solved this tick: `plans` (one per
    /// axis of the problem) are the accepted solution, `duals` that
    /// solver's rows' multipliers ([`AxisSolver::row_duals`]), a warm
    /// start for the next tick.
    Accepted {
        /// The accepted plans `y*_0..y*_N` \[m\], one per axis.
        plans: &'a [&'a [f64]],
        /// Its rows' multipliers `[upper, lower]` (empty: none).
        duals: &'a [[f64; 2]],
    },
    /// A tick that did not need the constrained plan.
    Skipped,
    /// A controller reset: forget everything carried.
    Reset,
}

/// A solver of one axis's constrained plan.
pub trait AxisSolver: std::fmt::Debug + Send {
    /// Solves `axis` in place: its `plan` holds a start on entry (the fast
    /// path's plan) and the solution on success; on a failure it is
    /// unchanged or holds the start.
    fn solve(&mut self, axis: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure>;

    /// What carries between ticks (a solver that keeps no warm start
    /// ignores it).
    fn carry(&mut self, event: Carry<'_>);

    /// Its rows' multipliers `[upper, lower]` after its last solve, in
    /// `AxisBounds::row_bounds`' order (empty when it does not give them).
    fn row_duals(&self) -> &[[f64; 2]];

    /// This tick's offset of the plan's acceleration from the thrust's
    /// ([`super::AxisBounds::offset`]) and its change per stage
    /// ([`super::AxisBounds::offset_slope`]) for the next solves (a solver
    /// without an acceleration bound ignores them).
    fn set_offset(&mut self, offset: Option<f64>, slope: f64);
}

/// A solver of the horizontal pair's constrained plan (the tilt cone).
pub trait PairSolver: std::fmt::Debug + Send {
    /// Solves the pair in place (plans as [`AxisSolver::solve`]).
    fn solve(&mut self, x: AxisProblem<'_>, y: AxisProblem<'_>) -> Result<SolveInfo, SolveFailure>;

    /// What carries between ticks (as [`AxisSolver::carry`]).
    fn carry(&mut self, event: Carry<'_>);

    /// Sets the tilt cone's radius per stage [m/s²] for the next solves.
    fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError>;

    /// Sets the tilt cone's centre per stage [m/s²] for the next solves
    /// (the disc bounds the plan's acceleration less it: the thrust's).
    fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError>;
}

/// An ordered list of solvers of one problem (`S`: `dyn AxisSolver` or
/// `dyn PairSolver`), tried in turn until one converges (the fallback
/// cascade, as data).
#[derive(Debug)]
pub struct Cascade<S: ?Sized> {
    solvers: Vec<Box<S>>,
    /// Which solver solved the last tick the cascade ran, and how.
    solved_by: Option<(usize, SolveInfo)>,
}

/// One axis's cascade.
pub type AxisCascade = Cascade<dyn AxisSolver>;
/// The horizontal pair's cascade.
pub type PairCascade = Cascade<dyn PairSolver>;

/// What every solver of a cascade is told between ticks (both
/// interfaces' `carry`).
pub trait Carries {
    /// Tells the solver `event`.
    fn tell(&mut self, event: Carry<'_>);
}

impl Carries for dyn AxisSolver {
    fn tell(&mut self, event: Carry<'_>) {
        self.carry(event);
    }
}

impl Carries for dyn PairSolver {
    fn tell(&mut self, event: Carry<'_>) {
        self.carry(event);
    }
}

impl<S: ?Sized + Carries> Cascade<S> {
    /// A tick that did not need the constrained plan (every solver).
    pub fn skip(&mut self) {
        self.solved_by = None;
        self.solvers.iter_mut().for_each(|s| s.tell(Carry::Skipped));
    }

    /// A controller reset (every solver).
    pub fn reset(&mut self) {
        self.solved_by = None;
        self.solvers.iter_mut().for_each(|s| s.tell(Carry::Reset));
    }
}

impl Cascade<dyn AxisSolver> {
    /// Sets this tick's [`super::AxisBounds::offset`] and
    /// [`super::AxisBounds::offset_slope`] in every solver
    /// ([`AxisSolver::set_offset`]).
    pub fn set_offset(&mut self, offset: Option<f64>, slope: f64) {
        self.solvers
            .iter_mut()
            .for_each(|s| s.set_offset(offset, slope));
    }
}

impl<S: ?Sized> Cascade<S> {
    /// The cascade of `solvers`, in order (at least one).
    pub fn new(solvers: Vec<Box<S>>) -> Result<Self, ControlError> {
        if solvers.is_empty() {
            return Err(super::problem::invalid("cascade", "at least one solver"));
        }
        Ok(Self {
            solvers,
            solved_by: None,
        })
    }

    /// Inserts `solver` at `place` (0: first; at most the number of
    /// solvers). A solver that returns [`SolveFailure::Observer`] passes
    /// the tick on to the next: the corner bench inserts one first that
    /// times another method on the same problem and leaves the plan to
    /// the cascade.
    pub fn insert(&mut self, place: usize, solver: Box<S>) -> Result<(), ControlError> {
        if place > self.solvers.len() {
            return Err(super::problem::invalid(
                "cascade",
                "a place within the cascade",
            ));
        }
        self.solvers.insert(place, solver);
        self.solved_by = None;
        Ok(())
    }

    /// The solver that solved the last tick the cascade ran: its place
    /// and what it did.
    pub fn solved_by(&self) -> Option<(usize, SolveInfo)> {
        self.solved_by
    }

    /// The solvers, in order.
    pub fn solvers(&self) -> impl Iterator<Item = &S> {
        self.solvers.iter().map(|s| s.as_ref())
    }

    /// Tries `solve` on each solver in turn; the first that converges is
    /// the cascade's (its place and what it did). The last failure is
    /// the cascade's error.
    fn run(
        &mut self,
        mut solve: impl FnMut(&mut S) -> Result<SolveInfo, SolveFailure>,
    ) -> Result<(usize, SolveInfo), ControlError> {
        self.solved_by = None;
        let mut failure = None;
        for i in 0..self.solvers.len() {
            match solve(&mut self.solvers[i]) {
                Ok(info) => {
                    self.solved_by = Some((i, info));
                    return Ok((i, info));
                }
                Err(SolveFailure::Observer) => {}
                Err(e) => failure = Some(e),
            }
        }
        Err(match failure {
            Some(SolveFailure::Invalid(e)) => e,
            Some(SolveFailure::Failed { method, fault, .. }) => ControlError::Solver {
                method: Some(method),
                fault,
            },
            Some(SolveFailure::Observer) | None => SolverFault::NoSolver.into(),
        })
    }
}

impl Cascade<dyn AxisSolver> {
    /// Tries each solver in turn on `axis`; returns what the one that
    /// converged did. The solvers before it are told the solution and
    /// its rows' multipliers ([`Carry::Accepted`]).
    pub fn solve(&mut self, mut axis: AxisProblem<'_>) -> Result<SolveInfo, ControlError> {
        let (i, info) = self.run(|s| s.solve(axis.reborrow()))?;
        let (earlier, rest) = self.solvers.split_at_mut(i);
        let plans = [&*axis.plan];
        let event = Carry::Accepted {
            plans: &plans,
            duals: rest[0].row_duals(),
        };
        earlier.iter_mut().for_each(|s| s.carry(event));
        Ok(info)
    }
}

impl Cascade<dyn PairSolver> {
    /// Tries each solver in turn on the pair; returns what the one that
    /// converged did. The solvers before it are told the solution
    /// ([`Carry::Accepted`]).
    pub fn solve(
        &mut self,
        mut x: AxisProblem<'_>,
        mut y: AxisProblem<'_>,
    ) -> Result<SolveInfo, ControlError> {
        let (i, info) = self.run(|s| s.solve(x.reborrow(), y.reborrow()))?;
        let plans = [&*x.plan, &*y.plan];
        let event = Carry::Accepted {
            plans: &plans,
            duals: &[],
        };
        self.solvers[..i].iter_mut().for_each(|s| s.carry(event));
        Ok(info)
    }

    /// Sets the tilt cone's radius per stage on every solver.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        self.solvers
            .iter_mut()
            .try_for_each(|s| s.set_radius(radius))
    }

    /// Sets the tilt cone's centre per stage on every solver (each checks
    /// it before it changes anything; all of one horizon, the first
    /// refuses what any would).
    pub fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        self.solvers
            .iter_mut()
            .try_for_each(|s| s.set_centre(centre))
    }
}
