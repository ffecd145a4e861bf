//! The window of a cold solve with the horizon's head eliminated (module
//! docs of [`super`], "The eliminated head"): opened from the first
//! gradient, closed when it converged.
//!
//! The windows' factorisations go into a factor of their own (`head`),
//! factored from P once, at construction: its rows before any window are
//! P's — a window's first factorisation restores to P's the rows that an
//! earlier-starting window changed before its own start — so it too
//! refactors the window's rows only, not the whole horizon as it would
//! into the factor the last warm solve left (a late corner's cold solve
//! after one over the whole horizon: ~162 → ~153 µs, median of 400, five
//! alternating runs). Each step's back substitution stops eight stages
//! before the window (`BandedCholesky::solve_in_place_cut`): nothing
//! reads the unknowns before that until the window closes, when they move
//! once, by the steps' sum extended back (`BandedCholesky::extend_back`;
//! linear, the head's factor being P's throughout). On the course of
//! corners at N = 200 the window solves took 71 µs on average against
//! 83 µs without the cut (eight alternating runs).

use super::{BandedAlm, WINDOW_MARGIN, WINDOW_MIN_SHARE};

/// Stages before the window from which its steps move the head's
/// unknowns at once ([`BandedAlm::move_x`]).
const CUT_MARGIN: usize = 8;

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
        let Some(first) = self.ws.active[..n].iter().position(|a| *a != 0) else {
            return done;
        };
        let window = first.saturating_sub(WINDOW_MARGIN);
        if window < 2 || (window as f64) < WINDOW_MIN_SHARE * n as f64 || !self.head.valid {
            return done;
        }
        let j0 = self.k * (window - 2);
        let rows_quiet = (0..self.rows.len()).all(|r| {
            self.row_first[r] >= j0
                || self.ws.active[n + 2 * r] == 0 && self.ws.active[n + 2 * r + 1] == 0
        });
        let head_g = self.ws.g[..j0].iter().fold(0.0f64, |a, b| a.max(b.abs()));
        if !(rows_quiet && head_g <= head_tol) {
            return done;
        }
        self.ws.window = window;
        self.ws.last_window = window;
        // The head's unknowns P·x and the window's stages read reach
        // 2 + 4 stages before the window (P's half-bandwidth per axis is at
        // most 4); two more for margin.
        self.ws.cut = if self.head.factor.can_cut() && !self.cut_off() {
            self.k * window.saturating_sub(CUT_MARGIN)
        } else {
            0
        };
        self.ws.cut_seed.fill(0.0);
        let gn = self.ws.g[j0..].iter().fold(0.0f64, |a, b| a.max(b.abs()));
        (gn, done.1, done.2)
    }

    /// The first stage at which the held iterate ([`BandedAlm::set_start`])
    /// leaves its disc, or breaks a row that starts there, for fixed
    /// relative accelerations `a0` [m/s²] and row bounds `lo ≤ h·x ≤ hi`
    /// (n: nowhere; intervals: 0, not asked). A cold solve of the pair
    /// whose plan breaks nothing before late in the horizon (a burst's
    /// first tick, its arc entering at the end) needs no interior-point
    /// start. Leaves `u` the iterate's accelerations (a solve's first
    /// gradient evaluates them afresh).
    pub fn first_broken_stage(&mut self, a0: [f64; 2], lo: &[f64], hi: &[f64]) -> usize {
        let super::StageSet::Disc(radius) = &self.stages else {
            return 0;
        };
        Self::accelerations(self.k, self.inv_dt2, &self.ws.x, &mut self.ws.u, 0);
        let mut first = radius
            .iter()
            .zip(&self.ws.u)
            .zip(&self.centre)
            .position(|((&r, u), o)| (u[0] + a0[0] - o[0]).hypot(u[1] + a0[1] - o[1]) > r)
            .unwrap_or(self.n);
        for (r, row) in self.rows.iter().enumerate() {
            let stage = self.row_first[r] / self.k;
            if stage < first {
                let h = row.dot(&self.ws.x);
                if h > hi[r] || h < lo[r] {
                    first = stage;
                }
            }
        }
        first
    }

    /// Back to the whole horizon: P·x and the stages' accelerations
    /// evaluated afresh on it by the next gradient.
    pub(super) fn close_window(&mut self) {
        if self.ws.cut > 0 {
            // The head's unknowns before the cut move by the steps' sum,
            // extended back from its b unknowns at the cut (d is free
            // until the next step).
            let (cut, b) = (self.ws.cut, self.ws.cut_seed.len());
            self.ws.d[cut..cut + b].copy_from_slice(&self.ws.cut_seed);
            self.head.factor.extend_back(&mut self.ws.d, cut);
            for (x, d) in self.ws.x[..cut].iter_mut().zip(&self.ws.d[..cut]) {
                *x += d;
            }
            self.ws.cut = 0;
        }
        self.ws.window = 0;
        self.ws.full_step = None;
        self.ws.px_current = false;
    }

    /// `x += α·d`; while the window is open, from the cut on, with the
    /// step's b unknowns at the cut added to the seed of the head's move.
    pub(super) fn move_x(&mut self, alpha: f64) {
        let cut = self.ws.cut;
        for (x, d) in self.ws.x[cut..].iter_mut().zip(&self.ws.d[cut..]) {
            *x += alpha * d;
        }
        if cut > 0 {
            for (s, d) in self.ws.cut_seed.iter_mut().zip(&self.ws.d[cut..]) {
                *s += alpha * d;
            }
        }
    }

    /// Whether the cut is switched off (tests only).
    fn cut_off(&self) -> bool {
        #[cfg(test)]
        return self.no_cut;
        #[cfg(not(test))]
        false
    }
}
