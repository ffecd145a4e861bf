//! DF-MPC's hook points for the learned residual
//! ([`crate::learned::LearnedTerm`]): the offset added to the maps'
//! acceleration offset each tick, the score of the residual against the
//! acceleration the parametric model leaves unexplained, and the plan it is
//! evaluated along.

use nalgebra::Vector3;

use super::{DfMpc, commanded_acceleration};
use crate::Measurement;
use crate::disturbance::DisturbanceEstimate;
use crate::learned::{LearnedResidual, LearnedTerm, thrust_axis};
use crate::model::ControlModel;

/// What scoring the residual needs between ticks (classic mode).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Score {
    /// The newest measured outputs, oldest first \[m\].
    recent: [Vector3<f64>; 3],
    /// How many of `recent` are filled (up to 3).
    filled: usize,
    /// The parametric model's acceleration (no drag) at the previous tick
    /// and at this one: the commands' through the attitude lag τ [m/s²].
    previous: Vector3<f64>,
    now: Option<Vector3<f64>>,
    /// The model's pitch and roll \[rad\]: the commands through the lag.
    attitude: Option<(f64, f64)>,
    /// The newest pose samples (multi-rate mode), oldest first: time \[s\]
    /// and position \[m\].
    samples: [(f64, Vector3<f64>); 3],
    /// How many of `samples` are filled (up to 3).
    sampled: usize,
}

/// Longest span \[s\] of three pose samples whose second difference
/// scores the residual (multi-rate mode): a dropout does not.
const SAMPLE_SPAN_S: f64 = 0.3;

impl DfMpc {
    /// Flies with a learned residual (`None`: the parametric model alone).
    /// The shell validates the model and checks its `[vehicle]` table
    /// ([`LearnedResidual::validate`], [`LearnedResidual::check_vehicle`])
    /// first. The residual is in the model frame (local NED in flight).
    pub fn set_learned(&mut self, model: Option<LearnedResidual>) {
        self.learned = model.map(LearnedTerm::new);
        self.learned_score = Score::default();
    }

    /// The learned term with its fade state, when one is flown.
    pub fn learned(&self) -> Option<&LearnedTerm> {
        self.learned.as_ref()
    }

    /// The tick's estimate with the learned offset added, after scoring the
    /// residual on a new measurement (classic mode): the measured
    /// acceleration `(y_k − 2y_{k−1} + y_{k−2})/δt²` less the parametric
    /// model's (the commands' through the lag, less the drag) is what the
    /// residual should have predicted.
    pub(super) fn learned_disturbance(
        &mut self,
        d: DisturbanceEstimate,
        measurement: &Measurement,
    ) -> DisturbanceEstimate {
        let Some(term) = &mut self.learned else {
            return d;
        };
        let fresh = self.multi.is_none()
            && measurement.t > self.last_t
            && self.record == super::RecordState::Pending;
        let s = &mut self.learned_score;
        if fresh {
            s.recent = [s.recent[1], s.recent[2], measurement.position];
            s.filled = (s.filled + 1).min(3);
            if s.filled == 3 && s.now.is_some() {
                let dt = self.model.dt();
                let [y2, y1, y0] = s.recent;
                let measured = (y0 - y1 * 2.0 + y2) / (dt * dt);
                let v = (y0 - y2) / (2.0 * dt);
                let mut unexplained = measured - (s.previous - self.model.drag().component_mul(&v));
                if let ControlModel::Planar(_) = self.model {
                    unexplained.z = 0.0;
                }
                term.observe(&unexplained);
            }
        } else {
            s.filled = 0;
        }
        DisturbanceEstimate {
            acceleration: d.acceleration + term.offset(),
            ..d
        }
    }

    /// After a good tick: the residual for the next tick, along this plan
    /// and the model's attitude (the commands through its lag τ and gain
    /// k̃); the parametric acceleration moved on by the command through the
    /// same lag.
    pub(super) fn learned_after_tick(&mut self, plan: &[Vector3<f64>; 4], sent: &Vector3<f64>) {
        if self.learned.is_none() {
            return;
        }
        let dt = self.model.dt();
        let (tau, gain) = match &self.model {
            ControlModel::Planar(m) => (m.params().tau, m.params().k),
            ControlModel::Spatial(m) => (m.params().tau, m.params().k),
        };
        let step = (dt / tau).min(1.0);
        let commanded = commanded_acceleration(&self.model, sent).ok();
        let c = self.model.command(sent);
        let s = &mut self.learned_score;
        match (s.now, commanded) {
            (Some(now), Some(a)) => {
                s.previous = now;
                s.now = Some(now + (a - now) * step);
            }
            (None, Some(a)) => s.now = Some(a),
            (_, None) => s.now = None,
        }
        let target = (gain * c.pitch, gain * c.roll);
        let (pitch, roll) = match s.attitude {
            Some((p, r)) => (p + (target.0 - p) * step, r + (target.1 - r) * step),
            None => target,
        };
        s.attitude = Some((pitch, roll));
        let n = thrust_axis(roll, pitch, c.yaw);
        let thrust = match self.model {
            ControlModel::Planar(_) => c.thrust / n.z.max(0.1),
            ControlModel::Spatial(_) => c.thrust,
        };
        if let Some(term) = &mut self.learned {
            term.after_tick(plan, &n, thrust, dt);
        }
    }

    /// Scores the residual on a pose sample (multi-rate mode, where poses
    /// come at their own rate): the second difference of the last three
    /// samples over their times, `2·((y₂ − y₁)/(t₂ − t₁) − (y₁ − y₀)/(t₁ −
    /// t₀))/(t₂ − t₀)`, less the parametric model's acceleration of the tick
    /// (the commands' through the lag, less the drag at the samples'
    /// velocity), is what the residual should have predicted.
    pub(super) fn learned_observe(&mut self, sample: &Measurement) {
        let Some(term) = &mut self.learned else {
            return;
        };
        let s = &mut self.learned_score;
        if !(sample.t.is_finite() && sample.position.iter().all(|v| v.is_finite())) {
            return;
        }
        if s.sampled > 0 && sample.t <= s.samples[2].0 {
            return;
        }
        s.samples = [s.samples[1], s.samples[2], (sample.t, sample.position)];
        s.sampled = (s.sampled + 1).min(3);
        let [(t0, y0), (t1, y1), (t2, y2)] = s.samples;
        let (Some(now), true) = (s.now, s.sampled == 3 && t2 - t0 <= SAMPLE_SPAN_S) else {
            return;
        };
        let measured = ((y2 - y1) / (t2 - t1) - (y1 - y0) / (t1 - t0)) * (2.0 / (t2 - t0));
        let v = (y2 - y0) / (t2 - t0);
        let mut unexplained = measured - (now - self.model.drag().component_mul(&v));
        if let ControlModel::Planar(_) = self.model {
            unexplained.z = 0.0;
        }
        term.observe(&unexplained);
    }

    /// Forgets the scoring history (a reset).
    pub(super) fn learned_reset(&mut self) {
        self.learned_score = Score::default();
        if let Some(l) = &mut self.learned {
            l.reset();
        }
    }
}
