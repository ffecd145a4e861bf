//! The command-smoothness term of [`DfMpc`] ([`Smoothness`]): the banded
//! fast path against a dense solve of the same cost written out from its
//! definition, clarabel against the fast path, and its effect in closed
//! loop on noisy positions.

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::optimise::{
    AxisBounds, AxisProblem, ClarabelSolver, FastBandedSolver, Smoothness,
};
use dflat_control::{ControlError, ControlModel, Controller, Frame, Measurement};
use dflat_model::{FlatModel, PlanarModel, PlanarParams};
use nalgebra::{DMatrix, DVector, SVector, Vector2, Vector3};

mod common;
use common::{DT, G, Noise, Setpoint};

/// The optimum from the definition: stack every cost term as a weighted
/// least-squares row over the free outputs y_3..y_N (y_0..y_2 moved to the
/// right-hand side) and solve by QR (no normal equations).
fn dense_optimum(
    n: usize,
    q: f64,
    r: f64,
    sm: Smoothness,
    fixed: [f64; 3],
    sent: f64,
    reference: &[f64],
) -> Vec<f64> {
    let free = n - 2;
    let mut rows: Vec<(Vec<f64>, f64)> = Vec::new();
    // A row Σ coeffs[a]·y_{j+a} = target, weight √w: split fixed/free.
    let mut push = |j0: usize, coeffs: &[f64], target: f64, w: f64| {
        let mut row = vec![0.0; free];
        let mut b = target;
        for (a, &c) in coeffs.iter().enumerate() {
            let j = j0 + a;
            if j < 3 {
                b -= c * fixed[j];
            } else {
                row[j - 3] += c;
            }
        }
        let sw = w.sqrt();
        rows.push((row.iter().map(|v| v * sw).collect(), b * sw));
    };
    for (j, &rj) in reference.iter().enumerate().take(n + 1) {
        push(j, &[1.0], rj, q);
    }
    let w3 = r / DT.powi(6);
    for j in 0..=n - 3 {
        push(j, &[-1.0, 3.0, -3.0, 1.0], 0.0, w3);
    }
    // c_j·δt² = Δ²y_j + κ·Δ³y_j on y_j..y_{j+3}.
    let k = sm.kappa;
    let c = [1.0 - k, -2.0 + 3.0 * k, 1.0 - 3.0 * k, k];
    let ws = sm.weight / (G * G) / DT.powi(4);
    // j = 0: (c_0 − c_{−1}) with c_{−1} = sent.
    push(0, &c, sent * DT * DT, ws);
    for j in 1..=n - 3 {
        // c_j − c_{j−1} on y_{j−1}..y_{j+3}.
        let mut d = [0.0; 5];
        for a in 0..4 {
            d[a + 1] += c[a];
            d[a] -= c[a];
        }
        push(j - 1, &d, 0.0, ws);
    }
    let a = DMatrix::from_fn(rows.len(), free, |i, j| rows[i].0[j]);
    let b = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.1));
    let x = a.svd(true, true).solve(&b, 1e-300).unwrap();
    let mut y = fixed.to_vec();
    y.extend(x.iter());
    y
}

fn smoothness(weight: f64) -> Smoothness {
    Smoothness {
        weight,
        kappa: 0.2 / DT,
        gravity: G,
    }
}

/// The banded O(N) solve (half-bandwidth 4, refined) equals the dense
/// least-squares optimum of the cost as defined, including the first term
/// tied to the sent command.
#[test]
fn smooth_fast_path_matches_dense_optimum() {
    let n = 60;
    let reference: Vec<f64> = (0..=n).map(|j| 4.0 + 0.05 * j as f64).collect();
    for (weight, fixed, sent) in [
        (1.0, [0.0, 0.01, 0.03], 0.0),
        (10.0, [1.0, 1.05, 1.11], 3.0),
        (0.3, [-2.0, -2.0, -1.99], -6.0),
    ] {
        let sm = smoothness(weight);
        let mut solver = FastBandedSolver::with_smoothness(n, 1.0, 0.01, DT, sm).unwrap();
        let mut plan = vec![0.0; n + 1];
        solver
            .solve_problem(AxisProblem {
                fixed: &fixed,
                sent: Some(sent),
                reference: &reference,
                plan: &mut plan,
            })
            .unwrap();
        let exact = dense_optimum(n, 1.0, 0.01, sm, fixed, sent, &reference);
        for j in 0..=n {
            let err = (plan[j] - exact[j]).abs();
            assert!(
                err < 1e-9 * (1.0 + exact[j].abs()),
                "s = {weight}, y_{j}: {} vs {} ({err:e})",
                plan[j],
                exact[j]
            );
        }
        // The sent command matters: another one moves y*_3.
        let mut other = vec![0.0; n + 1];
        solver
            .solve_problem(AxisProblem {
                fixed: &fixed,
                sent: Some(sent + 1.0),
                reference: &reference,
                plan: &mut other,
            })
            .unwrap();
        assert!((other[3] - plan[3]).abs() > 1e-7, "s = {weight}");
    }
}

/// Weight 0 is the paper's problem, bit for bit.
#[test]
fn zero_smoothness_is_the_plain_problem() {
    let n = 100;
    let reference = vec![10.0; n + 1];
    let fixed = [0.5, 0.52, 0.55];
    let mut plain = FastBandedSolver::new(n, 5.0, 0.01, DT).unwrap();
    let mut zero = FastBandedSolver::with_smoothness(n, 5.0, 0.01, DT, smoothness(0.0)).unwrap();
    let (mut a, mut b) = (vec![0.0; n + 1], vec![0.0; n + 1]);
    plain.solve(&fixed, &reference, &mut a).unwrap();
    zero.solve_problem(AxisProblem {
        fixed: &fixed,
        sent: Some(1.0),
        reference: &reference,
        plan: &mut b,
    })
    .unwrap();
    assert_eq!(a, b);
}

/// clarabel carries the same term: without bounds it agrees with the fast
/// path; with a binding bound the plan respects it.
#[test]
fn smooth_clarabel_agrees_with_fast_path() {
    let n = 80;
    let sm = smoothness(5.0);
    let reference = vec![10.0; n + 1];
    let fixed = [1.0, 1.05, 1.11];
    fn problem<'a>(
        fixed: &'a [f64; 3],
        reference: &'a [f64],
        plan: &'a mut [f64],
    ) -> AxisProblem<'a> {
        AxisProblem {
            fixed,
            sent: Some(2.0),
            reference,
            plan,
        }
    }
    let mut fast = FastBandedSolver::with_smoothness(n, 1.0, 0.08, DT, sm).unwrap();
    let mut generic =
        ClarabelSolver::with_smoothness(n, 1.0, 0.08, DT, AxisBounds::default(), f64::INFINITY, sm)
            .unwrap();
    let (mut a, mut b) = (vec![0.0; n + 1], vec![0.0; n + 1]);
    fast.solve_problem(problem(&fixed, &reference, &mut a))
        .unwrap();
    generic
        .solve_problem(problem(&fixed, &reference, &mut b))
        .unwrap();
    for j in 0..=n {
        assert!(
            (a[j] - b[j]).abs() < 1e-5 * (1.0 + a[j].abs()),
            "y_{j}: {} vs {}",
            a[j],
            b[j]
        );
    }
    let bounds = AxisBounds {
        acceleration: Some([-2.0, 2.0]),
        ..Default::default()
    };
    let mut bounded =
        ClarabelSolver::with_smoothness(n, 1.0, 0.08, DT, bounds, f64::INFINITY, sm).unwrap();
    assert!(bounds.violated_by(&a, DT));
    bounded
        .solve_problem(problem(&fixed, &reference, &mut b))
        .unwrap();
    let relaxed = AxisBounds {
        acceleration: Some([-2.0001, 2.0001]),
        ..Default::default()
    };
    assert!(!relaxed.violated_by(&b, DT));
}

/// Mean |Δu| [deg/tick] and mean error after `settle` ticks of a noisy
/// closed loop (plant = the planar model's Euler step, σ per axis at every
/// tick: the paper's §VI noise, in 2-D).
fn noisy_run(weight: f64, sigma: f64) -> (f64, f64) {
    let plant = PlanarModel::new(PlanarParams {
        psi: 0.6,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap();
    let settings = DfMpcSettings {
        smoothness_weight: [weight; 3],
        ..DfMpcSettings::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Planar(plant), settings).unwrap();
    let target = Vector3::new(4.0, -3.0, -2.0);
    let mut reference = Setpoint(target);
    let mut noise = Noise(3);
    let mut x = SVector::<f64, 6>::zeros();
    let (mut du, mut err, mut n) = (0.0, 0.0, 0);
    let mut prev: Option<Vector2<f64>> = None;
    for k in 0..1500 {
        let y = plant.output(&x);
        let m = Measurement {
            t: k as f64 * DT,
            position: Vector3::new(
                y.x + sigma * noise.normal(),
                y.y + sigma * noise.normal(),
                -2.0,
            ),
            yaw: 0.6,
        };
        let out = ctrl.update(&m, &mut reference).unwrap();
        let u = Vector2::new(out.command.pitch, out.command.roll);
        if k >= 500 {
            du += (u - prev.unwrap()).norm().to_degrees();
            err += (Vector2::new(y.x, y.y) - target.xy()).norm();
            n += 1;
        }
        prev = Some(u);
        x = plant.step(&x, &u);
    }
    (du / n as f64, err / n as f64)
}

/// On 50 Hz positions with 0.5 mm noise (motion-capture grade), holding a
/// setpoint after the step: the weight cuts the mean command change per
/// tick by more than half (measured 4.2 → 1.3°/tick at s = 100) while the
/// error stays below a centimetre.
///
/// The term is linearised about hover: it acts where the window's
/// accelerations are physical. With a 50 Hz window and noise ≥ 1 mm the
/// fixed second difference alone is ±6…30 m/s² (the command saturates
/// whatever the plan), which no cost on the plan removes: that is what the
/// multi-rate window is for (see `df_multirate`).
#[test]
fn smoothness_reduces_command_changes_on_noisy_run() {
    let (du0, e0) = noisy_run(0.0, 0.0005);
    let (du1, e1) = noisy_run(100.0, 0.0005);
    eprintln!("s = 0: |Δu| {du0:.2}°/tick, error {e0:.4} m; s = 100: {du1:.2}°/tick, {e1:.4} m");
    assert!(du1 < 0.5 * du0, "|Δu| {du1} vs {du0} without smoothness");
    assert!(e1 < 0.01, "mean error {e1} m with smoothness");
}

#[test]
fn smoothness_weight_is_validated() {
    let model = ControlModel::Planar(PlanarModel::new(PlanarParams::default()).unwrap());
    for bad in [-1.0, f64::NAN, f64::INFINITY] {
        let e = DfMpc::new(
            model,
            DfMpcSettings {
                smoothness_weight: [0.0, bad, 0.0],
                ..Default::default()
            },
        )
        .unwrap_err();
        assert!(
            matches!(
                e,
                ControlError::InvalidSetting {
                    field: "smoothness_weight",
                    ..
                }
            ),
            "{e:?}"
        );
    }
}
