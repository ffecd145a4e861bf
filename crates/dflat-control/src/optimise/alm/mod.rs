//! The constrained plan by an augmented Lagrangian on the free outputs
//! alone ([`BandedAlm`]), each subproblem minimised by semismooth Newton on
//! a banded positive-definite matrix: the fast path's matrix plus one block
//! per stage outside its set and one outer product per active row, so that
//! a tick whose active set barely moved costs a few banded factorisations.
//! It serves both constrained families: the horizontal pair's tilt cone
//! (a disc per stage, soft speed rows) and one axis's box (an interval per
//! stage, hard speed and tilt-rate rows, multipliers clamped at 0).
//!
//! Unknowns: `x = (p_{0,0}, …, p_{K−1,0}, p_{0,1}, …)`, the deviations of
//! the free outputs of K = 1 or 2 axes from the zero-jerk baseline (K·n,
//! n = N − 2), stage-interleaved; objective `½xᵀPx + cᵀx` with P = 2·H per
//! axis (H: [`FastBandedSolver`]'s Hessian; half-bandwidth 3 for one axis,
//! 7 interleaved, one more per axis with the smoothness term). Stage f's
//! acceleration `u_f = G_f·x + a_0`, `G_f·x = (p_f − 2p_{f−1} +
//! p_{f−2})/δt²` per axis (inside the band).
//!
//! With stage multipliers y_f ∈ ℝᴷ and penalty σ, the augmented Lagrangian
//!
//! ```text
//! L(x) = ½xᵀPx + cᵀx + Σ_f [σ/2·dist²(u_f + y_f/σ, D_f) − ‖y_f‖²/(2σ)] + row terms
//! ```
//!
//! (D_f the stage's set: the disc of radius A_f, or the box `[lo_f, hi_f]`
//! per axis) is convex, once differentiable, piecewise twice: its
//! generalised Hessian is `P + σ·Σ G_fᵀ(I − ∂Π_D)G_f`, where for the disc
//! `I − ∂Π_D(w) = (1 − A/‖w‖)·I + (A/‖w‖)·ŵŵᵀ` outside it, for the box the
//! diagonal of the axes outside their interval, and 0 inside. Newton
//! minimises it (the full step where it passes Armijo's test, else the
//! exact minimiser along the direction: below); then `y_f ← σ(w_f − Π_D(w_f))`, and
//! σ grows tenfold when the constraint residual did not fall tenfold, and
//! on a cold solve after each update until it reaches its warm value
//! (below). A row side `h·x ≤ b` with exact penalty ρ (∞ when hard) has its
//! multiplier clamped to [0, ρ]: `v ← clamp(v + σ_h·t, 0, ρ)`, σ_h the
//! stage σ in the row's units (`RowBlock::scale`).
//!
//! Each inner solve stops when the gradient is below 1e-8 of the linear
//! term's scale (or below the rounding floor of P·x, whose entries reach
//! 1e10, right after a full Newton step on a fresh factor) or the Newton
//! decrement `−gᵀd` below 1e-13 of the objective's — or, while the
//! multipliers are far off, below σ·(0.1·residual)², the change the next
//! update makes (inexact inner solves). The solve stops
//! when the constraint residual (the multipliers' change in the update,
//! over σ) is below 1e-8 of the bounds' scale (hard rows 1e-9) and what the residuals can
//! cost, `Σ‖y_f‖·residual_f`, is below 3e-10 of the objective's scale (a
//! stage strictly inside its set where the optimum is on its boundary
//! costs ‖y_f‖ per m/s²: with many active stages the residual test alone
//! left the cost 1e-7 above the optimum). σ grows tenfold only while the
//! residual is above its tolerance and did not fall tenfold (or, cold,
//! while σ is below the warm σ); with discs and rows, the residuals'
//! cost over its tolerance counts as a residual there. With intervals the matrix depends only on
//! σ and the active set (stages outside their set, per axis; row sides in
//! their quadratic range): the factor is reused whenever they are the ones
//! factored. With discs it also depends on where each active stage lies,
//! so the factor is reused only while the last step was full, its
//! decrement small (below 1e-7 of the objective's scale, or within 10× of
//! the inexact inner tolerance) and the active set the one factored; once
//! a reused factor stops converging tenfold per step, the next step
//! refactors. A factorisation keeps the held factor's columns before the
//! first one the matrix changed in ([`BandedCholesky::refactor_taking`],
//! bit-identical to a fresh factor): where the set changes only near the
//! horizon's end — the first tick of a constrained burst, whose arc enters
//! there — a factorisation costs that tail's share. `P·x` is evaluated by differencing
//! (`FastBandedSolver::apply_hessian_strided`) and then updated by `α·P·d`.
//! The stages' accelerations likewise: the line search evaluates the full
//! step by the gradient's own stage pass (projections, multipliers, I −
//! ∂Π_f, active set at `u + G·d`), which the next gradient takes when the
//! step is full — one pass fewer per step, and no cancellation from
//! differencing positions of tens of metres (box on the corner bench at
//! N = 200: 6.39 → 4.95 Newton steps per solve, the confirming step
//! mostly no longer needed).
//!
//! **The eliminated head.** A cold solve (every multiplier 0) starts from
//! the unconstrained optimum, where the gradient is 0 up to rounding. When
//! its plan leaves its sets only from stage f_a on — a corner entering at
//! the horizon's end, the first tick of a constrained burst — and no row
//! before binds, the solve iterates on the window from stage `f_a −`
//! six stages (`WINDOW_MARGIN`; if that is at least a quarter of the
//! horizon in): the head's block of the Newton matrix is P's and its
//! gradient stays 0, so each Newton step's head part is the unconstrained
//! response to the window's, `d_H = −P_HH⁻¹·P_HT·d_T` — what the back
//! substitution gives from a right-hand side 0 on the head — and `P·d` is
//! 0 there. The gradient, stage pass, line search, `P·d`, the forward
//! substitution, the assembly and the factor
//! ([`BandedCholesky::refactor_rows_from`]) then run on the window's rows;
//! x is moved whole. When the window converges, the whole horizon's
//! gradient checks it, and the solve goes on there should a stage or row
//! of the head bind after all. On the course of corners at N = 200 a
//! burst's first tick went from ~270–460 µs to ~130–140 µs.
//!
//! The window's own factor and its cut back substitution: `window.rs`.
//!
//! **The rollout start.** A cold solve whose plan leaves its discs at once
//! (the flight's first tick, from rest) starts near the constrained plan
//! and its multipliers instead (`rollout_start.rs`).
//!
//! **The interior-point start** (`interior_start.rs`; the pair's discs
//! with rows: the cone with the tilt rate). A cold solve, and a warm one
//! that has not ended within a few Newton steps, start from a condensed
//! interior point's solution and multipliers (its Newton matrix this
//! solver's own, with the discs' barrier blocks): the first-order updates
//! find a chain of rate rows' multipliers slowly, and from the optimum's
//! the solve ends in a few steps ([`BandedAlm::interior_start`]). After
//! a warm solve that did not end, the interior point is restarted from
//! its iterate and multipliers ([`BandedAlm::interior_restart`]).
//!
//! **The active-set polish** (`polish.rs`; one axis with rows: speed and
//! tilt-rate rows). A warm solve first, and every multiplier update after,
//! takes the active set the multipliers name (below 1e-6 of the largest:
//! none), solves the QP with those constraints as equalities exactly (a
//! banded LDLᵀ of the KKT matrix ordered by stage) and corrects the set
//! (free the wrong-signed, then bind the broken) up to eight times; a KKT
//! point whose multipliers have their signs and that breaks no bound is
//! the optimum, and the solve ends there. Chains of tilt-rate rows are
//! what it is for: their multipliers' slow modes fall a few times per
//! update, and each rise of σ reshuffles the chain a row per Newton step.
//!
//! **The exact line search.** Where the full Newton step fails Armijo's
//! test, the step is L's minimiser along the direction on (0, 1) (L is
//! convex along it: piecewise quadratic for intervals), by Newton's method
//! on its derivative — first for intervals, then for the discs in place of
//! step halvings: on the corner bench at N = 200 the cone with the tilt
//! rate went from 7.84 to 7.61 Newton steps per solve (p99 27 → 22) and
//! its first tick from rest from ~1.58 to ~1.40 ms
//! (docs/performance-log.md, "The exact line search for the discs").
//!
//! Warm start ([`BandedAlm::shift`]): the multipliers one stage on,
//! extrapolated linearly from the last two solves, σ from its initial
//! value (1e4). Between constrained bursts the multipliers are
//! aged a stage per tick ([`BandedAlm::age`]), so the first tick of the
//! next burst starts from what the last one left where it still applies.

use std::ops::Range;

mod interior_start;
mod lagrangian;
mod line_search;
mod polish;
mod rollout_start;
mod solve;
mod warm_start;
mod window;

use super::banded::{BandedCholesky, SymBand};
use super::bounds::{Row, RowRun};
use super::fast_banded::FastBandedSolver;
use crate::ControlError;

/// Newton steps per warm solve, over all outer iterations (the default of
/// [`AlmTuning::max_newton_steps`]; a cold solve may take twice as many).
pub const MAX_NEWTON_STEPS: usize = 40;
/// Outer (multiplier) updates per solve.
const MAX_OUTER: usize = 20;
/// Armijo's sufficient-decrease fraction.
const ARMIJO: f64 = 1e-4;
/// Relative tolerance of the Lagrangian's gradient.
const DUAL_TOLERANCE: f64 = 1e-8;
/// Tolerance of the Newton decrement `−gᵀd` (the predicted decrease of
/// L) relative to the objective's scale `|c|·|x|`.
const DECREMENT_TOLERANCE: f64 = 1e-13;
/// Decrement (relative, as [`DECREMENT_TOLERANCE`]) below which a full
/// step counts as the local phase, where the next step reuses the factor
/// (discs with rows: the cone with the tilt rate).
const REUSE_DECREMENT: f64 = 1e-7;
/// [`REUSE_DECREMENT`] for discs without rows (the plain cone): on the
/// corner bench at N = 200 its constrained median went 77.6–79.2 →
/// 70.2–72.9 µs (factorisations per solve 3.28 → 3.07, Newton steps 6.13
/// → 6.20; p99 unchanged), where the cone with the tilt rate went 163.2–
/// 163.5 → 165.0–168.6 µs (six alternated runs each;
/// docs/performance-log.md, "The cone with the tilt rate: the rows' passes").
const REUSE_DECREMENT_DISCS: f64 = 1e-6;
/// Multiple of the inexact inner tolerance (`loose`, below) under which
/// the last decrement lets the next step reuse the factor: the step then
/// only has to bring an already small decrement below `loose`.
const LOOSE_REUSE: f64 = 10.0;
/// Decrement (relative, as [`DECREMENT_TOLERANCE`]) after whose full step
/// the inner loop stops without a confirming step.
const LOCAL_STOP: f64 = 1e-11;
/// Relative tolerance of the constraint residual.
const PRIMAL_TOLERANCE: f64 = 1e-8;
/// Relative tolerance of the residual of hard rows, a tenth of the
/// stages' (soft rows: the stages' over their penalty ρ): a
/// tilt-rate row's interval can sit within 0.01 m/s² of zero, and a plan
/// keeps it when it is within 1e-6 of its bound plus 1e-9 m/s²
/// (`TiltRate::violated_by`); at 1e-8 of the bounds' scale a draw broke
/// one by 1.5e-8 m/s².
const ROW_TOLERANCE: f64 = 1e-9;
/// Tolerance of the residuals' cost (`residual_cost`) relative to the
/// objective's scale `|c|·|x|`: with many active stages and large
/// multipliers the residual tolerance alone left the cost 1e-7 above the
/// optimum. That scale is the linear term's, which can reach 1e4 where the
/// plan's whole cost (with the constant the solver does not see) is
/// 1e-6: at 3e-9 the solve stopped as soon as its multipliers' warm start
/// was good enough, and the accuracy proptest (cost within 1e-7 of
/// clarabel's) failed draws in two of three 1000-case runs; at 3e-10 none
/// in three, for 0.2 more Newton steps per warm solve.
const GAP_TOLERANCE: f64 = 3e-10;
/// [`GAP_TOLERANCE`] of the solve right after an interior-point start's
/// hand-over (`interior_start.rs`): its iterate and multipliers satisfy
/// the other tests at once, with the residuals' cost just under
/// [`GAP_TOLERANCE`] (a restarted tick of the cone with the tilt rate
/// stopped after one Newton step 3.4e-6 above clarabel's cost, the
/// residuals' cost 2.3e-6 against a tolerance of 9.8e-6 on a plan
/// costing 0.57: `restarted_warm_ticks_match_clarabel_socp`); a tenth of
/// it there costs the other solves nothing (at every solve: the cone with
/// the tilt rate's median at N = 200 +4 %, one pair of runs).
const GAP_TOLERANCE_AFTER_INTERIOR: f64 = 3e-11;
/// Shortest line-search step (a fraction of the Newton step) a warm
/// solve's first inner solve takes before it gives up, when its caller
/// has a better start ([`BandedAlm::set_first_inner_steps`]): a step
/// stopped short of it is a chain of rate rows that moved, whose next
/// rows activate one or two a step (the corner bench's restarted ticks
/// took steps of 0.00–0.01 from the first). The cone with the tilt rate's
/// constrained p99 on the corner bench, three alternated runs of each
/// binary: N = 200 1048–1063 → 980–1007 µs; 0.02, 0.1 and 0.2 gave
/// 981–997, 980–993 and 979–993; giving up at the second such step in a
/// row 1017–1044 (docs/performance-log.md, "A blocked warm step").
const BLOCKED_STEP: f64 = 0.05;
/// Multiple of the stage residual's tolerance that ends a solve at the
/// largest σ (where the residual can stall at rounding), with the
/// residuals' cost within its tolerance.
const STALL_TOLERANCE: f64 = 100.0;
/// Fraction of the constraint residual within which an inner solve is
/// accurate enough for the next multiplier update.
const INEXACT: f64 = 0.1;
/// Stages before the first one outside its set that the window keeps
/// (`BandedAlm::open_window`): the arc's start moves a few stages during
/// a solve.
const WINDOW_MARGIN: usize = 6;
/// Share of the horizon the eliminated head must have at least for the
/// window to open (a shorter head saves less than its checks cost).
const WINDOW_MIN_SHARE: f64 = 0.25;
/// Growth of σ when the constraint residual stalls.
const SIGMA_GROWTH: f64 = 10.0;

/// Tuning of [`BandedAlm`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlmTuning {
    /// Initial penalty σ on the stage sets, per (m/s²)² of violation.
    pub sigma: f64,
    /// Initial σ of a cold solve (every multiplier zero): a softer first
    /// subproblem, whose semismooth Newton does not walk the active set
    /// from the unconstrained plan one factorisation at a time. On the
    /// corner bench at N = 200 (warm starts off), 1e2 instead of 1e4 took
    /// the p99 from 9181 to ~2900 µs and the interior-point fallbacks from
    /// 85 to 10 of 1905; warm solves keep [`AlmTuning::sigma`], which is
    /// faster there.
    pub sigma_cold: f64,
    /// Largest σ.
    pub sigma_max: f64,
    /// Newton steps per solve, over all outer iterations; a cold solve
    /// (every multiplier zero) may take twice as many. On the course of
    /// corners (`benches/corner.rs`) at N = 400 the first tick, from rest,
    /// took 42 and fell to the interior point at 40: 13–17 ms against
    /// 2.9 ms.
    pub max_newton_steps: usize,
    /// Whether a cold solve whose plan leaves its sets only late in the
    /// horizon iterates on that window alone, the head eliminated (module
    /// docs, "The eliminated head").
    pub eliminate_head: bool,
    /// Whether a cold solve whose plan leaves its discs at once starts
    /// from the saturated rollout and the multipliers that hold it
    /// (`rollout_start.rs`). Discs only.
    pub rollout_start: bool,
    /// KKT solves of the active-set method per solve (one axis with rows:
    /// [`super::active_set`]); beyond them the solve fails.
    pub max_kkt_solves: usize,
}

impl Default for AlmTuning {
    fn default() -> Self {
        Self {
            sigma: 1e4,
            sigma_cold: 1e2,
            sigma_max: 1e8,
            max_newton_steps: MAX_NEWTON_STEPS,
            eliminate_head: true,
            rollout_start: true,
            max_kkt_solves: super::active_set::MAX_SOLVES,
        }
    }
}

/// What each stage's acceleration `u_f` [m/s²] must lie in.
#[derive(Debug, Clone, PartialEq)]
pub enum StageSet {
    /// The pair's disc `‖u_f‖ ≤ A_f` (two axes), radius per stage.
    Disc(Vec<f64>),
    /// Per axis `lo ≤ u_{axis,f} ≤ hi` (`[lo, hi]` per stage and axis;
    /// infinite: no bound), set per solve ([`BandedAlm::interval_mut`]).
    Interval(Vec<[[f64; 2]; 2]>),
}

/// Rows of one kind in stage order (shifted together by a warm start):
/// the rows, their σ relative to the stages' (`scale`: 1/δt² for rows in
/// m/s, 1 for rows in m/s²) and their exact penalty ρ per unit of
/// violation (`f64::INFINITY`: hard).
#[derive(Debug, Clone)]
pub(super) struct RowBlock {
    pub(super) rows: Vec<Row>,
    pub(super) scale: f64,
    pub(super) penalty: f64,
}

/// Which factor holds the Newton matrix of the current σ and active set
/// (`solve.rs`): none (σ changed, or no factorisation yet this solve),
/// the whole horizon's, or the window's ([`HeadFactor`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Factored {
    Stale,
    Whole,
    Window,
}

/// The factor of the windows' Newton matrices (module docs, "The
/// eliminated head"): its held matrix is P's on the unknowns before
/// `p_until`, so a window's factorisation refactors its rows only;
/// `valid`: P factored (else no window opens).
#[derive(Debug, Clone)]
pub(super) struct HeadFactor {
    pub(super) factor: BandedCholesky,
    pub(super) p_until: usize,
    pub(super) valid: bool,
}

/// What a solve carries to the next tick (`warm_start.rs`): the stage
/// multipliers y_f and the rows' `[upper, lower]`, and the last two
/// solves' stage multipliers (unshifted) for [`BandedAlm::shift`]'s
/// extrapolation, with whether `y_last` is of the solve just before.
#[derive(Debug, Clone)]
pub(super) struct WarmStart {
    pub(super) y: Vec<[f64; 2]>,
    pub(super) v: Vec<[f64; 2]>,
    pub(super) y_last: Vec<[f64; 2]>,
    pub(super) y_older: Vec<[f64; 2]>,
    pub(super) y_last_valid: bool,
}

/// The scratch of one solve: rewritten by every solve, nothing in it
/// carries to the next tick but what the accessors report.
#[derive(Debug, Clone)]
pub(super) struct Workspace {
    /// Iterate, linear term, gradient, direction, P·direction, P·x.
    pub(super) x: Vec<f64>,
    pub(super) c: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) d: Vec<f64>,
    pub(super) pd: Vec<f64>,
    pub(super) px: Vec<f64>,
    /// Whether `px` holds P·x for the current x.
    pub(super) px_current: bool,
    /// Per-stage u_f, u_f at the full step x + d (the line search's) and
    /// G_f·d.
    pub(super) u: Vec<[f64; 2]>,
    pub(super) u_trial: Vec<[f64; 2]>,
    pub(super) du: Vec<[f64; 2]>,
    /// The stage multipliers' update `σ·(w_f − Π(w_f))` at x (set by
    /// `gradient`).
    pub(super) y_next: Vec<[f64; 2]>,
    /// The full step's stage pass (largest `‖y' − y‖²`, the stages'
    /// penalty), when the line search took it: the next gradient's.
    pub(super) full_step: Option<(f64, f64)>,
    /// Per stage `I − ∂Π_f(w_f)` at x (0 inside the set; set by the stage
    /// pass, read by `assemble`).
    pub(super) jac: Vec<[[f64; 2]; 2]>,
    /// Per-row h·x and h·d.
    pub(super) hx: Vec<f64>,
    pub(super) hd: Vec<f64>,
    /// Scratch of `apply_p` (one axis, n).
    pub(super) p_work: Vec<f64>,
    /// The Lagrangian's non-quadratic part at x (set by `gradient`).
    pub(super) penalty_value: f64,
    /// Which stages lie outside their set (per stage a bit per axis whose
    /// multiplier is non-zero) and which row sides are in their penalty's
    /// quadratic range, at x (set by `gradient`) and at the last
    /// factorisation.
    pub(super) active: Vec<u8>,
    pub(super) factored_active: Vec<u8>,
    /// The first stage of the window iterated on (0: the whole horizon;
    /// module docs, "The eliminated head"); while it is open, the first
    /// unknown whose steps are taken (0: all) — those before it move
    /// once, as the window closes, by the steps' sum at the b unknowns
    /// from `cut` on (`cut_seed`).
    pub(super) window: usize,
    pub(super) cut: usize,
    pub(super) cut_seed: Vec<f64>,
    /// The last solve's Newton steps and factorisations, the window it
    /// opened (0: none), whether it started from the rollout, and what
    /// the active-set method did (one axis with rows).
    pub(super) newton_steps: usize,
    pub(super) factorisations: usize,
    pub(super) last_window: usize,
    pub(super) rollout_started: bool,
    pub(super) active_set_work: super::active_set::Work,
}

impl Workspace {
    fn new(n: usize, size: usize, m: usize, bandwidth: usize) -> Self {
        Self {
            x: vec![0.0; size],
            c: vec![0.0; size],
            g: vec![0.0; size],
            d: vec![0.0; size],
            pd: vec![0.0; size],
            px: vec![0.0; size],
            px_current: false,
            u: vec![[0.0; 2]; n],
            u_trial: vec![[0.0; 2]; n],
            du: vec![[0.0; 2]; n],
            y_next: vec![[0.0; 2]; n],
            full_step: None,
            jac: vec![[[0.0; 2]; 2]; n],
            hx: vec![0.0; m],
            hd: vec![0.0; m],
            p_work: vec![0.0; n],
            penalty_value: 0.0,
            active: vec![0; n + 2 * m],
            factored_active: vec![0; n + 2 * m],
            window: 0,
            cut: 0,
            cut_seed: vec![0.0; bandwidth],
            newton_steps: 0,
            factorisations: 0,
            last_window: 0,
            rollout_started: false,
            active_set_work: super::active_set::Work::default(),
        }
    }
}

/// The augmented-Lagrangian solver of the constrained plan (module docs):
/// the problem's data, the factors, the warm start carried between ticks
/// (`WarmStart`) and one solve's scratch (`Workspace`). Allocates at
/// construction only.
#[derive(Debug, Clone)]
pub struct BandedAlm {
    /// Axes K (1 or 2) and free outputs per axis n.
    k: usize,
    n: usize,
    inv_dt2: f64,
    stages: StageSet,
    /// The disc's centre per stage `o_f` [m/s²] (zeros unless set,
    /// [`BandedAlm::set_centre`]): the disc bounds `u_f − o_f`.
    centre: Vec<[f64; 2]>,
    tuning: AlmTuning,
    /// Newton steps a warm solve's first inner solve may take
    /// ([`BandedAlm::set_first_inner_steps`]).
    first_inner_steps: usize,
    /// Whether the iterate and multipliers held are an interior-point
    /// start's hand-over, not yet solved from: the next solve stops at
    /// [`GAP_TOLERANCE_AFTER_INTERIOR`].
    handed_over: bool,
    sigma: f64,
    axes: Vec<FastBandedSolver>,
    /// P; the Newton matrix assembled; the whole horizon's factor, the
    /// windows' ([`HeadFactor`]), and which holds the current matrix.
    base: SymBand,
    kkt: SymBand,
    chol: BandedCholesky,
    head: HeadFactor,
    factored: Factored,
    /// The rows; per row σ scale, penalty ρ and first unknown; the blocks'
    /// ranges (shifts).
    rows: Vec<Row>,
    row_scale: Vec<f64>,
    row_penalty: Vec<f64>,
    /// Hard rows beside soft ones (the cone's tilt-rate rows beside its
    /// speed rows): the factor a hard row's multiplier change enters the
    /// row residual with, set per solve (`solve.rs`, `tolerances`), so
    /// that the one row tolerance — the soft rows', ρ times tighter than
    /// the stages' — holds each hard row to [`ROW_TOLERANCE`] of the hard
    /// rows' own bounds' scale (a first-stage rate interval can sit within
    /// 1e-3 m/s² of zero, while the speed rows' bounds reach 10 m/s); 1
    /// otherwise.
    hard_row_weight: f64,
    row_first: Vec<usize>,
    /// The rows as runs of one row shifted ([`RowRun`]): their products
    /// with a vector in one pass per run.
    row_runs: Vec<RowRun>,
    blocks: Vec<Range<usize>>,
    /// Largest diagonal entry of P.
    diag_max: f64,
    warm: WarmStart,
    ws: Workspace,
    /// Tests: every step's back substitution over the whole horizon.
    #[cfg(test)]
    no_cut: bool,
    /// The active-set method (`polish.rs`): one axis with intervals and
    /// rows.
    polish: Option<super::active_set::ActiveSet>,
    /// The condensed interior point's storage (`interior_start.rs`): the
    /// pair's discs with rows.
    interior: Option<interior_start::InteriorStart>,
}

impl BandedAlm {
    /// A solver for the axes' weights (K = `axes.len()`, 1 or 2, of one
    /// horizon N; n = N − 2 free outputs per axis) at step δt \[s\], the
    /// stage set (a disc needs two axes) and the row blocks (their rows'
    /// indices in this solver's interleaved unknowns, [`BandedAlm::index`]).
    pub(super) fn new(
        axes: Vec<FastBandedSolver>,
        dt: f64,
        stages: StageSet,
        blocks: Vec<RowBlock>,
        tuning: AlmTuning,
    ) -> Self {
        let k = axes.len();
        assert!(k == 1 || k == 2, "one or two axes");
        let n = axes[0].horizon() - 2;
        assert!(
            axes.iter().all(|a| a.horizon() - 2 == n),
            "axes of one horizon"
        );
        match &stages {
            StageSet::Disc(r) => assert!(k == 2 && r.len() == n, "a disc per stage of a pair"),
            StageSet::Interval(b) => assert_eq!(b.len(), n, "an interval per stage"),
        }
        let size = k * n;
        let axis_b = axes
            .iter()
            .map(|a| a.hessian_band().bandwidth())
            .max()
            .unwrap_or(3);
        // Interleaved, P couples each axis with itself only (offsets
        // 2·(f − g) ≤ 2·axis_b), and the stage blocks reach two stages
        // back (offsets ≤ 2·2 + 1): the band is 2·axis_b wide, not
        // 2·axis_b + 1 — the entry one further, across the axes, is always
        // 0, and a banded factor fills nothing outside the band.
        let mut bandwidth = if k == 1 { axis_b } else { (2 * axis_b).max(5) };
        let mut rows = Vec::new();
        let (mut row_scale, mut row_penalty, mut ranges) = (Vec::new(), Vec::new(), Vec::new());
        for block in blocks {
            let start = rows.len();
            for row in &block.rows {
                bandwidth = bandwidth.max(row.span());
            }
            row_scale.extend(std::iter::repeat_n(block.scale, block.rows.len()));
            row_penalty.extend(std::iter::repeat_n(block.penalty, block.rows.len()));
            rows.extend(block.rows);
            ranges.push(start..rows.len());
        }
        let mut base = SymBand::zeros(size, bandwidth);
        for (i, ax) in axes.iter().enumerate() {
            let h = ax.hessian_band();
            for f in 0..n {
                for g in f.saturating_sub(h.bandwidth())..=f {
                    base.add(k * f + i, k * g + i, 2.0 * h.get(f, g));
                }
            }
        }
        let diag_max = (0..size).fold(0.0f64, |a, i| a.max(base.get(i, i)));
        // P's factor, the head of every window's (P is positive definite
        // for valid weights; should it not factor, no window opens).
        let mut head = BandedCholesky::new(size, bandwidth);
        let head_valid = head.refactor_taking(&mut base.clone()).is_ok();
        let m = rows.len();
        let polish_on = k == 1 && m > 0 && matches!(stages, StageSet::Interval(_));
        let interior = (k == 2 && m > 0 && matches!(stages, StageSet::Disc(_)))
            .then(|| interior_start::InteriorStart::new(n, &rows, size, bandwidth, diag_max));
        let row_first = rows
            .iter()
            .map(|r| r.idx[..r.len].iter().copied().min().unwrap_or(0))
            .collect();
        let row_runs = RowRun::runs(&rows);
        let mut alm = Self {
            first_inner_steps: usize::MAX,
            handed_over: false,
            k,
            n,
            inv_dt2: 1.0 / (dt * dt),
            stages,
            centre: vec![[0.0; 2]; n],
            tuning,
            sigma: tuning.sigma,
            axes,
            kkt: base.clone(),
            base,
            chol: BandedCholesky::new(size, bandwidth),
            head: HeadFactor {
                factor: head,
                p_until: size,
                valid: head_valid,
            },
            factored: Factored::Stale,
            rows,
            row_scale,
            row_penalty,
            hard_row_weight: 1.0,
            row_first,
            row_runs,
            blocks: ranges,
            diag_max,
            warm: WarmStart {
                y: vec![[0.0; 2]; n],
                v: vec![[0.0; 2]; m],
                y_last: vec![[0.0; 2]; n],
                y_older: vec![[0.0; 2]; n],
                y_last_valid: false,
            },
            ws: Workspace::new(n, size, m, bandwidth),
            #[cfg(test)]
            no_cut: false,
            polish: None,
            interior,
        };
        if polish_on {
            alm.polish = Some(alm.new_polish());
        }
        alm
    }

    /// Index of `p_{axis, f}` in this solver's unknowns.
    pub fn index(&self, axis: usize, f: usize) -> usize {
        self.k * f + axis
    }

    /// The weights of axis i.
    pub fn axis(&self, i: usize) -> &FastBandedSolver {
        &self.axes[i]
    }

    /// Whether this solver's problems go to the active-set method (one
    /// axis with intervals and rows).
    pub fn has_active_set(&self) -> bool {
        self.polish.is_some()
    }

    /// What the active-set method did in the last solve (one axis with
    /// rows; zero otherwise).
    pub fn active_set_work(&self) -> super::active_set::Work {
        self.ws.active_set_work
    }

    /// Newton steps of the last solve.
    pub fn newton_steps(&self) -> usize {
        self.ws.newton_steps
    }

    /// The first stage of the window the last solve iterated on before the
    /// whole horizon (0: none; module docs, "The eliminated head").
    pub fn last_window(&self) -> usize {
        self.ws.last_window
    }

    /// Whether the last solve started from the saturated rollout (module
    /// docs, "The rollout start"; `rollout_start.rs`).
    pub fn rollout_started(&self) -> bool {
        self.ws.rollout_started
    }

    /// Turns the window's cut back substitution off (tests: the same solve
    /// both ways).
    #[cfg(test)]
    pub(crate) fn set_no_cut(&mut self, on: bool) {
        self.no_cut = on;
    }

    /// Turns the rollout start on or off (tests: the same solve both ways).
    #[cfg(test)]
    pub(crate) fn set_rollout_start(&mut self, on: bool) {
        self.tuning.rollout_start = on;
    }

    /// Factorisations of the last solve (Newton steps in the local phase
    /// reuse the last factor).
    pub fn factorisations(&self) -> usize {
        self.ws.factorisations
    }

    /// The deviation `p_{axis, f}` of the current iterate.
    pub fn p(&self, axis: usize, f: usize) -> f64 {
        self.ws.x[self.index(axis, f)]
    }

    /// Sets the primal start from `p` (per axis, length n).
    pub fn set_start(&mut self, p: &[&[f64]]) {
        self.ws.px_current = false;
        for (i, p) in p.iter().enumerate().take(self.k) {
            for (f, &v) in p.iter().enumerate().take(self.n) {
                self.ws.x[self.k * f + i] = v;
            }
        }
    }

    /// Sets the Newton-step budget of a warm solve (a cold one has twice
    /// as many): tests make the method give up; the pair with tilt-rate
    /// rows gives a warm start `WARM_STEPS_BEFORE_START` before its
    /// interior-point start.
    pub(crate) fn set_max_newton_steps(&mut self, steps: usize) {
        self.tuning.max_newton_steps = steps;
    }

    /// Sets the Newton steps a warm solve's first inner solve (the
    /// multipliers as shifted) may take before the solve gives up
    /// (`usize::MAX`: no such limit, the default): the pair with tilt-rate
    /// rows gives up there on a warm start far from its optimum
    /// (`WARM_FIRST_INNER_STEPS`) for the interior point's restart. With
    /// such a limit the first inner solve also gives up at its first line
    /// search that stops short of [`BLOCKED_STEP`].
    pub(crate) fn set_first_inner_steps(&mut self, steps: usize) {
        self.first_inner_steps = steps;
    }

    /// The Newton-step budget of a warm solve.
    pub(crate) fn max_newton_steps(&self) -> usize {
        self.tuning.max_newton_steps
    }

    /// Turns the head's elimination on or off (tests: the same solve both
    /// ways).
    #[cfg(test)]
    pub(crate) fn set_eliminate_head(&mut self, on: bool) {
        self.tuning.eliminate_head = on;
    }

    /// The stage set.
    pub fn stages(&self) -> &StageSet {
        &self.stages
    }

    /// The disc's radius per stage `A_f` [m/s²] (empty for intervals).
    pub fn radius(&self) -> &[f64] {
        match &self.stages {
            StageSet::Disc(r) => r,
            StageSet::Interval(_) => &[],
        }
    }

    /// Sets the disc's radius per stage `A_f` [m/s²] (n entries, finite
    /// and > 0; stage f bounds the acceleration of output f + 2), for the
    /// next solves — the spatial model's tilt cone, whose radius follows
    /// the planned vertical acceleration. An error for intervals.
    pub fn set_radius(&mut self, radius: &[f64]) -> Result<(), ControlError> {
        super::cone::check_radius(radius, self.n)?;
        match &mut self.stages {
            StageSet::Disc(r) => {
                r.copy_from_slice(radius);
                Ok(())
            }
            StageSet::Interval(_) => Err(super::problem::invalid(
                "radius",
                "a disc's, not an interval's",
            )),
        }
    }

    /// The disc's centre per stage `o_f` [m/s²] (zeros unless set).
    pub fn centre(&self) -> &[[f64; 2]] {
        &self.centre
    }

    /// Sets the disc's centre per stage `o_f` [m/s²] (n entries, finite):
    /// the disc then bounds `‖u_f − o_f‖ ≤ A_f` — the thrust's
    /// acceleration where the model adds `o_f` to it (the drag, a learned
    /// residual). An error for intervals, and for a wrong length or a
    /// value that is not finite (nothing changed then).
    pub fn set_centre(&mut self, centre: &[[f64; 2]]) -> Result<(), ControlError> {
        super::cone::check_centre(centre, self.n)?;
        match &self.stages {
            StageSet::Disc(_) => {
                self.centre.copy_from_slice(centre);
                Ok(())
            }
            StageSet::Interval(_) => Err(super::problem::invalid(
                "centre",
                "a disc's, not an interval's",
            )),
        }
    }

    /// The intervals `[lo, hi]` per stage and axis [m/s²] of the absolute
    /// acceleration u_f, to set before a solve (`None` for a disc).
    pub fn interval_mut(&mut self) -> Option<&mut [[[f64; 2]; 2]]> {
        match &mut self.stages {
            StageSet::Interval(b) => Some(b),
            StageSet::Disc(_) => None,
        }
    }
}

/// The tuning of the accuracy tests, which run the augmented Lagrangian
/// alone from a cold start on random instances: the step budget of the
/// hardest draws (up to 184 Newton steps were seen in 256 cases; in the
/// cascade such a tick goes to the interior point after
/// [`MAX_NEWTON_STEPS`]).
#[cfg(test)]
pub(crate) const COLD_TUNING: AlmTuning = AlmTuning {
    sigma: 1e4,
    sigma_cold: 1e2,
    sigma_max: 1e8,
    max_newton_steps: 1000,
    eliminate_head: true,
    rollout_start: true,
    max_kkt_solves: 1000,
};

#[cfg(test)]
mod tests;
