//! PD control, the paper's non-predictive baseline (§VII-C, its ref. c20).
//!
//! Each tick: the reference position and velocity are the closest point of
//! the path and the desired speed along it ([`ReferenceSource::closest`]),
//! optionally limited before corners and the end, with that profile's
//! along-path acceleration `a_ff` fed forward ([`PdSettings::corners`]);
//! position and velocity, by [`PdSettings::state`], are the measurement and
//! the first difference of the measured positions `(y_k − y_{k−1})/δt`,
//! optionally low-pass filtered — the paper's simulation set-up — or the
//! estimate of a [`crate::estimator::StateEstimator`] fed with every pose
//! at its capture time and predicted to the tick — the outdoor set-up
//! (§VII, STEAM); the desired acceleration is
//! `a = a_ff + k_p (p_ref − p) + k_d (v_ref − v)` per axis, limited; the attitude
//! (and, for the spatial model, the thrust) follows from the model's
//! attitude map, `θ_cmd = θ/k̃`, saturated at the maximum tilt.

use dflat_model::attitude::thrust_pitch_roll;
use dflat_model::{FlatError, Frame};
use nalgebra::{Vector2, Vector3};

use crate::estimator::differences::PoseDifferences;
use crate::estimator::{BaselineEstimator, StateSource};
use crate::fmpc::limit_pair;
use crate::{
    AttitudeCommand, ControlError, ControlModel, Controller, Measurement, ReferenceSource,
    TickOutput,
};
use crate::{Limit, TiltLimit};

/// Settings of [`Pd`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdSettings {
    /// Position gains k_p per axis (x, y, z) [1/s²], finite, > 0 (z unused by
    /// the planar model). Default 2.
    pub kp: [f64; 3],
    /// Velocity gains k_d per axis (x, y, z) [1/s], finite, > 0. Default 2.5.
    ///
    /// With the attitude lag τ = 0.2 s the linearised loop per axis is
    /// `τs³ + s² + k_d s + k_p`; the defaults place its poles at −1.3 and
    /// −1.85 ± 2.07j (damping 0.67). Among the gains tried in closed loop
    /// (k_p 0.5–3, k_d 1–4) they settle a 10 m step in ~4.5 s without
    /// overshoot and keep the L-path error near the lowest; a higher k_p
    /// lowers the path error a little but overshoots the step.
    pub kd: [f64; 3],
    /// Limit on the horizontal desired acceleration magnitude [m/s²], finite,
    /// > 0 (direction kept). Default g·tan(35°) ≈ 6.87.
    pub max_horizontal_acceleration: f64,
    /// Limit on |a_z| [m/s²] (spatial model), finite, in (0, g). Default 4.
    pub max_vertical_acceleration: f64,
    /// Cut-off of the first-order low-pass on the finite-difference velocity
    /// \[Hz\], finite, > 0; `None` (default) leaves it unfiltered.
    pub velocity_cutoff_hz: Option<f64>,
    /// Saturation of the pitch and roll commands \[rad\], in (0, π/2).
    /// Default 35°.
    pub max_tilt: f64,
    /// How `max_tilt` applies (default [`TiltLimit::PerAxis`], the paper).
    pub tilt_limit: TiltLimit,
    /// Slow down for a path's corners and its end, as PX4's mission mode
    /// does ([`ReferenceSource::corner_speed`]); `None` (default): the
    /// paper's PD, which flies every corner at the path speed.
    pub corners: Option<CornerSlowdown>,
    /// Where position and velocity come from. Default
    /// [`StateSource::FiniteDifference`]; the daemon and the lab's path
    /// study default to the estimator (`velocity_cutoff_hz` then unused).
    pub state: StateSource,
    /// Feed the reference's acceleration forward (its second difference
    /// over the next two control steps), for a reference the vehicle can
    /// fly as it is ([`ReferenceSource::flyable`]: a planner's stream) —
    /// an autopilot's position loop with velocity and acceleration
    /// feed-forward. Default off (the paper's PD).
    pub acceleration_feed_forward: bool,
}

/// How PD rounds a path's corners: the reference speed is limited so that a
/// vehicle braking and turning at `acceleration` rounds each corner on an arc
/// whose tangent points lie `radius` from the waypoint, and stops at the end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerSlowdown {
    /// Distance from a waypoint at which the turn starts \[m\]
    /// ([`CornerSlowdown::RADIUS`]: > 0 to 50; PX4's acceptance radius).
    pub radius: f64,
    /// Braking and turning acceleration [m/s²]
    /// ([`CornerSlowdown::ACCELERATION`]: 0.1 to 20; at most the
    /// horizontal acceleration limit, with room for the feedback).
    pub acceleration: f64,
}

impl CornerSlowdown {
    /// `radius` \[m\] (the daemon's `controller.pd.corner_radius`; 0 there =
    /// no slowdown).
    pub const RADIUS: Limit = Limit::above(0.0, 50.0, "m");
    /// `acceleration` \[m/s²\].
    pub const ACCELERATION: Limit = Limit::closed(0.1, 20.0, "m/s²");
}

impl Default for PdSettings {
    fn default() -> Self {
        let max_tilt = 35f64.to_radians();
        Self {
            kp: [2.0; 3],
            kd: [2.5; 3],
            max_horizontal_acceleration: 9.81 * max_tilt.tan(),
            max_vertical_acceleration: 4.0,
            velocity_cutoff_hz: None,
            max_tilt,
            tilt_limit: TiltLimit::PerAxis,
            corners: None,
            state: StateSource::FiniteDifference,
            acceleration_feed_forward: false,
        }
    }
}

fn invalid(field: &'static str, reason: impl Into<String>) -> ControlError {
    ControlError::InvalidSetting {
        field,
        reason: reason.into(),
    }
}

impl PdSettings {
    /// Each of `kp` \[1/s²\].
    pub const KP: Limit = Limit::positive("1/s²");
    /// Each of `kd` \[1/s\].
    pub const KD: Limit = Limit::positive("1/s");

    /// Checks every field; the error names the first invalid one.
    pub fn validate(&self) -> Result<(), ControlError> {
        Self::KP.check_all("kp", &self.kp)?;
        Self::KD.check_all("kd", &self.kd)?;
        let a = self.max_horizontal_acceleration;
        if !(a.is_finite() && a > 0.0) {
            return Err(invalid(
                "max_horizontal_acceleration",
                format!("must be finite and > 0 m/s², got {a}"),
            ));
        }
        let a = self.max_vertical_acceleration;
        if !(a.is_finite() && a > 0.0) {
            return Err(invalid(
                "max_vertical_acceleration",
                format!("must be finite and > 0 m/s² (and below g), got {a}"),
            ));
        }
        if let Some(f) = self.velocity_cutoff_hz
            && !(f.is_finite() && f > 0.0)
        {
            return Err(invalid(
                "velocity_cutoff_hz",
                format!("must be finite and > 0 Hz, got {f}"),
            ));
        }
        if let Some(c) = self.corners {
            CornerSlowdown::RADIUS.check("corners.radius", c.radius)?;
            CornerSlowdown::ACCELERATION.check("corners.acceleration", c.acceleration)?;
        }
        let t = self.max_tilt;
        if !(t.is_finite() && t > 0.0 && t < std::f64::consts::FRAC_PI_2) {
            return Err(invalid(
                "max_tilt",
                format!("must be in (0, π/2) rad, got {t}"),
            ));
        }
        Ok(())
    }
}

/// The paper's PD controller (§VII-C): see the module docs.
#[derive(Debug, Clone)]
pub struct Pd {
    model: ControlModel,
    settings: PdSettings,
    /// Control step δt \[s\] (the model's).
    dt: f64,
    /// Low-pass coefficient α ∈ (0, 1] of the velocity filter (1 = off).
    alpha: f64,
    /// The finite-difference velocity's poses at their capture times
    /// ([`StateSource::FiniteDifference`]).
    differences: PoseDifferences,
    /// Velocity estimate (NED [m/s]).
    velocity: Vector3<f64>,
    /// The state estimator ([`StateSource::Estimator`]), else None.
    estimator: Option<BaselineEstimator>,
}

impl Pd {
    /// Builds the controller for `model` (its δt is the control step).
    /// Errors name an invalid setting; the vertical acceleration limit must
    /// stay below the model's g (the thrust must point up).
    pub fn new(model: ControlModel, settings: PdSettings) -> Result<Self, ControlError> {
        settings.validate()?;
        let (dt, g) = match &model {
            ControlModel::Planar(m) => (m.params().dt, m.params().g),
            ControlModel::Spatial(m) => (m.params().dt, m.params().g),
        };
        if !(dt.is_finite() && dt > 0.0) {
            return Err(invalid(
                "dt",
                format!("model step must be finite and > 0 s, got {dt}"),
            ));
        }
        if settings.max_vertical_acceleration >= g {
            return Err(invalid(
                "max_vertical_acceleration",
                format!(
                    "must be below g = {g} m/s², got {}",
                    settings.max_vertical_acceleration
                ),
            ));
        }
        let alpha = match settings.velocity_cutoff_hz {
            None => 1.0,
            Some(f) => {
                let time_constant = 1.0 / (2.0 * std::f64::consts::PI * f);
                dt / (dt + time_constant)
            }
        };
        Ok(Self {
            model,
            settings,
            dt,
            alpha,
            differences: PoseDifferences::new(dt),
            velocity: Vector3::zeros(),
            estimator: BaselineEstimator::from_source(settings.state, &model)?,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &PdSettings {
        &self.settings
    }

    /// The current velocity estimate (NED [m/s]).
    pub fn velocity(&self) -> Vector3<f64> {
        self.velocity
    }

    /// The reference the tick flies from the position `y`: its point,
    /// velocity and the acceleration fed forward (a flyable reference's
    /// own with `acceleration_feed_forward`; a corner's braking with
    /// `corners`). Errors on a non-finite reference.
    fn reference_at(
        &self,
        y: &Vector3<f64>,
        reference: &mut dyn ReferenceSource,
    ) -> Result<[Vector3<f64>; 3], ControlError> {
        // One control step of the reference first: a path's start ramp
        // advances only with `horizon` (its speed would stay at the ramp's
        // v0 = 0 and PD would hover at the start).
        let mut step = [Vector3::zeros(); 3];
        let feed_forward = self.settings.acceleration_feed_forward && reference.flyable();
        let steps = if feed_forward { 3 } else { 1 };
        reference.horizon(y, self.dt, &mut step[..steps]);
        let (p_ref, mut v_ref) = reference.closest(y);
        // A flyable reference's acceleration, fed forward.
        let mut a_ff = if feed_forward {
            (step[2] - step[1] * 2.0 + step[0]) / (self.dt * self.dt)
        } else {
            Vector3::zeros()
        };
        // Slowing for a corner: the limited speed, and its rate along the
        // path fed forward (PD alone lags the braking).
        if let Some(c) = self.settings.corners
            && let Some((limit, rate)) = reference.corner_speed(c.radius, c.acceleration)
        {
            let speed = v_ref.norm();
            if speed > limit {
                let dir = v_ref / speed;
                v_ref = dir * limit;
                a_ff = dir * rate;
            }
        }
        if !(p_ref
            .iter()
            .chain(v_ref.iter())
            .chain(a_ff.iter())
            .all(|c| c.is_finite()))
        {
            return Err(ControlError::NonFiniteReference);
        }
        Ok([p_ref, v_ref, a_ff])
    }
}

/// Limits the horizontal part of `a` to `max` [m/s²] keeping its direction.
fn limit_horizontal(a: &mut Vector3<f64>, max: f64, saturated: &mut bool) {
    let h = Vector2::new(a.x, a.y);
    let n = h.norm();
    if n > max {
        let scale = max / n;
        a.x *= scale;
        a.y *= scale;
        *saturated = true;
    }
}

impl Controller for Pd {
    fn name(&self) -> &'static str {
        "pd"
    }

    fn multi_rate(&self) -> bool {
        self.estimator.is_some()
    }

    fn observe(&mut self, sample: &Measurement) {
        BaselineEstimator::observe(self.estimator.as_mut(), sample);
    }

    fn skipped(&mut self, ticks: u32) {
        // The estimator takes the tick time from the update.
        self.differences.skip(ticks);
    }

    fn tick_time(&self, measurement: &Measurement) -> f64 {
        BaselineEstimator::tick_time(self.estimator.as_ref(), &self.differences, measurement)
    }

    fn correct_last_input(&mut self, applied: &Vector3<f64>) {
        if let Some(e) = &mut self.estimator {
            e.correct(&self.model, applied);
        }
    }

    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError> {
        let estimate = BaselineEstimator::checked_state(self.estimator.as_ref(), measurement)?;
        // The finite difference takes each pose at its capture time: a
        // tick without a new pose is carried forward with the velocity
        // estimate, not read as a stop, and a late pose or one after
        // skipped ticks is differenced over its own spacing.
        let mut differences = self.differences.clone();
        let (y, velocity) = match &estimate {
            Some(s) => (
                Vector3::new(s[0][0], s[1][0], s[2][0]),
                Vector3::new(s[0][1], s[1][1], s[2][1]),
            ),
            None => {
                let first = !differences.started();
                let new = differences.tick(measurement.t, &measurement.position);
                let velocity = match differences.first_difference() {
                    Some(raw) if new && !first => {
                        self.velocity + (raw - self.velocity) * self.alpha
                    }
                    _ if first => Vector3::zeros(),
                    _ => self.velocity,
                };
                let (_, newest) = differences.newest().unwrap_or((0.0, measurement.position));
                let tau = differences.extrapolation().unwrap_or(0.0);
                let y = if tau != 0.0 {
                    newest + velocity * tau
                } else {
                    newest
                };
                (y, velocity)
            }
        };
        let [p_ref, v_ref, a_ff] = self.reference_at(&y, reference)?;

        let s = &self.settings;
        let mut a = Vector3::from_fn(|i, _| {
            a_ff[i] + s.kp[i] * (p_ref[i] - y[i]) + s.kd[i] * (v_ref[i] - velocity[i])
        });
        let mut saturated = false;
        limit_horizontal(&mut a, s.max_horizontal_acceleration, &mut saturated);
        let limit = Some(s.max_tilt);

        // The flat attitude and thrust, then the attitude loop's gain k̃.
        let (theta, phi, thrust, k, psi) = match &self.model {
            ControlModel::Planar(m) => {
                let p = m.params();
                let (theta, phi) = m.attitude(&Vector2::new(a.x, a.y));
                (theta, phi, p.g, p.k, p.psi)
            }
            ControlModel::Spatial(m) => {
                let p = m.params();
                let az_max = s.max_vertical_acceleration;
                if a.z.abs() > az_max {
                    a.z = a.z.clamp(-az_max, az_max);
                    saturated = true;
                }
                let t = spatial_thrust_vector(p.frame, p.g, &a);
                let (thrust, theta, phi) = thrust_pitch_roll(t, p.psi)?;
                (theta, phi, thrust, p.k, p.psi)
            }
        };
        let (pitch, roll) = limit_pair(theta / k, phi / k, limit, s.tilt_limit, &mut saturated);
        let command = AttitudeCommand {
            pitch,
            roll,
            yaw: psi,
            thrust,
        };
        if !command.is_finite() {
            return Err(ControlError::Flat(FlatError::NonFinite("PD command")));
        }

        self.differences = differences;
        self.velocity = velocity;
        if let Some(e) = &mut self.estimator {
            e.sent(&self.model, measurement.t, &command);
        }
        Ok(TickOutput {
            command,
            plan: [y; 4],
            reference: p_ref,
            saturated,
            constrained: false,
            qp_fallback: false,
            cone_interior_point: false,
        })
    }

    fn reset(&mut self) {
        self.differences.reset();
        self.velocity = Vector3::zeros();
        if let Some(e) = &mut self.estimator {
            e.estimator.reset();
        }
    }
}

fn spatial_thrust_vector(frame: Frame, g: f64, a: &Vector3<f64>) -> [f64; 3] {
    frame.thrust_vector([a.x, a.y, a.z], g)
}
