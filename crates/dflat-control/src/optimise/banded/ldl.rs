//! LDLᵀ of quasi-definite banded matrices ([`BandedLdl`]): the banded
//! interior point's KKT systems.

use super::SymBand;
use crate::ControlError;

/// LDLᵀ of a symmetric banded matrix without pivoting (for quasi-definite
/// matrices), L unit lower triangular with the same band.
#[derive(Debug, Clone)]
pub struct BandedLdl {
    n: usize,
    b: usize,
    /// Strictly lower part of L by row, column-aligned: `L[i][i − b + t]`
    /// at `i·b + t`, t = 0..b (zero before column 0).
    l: Vec<f64>,
    /// The same transposed for the back substitution: `L[i + d][i]` at
    /// `i·b + d − 1`, d = 1..=b (zero past row n − 1).
    lt: Vec<f64>,
    d: Vec<f64>,
    inv_d: Vec<f64>,
    /// Row i of L times D, scratch of the factorisation.
    work: Vec<f64>,
}

impl BandedLdl {
    /// Storage for n×n matrices of half-bandwidth b ≥ 1.
    pub fn new(n: usize, b: usize) -> Self {
        Self {
            n,
            b,
            l: vec![0.0; n * b],
            lt: vec![0.0; n * b],
            d: vec![0.0; n],
            inv_d: vec![0.0; n],
            work: vec![0.0; b],
        }
    }

    /// Factors `a` (same n and b). A pivot that is not finite or whose
    /// magnitude is below 1e-300 is [`ControlError::NotPositiveDefinite`].
    ///
    /// # Panics
    /// If `a` has another shape.
    pub fn factor(&mut self, a: &SymBand) -> Result<(), ControlError> {
        self.factor_from(a, 0)
    }

    /// As [`BandedLdl::factor`], keeping the held factor's rows before
    /// `start`: valid when the matrix factored last had the same rows
    /// before `start` as `a` (the rows of L and D before it depend on
    /// those alone).
    ///
    /// # Panics
    /// If `a` has another shape.
    pub fn factor_from(&mut self, a: &SymBand, start: usize) -> Result<(), ControlError> {
        let (n, b) = (self.n, self.b);
        assert!(a.n() == n && a.bandwidth() == b, "shape mismatch");
        let lower = a.lower();
        let w = b + 1;
        for i in start.min(n)..n {
            let t0 = b.saturating_sub(i);
            let (done, rest) = self.l.split_at_mut(i * b);
            let row = &mut rest[..b];
            row[..t0].fill(0.0);
            for t in t0..b {
                // Column j = i − b + t; Σ over k in [i − b, j): in row i at
                // t' = 0..t, in row j at t' + b − t.
                let j = i + t - b;
                let rj = &done[j * b..(j + 1) * b];
                let mut s = lower[i * w + (b - t)];
                for (wk, lj) in self.work[t0..t].iter().zip(&rj[t0 + b - t..]) {
                    s -= wk * lj;
                }
                self.work[t] = s;
                row[t] = s * self.inv_d[j];
            }
            let mut dii = lower[i * w];
            for (wk, li) in self.work[t0..].iter().zip(&row[t0..]) {
                dii -= wk * li;
            }
            if !(dii.is_finite() && dii.abs() > 1e-300) {
                return Err(ControlError::NotPositiveDefinite);
            }
            self.d[i] = dii;
            self.inv_d[i] = 1.0 / dii;
        }
        for i in start.saturating_sub(b)..n {
            for d in 1..=b {
                self.lt[i * b + d - 1] = if i + d < n {
                    self.l[(i + d) * b + b - d]
                } else {
                    0.0
                };
            }
        }
        Ok(())
    }

    /// Solves `L·D·Lᵀ·x = rhs` in place.
    ///
    /// # Panics
    /// If `x` does not have length n.
    pub fn solve(&self, x: &mut [f64]) {
        let (n, b) = (self.n, self.b);
        assert!(x.len() == n, "length mismatch");
        for i in 0..n {
            let t0 = b.saturating_sub(i);
            let row = &self.l[i * b + t0..(i + 1) * b];
            let s = dot(row, &x[i + t0 - b..i]);
            x[i] -= s;
        }
        for (xi, di) in x.iter_mut().zip(&self.inv_d) {
            *xi *= di;
        }
        for i in (0..n).rev() {
            let m = b.min(n - 1 - i);
            let col = &self.lt[i * b..i * b + m];
            let s = dot(col, &x[i + 1..i + 1 + m]);
            x[i] -= s;
        }
    }
}

/// `Σ a_k·b_k` over the shorter length, with four partial sums: a single
/// accumulator makes the substitutions' dot products latency-bound (the
/// interior point's LDLᵀ solve of half-bandwidth 14 at N = 200: 14.7 →
/// 12.6 µs, `cargo bench -p dflat-control --bench banded -- ldl`; in the
/// factorisation's short triangular dots it cost more than it saved).
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 4];
    let (ca, ra) = a.split_at(n - n % 4);
    let (cb, rb) = b.split_at(n - n % 4);
    for (x, y) in ca.chunks_exact(4).zip(cb.chunks_exact(4)) {
        for k in 0..4 {
            s[k] += x[k] * y[k];
        }
    }
    let mut t = (s[0] + s[2]) + (s[1] + s[3]);
    for (x, y) in ra.iter().zip(rb) {
        t += x * y;
    }
    t
}
