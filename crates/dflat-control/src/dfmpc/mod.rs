//! The discrete-flatness MPC (DF-MPC) of *Fly Out The Window*, §IV-C and §V.
//!
//! # The problem solved at tick k
//!
//! Per position axis (x, y; and z for the spatial model), over the output
//! trajectory `y_k..y_{k+N}` (horizon N, control step δt):
//!
//! ```text
//! minimise   Σ_{j=0..N} q·(y_{k+j} − y_ref,{k+j})²  +  Σ_{j=0..N−3} r·(Δ³y_{k+j}/δt³)²
//!            Δ³y_j = y_{j+3} − 3y_{j+2} + 3y_{j+1} − y_j          (jerk × δt³)
//! subject to y_k = y^m_k                                 (newest measurement)
//!            y_{k+1}, y_{k+2} = F⁻¹ chained over the window (paper eq. input_to_output)
//!            and, when configured (all optional):
//!            |Δ²y_j/δt²| ≤ g·tan(tilt_max)     j = 1..N−2, horizontal axes
//!            a_min ≤ Δ²z_j/δt² ≤ a_max          j = 1..N−2, vertical axis (spatial)
//!            |Δy_j/δt| ≤ v_max                   j = 2..N−1, every axis
//! ```
//!
//! The paper weights the raw third difference with R; here r weights the
//! jerk, `R = r/δt⁶` (the paper's R = 1.25e9 at δt = 0.02 s is r = 0.08), so
//! weights are O(0.01–1). Then `u_k = F(y*_k..y*_{k+3})`, saturated, is sent
//! and recorded in the [`Window`].
//!
//! # Multi-rate windows (optional)
//!
//! With [`DfMpcSettings::multi_rate`] the fixed outputs `y_k, y_{k+1},
//! y_{k+2}` come from a [`MultiRateWindow`]: timestamped pose samples
//! (vision at 10–35 Hz, latency, dropouts) fitted by a chain of F⁻¹ through
//! the inputs sent over the last M ticks (maths in [`crate::window`]). The
//! shell calls [`Controller::observe`] per sample and [`Controller::update`]
//! per tick with the tick time. Everything after the fixed outputs is as
//! above.

mod delay;
mod learned_hook;
#[cfg(test)]
mod learned_tests;
mod settings;
mod solve;
#[cfg(test)]
mod tests;

use delay::DelayLine;
pub use delay::MAX_DELAY_TICKS;
pub use settings::{DfMpcSettings, InputSaturation, OutputConstraints, PlanTiltBound, QpSolver};

use solve::{AxisPipeline, HorizontalCone, build_pipelines};

use nalgebra::Vector3;

use crate::disturbance::{DisturbanceEstimate, DisturbanceEstimator};
use crate::model::ControlModel;
use crate::optimise::{AxisBounds, AxisCascade, ConeBounds, PairCascade, invalid};
use crate::window::{MultiRateWindow, Placement, SLOTS, Window};
use crate::{ControlError, Controller, Measurement, ReferenceSource, TickOutput, limit_tilt};

/// Most ticks [`Controller::plan_fallback`] flies the last good plan (and
/// at most N − 3: the plan's end).
pub const MAX_FALLBACK_STEPS: usize = 50;

// ---------------------------------------------------------------------------
// The controller
// ---------------------------------------------------------------------------

/// The discrete-flatness MPC controller (see the module docs).
///
/// One [`Controller::update`] per control step δt: window → F⁻¹ prediction
/// of y_{k+1}, y_{k+2} → reference over the horizon → per-axis optimisation
/// → F on y*_k..y*_{k+3} → saturation → the sent input into the window.
/// The measurement is placed in the window by its time `t`
/// ([`Window::place`]): one not newer than the last one used (a tick
/// without a new pose) is not entered as new, and y_k is the model's own
/// prediction, F⁻¹ over the window with the inputs already sent (dead
/// reckoning; the shell's pose timeout bounds how long); a pose a tick late
/// takes its own tick's slot; ticks the shell skipped are filled with
/// predictions under the input it held.
/// With [`DfMpcSettings::multi_rate`] the window is a [`MultiRateWindow`]:
/// samples come through [`Controller::observe`], `update` takes the tick
/// time. Commands use the model's fixed yaw ψ⋆ (the measured yaw is only
/// checked for being finite). Without binding constraints `update` allocates nothing
/// (all workspaces are sized in [`DfMpc::new`]); clarabel's solve may.
#[derive(Debug)]
pub struct DfMpc {
    model: ControlModel,
    settings: DfMpcSettings,
    /// The flatness window (classic mode): the last R measured outputs and
    /// R − 1 sent inputs.
    window: Window,
    /// The multi-rate window, when configured (then `window` stays empty).
    multi: Option<MultiRateWindow>,
    /// Disturbance estimator, when configured.
    estimator: Option<DisturbanceEstimator>,
    /// One optimisation pipeline per controlled axis (x, y; z spatial).
    axes: Vec<AxisPipeline>,
    /// The horizontal pair's tilt-cone QP, when the plan's tilt bound is
    /// the cone ([`PlanTiltBound::Cone`]).
    cone: Option<HorizontalCone>,
    /// Reference y_ref,k..y_ref,k+d+N (model frame, m; d the input
    /// delay's ticks: the plan takes it from k + d) of this tick, and of
    /// the last good tick (swapped after each good tick).
    reference: Vec<Vector3<f64>>,
    good_reference: Vec<Vector3<f64>>,
    /// y_k of the last good tick (the z of planar plans) \[m\].
    good_y0: Vector3<f64>,
    /// True when some axis has a smoothness weight.
    smooth: bool,
    /// What plan there is to fly.
    plan: PlanState,
    /// Whether the sent inputs are all recorded.
    record: RecordState,
    /// Ticks the shell skipped since the last recorded tick
    /// ([`Controller::skipped`]; classic window only).
    skipped: u32,
    /// The inputs sent and not yet in effect (input delay).
    delay: DelayLine,
    /// The learned residual, when flown ([`DfMpc::set_learned`]).
    learned: Option<crate::learned::LearnedTerm>,
    /// What scoring the learned term needs between ticks.
    learned_score: learned_hook::Score,
}

/// The plan DF-MPC can fly without a new solve ([`Controller::plan_fallback`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PlanState {
    /// None: before the first good tick, after a reset, or once the kept
    /// plan is used up or could not be mapped.
    Empty,
    /// The last `update` succeeded: its plan is current ([`DfMpc::plan`]);
    /// `flown` steps of it flown since by `plan_fallback` (late ticks).
    Fresh {
        /// Plan steps flown.
        flown: usize,
    },
    /// An `update` failed (or is under way) after a good one: the last good
    /// plan is kept; `flown` steps of it flown by `plan_fallback`.
    Kept {
        /// Plan steps flown.
        flown: usize,
    },
}

impl PlanState {
    /// Plan steps flown since the last good tick, if there is a plan.
    fn flown(self) -> Option<usize> {
        match self {
            Self::Empty => None,
            Self::Fresh { flown } | Self::Kept { flown } => Some(flown),
        }
    }
}

/// Whether every command this controller produced was recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RecordState {
    /// Every tick's command is in the window.
    Recorded,
    /// This tick started and its command is not recorded yet.
    Pending,
    /// An earlier tick was never recorded (failed `update`, no plan
    /// fallback) and this one is pending: the classic window has a gap and
    /// restarts from its start-up padding at the next recorded tick.
    PendingAfterGap,
}

impl DfMpc {
    /// Builds the controller: validates the settings, factors the fast-path
    /// Hessians and builds the bounded solvers (all allocation happens here).
    pub fn new(model: ControlModel, settings: DfMpcSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let axes = model.axes();
        let c = &settings.constraints;
        if axes < 3 && c.vertical_acceleration.is_some() {
            return Err(invalid(
                "constraints.vertical_acceleration",
                "needs the spatial model (the planar model does not control z)",
            ));
        }
        let (pipelines, cone) = build_pipelines(&model, &settings)?;
        let n = settings.horizon;
        Ok(Self {
            model,
            settings,
            window: Window::new(model.hover_input()),
            multi: settings
                .multi_rate
                .map(|m| MultiRateWindow::new(&model, m))
                .transpose()?,
            estimator: settings
                .disturbance
                .map(|d| DisturbanceEstimator::new(model, d))
                .transpose()?,
            axes: pipelines,
            cone,
            reference: vec![Vector3::zeros(); n + 1 + settings.delay_ticks],
            good_reference: vec![Vector3::zeros(); n + 1 + settings.delay_ticks],
            good_y0: Vector3::zeros(),
            smooth: settings
                .smoothness_weight
                .iter()
                .take(axes)
                .any(|s| *s > 0.0),
            plan: PlanState::Empty,
            record: RecordState::Recorded,
            skipped: 0,
            delay: DelayLine::new(settings.delay_ticks, model.hover_input()),
            learned: None,
            learned_score: learned_hook::Score::default(),
        })
    }

    /// The model.
    pub fn model(&self) -> &ControlModel {
        &self.model
    }

    /// The settings.
    pub fn settings(&self) -> &DfMpcSettings {
        &self.settings
    }

    /// The disturbance estimator, when configured.
    pub fn disturbance_estimator(&self) -> Option<&DisturbanceEstimator> {
        self.estimator.as_ref()
    }

    /// The window of past measurements and sent inputs (classic mode; it
    /// stays empty in multi-rate mode).
    pub fn window(&self) -> &Window {
        &self.window
    }

    /// The multi-rate window, when configured.
    pub fn multi_rate_window(&self) -> Option<&MultiRateWindow> {
        self.multi.as_ref()
    }

    /// The full plan `y*_k..y*_{k+N}` \[m\] of `axis` (0 = x, 1 = y, 2 = z)
    /// from the last update when it succeeded; `None` before one, after a
    /// failed one or for an axis the model does not control.
    pub fn plan(&self, axis: usize) -> Option<&[f64]> {
        match self.plan {
            PlanState::Fresh { .. } => self.axes.get(axis).map(|a| a.good_plan.as_slice()),
            _ => None,
        }
    }

    /// The horizontal tilt cone (and its soft speed bounds), when the plan's
    /// tilt bound is the cone ([`PlanTiltBound::Cone`]).
    pub fn cone_bounds(&self) -> Option<&ConeBounds> {
        self.cone.as_ref().map(|c| c.bounds())
    }

    /// The tilt cone's radius per stage [m/s²] as of the last tick
    /// (stage f bounds the planned horizontal acceleration of output
    /// f + 2): `g·tan(max_tilt)` with the planar model; with the spatial
    /// model `tan(max_tilt)·(g − a_z)` (NED; `g + a_z` z up) from the
    /// vertical plan, the thrust's vertical part floored at 0.2·g.
    pub fn cone_radius(&self) -> Option<&[f64]> {
        self.cone.as_ref().map(|c| c.radius())
    }

    /// The tilt cone's centre per stage [m/s²] as of the last tick (x, y;
    /// stage f as [`DfMpc::cone_radius`]): what the model adds to the
    /// thrust's acceleration (the drag `−D·v`, a learned residual), so
    /// that the cone bounds the planned acceleration less it, the thrust's
    /// tilt. Zero without drag or residual.
    pub fn cone_centre(&self) -> Option<&[[f64; 2]]> {
        self.cone.as_ref().map(|c| c.centre())
    }

    /// Whether the last tick's cone centre came along the last plan
    /// (true: the model's offsets one tick on along the plan the tick
    /// before made) or by the box's rule (false: no drag or residual, no
    /// plan of the tick before, or it failed); `None` without the cone.
    pub fn cone_centre_along_last_plan(&self) -> Option<bool> {
        self.cone.as_ref().map(|c| c.along_valid)
    }

    /// The tilt cone's cascade of solvers, with the statistics of their
    /// last solves (which solved, iterations, warm start), when the plan's
    /// tilt bound is the cone.
    pub fn cone_cascade(&self) -> Option<&PairCascade> {
        self.cone.as_ref().map(|c| c.cascade())
    }

    /// The box cascade of `axis` (0 = x, 1 = y, 2 = z), when that axis
    /// has bounds of its own.
    pub fn box_cascade(&self, axis: usize) -> Option<&AxisCascade> {
        self.axes.get(axis).and_then(|a| a.bounded.as_ref())
    }

    /// The tilt cone's cascade, mutable: for a solver inserted to observe
    /// its problems ([`PairCascade::insert`]; the corner bench's OSQP anchor).
    pub fn cone_cascade_mut(&mut self) -> Option<&mut PairCascade> {
        self.cone.as_mut().map(|c| &mut c.cascade)
    }

    /// The box cascade of `axis`, mutable (as [`DfMpc::cone_cascade_mut`]).
    pub fn box_cascade_mut(&mut self, axis: usize) -> Option<&mut AxisCascade> {
        self.axes.get_mut(axis).and_then(|a| a.bounded.as_mut())
    }

    /// The per-axis bounds derived from the constraints (x, y, z order);
    /// with the cone, the horizontal axes' are in [`DfMpc::cone_bounds`].
    pub fn bounds(&self, axis: usize) -> Option<&AxisBounds> {
        self.axes.get(axis).map(|a| &a.bounds)
    }

    /// Clips `u` to the input saturation; returns it and whether it clipped.
    fn saturate(&self, u: Vector3<f64>) -> (Vector3<f64>, bool) {
        let Some(s) = &self.settings.saturation else {
            return (u, false);
        };
        let mut out = u;
        (out.x, out.y, _) = limit_tilt(u.x, u.y, s.max_tilt, s.tilt_limit);
        if matches!(self.model, ControlModel::Spatial(_)) {
            out.z = u.z.clamp(s.thrust_min, s.thrust_max);
        }
        (out, out != u)
    }

    /// The disturbance estimate this tick uses (nominal without an
    /// estimator).
    fn disturbance_estimate(&self) -> DisturbanceEstimate {
        self.estimator
            .as_ref()
            .map_or(DisturbanceEstimate::NOMINAL, |e| e.estimate())
    }

    /// Step 3: the reference from tick k (`y_k` the window's output
    /// there), split per axis from the plan's start on: with an input
    /// delay of d ticks the plan starts at k + d, and so does each axis's
    /// reference (`y_ref,k+d..`; before, a time-indexed source — a stream,
    /// a route — was tracked d ticks late).
    fn build_reference(
        &mut self,
        y_k: &Vector3<f64>,
        reference: &mut dyn ReferenceSource,
    ) -> Result<(), ControlError> {
        let axes = self.axes.len();
        let lead = self.settings.delay_ticks;
        reference.horizon(y_k, self.model.dt(), &mut self.reference);
        if !self
            .reference
            .iter()
            .all(|r| r.iter().take(axes).all(|v| v.is_finite()))
        {
            return Err(ControlError::NonFiniteReference);
        }
        let flyable = reference.flyable();
        let dt = self.model.dt();
        for (axis, pipeline) in self.axes.iter_mut().enumerate() {
            for (dst, r) in pipeline.reference.iter_mut().zip(&self.reference[lead..]) {
                *dst = r[axis];
            }
            if flyable {
                let (q, r) = (
                    self.settings.tracking_weight[axis],
                    self.settings.jerk_weight[axis],
                );
                crate::optimise::feed_forward::feed_forward(
                    &mut pipeline.reference,
                    &mut pipeline.feed_forward,
                    q,
                    r,
                    dt,
                    &pipeline.fast.smoothness(),
                );
            }
        }
        Ok(())
    }

    /// Step 5: the output-to-input map F on y*_k..y*_{k+3} of this tick's
    /// plan; returns the four outputs and the input.
    fn map_through_f(
        &self,
        y0: Vector3<f64>,
        d: &DisturbanceEstimate,
    ) -> Result<([Vector3<f64>; 4], Vector3<f64>), ControlError> {
        let mut plan4 = [y0; 4];
        for (j, p) in plan4.iter_mut().enumerate() {
            for (axis, pipeline) in self.axes.iter().enumerate() {
                p[axis] = pipeline.plan[j];
            }
        }
        let u = self.f(&plan4, d)?;
        if !u.iter().all(|v| v.is_finite()) {
            return Err(ControlError::Flat(dflat_model::FlatError::NonFinite(
                "input",
            )));
        }
        Ok((plan4, u))
    }

    /// Keeps this tick's plan and reference as the good ones (O(1): the
    /// buffers swap; the next tick overwrites the other pair in full).
    fn keep_plan(&mut self, y0: Vector3<f64>) {
        for p in &mut self.axes {
            std::mem::swap(&mut p.plan, &mut p.good_plan);
        }
        std::mem::swap(&mut self.reference, &mut self.good_reference);
        self.good_y0 = y0;
        self.plan = PlanState::Fresh { flown: 0 };
    }
}

/// What [`DfMpc::fixed_outputs`] gives a tick.
struct FixedOutputs {
    /// The classic window with y_k pushed (a copy; unused in multi-rate).
    window: Window,
    /// `[y_k, y_{k+1}, y_{k+2}]` \[m\], model frame.
    fixed: [Vector3<f64>; 3],
    /// The input sent at k−1.
    previous_input: Vector3<f64>,
    /// Skipped ticks the classic window filled before y_k (0 in
    /// multi-rate).
    filled: usize,
    /// Ticks since the last committed one that nothing was sent on (the
    /// classic window's filled ticks; the multi-rate window's, from the
    /// tick times): the input delay's line moves on over them.
    gap: usize,
}

impl DfMpc {
    /// The fixed outputs `[y_k, y_{k+1}, y_{k+2}]` and the input sent at
    /// k−1: from the multi-rate window (moved to `measurement.t`, committed
    /// by [`DfMpc::commit`]), or from a copy of the classic window with the
    /// measurement placed by its time ([`Window::place`]: y_k is the
    /// measurement, or the model's own prediction on a tick without a new
    /// pose; a late pose takes its own tick's slot, skipped ticks are
    /// filled) — then F⁻¹ for y_{k+1}, y_{k+2}. The copy is returned for
    /// `commit`; after a gap it starts from the start-up padding.
    fn fixed_outputs(
        &mut self,
        measurement: &Measurement,
        d: &DisturbanceEstimate,
    ) -> Result<FixedOutputs, ControlError> {
        let mut window = self.window;
        if self.record == RecordState::PendingAfterGap {
            window.reset();
        }
        // With an input delay, the ticks nothing was sent on had the
        // inputs in flight in effect, then the newest held.
        let (in_flight, delayed) = self.delay.in_flight();
        if let Some(multi) = &mut self.multi {
            let dt = self.model.dt();
            let gap = multi.last_tick().map_or(0, |last| {
                (((measurement.t - last) / dt).round() - 1.0).clamp(0.0, MAX_DELAY_TICKS as f64)
                    as usize
            });
            multi.set_pending_inputs(&in_flight[..delayed]);
            let (model, learned) = (&self.model, self.learned.as_ref());
            let e = multi.estimate(measurement.t, |y, u| {
                learned_hook::next_output(model, learned, y, u, d)
            })?;
            return Ok(FixedOutputs {
                window,
                fixed: e.fixed,
                previous_input: e.previous_input,
                filled: 0,
                gap,
            });
        }
        window.set_pending_inputs(&in_flight[..delayed]);
        // Ticks the shell skipped, known from its clock: filled before
        // y_k, so a tick after them without a new pose is at its own slot.
        let skipped = window.fill_skipped(self.skipped as usize, &|y, u| self.f_inv(y, u, d))?;
        let placement = window.place(
            measurement.t,
            measurement.position,
            self.model.dt(),
            &|y, u| self.f_inv(y, u, d),
        )?;
        let filled = skipped
            + match placement {
                Placement::Next { filled } => filled,
                _ => 0,
            };
        let [ym2, ym1, y0] = *window.outputs();
        let [u2, u1] = *window.inputs();
        let y1 = self.f_inv(&[ym2, ym1, y0], &u2, d)?;
        let y2 = self.f_inv(&[ym1, y0, y1], &u1, d)?;
        Ok(FixedOutputs {
            window,
            fixed: [y0, y1, y2],
            previous_input: u1,
            filled,
            gap: filled,
        })
    }

    /// Records `sent` as this tick's input: the disturbance estimator, then
    /// the classic window (the copy from [`DfMpc::fixed_outputs`]) and the
    /// prediction of the next tick's output, or the multi-rate commit.
    fn commit(
        &mut self,
        mut window: Window,
        t: f64,
        fixed: &[Vector3<f64>; 3],
        (filled, gap): (usize, usize),
        sent: &Vector3<f64>,
        saturated: bool,
    ) {
        // The input in effect at this tick (the one sent d ticks ago; over
        // the ticks nothing was sent on, the newest held).
        self.delay.skip(gap);
        let applied = self.delay.push(*sent);
        let sent = &applied;
        if let Some(e) = &mut self.estimator {
            if self.multi.is_some() {
                // Multi-rate: the estimator fits the timestamped samples it
                // got through `observe`, never the window's estimate of y_k.
                e.record_input(t, sent, saturated);
            } else {
                // Skipped ticks the window filled, under the input held:
                // the estimator's own window stays a tick apart too (left
                // out, a skipped tick biased its horizontal estimate by
                // 0.1 m/s²: `classic_window_timing.rs`).
                // Output slot i was in effect under input slot i + 1 (y_k
                // is placed, u_k not yet pushed). Filled slots beyond those
                // the window keeps (a longer stall) are gone: the
                // estimator's window starts again from the kept ones.
                let (slots, inputs) = (window.slot_outputs(), window.slot_inputs());
                if filled > SLOTS - 1 {
                    e.after_gap();
                }
                for back in (1..=filled.min(SLOTS - 1)).rev() {
                    e.record(&slots[SLOTS - 1 - back], &inputs[SLOTS - back], false);
                }
                // A tick without a new pose: the predicted y_k stands in.
                e.record(&fixed[0], sent, saturated);
            }
        }
        if let Some(multi) = &mut self.multi {
            multi.commit(sent);
        } else {
            window.push_input(*sent);
            self.window = window;
        }
        self.record = RecordState::Recorded;
        self.skipped = 0;
    }
}

/// The acceleration [m/s²] (model frame) that input `u` asks for: the
/// model's acceleration at the attitude (and thrust) the input dynamics
/// settle to, `k̃·(θ_cmd, φ_cmd)` (and `T_cmd`). Planar: z = 0.
fn commanded_acceleration(
    model: &ControlModel,
    u: &Vector3<f64>,
) -> Result<Vector3<f64>, ControlError> {
    Ok(match model {
        ControlModel::Planar(m) => {
            let k = m.params().k;
            let a = m.acceleration(k * u.x, k * u.y)?;
            Vector3::new(a.x, a.y, 0.0)
        }
        ControlModel::Spatial(m) => {
            let k = m.params().k;
            m.acceleration(k * u.x, k * u.y, u.z)
        }
    })
}

impl Controller for DfMpc {
    fn name(&self) -> &'static str {
        "df-mpc"
    }

    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        // A previous tick sent something this controller did not record
        // (failed update, no plan fallback): the window has a gap.
        self.record = match self.record {
            RecordState::Recorded => RecordState::Pending,
            RecordState::Pending | RecordState::PendingAfterGap => RecordState::PendingAfterGap,
        };
        // The last plan is the last tick's only when that tick's update
        // made it and flew none of it since (a failed update leaves it
        // `Kept`: a tick older, its stages one off).
        let last_ticks_plan = self.plan == PlanState::Fresh { flown: 0 } && self.skipped == 0;
        if let PlanState::Fresh { flown } = self.plan {
            self.plan = PlanState::Kept { flown };
        }
        if let Some(e) = &mut self.estimator {
            e.begin_tick();
        }
        let d = self.disturbance_estimate();
        self.learned_score_tick(measurement);
        let axes = self.model.axes();
        // Multi-rate mode takes only the tick time (and checks the yaw).
        let position_ok = self.multi.is_some()
            || measurement
                .position
                .iter()
                .take(axes)
                .all(|v| v.is_finite());
        if !(position_ok && measurement.yaw.is_finite()) {
            return Err(ControlError::NonFiniteMeasurement);
        }
        // 1–2. The window and the input-to-output map F⁻¹ over it: y_k,
        // y_{k+1}, y_{k+2}, and the input sent at k−1 (for the smoothness
        // term). The window is a copy: on error nothing is recorded.
        let FixedOutputs {
            window,
            fixed,
            previous_input,
            filled,
            gap,
        } = self.fixed_outputs(measurement, &d)?;
        // 2b. Across the inputs sent and not yet in effect (input delay):
        // the plan starts at k + d.
        let mut line = self.delay;
        line.skip(gap);
        let planned = line.predict(fixed, |y, u| self.f_inv(y, u, &d))?;
        let previous_input = line.newest().unwrap_or(previous_input);
        let y0 = planned[0];
        // The sent command's acceleration in the plan's terms (Δ²y/δt²):
        // the thrust's, less the drag at the plan's start velocity, plus
        // the disturbance. Without the drag the tilt-rate bound's first
        // row pinned the plan's acceleration to the thrust's, D·v too
        // high, and a model with drag ran away (0.3 /s: 100 m).
        let sent_acceleration = if self.anchors_sent() {
            let velocity = (y0 - planned[1]) / -self.model.dt();
            Some(
                commanded_acceleration(&self.model, &previous_input)?
                    + d.acceleration
                    + self.sent_offset(&velocity),
            )
        } else {
            None
        };
        // 3. The reference over the horizon (from tick k: the plan takes
        // it from its start, k + d).
        self.build_reference(&fixed[0], reference)?;
        // 4. Output trajectory optimisation.
        let (offsets, slopes) = self.bound_shifts(&planned, &d);
        // The cone's centre along the last plan (`solve.rs`, `cone_centre`):
        // without drag or a residual every offset is 0.
        let offsets_move = self.learned.is_some() || self.model.drag() != Vector3::zeros();
        if let Some(mut along) = self.cone.as_mut().map(|c| std::mem::take(&mut c.along)) {
            let valid =
                offsets_move && last_ticks_plan && self.offsets_along_last_plan(&d, &mut along);
            if let Some(c) = self.cone.as_mut() {
                (c.along, c.along_valid) = (along, valid);
            }
        }
        let solve = self.optimise(&planned, sent_acceleration, offsets, slopes)?;
        // 5. The output-to-input map F on y*_k..y*_{k+3}.
        let (plan4, u) = self.map_through_f(y0, &d)?;
        // 6. Saturation; the sent input into the window.
        let (sent, saturated) = self.saturate(u);
        self.commit(
            window,
            measurement.t,
            &fixed,
            (filled, gap),
            &sent,
            saturated,
        );
        self.keep_plan(y0);
        self.keep_sent_offset(&plan4, &d);
        self.learned_after_tick(measurement.t, &plan4, &sent, &d);
        Ok(TickOutput {
            command: self.model.command(&sent),
            plan: plan4,
            reference: self.good_reference[0],
            saturated,
            constrained: solve.constrained,
            qp_fallback: solve.qp_fallback,
            cone_interior_point: solve.interior_point,
        })
    }

    fn multi_rate(&self) -> bool {
        self.multi.is_some()
    }

    fn skipped(&mut self, ticks: u32) {
        // The multi-rate window takes the tick time from the update.
        if self.multi.is_none() {
            self.skipped = self.skipped.saturating_add(ticks);
        }
    }

    fn tick_time(&self, measurement: &Measurement) -> f64 {
        // `update` restarts the window when a tick since the last one sent
        // something unrecorded (`RecordState`).
        if self.multi.is_some() || self.record != RecordState::Recorded {
            // The tick time itself, or a window that starts again.
            measurement.t
        } else {
            self.window
                .tick_time(measurement.t, self.model.dt(), self.skipped as usize)
        }
    }

    fn window_stats(&self) -> Option<crate::window::PoseWindowStats> {
        use crate::window::PoseWindowStats;
        Some(match &self.multi {
            Some(multi) => PoseWindowStats::MultiRate(multi.stats()),
            None => PoseWindowStats::Classic(self.window.stats()),
        })
    }

    /// Flies the last good plan: step s = 1, 2, … of it through F (with
    /// the current disturbance estimate) and saturation, s counting the
    /// ticks since the good one, skipped ticks ([`Controller::skipped`],
    /// or found by the tick times) included. A non-finite
    /// measurement is not used (classic mode: y_k is the model's
    /// prediction, as on a tick without a new pose). In multi-rate mode a
    /// tick time not after the last committed tick (a late update's tick)
    /// is taken as the step after it. `None` once
    /// `max_steps` or [`MAX_FALLBACK_STEPS`] steps are flown, the kept plan
    /// is used up, or the map fails.
    fn plan_fallback(&mut self, measurement: &Measurement, max_steps: usize) -> Option<TickOutput> {
        // Until a plan step is recorded, this tick's command is unknown.
        if self.record == RecordState::Recorded {
            self.record = RecordState::Pending;
        }
        let previous = self.plan;
        // Used up or unmappable unless this step is flown.
        self.plan = PlanState::Empty;
        let next = previous.flown()? + 1;
        let last_step = max_steps
            .min(MAX_FALLBACK_STEPS)
            .min(self.settings.horizon.saturating_sub(3));
        if next > last_step {
            return None;
        }
        let d = self.disturbance_estimate();
        let axes = self.model.axes();
        let mut m = *measurement;
        match &self.multi {
            // A tick already committed at this time (the shell could not
            // use a late update's result): this is the step after it.
            Some(multi) => {
                if let Some(last) = multi.last_tick()
                    && (m.t.is_nan() || m.t <= last)
                {
                    m.t = last + self.model.dt();
                }
            }
            None => {
                if !m.position.iter().take(axes).all(|v| v.is_finite()) {
                    m.t = f64::NEG_INFINITY;
                }
            }
        }
        let FixedOutputs {
            window,
            fixed,
            filled,
            gap,
            ..
        } = self.fixed_outputs(&m, &d).ok()?;
        // Step s of the plan is in effect at (good tick + d + s): sending
        // it now keeps the delay's bookkeeping. Ticks skipped since the
        // last one sent (`gap`) count: the plan is that much older.
        let step = next + gap;
        if step > last_step {
            return None;
        }
        let plan4: [Vector3<f64>; 4] = std::array::from_fn(|j| {
            let mut p = self.good_y0;
            for (axis, pipeline) in self.axes.iter().enumerate() {
                p[axis] = pipeline.good_plan[step + j];
            }
            p
        });
        let u = self.f(&plan4, &d).ok()?;
        if !u.iter().all(|v| v.is_finite()) {
            return None;
        }
        let (sent, saturated) = self.saturate(u);
        self.commit(window, m.t, &fixed, (filled, gap), &sent, saturated);
        self.keep_sent_offset(&plan4, &d);
        self.plan = match previous {
            PlanState::Fresh { .. } => PlanState::Fresh { flown: step },
            _ => PlanState::Kept { flown: step },
        };
        Some(TickOutput {
            command: self.model.command(&sent),
            plan: plan4,
            reference: self.good_reference[step],
            saturated,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }

    /// Replaces the input recorded last (classic or multi-rate window, and
    /// the disturbance estimator's input state) with `applied`. The kept
    /// plan was made for the input sent, so the plan fallback is dropped.
    fn correct_last_input(&mut self, applied: &Vector3<f64>) {
        if !applied.iter().all(|v| v.is_finite()) || self.record != RecordState::Recorded {
            return;
        }
        if let Some(multi) = &mut self.multi {
            multi.replace_last_input(applied);
        } else {
            self.window.replace_last_input(*applied);
        }
        if let Some(e) = &mut self.estimator {
            e.correct_last_input(applied);
        }
        // The inputs sent in standby were not flown: take the applied one
        // as what is pending.
        self.delay.fill(*applied);
        self.plan = PlanState::Empty;
        self.forget_sent_offset();
    }

    fn observe(&mut self, sample: &Measurement) {
        if self.multi.is_some() {
            self.learned_observe(sample);
        }
        if let Some(multi) = &mut self.multi {
            multi.observe(sample.t, &sample.position);
            if let Some(e) = &mut self.estimator {
                e.observe(sample.t, &sample.position);
            }
        }
    }

    fn reset(&mut self) {
        self.window.reset();
        self.skipped = 0;
        self.delay.fill(self.model.hover_input());
        if let Some(multi) = &mut self.multi {
            multi.reset();
        }
        self.plan = PlanState::Empty;
        self.record = RecordState::Recorded;
        if let Some(e) = &mut self.estimator {
            e.reset();
        }
        self.learned_reset();
        if let Some(c) = &mut self.cone {
            c.reset();
        }
        for a in &mut self.axes {
            if let Some(b) = &mut a.bounded {
                b.reset();
            }
        }
    }

    fn disturbance(&self) -> Option<crate::disturbance::DisturbanceReport> {
        self.estimator.as_ref().map(|e| e.report())
    }

    fn learned_status(&self) -> Option<crate::learned::LearnedStatus> {
        self.learned.as_ref().map(|l| l.status())
    }
}
