//! Disturbance estimation for offset-free DF-MPC ([`dflat_control::disturbance`]):
//! the estimator alone on the models' own Euler steps with injected
//! disturbances, its guards (clamp, freeze, pose jump, reset), and the
//! closed loop with [`DfMpc`].
//!
//! Tolerances. With the plant equal to the model plus a constant offset d,
//! the window fit is exact (module docs): every update sees δ̂ = d, so after
//! n updates the low-pass leaves `|d̂ − d| = |d|·β^n`, β = 1 − α; the tests
//! allow that plus 1e-9 m/s² of rounding. With position noise σ the
//! estimate's standard deviation is `G·σ` (G = `noise_gain()`, 0.36 s⁻² for
//! the defaults); the test allows 0.5–1.5·G·σ RMS over 100 s (about 60
//! independent samples at the 1.6 s time constant).

use dflat_control::dfmpc::{DfMpc, DfMpcSettings};
use dflat_control::disturbance::{
    DisturbanceEstimate, DisturbanceEstimator, DisturbanceSettings, EstimatorStatus,
};
use dflat_control::{ControlModel, Controller, Frame, Measurement};
use dflat_model::{FlatModel, PlanarModel, SpatialModel, SpatialParams};
use nalgebra::{SVector, Vector2, Vector3};

mod common;
use common::{DT, G, Setpoint, planar_ned};

/// Deterministic standard normals (xorshift64 + Box–Muller), no dependency.
struct Normal(u64);

impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn sample(&mut self) -> f64 {
        let (u1, u2) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

fn planar_model() -> PlanarModel {
    planar_ned(0.3)
}

fn spatial_model() -> SpatialModel {
    SpatialModel::new(SpatialParams {
        psi: 0.3,
        frame: Frame::Ned,
        ..Default::default()
    })
    .unwrap()
}

/// The planar model's own Euler step plus a constant acceleration offset
/// `d` [m/s²] in x, y.
fn planar_step(
    m: &PlanarModel,
    x: &SVector<f64, 6>,
    u: &Vector3<f64>,
    d: &Vector2<f64>,
) -> SVector<f64, 6> {
    let mut n = m.step(x, &Vector2::new(u.x, u.y));
    n[1] += DT * d.x;
    n[3] += DT * d.y;
    n
}

/// The spatial model's own Euler step with its thrust scaled by `kappa`
/// (the vehicle's thrust per commanded thrust) plus an offset `d` in x, y.
fn spatial_step(
    m: &SpatialModel,
    x: &SVector<f64, 9>,
    u: &Vector3<f64>,
    kappa: f64,
    d: &Vector2<f64>,
) -> SVector<f64, 9> {
    let mut n = m.step(x, &Vector3::new(u.x, u.y, kappa * u.z));
    n[1] += DT * d.x;
    n[3] += DT * d.y;
    n
}

/// A varied, small input sequence (rad).
fn wiggle(k: usize) -> Vector3<f64> {
    let t = k as f64 * DT;
    Vector3::new(0.1 * (0.7 * t).sin(), 0.05 * (1.3 * t).cos(), G)
}

/// The planar model's open-loop response to [`wiggle`] under a constant
/// offset, measured with Gaussian noise σ, fed to an estimator tick by tick.
struct OpenLoop {
    m: PlanarModel,
    x: SVector<f64, 6>,
    k: usize,
    noise: Normal,
    sigma: f64,
}

impl OpenLoop {
    fn new(sigma: f64) -> Self {
        Self {
            m: planar_model(),
            x: SVector::zeros(),
            k: 0,
            noise: Normal(0x9E37_79B9_7F4A_7C15),
            sigma,
        }
    }

    /// One tick: measure, record (`saturated` as given), step under `d`.
    fn tick(&mut self, est: &mut DisturbanceEstimator, d: &Vector2<f64>, saturated: bool) {
        let n = Vector3::new(self.noise.sample(), self.noise.sample(), 0.0);
        let y = Vector3::new(self.x[0], self.x[2], 0.0) + self.sigma * n;
        let u = wiggle(self.k);
        est.begin_tick();
        est.record(&y, &u, saturated);
        self.x = planar_step(&self.m, &self.x, &u, d);
        self.k += 1;
    }

    /// `ticks` unsaturated ticks; returns the number of estimate updates
    /// and the RMS of `d̂ − d` per axis over the last `tail` ticks.
    fn run(
        &mut self,
        est: &mut DisturbanceEstimator,
        d: Vector2<f64>,
        ticks: usize,
        tail: usize,
    ) -> (usize, f64) {
        let (mut updates, mut sum2, mut n) = (0, 0.0, 0);
        for i in 0..ticks {
            self.tick(est, &d, false);
            if est.status() == EstimatorStatus::Tracking {
                updates += 1;
            }
            if i + tail >= ticks {
                let e = est.estimate().acceleration;
                sum2 += (e.x - d.x).powi(2) + (e.y - d.y).powi(2);
                n += 2;
            }
        }
        (updates, (sum2 / n as f64).sqrt())
    }
}

/// The spatial model's input at `t` \[s\] for identifying the thrust scale
/// `kappa`: slow pitch and roll waves and a thrust wave about the hover
/// thrust the vehicle needs (pitch, roll \[rad\], thrust \[m/s²\]).
fn exciting_input(t: f64, kappa: f64) -> Vector3<f64> {
    Vector3::new(
        0.1 * (0.7 * t).sin(),
        0.05 * (1.3 * t).cos(),
        G / kappa + 0.5 * (0.9 * t).sin(),
    )
}

fn planar_estimator() -> DisturbanceEstimator {
    DisturbanceEstimator::new(
        ControlModel::Planar(planar_model()),
        DisturbanceSettings::default(),
    )
    .unwrap()
}

#[test]
fn estimator_converges_to_constant_offset_on_planar_step() {
    let d = Vector2::new(0.7, -0.4);
    let mut est = planar_estimator();
    let (updates, _) = OpenLoop::new(0.0).run(&mut est, d, 1000, 1);
    let beta = 1.0 - est.alpha();
    let e = est.estimate();
    // Exact fit ⇒ first-order convergence |d̂ − d| = |d|·β^n (+ rounding).
    let bound = d.norm() * beta.powi(updates as i32) + 1e-9;
    let err = (Vector2::new(e.acceleration.x, e.acceleration.y) - d).norm();
    assert!(updates > 800, "{updates} updates");
    assert!(err <= bound, "|d̂ − d| = {err:e} > {bound:e}");
    assert_eq!(e.acceleration.z, 0.0);
    assert_eq!(e.thrust_scale, 1.0);
    assert_eq!(est.status(), EstimatorStatus::Tracking);
    assert!(!est.clamped());
}

#[test]
fn estimator_noise_is_as_derived() {
    // σ = 1 cm on both axes: after convergence the RMS error is G·σ. A small
    // offset keeps the open-loop drift under the pose-jump threshold.
    let d = Vector2::new(0.2, -0.1);
    let mut est = planar_estimator();
    let sigma = 0.01;
    let (_, rms) = OpenLoop::new(sigma).run(&mut est, d, 6000, 5000);
    assert_eq!(est.jumps(), 0);
    let expected = est.noise_gain() * sigma;
    assert!(
        rms < 1.5 * expected && rms > 0.5 * expected,
        "rms {rms} vs G·σ = {expected}"
    );
}

#[test]
fn estimator_converges_to_thrust_scale_on_spatial_step() {
    let m = spatial_model();
    let mut est =
        DisturbanceEstimator::new(ControlModel::Spatial(m), DisturbanceSettings::default())
            .unwrap();
    let (kappa, d) = (1.25, Vector2::new(-0.3, 0.5));
    // Hover for the vehicle: thrust state κ·g (it flies what the model calls g).
    let mut x = SVector::<f64, 9>::zeros();
    x[8] = G;
    for k in 0..1500 {
        let u = exciting_input(k as f64 * DT, kappa);
        est.begin_tick();
        est.record(&m.output(&x), &u, false);
        x = spatial_step(&m, &x, &u, kappa, &d);
    }
    let e = est.estimate();
    assert_eq!(est.jumps(), 0);
    assert!(
        (e.thrust_scale - kappa).abs() < 1e-6,
        "κ̂ = {}",
        e.thrust_scale
    );
    assert!((e.acceleration.x - d.x).abs() < 1e-6, "{}", e.acceleration);
    assert!((e.acceleration.y - d.y).abs() < 1e-6, "{}", e.acceleration);
    assert_eq!(e.acceleration.z, 0.0);
    assert!((est.hover_thrust() - G / kappa).abs() < 1e-5);
    assert!((e.hover_thrust(G) - 0.4 / 0.5 * G).abs() < 1e-5);
}

#[test]
fn estimate_is_clamped_under_huge_disturbance_and_recovers() {
    // 30 m/s² (3 g) against a 3 m/s² clamp; the jump threshold is raised
    // (to its largest, 100 m per tick) because the open-loop vehicle soon
    // flies faster than 50 m/s.
    let settings = DisturbanceSettings {
        max_step: 100.0,
        ..Default::default()
    };
    let mut est =
        DisturbanceEstimator::new(ControlModel::Planar(planar_model()), settings).unwrap();
    let lim = settings.max_acceleration;
    let mut plant = OpenLoop::new(0.0);
    plant.run(&mut est, Vector2::new(30.0, -30.0), 400, 1);
    let e = est.estimate().acceleration;
    assert_eq!((e.x, e.y), (lim, -lim), "{e}");
    assert!(est.clamped());
    // No wind-up: with the disturbance gone the estimate leaves the bound
    // as soon as the window holds only new data, then converges as the
    // low-pass from at most the bound.
    let window = settings.fit_span;
    plant.run(&mut est, Vector2::zeros(), window + 300, 1);
    let e = est.estimate().acceleration;
    let bound = lim * (1.0 - est.alpha()).powi(300) + 1e-9;
    assert!(e.x.abs() <= bound && e.y.abs() <= bound, "{e} vs {bound}");
    assert!(!est.clamped());
}

#[test]
fn estimate_freezes_while_saturated() {
    let mut est = planar_estimator();
    let mut plant = OpenLoop::new(0.0);
    plant.run(&mut est, Vector2::new(0.5, 0.5), 600, 1);
    let before = est.estimate();
    // The disturbance changes, but every command is reported clipped.
    let changed = Vector2::new(-1.0, 0.2);
    for _ in 0..300 {
        plant.tick(&mut est, &changed, true);
        assert_eq!(est.estimate(), before);
        assert_eq!(est.status(), EstimatorStatus::Frozen);
    }
    // Unsaturated again: it moves towards the new value at once.
    plant.tick(&mut est, &changed, false);
    assert_eq!(est.status(), EstimatorStatus::Tracking);
    assert!(est.estimate().acceleration.x < before.acceleration.x);
}

#[test]
fn estimate_resets_on_pose_jump_and_gap() {
    let mut est = planar_estimator();
    OpenLoop::new(0.0).run(&mut est, Vector2::new(0.5, -0.5), 600, 1);
    assert!(!est.estimate().is_nominal());
    assert_eq!(est.jumps(), 0);
    // A 100 m step in one tick: the pose source jumped.
    let y = Vector3::new(100.0, 100.0, 0.0);
    est.begin_tick();
    est.record(&y, &wiggle(0), false);
    assert_eq!(est.jumps(), 1);
    assert_eq!(est.estimate(), DisturbanceEstimate::NOMINAL);
    assert_eq!(est.status(), EstimatorStatus::Filling);
    // A step just under the threshold is motion, not a jump.
    let step = 0.99 * est.settings().max_step;
    est.begin_tick();
    est.record(&(y + Vector3::new(step, 0.0, 0.0)), &wiggle(1), false);
    assert_eq!(est.jumps(), 1);
    // A tick that never recorded (controller error) restarts the window.
    est.begin_tick();
    est.begin_tick();
    est.record(&y, &wiggle(2), false);
    assert_eq!(est.status(), EstimatorStatus::Filling);
}

/// Flies DF-MPC on the planar model's own step with a constant offset;
/// returns the mean position error over the last 5 s \[m\] and the controller.
fn planar_closed_loop(d: Vector2<f64>, estimator: Option<DisturbanceSettings>) -> (f64, DfMpc) {
    let m = planar_model();
    let settings = DfMpcSettings {
        disturbance: estimator,
        ..Default::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Planar(m), settings).unwrap();
    let target = Vector3::new(3.0, -2.0, -1.5);
    let error = mean_final_error(
        &mut ctrl,
        target,
        SVector::<f64, 6>::zeros(),
        |x| Vector3::new(x[0], x[2], -1.5),
        |x, u| planar_step(&m, x, u, &d),
    );
    (error, ctrl)
}

/// Flies `ctrl` to the setpoint `target` for 20 s on a plant from state
/// `x` (its position `output`, its `step` under the command (pitch, roll,
/// thrust)); returns the mean distance to the target over the last 5 s \[m\].
fn mean_final_error<S>(
    ctrl: &mut DfMpc,
    target: Vector3<f64>,
    mut x: S,
    output: impl Fn(&S) -> Vector3<f64>,
    step: impl Fn(&S, &Vector3<f64>) -> S,
) -> f64 {
    let mut reference = Setpoint(target);
    let ticks = 1000; // 20 s
    let (mut sum, mut n) = (0.0, 0);
    for k in 0..ticks {
        let p = output(&x);
        if k >= ticks - 250 {
            sum += (p - target).norm();
            n += 1;
        }
        let m_k = Measurement {
            t: k as f64 * DT,
            position: p,
            yaw: 0.3,
        };
        let out = ctrl.update(&m_k, &mut reference).unwrap();
        let u = Vector3::new(out.command.pitch, out.command.roll, out.command.thrust);
        x = step(&x, &u);
    }
    sum / n as f64
}

#[test]
fn df_with_estimator_removes_wind_offset_in_closed_loop() {
    // A 3 m/s wind on 0.3 1/s of drag: 0.9 m/s² (and some across).
    let d = Vector2::new(0.9, -0.5);
    let (without, _) = planar_closed_loop(d, None);
    let (with, ctrl) = planar_closed_loop(d, Some(DisturbanceSettings::default()));
    assert!(without > 0.05, "without the estimator: {without} m");
    assert!(
        with < 0.05 && with < 0.1 * without,
        "with: {with} m, without {without} m"
    );
    let e = ctrl.disturbance().unwrap();
    assert!((e.acceleration[0] - d.x).abs() < 1e-3, "{e:?}");
    assert!((e.acceleration[1] - d.y).abs() < 1e-3, "{e:?}");
    // The controller's reset (failsafe) forgets the estimate.
    let mut ctrl = ctrl;
    ctrl.reset();
    let r = ctrl.disturbance().unwrap();
    assert_eq!(r.acceleration, [0.0; 3]);
    assert_eq!(r.thrust_scale, 1.0);
    assert_eq!(r.status, EstimatorStatus::Settling);
}

/// DF-MPC on the spatial model's own step with the vehicle's thrust scaled
/// by `kappa`; returns the mean |z error| over the last 5 s \[m\] and the
/// controller.
fn spatial_closed_loop(kappa: f64, estimator: Option<DisturbanceSettings>) -> (f64, DfMpc) {
    let m = spatial_model();
    let settings = DfMpcSettings {
        disturbance: estimator,
        ..Default::default()
    };
    let mut ctrl = DfMpc::new(ControlModel::Spatial(m), settings).unwrap();
    let target = Vector3::new(2.0, 1.0, -3.0);
    let start = Vector3::new(2.0, 1.0, -1.0);
    let mut x = SVector::<f64, 9>::zeros();
    (x[0], x[2], x[4], x[8]) = (start.x, start.y, start.z, G);
    let error = mean_final_error(
        &mut ctrl,
        target,
        x,
        |x| m.output(x),
        |x, u| spatial_step(&m, x, u, kappa, &Vector2::zeros()),
    );
    (error, ctrl)
}

#[test]
fn spatial_hover_thrust_mismatch_is_removed() {
    // Normalised hover thrust 0.4 on the vehicle against 0.5 in the model:
    // the vehicle makes 0.5/0.4 = 1.25 times the thrust the model expects.
    let kappa = 0.5 / 0.4;
    let (without, _) = spatial_closed_loop(kappa, None);
    let (with, ctrl) = spatial_closed_loop(kappa, Some(DisturbanceSettings::default()));
    assert!(without > 0.05, "without the estimator: {without} m");
    assert!(with < 0.05, "with: {with} m (without {without} m)");
    let r = ctrl.disturbance().unwrap();
    assert!((r.thrust_scale - kappa).abs() < 1e-3, "{r:?}");
    // Normalised by the model's full scale g/0.5: the vehicle's 0.4.
    assert!((r.hover_thrust / (G / 0.5) - 0.4).abs() < 1e-3, "{r:?}");
}

/// Multi-rate mode: the estimator fits timestamped samples given through
/// `observe` (never a controller's estimate). On the spatial model's own
/// step with κ = 1.25 and an offset d, σ = 1 cm noise on every 50 Hz
/// sample, it converges to (κ, d) within a few noise standard deviations
/// (G·σ = 0.0036 m/s² for d, ≈ G·σ/g for κ); noise-free 15 Hz samples
/// between the ticks (lerped model outputs, 60 ms late) give them exactly.
#[test]
fn multi_rate_estimator_converges_with_1cm_noise_on_spatial_step() {
    let m = spatial_model();
    let (kappa, d) = (1.25, Vector2::new(-0.3, 0.5));
    for (sigma, rate, latency) in [(0.01, 50.0, 0.0), (0.0, 15.0, 0.06)] {
        let mut est =
            DisturbanceEstimator::new(ControlModel::Spatial(m), DisturbanceSettings::default())
                .unwrap();
        let mut noise = Normal(0x2545_F491_4F6C_DD1D);
        let mut x = SVector::<f64, 9>::zeros();
        x[8] = G;
        // (capture time, position) waiting for their arrival.
        let mut pending: Vec<(f64, Vector3<f64>)> = Vec::new();
        let mut next_capture = 0.0;
        for k in 0..1500 {
            let t = k as f64 * DT;
            let u = exciting_input(t, kappa);
            let next = spatial_step(&m, &x, &u, kappa, &d);
            // Captures in [t, t + δt): the model's outputs lerped.
            while next_capture < t + DT - 1e-12 {
                let a = (next_capture - t) / DT;
                let p = m.output(&x) + a * (m.output(&next) - m.output(&x));
                let n = Vector3::new(noise.sample(), noise.sample(), noise.sample());
                pending.push((next_capture, p + sigma * n));
                next_capture += 1.0 / rate;
            }
            // Samples arrive `latency` after capture, before the tick.
            for &(tc, p) in pending.iter().filter(|(tc, _)| tc + latency <= t + 1e-12) {
                est.observe(tc, &p);
            }
            pending.retain(|(tc, _)| tc + latency > t + 1e-12);
            est.begin_tick();
            est.record_input(t, &u, false);
            x = next;
        }
        let e = est.estimate();
        assert_eq!(est.jumps(), 0);
        assert_eq!(est.status(), EstimatorStatus::Tracking);
        let (tol_d, tol_k) = if sigma > 0.0 {
            (
                5.0 * est.noise_gain() * sigma,
                5.0 * est.noise_gain() * sigma / G,
            )
        } else {
            (1e-6, 1e-6)
        };
        assert!(
            (e.thrust_scale - kappa).abs() < tol_k,
            "σ = {sigma}: κ̂ = {}",
            e.thrust_scale
        );
        assert!((e.acceleration.x - d.x).abs() < tol_d, "{}", e.acceleration);
        assert!((e.acceleration.y - d.y).abs() < tol_d, "{}", e.acceleration);
    }
}

/// DF-MPC on multi-rate windows with the estimator, σ = 1 cm on every
/// 50 Hz sample (through `observe`), on the spatial model's own step with
/// the vehicle's thrust 1.25 times the model's: the altitude offset is
/// removed and κ̂ is the vehicle's.
#[test]
fn multi_rate_df_with_estimator_removes_hover_offset_under_1cm_noise() {
    let m = spatial_model();
    let kappa = 1.25;
    let run = |estimator: Option<DisturbanceSettings>| {
        let settings = DfMpcSettings {
            tracking_weight: [1.0; 3],
            jerk_weight: [0.003; 3],
            smoothness_weight: [50.0, 50.0, 0.0],
            multi_rate: Some(dflat_control::window::MultiRateSettings::default()),
            disturbance: estimator,
            ..Default::default()
        };
        let mut ctrl = DfMpc::new(ControlModel::Spatial(m), settings).unwrap();
        let target = Vector3::new(2.0, 1.0, -3.0);
        let mut reference = Setpoint(target);
        let mut x = SVector::<f64, 9>::zeros();
        (x[0], x[2], x[4], x[8]) = (2.0, 1.0, -1.0, G);
        let mut noise = Normal(0x9E37_79B9_7F4A_7C15);
        let (ticks, mut sum, mut n) = (1500, 0.0, 0);
        for k in 0..ticks {
            let t = k as f64 * DT;
            let p = m.output(&x);
            if k >= ticks - 250 {
                sum += (p - target).norm();
                n += 1;
            }
            let noisy = p + 0.01 * Vector3::new(noise.sample(), noise.sample(), noise.sample());
            let sample = Measurement {
                t,
                position: noisy,
                yaw: 0.3,
            };
            ctrl.observe(&sample);
            let out = ctrl.update(&sample, &mut reference).unwrap();
            let u = Vector3::new(out.command.pitch, out.command.roll, out.command.thrust);
            x = spatial_step(&m, &x, &u, kappa, &Vector2::zeros());
        }
        (sum / n as f64, ctrl)
    };
    let (without, _) = run(None);
    let (with, ctrl) = run(Some(DisturbanceSettings::default()));
    assert!(without > 0.2, "without the estimator: {without} m");
    assert!(with < 0.03, "with: {with} m (without {without} m)");
    let r = ctrl.disturbance().unwrap();
    assert!((r.thrust_scale - kappa).abs() < 0.005, "{r:?}");
}
