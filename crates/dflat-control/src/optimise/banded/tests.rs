//! Tests of the banded matrices and their factors.

use super::*;
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

fn to_dense(a: &SymBand) -> DMatrix<f64> {
    DMatrix::from_fn(a.n(), a.n(), |i, j| a.get(i, j))
}

#[test]
fn solves_a_tridiagonal_system() {
    let n = 6;
    let mut a = SymBand::zeros(n, 1);
    for i in 0..n {
        a.set(i, i, 2.0);
        if i > 0 {
            a.set(i, i - 1, -1.0);
        }
    }
    let mut f = BandedCholesky::new(n, 1);
    f.factor(&a).unwrap();
    let x_true: Vec<f64> = (0..n).map(|i| i as f64 - 2.5).collect();
    let mut x = vec![0.0; n];
    a.mul_vec(&x_true, &mut x);
    f.solve_in_place(&mut x).unwrap();
    for (u, v) in x.iter().zip(&x_true) {
        assert!((u - v).abs() < 1e-12);
    }
}

#[test]
fn indefinite_is_an_error() {
    let mut a = SymBand::zeros(3, 1);
    a.set(0, 0, 1.0);
    a.set(1, 0, 2.0);
    a.set(1, 1, 1.0);
    a.set(2, 2, 1.0);
    let mut f = BandedCholesky::new(3, 1);
    assert_eq!(f.factor(&a), Err(ControlError::NotPositiveDefinite));
    assert!(!f.is_factored());
    let mut x = [1.0, 1.0, 1.0];
    assert_eq!(
        f.solve_in_place(&mut x),
        Err(ControlError::NotPositiveDefinite)
    );
    a.set(2, 2, f64::NAN);
    a.set(1, 0, 0.0);
    assert_eq!(f.factor(&a), Err(ControlError::NotPositiveDefinite));
}

#[test]
fn mul_vec_matches_dense() {
    let mut a = SymBand::zeros(5, 2);
    for i in 0..5usize {
        for j in i.saturating_sub(2)..=i {
            a.set(i, j, (1 + i * 5 + j) as f64);
        }
    }
    let x = [1.0, -2.0, 0.5, 3.0, -1.0];
    let mut y = [0.0; 5];
    a.mul_vec(&x, &mut y);
    let yd = to_dense(&a) * DVector::from_row_slice(&x);
    for i in 0..5 {
        assert!((y[i] - yd[i]).abs() < 1e-12);
    }
}

/// `M·Mᵀ + I`, SPD with half-bandwidth b, M lower-banded from `seed`
/// (10 per row).
fn spd_dense(n: usize, b: usize, seed: &[f64]) -> DMatrix<f64> {
    let mut m = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        for d in 0..=b.min(i) {
            m[(i, i - d)] = seed[i * 10 + d];
        }
    }
    &m * m.transpose() + DMatrix::identity(n, n)
}

/// The band of half-width b of `dense`.
fn band_of(dense: &DMatrix<f64>, b: usize) -> SymBand {
    let n = dense.nrows();
    let mut a = SymBand::zeros(n, b);
    for i in 0..n {
        for j in i.saturating_sub(b)..=i {
            a.set(i, j, dense[(i, j)]);
        }
    }
    a
}

/// [`spd_dense`] in a band.
fn spd_band(n: usize, b: usize, seed: &[f64]) -> SymBand {
    band_of(&spd_dense(n, b, seed), b)
}

/// `a` plus an SPD band from `change` on its trailing block (rows and
/// columns j0 and after): still SPD, changed from column j0 on (its
/// diagonal there grows by at least 1).
fn with_trailing_change(a: &SymBand, j0: usize, change: &[f64]) -> SymBand {
    let (n, b) = (a.n(), a.bandwidth());
    let t = spd_band(n - j0, b, change);
    let mut a2 = a.clone();
    for i in j0..n {
        for j in i.saturating_sub(b).max(j0)..=i {
            a2.add(i, j, t.get(i - j0, j - j0));
        }
    }
    a2
}

proptest! {
    /// `refactor_taking` after a change in the trailing block (rows and
    /// columns j0 and after, kept SPD) reports j0 — the first changed
    /// column — and holds bit for bit the factor a fresh `factor` of
    /// the changed matrix gives: L, D and the substitutions' data. The
    /// same matrix again is recognised (n), and a solve agrees.
    #[test]
    fn refactor_from_the_first_changed_column_is_a_fresh_factor(
        n in 1usize..60,
        b in prop::sample::select(vec![1usize, 3, 4, 6, 7, 8, 9]),
        cut in 0.0f64..1.0,
        seed in proptest::collection::vec(-1.0f64..1.0, 60 * 10),
        change in proptest::collection::vec(-1.0f64..1.0, 60 * 10),
    ) {
        let a = spd_band(n, b, &seed);
        let mut f = BandedCholesky::new(n, b);
        prop_assert_eq!(f.refactor_taking(&mut a.clone()).unwrap(), 0);
        prop_assert_eq!(f.refactor_taking(&mut a.clone()).unwrap(), n);
        // A second SPD band added on the trailing block only.
        let j0 = ((n as f64) * cut) as usize;
        let a2 = with_trailing_change(&a, j0, &change);
        let got = f.refactor_taking(&mut a2.clone()).unwrap();
        // The reported column is the first changed one (j0: the
        // trailing block's diagonal grew by at least 1), or 0 for the
        // bandwidths that factor afresh.
        let first = (0..n)
            .flat_map(|i| (i.saturating_sub(b)..=i).map(move |j| (i, j)))
            .filter(|&(i, j)| a.get(i, j).to_bits() != a2.get(i, j).to_bits())
            .map(|(_, j)| j)
            .min()
            .unwrap();
        prop_assert_eq!(first, j0);
        prop_assert_eq!(got, if [3, 4, 6, 7, 8, 9].contains(&b) { j0 } else { 0 });
        let mut fresh = BandedCholesky::new(n, b);
        fresh.factor(&a2).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&f.l), bits(&fresh.l));
        prop_assert_eq!(bits(&f.fwd), bits(&fresh.fwd));
        prop_assert_eq!(bits(&f.bwd), bits(&fresh.bwd));
        prop_assert_eq!(bits(&f.cols), bits(&fresh.cols));
        let mut x: Vec<f64> = change[..n].to_vec();
        let mut y = x.clone();
        f.solve_in_place(&mut x).unwrap();
        fresh.solve_in_place(&mut y).unwrap();
        prop_assert_eq!(bits(&x), bits(&y));
    }

    /// `refactor_rows_from(a, from)` reads only `a`'s rows from `from`
    /// on (the rows before are garbage here): with the held matrix's
    /// rows before them, it holds bit for bit the fresh factor of the
    /// whole, and reports the first changed column (≥ from − b).
    #[test]
    fn refactor_rows_from_reads_the_rows_given(
        n in 2usize..60,
        b in prop::sample::select(vec![3usize, 4, 6, 8]),
        cut in 0.0f64..1.0,
        seed in proptest::collection::vec(-1.0f64..1.0, 60 * 10),
        change in proptest::collection::vec(-1.0f64..1.0, 60 * 10),
    ) {
        let a = spd_band(n, b, &seed);
        let mut f = BandedCholesky::new(n, b);
        f.refactor_taking(&mut a.clone()).unwrap();
        let from = ((n as f64) * cut) as usize;
        let a2 = with_trailing_change(&a, from, &change);
        let mut given = a2.clone();
        let w = b + 1;
        given.lower_mut()[..from * w].fill(f64::NAN);
        let got = f.refactor_rows_from(&given, from).unwrap();
        prop_assert_eq!(got, from);
        let mut fresh = BandedCholesky::new(n, b);
        fresh.factor(&a2).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&f.l), bits(&fresh.l));
        prop_assert_eq!(bits(&f.fwd), bits(&fresh.fwd));
        prop_assert_eq!(bits(&f.cols), bits(&fresh.cols));
        // The same rows again: nothing to do.
        prop_assert_eq!(f.refactor_rows_from(&given, from).unwrap(), n);
    }

    /// `solve_in_place_from(x, j0)` is the full solve of the
    /// right-hand side that is 0 before j0.
    #[test]
    fn a_solve_from_j0_is_the_full_solve_of_a_zero_head(
        n in 1usize..60,
        b in prop::sample::select(vec![1usize, 3, 4, 6, 8]),
        cut in 0.0f64..1.0,
        seed in proptest::collection::vec(-1.0f64..1.0, 60 * 10),
        rhs in proptest::collection::vec(-10.0f64..10.0, 60),
    ) {
        let a = spd_band(n, b, &seed);
        let mut f = BandedCholesky::new(n, b);
        f.factor(&a).unwrap();
        let j0 = ((n as f64) * cut) as usize;
        let mut full: Vec<f64> = rhs[..n].to_vec();
        full[..j0].fill(0.0);
        let mut from = rhs[..n].to_vec();
        f.solve_in_place(&mut full).unwrap();
        f.solve_in_place_from(&mut from, j0).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        prop_assert_eq!(bits(&from), bits(&full));
    }

    /// A factor that failed (not positive definite) is not reused: the
    /// next refactor starts afresh.
    #[test]
    fn refactor_after_a_failure_starts_afresh(
        n in 2usize..30,
        seed in proptest::collection::vec(-1.0f64..1.0, 30 * 10),
    ) {
        let a = spd_band(n, 6, &seed);
        let mut f = BandedCholesky::new(n, 6);
        f.refactor_taking(&mut a.clone()).unwrap();
        let mut bad = a.clone();
        bad.set(n - 1, n - 1, -1.0);
        prop_assert_eq!(f.refactor_taking(&mut bad.clone()), Err(ControlError::NotPositiveDefinite));
        prop_assert!(!f.is_factored());
        prop_assert_eq!(f.refactor_taking(&mut a.clone()).unwrap(), 0);
        prop_assert!(f.is_factored());
    }
}

proptest! {
    /// A = M·Mᵀ + I with M lower-banded is SPD with the same band; the
    /// banded solve agrees with nalgebra's dense Cholesky.
    #[test]
    fn agrees_with_dense_cholesky(
        n in 1usize..40,
        b in 0usize..10,
        seed in proptest::collection::vec(-1.0f64..1.0, 40 * 10),
        rhs in proptest::collection::vec(-10.0f64..10.0, 40),
    ) {
        let dense = spd_dense(n, b, &seed);
        let a = band_of(&dense, b);
        prop_assert_eq!(to_dense(&a), dense.clone());
        let mut f = BandedCholesky::new(n, b);
        f.factor(&a).unwrap();
        let mut x = rhs[..n].to_vec();
        f.solve_in_place(&mut x).unwrap();
        let xd = dense.cholesky().unwrap().solve(&DVector::from_row_slice(&rhs[..n]));
        for i in 0..n {
            prop_assert!((x[i] - xd[i]).abs() <= 1e-10 * (1.0 + xd[i].abs()), "i={} {} vs {}", i, x[i], xd[i]);
        }
        // Two right-hand sides at once give the same answers bit for bit.
        // (b = 3, 4 run the specialised two-sided loop, others the
        // generic one.)
        let mut y1 = rhs[..n].to_vec();
        let mut y2: Vec<f64> = rhs[..n].iter().map(|v| -2.0 * v).collect();
        f.solve2_in_place(&mut y1, &mut y2).unwrap();
        let mut x2: Vec<f64> = rhs[..n].iter().map(|v| -2.0 * v).collect();
        f.solve_in_place(&mut x2).unwrap();
        prop_assert_eq!(&y1, &x);
        prop_assert_eq!(&y2, &x2);
        // Taking the matrix's storage factors the same matrix
        // (b = 6 … 9 run the fixed-bandwidth factorisation).
        let mut g = BandedCholesky::new(n, b);
        let mut taken = a.clone();
        g.factor_taking(&mut taken).unwrap();
        let mut x3 = rhs[..n].to_vec();
        g.solve_in_place(&mut x3).unwrap();
        prop_assert_eq!(&x3, &x);
    }
}

#[test]
fn ldl_solves_a_quasi_definite_band() {
    // [[4, 1, 2], [1, 3, 0], [2, 0, −5]] (half-bandwidth 2).
    let mut a = SymBand::zeros(3, 2);
    a.set(0, 0, 4.0);
    a.set(1, 0, 1.0);
    a.set(2, 0, 2.0);
    a.set(1, 1, 3.0);
    a.set(2, 2, -5.0);
    let mut ldl = BandedLdl::new(3, 2);
    ldl.factor(&a).unwrap();
    let want = [1.0, -2.0, 0.5];
    let mut x = [0.0; 3];
    a.mul_vec(&want, &mut x);
    ldl.solve(&mut x);
    for (g, w) in x.iter().zip(want) {
        assert!((g - w).abs() < 1e-12, "{x:?}");
    }
    let mut singular = SymBand::zeros(2, 1);
    singular.set(0, 0, 1.0);
    singular.set(1, 0, 1.0);
    singular.set(1, 1, 1.0);
    assert!(BandedLdl::new(2, 1).factor(&singular).is_err());
}
