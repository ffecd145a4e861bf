//! Refactoring a held factor from the first column its matrix changed in
//! ([`BandedCholesky::refactor_taking`], [`BandedCholesky::refactor_rows_from`]):
//! the columns before it kept, the b×b block there rebuilt from their L
//! and D, the rest factored again — bit-identical to a fresh factor.

use super::{BandedCholesky, SymBand};
use crate::ControlError;

impl BandedCholesky {
    /// As [`BandedCholesky::factor_taking`], keeping the columns of the
    /// held factor before the first column j0 in which `a` differs (bit
    /// for bit) from the matrix that factor is of: only columns j0 … n − 1
    /// are factored again, after the b×b block at j0 has taken what the
    /// kept columns contribute to it (rebuilt from their L and D, O(b³)).
    /// A matrix that changed only in its last rows — the Newton matrix of
    /// a plan whose constraints bind near the horizon's end — costs that
    /// fraction of a factorisation. The result is bit-identical to
    /// [`BandedCholesky::factor`]'s: the same operations in the same
    /// order. `a`'s storage is kept as the held matrix, and `a` left
    /// holding unspecified values. Returns j0 (0: factored afresh, n: `a`
    /// is the held matrix). The compiled bandwidths (3, 4, 6–9) restart at
    /// j0, the others factor afresh when anything changed.
    ///
    /// # Panics
    /// If `a` has another dimension or bandwidth than this factor.
    pub fn refactor_taking(&mut self, a: &mut SymBand) -> Result<usize, ControlError> {
        assert!(a.n == self.n && a.b == self.b, "shape mismatch");
        let (n, b) = (self.n, self.b);
        let mut j0 = if self.factored && self.held_valid {
            first_changed_column(&self.held, &a.lower, n, b)
        } else {
            0
        };
        if j0 == n {
            return Ok(n);
        }
        if !matches!(b, 3 | 4 | 6..=9) {
            j0 = 0;
        }
        std::mem::swap(&mut self.held, &mut a.lower);
        self.factor_held_from(j0)?;
        Ok(j0)
    }

    /// As [`BandedCholesky::refactor_taking`] for a matrix given by its
    /// rows `from` … n − 1 only: the rows before `from` are the held
    /// matrix's (the caller's guarantee; `a`'s are not read), and `a` is
    /// copied, not taken. An error when no valid factor is held.
    ///
    /// # Panics
    /// If `a` has another dimension or bandwidth than this factor, or
    /// `from` > n.
    pub fn refactor_rows_from(&mut self, a: &SymBand, from: usize) -> Result<usize, ControlError> {
        assert!(
            a.n == self.n && a.b == self.b && from <= self.n,
            "shape mismatch"
        );
        if !(self.factored && self.held_valid) {
            return Err(ControlError::NotPositiveDefinite);
        }
        let (n, b, w) = (self.n, self.b, self.b + 1);
        let first = first_changed_column(&self.held[from * w..], &a.lower[from * w..], n - from, b);
        // Row i of the slices is row from + i; its slot s column from + i − s,
        // so a change found at "column" c of the slices (c may be
        // negative there, clamped by the scan to ≥ 0) is at from + c or,
        // within b before from, earlier: rescan the first b rows exactly.
        let mut j0 = if first == n - from { n } else { from + first };
        for i in from..(from + b).min(n) {
            for s in (i - from + 1)..=b.min(i) {
                if self.held[i * w + s].to_bits() != a.lower[i * w + s].to_bits() {
                    j0 = j0.min(i - s);
                }
            }
        }
        if j0 == n {
            return Ok(n);
        }
        // Rows from … n − 1 into the held matrix.
        self.held[from * w..].copy_from_slice(&a.lower[from * w..]);
        self.factor_held_from(j0)?;
        Ok(j0)
    }

    /// Factors the held matrix (`held`, just replaced), keeping L's
    /// columns before j0 (those of the matrix factored before, which
    /// agrees with it there): L's rows j0 … n − 1, columns j0 and after,
    /// from `held`, the block at j0 rebuilt, the rest factored
    /// (bandwidths without a compiled kernel, and j0 = 0: afresh).
    fn factor_held_from(&mut self, j0: usize) -> Result<(), ControlError> {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        self.held_valid = false;
        self.factored = false;
        if j0 == 0 || !matches!(b, 3 | 4 | 6..=9) {
            self.l.copy_from_slice(&self.held);
            self.factor_held()?;
        } else {
            // (Rows j0 + b and after are whole rows: one copy.)
            let whole = (j0 + b).min(n);
            for i in j0..whole {
                let r = i * w..i * w + (i - j0) + 1;
                self.l[r.clone()].copy_from_slice(&self.held[r]);
            }
            self.l[whole * w..].copy_from_slice(&self.held[whole * w..]);
            self.schur_window(j0);
            match b {
                3 => self.factor_window_from::<3>(j0)?,
                4 => self.factor_window_from::<4>(j0)?,
                6 => self.factor_band_from::<6>(j0)?,
                7 => self.factor_band_from::<7>(j0)?,
                8 => self.factor_band_from::<8>(j0)?,
                _ => self.factor_band_from::<9>(j0)?,
            }
            self.factored = true;
        }
        self.held_valid = true;
        Ok(())
    }

    /// Entry (i, k) of the b×b block at j0 (j0 ≤ k ≤ i < j0 + b) loses
    /// what the kept columns j < j0 subtract from it in the factorisation,
    /// `l_{i,j}·a_{k,j}` (a_{k,j} the column before scaling, held in
    /// `cols`), in the order of the columns — as the right-looking kernels
    /// do.
    fn schur_window(&mut self, j0: usize) {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        for i in j0..(j0 + b).min(n) {
            for k in j0..=i {
                let mut v = self.l[i * w + (i - k)];
                for j in i.saturating_sub(b)..j0 {
                    v -= self.l[i * w + (i - j)] * self.cols[j * w + (k - j)];
                }
                self.l[i * w + (i - k)] = v;
            }
        }
    }
}

/// The first column in which the lower bands `old` and `new` (n rows,
/// half-bandwidth b, row-major as [`SymBand`]) differ bit for bit; n when
/// they are equal. A changed entry of row i lies in column i − b or later,
/// so the scan stops once rows can no longer lower the answer.
fn first_changed_column(old: &[f64], new: &[f64], n: usize, b: usize) -> usize {
    let w = b + 1;
    let mut first = n;
    for i in 0..n {
        if i.saturating_sub(b) >= first {
            break;
        }
        let (o, m) = (&old[i * w..(i + 1) * w], &new[i * w..(i + 1) * w]);
        // Slot s is column i − s: the largest differing slot is the row's
        // first changed column.
        if let Some(s) = (0..=b.min(i))
            .rev()
            .find(|&s| o[s].to_bits() != m[s].to_bits())
        {
            first = first.min(i - s);
        }
    }
    first
}
