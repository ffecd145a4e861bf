//! # dflat-control — window, reference and the flatness-based controllers
//!
//! Pure: no I/O, no clock, no threads, deterministic; time enters as
//! arguments. One flow, one direction:
//!
//! ```text
//! pose → window → predict (F⁻¹) → reference → optimize → map (F) → saturate → command
//! ```
//!
//! * [`window::Window`] — the last R measured outputs and R−1 sent inputs;
//!   [`window::MultiRateWindow`] — timestamped pose samples at their own
//!   rate (vision, with latency and dropouts) fitted through the sent
//!   inputs (multi-rate mode, see [`Controller`]).
//! * [`reference::Reference`] — a fixed setpoint or a path with a speed.
//! * [`dfmpc::DfMpc`] — the discrete-flatness MPC of the paper (§V).
//! * [`fmpc::FlatnessMpc`] and [`pd::Pd`] — the paper's baselines.
//! * [`estimator::StateEstimator`] — the baselines' state estimator: a
//!   white-noise-on-jerk Kalman filter over timestamped poses, predicted
//!   to the tick through the sent inputs.
//! * [`disturbance::DisturbanceEstimator`] — acceleration-offset and
//!   thrust-scale estimation for offset-free DF-MPC (optional).
//! * [`learned::LearnedResidual`] — the flat maps' residual learned from
//!   flight records (`dflat learn`): the acceleration the parametric model
//!   does not explain, faded outside the support of its data.
//!
//! All three implement [`Controller`], so shells choose one by configuration.
//! Positions are local NED \[m\]; angles ZYX \[rad\]; thrust is specific
//! collective thrust [m/s²] (thrust / mass).

pub mod dfmpc;
pub mod disturbance;
pub mod estimator;
pub mod fmpc;
pub mod learned;
pub mod limits;
pub mod model;
pub mod optimise;
pub mod pd;
pub mod reference;
pub mod tilt;
pub mod window;

pub use limits::Limit;
pub use model::ControlModel;
pub use tilt::{TiltLimit, limit_tilt};

use nalgebra::Vector3;
use thiserror::Error;

pub use dflat_model::{FlatError, Frame};

/// One pose measurement as the controller sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Time of the measurement \[s\] (the shell's clock; only differences matter).
    pub t: f64,
    /// Position, local NED \[m\] (z unused by planar models).
    pub position: Vector3<f64>,
    /// Yaw ψ \[rad\].
    pub yaw: f64,
}

/// The attitude and thrust command for the autopilot at one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeCommand {
    /// Pitch θ \[rad\], ZYX, FRD (nose down negative).
    pub pitch: f64,
    /// Roll φ \[rad\], ZYX, FRD (right wing down positive).
    pub roll: f64,
    /// Yaw ψ \[rad\].
    pub yaw: f64,
    /// Specific collective thrust [m/s²]; the planar model commands hover (g).
    pub thrust: f64,
}

impl AttitudeCommand {
    /// True when every field is finite.
    pub fn is_finite(&self) -> bool {
        self.pitch.is_finite()
            && self.roll.is_finite()
            && self.yaw.is_finite()
            && self.thrust.is_finite()
    }
}

/// What a controller produced at one tick, for the shell to send and log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickOutput {
    /// The (saturated) command to send.
    pub command: AttitudeCommand,
    /// The planned outputs y*_k … y*_{k+3} (NED m); baselines fill their
    /// own prediction where they have one, else the measurement.
    pub plan: [Vector3<f64>; 4],
    /// The reference at the tick y_ref,k (NED m).
    pub reference: Vector3<f64>,
    /// True when the command was clipped by input saturation.
    pub saturated: bool,
    /// True when a bound was violated by the unconstrained plan and the
    /// inequality-constrained QP was solved.
    pub constrained: bool,
    /// True when the banded solvers of a constrained cascade did not
    /// converge on some axis (or the cone pair) and clarabel, the last of
    /// the cascade, solved it instead (DF-MPC with `QpSolver::Banded`; see
    /// `optimise::Cascade`).
    pub qp_fallback: bool,
    /// True when a cascade's first solver did not converge and a banded
    /// interior point solved instead: the cone's or the box's augmented
    /// Lagrangian falling back (the name predates the box's; see
    /// `optimise::Cascade`).
    pub cone_interior_point: bool,
}

/// Why a controller tick failed. The shell decides what to do (hold the
/// previous plan, level hover, failsafe); the controller never emits NaN.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ControlError {
    /// A flatness map was singular or got invalid data.
    #[error("flat map: {0}")]
    Flat(#[from] FlatError),
    /// The measurement holds NaN or infinite values.
    #[error("non-finite measurement")]
    NonFiniteMeasurement,
    /// Multi-rate mode: no pose sample has been observed yet.
    #[error("no pose sample yet")]
    NoMeasurement,
    /// The reference holds NaN or infinite values.
    #[error("non-finite reference")]
    NonFiniteReference,
    /// The constrained QP did not solve: the method that failed last
    /// (`None` where the solver's caller names it) and why.
    #[error("QP solver failed: {}{fault}", method.map_or(String::new(), |m| format!("{m}: ")))]
    Solver {
        /// The cascade's last method (`None` inside a solver).
        method: Option<optimise::SolverMethod>,
        /// Why it gave no plan.
        fault: optimise::SolverFault,
    },
    /// The banded system was not positive definite (bad weights).
    #[error("banded Cholesky failed: matrix not positive definite")]
    NotPositiveDefinite,
    /// Settings out of range; names the field.
    #[error("invalid setting {field}: {reason}")]
    InvalidSetting {
        /// The field name.
        field: &'static str,
        /// What is allowed.
        reason: String,
    },
}

/// One interface for DF-MPC, Flatness MPC and PD.
///
/// Two ways to feed poses, chosen by the controller ([`Controller::multi_rate`]):
///
/// * **classic** (every controller): once per control step δt the shell
///   calls [`Controller::update`] with the newest pose at or before the tick
///   (the paper's 50 Hz stream, or vision extrapolated to the tick);
/// * **multi-rate** (DF-MPC with `multi_rate` settings): the shell calls
///   [`Controller::observe`] for every new pose sample, stamped with its
///   measurement (capture) time, as it arrives; then, once per control
///   step, [`Controller::update`] with `measurement.t` = the tick time (same
///   clock as the samples). The tick's `position` is not used then (the
///   samples are); `yaw` must be finite.
///
/// A shell may always call `observe`: controllers without multi-rate
/// support ignore it.
pub trait Controller: Send {
    /// Short name for logs and plots ("df-mpc", "fmpc", "pd").
    fn name(&self) -> &'static str;
    /// True when the controller consumes timestamped samples through
    /// [`Controller::observe`] and takes only the tick time from
    /// [`Controller::update`]'s measurement. Default false.
    fn multi_rate(&self) -> bool {
        false
    }
    /// What DF-MPC's window did with the poses since it was built: the
    /// classic window's time placement ([`window::Window::place`]: ticks
    /// predicted, skipped ticks filled, late poses placed, restarts) or the
    /// multi-rate window's counts ([`window::MultiRateStats`]: poses taken
    /// and refused, ticks with no pose in the window); `None` for other
    /// controllers. Default `None`.
    fn window_stats(&self) -> Option<window::PoseWindowStats> {
        None
    }
    /// A raw pose sample at its measurement time `sample.t` \[s\] (multi-rate
    /// mode; see the trait docs). Bad or stale samples are dropped. Default:
    /// ignored.
    fn observe(&mut self, sample: &Measurement) {
        let _ = sample;
    }
    /// The shell skipped `ticks` control ticks since the last
    /// [`Controller::update`] (its loop stalled; the autopilot held the
    /// last command). A controller that takes the tick's time from its
    /// poses (finite differences, the classic window) counts them into the
    /// next update, so a tick after them without a new pose is at its own
    /// time, not a step after the last. Multi-rate controllers take the
    /// tick time from the update itself. Default: ignored.
    fn skipped(&mut self, ticks: u32) {
        let _ = ticks;
    }
    /// The time \[s\] (the poses' clock) that [`Controller::update`] with
    /// `measurement` will take its tick to be, without updating: the shell
    /// sets a trajectory reference (a route, a stream) to it, so the plan
    /// and the state are at one time. Multi-rate: `measurement.t`, the
    /// tick time; a controller that takes its clock from the poses: the
    /// tick a step after its last (plus the ticks skipped), or the grid
    /// time of a new pose — on a tick without a new pose, a step after
    /// the pose's time, not the pose's. Default: `measurement.t`.
    fn tick_time(&self, measurement: &Measurement) -> f64 {
        measurement.t
    }
    /// One control tick at control step δt: takes the newest measurement
    /// (at or before the tick; in multi-rate mode the tick time) and the
    /// reference, returns the command and records it as sent. On error
    /// nothing is recorded.
    fn update(
        &mut self,
        measurement: &Measurement,
        reference: &mut dyn ReferenceSource,
    ) -> Result<TickOutput, ControlError>;
    /// Forgets all history (window, estimates); the next update starts as
    /// the first one did.
    fn reset(&mut self);
    /// The command for a tick whose [`Controller::update`] failed, or whose
    /// result came too late to send: the last good plan shifted one step
    /// per tick since it (step s = 1, 2, … ≤ `max_steps`; a skipped tick
    /// counts), mapped
    /// to an input and saturated as `update` does, and recorded with
    /// `measurement` as this tick's (so the window stays consistent and
    /// the controller resumes cleanly). After a late `update` the plan is
    /// that update's own, so the call skips the step that was missed.
    ///
    /// `None` when there is no plan to fly — none yet, used up, `max_steps`
    /// reached, or a controller without one (PD, Flatness MPC: the
    /// default). The shell then sends its own fallback (held command, level
    /// hover); DF-MPC restarts its window at the next `update`, since it
    /// cannot know what was sent.
    fn plan_fallback(&mut self, measurement: &Measurement, max_steps: usize) -> Option<TickOutput> {
        let _ = (measurement, max_steps);
        None
    }
    /// Standby: the command this controller produced last (its last
    /// [`Controller::update`] or [`Controller::plan_fallback`]) was not
    /// what the autopilot applied — it flew its own position mode — and
    /// `applied` `[θ_cmd, φ_cmd, T_cmd]` (model input units: rad, rad,
    /// specific thrust m/s²) is the input that explains what the vehicle
    /// did (from its measured attitude, [`ControlModel::input_from_attitude`]).
    /// Replaces the recorded input, so the window stays true. Non-finite
    /// values are ignored. Default: nothing (controllers without a window
    /// of inputs).
    fn correct_last_input(&mut self, applied: &Vector3<f64>) {
        let _ = applied;
    }
    /// The disturbance estimate for logs and telemetry, when the controller
    /// runs an estimator ([`disturbance`]); `None` otherwise (the default).
    fn disturbance(&self) -> Option<disturbance::DisturbanceReport> {
        None
    }
    /// The learned residual's state ([`learned::LearnedStatus`]: acting, or
    /// faded and why) when the controller flies one; `None` otherwise (the
    /// default).
    fn learned_status(&self) -> Option<learned::LearnedStatus> {
        None
    }
}

/// A source of reference positions over a horizon.
pub trait ReferenceSource {
    /// Fills `out[j]` with the reference position at tick k+j, j = 0..out.len(),
    /// given the measured position at tick k and the control step δt \[s\].
    fn horizon(&mut self, measured: &Vector3<f64>, dt: f64, out: &mut [Vector3<f64>]);
    /// Closest reference point to `measured` and the reference velocity
    /// there [m/s] (for non-predictive controllers).
    fn closest(&mut self, measured: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>);
    /// Whether the horizon is a trajectory the vehicle can fly as it is
    /// (continuous acceleration: a planner's stream). DF-MPC then weighs
    /// the plan's jerk and command changes against the reference's own
    /// ([`optimise::feed_forward`]), not against zero. Default: no.
    fn flyable(&self) -> bool {
        false
    }
    /// For a path flown by closest point: the highest reference speed
    /// [m/s] at the current progress with which a vehicle braking and
    /// turning at `acceleration` [m/s²] rounds each corner within an arc
    /// whose tangent points lie `radius` \[m\] from the waypoint and stops
    /// at the end (PX4's mission corners), and that speed profile's rate
    /// of change there [m/s²] (the along-path feed-forward). `None`: no
    /// such limit (not a path, or the reference's own profile already
    /// accounts for it). Default: `None`.
    fn corner_speed(&self, _radius: f64, _acceleration: f64) -> Option<(f64, f64)> {
        None
    }
}
