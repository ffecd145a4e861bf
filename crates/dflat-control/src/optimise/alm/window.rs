//! The window of a cold solve with the horizon's head eliminated (module
//! docs of [`super`], "The eliminated head"): opened from the first
//! gradient, closed when it converged.

use super::{BandedAlm, WINDOW_MARGIN, WINDOW_MIN_SHARE};

impl BandedAlm {
    /// Opens the window on a cold solve whose plan leaves its sets only
    /// late in the horizon (module docs, "The eliminated head"): from the
    /// first gradient over the whole horizon, the first stage outside its
    /// set less [`WINDOW_MARGIN`], if that is at least [`WINDOW_MIN_SHARE`]
    /// of the horizon in, no row of the head binds and the head's gradient
    /// is within `head_tol` (the start is the unconstrained optimum there).
    /// Returns that gradient's `(‖g‖∞, stage residual, row residual)`,
    /// ‖g‖∞ on the window when it opened.
    pub(super) fn open_window(
        &mut self,
        a0: [f64; 2],
        lo: &[f64],
        hi: &[f64],
        head_tol: f64,
    ) -> (f64, f64, f64) {
        let done = self.gradient(a0, lo, hi);
        let n = self.n;
        let Some(first) = self.active[..n].iter().position(|a| *a != 0) else {
            return done;
        };
        let window = first.saturating_sub(WINDOW_MARGIN);
        if window < 2 || (window as f64) < WINDOW_MIN_SHARE * n as f64 || !self.head_valid {
            return done;
        }
        let j0 = self.k * (window - 2);
        let rows_quiet = (0..self.rows.len()).all(|r| {
            self.row_first[r] >= j0
                || self.active[n + 2 * r] == 0 && self.active[n + 2 * r + 1] == 0
        });
        let head_g = self.g[..j0].iter().fold(0.0f64, |a, b| a.max(b.abs()));
        if !(rows_quiet && head_g <= head_tol) {
            return done;
        }
        self.window = window;
        self.last_window = window;
        let gn = self.g[j0..].iter().fold(0.0f64, |a, b| a.max(b.abs()));
        (gn, done.1, done.2)
    }

    /// Back to the whole horizon: P·x and the stages' accelerations
    /// evaluated afresh on it by the next gradient.
    pub(super) fn close_window(&mut self) {
        self.window = 0;
        self.full_step = None;
        self.px_current = false;
    }
}
