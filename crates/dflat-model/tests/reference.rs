//! Agreement with the independently derived reference vectors in
//! `reference/` (vendored from the shared derivation; 80-bit arithmetic, rounded to f64).
//!
//! Rule (reference README): per vector `rtol = max(1e-9, 10·float64_roundoff)`,
//! where `float64_roundoff` is the worst component-wise relative error of
//! the reference maps themselves evaluated in float64 on the rounded
//! outputs; each component must satisfy `|got − ref| ≤ rtol·max(|ref|, 1e-3)`.
//! Every map is checked in isolation on the reference's own arguments:
//! Λ(outputs[0..R]) vs `state`, F(outputs[0..=R]) vs `input`,
//! F⁻¹(outputs[0..R], input) vs `next_output`, step(state, input) vs
//! `next_state`.
//!
//! The JSON must be parsed with correct rounding (serde_json's
//! `float_roundtrip` feature, enabled in this crate's dev-dependencies):
//! the default parser may be one ulp off, and one ulp of a 15 m position
//! becomes ~1e-9 rad in a pitch command at δt = 0.01 s, the whole tolerance.

use std::path::PathBuf;

use dflat_model::full::{FullInput, FullOutput, FullState};
use dflat_model::planar::{PlanarInput, PlanarOutput, PlanarState};
use dflat_model::spatial::{SpatialInput, SpatialOutput, SpatialState};
use dflat_model::{
    FlatError, FlatModel, Frame, FullModel, FullParams, PlanarModel, PlanarParams, SpatialModel,
    SpatialParams,
};
use serde::Deserialize;

#[derive(Deserialize)]
struct File<V> {
    vectors: Vec<V>,
}

#[derive(Deserialize)]
struct PlanarVector {
    params: PlanarJsonParams,
    outputs: Vec<[f64; 2]>,
    state: [f64; 6],
    input: [f64; 2],
    next_output: Option<[f64; 2]>,
    next_state: [f64; 6],
    float64_roundoff: f64,
}

#[derive(Deserialize)]
struct PlanarJsonParams {
    dt: f64,
    tau: f64,
    k: f64,
    g: f64,
    psi: f64,
    frame: String,
}

#[derive(Deserialize)]
struct SpatialVector {
    params: SpatialJsonParams,
    outputs: Vec<[f64; 3]>,
    state: [f64; 9],
    input: [f64; 3],
    next_output: Option<[f64; 3]>,
    next_state: [f64; 9],
    float64_roundoff: f64,
}

#[derive(Deserialize)]
struct SpatialJsonParams {
    dt: f64,
    tau: f64,
    k: f64,
    tau_t: f64,
    g: f64,
    psi: f64,
    frame: String,
}

#[derive(Deserialize)]
struct FullVector {
    params: FullJsonParams,
    outputs: Vec<[f64; 4]>,
    state: [f64; 12],
    input: [f64; 4],
    next_output: Option<[f64; 4]>,
    next_state: [f64; 12],
    float64_roundoff: f64,
}

#[derive(Deserialize)]
struct FullJsonParams {
    dt: f64,
    m: f64,
    g: f64,
    #[serde(rename = "Ixx")]
    ixx: f64,
    #[serde(rename = "Iyy")]
    iyy: f64,
    #[serde(rename = "Izz")]
    izz: f64,
    frame: String,
}

fn reference_dir() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../reference");
    assert!(
        dir.is_dir(),
        "reference vectors not found: expected the directory {} (the repository's \
         `reference/` folder, vendored from the shared derivation)",
        dir.display()
    );
    dir
}

fn load<V: for<'de> Deserialize<'de>>(name: &str) -> Vec<V> {
    let path = reference_dir().join(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read reference file {}: {e}", path.display()));
    let file: File<V> = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("cannot parse reference file {}: {e}", path.display()));
    assert!(
        !file.vectors.is_empty(),
        "{} holds no vectors",
        path.display()
    );
    file.vectors
}

fn frame(name: &str) -> Frame {
    match name {
        "zup" => Frame::Zup,
        "ned" => Frame::Ned,
        other => panic!("unknown frame {other:?} in the reference vectors"),
    }
}

/// Compares component-wise by the README rule; returns the worst
/// `|got − ref| / (rtol·max(|ref|, 1e-3))` (must be ≤ 1).
fn check(case: usize, what: &str, got: &[f64], reference: &[f64], rtol: f64) -> f64 {
    assert_eq!(got.len(), reference.len());
    let mut worst: f64 = 0.0;
    for (i, (g, r)) in got.iter().zip(reference).enumerate() {
        let bound = rtol * r.abs().max(1e-3);
        let err = (g - r).abs();
        assert!(
            err <= bound,
            "vector {case}: {what}[{i}] = {g:e}, reference {r:e}, |err| = {err:e} > {bound:e} (rtol {rtol:e})"
        );
        worst = worst.max(err / bound);
    }
    worst
}

#[test]
fn planar_matches_reference_vectors() {
    let vectors: Vec<PlanarVector> = load("vectors_planar.json");
    let mut worst: f64 = 0.0;
    for (i, v) in vectors.iter().enumerate() {
        let p = &v.params;
        let m = PlanarModel::new(PlanarParams {
            dt: p.dt,
            tau: p.tau,
            k: p.k,
            g: p.g,
            psi: p.psi,
            frame: frame(&p.frame),
            drag_h: 0.0,
        })
        .expect("reference parameters are valid");
        let rtol = (10.0 * v.float64_roundoff).max(1e-9);
        let y: Vec<PlanarOutput> = v.outputs.iter().map(|o| PlanarOutput::from(*o)).collect();
        assert_eq!(y.len(), 4, "vector {i}: planar vectors hold y_k..y_k+3");
        let u_ref = PlanarInput::from(v.input);
        let x_ref = PlanarState::from(v.state);

        let x = m.state_from_outputs(&y[..3]).expect("Λ");
        worst = worst.max(check(i, "state", x.as_slice(), &v.state, rtol));
        let u = m.input_from_outputs(&y).expect("F");
        worst = worst.max(check(i, "input", u.as_slice(), &v.input, rtol));
        let next = v.next_output.expect("planar vectors have a next_output");
        let y3 = m.next_output(&y[..3], &u_ref).expect("F⁻¹");
        worst = worst.max(check(i, "next_output", y3.as_slice(), &next, rtol));
        let x1 = m.step(&x_ref, &u_ref);
        worst = worst.max(check(i, "next_state", x1.as_slice(), &v.next_state, rtol));
    }
    println!(
        "planar: worst error / bound = {worst:.3e} over {} vectors",
        vectors.len()
    );
}

#[test]
fn full_matches_reference_vectors() {
    let vectors: Vec<FullVector> = load("vectors_full.json");
    let mut worst: f64 = 0.0;
    for (i, v) in vectors.iter().enumerate() {
        let p = &v.params;
        let m = FullModel::new(FullParams {
            dt: p.dt,
            m: p.m,
            g: p.g,
            ixx: p.ixx,
            iyy: p.iyy,
            izz: p.izz,
            frame: frame(&p.frame),
        })
        .expect("reference parameters are valid");
        let rtol = (10.0 * v.float64_roundoff).max(1e-9);
        let y: Vec<FullOutput> = v.outputs.iter().map(|o| FullOutput::from(*o)).collect();
        assert_eq!(y.len(), 5, "vector {i}: full vectors hold y_k..y_k+4");
        let u_ref = FullInput::from(v.input);
        let x_ref = FullState::from(v.state);

        let x = m.state_from_outputs(&y[..4]).expect("Λ");
        worst = worst.max(check(i, "state", x.as_slice(), &v.state, rtol));
        let u = m.input_from_outputs(&y).expect("F");
        worst = worst.max(check(i, "input", u.as_slice(), &v.input, rtol));
        assert!(
            v.next_output.is_none(),
            "vector {i}: the full model has no F⁻¹"
        );
        assert_eq!(
            m.next_output(&y[..4], &u_ref),
            Err(FlatError::NoInputToOutputMap)
        );
        let x1 = m.step(&x_ref, &u_ref);
        worst = worst.max(check(i, "next_state", x1.as_slice(), &v.next_state, rtol));
    }
    println!(
        "full: worst error / bound = {worst:.3e} over {} vectors",
        vectors.len()
    );
}

/// The spatial model — the one dflat flies with PX4 — against its own
/// independently derived vectors (same format and rule as the planar ones;
/// both frames are in the file).
#[test]
fn spatial_matches_reference_vectors() {
    let vectors: Vec<SpatialVector> = load("vectors_spatial.json");
    assert!(vectors.len() >= 50, "{} vectors", vectors.len());
    let frames: std::collections::HashSet<&str> =
        vectors.iter().map(|v| v.params.frame.as_str()).collect();
    assert!(
        frames.contains("ned") && frames.contains("zup"),
        "{frames:?}"
    );
    let mut worst: f64 = 0.0;
    for (i, v) in vectors.iter().enumerate() {
        let p = &v.params;
        let m = SpatialModel::new(SpatialParams {
            dt: p.dt,
            tau: p.tau,
            k: p.k,
            tau_thrust: p.tau_t,
            g: p.g,
            psi: p.psi,
            frame: frame(&p.frame),
            drag_h: 0.0,
            drag_v: 0.0,
        })
        .expect("reference parameters are valid");
        let rtol = (10.0 * v.float64_roundoff).max(1e-9);
        let y: Vec<SpatialOutput> = v.outputs.iter().map(|o| SpatialOutput::from(*o)).collect();
        assert_eq!(y.len(), 4, "vector {i}: spatial vectors hold y_k..y_k+3");
        let u_ref = SpatialInput::from(v.input);
        let x_ref = SpatialState::from(v.state);

        let x = m.state_from_outputs(&y[..3]).expect("Λ");
        worst = worst.max(check(i, "state", x.as_slice(), &v.state, rtol));
        let u = m.input_from_outputs(&y).expect("F");
        worst = worst.max(check(i, "input", u.as_slice(), &v.input, rtol));
        let next = v.next_output.expect("spatial vectors have a next_output");
        let y3 = m.next_output(&y[..3], &u_ref).expect("F⁻¹");
        worst = worst.max(check(i, "next_output", y3.as_slice(), &next, rtol));
        let x1 = m.step(&x_ref, &u_ref);
        worst = worst.max(check(i, "next_state", x1.as_slice(), &v.next_state, rtol));
    }
    println!(
        "spatial: worst error / bound = {worst:.3e} over {} vectors",
        vectors.len()
    );
}

/// `vectors_drag.json`: planar and spatial vectors with linear drag in the
/// world frame (`drag_h`; `drag_v` for the spatial model).
#[derive(Deserialize)]
struct DragFile {
    planar: Vec<DragVector>,
    spatial: Vec<DragVector>,
}

#[derive(Deserialize)]
struct DragVector {
    params: DragJsonParams,
    outputs: Vec<Vec<f64>>,
    state: Vec<f64>,
    input: Vec<f64>,
    next_output: Vec<f64>,
    next_state: Vec<f64>,
    float64_roundoff: f64,
}

#[derive(Deserialize)]
struct DragJsonParams {
    dt: f64,
    tau: f64,
    k: f64,
    g: f64,
    psi: f64,
    frame: String,
    drag_h: f64,
    drag_v: f64,
    tau_t: Option<f64>,
}

fn load_drag() -> DragFile {
    let path = reference_dir().join("vectors_drag.json");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read reference file {}: {e}", path.display()));
    serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("cannot parse reference file {}: {e}", path.display()))
}

/// Checks Λ, F, F⁻¹ and the step of `m` against one drag vector; returns
/// the worst error / bound.
#[allow(clippy::too_many_arguments)]
fn check_drag_vector<M: FlatModel>(
    m: &M,
    i: usize,
    v: &DragVector,
    out: impl Fn(&[f64]) -> M::Output,
    inp: impl Fn(&[f64]) -> M::Input,
    st: impl Fn(&[f64]) -> M::State,
    slice_s: impl Fn(&M::State) -> Vec<f64>,
    slice_u: impl Fn(&M::Input) -> Vec<f64>,
    slice_y: impl Fn(&M::Output) -> Vec<f64>,
) -> f64 {
    let rtol = (10.0 * v.float64_roundoff).max(1e-9);
    let y: Vec<M::Output> = v.outputs.iter().map(|o| out(o)).collect();
    assert_eq!(y.len(), 4, "vector {i}: drag vectors hold y_k..y_k+3");
    let u_ref = inp(&v.input);
    let x_ref = st(&v.state);
    let mut worst: f64 = 0.0;
    let x = m.state_from_outputs(&y[..3]).expect("Λ");
    worst = worst.max(check(i, "state", &slice_s(&x), &v.state, rtol));
    let u = m.input_from_outputs(&y).expect("F");
    worst = worst.max(check(i, "input", &slice_u(&u), &v.input, rtol));
    let y3 = m.next_output(&y[..3], &u_ref).expect("F⁻¹");
    worst = worst.max(check(i, "next_output", &slice_y(&y3), &v.next_output, rtol));
    let x1 = m.step(&x_ref, &u_ref);
    worst = worst.max(check(i, "next_state", &slice_s(&x1), &v.next_state, rtol));
    worst
}

/// Both models with linear drag against `vectors_drag.json` (the
/// reference README's rule); the drag-free files above still pass with
/// drag 0.
#[test]
fn drag_matches_reference_vectors() {
    let file = load_drag();
    assert!(file.planar.len() >= 50 && file.spatial.len() >= 50);
    assert!(
        file.planar.iter().any(|v| v.params.drag_h > 0.0)
            && file.spatial.iter().any(|v| v.params.drag_v > 0.0),
        "the drag file holds cases with drag"
    );
    let mut worst: f64 = 0.0;
    for (i, v) in file.planar.iter().enumerate() {
        let p = &v.params;
        let m = PlanarModel::new(PlanarParams {
            dt: p.dt,
            tau: p.tau,
            k: p.k,
            g: p.g,
            psi: p.psi,
            frame: frame(&p.frame),
            drag_h: p.drag_h,
        })
        .expect("reference parameters are valid");
        worst = worst.max(check_drag_vector(
            &m,
            i,
            v,
            |o| PlanarOutput::new(o[0], o[1]),
            |u| PlanarInput::new(u[0], u[1]),
            PlanarState::from_column_slice,
            |x| x.as_slice().to_vec(),
            |u| u.as_slice().to_vec(),
            |y| y.as_slice().to_vec(),
        ));
    }
    for (i, v) in file.spatial.iter().enumerate() {
        let p = &v.params;
        let m = SpatialModel::new(SpatialParams {
            dt: p.dt,
            tau: p.tau,
            k: p.k,
            tau_thrust: p.tau_t.expect("spatial vectors give tau_t"),
            g: p.g,
            psi: p.psi,
            frame: frame(&p.frame),
            drag_h: p.drag_h,
            drag_v: p.drag_v,
        })
        .expect("reference parameters are valid");
        worst = worst.max(check_drag_vector(
            &m,
            i,
            v,
            |o| SpatialOutput::new(o[0], o[1], o[2]),
            |u| SpatialInput::new(u[0], u[1], u[2]),
            SpatialState::from_column_slice,
            |x| x.as_slice().to_vec(),
            |u| u.as_slice().to_vec(),
            |y| y.as_slice().to_vec(),
        ));
    }
    println!(
        "drag: worst error / bound = {worst:.3e} over {} vectors",
        file.planar.len() + file.spatial.len()
    );
}
