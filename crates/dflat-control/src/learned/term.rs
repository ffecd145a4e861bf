//! The learned residual as DF-MPC flies it: an acceleration offset of the
//! flat maps per step, at the velocity and thrust of that step, faded
//! outside its data's support and when its running prediction error grows.
//!
//! The maps F and F⁻¹ span two model steps (the outputs `y_k..y_{k+3}`);
//! the residual enters each step at that step's own velocity `(y_{j+1} −
//! y_j)/δt` and thrust axis ([`LearnedTerm::step_offsets`]). A single
//! offset for both steps misses the residual's change between them, which
//! F amplifies by τ/δt (the attitude command is `θ_k + τ·(θ_{k+1} −
//! θ_k)/δt`): on a 20 m circle at 9 m/s that was a tenth of the residual.
//! The outputs a map spans are known when it runs (the window's, F⁻¹'s own
//! chain, the plan's), so the residual is evaluated there, not linearised:
//! the optimisation stays the banded QP of the parametric model (the
//! residual enters only its fixed outputs and the sent command's
//! acceleration), and every solver serves it.
//!
//! The weight is the product of the support's ([`LearnedResidual::support_weight`],
//! per step) and the running error's ([`RunningError`]: the mean
//! acceleration the parametric model leaves unexplained, against what the
//! residual leaves); [`LearnedTerm::status`] says which one holds it back,
//! for the shell to say in words.

use nalgebra::Vector3;

use super::LearnedResidual;
use crate::model::ControlModel;

/// Time constant of the running errors \[samples\] (2 s at 50 Hz).
pub const ERROR_TICKS: f64 = 100.0;
/// Ratio of the learned to the parametric running error up to which the
/// residual acts in full.
pub const ERROR_RATIO_FULL: f64 = 1.1;
/// Ratio at and beyond which it is faded out entirely.
pub const ERROR_RATIO_OFF: f64 = 1.5;

/// Least acceleration [m/s²] the running means are compared against (below
/// it both models explain the flight); raised to the running means' own
/// noise under noisy poses ([`RunningError::with_pose_noise`]).
pub const ERROR_FLOOR: f64 = 0.05;

/// Running means (exponential, [`ERROR_TICKS`]) of the acceleration the
/// parametric model leaves unexplained — measured minus the model's — and
/// of what the residual leaves of it [m/s², model frame]. The mean of
/// second differences telescopes (their noise does not add up), so a
/// residual that explains the flight drives the second towards 0, and one
/// learned on another airframe leaves more than the parametric model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunningError {
    /// Mean of measured − parametric − residual [m/s²].
    pub learned: Vector3<f64>,
    /// Mean of measured − parametric [m/s²].
    pub parametric: Vector3<f64>,
    /// Samples observed.
    pub count: u64,
    /// The floor both means are compared above [m/s²].
    pub floor: f64,
}

impl Default for RunningError {
    fn default() -> Self {
        Self {
            learned: Vector3::zeros(),
            parametric: Vector3::zeros(),
            count: 0,
            floor: ERROR_FLOOR,
        }
    }
}

impl RunningError {
    /// Running errors whose floor is their own noise when they are scored
    /// on the second difference of poses `h` \[s\] apart with noise `sigma`
    /// \[m\] per axis, one score per tick of `dt` \[s\] (at most): one score
    /// is `√6·σ/h²`, neighbouring scores share their samples for about
    /// `2h/δt` ticks, so the mean of [`ERROR_TICKS`] has
    /// `√6·σ/h²·√(2h/(δt·ERROR_TICKS))`; the floor is twice that (1.7 m/s²
    /// at 2 cm, 0.15 s and 50 Hz), at least [`ERROR_FLOOR`]. Below it the
    /// flight cannot tell the models apart, and the residual is not faded
    /// for noise.
    pub fn with_pose_noise(sigma: f64, h: f64, dt: f64) -> Self {
        let one = 6f64.sqrt() * sigma / (h * h);
        let noise = 2.0 * one * (2.0 * h / (dt * ERROR_TICKS)).min(1.0).sqrt();
        Self {
            floor: if noise.is_finite() {
                noise.max(ERROR_FLOOR)
            } else {
                ERROR_FLOOR
            },
            ..Self::default()
        }
    }

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
            self.learned.norm().max(self.floor) / self.parametric.norm().max(self.floor)
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
    /// The support's weight at the start of the last plan (None before one).
    support: Option<f64>,
}

/// Fixed-point passes for the thrust axis of a step (the residual tilts
/// the thrust that flies the step; three passes converge to ~1e-4 of it).
const AXIS_PASSES: usize = 3;

impl LearnedTerm {
    /// A term for a validated `model` (see [`LearnedResidual::validate`]).
    pub fn new(model: LearnedResidual) -> Self {
        Self {
            model,
            errors: RunningError::default(),
            support: None,
        }
    }

    /// The same, its running errors judged above the noise of their
    /// scores ([`RunningError::with_pose_noise`]).
    pub fn with_pose_noise(model: LearnedResidual, sigma: f64, h: f64, dt: f64) -> Self {
        Self {
            errors: RunningError::with_pose_noise(sigma, h, dt),
            ..Self::new(model)
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

    /// The weight in [0, 1] at the start of the last plan: support ×
    /// running error (0 before the first plan).
    pub fn weight(&self) -> f64 {
        self.support.unwrap_or(0.0) * self.errors.weight()
    }

    /// What holds the term back: the running error before the support.
    pub fn status(&self) -> LearnedStatus {
        if self.errors.weight() < 1.0 {
            LearnedStatus::ErrorGrew
        } else if self.support.is_some_and(|s| s < 1.0) {
            LearnedStatus::OutOfSupport
        } else {
            LearnedStatus::Active
        }
    }

    /// The residual [m/s², model frame] at velocity `v` [m/s] when the
    /// thrust's acceleration plus the residual is `a` (the step's second
    /// difference plus the model's drag minus the disturbance offset),
    /// weighted by the support there and by the running error, and its
    /// support weight. The thrust axis solves `t = thrust_vector(a − ρ)`
    /// by [`AXIS_PASSES`] fixed-point passes. Planar: z is 0 (the autopilot
    /// holds the altitude: the thrust is `g/n_z`). Always finite.
    fn at(&self, model: &ControlModel, v: &Vector3<f64>, a: &Vector3<f64>) -> (Vector3<f64>, f64) {
        let planar = matches!(model, ControlModel::Planar(_));
        let (frame, g) = (model.frame(), model.gravity());
        let mut rho = Vector3::zeros();
        let mut support = 0.0;
        for _ in 0..AXIS_PASSES {
            let mut thrust_acc = a - rho;
            if planar {
                thrust_acc.z = 0.0;
            }
            let t = Vector3::from(frame.thrust_vector(thrust_acc.into(), g));
            let thrust = t.norm();
            if !(thrust.is_finite() && thrust > 1e-9) {
                return (Vector3::zeros(), 0.0);
            }
            let n = t / thrust;
            let tilt = n.z.clamp(-1.0, 1.0).acos();
            support = self.model.support_weight(v.norm(), tilt, thrust);
            rho = self.model.residual(v, &n);
            if planar {
                rho.z = 0.0;
            }
        }
        let out = rho * (support * self.errors.weight());
        if out.iter().all(|x| x.is_finite()) {
            (out, support)
        } else {
            (Vector3::zeros(), 0.0)
        }
    }

    /// The residual [m/s², model frame] in each of the two model steps
    /// from `y[0]` and `y[1]` (model frame \[m\], three outputs for F⁻¹,
    /// four for F), `d` the disturbance estimate's acceleration offset
    /// \[m/s²\]. The residual enters the Euler step as the drag does: a
    /// function of the step's state, at its velocity `v_j = (y_{j+1} −
    /// y_j)/δt` (the model's `v_k`), and at the thrust of step j's second
    /// difference (the step F⁻¹ predicts, with no `y_3`: the thrust of the
    /// step before). At the second difference's centre instead (the
    /// central difference `(y_{j+2} − y_j)/(2δt)`, the continuous-time
    /// velocity `dflat learn` fits the residual at) the exact aerodynamics
    /// flew the lab's figure eight at 9 m/s (its first 20 s) 10× the
    /// matched plant without pose noise, and a linear drag given as a
    /// residual 9× the same drag in the parametric model (`learned::tests::
    /// the_residual_is_taken_at_the_euler_steps_velocity` in `dflat-lab`).
    /// Weighted (support, running error); for
    /// [`ControlModel::next_output_stepped`] and
    /// [`ControlModel::input_from_outputs_stepped`].
    pub fn step_offsets(
        &self,
        model: &ControlModel,
        y: &[Vector3<f64>],
        d: &Vector3<f64>,
    ) -> [Vector3<f64>; 2] {
        self.steps(model, y, d).map(|(rho, _)| rho)
    }

    fn steps(
        &self,
        model: &ControlModel,
        y: &[Vector3<f64>],
        d: &Vector3<f64>,
    ) -> [(Vector3<f64>, f64); 2] {
        let dt = model.dt();
        let drag = model.drag();
        let mut a = Vector3::zeros();
        std::array::from_fn(|j| {
            let v = (y[j + 1] - y[j]) / dt;
            if let Some(y2) = y.get(j + 2) {
                // The thrust's acceleration: the second difference plus
                // what the model's drag took at the same velocity.
                a = (y2 - y[j + 1] * 2.0 + y[j]) / (dt * dt) + drag.component_mul(&v) - d;
            }
            self.at(model, &v, &a)
        })
    }

    /// After a good tick, on its plan `y*_k..y*_{k+3}` \[m\]: the support
    /// at the plan's start, for [`LearnedTerm::status`] and
    /// [`LearnedTerm::weight`].
    pub fn after_tick(&mut self, model: &ControlModel, plan: &[Vector3<f64>; 4], d: &Vector3<f64>) {
        let [(_, s0), (_, s1)] = self.steps(model, plan, d);
        self.support = Some(s0.min(s1));
    }

    /// One measured acceleration the parametric model did not explain
    /// [m/s², model frame], at velocity `v` [m/s] and with the parametric
    /// model's thrust acceleration `thrust_acc` [m/s²] (the commands
    /// through the lags), scored against the residual's unweighted
    /// prediction there (so a faded term is still judged).
    pub fn observe(
        &mut self,
        model: &ControlModel,
        unexplained: &Vector3<f64>,
        v: &Vector3<f64>,
        thrust_acc: &Vector3<f64>,
    ) {
        let t = Vector3::from(
            model
                .frame()
                .thrust_vector((*thrust_acc).into(), model.gravity()),
        );
        let thrust = t.norm();
        if !(thrust.is_finite() && thrust > 1e-9) {
            return;
        }
        let mut rho = self.model.residual(v, &(t / thrust));
        if matches!(model, ControlModel::Planar(_)) {
            rho.z = 0.0;
        }
        self.errors.observe(unexplained, &rho);
    }

    /// Forgets the plan and the running errors (engagement, reset).
    pub fn reset(&mut self) {
        self.errors = RunningError {
            floor: self.errors.floor,
            ..RunningError::default()
        };
        self.support = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learned::tests::aero_residual;
    use dflat_model::{PlanarModel, PlanarParams};

    fn planar() -> ControlModel {
        ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap())
    }

    /// Outputs along x at `speed` (level, unaccelerated).
    fn plan_at(speed: f64) -> [Vector3<f64>; 4] {
        std::array::from_fn(|j| Vector3::new(speed * 0.02 * j as f64, 0.0, -10.0))
    }

    /// Learned at up to 3 m/s: at 2 m/s it acts in full in both steps
    /// (parasitic and rotor drag, the thrust tilted against them), at 9 m/s
    /// the offsets are 0 and the status says it is out of its support.
    #[test]
    fn it_fades_out_of_its_support() {
        let m = planar();
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        assert_eq!(t.weight(), 0.0);
        let z = Vector3::zeros();
        t.after_tick(&m, &plan_at(2.0), &z);
        assert_eq!(t.status(), LearnedStatus::Active);
        for rho in t.step_offsets(&m, &plan_at(2.0), &z) {
            assert!((rho.x - (-0.03 * 4.0 - 0.2 * 2.0)).abs() < 2e-3, "{rho}");
            assert_eq!((rho.y, rho.z), (0.0, 0.0));
        }
        t.after_tick(&m, &plan_at(9.0), &z);
        assert_eq!(t.step_offsets(&m, &plan_at(9.0), &z), [z, z]);
        assert_eq!(t.status(), LearnedStatus::OutOfSupport);
    }

    /// Each step at its own velocity: outputs speeding up give the second
    /// step the larger drag, and F⁻¹'s three outputs give two steps too.
    #[test]
    fn each_step_has_its_own_velocity() {
        let m = planar();
        let t = LearnedTerm::new(aero_residual(0.03, 0.2, 12.0));
        // 2 m/s, accelerating at 1 m/s².
        let y: [Vector3<f64>; 4] = std::array::from_fn(|j| {
            let t = 0.02 * j as f64;
            Vector3::new(2.0 * t + 0.5 * t * t, 0.0, 0.0)
        });
        let [r0, r1] = t.step_offsets(&m, &y, &Vector3::zeros());
        assert!(r1.x < r0.x && r0.x < 0.0, "{r0} {r1}");
        let [f0, f1] = t.step_offsets(&m, &y[..3], &Vector3::zeros());
        assert_eq!(f0, r0);
        assert!(f1.x < f0.x, "{f0} {f1}");
    }

    /// When its running prediction error grows past the parametric
    /// model's, it fades out, said in its status; when it recovers, it
    /// comes back.
    #[test]
    fn it_fades_when_its_error_grows() {
        let m = planar();
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        let z = Vector3::zeros();
        t.after_tick(&m, &plan_at(2.0), &z);
        let v = Vector3::new(2.0, 0.0, 0.0);
        let rho = t.model().residual(&v, &Vector3::z());
        // The flight shows what the residual predicts: it acts.
        for _ in 0..100 {
            t.observe(&m, &rho, &v, &z);
        }
        assert_eq!(t.weight(), 1.0);
        // Another airframe: a third of what it predicts.
        for _ in 0..300 {
            t.observe(&m, &(rho / 3.0), &v, &z);
        }
        assert_eq!(t.weight(), 0.0);
        assert_eq!(t.status(), LearnedStatus::ErrorGrew);
        assert_eq!(t.step_offsets(&m, &plan_at(2.0), &z), [z, z]);
        for _ in 0..300 {
            t.observe(&m, &rho, &v, &z);
        }
        assert_eq!(t.weight(), 1.0);
    }

    #[test]
    fn non_finite_errors_and_plans_change_nothing() {
        let m = planar();
        let mut t = LearnedTerm::new(aero_residual(0.03, 0.2, 3.0));
        let z = Vector3::zeros();
        t.after_tick(&m, &plan_at(2.0), &z);
        t.observe(&m, &Vector3::new(f64::NAN, 0.0, 0.0), &z, &z);
        assert_eq!(t.errors().count, 0);
        let mut plan = plan_at(2.0);
        plan[3].x = f64::NAN;
        let [_, r1] = t.step_offsets(&m, &plan, &z);
        assert_eq!(r1, z);
    }
}
