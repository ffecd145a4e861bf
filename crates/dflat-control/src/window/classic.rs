//! The classic window (module docs of [`crate::window`], "Classic"): the
//! paper's r = 3 outputs and r − 1 = 2 inputs, each pose placed in its slot
//! by its time ([`Window::place`]).

use dflat_model::FlatError;
use nalgebra::Vector3;

use crate::ControlError;

/// Measured outputs the window hands F⁻¹: r = 3.
pub const OUTPUTS: usize = 3;
/// Sent inputs the window hands F⁻¹: r − 1 = 2.
pub const INPUTS: usize = 2;
/// Slots (ticks) kept: the r = 3 of the window plus the ones a late pose
/// may land in and the later slots be predicted again from (a pose up to
/// `SLOTS − 2` = 6 ticks late is placed).
pub const SLOTS: usize = 8;
/// Skipped ticks [`Window::place`] fills at most (1 s at 50 Hz); a longer
/// gap restarts the window from its padding.
pub const MAX_FILL: usize = 50;
/// Inputs in effect after the last committed tick the window can be told
/// ([`Window::set_pending_inputs`]): 0.5 s at 50 Hz, as the controller's
/// longest input delay.
pub const PENDING_INPUTS: usize = 25;
/// Type of the one-step prediction F⁻¹ the window is given:
/// `y_{j+3} = F⁻¹(y_j, y_{j+1}, y_{j+2}; u_j)`.
type NextOutput<'a> =
    &'a dyn Fn(&[Vector3<f64>; 3], &Vector3<f64>) -> Result<Vector3<f64>, FlatError>;

/// What [`Window::place`] did with this tick's measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// The first measurement since construction or [`Window::reset`] (or a
    /// restart: a gap of more than [`MAX_FILL`] ticks, or a new pose that
    /// lands before the slots kept): the padding; y_k is the measurement.
    Start,
    /// y_k is the measurement: one step after the newest slot, or after
    /// `filled` skipped ticks filled with the model's predictions under the
    /// input the autopilot held.
    Next {
        /// Skipped ticks filled.
        filled: usize,
    },
    /// The pose landed on the slot `back` ticks before this one (1: the
    /// previous tick's), which held a prediction: it replaced it, the
    /// slots after it were predicted again from it, and y_k is predicted.
    Late {
        /// Ticks before this one.
        back: usize,
    },
    /// No new pose (none in a later grid slot than the newest placed): y_k
    /// is the model's prediction, F⁻¹ with the inputs sent.
    Predicted,
}

/// What the window's placement has done since construction (never reset).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WindowStats {
    /// Ticks whose y_k is a prediction ([`Placement::Predicted`] and
    /// [`Placement::Late`]).
    pub predicted: u64,
    /// Skipped ticks filled with predictions.
    pub filled: u64,
    /// Poses placed in an earlier tick's slot ([`Placement::Late`]).
    pub late: u64,
    /// Restarts from the padding after the first start (see
    /// [`Placement::Start`]).
    pub restarts: u64,
}

/// Where [`Window::place`] puts a pose ([`Window::slot_for`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SlotFor {
    /// The padding from the pose (the first, or a restart).
    Start {
        /// A restart (counted).
        restart: bool,
    },
    /// The slot after the newest, `filled` skipped ticks after it.
    Next {
        /// Skipped ticks filled before it.
        filled: usize,
    },
    /// An earlier slot: `idx` in the slots, `back` ticks before the tick's.
    Late {
        /// Index in the slots.
        idx: usize,
        /// Ticks before the tick's slot.
        back: usize,
    },
    /// No new pose: the tick's slot is predicted.
    Predicted,
}

/// The last r measured outputs and r − 1 sent inputs, with start-up
/// padding, and the [`SLOTS`] − r older slots that time placement needs.
///
/// Between ticks (after the input of tick k − 1 is pushed) slot `i` of the
/// outputs and of the inputs belong to the same tick; [`Window::place`]
/// then pushes y_k, and the controller's [`Window::push_input`] pushes u_k.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Outputs of the last [`SLOTS`] ticks, oldest first, positions \[m\] in
    /// the model frame.
    outputs: [Vector3<f64>; SLOTS],
    /// Inputs `[θ_cmd, φ_cmd, T_cmd]` (rad, rad, m/s²) of the last
    /// [`SLOTS`] ticks, oldest first.
    inputs: [Vector3<f64>; SLOTS],
    /// Whether each output slot holds a measurement (or the padding), not a
    /// prediction.
    measured: [bool; SLOTS],
    /// Input used for padding.
    hover: Vector3<f64>,
    /// Outputs pushed since construction or reset (saturating).
    measurements: usize,
    /// Time of the first pose since the start \[s\] (the poses' clock): the
    /// slots lie one step apart from it.
    origin_t: f64,
    /// The newest output slot's index on that grid.
    newest: i64,
    /// Time of the newest pose placed \[s\] (−∞ before one).
    pose_t: f64,
    /// What placement has done.
    stats: WindowStats,
    /// The inputs in effect at the ticks after the last committed one,
    /// oldest first, the last repeated beyond them (an input delay's
    /// pending inputs); none: the last input, held.
    pending: [Vector3<f64>; PENDING_INPUTS],
    /// How many of `pending` hold.
    pending_len: usize,
    /// Slots filled since the last [`Window::push_input`].
    filled_since_input: usize,
}

impl Window {
    /// An empty window padded with `hover` as the past inputs
    /// (`[0, 0, g]`: level attitude, hover specific thrust).
    pub fn new(hover: Vector3<f64>) -> Self {
        Self {
            outputs: [Vector3::zeros(); SLOTS],
            inputs: [hover; SLOTS],
            measured: [true; SLOTS],
            hover,
            measurements: 0,
            origin_t: f64::NEG_INFINITY,
            newest: 0,
            pose_t: f64::NEG_INFINITY,
            stats: WindowStats::default(),
            pending: [hover; PENDING_INPUTS],
            pending_len: 0,
            filled_since_input: 0,
        }
    }

    /// Pushes the newest measured output `y^m_k` \[m\] as the next slot,
    /// without a time (the raw ring operation; the controller uses
    /// [`Window::place`]). The first one after construction or
    /// [`Window::reset`] fills every output slot.
    pub fn push_measurement(&mut self, y: Vector3<f64>) {
        self.push_output(y, true);
    }

    /// Pushes an output slot, measured or predicted.
    fn push_output(&mut self, y: Vector3<f64>, measured: bool) {
        if self.measurements == 0 {
            self.outputs = [y; SLOTS];
            self.measured = [true; SLOTS];
        } else {
            self.outputs.rotate_left(1);
            self.outputs[SLOTS - 1] = y;
            self.measured.rotate_left(1);
            self.measured[SLOTS - 1] = measured;
        }
        self.measurements = self.measurements.saturating_add(1);
    }

    /// Pushes the input `u_k` in effect at the newest tick (the one sent,
    /// or with an input delay the one sent d ticks before); forgets the
    /// pending inputs told ([`Window::set_pending_inputs`]).
    pub fn push_input(&mut self, u: Vector3<f64>) {
        self.push_slot_input(u);
        self.pending_len = 0;
        self.filled_since_input = 0;
    }

    /// Tells the window the inputs in effect at the ticks after the newest
    /// committed one, oldest first, when they are not the last input held:
    /// with an input delay of d ticks, the d inputs sent and not yet in
    /// effect (beyond them the newest repeats, as the autopilot holds it).
    /// Skipped ticks are filled under them; at most [`PENDING_INPUTS`]
    /// are kept. The next [`Window::push_input`] forgets them.
    pub fn set_pending_inputs(&mut self, inputs: &[Vector3<f64>]) {
        let n = inputs.len().min(PENDING_INPUTS);
        self.pending[..n].copy_from_slice(&inputs[..n]);
        self.pending_len = n;
    }

    /// The input slot ring's push.
    fn push_slot_input(&mut self, u: Vector3<f64>) {
        self.inputs.rotate_left(1);
        self.inputs[SLOTS - 1] = u;
    }

    /// Replaces the newest input (the one pushed last) with `u`: the input
    /// actually applied when it differs from the one sent (standby).
    pub fn replace_last_input(&mut self, u: Vector3<f64>) {
        self.inputs[SLOTS - 1] = u;
    }

    /// Forgets all history: the next measurement starts the padding again
    /// (the [`WindowStats`] are kept).
    pub fn reset(&mut self) {
        *self = Self {
            stats: self.stats,
            ..Self::new(self.hover)
        };
    }

    /// Enters tick k's measurement (position `y` \[m\], model frame, taken
    /// at `t` \[s\], the poses' clock) by its time, and pushes y_k: the
    /// measurement, or the model's prediction through `next_output` (F⁻¹,
    /// `y_{j+3} = F⁻¹(y_j, y_{j+1}, y_{j+2}; u_j)`). Call it between ticks
    /// (after the last tick's input was pushed); then [`Window::outputs`]
    /// ends at y_k and [`Window::inputs`] at u_{k−1}.
    ///
    /// The slots lie on a grid one step δt (`dt` \[s\]) apart from the first
    /// pose's time. A new pose (its grid slot, the one nearest its time,
    /// later than the newest placed pose's) goes to that slot, `n = round((t − t_newest)/δt)`
    /// slots from the newest, moved to the slot's time along the window's
    /// velocity there (`y − v̂·(t − t_slot)`: off by `a·δt²/8` at most, where
    /// snapping it would be off by `v·δt/2`):
    /// * `n ≥ 1`: `n − 1` ticks were skipped (the autopilot held the last
    ///   input): each gets F⁻¹'s prediction under that input, then y_k is
    ///   the measurement ([`Placement::Next`]);
    /// * `n ≤ 0`: if that slot holds a prediction, the pose replaces it and
    ///   the slots after it are predicted again ([`Placement::Late`]); y_k
    ///   is predicted. A new pose older than the slots kept, or a gap of
    ///   more than [`MAX_FILL`] ticks, restarts the window
    ///   ([`Placement::Start`]).
    ///
    /// Otherwise (no new pose) y_k is predicted ([`Placement::Predicted`]).
    ///
    /// A pose that lands just after a run of predicted slots (missing
    /// poses, skipped ticks) corrects the run by its innovation, the pose
    /// less the prediction at its slot, as one acceleration error from the
    /// measured slot before the run on would have put the run off
    /// (`correct_predicted_run`).
    /// A non-finite `t` is no new pose. Errors: F⁻¹'s, or a non-finite `t`
    /// or `y` for the first measurement
    /// ([`ControlError::NonFiniteMeasurement`]). On error the window may be
    /// part-changed: the controller places on a copy.
    pub fn place(
        &mut self,
        t: f64,
        y: Vector3<f64>,
        dt: f64,
        next_output: NextOutput<'_>,
    ) -> Result<Placement, ControlError> {
        let origin_t = self.origin_t;
        let slot_time = |i: i64| origin_t + i as f64 * dt;
        // How far the pose is from slot `i`'s time \[s\]: none when on it
        // (then no velocity is needed).
        let off = |i: i64| Some(t - slot_time(i)).filter(|o| o.abs() > 1e-9 * dt);
        let mut placement = Placement::Predicted;
        match self.slot_for(t, dt, self.newest) {
            SlotFor::Start { restart } => return self.start(t, y, restart),
            SlotFor::Next { filled } => {
                self.fill(filled, next_output)?;
                let slot = self.newest + 1;
                let predicted = self.predict_next(next_output)?;
                let onto = match off(slot) {
                    // Moved onto the slot's time along the velocity there.
                    Some(o) => y - (predicted - self.outputs[SLOTS - 1]) * (o / dt),
                    None => y,
                };
                self.correct_predicted_run(SLOTS, onto - predicted);
                self.newest = slot;
                self.push_output(onto, true);
                self.pose_t = t;
                return Ok(Placement::Next { filled });
            }
            SlotFor::Late { idx, back } if !self.measured[idx] => {
                let onto = match off(self.newest + 1 - back as i64) {
                    Some(o) => y - (self.outputs[idx] - self.outputs[idx - 1]) / dt * o,
                    None => y,
                };
                self.correct_predicted_run(idx, onto - self.outputs[idx]);
                self.outputs[idx] = onto;
                self.measured[idx] = true;
                for i in idx + 1..SLOTS {
                    if !self.measured[i] {
                        self.outputs[i] = self.predict_at(i, next_output)?;
                    }
                }
                self.pose_t = t;
                self.stats.late += 1;
                placement = Placement::Late { back };
            }
            SlotFor::Late { .. } | SlotFor::Predicted => {}
        }
        let p = self.predict_next(next_output)?;
        self.push_output(p, false);
        self.newest += 1;
        self.stats.predicted += 1;
        Ok(placement)
    }

    /// The time \[s\] of the slot that [`Window::place`] of a pose taken at
    /// `t` \[s\], after `skipped` ticks the shell said
    /// ([`Window::fill_skipped`]), makes the tick's, without placing it:
    /// the grid slot of a new pose, or the slot after the newest; `t`
    /// where the place starts the window (the first measurement, a
    /// restart). The controller's tick time, for the reference.
    pub fn tick_time(&self, t: f64, dt: f64, skipped: usize) -> f64 {
        if skipped > MAX_FILL {
            return t;
        }
        let newest = self.newest + skipped as i64;
        let slot_time = |i: i64| self.origin_t + i as f64 * dt;
        match self.slot_for(t, dt, newest) {
            SlotFor::Start { .. } => t,
            SlotFor::Next { filled } => slot_time(newest + filled as i64 + 1),
            SlotFor::Late { .. } | SlotFor::Predicted => slot_time(newest + 1),
        }
    }

    /// Where [`Window::place`] puts a pose taken at `t` \[s\] with the
    /// newest slot `newest`: the rules of its docs, decided once for the
    /// place itself and for [`Window::tick_time`].
    fn slot_for(&self, t: f64, dt: f64, newest: i64) -> SlotFor {
        if self.measurements == 0 {
            return SlotFor::Start { restart: false };
        }
        // New: in a later grid slot than the newest pose placed. (Half a
        // step newer, as before, dropped the next pose after one stamped
        // late: a pose at k + 0.4 δt, then one at k + 0.8 δt.)
        let slot_of = |x: f64| ((x - self.origin_t) / dt).round();
        if !(t.is_finite() && slot_of(t) > slot_of(self.pose_t)) {
            return SlotFor::Predicted;
        }
        let n = ((t - (self.origin_t + newest as f64 * dt)) / dt).round();
        if n >= 1.0 {
            let filled = n as usize - 1;
            return if filled > MAX_FILL {
                SlotFor::Start { restart: true }
            } else {
                SlotFor::Next { filled }
            };
        }
        // Slot `idx` (newest = SLOTS − 1); re-predicting the slots after
        // it needs three before each.
        let back = (-n) as usize + 1;
        match SLOTS.checked_sub(back).filter(|i| *i >= 2) {
            Some(idx) => SlotFor::Late { idx, back },
            None => SlotFor::Start { restart: true },
        }
    }

    /// The shell skipped `ticks` ticks (its loop stalled; the autopilot
    /// held the last input), known from its clock rather than a pose's
    /// time: each gets F⁻¹'s prediction under the held input, as skipped
    /// ticks found by [`Window::place`] do, and the next `place` is the
    /// tick after them (so a tick after them without a new pose is
    /// predicted at its own slot). Returns the slots filled. More than
    /// [`MAX_FILL`] restarts the window (the next `place` starts it from
    /// its pose); nothing before the first measurement. On error the
    /// window may be part-changed: the controller fills a copy.
    pub fn fill_skipped(
        &mut self,
        ticks: usize,
        next_output: NextOutput<'_>,
    ) -> Result<usize, ControlError> {
        if self.measurements == 0 || ticks == 0 {
            return Ok(0);
        }
        if ticks > MAX_FILL {
            self.reset();
            self.stats.restarts += 1;
            return Ok(0);
        }
        self.fill(ticks, next_output)?;
        Ok(ticks)
    }

    /// A pose has come for slot `at` (0 ..= [`SLOTS`]; `SLOTS` is the slot
    /// after the newest), `innovation` \[m\] from the prediction there: the
    /// run of predicted slots just before it, back to a measured slot, is
    /// moved towards the pose as one acceleration error from that slot on
    /// would have moved it. Predicted j slots after the measured one, such
    /// an error δa has put the prediction off by `j(j+1)/2·δa·δt²`; the run
    /// of m slots and the pose (j = m + 1) share it, slot j taking
    /// `j(j+1)/((m+1)(m+2))` of the innovation. Left as predicted, a slot
    /// off by e reads, between the two measured slots, as accelerations
    /// e/δt² and −2e/δt² (at 50 Hz, 1 mm as 2.5 and −5 m/s²), and a
    /// command made from them is what the next prediction misses by: a
    /// pose missing every other tick grew that to metres
    /// (`classic_window_timing.rs`). The slots stay predictions (a late
    /// pose may still replace them); nothing moves without a measured slot
    /// before the run.
    fn correct_predicted_run(&mut self, at: usize, innovation: Vector3<f64>) {
        let run = self.measured[..at]
            .iter()
            .rev()
            .take_while(|m| !**m)
            .count();
        if run == 0 || run == at || !innovation.iter().all(|v| v.is_finite()) {
            return;
        }
        let whole = ((run + 1) * (run + 2)) as f64;
        for j in 1..=run {
            let share = (j * (j + 1)) as f64 / whole;
            self.outputs[at - run - 1 + j] += innovation * share;
        }
    }

    /// `n` skipped ticks after the newest slot: F⁻¹'s predictions under the
    /// input held (or the pending inputs told), the newest slot moved on
    /// by `n`.
    fn fill(&mut self, n: usize, next_output: NextOutput<'_>) -> Result<(), FlatError> {
        for _ in 0..n {
            self.filled_since_input += 1;
            let held = match self.pending_len {
                0 => self.inputs[SLOTS - 1],
                len => self.pending[self.filled_since_input.min(len) - 1],
            };
            let p = self.predict_next(next_output)?;
            self.push_output(p, false);
            self.push_slot_input(held);
        }
        self.newest += n as i64;
        self.stats.filled += n as u64;
        Ok(())
    }

    /// The padding from measurement `y` at `t`; `restart` counts it.
    fn start(&mut self, t: f64, y: Vector3<f64>, restart: bool) -> Result<Placement, ControlError> {
        if !(t.is_finite() && y.iter().all(|v| v.is_finite())) {
            return Err(ControlError::NonFiniteMeasurement);
        }
        self.reset();
        self.push_output(y, true);
        self.origin_t = t;
        self.newest = 0;
        self.pose_t = t;
        if restart {
            self.stats.restarts += 1;
        }
        Ok(Placement::Start)
    }

    /// F⁻¹ over the newest three slots with the input of the oldest of
    /// them: the output of the slot after the newest.
    fn predict_next(&self, next_output: NextOutput<'_>) -> Result<Vector3<f64>, FlatError> {
        self.predict_at(SLOTS, next_output)
    }

    /// F⁻¹ over the three slots before slot `i` (3 ..= [`SLOTS`]; `SLOTS`
    /// is the slot after the newest) with the input of the oldest of them.
    fn predict_at(&self, i: usize, next_output: NextOutput<'_>) -> Result<Vector3<f64>, FlatError> {
        let before: &[Vector3<f64>; 3] = self.outputs[i - 3..i].try_into().expect("three slots");
        next_output(before, &self.inputs[i - 3])
    }

    /// Measured outputs `[y^m_{k−2}, y^m_{k−1}, y^m_k]`, oldest first (some
    /// may be predictions: see [`Window::place`]).
    pub fn outputs(&self) -> &[Vector3<f64>; OUTPUTS] {
        self.outputs.last_chunk().expect("SLOTS ≥ OUTPUTS")
    }

    /// Every output slot kept, oldest first \[m\] (the last [`OUTPUTS`] are
    /// [`Window::outputs`]).
    pub fn slot_outputs(&self) -> &[Vector3<f64>; SLOTS] {
        &self.outputs
    }

    /// Every input slot kept, oldest first (`[θ_cmd, φ_cmd, T_cmd]`; the
    /// last [`INPUTS`] are [`Window::inputs`]): the input in effect at
    /// each slot's tick, the output slots' one tick behind after a
    /// [`Window::place`].
    pub fn slot_inputs(&self) -> &[Vector3<f64>; SLOTS] {
        &self.inputs
    }

    /// Sent inputs `[u_{k−2}, u_{k−1}]`, oldest first.
    pub fn inputs(&self) -> &[Vector3<f64>; INPUTS] {
        self.inputs.last_chunk().expect("SLOTS ≥ INPUTS")
    }

    /// Newest output `y_k`.
    pub fn latest(&self) -> &Vector3<f64> {
        &self.outputs[SLOTS - 1]
    }

    /// Number of outputs pushed since construction or reset (saturates).
    pub fn measurements(&self) -> usize {
        self.measurements
    }

    /// True until the first measurement.
    pub fn is_empty(&self) -> bool {
        self.measurements == 0
    }

    /// True once r outputs fill the output slots (no padding left).
    pub fn is_full(&self) -> bool {
        self.measurements >= OUTPUTS
    }

    /// Time of the newest pose placed \[s\] (−∞ before one).
    pub fn pose_time(&self) -> f64 {
        self.pose_t
    }

    /// What placement has done since construction.
    pub fn stats(&self) -> WindowStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64) -> Vector3<f64> {
        Vector3::new(x, 0.0, 0.0)
    }

    #[test]
    fn pads_then_shifts() {
        let hover = Vector3::new(0.0, 0.0, 9.81);
        let mut w = Window::new(hover);
        assert!(w.is_empty());
        w.push_measurement(v(1.0));
        assert_eq!(w.outputs(), &[v(1.0), v(1.0), v(1.0)]);
        assert_eq!(w.inputs(), &[hover, hover]);
        w.push_input(v(0.1));
        w.push_measurement(v(2.0));
        assert_eq!(w.outputs(), &[v(1.0), v(1.0), v(2.0)]);
        assert_eq!(w.inputs(), &[hover, v(0.1)]);
        assert!(!w.is_full());
        w.push_input(v(0.2));
        w.push_measurement(v(3.0));
        w.push_input(v(0.3));
        assert!(w.is_full());
        assert_eq!(w.outputs(), &[v(1.0), v(2.0), v(3.0)]);
        assert_eq!(w.inputs(), &[v(0.2), v(0.3)]);
        assert_eq!(w.latest(), &v(3.0));
        w.reset();
        assert!(w.is_empty());
        w.push_measurement(v(5.0));
        assert_eq!(w.outputs(), &[v(5.0); 3]);
        assert_eq!(w.inputs(), &[hover, hover]);
    }

    const DT: f64 = 0.02;

    /// A double integrator on x: `y_{j+3} = 2y_{j+2} − y_{j+1} + u_j·δt²`
    /// (u's x the acceleration).
    fn integrator(y: &[Vector3<f64>; 3], u: &Vector3<f64>) -> Result<Vector3<f64>, FlatError> {
        Ok(y[2] * 2.0 - y[1] + u * DT * DT)
    }

    /// A window that has seen ticks 0..=k of a vehicle at 4 m/s along x
    /// (poses on time, zero input): the committed state after tick k.
    fn cruising(k: usize) -> Window {
        let mut w = Window::new(Vector3::zeros());
        for j in 0..=k {
            let t = j as f64 * DT;
            w.place(t, v(4.0 * t), DT, &integrator).unwrap();
            w.push_input(Vector3::zeros());
        }
        w
    }

    /// Differences of the window's outputs over one step [m/s].
    fn speeds(w: &Window) -> [f64; 2] {
        let [a, b, c] = *w.outputs();
        [(b.x - a.x) / DT, (c.x - b.x) / DT]
    }

    proptest::proptest! {
        /// The tick time told before a place is the time of the slot the
        /// place makes the tick's (or of the pose it starts from), through
        /// any mix of poses on time, late, early, missing, after skipped
        /// ticks said and unsaid, and gaps that restart the window.
        #[test]
        fn the_tick_time_told_is_the_slot_placed(
            ticks in proptest::collection::vec((0usize..3, -3.4f64..3.4, proptest::bool::ANY), 1..60),
            gap in proptest::option::of(40usize..70),
        ) {
            let mut w = cruising(3);
            let mut tick = 3.0;
            for (i, (skipped, offset, pose)) in ticks.into_iter().enumerate() {
                let skipped = if Some(i) == gap.map(|_| 5) { gap.unwrap() } else { skipped };
                tick += 1.0 + skipped as f64;
                let t = if pose { (tick + offset) * DT } else { w.pose_time() };
                let told = w.tick_time(t, DT, skipped);
                w.fill_skipped(skipped, &integrator).unwrap();
                w.place(t, v(4.0 * t), DT, &integrator).unwrap();
                let placed = w.origin_t + w.newest as f64 * DT;
                proptest::prop_assert!((told - placed).abs() < 1e-12, "{} {}", told, placed);
                w.push_input(Vector3::zeros());
            }
        }
    }

    proptest::proptest! {
        /// Predicted slots (ticks without a new pose, or skipped ticks)
        /// under inputs off the truth by a constant δa: the pose after
        /// them puts every one of them on the true path, as if measured.
        #[test]
        fn the_pose_after_predicted_slots_corrects_them(
            run in 1usize..6,
            sent in -5.0f64..5.0,
            error in -3.0f64..3.0,
            skipped in proptest::bool::ANY,
        ) {
            // The truth under the inputs applied: 0 up to tick 5 (the
            // cruise), `sent + error` from tick 6 on; F⁻¹ is given `sent`.
            let applied = |j: usize| if j <= 5 { 0.0 } else { sent + error };
            let mut truth = vec![0.0; 0];
            for n in 0..=9 + run {
                truth.push(match n {
                    0..=5 => 4.0 * n as f64 * DT,
                    _ => 2.0 * truth[n - 1] - truth[n - 2] + applied(n - 3) * DT * DT,
                });
            }
            let mut w = cruising(5);
            for (n, y) in truth.iter().enumerate().take(9).skip(6) {
                w.place(n as f64 * DT, v(*y), DT, &integrator).unwrap();
                w.push_input(v(sent));
            }
            if skipped {
                w.fill_skipped(run, &integrator).unwrap();
            } else {
                for _ in 0..run {
                    w.place(8.0 * DT, v(truth[8]), DT, &integrator).unwrap();
                    w.push_input(v(sent));
                }
            }
            let n = 9 + run;
            w.place(n as f64 * DT, v(truth[n]), DT, &integrator).unwrap();
            for (i, y) in w.slot_outputs().iter().enumerate() {
                let want = truth[n + 1 + i - SLOTS];
                proptest::prop_assert!((y.x - want).abs() < 1e-12, "slot {}: {} against {}", i, y.x, want);
            }
        }
    }

    #[test]
    fn poses_on_time_are_the_papers_window() {
        let mut w = cruising(5);
        let p = w
            .place(6.0 * DT, v(4.0 * 6.0 * DT), DT, &integrator)
            .unwrap();
        assert_eq!(p, Placement::Next { filled: 0 });
        assert_eq!(w.latest(), &v(0.48));
        assert!(w.stats() == WindowStats::default());
    }

    #[test]
    fn a_tick_without_a_new_pose_is_predicted() {
        let mut w = cruising(5);
        // The tick-5 pose again, with its own time.
        let p = w.place(5.0 * DT, v(0.4), DT, &integrator).unwrap();
        assert_eq!(p, Placement::Predicted);
        for s in speeds(&w) {
            assert!((s - 4.0).abs() < 1e-9, "{s}");
        }
    }

    #[test]
    fn skipped_ticks_are_filled_under_the_held_input() {
        let mut w = cruising(5);
        w.replace_last_input(v(1.0)); // tick 5 sent 1 m/s², held over 6, 7
        // Ticks 6 and 7 skipped: the pose of tick 8 (the true path under
        // the held input: the input acts from slot j + 3 on).
        let p = w.place(8.0 * DT, v(0.6404), DT, &integrator).unwrap();
        assert_eq!(p, Placement::Next { filled: 2 });
        assert_eq!(w.inputs(), &[v(1.0), v(1.0)]);
        assert_eq!(w.stats().filled, 2);
        // The fills sit at the vehicle's speed, not at a third of it.
        let [a, b, _] = *w.outputs();
        assert!(((b.x - a.x) / DT - 4.0).abs() < 1e-9);
    }

    #[test]
    fn a_late_pose_replaces_its_prediction_and_the_window_stays_one_step_apart() {
        let mut w = cruising(5);
        // Tick 6 finds no new pose: predicted at 0.48 m.
        w.place(5.0 * DT, v(0.4), DT, &integrator).unwrap();
        w.push_input(Vector3::zeros());
        // Tick 7 gets the pose of tick 6 (late), 1 cm off the prediction:
        // it takes tick 6's slot, and tick 7 is predicted from it.
        let p = w.place(6.0 * DT, v(0.49), DT, &integrator).unwrap();
        assert_eq!(p, Placement::Late { back: 1 });
        let [a, b, c] = *w.outputs();
        assert_eq!((a, b), (v(0.4), v(0.49)));
        assert!((c.x - 0.58).abs() < 1e-12, "{c}");
        // Tick 8 gets its own pose on time: the next slot.
        w.push_input(Vector3::zeros());
        let p = w.place(8.0 * DT, v(0.64), DT, &integrator).unwrap();
        assert_eq!(p, Placement::Next { filled: 0 });
        assert_eq!(w.stats().late, 1);
    }

    #[test]
    fn a_stream_one_tick_late_for_good_is_placed_every_tick() {
        let mut w = cruising(5);
        w.place(5.0 * DT, v(0.4), DT, &integrator).unwrap();
        w.push_input(Vector3::zeros());
        for k in 7..20 {
            let t = (k - 1) as f64 * DT;
            let p = w.place(t, v(4.0 * t), DT, &integrator).unwrap();
            assert_eq!(p, Placement::Late { back: 1 }, "tick {k}");
            w.push_input(Vector3::zeros());
            for s in speeds(&w) {
                assert!((s - 4.0).abs() < 1e-9, "tick {k}: {s}");
            }
        }
    }

    #[test]
    fn poses_off_their_slot_times_are_moved_onto_them() {
        // Capture times up to ±0.45 δt off the grid (a starved sender) and
        // a 60 Hz stream: the window stays on the 4 m/s line at its slots.
        for (name, times) in [
            (
                "jittered",
                (6..40)
                    .map(|k| (k as f64 + 0.45 * ((k * 7 % 5) as f64 / 2.0 - 1.0)) * DT)
                    .collect::<Vec<_>>(),
            ),
            (
                "60 Hz",
                (0..40).map(|k| 0.12 + k as f64 / 60.0 + 0.001).collect(),
            ),
        ] {
            let mut w = cruising(5);
            for (tick, t) in times.into_iter().enumerate() {
                w.place(t, v(4.0 * t), DT, &integrator).unwrap();
                w.push_input(Vector3::zeros());
                for s in speeds(&w) {
                    assert!((s - 4.0).abs() < 1e-9, "{name}, tick {tick}: {s}");
                }
            }
        }
    }

    #[test]
    fn the_pose_after_one_stamped_late_is_new() {
        // Tick 6's pose stamped 0.4 δt late (its slot, 6), tick 7's 0.2 δt
        // early: 0.4 δt apart, but in slot 7. It is placed there, not
        // dropped for a prediction.
        let mut w = cruising(5);
        w.place(6.4 * DT, v(4.0 * 6.4 * DT), DT, &integrator)
            .unwrap();
        w.push_input(Vector3::zeros());
        let p = w
            .place(6.8 * DT, v(4.0 * 6.8 * DT), DT, &integrator)
            .unwrap();
        assert_eq!(p, Placement::Next { filled: 0 });
        assert_eq!(w.stats().predicted, 0);
        for s in speeds(&w) {
            assert!((s - 4.0).abs() < 1e-9, "{s}");
        }
        // A second pose in the newest pose's slot is not new.
        w.push_input(Vector3::zeros());
        let p = w
            .place(7.2 * DT, v(4.0 * 7.2 * DT), DT, &integrator)
            .unwrap();
        assert_eq!(p, Placement::Predicted);
    }

    #[test]
    fn repeated_and_older_poses_change_nothing_but_the_prediction() {
        let mut w = cruising(5);
        for t in [5.0 * DT, 4.0 * DT, 5.3 * DT, f64::NAN, f64::NEG_INFINITY] {
            let p = w.place(t, v(99.0), DT, &integrator).unwrap();
            assert_eq!(p, Placement::Predicted, "t {t}");
            w.push_input(Vector3::zeros());
            assert!(w.outputs().iter().all(|y| y.x < 1.0));
        }
    }

    #[test]
    fn a_long_gap_or_a_pose_behind_the_slots_restarts_the_padding() {
        let mut w = cruising(5);
        let t = 5.0 * DT + (MAX_FILL + 2) as f64 * DT;
        assert_eq!(
            w.place(t, v(7.0), DT, &integrator).unwrap(),
            Placement::Start
        );
        assert_eq!(w.outputs(), &[v(7.0); 3]);
        let mut w = cruising(5);
        for _ in 0..8 {
            w.place(5.0 * DT, v(0.4), DT, &integrator).unwrap();
            w.push_input(Vector3::zeros());
        }
        // Eight predicted ticks; a new pose seven slots back.
        assert_eq!(
            w.place(6.0 * DT, v(0.48), DT, &integrator).unwrap(),
            Placement::Start
        );
        assert_eq!(w.stats().restarts, 1);
        let mut w = Window::new(Vector3::zeros());
        assert!(matches!(
            w.place(f64::NAN, v(0.0), DT, &integrator),
            Err(ControlError::NonFiniteMeasurement)
        ));
        assert!(w.is_empty());
    }
}
