//! The banded symmetric matrix ([`SymBand`]): its lower band, row by row.

/// A symmetric n×n matrix with half-bandwidth b: `A[i][j] = 0` for `|i − j| > b`.
#[derive(Debug, Clone, PartialEq)]
pub struct SymBand {
    pub(super) n: usize,
    pub(super) b: usize,
    pub(super) lower: Vec<f64>,
}

impl SymBand {
    /// The n×n zero matrix with half-bandwidth `bandwidth` (allocates once).
    pub fn zeros(n: usize, bandwidth: usize) -> Self {
        Self {
            n,
            b: bandwidth,
            lower: vec![0.0; n * (bandwidth + 1)],
        }
    }

    /// Dimension n.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Half-bandwidth b.
    pub fn bandwidth(&self) -> usize {
        self.b
    }

    /// Row i's lower band: entry d is `A[i][i − d]`, d = 0..=b (entries
    /// before column 0 are 0).
    pub(crate) fn lower_row(&self, i: usize) -> &[f64] {
        &self.lower[i * (self.b + 1)..(i + 1) * (self.b + 1)]
    }

    fn index(&self, i: usize, j: usize) -> usize {
        let (r, c) = if i >= j { (i, j) } else { (j, i) };
        assert!(
            r < self.n && r - c <= self.b,
            "entry ({i}, {j}) outside the band"
        );
        r * (self.b + 1) + (r - c)
    }

    /// Entry `A[i][j]`; zero outside the band.
    ///
    /// # Panics
    /// If `i` or `j` is not below n.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        assert!(
            i < self.n && j < self.n,
            "entry ({i}, {j}) outside the matrix"
        );
        if i.abs_diff(j) > self.b {
            0.0
        } else {
            self.lower[self.index(i, j)]
        }
    }

    /// Sets `A[i][j] = A[j][i] = v`.
    ///
    /// # Panics
    /// If the entry lies outside the matrix or the band.
    pub fn set(&mut self, i: usize, j: usize, v: f64) {
        let k = self.index(i, j);
        self.lower[k] = v;
    }

    /// Adds `v` to `A[i][j]` (and so to `A[j][i]`).
    ///
    /// # Panics
    /// If the entry lies outside the matrix or the band.
    pub fn add(&mut self, i: usize, j: usize, v: f64) {
        let k = self.index(i, j);
        self.lower[k] += v;
    }

    /// The lower band, row-major: `(i, i − d)` at `i·(b + 1) + d`.
    pub(crate) fn lower(&self) -> &[f64] {
        &self.lower
    }

    /// The lower band, mutable (layout as [`SymBand::lower`]).
    pub(crate) fn lower_mut(&mut self) -> &mut [f64] {
        &mut self.lower
    }

    /// Sets every entry to zero.
    pub fn fill_zero(&mut self) {
        self.lower.iter_mut().for_each(|v| *v = 0.0);
    }

    /// `out = A·x`.
    ///
    /// # Panics
    /// If `x` or `out` does not have length n.
    pub fn mul_vec(&self, x: &[f64], out: &mut [f64]) {
        assert!(x.len() == self.n && out.len() == self.n, "length mismatch");
        let w = self.b + 1;
        for i in 0..self.n {
            let row = &self.lower[i * w..(i + 1) * w];
            let mut s = row[0] * x[i];
            for d in 1..=self.b.min(i) {
                s += row[d] * x[i - d];
            }
            for d in 1..=self.b.min(self.n - 1 - i) {
                s += self.lower[(i + d) * w + d] * x[i + d];
            }
            out[i] = s;
        }
    }
}
