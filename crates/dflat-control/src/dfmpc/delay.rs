//! A pure input delay of d ticks (`DfMpcSettings::delay_ticks`).
//!
//! The vehicle applies the input sent at tick k at tick k + d. The
//! controller keeps the d inputs sent and not yet in effect; the window
//! (and the disturbance estimator) record the input *in effect* at each
//! tick, the one sent d ticks earlier. At tick k the fixed outputs
//! y_k, y_{k+1}, y_{k+2} come from the window as without delay; F⁻¹ then
//! carries them across the pending inputs,
//!
//! ```text
//! y_{k+3+i} = F⁻¹(y_{k+i}, y_{k+i+1}, y_{k+i+2}, u_{k+i−d}),   i = 0 … d−1
//! ```
//!
//! and the optimisation plans from `y_{k+d}, y_{k+d+1}, y_{k+d+2}`: its
//! first input F(y*_{k+d}..y*_{k+d+3}) is the one that takes effect at
//! k + d, and is sent now. With d = 0 nothing changes.

use nalgebra::Vector3;

use dflat_model::FlatError;

use crate::ControlError;

/// Most ticks of delay: 0.5 s at 50 Hz.
pub const MAX_DELAY_TICKS: usize = 25;

/// The inputs sent and not yet in effect, oldest first (a fixed ring; no
/// allocation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct DelayLine {
    pending: [Vector3<f64>; MAX_DELAY_TICKS],
    head: usize,
    len: usize,
}

impl DelayLine {
    /// `d` ticks of delay, the pending inputs all `fill`.
    pub fn new(d: usize, fill: Vector3<f64>) -> Self {
        let mut line = Self {
            pending: [fill; MAX_DELAY_TICKS],
            head: 0,
            len: d.min(MAX_DELAY_TICKS),
        };
        line.fill(fill);
        line
    }

    /// Sets every pending input to `u`.
    pub fn fill(&mut self, u: Vector3<f64>) {
        self.pending = [u; MAX_DELAY_TICKS];
        self.head = 0;
    }

    /// The i-th pending input, oldest first (i < d): in effect at k + i.
    pub fn get(&self, i: usize) -> Vector3<f64> {
        self.pending[(self.head + i) % MAX_DELAY_TICKS]
    }

    /// The input sent last (in effect at k + d − 1), if d > 0.
    pub fn newest(&self) -> Option<Vector3<f64>> {
        (self.len > 0).then(|| self.get(self.len - 1))
    }

    /// The inputs sent and not yet in effect, oldest first: the first
    /// `len` of the array (`len` = d).
    pub fn in_flight(&self) -> ([Vector3<f64>; MAX_DELAY_TICKS], usize) {
        let mut out = [Vector3::zeros(); MAX_DELAY_TICKS];
        for (i, u) in out.iter_mut().enumerate().take(self.len) {
            *u = self.get(i);
        }
        (out, self.len)
    }

    /// `n` ticks on which nothing was sent (the shell skipped them; the
    /// autopilot holds the newest input it has): each moves the line on
    /// with the newest input sent again.
    pub fn skip(&mut self, n: usize) {
        for _ in 0..n.min(self.len) {
            if let Some(u) = self.newest() {
                self.push(u);
            }
        }
    }

    /// Sends `u`: returns the input that takes effect now (`u` itself for
    /// d = 0, else the one sent d ticks ago).
    pub fn push(&mut self, u: Vector3<f64>) -> Vector3<f64> {
        if self.len == 0 {
            return u;
        }
        let out = self.pending[self.head];
        self.pending[(self.head + self.len) % MAX_DELAY_TICKS] = u;
        self.head = (self.head + 1) % MAX_DELAY_TICKS;
        out
    }

    /// Carries the fixed outputs `[y_k, y_{k+1}, y_{k+2}]` across the d
    /// pending inputs through `next_output` (F⁻¹):
    /// `[y_{k+d}, y_{k+d+1}, y_{k+d+2}]`.
    pub fn predict(
        &self,
        fixed: [Vector3<f64>; 3],
        next_output: impl Fn(&[Vector3<f64>; 3], &Vector3<f64>) -> Result<Vector3<f64>, FlatError>,
    ) -> Result<[Vector3<f64>; 3], ControlError> {
        let mut y = fixed;
        for i in 0..self.len {
            let next = next_output(&y, &self.get(i))?;
            y = [y[1], y[2], next];
        }
        Ok(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64) -> Vector3<f64> {
        Vector3::new(x, 0.0, 0.0)
    }

    #[test]
    fn skipped_ticks_move_the_line_on_under_the_newest_input() {
        let mut line = DelayLine::new(3, v(0.0));
        for i in 1..=3 {
            line.push(v(i as f64));
        }
        let (pending, len) = line.in_flight();
        assert_eq!(&pending[..len], &[v(1.0), v(2.0), v(3.0)]);
        // Two ticks skipped: 1 and 2 took effect, 3 is held.
        line.skip(2);
        assert_eq!(line.push(v(4.0)), v(3.0));
        let (pending, len) = line.in_flight();
        assert_eq!(&pending[..len], &[v(3.0), v(3.0), v(4.0)]);
        // More skipped ticks than the delay: only the newest is left.
        line.skip(10);
        assert_eq!(&line.in_flight().0[..3], &[v(4.0); 3]);
    }

    #[test]
    fn delays_by_d_ticks() {
        let mut line = DelayLine::new(3, v(0.0));
        let out: Vec<f64> = (1..=6).map(|i| line.push(v(i as f64)).x).collect();
        assert_eq!(out, vec![0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        assert_eq!((line.get(0).x, line.get(2).x), (4.0, 6.0));
        assert_eq!(line.newest(), Some(v(6.0)));
        let mut none = DelayLine::new(0, v(0.0));
        assert_eq!(none.push(v(5.0)), v(5.0));
        assert_eq!(none.newest(), None);
    }
}
