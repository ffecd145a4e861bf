//! Unit tests of [`BandedAlm`] (module docs of [`super`]).

use super::*;

fn pair(n: usize) -> BandedAlm {
    let axis = || FastBandedSolver::new(n + 2, 1.0, 1e-4, 0.02).unwrap();
    BandedAlm::new(
        vec![axis(), axis()],
        0.02,
        StageSet::Disc(vec![3.0; n]),
        Vec::new(),
        AlmTuning::default(),
    )
}

/// The warm start extrapolates each stage multiplier from the last two
/// solves where both are non-zero and no axis changes sign, shifts it
/// elsewhere, and only shifts after an aged (skipped) tick.
#[test]
fn shift_extrapolates_the_multipliers_of_consecutive_solves() {
    let n = 6;
    let mut alm = pair(n);
    // Solve k − 1 (stage f at 10·f), then its shift: nothing to
    // extrapolate from yet.
    let older: Vec<[f64; 2]> = (0..n).map(|f| [10.0 * f as f64, -1.0]).collect();
    alm.warm.y.copy_from_slice(&older);
    alm.shift();
    assert_eq!(alm.warm.y[0], older[1]);
    assert_eq!(alm.warm.y[n - 1], older[n - 1]);
    // Solve k: stage f − 1 now carries what stage f did, changed.
    let mut last: Vec<[f64; 2]> = (0..n)
        .map(|f| [10.0 * (f + 1) as f64 + 1.0, -2.0])
        .collect();
    last[3] = [0.0; 2]; // inactive in solve k
    last[4] = [5.0, 3.0]; // the prediction (−40, 7) flips both axes
    alm.warm.y.copy_from_slice(&last);
    alm.shift();
    // f = 0: 2·last[1] − older[2] = 2·(21, −2) − (20, −1) = (22, −3).
    assert_eq!(alm.warm.y[0], [22.0, -3.0]);
    assert_eq!(alm.warm.y[1], [2.0 * 31.0 - 30.0, -3.0]);
    // last[3] = 0, and last[4]'s prediction flips: shifted only.
    assert_eq!(alm.warm.y[2], last[3]);
    assert_eq!(alm.warm.y[3], last[4]);
    // The last stages have no partner two solves back.
    assert_eq!(alm.warm.y[4], last[5]);
    assert_eq!(alm.warm.y[5], last[5]);
    // A tick without a solve: the next shift does not extrapolate.
    alm.age();
    let after = alm.warm.y.clone();
    alm.shift();
    assert_eq!(alm.warm.y[0], after[1]);
    assert_eq!(alm.warm.y[1], after[2]);
}

/// The warm start shifts the row multipliers a stage on within each row
/// block, but each block's first row (the one on the window and the sent
/// command) keeps its own, and the last row keeps its own too.
#[test]
fn shift_keeps_each_blocks_first_row_multiplier() {
    let n = 6;
    let dt = 0.02;
    let axis = || FastBandedSolver::new(n + 2, 1.0, 1e-4, dt).unwrap();
    let blocks = (0..2)
        .map(|a| RowBlock {
            rows: (0..n)
                .map(|f| {
                    super::super::bounds::Row::tilt_rate(f, 5.0, |s| s)
                        .on_outputs(1.0 / (dt * dt), |k| 2 * k + a)
                })
                .collect(),
            scale: 1.0,
            penalty: f64::INFINITY,
        })
        .collect();
    let mut alm = BandedAlm::new(
        vec![axis(), axis()],
        dt,
        StageSet::Disc(vec![3.0; n]),
        blocks,
        AlmTuning::default(),
    );
    let v: Vec<[f64; 2]> = (0..2 * n)
        .map(|r| [100.0 + r as f64, 200.0 + r as f64])
        .collect();
    alm.warm.v.copy_from_slice(&v);
    alm.shift();
    for block in [0..n, n..2 * n] {
        let (start, end) = (block.start, block.end);
        assert_eq!(alm.warm.v[start], v[start], "first row of {start}..{end}");
        for r in start + 1..end - 1 {
            assert_eq!(alm.warm.v[r], v[r + 1], "row {r}");
        }
        assert_eq!(
            alm.warm.v[end - 1],
            v[end - 1],
            "last row of {start}..{end}"
        );
    }
}
