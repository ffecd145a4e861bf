//! The learned residual as DF-MPC flies it: an acceleration offset of the
//! flat maps, evaluated along the previous plan, faded outside its data's
//! support and when its running prediction error grows.
//!
//! Each tick the controller adds [`LearnedTerm::offset`] to the maps'
//! acceleration offset (the input-to-output map that predicts from the
//! window, and the output-to-input map that turns the plan into the
//! command). The offset is the residual at the previous plan's velocity
//! `(y*_3 − y*_2)/δt` and the model's thrust axis and thrust (the commands
//! through its lag) ([`LearnedTerm::after_tick`]): frozen over the tick, so the
//! optimisation stays the banded QP of the parametric model (the offset
//! enters only its fixed outputs and the map), and every solver serves it.
//!
//! The weight is the product of the support's ([`LearnedResidual::support_weight`])
//! and the running error's ([`RunningError`]: the mean acceleration the
//! parametric model leaves unexplained, against what the residual leaves); [`LearnedTerm::status`] says
//! which one holds it back, for the shell to say in words.

use nalgebra::Vector3;

use super::LearnedResidual;

/// Time constant of the running errors \[ticks\] (1 s at 50 Hz).
pub const ERROR_TICKS: f64 = 50.0;
/// Ratio of the learned to the parametric running error up to which the
/// residual acts in full.
pub const ERROR_RATIO_FULL: f64 = 1.1;
/// Ratio at and beyond which it is faded out entirely.
pub const ERROR_RATIO_OFF: f64 = 1.5;

/// Least acceleration [m/s²] the running means are compared against (below
/// it both models explain the flight).
pub const ERROR_FLOOR: f64 = 0.05;

/// Running means (exponential, [`ERROR_TICKS`]) of the acceleration the
/// parametric model leaves unexplained — measured minus the model's — and
/// of what the residual leaves of it [m/s², model frame]. The mean of
/// second differences telescopes (their noise does not add up), so a
/// residual that explains the flight drives the second towards 0, and one
/// learned on another airframe leaves more than the parametric model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunningError {
    /// Mean of measured − parametric − residual [m/s²].
    pub learned: Vector3<f64>,
    /// Mean of measured − parametric [m/s²].
    pub parametric: Vector3<f64>,
    /// Samples observed.
    pub count: u64,
}

impl RunningError {
    /// Adds one tick: the acceleration the parametric model did not explain
    /// and the residual's prediction of it [m/s²] (non-finite ignored).
    pub fn observe(&mut self, unexplained: &Vector3<f64>, residual: &Vector3<f64>) {
        if !(unexplained
            .iter()
            .chain(residual.iter())
            .all(|v| v.is_finite()))
        {
            return;
        }
        let a = 1.0 / ERROR_TICKS.min(self.count as f64 + 1.0);
        self.learned += (unexplained - residual - self.learned) * a;
        self.parametric += (unexplained - self.parametric) * a;
        self.count += 1;
    }

    /// Ratio of the residual's running error to the parametric model's
    /// (1 before any sample; both floored at [`ERROR_FLOOR`]).
    pub fn ratio(&self) -> f64 {
        if self.count == 0 {
            1.0
        } else {
            self.learned.norm().max(ERROR_FLOOR) / self.parametric.norm().max(ERROR_FLOOR)
        }
    }

    /// Weight in [0, 1]: 1 up to [`ERROR_RATIO_FULL`], 0 from
    /// [`ERROR_RATIO_OFF`], linear between.
    pub fn weight(&self) -> f64 {
        let r = self.ratio();
        ((ERROR_RATIO_OFF - r) / (ERROR_RATIO_OFF - ERROR_RATIO_FULL)).clamp(0.0, 1.0)
    }
}

/// What holds the learned term back this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LearnedStatus {
    /// Acting in full (weight 1).
    Active,
    /// Faded (in part or fully) outside its data's speed, tilt or thrust.
    OutOfSupport,
    /// Faded because its running prediction error grew past the
    /// parametric model's.
    ErrorGrew,
}

/// The residual with its fade state, owned by the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedTerm {
    model: LearnedResidual,
    errors: RunningError,
    /// Residual (unweighted) and support weight along the previous plan.
    along: Option<(Vector3<f64>, f64)>,
}

impl LearnedTerm {
    /// A term for a validated `model` (see [`LearnedResidual::validate`]).
    pub fn new(model: LearnedResidual) -> Self {
        Self {
            model,
            errors: RunningError::default(),
            along: None,
        }
    }

    /// The residual model.
    pub fn model(&self) -> &LearnedResidual {
        &self.model
    }

    /// The running errors.
    pub fn errors(&self) -> &RunningError {
        &self.errors
    }

    /// The weight in [0, 1] this tick: support × running error (0 before
    /// the first plan).
    pub fn weight(&self) -> f64 {
        self.along.map_or(0.0, |(_, s)| s) * self.errors.weight()
    }

    /// What holds the term back: the running error before the support.
    pub fn status(&self) -> LearnedStatus {
        if self.errors.weight() < 1.0 {
            LearnedStatus::ErrorGrew
        } else if self.along.is_some_and(|(_, s)| s < 1.0) {
            LearnedStatus::OutOfSupport
        } else {
            LearnedStatus::Active
        }
    }

    /// The acceleration offset to add this tick [m/s², NED]: the residual
    /// along the previous plan, weighted. Always finite.
    pub fn offset(&self) -> Vector3<f64> {
        let Some((rho, _)) = self.along else {
            return Vector3::zeros();
        };
        let a = rho * self.weight();
        if a.iter().all(|v| v.is_finite()) {
            a
        } else {
            Vector3::zeros()
        }
    }

    /// After a tick: the plan `y*_k … y*_{k+3}` (NED \[m\]), the thrust axis
    /// (unit, NED) and specific thrust [m/s²] the model expects at the next
    /// tick, and the step δt \[s\]. The next tick's offset is the residual
    /// there, at the plan's velocity `(y*_{k+3} − y*_{k+2})/δt`: the velocity
    /// at the tick after the next, in the middle of the outputs the next
    /// tick's maps span.
    pub fn after_tick(
        &mut self,
        plan: &[Vector3<f64>; 4],
        axis: &Vector3<f64>,
        thrust: f64,
        dt: f64,
    ) {
        let v = (plan[3] - plan[2]) / dt;
        let tilt = axis.z.clamp(-1.0, 1.0).acos();
        let support = self.model.support_weight(v.norm(), tilt, thrust);
        let rho = self.model.residual(&v, axis);
        self.along =
            (support.is_finite() && rho.iter().all(|x| x.is_finite())).then_some((rho, support));
    }

    /// One tick's acceleration the parametric model did not explain
    /// [m/s², model frame], scored against the residual's unweighted
    /// prediction along the previous plan (so a faded term is still judged).
    pub fn observe(&mut self, unexplained: &Vector3<f64>) {
        if let Some((rho, _)) = self.along {
            self.errors.observe(unexplained, &rho);
        }
    }

    /// Forgets the plan and the running errors (engagement, reset).
    pub fn reset(&mut self) {
        self.errors = RunningError::default();
        self.along = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::tests::aero_residual;

    fn plan_at(speed: f64) -> [Vector3<f64>; 4] {
        std::array::from_fn(|j| Vector3::new(speed * 0.02 * j as f64, 0.0, -10.0))
    }

    /// Learned at up to 3 m/s: at 2 m/s it acts in full, at 9 m/s the
    /// offset is 0 and the status says it is out of its support.
    #[test]
    fn it_fades_out_of_its_support() {
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        assert_eq!(t.offset(), Vector3::zeros());
        t.after_tick(&plan_at(2.0), &Vector3::z(), 9.81, 0.02);
        assert_eq!(t.status(), LearnedStatus::Active);
        assert!(
            (t.offset().x - (-0.03 * 4.0 - 0.2 * 2.0)).abs() < 1e-9,
            "{}",
            t.offset()
        );
        t.after_tick(&plan_at(9.0), &Vector3::z(), 9.81, 0.02);
        assert_eq!(t.offset(), Vector3::zeros());
        assert_eq!(t.status(), LearnedStatus::OutOfSupport);
    }

    /// When its running prediction error grows past the parametric
    /// model's, it fades out, said in its status; when it recovers, it
    /// comes back.
    #[test]
    fn it_fades_when_its_error_grows() {
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        t.after_tick(&plan_at(2.0), &Vector3::z(), 9.81, 0.02);
        let rho = t
            .model()
            .residual(&Vector3::new(2.0, 0.0, 0.0), &Vector3::z());
        // The flight shows what the residual predicts: it acts.
        for _ in 0..100 {
            t.observe(&rho);
        }
        assert_eq!(t.weight(), 1.0);
        // Another airframe: a third of what it predicts.
        for _ in 0..300 {
            t.observe(&(rho / 3.0));
        }
        assert_eq!(t.weight(), 0.0);
        assert_eq!(t.status(), LearnedStatus::ErrorGrew);
        assert_eq!(t.offset(), Vector3::zeros());
        for _ in 0..300 {
            t.observe(&rho);
        }
        assert_eq!(t.weight(), 1.0);
    }

    #[test]
    fn non_finite_errors_and_plans_change_nothing() {
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        t.after_tick(&plan_at(2.0), &Vector3::z(), 9.81, 0.02);
        t.observe(&Vector3::new(f64::NAN, 0.0, 0.0));
        assert_eq!(t.errors().count, 0);
        let mut plan = plan_at(2.0);
        plan[3].x = f64::NAN;
        t.after_tick(&plan, &Vector3::z(), 9.81, 0.02);
        assert_eq!(t.offset(), Vector3::zeros());
    }
}
