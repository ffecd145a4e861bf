//! Step 4 of the tick, output trajectory optimisation: the per-axis
//! pipelines (fast path, bounded QP) and the horizontal pair's tilt cone.

use nalgebra::Vector3;

use super::{DfMpc, DfMpcSettings, PlanTiltBound, QpSolver};
use crate::ControlError;
use crate::model::ControlModel;
use crate::optimise::{
    AxisBounds, AxisCascade, AxisProblem, AxisSolver, AxisWeights, BandedConeSolver,
    BandedInteriorPointSolver, BoxAlmSolver, ClarabelConeSolver, ClarabelSolver, ConeBounds,
    FastBandedSolver, KktTuning, PairCascade, PairSolver, Smoothness, SolveInfo, SolverMethod,
    TiltRate,
};
use crate::window::input_lags;

/// One axis's optimisation: the fast path, the constrained cascade when
/// the axis has bounds, and its reference and plan buffers.
#[derive(Debug)]
pub(super) struct AxisPipeline {
    /// The unconstrained problem (the fast path).
    pub(super) fast: FastBandedSolver,
    /// The problem with this axis's bounds, when it has any: the box's
    /// cascade (augmented Lagrangian, interior point, clarabel).
    pub(super) bounded: Option<AxisCascade>,
    /// The bounds (empty when none).
    pub(super) bounds: AxisBounds,
    /// This tick's reference on this axis, y_ref,k..y_ref,k+N \[m\].
    pub(super) reference: Vec<f64>,
    /// Scratch for the feed-forward shift (N + 1 values).
    pub(super) feed_forward: Vec<f64>,
    /// This tick's plan y*_k..y*_{k+N} \[m\] (a workspace until it is good).
    pub(super) plan: Vec<f64>,
    /// The last good tick's plan \[m\] (swapped with `plan`).
    pub(super) good_plan: Vec<f64>,
}

impl AxisPipeline {
    /// This axis's fast path and its problem for this tick: the `fixed`
    /// outputs, the sent command's acceleration `sent` and the axis's
    /// reference and plan buffers.
    fn problem<'a>(
        &'a mut self,
        fixed: &'a [f64; 3],
        sent: Option<f64>,
    ) -> (&'a mut FastBandedSolver, AxisProblem<'a>) {
        let problem = AxisProblem {
            fixed,
            sent,
            reference: &self.reference,
            plan: &mut self.plan,
        };
        (&mut self.fast, problem)
    }
}

/// What [`DfMpc::optimise`] reports of a tick's solve.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SolveReport {
    /// A bound was binding on some axis (a constrained cascade ran).
    pub(super) constrained: bool,
    /// Clarabel solved where a banded solver came before it.
    pub(super) qp_fallback: bool,
    /// A banded interior point solved where the augmented Lagrangian did
    /// not converge (box or cone).
    pub(super) interior_point: bool,
}

impl SolveReport {
    /// Notes which solver of a cascade solved (its place and method).
    fn solved(&mut self, solved_by: Option<(usize, SolveInfo)>) {
        self.constrained = true;
        if let Some((place, info)) = solved_by
            && place > 0
        {
            self.qp_fallback |= info.method == SolverMethod::Clarabel;
            self.interior_point |= info.method == SolverMethod::InteriorPoint;
        }
    }
}

/// The horizontal pair's tilt-cone QP ([`PlanTiltBound::Cone`]): its
/// cascade — with [`QpSolver::Banded`] the augmented Lagrangian
/// (warm-started), the banded interior point, then clarabel's SOCP.
#[derive(Debug)]
pub(super) struct HorizontalCone {
    pub(super) cascade: PairCascade,
    bounds: ConeBounds,
    /// tan(max_tilt).
    tilt_tan: f64,
    /// Gravity g [m/s²], and the sign of the vertical acceleration in the
    /// thrust's vertical part `g − sign·a_z` (NED, z down: +1; z up: −1).
    gravity: f64,
    down: f64,
    /// The cone's radius per stage [m/s²]: `g·tan(max_tilt)` with the
    /// planar model; with the spatial model `tan(max_tilt)·(g − sign·a_z)`
    /// from the vertical plan, the thrust's vertical part floored at
    /// [`MIN_VERTICAL_SHARE`]·g.
    radius: Vec<f64>,
    /// The cone's centre per stage [m/s²]: per horizontal axis what the
    /// model adds to the thrust's acceleration (the drag `−D·v`, a learned
    /// residual; [`cone_centre`]), so that the cone bounds the planned
    /// acceleration less it, the thrust's tilt, as the box's rows do
    /// ([`AxisBounds::offset`]).
    centre: Vec<[f64; 2]>,
    /// What the model adds to the thrust's acceleration along the last
    /// plan, less its first stage's (`DfMpc::offsets_along_last_plan`),
    /// and whether it is this tick's.
    pub(super) along: Vec<[f64; 2]>,
    pub(super) along_valid: bool,
}

/// Floor of the thrust's vertical part, as a share of g, in the spatial
/// model's tilt cone (a plan descending at nearly g would otherwise leave
/// no horizontal acceleration at all).
pub(super) const MIN_VERTICAL_SHARE: f64 = 0.2;

impl HorizontalCone {
    /// The bounds of the pair.
    pub(super) fn bounds(&self) -> &ConeBounds {
        &self.bounds
    }

    /// The cascade of solvers.
    pub(super) fn cascade(&self) -> &PairCascade {
        &self.cascade
    }

    /// The cone's radius per stage [m/s²] (stage f bounds the acceleration
    /// of output f + 2).
    pub(super) fn radius(&self) -> &[f64] {
        &self.radius
    }

    /// Sets the radius per stage from the vertical plan `z` (`z_0..z_N`
    /// \[m\], model frame) for the solvers: the spatial model's tilt cone
    /// `‖a_h‖ ≤ tan(max_tilt)·(g − sign·a_z)`.
    fn follow_vertical_plan(&mut self, z: &[f64], dt: f64) -> Result<(), ControlError> {
        let dt2 = dt * dt;
        let floor = MIN_VERTICAL_SHARE * self.gravity;
        for (f, r) in self.radius.iter_mut().enumerate() {
            let j = f + 1;
            let az = (z[j + 2] - 2.0 * z[j + 1] + z[j]) / dt2;
            *r = self.tilt_tan * (self.gravity - self.down * az).max(floor);
        }
        self.cascade.set_radius(&self.radius)
    }

    /// The cone's centre per stage [m/s²] as of the last tick.
    pub(super) fn centre(&self) -> &[[f64; 2]] {
        &self.centre
    }

    /// A controller reset: nothing carried to the next solve.
    pub(super) fn reset(&mut self) {
        self.cascade.reset();
    }
}

/// The per-axis pipelines (fast path and, where the axis has bounds of
/// its own, the bounded QP) and, with the cone, the horizontal pair's
/// cone QP (all allocation happens here).
pub(super) fn build_pipelines(
    model: &ControlModel,
    settings: &DfMpcSettings,
) -> Result<(Vec<AxisPipeline>, Option<HorizontalCone>), ControlError> {
    let axes = model.axes();
    let c = &settings.constraints;
    let cone_mode = settings.plan_tilt_bound == PlanTiltBound::Cone && c.max_tilt.is_some();
    let dt = model.dt();
    let n = settings.horizon;
    let lags = input_lags(model);
    let mut pipelines = Vec::with_capacity(axes);
    for (axis, lag) in lags.iter().enumerate().take(axes) {
        let (q, r) = (settings.tracking_weight[axis], settings.jerk_weight[axis]);
        let smoothness = Smoothness {
            weight: settings.smoothness_weight[axis],
            kappa: lag / dt,
            gravity: model.gravity(),
        };
        let acceleration = if axis < 2 {
            c.max_tilt.filter(|_| !cone_mode).map(|t| {
                let a = model.gravity() * t.tan();
                [-a, a]
            })
        } else {
            c.vertical_acceleration
        };
        // With the cone the tilt-rate rows are the pair's (`horizontal_cone`).
        let tilt_rate = c
            .max_tilt_rate
            .filter(|_| axis < 2 && !cone_mode)
            .map(|w| tilt_rate(model, w, *lag));
        let bounds = AxisBounds {
            acceleration,
            speed: c.max_speed,
            tilt_rate,
            // The tilt bound holds the thrust's acceleration (the plan's
            // plus D·v); the vertical bound is on the plan's own.
            drag: if axis < 2 { model.drag()[axis] } else { 0.0 },
            offset: None,
            offset_slope: 0.0,
        };
        let bounded = if bounds.is_empty() {
            None
        } else {
            let mut solvers: Vec<Box<dyn AxisSolver>> = Vec::new();
            if settings.qp_solver == QpSolver::Banded {
                let alm: Box<dyn AxisSolver> = Box::new(BoxAlmSolver::new(
                    n,
                    (q, r, dt),
                    bounds,
                    smoothness,
                    settings.warm_start,
                )?);
                let ip: Box<dyn AxisSolver> = Box::new(BandedInteriorPointSolver::new(
                    n,
                    (q, r, dt),
                    bounds,
                    smoothness,
                )?);
                // With tilt-rate rows too: the augmented Lagrangian ends
                // there in the active-set polish (`optimise/alm/polish.rs`),
                // the interior point is the fallback.
                solvers.extend([alm, ip]);
            }
            solvers.push(Box::new(ClarabelSolver::with_smoothness(
                n,
                q,
                r,
                dt,
                bounds,
                settings.solver_time_limit,
                smoothness,
            )?));
            Some(AxisCascade::new(solvers)?)
        };
        pipelines.push(AxisPipeline {
            fast: FastBandedSolver::with_smoothness(n, q, r, dt, smoothness)?,
            bounded,
            bounds,
            reference: vec![0.0; n + 1],
            feed_forward: vec![0.0; n + 1],
            plan: vec![0.0; n + 1],
            good_plan: vec![0.0; n + 1],
        });
    }

    let cone = horizontal_cone(model, settings, &pipelines)?;
    Ok((pipelines, cone))
}

/// The tilt-rate bound `max_tilt_rate` [rad/s] of a horizontal axis whose
/// attitude lags by `lag` \[s\].
fn tilt_rate(model: &ControlModel, max_tilt_rate: f64, lag: f64) -> TiltRate {
    let dt = model.dt();
    TiltRate {
        step: max_tilt_rate * dt,
        kappa: lag / dt,
        gain: model.attitude_gain(),
        gravity: model.gravity(),
    }
}

/// With the cone (`plan_tilt_bound = Cone` and a tilt limit), the
/// horizontal pair's cone QP on the weights of the axes' `pipelines`.
fn horizontal_cone(
    model: &ControlModel,
    settings: &DfMpcSettings,
    pipelines: &[AxisPipeline],
) -> Result<Option<HorizontalCone>, ControlError> {
    let c = &settings.constraints;
    let cone_mode = settings.plan_tilt_bound == PlanTiltBound::Cone && c.max_tilt.is_some();
    let (dt, n) = (model.dt(), settings.horizon);
    let lags = input_lags(model);
    let cone = match c.max_tilt {
        Some(t) if cone_mode => {
            let mut bounds = ConeBounds::new(model.gravity() * t.tan(), c.max_speed);
            if let Some(w) = c.max_tilt_rate {
                bounds = bounds.with_tilt_rate([0, 1].map(|i| tilt_rate(model, w, lags[i])));
            }
            let down = match model.frame() {
                crate::Frame::Ned => 1.0,
                crate::Frame::Zup => -1.0,
            };
            let weights: [AxisWeights; 2] = std::array::from_fn(|axis| AxisWeights {
                q: settings.tracking_weight[axis],
                r: settings.jerk_weight[axis],
                smoothness: pipelines[axis].fast.smoothness(),
            });
            let mut solvers: Vec<Box<dyn PairSolver>> = Vec::new();
            if settings.qp_solver == QpSolver::Banded {
                for methods in [[true, false], [false, true]] {
                    solvers.push(Box::new(BandedConeSolver::with_methods(
                        n,
                        dt,
                        weights,
                        bounds,
                        settings.warm_start,
                        methods,
                    )?));
                }
            }
            solvers.push(Box::new(ClarabelConeSolver::new(
                n,
                dt,
                weights,
                bounds,
                settings.solver_time_limit,
                true,
                KktTuning::SHIPPED,
            )?));
            Some(HorizontalCone {
                cascade: PairCascade::new(solvers)?,
                bounds,
                tilt_tan: t.tan(),
                gravity: model.gravity(),
                down,
                radius: vec![bounds.acceleration; n - 2],
                centre: vec![[0.0; 2]; n - 2],
                along: vec![[0.0; 2]; n - 2],
                along_valid: false,
            })
        }
        _ => None,
    };
    Ok(cone)
}

impl DfMpc {
    /// Step 4: output trajectory optimisation, per axis — the fast path
    /// first (x and y together when they share weights), then the bounded
    /// QP for an axis whose fast plan violates a configured bound.
    /// `sent_acceleration`: what the command sent at k−1 asks for (with a
    /// smoothness weight). `offsets`: per horizontal axis, the plan's
    /// acceleration less the thrust's at the window ([`AxisBounds::offset`];
    /// `None`: the drag's alone); `slopes`: its change per stage
    /// ([`AxisBounds::offset_slope`]).
    pub(super) fn optimise(
        &mut self,
        fixed: &[Vector3<f64>; 3],
        sent_acceleration: Option<Vector3<f64>>,
        offsets: Option<[f64; 2]>,
        slopes: [f64; 2],
    ) -> Result<SolveReport, ControlError> {
        let mut fixed_axis = [[0.0; 3]; 3];
        for (axis, f) in fixed_axis.iter_mut().enumerate().take(self.axes.len()) {
            *f = [fixed[0][axis], fixed[1][axis], fixed[2][axis]];
        }
        let sent = |axis: usize| sent_acceleration.map(|c| c[axis]);
        let [ax, ay, rest @ ..] = self.axes.as_mut_slice() else {
            unreachable!("DfMpc::new makes at least two axes")
        };
        let paired =
            ax.fast.weights() == ay.fast.weights() && ax.fast.smoothness() == ay.fast.smoothness();
        if paired {
            let (fast, px) = ax.problem(&fixed_axis[0], sent(0));
            let (_, py) = ay.problem(&fixed_axis[1], sent(1));
            fast.solve_pair(px, py)?;
        } else {
            for (axis, p) in [(0, &mut *ax), (1, &mut *ay)] {
                let (fast, problem) = p.problem(&fixed_axis[axis], sent(axis));
                fast.solve_problem(problem)?;
            }
        }
        if let Some(az) = rest.first_mut() {
            let (fast, problem) = az.problem(&fixed_axis[2], sent(2));
            fast.solve_problem(problem)?;
        }
        let mut report = SolveReport::default();
        let dt = self.model.dt();
        for (axis, p) in self.axes.iter_mut().enumerate() {
            p.bounds.offset = offsets.and_then(|o| o.get(axis).copied());
            p.bounds.offset_slope = slopes.get(axis).copied().unwrap_or(0.0);
        }
        for (axis, p) in self.axes.iter_mut().enumerate() {
            let Some(cascade) = &mut p.bounded else {
                continue;
            };
            cascade.set_offset(p.bounds.offset, p.bounds.offset_slope);
            if !p.bounds.violated(&p.plan, sent(axis), dt) {
                cascade.skip();
                continue;
            }
            cascade.solve(AxisProblem {
                fixed: &fixed_axis[axis],
                sent: sent(axis),
                reference: &p.reference,
                plan: &mut p.plan,
            })?;
            report.solved(cascade.solved_by());
        }
        if let Some(cone) = &mut self.cone {
            let [ax, ay, rest @ ..] = self.axes.as_mut_slice() else {
                unreachable!("DfMpc::new makes at least two axes")
            };
            if let Some(az) = rest.first() {
                // The spatial model plans thrust: the tilt cone's radius
                // follows the vertical plan (solved above).
                cone.follow_vertical_plan(&az.plan, dt)?;
            }
            // The thrust's tilt: the cone about the model's offsets, along
            // the last plan when it is the last tick's.
            let along = cone.along_valid.then_some(cone.along.as_slice());
            cone_centre(
                &mut cone.centre,
                [&*ax, &*ay],
                [&fixed_axis[0], &fixed_axis[1]],
                along,
                dt,
            );
            cone.cascade.set_centre(&cone.centre)?;
            let plans = [ax.plan.as_slice(), ay.plan.as_slice()];
            if !(cone
                .bounds
                .violated_within(plans[0], plans[1], dt, (&cone.radius, &cone.centre))
                || cone.bounds.rate_violated_by(plans, [sent(0), sent(1)], dt))
            {
                // Not solved: the next solve has no previous one to shift.
                cone.cascade.skip();
                return Ok(report);
            }
            let (_, px) = ax.problem(&fixed_axis[0], sent(0));
            let (_, py) = ay.problem(&fixed_axis[1], sent(1));
            cone.cascade.solve(px, py)?;
            report.solved(cone.cascade.solved_by());
        }
        Ok(report)
    }
}

/// The tilt cone's centre per stage f (acceleration row j = f + 1) [m/s²]
/// into `centre`: per horizontal axis `o_j`, what the model adds to the
/// thrust's acceleration (`ρ − D·v`), so that the cone bounds the thrust's
/// tilt (the plan's acceleration less o_j).
///
/// * At j = 1 it is the window's offset ([`AxisBounds::stage_offsets`]:
///   the learned hook's when a residual is flown, else `−D·v_1` at the
///   window's speed).
/// * Along the horizon, with `along` (the last plan's offsets one tick on
///   less its first stage's, `DfMpc::offsets_along_last_plan`): `o_1 +
///   along_f` — the model's offsets linearised along the last plan, as the
///   learned maps are, so that a braking plan counts on the drag of the
///   speed it will have and a turn on the drag it will meet.
/// * Without: the box's offsets ([`AxisBounds::stage_offsets`]: the
///   start's, moved towards 0 by its change per stage while it shrinks).
///
/// On the lab's L at 5 and 7 m/s (`dflat experiment learned
/// --plan-tilt-bound cone`) the box's rule alone flew the learned maps
/// 1.09–1.26× the matched plant, along the last plan 0.95–1.15×: a
/// braking plan counted on the cruise drag to its stop, a turn not on the
/// drag it meets (docs/results.md, "The tilt cone about the model's
/// offsets").
fn cone_centre(
    centre: &mut [[f64; 2]],
    axes: [&AxisPipeline; 2],
    fixed: [&[f64; 3]; 2],
    along: Option<&[[f64; 2]]>,
    dt: f64,
) {
    for (i, (p, f)) in axes.into_iter().zip(fixed).enumerate() {
        let offsets = p.bounds.stage_offsets(f, dt);
        let o1 = offsets(1);
        for (k, o) in centre.iter_mut().enumerate() {
            o[i] = match along {
                Some(a) => o1 + a[k][i],
                None => offsets(k + 1),
            };
        }
    }
}
