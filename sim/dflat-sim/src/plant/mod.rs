//! Plants: the vehicle (and its autopilot) the controllers fly in the lab.
//!
//! Independent of the controllers' Euler models: continuous-time dynamics
//! integrated with RK4 (or forward Euler, to replay the paper's set-up) at
//! [`PlantOptions::plant_dt`] (200 Hz by default), the command held
//! (zero-order hold) between controller ticks. All plants are local NED with
//! body FRD, ZYX Euler angles, thrust along −z body:
//!
//! ```text
//! v̇ = g·e3 − T·R·e3 + a_aero(v − w)    (T specific thrust [m/s²], w wind)
//! a_aero(u) = −c·u − c_q·|u|·u − d·R·diag(1, 1, 0)·Rᵀ·u
//! ```
//!
//! with `u` the air-relative velocity, `c` linear drag [1/s]
//! ([`PlantOptions::drag`]), `c_q` quadratic parasitic drag [1/m]
//! ([`PlantOptions::quadratic_drag`]) and `d` rotor drag in the body plane
//! [1/s] ([`PlantOptions::rotor_drag`]; `R·diag(1, 1, 0)·Rᵀ = I − n·nᵀ` with
//! `n = R·e3` the thrust axis, so it does not depend on the heading): see
//! [`aero_acceleration`].
//!
//! so at ψ = 0 and constant altitude `ẍ = −g·R13/R33 = −g·tanθ` (nose down
//! accelerates north) and `ÿ = −g·R23/R33 = g·tanφ/cosθ`.
//!
//! * [`PlanarPlant`] — paper §IV-B: first-order pitch/roll
//!   `θ̇ = (k̃·θ_cmd − θ)/τ`, constant altitude and yaw.
//! * [`SpatialPlant`] — the planar attitude plus altitude through a
//!   first-order collective thrust `Ṫ = (k_T·T_cmd − T)/τ_T`.
//! * [`RigidBodyPlant`] — 12 rigid-body states (position, velocity, ZYX
//!   angles, FRD body rates) with an inner autopilot: attitude P → rate
//!   PID → torques, thrust through a first-order motor lag.
//!
//! Commands pass through the autopilot's saturation first (pitch and roll
//! each clipped to ±[`PlantOptions::tilt_limit`], 35° by default — the DJI
//! onboard SDK's limit — thrust to `[thrust_min, thrust_max]`).

mod delay;
mod planar;
mod rigid;
mod shell;
mod spatial;
mod wind;
mod yaw;

pub use delay::DelayedPlant;
pub use planar::PlanarPlant;
pub use rigid::RigidBodyPlant;
pub use spatial::SpatialPlant;
pub use wind::Wind;

use dflat_control::AttitudeCommand;
use nalgebra::{Matrix3, SVector, Vector3};
use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::error::{check_positive, check_range};

/// The common view of a plant's true state.
///
/// Position and velocity are local NED \[m\], [m/s]; angles ZYX \[rad\]; body
/// rates FRD [rad/s]; `thrust` is the *actual* specific collective thrust
/// [m/s²] (thrust / true mass) acting on the vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantState {
    /// Position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Velocity, local NED [m/s].
    pub velocity: Vector3<f64>,
    /// Roll φ \[rad\] (ZYX).
    pub roll: f64,
    /// Pitch θ \[rad\] (ZYX).
    pub pitch: f64,
    /// Yaw ψ \[rad\] (ZYX).
    pub yaw: f64,
    /// Body rates p, q, r, FRD [rad/s] (the first-order plants: from their
    /// roll and pitch rates at fixed yaw, [`body_rates_from_euler_rates`]).
    pub body_rates: Vector3<f64>,
    /// Actual specific collective thrust [m/s²].
    pub thrust: f64,
}

impl PlantState {
    /// Level hover at rest at `position` (NED \[m\]) with yaw 0 under gravity
    /// `g` [m/s²].
    pub fn hover(position: Vector3<f64>, g: f64) -> Self {
        Self {
            position,
            velocity: Vector3::zeros(),
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0,
            body_rates: Vector3::zeros(),
            thrust: g,
        }
    }

    /// Tilt of the thrust axis from vertical \[rad\]: `acos(cosθ·cosφ)`.
    pub fn tilt(&self) -> f64 {
        dflat_control::tilt::tilt(self.pitch, self.roll)
    }

    /// True when every field is finite.
    pub fn is_finite(&self) -> bool {
        self.position.iter().all(|v| v.is_finite())
            && self.velocity.iter().all(|v| v.is_finite())
            && self.body_rates.iter().all(|v| v.is_finite())
            && self.roll.is_finite()
            && self.pitch.is_finite()
            && self.yaw.is_finite()
            && self.thrust.is_finite()
    }
}

impl Default for PlantState {
    /// Level hover at rest at the origin, g = 9.81 m/s².
    fn default() -> Self {
        Self::hover(Vector3::zeros(), 9.81)
    }
}

/// A simulated vehicle with its autopilot, driven by attitude commands.
///
/// Protocol: [`Plant::reset`] once, then per controller tick
/// [`Plant::apply`] (zero-order hold until the next apply) and one or more
/// [`Plant::advance`]. Accessors report the true state at [`Plant::time`].
pub trait Plant: Send {
    /// Which plant this is.
    fn kind(&self) -> PlantKind;
    /// Puts the vehicle in `state` at time 0 and holds the command that
    /// keeps it there (attitude as in `state`, thrust for `state.thrust`).
    /// The gust process continues from the plant's seeded stream.
    fn reset(&mut self, state: &PlantState);
    /// Sets the held command. The autopilot saturates it (see
    /// [`Plant::applied_command`]); a command with non-finite fields is
    /// ignored and the previous one kept.
    fn apply(&mut self, command: &AttitudeCommand);
    /// Integrates the dynamics for `dt` \[s\] in equal steps of at most
    /// [`PlantOptions::plant_dt`]. Non-positive or non-finite `dt` does nothing.
    fn advance(&mut self, dt: f64);
    /// Position, local NED \[m\].
    fn position(&self) -> Vector3<f64>;
    /// Velocity, local NED [m/s].
    fn velocity(&self) -> Vector3<f64>;
    /// Attitude (roll φ, pitch θ, yaw ψ) \[rad\], ZYX.
    fn attitude(&self) -> (f64, f64, f64);
    /// The common view of the true state.
    fn true_state(&self) -> PlantState;
    /// The plant's raw state vector (layout documented on each plant).
    fn state_vector(&self) -> Vec<f64>;
    /// Simulated time since [`Plant::reset`] \[s\].
    fn time(&self) -> f64;
    /// The command after the autopilot's saturation, as held now.
    fn applied_command(&self) -> AttitudeCommand;
    /// True when the last applied command was clipped by the autopilot.
    fn saturated(&self) -> bool;
    /// Air-mass velocity now (mean wind + gust), local NED [m/s].
    fn wind(&self) -> Vector3<f64>;
}

/// Which plant to build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlantKind {
    /// [`PlanarPlant`]: first-order attitude, constant altitude and yaw.
    #[default]
    Planar,
    /// [`SpatialPlant`]: planar attitude plus altitude through thrust.
    Spatial,
    /// [`RigidBodyPlant`]: 12-state rigid body with an inner autopilot.
    RigidBody,
}

/// Numerical integrator of the plant dynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Classic fourth-order Runge–Kutta (the lab's default).
    #[default]
    Rk4,
    /// Forward Euler (to replay the paper's 1-D set-up step for step).
    Euler,
}

/// Options shared by all plants. Defaults: 200 Hz RK4, g = 9.81, ±35°
/// command saturation, τ = 0.2 s, k̃ = 1, no drag, no wind, no mismatch.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlantOptions {
    /// Integration step \[s\] (0.005 = 200 Hz).
    pub plant_dt: f64,
    /// Integrator.
    pub integrator: Integrator,
    /// Gravity [m/s²].
    pub g: f64,
    /// Saturation of the pitch and roll commands, each \[rad\] (35° default).
    pub tilt_limit: f64,
    /// Lower saturation of the specific-thrust command [m/s²].
    pub thrust_min: f64,
    /// Upper saturation of the specific-thrust command [m/s²].
    pub thrust_max: f64,
    /// Plant attitude time constant τ \[s\] (first-order plants).
    pub attitude_tau: f64,
    /// Plant attitude gain k̃ [-]: the attitude settles at k̃·command (all
    /// plants; the rigid body scales its pitch/roll setpoints by it).
    pub attitude_gain: f64,
    /// Thrust time constant τ_T \[s\] (spatial: thrust lag; rigid body: motor lag).
    pub thrust_tau: f64,
    /// Thrust gain [-]: actual thrust per commanded thrust, at nominal mass.
    pub thrust_gain: f64,
    /// True mass / nominal mass [-]: the actual specific thrust is
    /// `thrust_gain · command / mass_factor` (hover needs `g·mass_factor/thrust_gain`).
    pub mass_factor: f64,
    /// Linear drag coefficient c [1/s] on the air-relative velocity.
    pub drag: f64,
    /// Quadratic parasitic drag c_q [1/m]: `−c_q·|u|·u` on the air-relative
    /// velocity `u` (0 = none, the default).
    pub quadratic_drag: f64,
    /// Rotor drag d [1/s] in the body plane: `−d·R·diag(1, 1, 0)·Rᵀ·u`, the
    /// air-relative velocity's part across the thrust axis (0 = none, the
    /// default).
    pub rotor_drag: f64,
    /// Mean wind, local NED [m/s].
    pub wind: [f64; 3],
    /// Gust standard deviation per NED axis [m/s] (0 = no gusts).
    pub gust_std: [f64; 3],
    /// Gust correlation time \[s\] (Dryden's L/V).
    pub gust_tau: f64,
    /// Rigid-body parameters and autopilot gains.
    pub rigid: RigidBodyOptions,
    /// Pure delay \[s\] between a command and its application by the
    /// autopilot (0 = none): [`build_plant`] then wraps the plant in a
    /// [`DelayedPlant`].
    pub command_delay: f64,
    /// Largest yaw rate of the first-order plants' yaw loop \[rad/s\]
    /// (`plant/yaw.rs`); 0 (the default, the paper's set-up): the heading
    /// stays at its reset value and the yaw command is ignored.
    pub max_yaw_rate: f64,
    /// Time constant of that yaw loop \[s\] (> 0).
    pub yaw_tau: f64,
}

impl Default for PlantOptions {
    fn default() -> Self {
        Self {
            plant_dt: 0.005,
            integrator: Integrator::Rk4,
            g: 9.81,
            tilt_limit: 35f64.to_radians(),
            thrust_min: 0.0,
            thrust_max: 2.5 * 9.81,
            attitude_tau: 0.2,
            attitude_gain: 1.0,
            thrust_tau: 0.04,
            thrust_gain: 1.0,
            mass_factor: 1.0,
            drag: 0.0,
            quadratic_drag: 0.0,
            rotor_drag: 0.0,
            wind: [0.0; 3],
            gust_std: [0.0; 3],
            gust_tau: 1.0,
            rigid: RigidBodyOptions::default(),
            command_delay: 0.0,
            max_yaw_rate: 0.0,
            yaw_tau: 0.1,
        }
    }
}

impl PlantOptions {
    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<(), SimError> {
        check_range("plant_dt", self.plant_dt, 1e-6, 0.1, "1e-6 ..= 0.1 s")?;
        check_positive("g", self.g)?;
        check_range(
            "tilt_limit",
            self.tilt_limit,
            1e-6,
            80f64.to_radians(),
            "(0, 80°] in rad",
        )?;
        check_range("thrust_min", self.thrust_min, 0.0, f64::MAX, ">= 0 m/s²")?;
        check_range(
            "thrust_max",
            self.thrust_max,
            self.thrust_min.max(1e-9),
            f64::MAX,
            "> thrust_min m/s²",
        )?;
        check_positive("attitude_tau", self.attitude_tau)?;
        check_positive("attitude_gain", self.attitude_gain)?;
        check_positive("thrust_tau", self.thrust_tau)?;
        check_positive("thrust_gain", self.thrust_gain)?;
        check_positive("mass_factor", self.mass_factor)?;
        check_range("drag", self.drag, 0.0, f64::MAX, ">= 0 1/s")?;
        check_range(
            "quadratic_drag",
            self.quadratic_drag,
            0.0,
            10.0,
            "0 ..= 10 1/m",
        )?;
        check_range("rotor_drag", self.rotor_drag, 0.0, 10.0, "0 ..= 10 1/s")?;
        for w in self.wind {
            check_range("wind", w, -1e3, 1e3, "finite, |w| <= 1000 m/s")?;
        }
        for s in self.gust_std {
            check_range("gust_std", s, 0.0, 1e3, "0 ..= 1000 m/s")?;
        }
        check_positive("gust_tau", self.gust_tau)?;
        check_range("command_delay", self.command_delay, 0.0, 2.0, "0 ..= 2 s")?;
        check_range(
            "max_yaw_rate",
            self.max_yaw_rate,
            0.0,
            100.0,
            "0 ..= 100 rad/s",
        )?;
        check_positive("yaw_tau", self.yaw_tau)?;
        self.rigid.validate()
    }

    /// The specific-thrust command that holds `thrust` [m/s²] in steady state.
    pub fn thrust_command_for(&self, thrust: f64) -> f64 {
        thrust * self.mass_factor / self.thrust_gain
    }

    /// Saturates a command as the autopilot does: pitch and roll each to
    /// ±`tilt_limit`, thrust to `[thrust_min, thrust_max]`. Returns the
    /// clipped command and whether anything was clipped.
    pub fn saturate(&self, c: &AttitudeCommand) -> (AttitudeCommand, bool) {
        let lim = self.tilt_limit;
        let out = AttitudeCommand {
            pitch: c.pitch.clamp(-lim, lim),
            roll: c.roll.clamp(-lim, lim),
            yaw: c.yaw,
            thrust: c.thrust.clamp(self.thrust_min, self.thrust_max),
        };
        let clipped = out.pitch != c.pitch || out.roll != c.roll || out.thrust != c.thrust;
        (out, clipped)
    }

    /// Number of equal integration steps for a span `dt` \[s\] and their length.
    pub(crate) fn substeps(&self, dt: f64) -> (usize, f64) {
        let n = (dt / self.plant_dt - 1e-9).ceil().max(1.0) as usize;
        (n, dt / n as f64)
    }
}

/// Rigid-body parameters and the inner autopilot's gains.
///
/// The autopilot is continuous-time (an idealised fast inner loop):
/// `ω_sp = E(η)·K_att⊙(η_sp − η)` (Euler-angle error mapped to body rates),
/// `α = K_p⊙e_ω + K_i⊙∫e_ω − K_d⊙ω̇_f` (derivative on the measured rate,
/// low-pass filtered at `d_filter`), torque `J·α` with the nominal inertia.
/// With the defaults the pitch/roll response is close to first order with
/// τ ≈ 0.2 s (poles at about −6.9 and −18 rad/s).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigidBodyOptions {
    /// Nominal mass \[kg\] (the autopilot's; the true mass is `mass · mass_factor`).
    pub mass: f64,
    /// Nominal principal inertia [Ixx, Iyy, Izz] [kg·m²].
    pub inertia: [f64; 3],
    /// True inertia / nominal inertia [-].
    pub inertia_factor: f64,
    /// Attitude P gains (roll, pitch, yaw) [1/s].
    pub att_p: [f64; 3],
    /// Rate P gains (p, q, r) [1/s].
    pub rate_p: [f64; 3],
    /// Rate I gains (p, q, r) [1/s²].
    pub rate_i: [f64; 3],
    /// Rate D gains (p, q, r) [-].
    pub rate_d: [f64; 3],
    /// Derivative filter bandwidth [rad/s].
    pub d_filter: f64,
    /// Clamp of each rate integrator's contribution to α [rad/s²].
    pub i_limit: f64,
    /// Largest body-rate setpoint (p, q, r) the attitude loop may ask
    /// \[rad/s\] (PX4's MC_ROLLRATE_MAX and kin; ArduPilot's
    /// ATC_RATE_R_MAX); 0 on an axis: no limit (the default).
    pub max_rate: [f64; 3],
}

impl Default for RigidBodyOptions {
    /// A DJI M600-class hexacopter: 15 kg, inertia [1.2, 1.2, 2.0] kg·m².
    fn default() -> Self {
        Self {
            mass: 15.0,
            inertia: [1.2, 1.2, 2.0],
            inertia_factor: 1.0,
            att_p: [5.0, 5.0, 2.5],
            rate_p: [25.0, 25.0, 12.0],
            rate_i: [2.0, 2.0, 1.0],
            rate_d: [0.01, 0.01, 0.0],
            d_filter: 60.0,
            i_limit: 5.0,
            max_rate: [0.0; 3],
        }
    }
}

impl RigidBodyOptions {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), SimError> {
        check_positive("rigid.mass", self.mass)?;
        for v in self.inertia {
            check_positive("rigid.inertia", v)?;
        }
        check_positive("rigid.inertia_factor", self.inertia_factor)?;
        for v in self.att_p.iter().chain(&self.rate_p) {
            check_range("rigid.att_p/rate_p", *v, 0.0, 1e4, "0 ..= 1e4")?;
        }
        for v in self.rate_i.iter().chain(&self.rate_d) {
            check_range("rigid.rate_i/rate_d", *v, 0.0, 1e4, "0 ..= 1e4")?;
        }
        check_positive("rigid.d_filter", self.d_filter)?;
        for v in self.max_rate {
            check_range(
                "rigid.max_rate",
                v,
                0.0,
                100.0,
                "0 ..= 100 rad/s (0 = none)",
            )?;
        }
        check_range("rigid.i_limit", self.i_limit, 0.0, 1e6, "0 ..= 1e6 rad/s²")
    }
}

/// Builds a plant of `kind` with validated `options`; `seed` drives the gust
/// process. The plant starts in [`PlantState::hover`] at the origin.
pub fn build_plant(
    kind: PlantKind,
    options: &PlantOptions,
    seed: u64,
) -> Result<Box<dyn Plant>, SimError> {
    let plant: Box<dyn Plant> = match kind {
        PlantKind::Planar => Box::new(PlanarPlant::new(options.clone(), seed)?),
        PlantKind::Spatial => Box::new(SpatialPlant::new(options.clone(), seed)?),
        PlantKind::RigidBody => Box::new(RigidBodyPlant::new(options.clone(), seed)?),
    };
    Ok(if options.command_delay > 0.0 {
        Box::new(DelayedPlant::new(plant, options.command_delay))
    } else {
        plant
    })
}

/// One integration step of `ẋ = f(x)` over `h` \[s\].
pub(crate) fn integrate<const N: usize>(
    method: Integrator,
    x: &SVector<f64, N>,
    h: f64,
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, N>,
) -> SVector<f64, N> {
    match method {
        Integrator::Euler => x + f(x) * h,
        Integrator::Rk4 => {
            let k1 = f(x);
            let k2 = f(&(x + k1 * (h / 2.0)));
            let k3 = f(&(x + k2 * (h / 2.0)));
            let k4 = f(&(x + k3 * h));
            x + (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0)
        }
    }
}

/// Body→world rotation `R = Rz(ψ)·Ry(θ)·Rx(φ)` (ZYX).
pub fn rotation(roll: f64, pitch: f64, yaw: f64) -> Matrix3<f64> {
    let (sp, cp) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (ss, cs) = yaw.sin_cos();
    Matrix3::new(
        cs * ct,
        cs * st * sp - ss * cp,
        cs * st * cp + ss * sp,
        ss * ct,
        ss * st * sp + cs * cp,
        ss * st * cp - cs * sp,
        -st,
        ct * sp,
        ct * cp,
    )
}

/// Unit thrust axis `R·e3` (world frame) of the ZYX attitude; thrust acts
/// along its negative in NED.
pub fn thrust_axis(roll: f64, pitch: f64, yaw: f64) -> Vector3<f64> {
    let (sp, cp) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (ss, cs) = yaw.sin_cos();
    Vector3::new(cs * st * cp + ss * sp, ss * st * cp - cs * sp, ct * cp)
}

/// Aerodynamic acceleration [m/s²] (local NED) on a vehicle moving at
/// `air_velocity` (relative to the air mass, NED [m/s]) with thrust axis
/// `axis` (unit `R·e3`, NED): linear drag `−c·u`, quadratic parasitic drag
/// `−c_q·|u|·u` and rotor drag `−d·(u − n·(n·u))` (= `−d·R·diag(1, 1, 0)·Rᵀ·u`).
pub fn aero_acceleration(
    options: &PlantOptions,
    air_velocity: &Vector3<f64>,
    axis: &Vector3<f64>,
) -> Vector3<f64> {
    let u = air_velocity;
    let across = u - axis * axis.dot(u);
    -u * options.drag - u * (options.quadratic_drag * u.norm()) - across * options.rotor_drag
}

/// Horizontal NED acceleration at constant altitude [m/s²]:
/// `[−g·R13/R33, −g·R23/R33]` (non-finite at 90° tilt).
/// Body rates p, q, r (FRD [rad/s]) of ZYX Euler angles `roll`, `pitch`
/// changing at `roll_rate`, `pitch_rate`, `yaw_rate` [rad/s]:
/// p = φ̇ − sinθ·ψ̇, q = cosφ·θ̇ + sinφ·cosθ·ψ̇, r = −sinφ·θ̇ + cosφ·cosθ·ψ̇.
pub fn body_rates_from_euler_rates(
    roll: f64,
    pitch: f64,
    roll_rate: f64,
    pitch_rate: f64,
    yaw_rate: f64,
) -> Vector3<f64> {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    Vector3::new(
        roll_rate - sp * yaw_rate,
        cr * pitch_rate + sr * cp * yaw_rate,
        -sr * pitch_rate + cr * cp * yaw_rate,
    )
}

pub(crate) fn level_flight_acceleration(g: f64, roll: f64, pitch: f64, yaw: f64) -> (f64, f64) {
    let a = thrust_axis(roll, pitch, yaw);
    (-g * a.x / a.z, -g * a.y / a.z)
}

/// Shared command bookkeeping of the plants.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldCommand {
    pub(crate) command: AttitudeCommand,
    pub(crate) saturated: bool,
}

impl HeldCommand {
    /// The command that holds `state` still (in attitude and thrust).
    pub(crate) fn steady(options: &PlantOptions, state: &PlantState) -> Self {
        let (command, saturated) = options.saturate(&AttitudeCommand {
            pitch: state.pitch / options.attitude_gain,
            roll: state.roll / options.attitude_gain,
            yaw: state.yaw,
            thrust: options.thrust_command_for(state.thrust),
        });
        Self { command, saturated }
    }

    /// Applies a new command (ignored when non-finite).
    pub(crate) fn apply(&mut self, options: &PlantOptions, command: &AttitudeCommand) {
        if command.is_finite() {
            let (c, s) = options.saturate(command);
            self.command = c;
            self.saturated = s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every plant reports the body rates of its attitude motion: after a
    /// pitch step the pitch rate agrees with the finite difference of the
    /// pitch (the first-order plants reported 0 before).
    #[test]
    fn body_rates_follow_the_attitude_motion() {
        let options = PlantOptions {
            plant_dt: 1.0 / 200.0,
            ..PlantOptions::default()
        };
        for kind in [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody] {
            let mut plant = build_plant(kind, &options, 1).unwrap();
            plant.reset(&PlantState::hover(Vector3::zeros(), options.g));
            plant.apply(&AttitudeCommand {
                pitch: -0.3,
                roll: 0.2,
                yaw: 0.0,
                thrust: options.thrust_command_for(options.g),
            });
            let h = options.plant_dt;
            plant.advance(0.1);
            let before = plant.true_state();
            plant.advance(h);
            let after = plant.true_state();
            let q = 0.5 * (before.body_rates.y + after.body_rates.y);
            let p = 0.5 * (before.body_rates.x + after.body_rates.x);
            let dpitch = (after.pitch - before.pitch) / h;
            let droll = (after.roll - before.roll) / h;
            assert!(dpitch < -0.1 && droll > 0.05, "{kind:?}: {dpitch} {droll}");
            // q = cosφ·θ̇ at fixed yaw; p = φ̇.
            assert!(
                (q - before.roll.cos() * dpitch).abs() < 0.05 * dpitch.abs(),
                "{kind:?}: q {q} vs {dpitch}"
            );
            assert!(
                (p - droll).abs() < 0.05 * droll.abs(),
                "{kind:?}: p {p} vs {droll}"
            );
        }
    }

    use proptest::prelude::*;

    proptest! {
        /// The rotor drag is `−d·R·diag(1, 1, 0)·Rᵀ·u` with the full ZYX
        /// rotation (any heading), and the quadratic drag `−c_q·|u|·u`.
        #[test]
        fn aero_acceleration_is_the_body_plane_form(
            roll in -0.6f64..0.6, pitch in -0.6f64..0.6, yaw in -3.1f64..3.1,
            ux in -15.0f64..15.0, uy in -15.0f64..15.0, uz in -5.0f64..5.0,
            c in 0.0f64..0.5, cq in 0.0f64..0.1, d in 0.0f64..0.5,
        ) {
            let options = PlantOptions { drag: c, quadratic_drag: cq, rotor_drag: d,
                ..PlantOptions::default() };
            let u = Vector3::new(ux, uy, uz);
            let r = rotation(roll, pitch, yaw);
            let body_plane = r * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0)) * r.transpose();
            let want = -u * c - u * (cq * u.norm()) - body_plane * u * d;
            let got = aero_acceleration(&options, &u, &thrust_axis(roll, pitch, yaw));
            prop_assert!((got - want).norm() < 1e-9 * (1.0 + want.norm()), "{got} vs {want}");
        }
    }

    /// Each plant flown at a constant pitch θ at constant altitude settles
    /// at the speed where the pull of the tilt meets the aerodynamics. The
    /// rotor drag acts on the velocity's part across the thrust axis,
    /// `v·cosθ·(cosθ, 0, −sinθ)`: with thrust holding the altitude (spatial,
    /// rigid body) its vertical part lowers the thrust, and
    /// `g·tan|θ| = c_q·v² + d·v`; the planar plant's altitude is held
    /// without thrust, so `g·tan|θ| = c_q·v² + d·v·cos²θ`.
    #[test]
    fn the_plants_settle_at_the_aerodynamic_terminal_speed() {
        let (cq, d, pitch) = (0.03, 0.2, -0.25f64);
        let options = PlantOptions {
            quadratic_drag: cq,
            rotor_drag: d,
            ..PlantOptions::default()
        };
        let terminal = |b: f64| {
            let k = options.g * (-pitch).tan();
            (-b + (b * b + 4.0 * cq * k).sqrt()) / (2.0 * cq)
        };
        for kind in [PlantKind::Planar, PlantKind::Spatial, PlantKind::RigidBody] {
            let v_star = match kind {
                PlantKind::Planar => terminal(d * pitch.cos().powi(2)),
                _ => terminal(d),
            };
            let mut plant = build_plant(kind, &options, 1).unwrap();
            plant.reset(&PlantState::hover(Vector3::zeros(), options.g));
            for _ in 0..(60 * 50) {
                // Thrust that holds the altitude against gravity and the
                // vertical part of the aerodynamics, fed back on the climb rate.
                let s = plant.true_state();
                let axis = thrust_axis(s.roll, s.pitch, s.yaw);
                let aero = aero_acceleration(&options, &s.velocity, &axis);
                let thrust = (options.g + aero.z + 2.0 * s.velocity.z) / axis.z;
                plant.apply(&AttitudeCommand {
                    pitch,
                    roll: 0.0,
                    yaw: 0.0,
                    thrust: options.thrust_command_for(thrust),
                });
                plant.advance(0.02);
            }
            let v = plant.velocity();
            assert!(
                (v.x - v_star).abs() < 0.01 * v_star && v.y.abs() < 1e-3 && v.z.abs() < 1e-3,
                "{kind:?}: {v} vs {v_star}"
            );
        }
    }
}
