//! A solve whose back substitution stops short ([`BandedCholesky::solve_in_place_cut`])
//! and its rest, done later for a sum of such solves
//! ([`BandedCholesky::extend_back`]): the augmented Lagrangian's window,
//! whose steps need the head's part of each step only near the window.

use super::BandedCholesky;
use crate::ControlError;

impl BandedCholesky {
    /// Whether [`BandedCholesky::solve_in_place_cut`] can stop short at
    /// this bandwidth (the LDLᵀ kernels': 3, 4, 6–9).
    pub fn can_cut(&self) -> bool {
        matches!(self.b, 3 | 4 | 6..=9)
    }

    /// As [`BandedCholesky::solve_in_place_from`] (a right-hand side 0
    /// before `j0`), the back substitution stopped at `cut` ≤ j0: x's
    /// entries from `cut` on are that solve's, bit for bit, those before
    /// it 0. Their values are linear in x's b entries from `cut` on
    /// ([`BandedCholesky::extend_back`]). Without [`BandedCholesky::can_cut`]
    /// the whole solve; `cut` = 0 is the whole solve.
    ///
    /// # Panics
    /// If `x` does not have length n, or cut > j0 > n.
    pub fn solve_in_place_cut(
        &self,
        x: &mut [f64],
        j0: usize,
        cut: usize,
    ) -> Result<(), ControlError> {
        assert!(
            x.len() == self.n && cut <= j0 && j0 <= self.n,
            "length mismatch"
        );
        if !self.factored {
            return Err(ControlError::NotPositiveDefinite);
        }
        x[..j0].fill(0.0);
        let w = self.b + 1;
        Self::run(self.b, &self.fwd[j0 * w..], &mut x[j0..], false);
        if self.can_cut() {
            Self::run(self.b, &self.l[cut * w..], &mut x[cut..], true);
        } else {
            self.backward(x);
        }
        Ok(())
    }

    /// The rest of a solve stopped at `cut`: x's entries before `cut` from
    /// its b entries from `cut` on, as the back substitution of a
    /// right-hand side 0 before `cut` gives them (`x_j = −Σ_s l_{j+s,j}·
    /// x_{j+s}`). Linear in those b entries, so it serves a sum of solves
    /// of one factor at once. Needs [`BandedCholesky::can_cut`] (else
    /// nothing changes); agrees with the whole back substitution to
    /// rounding (the sums run in another order).
    ///
    /// # Panics
    /// If `x` does not have length n or cut > n.
    pub fn extend_back(&self, x: &mut [f64], cut: usize) {
        assert!(x.len() == self.n && cut <= self.n, "length mismatch");
        if !self.can_cut() {
            return;
        }
        let (n, b, w) = (self.n, self.b, self.b + 1);
        for j in (0..cut).rev() {
            let mut s = 0.0;
            for t in 1..=b.min(n - 1 - j) {
                s += self.l[(j + t) * w + t] * x[j + t];
            }
            x[j] = -s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{BandedCholesky, SymBand};

    /// A banded SPD matrix whose inverse decays slowly along the band (a
    /// second difference plus 0.2·I, small pseudo-random entries further
    /// out), as the Newton matrices' head does.
    fn matrix(n: usize, b: usize) -> SymBand {
        let mut a = SymBand::zeros(n, b);
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for i in 0..n {
            a.set(i, i, 2.2);
            for d in 1..=b.min(i) {
                a.set(i, i - d, if d == 1 { -1.0 } else { 0.02 * next() });
            }
        }
        a
    }

    /// Stopped at `cut`, the solve's entries from `cut` on are the whole
    /// solve's bit for bit and those before it 0; `extend_back` of the sum
    /// of two such solves gives the sum of the whole solves before `cut`.
    #[test]
    fn a_solve_stopped_short_and_extended_is_the_whole_solve() {
        for b in [3, 4, 6, 7] {
            let (n, j0, cut) = (80, 50, 41);
            let mut chol = BandedCholesky::new(n, b);
            chol.factor(&matrix(n, b)).unwrap();
            assert!(chol.can_cut());
            let rhs = |k: f64| -> Vec<f64> {
                (0..n)
                    .map(|i| if i < j0 { 9.0 } else { (k * i as f64).sin() })
                    .collect()
            };
            let (mut sum_whole, mut sum_cut) = (vec![0.0; n], vec![0.0; n]);
            for (k, alpha) in [(0.3, 1.0), (1.7, 0.25)] {
                let mut whole = rhs(k);
                chol.solve_in_place_from(&mut whole, j0).unwrap();
                let mut short = rhs(k);
                chol.solve_in_place_cut(&mut short, j0, cut).unwrap();
                assert_eq!(short[cut..], whole[cut..], "b = {b}");
                assert!(short[..cut].iter().all(|v| *v == 0.0));
                for i in 0..n {
                    sum_whole[i] += alpha * whole[i];
                    sum_cut[i] += alpha * short[i];
                }
            }
            chol.extend_back(&mut sum_cut, cut);
            for i in 0..cut {
                let tol = 1e-13 * (1.0 + sum_whole[i].abs());
                assert!(
                    (sum_cut[i] - sum_whole[i]).abs() <= tol,
                    "b = {b}, x_{i}: {} vs {}",
                    sum_cut[i],
                    sum_whole[i]
                );
            }
            assert!(
                sum_whole[..cut].iter().any(|v| v.abs() > 1e-3),
                "the head moves"
            );
        }
    }
}
