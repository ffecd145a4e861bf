//! Banded symmetric matrices: the positive-definite ones' Cholesky factor
//! ([`BandedCholesky`]) and the quasi-definite ones' LDLᵀ ([`BandedLdl`],
//! the banded interior point's KKT systems).
//!
//! The unconstrained DF-MPC problem per axis is a banded SPD system (band 3
//! from the third difference in the cost, band 4 with the command-smoothness
//! term); [`BandedCholesky`] solves it in
//! O(n·b²) time for the factorisation and O(n·b) per solve, with all storage
//! allocated once at construction.
//!
//! Storage: only the lower band is kept, row by row: entry `(i, i − d)` for
//! `d = 0..=b` lives at `i·(b + 1) + d`. Entries above the diagonal mirror
//! the lower ones.
//!
//! Shape mismatches (an index outside the band, a vector of the wrong
//! length) are programming errors and panic like slice indexing; numerical
//! failure (a non-positive or non-finite pivot) is returned as
//! [`ControlError::NotPositiveDefinite`].

use crate::ControlError;

mod ldl;
mod refactor;
mod sym_band;
mod truncated;

pub use ldl::BandedLdl;
pub(crate) use ldl::dot;
pub use sym_band::SymBand;

/// Cholesky factor `A = L·Lᵀ` of a banded SPD matrix; L has the same band.
///
/// Built once with its dimension and bandwidth; [`BandedCholesky::factor`]
/// and [`BandedCholesky::solve_in_place`] never allocate.
#[derive(Debug, Clone, PartialEq)]
pub struct BandedCholesky {
    n: usize,
    b: usize,
    /// L, lower band, row-major as in [`SymBand`] (the LDLᵀ kernels: d_i
    /// on the diagonal, unit L's entries below; row i, `[d_i, l_{i,i−1},
    /// …, l_{i,i−b}]`, is the back substitution's data).
    l: Vec<f64>,
    /// Forward substitution, per unknown i in order: its scale and the
    /// column below it, `[1/L_ii, L_{i+1,i}, …, L_{i+b,i}]` (the LDLᵀ
    /// kernels: `[1/d_i, l_{i+1,i}, …]`); 0 past the end.
    fwd: Vec<f64>,
    /// Back substitution of the generic LLᵀ, per unknown i from the last:
    /// its scale and the row before it, `[1/L_ii, L_{i,i−1}, …,
    /// L_{i,i−b}]`; 0 before the start. (The LDLᵀ kernels read `l`.)
    bwd: Vec<f64>,
    /// The LDLᵀ kernels' columns before scaling, `[·, a_{j+1,j}, …,
    /// a_{j+b,j}]` (`a_{j+t,j} = d_j·l_{j+t,j}` as the factorisation
    /// rounded it): what [`BandedCholesky::refactor_taking`] rebuilds the
    /// block at j0 from.
    cols: Vec<f64>,
    factored: bool,
    /// The matrix of the held factor (lower band, as `l`), when it was
    /// factored by [`BandedCholesky::refactor`]: what the next refactor
    /// compares against.
    held: Vec<f64>,
    held_valid: bool,
}

impl BandedCholesky {
    /// Storage for an n×n factor with half-bandwidth `bandwidth` (allocates once).
    pub fn new(n: usize, bandwidth: usize) -> Self {
        Self {
            n,
            b: bandwidth,
            l: vec![0.0; n * (bandwidth + 1)],
            fwd: vec![0.0; n * (bandwidth + 1)],
            bwd: vec![0.0; n * (bandwidth + 1)],
            cols: vec![0.0; n * (bandwidth + 1)],
            factored: false,
            held: vec![0.0; n * (bandwidth + 1)],
            held_valid: false,
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

    /// True when the last [`BandedCholesky::factor`] succeeded.
    pub fn is_factored(&self) -> bool {
        self.factored
    }

    /// Factors `a` (band-limited LLᵀ, O(n·b²)). On failure the factor is
    /// marked invalid and [`ControlError::NotPositiveDefinite`] returned.
    ///
    /// # Panics
    /// If `a` has another dimension or bandwidth than this factor.
    pub fn factor(&mut self, a: &SymBand) -> Result<(), ControlError> {
        assert!(a.n == self.n && a.b == self.b, "shape mismatch");
        self.l.copy_from_slice(&a.lower);
        self.factor_held()
    }

    /// As [`BandedCholesky::factor`], taking `a`'s storage instead of
    /// copying it: `a` is left holding unspecified values (for a matrix
    /// assembled afresh before every factorisation).
    ///
    /// # Panics
    /// If `a` has another dimension or bandwidth than this factor.
    pub fn factor_taking(&mut self, a: &mut SymBand) -> Result<(), ControlError> {
        assert!(a.n == self.n && a.b == self.b, "shape mismatch");
        std::mem::swap(&mut self.l, &mut a.lower);
        self.factor_held()
    }

    /// Factors the matrix held in `l`.
    fn factor_held(&mut self) -> Result<(), ControlError> {
        self.factored = false;
        self.held_valid = false;
        match self.b {
            3 => self.factor_window_from::<3>(0)?,
            4 => self.factor_window_from::<4>(0)?,
            6 => self.factor_band_from::<6>(0)?,
            7 => self.factor_band_from::<7>(0)?,
            8 => self.factor_band_from::<8>(0)?,
            9 => self.factor_band_from::<9>(0)?,
            _ => {
                self.factor_generic()?;
                self.substitution_rows();
            }
        }
        self.factored = true;
        Ok(())
    }

    /// The square-root-free factorisation `A = L·D·Lᵀ` (L unit lower) of
    /// `l` in place, for a compile-time bandwidth (3, 4: one axis, without
    /// and with the smoothness term; 6, 8: the two-axis cone problems; 7,
    /// 9: the same with the band one wider, as it was built before),
    /// right-looking: each pivot `d_j`, once inverted, scales its column to
    /// `l_{j+t,j} = a_{j+t,j}/d_j` and updates the B(B+1)/2 entries of the
    /// block after it, `a_{j+t1,j+t2} −= l_{j+t1,j}·a_{j+t2,j}` —
    /// independent multiply-adds, with one division and no square root on
    /// the chain from pivot to pivot (the row-oriented
    /// [`BandedCholesky::factor_generic`] chains its dot products, a
    /// division per entry and a square root per row). Row t1 of the block
    /// is updated as one run against the unscaled column held in reverse
    /// ([`BandedCholesky::update_block`], written out with constant
    /// indices). Writes the substitutions' data as it goes
    /// ([`BandedCholesky::ldl_rows`]). Starts at column j0 (0: all; else
    /// columns before it are kept and the block at j0 holds what they
    /// subtract from it, [`BandedCholesky::schur_window`]).
    fn factor_band_from<const B: usize>(&mut self, j0: usize) -> Result<(), ControlError> {
        let n = self.n;
        let w = B + 1;
        let l = &mut self.l;
        // ra[B − t] = a_{j+t, j} before scaling, rl[B − t] = l_{j+t, j}
        // (0 past the matrix's end).
        let (mut ra, mut rl) = ([0.0f64; B], [0.0f64; B]);
        for j in j0..n {
            let d = l[j * w];
            if !(d > 0.0 && d.is_finite()) {
                return Err(ControlError::NotPositiveDefinite);
            }
            let inv = 1.0 / d;
            if j + B < n {
                // The bulk: a full column, every bound known at compile
                // time.
                let block = &mut l[j * w..(j + B + 1) * w];
                for t in 1..=B {
                    let a = block[t * w + t];
                    let v = a * inv;
                    block[t * w + t] = v;
                    ra[B - t] = a;
                    rl[B - t] = v;
                }
                Self::update_block::<B>(block, &ra, &rl);
            } else {
                // The last B columns: a shorter block.
                let span = n - 1 - j;
                ra = [0.0; B];
                rl = [0.0; B];
                for t in 1..=span {
                    let a = l[(j + t) * w + t];
                    let v = a * inv;
                    l[(j + t) * w + t] = v;
                    ra[B - t] = a;
                    rl[B - t] = v;
                }
                for t1 in 1..=span {
                    let c1 = rl[B - t1];
                    let row = &mut l[(j + t1) * w..(j + t1) * w + t1];
                    for (r, c) in row.iter_mut().zip(&ra[B - t1..]) {
                        *r -= c1 * c;
                    }
                }
            }
            Self::ldl_rows::<B>(
                &mut self.fwd[j * w..j * w + w],
                &mut self.cols[j * w..j * w + w],
                inv,
                |t| ra[B - t],
                |t| rl[B - t],
            );
        }
        Ok(())
    }

    /// [`BandedCholesky::factor_band`] for the narrow bands (3, 4: one
    /// axis), with the (B + 1)² lower triangle of rows j … j + B held in
    /// a local window that the compiler keeps in registers: the chain
    /// from pivot to pivot (a division, two multiplications, a
    /// subtraction) no longer passes through memory, where the wide
    /// kernel's each column stores what the next loads. Rows past the
    /// matrix's end enter as zeros, so every column runs the same code.
    /// Same operations in the same order as `factor_band_from`, and as it
    /// starts at column j0.
    fn factor_window_from<const B: usize>(&mut self, j0: usize) -> Result<(), ControlError> {
        const { assert!(B <= 4, "the window holds five rows") };
        let n = self.n;
        let w = B + 1;
        let l = &mut self.l;
        // win[r][c] = the current entry (j + r, j + c), c ≤ r ≤ B.
        let mut win = [[0.0f64; 5]; 5];
        let row_of = |l: &[f64], i: usize, win_row: &mut [f64; 5], r: usize| {
            for c in 0..=r {
                win_row[c] = if i < n { l[i * w + (r - c)] } else { 0.0 };
            }
        };
        for (r, wr) in win.iter_mut().enumerate().take(B + 1) {
            row_of(l, j0 + r, wr, r);
        }
        for j in j0..n {
            let d = win[0][0];
            if !(d > 0.0 && d.is_finite()) {
                return Err(ControlError::NotPositiveDefinite);
            }
            let inv = 1.0 / d;
            let (mut a, mut lt) = ([0.0f64; 5], [0.0f64; 5]);
            for t in 1..=B {
                a[t] = win[t][0];
                lt[t] = a[t] * inv;
            }
            // Entry (j + t1, j + t2) loses l_{j+t1,j}·a_{j+t2,j}; the
            // window moves one row and column on, row j + 1 + B entering.
            let mut next = [[0.0f64; 5]; 5];
            for r in 0..B {
                for c in 0..=r {
                    next[r][c] = win[r + 1][c + 1] - lt[r + 1] * a[c + 1];
                }
            }
            let mut row = [0.0; 5];
            row_of(l, j + 1 + B, &mut row, B);
            next[B] = row;
            win = next;
            // L's column j into the storage (row j + t, slot t), then the
            // substitutions' data.
            l[j * w] = d;
            for t in 1..=B.min(n - 1 - j) {
                l[(j + t) * w + t] = lt[t];
            }
            Self::ldl_rows::<B>(
                &mut self.fwd[j * w..j * w + w],
                &mut self.cols[j * w..j * w + w],
                inv,
                |t| a[t],
                |t| lt[t],
            );
        }
        Ok(())
    }

    /// Column j's data of an LDLᵀ factor's forward substitution, `[1/d_j,
    /// l_{j+1,j}, …, l_{j+B,j}]` (`l(t)`; 0 past the end), and its column
    /// before scaling into `cols` (`a(t)`), so that
    /// [`BandedCholesky::solve_in_place`] runs `L·y = b`, `z = D⁻¹·y`, then
    /// `Lᵀ·x = z` on the rows of L.
    #[inline(always)]
    fn ldl_rows<const B: usize>(
        fwd: &mut [f64],
        cols: &mut [f64],
        inv: f64,
        a: impl Fn(usize) -> f64,
        l: impl Fn(usize) -> f64,
    ) {
        fwd[0] = inv;
        for t in 1..=B {
            fwd[t] = l(t);
            cols[t] = a(t);
        }
    }

    /// The update of the (B + 1)² block after a full column: entry
    /// (j + t1, j + t2), t1 ≥ t2, at `block[t1·w + t1 − t2]` loses
    /// `l_{j+t1,j}·a_{j+t2,j}`; row t1's run s = 0..t1 takes t2 = t1 − s,
    /// i.e. `ra[B − t1 + s]`. Written out for the bandwidths the solvers
    /// use (every index a constant: no loop, no index check), a loop for
    /// the others.
    #[inline(always)]
    fn update_block<const B: usize>(block: &mut [f64], ra: &[f64; B], rl: &[f64; B]) {
        /// `$t1: [$s …]` — row t1's entries s.
        macro_rules! unrolled {
            ($($t1:literal : [$($s:literal)*])*) => {{
                let w = B + 1;
                $(
                    let c1 = rl[B - $t1];
                    $( block[$t1 * w + $s] -= c1 * ra[B - $t1 + $s]; )*
                )*
            }};
        }
        match B {
            3 => unrolled!(1: [0] 2: [0 1] 3: [0 1 2]),
            4 => unrolled!(1: [0] 2: [0 1] 3: [0 1 2] 4: [0 1 2 3]),
            6 => {
                unrolled!(1: [0] 2: [0 1] 3: [0 1 2] 4: [0 1 2 3] 5: [0 1 2 3 4] 6: [0 1 2 3 4 5])
            }
            7 => {
                unrolled!(1: [0] 2: [0 1] 3: [0 1 2] 4: [0 1 2 3] 5: [0 1 2 3 4] 6: [0 1 2 3 4 5] 7: [0 1 2 3 4 5 6])
            }
            8 => {
                unrolled!(1: [0] 2: [0 1] 3: [0 1 2] 4: [0 1 2 3] 5: [0 1 2 3 4] 6: [0 1 2 3 4 5] 7: [0 1 2 3 4 5 6] 8: [0 1 2 3 4 5 6 7])
            }
            9 => {
                unrolled!(1: [0] 2: [0 1] 3: [0 1 2] 4: [0 1 2 3] 5: [0 1 2 3 4] 6: [0 1 2 3 4 5] 7: [0 1 2 3 4 5 6] 8: [0 1 2 3 4 5 6 7] 9: [0 1 2 3 4 5 6 7 8])
            }
            _ => {
                let w = B + 1;
                for t1 in 1..=B {
                    let c1 = rl[B - t1];
                    let row = &mut block[t1 * w..t1 * w + t1];
                    for (r, c) in row.iter_mut().zip(&ra[B - t1..]) {
                        *r -= c1 * c;
                    }
                }
            }
        }
    }

    /// The band-limited LLᵀ of `l` in place, any bandwidth.
    fn factor_generic(&mut self) -> Result<(), ControlError> {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        let l = &mut self.l;
        for i in 0..n {
            // Off-diagonal entries L[i][j], j = i−b..i−1, left to right.
            let j0 = i.saturating_sub(b);
            for j in j0..i {
                let mut s = l[i * w + (i - j)];
                // Σ_k L[i][k]·L[j][k] for k in max(i−b, j−b)..j (j−b ≤ i−b).
                for k in j0..j {
                    s -= l[i * w + (i - k)] * l[j * w + (j - k)];
                }
                l[i * w + (i - j)] = s / l[j * w];
            }
            let mut d = l[i * w];
            for k in j0..i {
                let v = l[i * w + (i - k)];
                d -= v * v;
            }
            if !(d > 0.0 && d.is_finite()) {
                return Err(ControlError::NotPositiveDefinite);
            }
            l[i * w] = d.sqrt();
        }
        Ok(())
    }

    /// The substitutions' data from `l` (the generic LLᵀ): per unknown
    /// `1/L_ii`, the column below it (forward) and the row before it
    /// (backward).
    fn substitution_rows(&mut self) {
        let (n, b, w) = (self.n, self.b, self.b + 1);
        for i in 0..n {
            let inv = 1.0 / self.l[i * w];
            self.fwd[i * w] = inv;
            self.bwd[i * w] = inv;
            for d in 1..=b {
                self.fwd[i * w + d] = if i + d < n {
                    self.l[(i + d) * w + d]
                } else {
                    0.0
                };
                self.bwd[i * w + d] = if d <= i { self.l[i * w + d] } else { 0.0 };
            }
        }
    }

    /// Solves `A·x = rhs` in place (`x` holds rhs on entry), O(n·b).
    ///
    /// Errors with [`ControlError::NotPositiveDefinite`] when no valid
    /// factorisation is held.
    ///
    /// # Panics
    /// If `x` does not have length n.
    pub fn solve_in_place(&self, x: &mut [f64]) -> Result<(), ControlError> {
        assert!(x.len() == self.n, "length mismatch");
        if !self.factored {
            return Err(ControlError::NotPositiveDefinite);
        }
        self.forward(x);
        self.backward(x);
        Ok(())
    }

    /// As [`BandedCholesky::solve_in_place`] for a right-hand side that is
    /// 0 before index `j0` (its entries there are not read): the forward
    /// substitution starts at j0, where the unknowns before it are 0, and
    /// the back substitution runs over all. The same result as the full
    /// solve of that right-hand side.
    ///
    /// # Panics
    /// If `x` does not have length n or j0 > n.
    pub fn solve_in_place_from(&self, x: &mut [f64], j0: usize) -> Result<(), ControlError> {
        self.solve_in_place_cut(x, j0, 0)
    }

    /// Solves `A·x = a` and `A·y = b` in place together: the two
    /// substitutions interleave, so two right-hand sides cost little more
    /// than one (the recurrences are latency-bound). Bit-identical to two
    /// [`BandedCholesky::solve_in_place`] calls.
    ///
    /// # Panics
    /// If `x` or `y` does not have length n.
    pub fn solve2_in_place(&self, x: &mut [f64], y: &mut [f64]) -> Result<(), ControlError> {
        assert!(x.len() == self.n && y.len() == self.n, "length mismatch");
        if !self.factored {
            return Err(ControlError::NotPositiveDefinite);
        }
        match self.b {
            3 => {
                Self::run_band::<3, 2>(&self.fwd, [&mut *x, &mut *y], false);
                Self::run_band::<3, 2>(&self.l, [x, y], true);
            }
            4 => {
                Self::run_band::<4, 2>(&self.fwd, [&mut *x, &mut *y], false);
                Self::run_band::<4, 2>(&self.l, [x, y], true);
            }
            _ => {
                self.solve_in_place(x)?;
                self.solve_in_place(y)?;
            }
        }
        Ok(())
    }

    /// `x ← L⁻¹·x` (LDLᵀ: `x ← D⁻¹·L⁻¹·x`).
    fn forward(&self, x: &mut [f64]) {
        self.substitute(x, false);
    }

    /// `x ← L⁻ᵀ·x`.
    fn backward(&self, x: &mut [f64]) {
        self.substitute(x, true);
    }

    /// One substitution, by the kernel of this factor's bandwidth over its
    /// data (LDLᵀ kernels: `fwd`, or the rows of `l` when `reverse`; the
    /// generic LLᵀ: `fwd` or `bwd`), inlined, so that each caller's
    /// direction is known at compile time.
    #[inline(always)]
    fn substitute(&self, x: &mut [f64], reverse: bool) {
        let data = match (reverse, matches!(self.b, 3 | 4 | 6..=9)) {
            (false, _) => &self.fwd,
            (true, true) => &self.l,
            (true, false) => &self.bwd,
        };
        Self::run(self.b, data, x, reverse);
    }

    /// One substitution over `data` (its unknowns' rows, from x's first)
    /// by the kernel of bandwidth b: compiled for 3, 4 and 6–9, else
    /// [`BandedCholesky::run_generic`].
    #[inline(always)]
    fn run(b: usize, data: &[f64], x: &mut [f64], reverse: bool) {
        match b {
            3 => Self::run_band::<3, 1>(data, [x], reverse),
            4 => Self::run_band::<4, 1>(data, [x], reverse),
            6 => Self::run_band::<6, 1>(data, [x], reverse),
            7 => Self::run_band::<7, 1>(data, [x], reverse),
            8 => Self::run_band::<8, 1>(data, [x], reverse),
            9 => Self::run_band::<9, 1>(data, [x], reverse),
            _ => Self::run_generic(b, data, x, reverse),
        }
    }

    /// A substitution by columns, any bandwidth: in processing order
    /// (ascending, or descending when `reverse`) each unknown is scaled
    /// (`x_i ← r₀·x_i`) and then removed from the b unknowns after it
    /// (`x_{i±t} −= r_t·x_i`).
    fn run_generic(b: usize, data: &[f64], x: &mut [f64], reverse: bool) {
        let (n, w) = (x.len(), b + 1);
        for s in 0..n {
            let i = if reverse { n - 1 - s } else { s };
            let r = &data[i * w..(i + 1) * w];
            let v = x[i] * r[0];
            x[i] = v;
            for (t, &rt) in r.iter().enumerate().take(b.min(n - 1 - s) + 1).skip(1) {
                let k = if reverse { i - t } else { i + t };
                x[k] -= rt * v;
            }
        }
    }

    // Fixed-bandwidth specialisation (B = 3: the DF-MPC; 4: with the
    // command-smoothness term; 6, 8: the cone's pairs; 7, 9: the same one
    // wider), on the unit L of an LDLᵀ factor. The partial sums
    // of the next B unknowns stay in registers (a window shifted by hand);
    // each step's B multiply-subtracts are independent, and only the next
    // unknown's waits for this one — through one multiply-subtract, since
    // L's diagonal is 1: the pivot's scale `1/d_i` (forward) is applied
    // to the output only, off the chain (with the scale on the chain, as
    // `run_generic` does, each unknown waited for a second multiplication:
    // `cargo bench -p dflat-control --bench banded`, fastest solve of 100,
    // two alternating runs: (198, 3) 1.94–1.99 → 1.57–1.60 µs, (396, 6)
    // 4.2–4.7 → 3.7–3.8 µs, (396, 8) 6.8–7.5 → 4.8–5.0 µs). K right-hand
    // sides interleave, each exactly as alone.

    /// Runs the bandwidth-B substitution over `data` (`[r₀, r₁, …, r_B]`
    /// per unknown) in processing order (ascending, or descending when
    /// `reverse`): unit-diagonal, `x_{i±t} −= r_t·x_i`, then `x_i ← r₀·x_i`
    /// going forward (`1/d_i`) and `x_i` as it is going back (r₀ ignored:
    /// `l`'s diagonal slot holds d_i).
    fn run_band<const B: usize, const K: usize>(data: &[f64], xs: [&mut [f64]; K], reverse: bool) {
        if reverse {
            Self::run_band_in::<B, K, true>(data, xs);
        } else {
            Self::run_band_in::<B, K, false>(data, xs);
        }
    }

    /// [`BandedCholesky::run_band`] with the direction at compile time.
    #[inline(always)]
    fn run_band_in<const B: usize, const K: usize, const REVERSE: bool>(
        data: &[f64],
        xs: [&mut [f64]; K],
    ) {
        let mut xs = xs;
        let n = xs[0].len();
        let at = |s: usize| if REVERSE { n - 1 - s } else { s };
        // win[t] = the partial sum of the unknown t steps ahead.
        let mut win = [[0.0f64; B]; K];
        for (x, wk) in xs.iter().zip(win.iter_mut()) {
            for (t, v) in wk.iter_mut().enumerate().take(n) {
                *v = x[at(t)];
            }
        }
        let step = |r: &[f64], x: &mut [f64], wk: &mut [f64; B], i: usize, next: f64| {
            let v = wk[0];
            x[i] = if REVERSE { v } else { v * r[0] };
            for t in 0..B - 1 {
                wk[t] = wk[t + 1] - r[t + 1] * v;
            }
            wk[B - 1] = next - r[B] * v;
        };
        // The bulk, where the unknown B ahead exists, then the last B.
        let bulk = n.saturating_sub(B);
        for s in 0..bulk {
            let i = at(s);
            let r = &data[(B + 1) * i..(B + 1) * (i + 1)];
            let ahead = at(s + B);
            for (x, wk) in xs.iter_mut().zip(win.iter_mut()) {
                let next = x[ahead];
                step(r, x, wk, i, next);
            }
        }
        for s in bulk..n {
            let i = at(s);
            let r = &data[(B + 1) * i..(B + 1) * (i + 1)];
            for (x, wk) in xs.iter_mut().zip(win.iter_mut()) {
                step(r, x, wk, i, 0.0);
            }
        }
    }
}

#[cfg(test)]
mod tests;
