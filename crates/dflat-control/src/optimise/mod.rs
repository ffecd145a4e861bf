//! Output trajectory optimisation: the per-axis QP of DF-MPC (paper §V)
//! and the solvers that solve it.
//!
//! # How it is solved
//!
//! With the three fixed outputs eliminated, the n = N − 2 free outputs enter
//! a banded SPD system (half-bandwidth 3): `(q·I + r/δt⁶·DᵀD)·p = q·(y_ref − b)`
//! where D is the (square, lower-triangular) third-difference matrix and `p`
//! the deviation of the free outputs from the *baseline* `b`: the fixed
//! outputs continued with zero jerk (`b_j = y_k + j·Δy_k + j(j−1)/2·Δ²y_k`).
//! The baseline has no third difference, so the right-hand side is formed
//! without cancellation. The Hessian is factored once in [`FastBandedSolver::new`]
//! (banded Cholesky, [`banded`]); each tick is one O(N) banded solve
//! plus one step of iterative refinement whose residual is evaluated by
//! repeated differencing, never with the assembled Hessian. That matters:
//! the Hessian's condition number is near 1e11 for the paper's weights, a
//! plain solve leaves ~1e-11 m in y*_{k+3} (≈ 3e-8 rad in the command, the
//! command is ≈ 2500 rad per metre of y*_{k+3}), the refined solve is within
//! ~1e-17 m of the exact optimum. x and y share one factor when their
//! weights are equal and are solved together ([`FastBandedSolver::solve_pair`]).
//! This fast path allocates nothing.
//!
//! When inequality constraints are configured and the fast plan violates
//! one, the axis (box bounds) or the horizontal pair (the tilt cone) is
//! re-solved by a [`Cascade`]: an ordered list of solvers of the axis's
//! problem ([`AxisSolver`]) or of the pair's ([`PairSolver`]) tried until
//! one converges. With
//! [`QpSolver::Banded`](crate::dfmpc::QpSolver::Banded) (the default) the
//! first is the augmented Lagrangian on the free outputs ([`alm`]: one
//! banded Newton system per step, warm-started from the previous tick's
//! plan and multipliers, and between bursts from the multipliers the last
//! burst left), serving the box (an interval per stage, [`BoxAlmSolver`])
//! and the cone (a disc per stage, soft speed rows, [`BandedConeSolver`]).
//! A box with rows — the tilt-rate bound's, speed rows — goes to the
//! active-set method on its compact KKT system instead ([`active_set`],
//! inside [`BoxAlmSolver`], warm-started from the last tick's working
//! set).
//! Should it not converge, a banded interior point solves the same QP in
//! the deviation variables plus the planned accelerations (cost `q·(b + p
//! − y_ref)² + r·(Δã/δt)²`, equality rows tie ã to Δ²p/δt², bounds on ã
//! are single-entry rows; a well-scaled QP, its KKT system ordered by
//! stage, O(N) per iteration: [`BandedInteriorPointSolver`], the cone's in
//! [`cone_qp`]), and then clarabel ([`ClarabelSolver`],
//! [`ClarabelConeSolver`]), whose structure is fixed, so one solver is
//! built once and only `q` and `b` are updated per tick. A clarabel status
//! other than `Solved` is [`crate::ControlError::Solver`].
//!
//! # Command smoothness (optional)
//!
//! With [`DfMpcSettings::smoothness_weight`](crate::dfmpc::DfMpcSettings::smoothness_weight) s > 0 on an axis, the cost also
//! weighs the change of the commanded attitude between ticks, linearised
//! through the output-to-input map about hover. Per axis the command asks
//! for the acceleration the attitude settles to,
//!
//! ```text
//! c_j = a_j + κ·(a_{j+1} − a_j),   a_j = Δ²y_j/δt²,   κ = τ/δt
//! ```
//!
//! (F linearised: `θ_cmd = (θ_j + κ·(θ_{j+1} − θ_j))/k̃`, and tilt ≈
//! acceleration/g; for z of the spatial model κ = τ_T/δt and the thrust).
//! The added cost is
//!
//! ```text
//! Σ_{j=0..N−3} s·((c_j − c_{j−1})/g)²,   c_{−1} = acceleration the command SENT at k−1 asks for
//! ```
//!
//! (≈ s·Δθ_cmd² \[rad²\] per tick; the first term ties the plan to the
//! command actually sent, after saturation). In the free outputs this is
//! `‖E·p + e‖²` with `E = T·D`, `T = κ·I + (1 − κ)·S` (S the one-step
//! delay, D the third-difference matrix above): the Hessian becomes
//! `q·I + Dᵀ(w·I + s'·TᵀT)·D`, half-bandwidth 4 instead of 3, still
//! factored once and solved in O(N), the residual still evaluated by
//! differencing. The sent command enters only the right-hand side (first
//! free output). Linearising about hover keeps the Hessian constant; at
//! 35° the true Δθ is ~0.67 times the linearised one (a milder weight at
//! large tilt). Default off: the paper's problem is unchanged. The clarabel
//! path carries the same term (band 2 in the acceleration variables).
//!
//!
//! # Files
//!
//! * [`fast_banded`] — [`FastBandedSolver`]: the unconstrained problem, a
//!   banded Cholesky factor built once, O(N) per tick (the fast path).
//! * [`cascade`] — [`AxisSolver`] and [`PairSolver`] (the box's and the
//!   cone's solvers' interfaces: [`SolveInfo`] or [`SolveFailure`], the
//!   method and its [`SolverFault`], an enum, never a string) and
//!   [`Cascade`] (the fallback order, as data).
//! * [`active_set`] — the active-set method of one axis with rows (the
//!   tilt-rate bound's problem), on a compact KKT system in profile form.
//! * [`problem`] — [`AxisProblem`] and the checks and helpers every solver
//!   shares.
//! * [`alm`] — [`alm::BandedAlm`]: the augmented Lagrangian of both
//!   constrained families; [`box_alm`] — [`BoxAlmSolver`], one axis's box
//!   with it; [`cone_solver`] — [`BandedConeSolver`], the pair's cone with
//!   it (or with the cone's interior point, [`cone_qp`]).
//! * [`banded_ip`] — [`banded_ip::BandedIp`]: the one banded primal-dual
//!   interior point (Mehrotra's predictor-corrector on the stage-ordered
//!   KKT system; interval rows, hard or soft, and per-stage discs as
//!   data), serving two problems: [`interior_point`] —
//!   [`interior_point::StageQp`], one axis's box, and
//!   [`BandedInteriorPointSolver`], the box's cascade member; and
//!   [`cone_qp`] — [`cone_qp::ConeQp`], the pair's cone.
//! * [`clarabel`], [`clarabel_cone`] — [`ClarabelSolver`],
//!   [`ClarabelConeSolver`]: the same problems in clarabel, the last
//!   fallback (and [`KktTuning`]).
//! * [`cone`] — [`ConeBounds`]: the tilt cone and its soft speed bounds.
//! * [`bounds`] — [`AxisBounds`]: tilt (acceleration), vertical
//!   acceleration and speed bounds, the braking funnel.
//! * [`smoothness`] — [`Smoothness`]: the command-smoothness term.
//! * [`feed_forward`] — a flyable reference's jerk and command changes as
//!   the jerk and smoothness terms' targets (streams).
//! * [`tilt_rate`] — [`TiltRate`]: the tilt-rate bound, rows on the
//!   command's change per tick (the box's solvers).
//! * [`banded`] — banded symmetric matrices, Cholesky and LDLᵀ factors
//!   ([`banded::BandedLdl`], the interior point's).

pub mod active_set;
pub mod alm;
pub mod banded;
pub mod banded_ip;
pub mod bounds;
pub mod box_alm;
pub mod cascade;
pub mod clarabel;
pub mod clarabel_cone;
pub mod cone;
#[cfg(test)]
mod cone_centre_tests;
pub mod cone_qp;
#[cfg(test)]
mod cone_rate_tests;
pub mod cone_solver;
#[cfg(test)]
mod cone_tests;
pub mod fast_banded;
pub mod feed_forward;
pub mod interior_point;
#[cfg(feature = "osqp-bench")]
pub mod osqp_anchor;
pub mod problem;
pub mod smoothness;
pub mod tilt_rate;
#[cfg(test)]
mod tilt_rate_tests;

pub use bounds::AxisBounds;
pub use box_alm::BoxAlmSolver;
pub use cascade::{
    AxisCascade, AxisSolver, Carry, Cascade, PairCascade, PairSolver, Restart, SolveFailure,
    SolveInfo, SolverFault, SolverMethod,
};
pub use clarabel::{ClarabelSolver, KktTuning};
pub use clarabel_cone::ClarabelConeSolver;
pub use cone::ConeBounds;
pub use cone_solver::{AxisWeights, BandedConeSolver, ConeMethod};
pub use fast_banded::FastBandedSolver;
pub use interior_point::BandedInteriorPointSolver;
pub use smoothness::Smoothness;
pub use tilt_rate::TiltRate;

pub use problem::{AxisProblem, MAX_HORIZON};
pub(crate) use problem::{check_problem, invalid};
