//! DF-MPC's hook points for the learned residual
//! ([`crate::learned::LearnedTerm`]): the maps with the residual in each
//! step ([`DfMpc::f_inv`], [`DfMpc::f`]), the score of the residual against
//! the acceleration the parametric model leaves unexplained, and the
//! support at the plan's start.

use nalgebra::Vector3;

use dflat_model::FlatError;

use super::{DfMpc, commanded_acceleration};
use crate::Measurement;
use crate::disturbance::DisturbanceEstimate;
use crate::learned::{LearnedResidual, LearnedTerm};
use crate::model::ControlModel;

/// F⁻¹ of `model` with the disturbance estimate `d` and, when flown, the
/// learned residual in each of its two steps: `y_{k+3}` from `y_k..y_{k+2}`
/// and `u_k`.
pub(super) fn next_output(
    model: &ControlModel,
    learned: Option<&LearnedTerm>,
    y: &[Vector3<f64>; 3],
    u: &Vector3<f64>,
    d: &DisturbanceEstimate,
) -> Result<Vector3<f64>, FlatError> {
    match learned {
        Some(l) => {
            let steps = l.step_offsets(model, y, &d.acceleration);
            model.next_output_stepped(y, u, d, &steps)
        }
        None => model.next_output_disturbed(y, u, d),
    }
}

/// What scoring the residual needs between ticks (classic mode).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Score {
    /// The newest measured outputs, oldest first \[m\].
    recent: [Vector3<f64>; 3],
    /// Their times \[s\] (the poses' clock), oldest first.
    recent_t: [f64; 3],
    /// How many of `recent` are filled (up to 3).
    filled: usize,
    /// The parametric model's acceleration (no drag) the commands sent so
    /// far ask for through the attitude lag τ [m/s²] (None before a
    /// command and after one F could not make).
    now: Option<Vector3<f64>>,
    /// The newest pose samples (multi-rate mode), oldest first: time \[s\]
    /// and position \[m\].
    samples: [(f64, Vector3<f64>); RING],
    /// How many of `samples` are filled (up to [`RING`]).
    sampled: usize,
    /// The parametric acceleration of the newest ticks' commands, oldest
    /// first: the time it acts on the vehicle (the tick's, plus the input
    /// delay) \[s\] and the acceleration [m/s²].
    ticks: [(f64, Vector3<f64>); RING],
    /// How many of `ticks` are filled.
    ticked: usize,
    /// What the model adds to the thrust's acceleration in the command
    /// sent last, in the plan's terms of the smoothness term and the
    /// tilt-rate bound: `o_0 + κ·(o_1 − o_0)` over its plan's two steps,
    /// `o_j = ρ_j − D·v_j` (κ = the input lag over δt, per axis) [m/s²];
    /// None before a plan, after a reset or a replaced input.
    sent_offset: Option<Vector3<f64>>,
}

/// Pose samples and ticks the multi-rate scoring keeps.
const RING: usize = 32;

/// Spacing \[s\] of the three pose samples whose second difference scores
/// the residual (multi-rate mode): wide, so the pose noise does not drown
/// it (√6·σ/h², 2 m/s² at 2 cm, against 120 m/s² for 50 Hz neighbours).
pub(crate) const SCORE_SPACING_S: f64 = 0.15;

/// Pushes `x` into a ring kept oldest first (full: the oldest drops).
fn push<T: Copy>(ring: &mut [T; RING], len: &mut usize, x: T) {
    if *len == RING {
        ring.copy_within(1.., 0);
        ring[RING - 1] = x;
    } else {
        ring[*len] = x;
        *len += 1;
    }
}

impl DfMpc {
    /// Flies with a learned residual (`None`: the parametric model alone).
    /// The shell validates the model and checks its `[vehicle]` table
    /// ([`LearnedResidual::validate`], [`LearnedResidual::check_vehicle`])
    /// first. The residual is in the model frame (local NED in flight).
    pub fn set_learned(&mut self, model: Option<LearnedResidual>) {
        // Multi-rate: judged above the noise of the poses it assumes.
        let sigma = self.settings.multi_rate.map(|m| m.sample_sigma);
        let dt = self.model.dt();
        self.learned = model.map(|m| match sigma {
            Some(s) => LearnedTerm::with_pose_noise(m, s, SCORE_SPACING_S, dt),
            None => LearnedTerm::new(m),
        });
        self.learned_score = Score::default();
    }

    /// The learned term with its fade state, when one is flown.
    pub fn learned(&self) -> Option<&LearnedTerm> {
        self.learned.as_ref()
    }

    /// F⁻¹ with the learned residual in each step (see [`next_output`]).
    pub(super) fn f_inv(
        &self,
        y: &[Vector3<f64>; 3],
        u: &Vector3<f64>,
        d: &DisturbanceEstimate,
    ) -> Result<Vector3<f64>, FlatError> {
        next_output(&self.model, self.learned.as_ref(), y, u, d)
    }

    /// F with the learned residual in each of its two steps: the input
    /// that flies `y_k..y_{k+3}`.
    pub(super) fn f(
        &self,
        y: &[Vector3<f64>; 4],
        d: &DisturbanceEstimate,
    ) -> Result<Vector3<f64>, FlatError> {
        match &self.learned {
            Some(l) => {
                let steps = l.step_offsets(&self.model, y, &d.acceleration);
                self.model.input_from_outputs_stepped(y, d, &steps)
            }
            None => self.model.input_from_outputs_disturbed(y, d),
        }
    }

    /// What the model adds to the command sent last in the plan's terms
    /// of the smoothness term and the tilt-rate bound \[m/s²\]
    /// (`velocity`: the plan's start velocity). F made that command from
    /// its plan's two steps with the drag `−D·v_j` and, when flown, the
    /// residual `ρ_j` in them, and those terms linearise a step's command
    /// as `c_j = a_j + κ·(a_{j+1} − a_j)`: the sent command's acceleration
    /// plus `o_0 + κ·(o_1 − o_0)`, `o_j = ρ_j − D·v_j`
    /// ([`DfMpc::keep_sent_offset`]). Without the κ term the anchor missed
    /// τ·ȯ, and the smoothness weight pulled every plan by it (the figure
    /// eight at 5 m/s with the aerodynamics' residual: 0.08 m against
    /// 0.009 m with it; with a matched linear drag of 0.4 /s and no
    /// residual, 0.099 m against 0.013 m). Before a plan: `−D·v` at the
    /// plan's start.
    pub(super) fn sent_offset(&self, velocity: &Vector3<f64>) -> Vector3<f64> {
        self.learned_score
            .sent_offset
            .unwrap_or_else(|| -self.model.drag().component_mul(velocity))
    }

    /// The tilt bound's shift at the plan's start `planned`
    /// (`y_{k+d}..y_{k+d+2}` \[m\]), per horizontal axis, from the
    /// window's two model steps `o_j = ρ_j − D·v_j` (one evaluation of the
    /// residual for both):
    ///
    /// * the offset ([`crate::optimise::AxisBounds::offset`]), with a
    ///   learned residual flown: `o_1`, the residual at the newest output
    ///   and the drag at the window's speed `v_1 = (y_2 − y_1)/δt`. The
    ///   bound holds the thrust's acceleration; a residual that takes the
    ///   drag back moves it with it (without: the box bound was shifted by
    ///   `D·v_1` alone, and a learned residual over an identified drag
    ///   flew the racing line at 9 m/s 1.58× matched instead of 1.01×).
    ///   `None` without a residual (the drag's shift alone) or when not
    ///   finite;
    /// * its change per stage
    ///   ([`crate::optimise::AxisBounds::offset_slope`]): `o_1 − o_0` (the
    ///   drag's `−D·a·δt` without a residual). The bound moved by the
    ///   start's offset at every stage let a braking plan count on the drag
    ///   of its start speed to its stop: on the lab's L at 9 m/s the exact
    ///   aerodynamics as the residual flew 1.06–1.13× the matched plant,
    ///   with the slope 0.95–0.97×. 0 without drag or residual, or when not
    ///   finite.
    pub(super) fn bound_shifts(
        &self,
        planned: &[Vector3<f64>; 3],
        d: &DisturbanceEstimate,
    ) -> (Option<[f64; 2]>, [f64; 2]) {
        let [o0, o1] = self.step_model_offsets(planned, d);
        let offset = [o1.x, o1.y];
        let offset =
            (self.learned.is_some() && offset.iter().all(|x| x.is_finite())).then_some(offset);
        let slope = [o1.x - o0.x, o1.y - o0.y];
        let slope = if slope.iter().all(|x| x.is_finite()) {
            slope
        } else {
            [0.0; 2]
        };
        (offset, slope)
    }

    /// What the model adds to the thrust's acceleration in each of the two
    /// steps over the outputs `y` (three or four, \[m\]; as
    /// [`LearnedTerm::step_offsets`]): `o_j = ρ_j − D·v_j`, the residual
    /// of step j (0 without one) and the drag at its backward speed
    /// `(y_{j+1} − y_j)/δt` — with rotor drag, the model's drag at the
    /// step's thrust axis ([`ControlModel::drag_acceleration`]), from the
    /// step's second difference (step 1 of three outputs: step 0's). At the
    /// level attitude's drag alone the anchor missed the rotor drag's part
    /// along the thrust axis, `d_r·n·(n·v)`.
    fn step_model_offsets(&self, y: &[Vector3<f64>], d: &DisturbanceEstimate) -> [Vector3<f64>; 2] {
        let dt = self.model.dt();
        let drag = self.model.drag();
        let rho = self.learned.as_ref().map_or([Vector3::zeros(); 2], |l| {
            l.step_offsets(&self.model, y, &d.acceleration)
        });
        let mut thrust = Vector3::zeros();
        std::array::from_fn(|j| {
            let v = (y[j + 1] - y[j]) / dt;
            if let Some(y2) = y.get(j + 2) {
                thrust = (y2 - y[j + 1] * 2.0 + y[j]) / (dt * dt) + drag.component_mul(&v)
                    - rho[j]
                    - d.acceleration;
            }
            rho[j] + self.model.drag_acceleration(&v, &thrust)
        })
    }

    /// What the model adds to the thrust's acceleration along the last
    /// plan one tick on (x, y; [`DfMpc::step_model_offsets`] of its step
    /// at each stage f of this tick's plan, outputs f + 1..f + 3: the
    /// drag at the plan's speed and the residual there), less its value at
    /// the first stage, into `out` (one per stage; the last stages repeat
    /// the last the plan reaches). The caller checks that the last plan
    /// is the last tick's (`update`: only when it began from a fresh plan
    /// with no step flown; after a failed update it is older, its stages
    /// one off). False when an offset is not finite.
    pub(super) fn offsets_along_last_plan(
        &self,
        d: &DisturbanceEstimate,
        out: &mut [[f64; 2]],
    ) -> bool {
        let len = self.axes.first().map_or(0, |a| a.good_plan.len());
        let output = |j: usize| {
            let mut y = self.good_y0;
            for (axis, p) in self.axes.iter().enumerate() {
                y[axis] = p.good_plan[j.min(len - 1)];
            }
            y
        };
        // This plan's stage f (outputs f + 1..f + 3) is the last plan's
        // step over its outputs f + 2..f + 4: two stages per evaluation of
        // four outputs (its steps 0 and 1), the last stages clamped to the
        // last step the plan reaches.
        let last_step = len.saturating_sub(3);
        let mut f = 0;
        while f < out.len() {
            let j = f + 2;
            let (steps, taken) = if j < last_step && f + 1 < out.len() {
                let y = [output(j), output(j + 1), output(j + 2), output(j + 3)];
                (self.step_model_offsets(&y, d), 2)
            } else {
                let j = j.min(last_step);
                let y = [output(j), output(j + 1), output(j + 2)];
                (self.step_model_offsets(&y, d), 1)
            };
            for (o, step) in out[f..f + taken].iter_mut().zip(steps) {
                *o = [step.x, step.y];
            }
            f += taken;
        }
        let first = out.first().copied().unwrap_or_default();
        for o in out.iter_mut() {
            *o = [o[0] - first[0], o[1] - first[1]];
        }
        out.iter().flatten().all(|v| v.is_finite())
    }

    /// Keeps what the model adds to the command F just made from `plan`
    /// (see [`DfMpc::sent_offset`]): the drag's and, when flown, the
    /// residual's.
    pub(super) fn keep_sent_offset(&mut self, plan: &[Vector3<f64>; 4], d: &DisturbanceEstimate) {
        if !self.anchors_sent() {
            return;
        }
        let dt = self.model.dt();
        let [o0, o1] = self.step_model_offsets(plan, d);
        let kappa = crate::window::input_lags(&self.model).map(|lag| lag / dt);
        let o = Vector3::from_fn(|i, _| o0[i] + kappa[i] * (o1[i] - o0[i]));
        self.learned_score.sent_offset = o.iter().all(|x| x.is_finite()).then_some(o);
    }

    /// True when a term reads the command sent at the previous tick in
    /// the plan's terms: the smoothness term or the tilt-rate bound's first
    /// row ([`DfMpc::sent_offset`]).
    pub(super) fn anchors_sent(&self) -> bool {
        self.smooth || self.settings.constraints.max_tilt_rate.is_some()
    }

    /// Forgets what the sent command's offset was (its input replaced).
    pub(super) fn forget_sent_offset(&mut self) {
        self.learned_score.sent_offset = None;
    }

    /// Scores the residual on a new measurement (classic mode): the
    /// measured acceleration `(y_k − 2y_{k−1} + y_{k−2})/δt²` less the
    /// parametric model's (the commands' through the lag, less the drag) is
    /// what the residual should have predicted.
    pub(super) fn learned_score_tick(&mut self, measurement: &Measurement) {
        let Some(term) = &mut self.learned else {
            return;
        };
        let fresh = self.multi.is_none()
            && measurement.t > self.window.pose_time()
            && self.record == super::RecordState::Pending;
        let s = &mut self.learned_score;
        if fresh {
            s.recent = [s.recent[1], s.recent[2], measurement.position];
            s.recent_t = [s.recent_t[1], s.recent_t[2], measurement.t];
            s.filled = (s.filled + 1).min(3);
            // The second difference centred on y_{k−1} is the Euler
            // step's acceleration at k − 2: the one acting then (made
            // by the command of tick k − 2 − d). Poses off the step (a
            // starved sender's capture times) take the second difference
            // over their own times, its acceleration a step before the
            // middle one's.
            let dt = self.model.dt();
            let [t2, t1, t0] = s.recent_t;
            let uniform =
                ((t0 - t1) - dt).abs() <= 1e-9 * dt && ((t1 - t2) - dt).abs() <= 1e-9 * dt;
            let at = if uniform {
                measurement.t - 2.0 * dt
            } else {
                t1 - dt
            };
            let parametric = s.ticks[..s.ticked]
                .iter()
                .rev()
                .find(|(acts, _)| (acts - at).abs() <= 0.5 * dt)
                .map(|(_, a)| *a);
            if s.filled == 3
                && t0 > t1
                && t1 > t2
                && let Some(parametric) = parametric
            {
                let [y2, y1, y0] = s.recent;
                let (measured, v) = if uniform {
                    ((y0 - y1 * 2.0 + y2) / (dt * dt), (y0 - y2) / (2.0 * dt))
                } else {
                    (
                        ((y0 - y1) / (t0 - t1) - (y1 - y2) / (t1 - t2)) * (2.0 / (t0 - t2)),
                        (y0 - y2) / (t0 - t2),
                    )
                };
                let mut unexplained =
                    measured - (parametric + self.model.drag_acceleration(&v, &parametric));
                if let ControlModel::Planar(_) = self.model {
                    unexplained.z = 0.0;
                }
                term.observe(&self.model, &unexplained, &v, &parametric);
            }
        } else {
            s.filled = 0;
        }
    }

    /// After a good tick: the support at the plan's start; the parametric
    /// acceleration moved on by the command through the model's lag τ.
    pub(super) fn learned_after_tick(
        &mut self,
        t: f64,
        plan: &[Vector3<f64>; 4],
        sent: &Vector3<f64>,
        d: &DisturbanceEstimate,
    ) {
        let Some(term) = &mut self.learned else {
            return;
        };
        term.after_tick(&self.model, plan, &d.acceleration);
        let dt = self.model.dt();
        let tau = match &self.model {
            ControlModel::Planar(m) => m.params().tau,
            ControlModel::Spatial(m) => m.params().tau,
        };
        let step = (dt / tau).min(1.0);
        let commanded = commanded_acceleration(&self.model, sent).ok();
        let s = &mut self.learned_score;
        match (s.now, commanded) {
            (Some(now), Some(a)) => s.now = Some(now + (a - now) * step),
            (None, Some(a)) => s.now = Some(a),
            (_, None) => s.now = None,
        }
        // The command acts on the vehicle the input delay's ticks later:
        // the lag's response to it is the acceleration then.
        let acts = t + self.settings.delay_ticks as f64 * dt;
        if let Some(now) = s.now
            && acts.is_finite()
            && (s.ticked == 0 || acts > s.ticks[s.ticked - 1].0)
        {
            push(&mut s.ticks, &mut s.ticked, (acts, now));
        }
    }

    /// Scores the residual on a pose sample (multi-rate mode, where poses
    /// come at their own rate): the newest sample and the two nearest
    /// [`SCORE_SPACING_S`] and twice that before it, their second
    /// difference over their times `2·((y₂ − y₁)/(t₂ − t₁) − (y₁ − y₀)/(t₁ −
    /// t₀))/(t₂ − t₀)`, less the parametric model's acceleration at the
    /// middle sample's time (the commands' through the lag, interpolated
    /// between ticks, less the drag at the samples' velocity), is what the
    /// residual should have predicted.
    pub(super) fn learned_observe(&mut self, sample: &Measurement) {
        let Some(term) = &mut self.learned else {
            return;
        };
        let s = &mut self.learned_score;
        if !(sample.t.is_finite() && sample.position.iter().all(|v| v.is_finite())) {
            return;
        }
        if s.sampled > 0 && sample.t <= s.samples[s.sampled - 1].0 {
            return;
        }
        push(&mut s.samples, &mut s.sampled, (sample.t, sample.position));
        let h = SCORE_SPACING_S;
        let (t2, y2) = (sample.t, sample.position);
        let nearest = |want: f64| {
            s.samples[..s.sampled]
                .iter()
                .copied()
                .min_by(|a, b| (a.0 - want).abs().total_cmp(&(b.0 - want).abs()))
                .filter(|(t, _)| (t - want).abs() <= h / 3.0)
        };
        let (Some((t1, y1)), Some((t0, y0))) = (nearest(t2 - h), nearest(t2 - 2.0 * h)) else {
            return;
        };
        // The parametric acceleration at t1, between the ticks around it.
        let ticks = &s.ticks[..s.ticked];
        let i = ticks.partition_point(|(t, _)| *t <= t1);
        if i == 0 || i == ticks.len() {
            return;
        }
        let ((ta, aa), (tb, ab)) = (ticks[i - 1], ticks[i]);
        let now = aa + (ab - aa) * ((t1 - ta) / (tb - ta));
        let measured = ((y2 - y1) / (t2 - t1) - (y1 - y0) / (t1 - t0)) * (2.0 / (t2 - t0));
        let v = (y2 - y0) / (t2 - t0);
        let mut unexplained = measured - (now + self.model.drag_acceleration(&v, &now));
        if let ControlModel::Planar(_) = self.model {
            unexplained.z = 0.0;
        }
        term.observe(&self.model, &unexplained, &v, &now);
    }

    /// Forgets the scoring history and the sent command's offset (a reset).
    pub(super) fn learned_reset(&mut self) {
        self.learned_score = Score::default();
        if let Some(l) = &mut self.learned {
            l.reset();
        }
    }
}
