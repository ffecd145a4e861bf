//! Sensing: what the controller sees of the plant.
//!
//! A [`Sensor`] is fed the true state after every plant step
//! ([`Sensor::observe`], 200 Hz) and asked for the [`Measurement`] at each
//! control tick ([`Sensor::measure`], 50 Hz). Two models:
//!
//! * [`GaussianSensor`] — the paper's §VI set-up: the true position at the
//!   tick plus zero-mean Gaussian noise (σ per NED axis), no delay.
//! * [`VisionSensor`] — a stand-in for the paper's §VII-B visual pipeline:
//!   pose samples captured at 15 Hz (configurable) with timing jitter,
//!   Gaussian noise, dropouts (independent or in bursts) and latency; the
//!   50 Hz measurement is extrapolated with a constant-velocity model fitted
//!   on the last two received samples (the paper used STEAM), or the last
//!   sample is held, or passed raw with its own timestamp
//!   ([`VisionMode`]).
//!
//! Every sensor also exposes the timestamped samples that arrived at the
//! last tick ([`Sensor::new_samples`]), for controllers that consume poses at
//! their own timestamps.
//!
//! Randomness comes from a seeded ChaCha8 stream; a sensor draws the same
//! random numbers per sample whatever the options and the trajectory, so
//! two controllers flown with the same seed see the same noise.

use std::collections::VecDeque;

use dflat_control::Measurement;
use nalgebra::Vector3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::error::{check_positive, check_range};
use crate::plant::PlantState;
use crate::rng::{STREAM_SENSOR, normal, stream};

/// One pose sample as produced by the sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// Time the pose describes (capture time) \[s\].
    pub t_measured: f64,
    /// Time the sample reaches the controller \[s\] (≥ `t_measured`).
    pub t_arrival: f64,
    /// Measured position, local NED \[m\].
    pub position: Vector3<f64>,
    /// Measured yaw ψ \[rad\].
    pub yaw: f64,
}

/// A position sensor between plant and controller.
pub trait Sensor: Send {
    /// Starts over at time `t0` \[s\] with the vehicle in `truth`, assumed to
    /// have moved at constant velocity before `t0` (so a delayed sensor has
    /// samples from the start).
    fn reset(&mut self, t0: f64, truth: &PlantState);
    /// Feeds the true state at time `t` \[s\] (after every plant step, with
    /// increasing `t`).
    fn observe(&mut self, t: f64, truth: &PlantState);
    /// The measurement for the control tick at time `t` \[s\] (call after
    /// `observe` at `t`); `None` while no sample has arrived.
    fn measure(&mut self, t: f64) -> Option<Measurement>;
    /// The samples that arrived at the last [`Sensor::measure`] call (since
    /// the previous one), oldest first.
    fn new_samples(&self) -> &[PoseSample];
}

/// Which sensor to build, with its options.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SensorSpec {
    /// The true position and yaw at the tick (the default).
    #[default]
    Perfect,
    /// [`GaussianSensor`].
    Gaussian(GaussianOptions),
    /// [`VisionSensor`].
    Vision(VisionOptions),
}

impl SensorSpec {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), SimError> {
        match self {
            Self::Perfect => Ok(()),
            Self::Gaussian(o) => o.validate(),
            Self::Vision(o) => o.validate(),
        }
    }
}

/// Builds the sensor of `spec`; `seed` drives its noise.
pub fn build_sensor(spec: &SensorSpec, seed: u64) -> Result<Box<dyn Sensor>, SimError> {
    Ok(match spec {
        SensorSpec::Perfect => Box::new(GaussianSensor::new(GaussianOptions::default(), seed)?),
        SensorSpec::Gaussian(o) => Box::new(GaussianSensor::new(o.clone(), seed)?),
        SensorSpec::Vision(o) => Box::new(VisionSensor::new(o.clone(), seed)?),
    })
}

/// Options of [`GaussianSensor`]. Default: no noise.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaussianOptions {
    /// Noise standard deviation per NED axis \[m\].
    pub sigma: [f64; 3],
    /// Yaw noise standard deviation \[rad\].
    pub yaw_sigma: f64,
}

impl GaussianOptions {
    /// The paper's §VI noise: σ \[m\] on x (north) only.
    pub fn x_only(sigma: f64) -> Self {
        Self {
            sigma: [sigma, 0.0, 0.0],
            yaw_sigma: 0.0,
        }
    }

    /// σ \[m\] on all three axes.
    pub fn isotropic(sigma: f64) -> Self {
        Self {
            sigma: [sigma; 3],
            yaw_sigma: 0.0,
        }
    }

    /// Checks the options.
    pub fn validate(&self) -> Result<(), SimError> {
        for s in self.sigma {
            check_range("sensor.sigma", s, 0.0, 1e3, "0 ..= 1000 m")?;
        }
        check_range(
            "sensor.yaw_sigma",
            self.yaw_sigma,
            0.0,
            10.0,
            "0 ..= 10 rad",
        )
    }
}

/// The truth at the latest `observe`, plus Gaussian noise, at every tick.
///
/// Each tick draws four standard normals (x, y, z, yaw) whatever σ is.
#[derive(Debug, Clone)]
pub struct GaussianSensor {
    options: GaussianOptions,
    rng: ChaCha8Rng,
    truth: Option<(f64, Vector3<f64>, f64)>,
    new: Vec<PoseSample>,
}

impl GaussianSensor {
    /// A sensor with validated `options`, noise seeded by `seed`.
    pub fn new(options: GaussianOptions, seed: u64) -> Result<Self, SimError> {
        options.validate()?;
        Ok(Self {
            options,
            rng: stream(seed, STREAM_SENSOR),
            truth: None,
            new: Vec::with_capacity(1),
        })
    }
}

impl Sensor for GaussianSensor {
    fn reset(&mut self, t0: f64, truth: &PlantState) {
        self.truth = Some((t0, truth.position, truth.yaw));
        self.new.clear();
    }

    fn observe(&mut self, t: f64, truth: &PlantState) {
        self.truth = Some((t, truth.position, truth.yaw));
    }

    fn measure(&mut self, _t: f64) -> Option<Measurement> {
        self.new.clear();
        let (t, p, yaw) = self.truth?;
        let s = self.options.sigma;
        let n = [
            normal(&mut self.rng),
            normal(&mut self.rng),
            normal(&mut self.rng),
            normal(&mut self.rng),
        ];
        let position = p + Vector3::new(s[0] * n[0], s[1] * n[1], s[2] * n[2]);
        let yaw = yaw + self.options.yaw_sigma * n[3];
        self.new.push(PoseSample {
            t_measured: t,
            t_arrival: t,
            position,
            yaw,
        });
        Some(Measurement { t, position, yaw })
    }

    fn new_samples(&self) -> &[PoseSample] {
        &self.new
    }
}

/// How [`VisionSensor`] turns samples into the per-tick measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VisionMode {
    /// Constant-velocity extrapolation to the tick time from the last two
    /// received samples (`p₁ + (p₁ − p₀)·(t − t₁)/(t₁ − t₀)`); the
    /// measurement is stamped with the tick time. One sample: held.
    #[default]
    Extrapolate,
    /// The last received sample, stamped with the tick time (a naive shell).
    Hold,
    /// The last received sample with its own capture time; the samples
    /// themselves are in [`Sensor::new_samples`]. Ticks without a new sample
    /// repeat the previous measurement (same `t`), so a consumer can tell.
    Raw,
}

/// Options of [`VisionSensor`]. Defaults: 15 Hz, 60 ms latency, σ = 2 cm,
/// ±5 ms capture jitter, no dropouts, extrapolated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VisionOptions {
    /// Nominal sample rate \[Hz\].
    pub rate_hz: f64,
    /// Latency from capture to arrival \[s\].
    pub latency: f64,
    /// Standard deviation of a Gaussian latency jitter \[s\]; arrivals stay in
    /// capture order and never precede the capture.
    pub latency_jitter: f64,
    /// Position noise standard deviation per axis \[m\].
    pub sigma: f64,
    /// Yaw noise standard deviation \[rad\].
    pub yaw_sigma: f64,
    /// Long-run share of dropped samples [0, 1).
    pub dropout: f64,
    /// Mean length of a dropout burst \[samples\] (≥ 1; 1 = independent
    /// dropouts, > 1 = a two-state Markov chain with the same long-run share).
    pub burst_len: f64,
    /// Capture times jitter uniformly in ±`timing_jitter` \[s\] about the
    /// nominal grid (< half the period).
    pub timing_jitter: f64,
    /// Per-tick measurement model.
    pub mode: VisionMode,
    /// Phase of the sample grid \[s\]: the captures are shifted this much
    /// earlier, so with a sample rate equal to the control rate (and no
    /// jitter) each sample arrives exactly `arrival_lead` before the control
    /// tick that first sees it (0: on the tick). `0 ..<` one sample period.
    pub arrival_lead: f64,
}

impl Default for VisionOptions {
    fn default() -> Self {
        Self {
            rate_hz: 15.0,
            latency: 0.06,
            latency_jitter: 0.0,
            sigma: 0.02,
            yaw_sigma: 0.0,
            dropout: 0.0,
            burst_len: 1.0,
            timing_jitter: 0.005,
            mode: VisionMode::Extrapolate,
            arrival_lead: 0.0,
        }
    }
}

impl VisionOptions {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), SimError> {
        check_range("vision.rate_hz", self.rate_hz, 1e-3, 1e4, "1e-3 ..= 1e4 Hz")?;
        check_range("vision.latency", self.latency, 0.0, 10.0, "0 ..= 10 s")?;
        check_range(
            "vision.latency_jitter",
            self.latency_jitter,
            0.0,
            10.0,
            "0 ..= 10 s",
        )?;
        check_range("vision.sigma", self.sigma, 0.0, 1e3, "0 ..= 1000 m")?;
        check_range(
            "vision.yaw_sigma",
            self.yaw_sigma,
            0.0,
            10.0,
            "0 ..= 10 rad",
        )?;
        check_range("vision.dropout", self.dropout, 0.0, 0.999, "0 ..= 0.999")?;
        check_range(
            "vision.burst_len",
            self.burst_len,
            1.0,
            1e6,
            "1 ..= 1e6 samples",
        )?;
        if self.burst_len > 1.0 {
            // P(ok → drop) = p / (L·(1 − p)) must be a probability.
            let enter = self.dropout / (self.burst_len * (1.0 - self.dropout));
            check_range(
                "vision.dropout",
                enter,
                0.0,
                1.0,
                "dropout <= burst_len/(burst_len + 1) when burst_len > 1",
            )?;
        }
        check_range(
            "vision.timing_jitter",
            self.timing_jitter,
            0.0,
            0.499 / self.rate_hz,
            "0 ..< half the sample period s",
        )?;
        check_range(
            "vision.arrival_lead",
            self.arrival_lead,
            0.0,
            0.999 / self.rate_hz,
            "0 ..< the sample period s",
        )?;
        check_positive("vision.rate_hz", self.rate_hz)
    }
}

/// Linear interpolation (or extrapolation) of a truth track.
#[derive(Debug, Clone, Copy)]
struct Truth {
    t: f64,
    position: Vector3<f64>,
    velocity: Vector3<f64>,
    yaw: f64,
}

/// Vision stand-in: jittered 15 Hz captures, noise, dropouts, latency.
///
/// Captures happen at `t_k = t_start + k/rate + U(−j, j)`, with `t_start`
/// chosen at reset so that samples captured before `t0` (on the assumed
/// constant-velocity past) arrive from `t0` on. The true pose at a capture
/// time is linearly interpolated between the two plant states around it.
/// Per capture the sensor draws, in this order: one uniform (dropout), four
/// normals (x, y, z, yaw noise), one normal (latency jitter), one uniform
/// (next capture's jitter).
#[derive(Debug, Clone)]
pub struct VisionSensor {
    options: VisionOptions,
    rng: ChaCha8Rng,
    t_start: f64,
    k: u64,
    next_capture: f64,
    reset_truth: Option<Truth>,
    prev: Option<Truth>,
    cur: Option<Truth>,
    dropping: bool,
    last_arrival: f64,
    in_flight: VecDeque<PoseSample>,
    received: [Option<PoseSample>; 2],
    new: Vec<PoseSample>,
    stats: VisionStats,
}

/// Counters of a [`VisionSensor`] since its last reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct VisionStats {
    /// Captures taken (including dropped ones).
    pub captured: u64,
    /// Captures dropped.
    pub dropped: u64,
    /// Samples delivered to the controller so far.
    pub delivered: u64,
}

impl VisionSensor {
    /// A sensor with validated `options`, randomness seeded by `seed`.
    pub fn new(options: VisionOptions, seed: u64) -> Result<Self, SimError> {
        options.validate()?;
        Ok(Self {
            options,
            rng: stream(seed, STREAM_SENSOR),
            t_start: 0.0,
            k: 0,
            next_capture: f64::INFINITY,
            reset_truth: None,
            prev: None,
            cur: None,
            dropping: false,
            last_arrival: f64::NEG_INFINITY,
            in_flight: VecDeque::new(),
            received: [None, None],
            new: Vec::new(),
            stats: VisionStats::default(),
        })
    }

    /// The options.
    pub fn options(&self) -> &VisionOptions {
        &self.options
    }

    /// Capture, dropout and delivery counters since the last reset.
    pub fn stats(&self) -> VisionStats {
        self.stats
    }

    fn period(&self) -> f64 {
        1.0 / self.options.rate_hz
    }

    fn jitter(&mut self) -> f64 {
        let u: f64 = self.rng.random();
        self.options.timing_jitter * (2.0 * u - 1.0)
    }

    /// True pose at `tc`: the reset track before the first observation,
    /// else interpolated between the last two observed states.
    fn truth_at(&self, tc: f64) -> Option<(Vector3<f64>, f64)> {
        let extrapolate = |a: &Truth| (a.position + a.velocity * (tc - a.t), a.yaw);
        match (self.prev, self.cur) {
            (Some(a), Some(b)) if tc >= a.t => {
                if b.t > a.t {
                    let s = (tc - a.t) / (b.t - a.t);
                    Some((
                        a.position + (b.position - a.position) * s,
                        a.yaw + (b.yaw - a.yaw) * s,
                    ))
                } else {
                    Some((b.position, b.yaw))
                }
            }
            _ => self.reset_truth.as_ref().map(extrapolate),
        }
    }

    /// Captures every scheduled sample up to time `t`.
    fn capture_until(&mut self, t: f64) {
        while self.next_capture <= t {
            let tc = self.next_capture;
            let Some((p, yaw)) = self.truth_at(tc) else {
                return;
            };
            let u: f64 = self.rng.random();
            let n = [
                normal(&mut self.rng),
                normal(&mut self.rng),
                normal(&mut self.rng),
                normal(&mut self.rng),
            ];
            let nl = normal(&mut self.rng);
            let o = &self.options;
            let drop = if o.burst_len > 1.0 {
                if self.dropping {
                    u < 1.0 - 1.0 / o.burst_len
                } else {
                    u < o.dropout / (o.burst_len * (1.0 - o.dropout))
                }
            } else {
                u < o.dropout
            };
            self.dropping = drop;
            self.stats.captured += 1;
            self.stats.dropped += u64::from(drop);
            if !drop {
                let latency = (o.latency + o.latency_jitter * nl).max(0.0);
                let arrival = (tc + latency).max(self.last_arrival);
                self.last_arrival = arrival;
                self.in_flight.push_back(PoseSample {
                    t_measured: tc,
                    t_arrival: arrival,
                    position: p + Vector3::new(n[0], n[1], n[2]) * o.sigma,
                    yaw: yaw + o.yaw_sigma * n[3],
                });
            }
            self.k += 1;
            let j = self.jitter();
            self.next_capture = self.t_start + self.k as f64 * self.period() + j;
        }
    }
}

impl Sensor for VisionSensor {
    fn reset(&mut self, t0: f64, truth: &PlantState) {
        let period = self.period();
        self.t_start = t0 - self.options.latency - 2.0 * period - self.options.arrival_lead;
        self.k = 0;
        self.dropping = false;
        self.last_arrival = f64::NEG_INFINITY;
        self.in_flight.clear();
        self.received = [None, None];
        self.new.clear();
        self.stats = VisionStats::default();
        self.prev = None;
        self.cur = None;
        self.reset_truth = Some(Truth {
            t: t0,
            position: truth.position,
            velocity: truth.velocity,
            yaw: truth.yaw,
        });
        let j = self.jitter();
        self.next_capture = self.t_start + j;
        self.capture_until(t0);
    }

    fn observe(&mut self, t: f64, truth: &PlantState) {
        let now = Truth {
            t,
            position: truth.position,
            velocity: truth.velocity,
            yaw: truth.yaw,
        };
        self.prev = self.cur.or(self.reset_truth);
        self.cur = Some(now);
        self.capture_until(t);
    }

    fn measure(&mut self, t: f64) -> Option<Measurement> {
        self.new.clear();
        while let Some(s) = self.in_flight.front() {
            if s.t_arrival > t + 1e-9 {
                break;
            }
            let s = *s;
            self.in_flight.pop_front();
            self.received = [self.received[1], Some(s)];
            self.new.push(s);
            self.stats.delivered += 1;
        }
        let last = self.received[1]?;
        Some(match (self.options.mode, self.received[0]) {
            (VisionMode::Extrapolate, Some(prev)) if last.t_measured > prev.t_measured => {
                let v = (last.position - prev.position) / (last.t_measured - prev.t_measured);
                Measurement {
                    t,
                    position: last.position + v * (t - last.t_measured),
                    yaw: last.yaw,
                }
            }
            (VisionMode::Raw, _) => Measurement {
                t: last.t_measured,
                position: last.position,
                yaw: last.yaw,
            },
            _ => Measurement {
                t,
                position: last.position,
                yaw: last.yaw,
            },
        })
    }

    fn new_samples(&self) -> &[PoseSample] {
        &self.new
    }
}
