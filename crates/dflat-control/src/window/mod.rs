//! The window of past data the DF-MPC needs (paper §IV-C, *input-to-output
//! map*), in two forms.
//!
//! # Classic: [`Window`]
//!
//! The last r = 3 measured outputs `y^m_{k−2}, y^m_{k−1}, y^m_k` and the last
//! r − 1 = 2 sent inputs `u_{k−2}, u_{k−1}`, one measurement per control
//! tick (the paper's 50 Hz position stream).
//!
//! Start-up padding, before enough history exists:
//! * outputs: the first measurement fills every slot, i.e. the vehicle is
//!   taken to have been at rest there (`y^m_{k−2} = y^m_{k−1} = y^m_0`);
//! * inputs: every slot holds the hover input given at construction (level
//!   attitude; hover thrust g for the spatial model).
//!
//! So at the first tick the prediction F⁻¹ from the window is "at rest,
//! hovering" and the predicted outputs equal the first measurement.
//!
//! The window's outputs must be one control step apart: F⁻¹ reads the
//! state from their second differences, so a pose entered one slot off
//! reads as a stop or a doubled speed (at 4 m/s, 200 m/s² for one tick).
//! On a real link poses and ticks are not one to one: a tick finds no new
//! pose, a pose arrives a tick late, a starved machine skips ticks while
//! the autopilot holds the last command, a sender's capture times wander.
//! [`Window::place`] therefore puts each pose in its slot *by its time*:
//! the slots lie on a grid one step apart from the first pose's time, and
//! a pose goes to the nearest slot, moved onto the slot's time along the
//! window's velocity (off by at most `a·δt²/8`). A tick without a new pose
//! gets the model's prediction (F⁻¹ with the inputs sent); a pose that
//! lands on a slot already predicted replaces it and the later slots are
//! predicted again from it; skipped ticks are filled with predictions
//! under the held input. The pose after a run of predicted slots corrects
//! them, as one acceleration error from the last measured slot on would
//! have put them off (a slot left 1 mm off reads as a 2.5 m/s² jolt at
//! 50 Hz). The window keeps [`SLOTS`] slots for this. With one pose per
//! tick, on time, it is the paper's window exactly.
//!
//! # Multi-rate: [`MultiRateWindow`]
//!
//! Pose samples at their own, irregular times (vision at 10–35 Hz, with
//! latency, jitter and dropouts) and the inputs at the control rate. The
//! window covers the last M control ticks `s = k − M … k`; the unknowns are
//! the r = 3 outputs at its start, `z = (y_s, y_{s+1}, y_{s+2})` (the flat
//! state there). Every later output of the window follows from z and the
//! inputs already sent, through F⁻¹ (the paper's eq. input_to_output,
//! chained M times):
//!
//! ```text
//! y_{j+3} = F⁻¹(y_j, y_{j+1}, y_{j+2}, u_j),   j = s … k−1   ⇒  y_{s+3} … y_{k+2}
//! ```
//!
//! so the fixed outputs of the optimisation, `y_k, y_{k+1}, y_{k+2}`, come
//! out of the same chain: no extrapolation, and the latency is compensated
//! by the inputs sent since the samples were taken. z is a moving-horizon
//! estimate: the least-squares fit of that chain to the samples in the
//! window plus an arrival cost that carries what the samples before the
//! window said,
//!
//! ```text
//! min_z  Σ_i (y^m_i − ŷ(t_i; z))² / σ²  +  (z − z̄)ᵀ·P⁻¹·(z − z̄)
//! ```
//!
//! * ŷ(t_i; z): a sample at time t_i sits at the fractional tick position
//!   `m_i = M − (t_k − t_i)/δt ∈ [0, M]`; ŷ interpolates linearly between
//!   the two neighbouring tick outputs. Interpolation, not snapping: its
//!   error is at most `|a|·δt²/8` (0.5 mm at 10 m/s²), far below the pose
//!   noise, while snapping to the nearest tick misplaces a sample by up to
//!   δt/2 in time, `v·δt/2` in space (9 cm at 9 m/s).
//! * Linearisation: F⁻¹ sees the outputs only through second differences,
//!   so adding `c + d·j` to every output of a chain gives another chain
//!   (exactly): position and velocity enter linearly. A change h of the
//!   second difference at s is an attitude (thrust) change that the
//!   first-order input dynamics forget at the rate `β = 1 − δt/τ` per tick;
//!   to first order (small tilt) the chain's second differences change by
//!   `β^i·h`, so
//!
//!   ```text
//!   δy_{s+m} = φ(m)·(c, d, h),   φ(m) = (1, m, g_m),   g_m = Σ_{i=0}^{m−2} (m−1−i)·β^i
//!   ```
//!
//!   Per axis this is a 3×3 normal system, O(samples) to build. z is
//!   updated by one Gauss–Newton step per tick about the previous tick's
//!   estimate, and the window is then propagated through the exact
//!   (nonlinear) F⁻¹: the estimate is always a chain of the model, the
//!   linearisation only weighs the samples.
//! * Arrival cost (z̄, P per axis, in (c, d, h)): a Kalman filter on the
//!   window start. When the window moves on by n ticks, the samples that
//!   leave it are absorbed by scalar Kalman updates (`K = Pφ/(φᵀPφ + σ²)`)
//!   at the old start, the mean is carried n ticks along the chain and the
//!   covariance with it, `P ← T_n·P·T_nᵀ + n·Q`,
//!   `T_n = [[1, n, g_n], [0, 1, g_{n+1} − g_n], [0, 0, β^n]]`, Q the
//!   random-walk process noise per step ([`MultiRateSettings::process_sigma`]:
//!   what the model does not explain). Each sample counts once, in the
//!   window or in the arrival cost, so no information is lost when samples
//!   leave, and none is double counted. With no sample in the window (a
//!   dropout) the estimate is the arrival cost carried forward by the sent
//!   inputs (dead reckoning through the model), its covariance growing by Q
//!   per tick, so the first samples after the dropout pull it back in
//!   proportion.
//!
//! With the samples exactly at the ticks s, s+1, s+2 and no arrival cost
//! (`M = 2`, infinite process noise, one sample per tick, no latency) the
//! fit is exact, z = the three measurements, and the window reproduces the
//! classic [`Window`] (to rounding): the paper's DF-MPC is the special case.
//! Start-up: the oldest sample is taken to have been at rest (two padding
//! samples at the same position one and two ticks earlier), the past
//! inputs to have been hover, as in the classic window.
//!
//! Why not join the fit and the optimisation in one QP? Then the plan
//! could bend the estimate of the past to make the future cost lower; the
//! separation is certainty equivalence, and it is exactly what the paper
//! does with r samples (hard equality constraints ⇔ an exact fit).
//!
//! Storage: the trajectory (M + 3 outputs), the inputs (M + 1) and the
//! samples ([`SAMPLE_CAPACITY`]) are sized at construction; a tick
//! allocates nothing. Cost per tick: 2·M + 2·n F⁻¹ steps (n = 1 normally)
//! and O(samples) arithmetic.

mod classic;
mod multi_rate;
pub use classic::{
    INPUTS, MAX_FILL, OUTPUTS, PENDING_INPUTS, Placement, SLOTS, Window, WindowStats,
};

/// What a DF-MPC window did with the poses, by window (the daemon's summary
/// `pose_window`, tagged `"window": "classic"` or `"multi-rate"`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "window", rename_all = "kebab-case")]
pub enum PoseWindowStats {
    /// The paper's window, one pose per tick ([`Window::place`]).
    Classic(WindowStats),
    /// The multi-rate window ([`MultiRateWindow`]).
    MultiRate(MultiRateStats),
}
pub(crate) use multi_rate::input_lags;
pub use multi_rate::{
    MAX_WINDOW, MultiRateEstimate, MultiRateSettings, MultiRateStats, MultiRateWindow, PoseSample,
    SAMPLE_CAPACITY,
};
