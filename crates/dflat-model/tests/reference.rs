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

use dflat_model::{
    FlatError, FlatModel, Frame, FullModel, FullParams, PlanarModel, PlanarParams, SpatialModel,
    SpatialParams,
};
use nalgebra::SVector;
use serde::Deserialize;

#[derive(Deserialize)]
struct File<V> {
    vectors: Vec<V>,
}

/// One reference vector of a model with parameters `P`: the outputs
/// y_k..y_k+R and what the maps give for them.
#[derive(Deserialize)]
struct Vector<P> {
    params: P,
    outputs: Vec<Vec<f64>>,
    state: Vec<f64>,
    input: Vec<f64>,
    /// F⁻¹'s result; none for a model without F⁻¹ (the full one).
    next_output: Option<Vec<f64>>,
    next_state: Vec<f64>,
    float64_roundoff: f64,
}

/// The planar model's parameters (`drag_h` only in the drag file).
#[derive(Deserialize)]
struct PlanarJsonParams {
    dt: f64,
    tau: f64,
    k: f64,
    g: f64,
    psi: f64,
    frame: String,
    #[serde(default)]
    drag_h: f64,
}

/// The spatial model's parameters (the drags only in the drag file).
#[derive(Deserialize)]
struct SpatialJsonParams {
    dt: f64,
    tau: f64,
    k: f64,
    tau_t: f64,
    g: f64,
    psi: f64,
    frame: String,
    #[serde(default)]
    drag_h: f64,
    #[serde(default)]
    drag_v: f64,
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

/// The parsed reference file `name`.
fn parse<T: for<'de> Deserialize<'de>>(name: &str) -> T {
    let path = reference_dir().join(name);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read reference file {}: {e}", path.display()));
    serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("cannot parse reference file {}: {e}", path.display()))
}

/// The vectors of the reference file `name`, which holds some.
fn load<V: for<'de> Deserialize<'de>>(name: &str) -> Vec<V> {
    let file: File<V> = parse(name);
    assert!(!file.vectors.is_empty(), "{name} holds no vectors");
    file.vectors
}

fn frame(name: &str) -> Frame {
    match name {
        "zup" => Frame::Zup,
        "ned" => Frame::Ned,
        other => panic!("unknown frame {other:?} in the reference vectors"),
    }
}

fn planar_model(p: &PlanarJsonParams) -> PlanarModel {
    PlanarModel::new(PlanarParams {
        dt: p.dt,
        tau: p.tau,
        k: p.k,
        g: p.g,
        psi: p.psi,
        frame: frame(&p.frame),
        drag_h: p.drag_h,
    })
    .expect("reference parameters are valid")
}

fn spatial_model(p: &SpatialJsonParams) -> SpatialModel {
    SpatialModel::new(SpatialParams {
        dt: p.dt,
        tau: p.tau,
        k: p.k,
        tau_thrust: p.tau_t,
        g: p.g,
        psi: p.psi,
        frame: frame(&p.frame),
        drag_h: p.drag_h,
        drag_v: p.drag_v,
        // The reference derives no rotor drag.
        drag_rotor: 0.0,
    })
    .expect("reference parameters are valid")
}

fn full_model(p: &FullJsonParams) -> FullModel {
    FullModel::new(FullParams {
        dt: p.dt,
        m: p.m,
        g: p.g,
        ixx: p.ixx,
        iyy: p.iyy,
        izz: p.izz,
        frame: frame(&p.frame),
    })
    .expect("reference parameters are valid")
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

/// Checks Λ, F, F⁻¹ (or, for a vector without a next output, that the
/// model has no F⁻¹) and the step of `m` against vector `i`; returns the
/// worst error / bound.
fn check_vector<M, P, const NY: usize, const NU: usize, const NX: usize>(
    m: &M,
    i: usize,
    v: &Vector<P>,
) -> f64
where
    M: FlatModel<Output = SVector<f64, NY>, Input = SVector<f64, NU>, State = SVector<f64, NX>>,
{
    let r = M::R;
    let rtol = (10.0 * v.float64_roundoff).max(1e-9);
    let y: Vec<M::Output> = v
        .outputs
        .iter()
        .map(|o| SVector::from_column_slice(o))
        .collect();
    assert_eq!(y.len(), r + 1, "vector {i}: the vectors hold y_k..y_k+R");
    let u_ref = SVector::from_column_slice(&v.input);
    let x_ref = SVector::from_column_slice(&v.state);

    let x = m.state_from_outputs(&y[..r]).expect("Λ");
    let mut worst = check(i, "state", x.as_slice(), &v.state, rtol);
    let u = m.input_from_outputs(&y).expect("F");
    worst = worst.max(check(i, "input", u.as_slice(), &v.input, rtol));
    match &v.next_output {
        Some(next) => {
            let y_next = m.next_output(&y[..r], &u_ref).expect("F⁻¹");
            worst = worst.max(check(i, "next_output", y_next.as_slice(), next, rtol));
        }
        None => assert_eq!(
            m.next_output(&y[..r], &u_ref),
            Err(FlatError::NoInputToOutputMap),
            "vector {i}: no next output, so the model must have no F⁻¹"
        ),
    }
    let x1 = m.step(&x_ref, &u_ref);
    worst.max(check(i, "next_state", x1.as_slice(), &v.next_state, rtol))
}

/// The worst error / bound of `vectors`, each flown through its model.
fn worst_of<P, M, const NY: usize, const NU: usize, const NX: usize>(
    vectors: &[Vector<P>],
    model: impl Fn(&P) -> M,
) -> f64
where
    M: FlatModel<Output = SVector<f64, NY>, Input = SVector<f64, NU>, State = SVector<f64, NX>>,
{
    vectors
        .iter()
        .enumerate()
        .map(|(i, v)| check_vector(&model(&v.params), i, v))
        .fold(0.0, f64::max)
}

#[test]
fn planar_matches_reference_vectors() {
    let vectors: Vec<Vector<PlanarJsonParams>> = load("vectors_planar.json");
    assert!(
        vectors.iter().all(|v| v.next_output.is_some()),
        "planar vectors have a next_output"
    );
    let worst = worst_of(&vectors, planar_model);
    println!(
        "planar: worst error / bound = {worst:.3e} over {} vectors",
        vectors.len()
    );
}

#[test]
fn full_matches_reference_vectors() {
    let vectors: Vec<Vector<FullJsonParams>> = load("vectors_full.json");
    assert!(
        vectors.iter().all(|v| v.next_output.is_none()),
        "the full model has no F⁻¹"
    );
    let worst = worst_of(&vectors, full_model);
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
    let vectors: Vec<Vector<SpatialJsonParams>> = load("vectors_spatial.json");
    assert!(vectors.len() >= 50, "{} vectors", vectors.len());
    let frames: std::collections::HashSet<&str> =
        vectors.iter().map(|v| v.params.frame.as_str()).collect();
    assert!(
        frames.contains("ned") && frames.contains("zup"),
        "{frames:?}"
    );
    assert!(
        vectors.iter().all(|v| v.next_output.is_some()),
        "spatial vectors have a next_output"
    );
    let worst = worst_of(&vectors, spatial_model);
    println!(
        "spatial: worst error / bound = {worst:.3e} over {} vectors",
        vectors.len()
    );
}

/// `vectors_drag.json`: planar and spatial vectors with linear drag in the
/// world frame (`drag_h`; `drag_v` for the spatial model).
#[derive(Deserialize)]
struct DragFile {
    planar: Vec<Vector<PlanarJsonParams>>,
    spatial: Vec<Vector<SpatialJsonParams>>,
}

/// Both models with linear drag against `vectors_drag.json` (the
/// reference README's rule); the drag-free files above still pass with
/// drag 0.
#[test]
fn drag_matches_reference_vectors() {
    let file: DragFile = parse("vectors_drag.json");
    assert!(file.planar.len() >= 50 && file.spatial.len() >= 50);
    assert!(
        file.planar.iter().any(|v| v.params.drag_h > 0.0)
            && file.spatial.iter().any(|v| v.params.drag_v > 0.0),
        "the drag file holds cases with drag"
    );
    assert!(
        file.planar.iter().all(|v| v.next_output.is_some())
            && file.spatial.iter().all(|v| v.next_output.is_some()),
        "drag vectors have a next_output"
    );
    let worst = worst_of(&file.planar, planar_model).max(worst_of(&file.spatial, spatial_model));
    println!(
        "drag: worst error / bound = {worst:.3e} over {} vectors",
        file.planar.len() + file.spatial.len()
    );
}
