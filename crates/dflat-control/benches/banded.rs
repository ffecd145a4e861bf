//! The banded kernels under the constrained solvers, alone: the Cholesky
//! factorisation and one solve of an n×n positive-definite band of
//! half-bandwidth b, for the shapes the augmented Lagrangian factors at
//! N = 200 (one axis: n = 198, b = 3 or 4; the cone's pair, interleaved:
//! n = 396, b = 6 or 8; until 2026-11-26 the band was built one wider, 7
//! or 9, which are kept for comparison).
//!
//! Run: `cargo bench -p dflat-control --bench banded`.

#![allow(missing_docs)]

use dflat_control::optimise::banded::{BandedCholesky, SymBand};
use divan::{Bencher, black_box};

fn main() {
    divan::main();
}

const SHAPES: [(usize, usize); 6] = [(198, 3), (198, 4), (396, 6), (396, 7), (396, 8), (396, 9)];

/// A diagonally dominant band with entries that vary along it.
fn matrix(n: usize, b: usize) -> SymBand {
    let mut a = SymBand::zeros(n, b);
    for i in 0..n {
        for d in 1..=b.min(i) {
            a.set(i, i - d, -1.0 / (d as f64 + (i % 7) as f64 * 0.1));
        }
    }
    for i in 0..n {
        let s: f64 = (0..n)
            .filter(|&j| j != i && i.abs_diff(j) <= b)
            .map(|j| a.get(i, j).abs())
            .sum();
        a.set(i, i, s + 1.0 + (i % 5) as f64);
    }
    a
}

#[divan::bench(args = SHAPES)]
fn factor(bencher: Bencher, (n, b): (usize, usize)) {
    let a = matrix(n, b);
    let mut chol = BandedCholesky::new(n, b);
    bencher.bench_local(|| chol.factor(black_box(&a)).unwrap());
}

#[divan::bench(args = SHAPES)]
fn solve(bencher: Bencher, (n, b): (usize, usize)) {
    let a = matrix(n, b);
    let mut chol = BandedCholesky::new(n, b);
    chol.factor(&a).unwrap();
    let mut x = vec![1.0; n];
    bencher.bench_local(|| chol.solve_in_place(black_box(&mut x)).unwrap());
}

/// The polish's KKT shapes (quasi-definite): N = 200, stride 3 (b = 14)
/// and 4 with speed rows (b = 19).
const LDL_SHAPES: [(usize, usize); 2] = [(594, 14), (792, 19)];

fn kkt(n: usize, b: usize) -> SymBand {
    let mut a = matrix(n, b);
    for i in (1..n).step_by(3) {
        let v = a.get(i, i);
        a.set(i, i, -v);
    }
    a
}

#[divan::bench(args = LDL_SHAPES)]
fn ldl_factor(bencher: Bencher, (n, b): (usize, usize)) {
    let a = kkt(n, b);
    let mut ldl = dflat_control::optimise::banded::BandedLdl::new(n, b);
    bencher.bench_local(|| ldl.factor(black_box(&a)).unwrap());
}

#[divan::bench(args = LDL_SHAPES)]
fn ldl_solve(bencher: Bencher, (n, b): (usize, usize)) {
    let a = kkt(n, b);
    let mut ldl = dflat_control::optimise::banded::BandedLdl::new(n, b);
    ldl.factor(&a).unwrap();
    let mut x = vec![1.0; n];
    bencher.bench_local(|| ldl.solve(black_box(&mut x)));
}
