//! The constrained plan's solvers behind one interface
//! ([`ConstrainedSolver`]), and the fallback cascade as data
//! ([`Cascade`]): an ordered list of solvers of one problem, tried in turn
//! until one converges.
//!
//! DF-MPC builds two cascades (`dfmpc/solve.rs`): per axis with box bounds
//! `[BoxAlmSolver, BandedInteriorPointSolver, ClarabelSolver]`, and for the
//! horizontal pair with the tilt cone `[BandedConeSolver (augmented
//! Lagrangian), BandedConeSolver (interior point), ClarabelConeSolver]`
//! (with `qp_solver = clarabel`, clarabel alone). The augmented Lagrangian
//! ([`super::alm`]) serves both families first.

use super::box_alm::BoxAlmSolver;
use super::clarabel::ClarabelSolver;
use super::clarabel_cone::ClarabelConeSolver;
use super::cone_solver::{BandedConeSolver, ConeMethod};
use super::interior_point::BandedInteriorPointSolver;
use super::problem::AxisProblem;
use crate::ControlError;

/// The method of a constrained solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolverMethod {
    /// The augmented Lagrangian on the banded free outputs ([`super::alm`]).
    Alm,
    /// A banded primal-dual interior point.
    InteriorPoint,
    /// clarabel (a general conic interior point).
    Clarabel,
}

/// One solver of a constrained plan: one axis (box bounds) or the
/// horizontal pair (the tilt cone).
pub trait ConstrainedSolver: std::fmt::Debug + Send {
    /// Its method.
    fn method(&self) -> SolverMethod;

    /// How many axes its problem has (1 or 2).
    fn axes(&self) -> usize;

    /// Solves the problem of `axes` (`axes()` of them) in place: each
    /// `plan` holds a start on entry (the fast path's plan) and the
    /// solution on success. On an error the plans are unchanged or hold
    /// the start; the error says it did not converge.
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError>;

    /// Iterations of its last solve (Newton steps or interior-point
    /// iterations).
    fn iterations(&self) -> usize;

    /// Factorisations of its last solve (0 where it does not count them).
    fn factorisations(&self) -> usize {
        0
    }

    /// Whether its last solve started from the previous tick's solution.
    fn warm_started(&self) -> bool {
        false
    }

    /// Its rows' multipliers `[upper, lower]` after its last solve, in
    /// `AxisBounds::row_bounds`' order
    /// (empty when it does not give them).
    fn row_duals(&self) -> &[[f64; 2]] {
        &[]
    }

    /// A later solver of the cascade solved the tick: `axes`' plans are
    /// the accepted solution and `duals` that solver's
    /// [`ConstrainedSolver::row_duals`], a warm start for this solver's
    /// next tick.
    fn accept(&mut self, _axes: &[AxisProblem<'_>], _duals: &[[f64; 2]]) {}

    /// A tick that did not need the constrained plan.
    fn skip(&mut self) {}

    /// Forgets everything carried between ticks (a controller reset).
    fn reset(&mut self) {}

    /// Sets the tilt cone's radius per stage [m/s²] (the cone's solvers;
    /// the box's ignore it).
    fn set_radius(&mut self, _radius: &[f64]) -> Result<(), ControlError> {
        Ok(())
    }
}

/// An ordered list of solvers of one problem, tried in turn until one
/// converges (the fallback cascade, as data).
#[derive(Debug)]
pub struct Cascade {
    solvers: Vec<Box<dyn ConstrainedSolver>>,
    /// Which solver solved the last tick it ran (index).
    solved_by: Option<usize>,
}

impl Cascade {
    /// The cascade of `solvers`, in order (at least one, all of one
    /// problem size).
    pub fn new(solvers: Vec<Box<dyn ConstrainedSolver>>) -> Result<Self, ControlError> {
        let Some(first) = solvers.first() else {
            return Err(super::problem::invalid("cascade", "at least one solver"));
        };
        if solvers.iter().any(|s| s.axes() != first.axes()) {
            return Err(super::problem::invalid(
                "cascade",
                "solvers of one problem size",
            ));
        }
        Ok(Self {
            solvers,
            solved_by: None,
        })
    }

    /// Inserts `solver` at `place` (0: first; at most the number of
    /// solvers) — a solver of the same problem size. A solver that returns
    /// an error from its `solve` passes the tick on to the next: the corner
    /// bench inserts one first that times another method on the same
    /// problem and leaves the plan to the cascade.
    pub fn insert(
        &mut self,
        place: usize,
        solver: Box<dyn ConstrainedSolver>,
    ) -> Result<(), ControlError> {
        if place > self.solvers.len() {
            return Err(super::problem::invalid(
                "cascade",
                "a place within the cascade",
            ));
        }
        if solver.axes() != self.solvers[0].axes() {
            return Err(super::problem::invalid(
                "cascade",
                "solvers of one problem size",
            ));
        }
        self.solvers.insert(place, solver);
        self.solved_by = None;
        Ok(())
    }

    /// Tries each solver in turn; returns the method of the one that
    /// converged. The solvers before it are told the solution
    /// ([`ConstrainedSolver::accept`]). The last solver's error is the
    /// cascade's.
    pub fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<SolverMethod, ControlError> {
        self.solved_by = None;
        let mut error = None;
        for i in 0..self.solvers.len() {
            match self.solvers[i].solve(axes) {
                Ok(()) => {
                    self.solved_by = Some(i);
                    let (earlier, rest) = self.solvers.split_at_mut(i);
                    let duals = rest[0].row_duals();
                    for solver in earlier {
                        solver.accept(axes, duals);
                    }
                    return Ok(self.solvers[i].method());
                }
                Err(e) => error = Some(e),
            }
        }
        Err(error.unwrap_or_else(|| ControlError::Solver("empty cascade".to_string())))
    }

    /// A tick that did not need the constrained plan (every solver).
    pub fn skip(&mut self) {
        self.solved_by = None;
        self.solvers.iter_mut().for_each(|s| s.skip());
    }

    /// A controller reset (every solver).
    pub fn reset(&mut self) {
        self.solved_by = None;
        self.solvers.iter_mut().for_each(|s| s.reset());
    }

    /// Sets the tilt cone's radius per stage on every solver.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        self.solvers
            .iter_mut()
            .try_for_each(|s| s.set_radius(radius))
    }

    /// The solvers, in order.
    pub fn solvers(&self) -> impl Iterator<Item = &dyn ConstrainedSolver> {
        self.solvers.iter().map(|s| s.as_ref())
    }

    /// The solver that solved the last tick the cascade ran, and its
    /// place in the cascade.
    pub fn solved_by(&self) -> Option<(usize, &dyn ConstrainedSolver)> {
        self.solved_by.map(|i| (i, self.solvers[i].as_ref()))
    }
}

/// The one axis of a per-axis solver's problem.
fn one<'a, 'b>(axes: &'a mut [AxisProblem<'b>]) -> Result<&'a mut AxisProblem<'b>, ControlError> {
    match axes {
        [a] => Ok(a),
        _ => Err(super::problem::invalid("axes", "one axis")),
    }
}

/// The two axes of a pair solver's problem.
fn pair<'a, 'b>(
    axes: &'a mut [AxisProblem<'b>],
) -> Result<(&'a mut AxisProblem<'b>, &'a mut AxisProblem<'b>), ControlError> {
    match axes {
        [x, y] => Ok((x, y)),
        _ => Err(super::problem::invalid("axes", "the horizontal pair")),
    }
}

impl ConstrainedSolver for BoxAlmSolver {
    fn method(&self) -> SolverMethod {
        SolverMethod::Alm
    }
    fn axes(&self) -> usize {
        1
    }
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError> {
        self.solve_problem(one(axes)?.reborrow())
    }
    fn iterations(&self) -> usize {
        BoxAlmSolver::iterations(self)
    }
    fn factorisations(&self) -> usize {
        BoxAlmSolver::factorisations(self)
    }
    fn warm_started(&self) -> bool {
        BoxAlmSolver::warm_started(self)
    }
    fn accept(&mut self, axes: &[AxisProblem<'_>], duals: &[[f64; 2]]) {
        if let [a] = axes {
            self.accept_plan(a.plan, duals);
        }
    }
    fn skip(&mut self) {
        BoxAlmSolver::skip(self);
    }
    fn reset(&mut self) {
        BoxAlmSolver::reset(self);
    }
}

impl ConstrainedSolver for BandedInteriorPointSolver {
    fn method(&self) -> SolverMethod {
        SolverMethod::InteriorPoint
    }
    fn axes(&self) -> usize {
        1
    }
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError> {
        self.solve_problem(one(axes)?.reborrow())
    }
    fn iterations(&self) -> usize {
        BandedInteriorPointSolver::iterations(self)
    }
    fn row_duals(&self) -> &[[f64; 2]] {
        BandedInteriorPointSolver::row_duals(self)
    }
}

impl ConstrainedSolver for ClarabelSolver {
    fn method(&self) -> SolverMethod {
        SolverMethod::Clarabel
    }
    fn axes(&self) -> usize {
        1
    }
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError> {
        self.solve_problem(one(axes)?.reborrow())
    }
    fn iterations(&self) -> usize {
        0
    }
}

impl ConstrainedSolver for BandedConeSolver {
    fn method(&self) -> SolverMethod {
        match BandedConeSolver::method(self) {
            ConeMethod::Alm => SolverMethod::Alm,
            ConeMethod::InteriorPoint => SolverMethod::InteriorPoint,
        }
    }
    fn axes(&self) -> usize {
        2
    }
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError> {
        let (x, y) = pair(axes)?;
        self.solve_pair(x.reborrow(), y.reborrow())
    }
    fn iterations(&self) -> usize {
        BandedConeSolver::iterations(self)
    }
    fn factorisations(&self) -> usize {
        BandedConeSolver::factorisations(self)
    }
    fn warm_started(&self) -> bool {
        BandedConeSolver::warm_started(self)
    }
    fn accept(&mut self, axes: &[AxisProblem<'_>], _duals: &[[f64; 2]]) {
        if let [x, y] = axes {
            self.accept_plans([x.plan, y.plan]);
        }
    }
    fn skip(&mut self) {
        self.forget();
    }
    fn reset(&mut self) {
        BandedConeSolver::reset(self);
    }
    fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        BandedConeSolver::set_radius(self, radius)
    }
}

impl ConstrainedSolver for ClarabelConeSolver {
    fn method(&self) -> SolverMethod {
        SolverMethod::Clarabel
    }
    fn axes(&self) -> usize {
        2
    }
    fn solve(&mut self, axes: &mut [AxisProblem<'_>]) -> Result<(), ControlError> {
        let (x, y) = pair(axes)?;
        self.solve_pair(x.reborrow(), y.reborrow())
    }
    fn iterations(&self) -> usize {
        0
    }
    fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        ClarabelConeSolver::set_radius(self, radius)
    }
}
