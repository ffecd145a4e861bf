//! Seeded random streams: one independent ChaCha8 stream per consumer, so a
//! trial's plant gusts and sensor noise do not depend on each other (and the
//! noise sequence for a seed is the same whatever controller flies).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Stream id of the plant's gust process.
pub(crate) const STREAM_PLANT: u64 = 1;
/// Stream id of the sensor.
pub(crate) const STREAM_SENSOR: u64 = 2;

/// A ChaCha8 generator for `seed` on stream `stream`.
pub(crate) fn stream(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// One standard normal sample (Box–Muller-free: rand_distr's ziggurat).
pub(crate) fn normal(rng: &mut ChaCha8Rng) -> f64 {
    use rand::Rng;
    rng.sample(rand_distr::StandardNormal)
}
