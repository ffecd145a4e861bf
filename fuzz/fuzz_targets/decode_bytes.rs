//! Raw bytes → FrameParser (chunked) → LinkRx → daemon event mapping →
//! Supervisor / PoseClock with 50 Hz ticks on a synthetic clock.
//!
//! Input: byte 0 picks the daemon configuration (pose source, setpoint
//! sources, time stamping, mission start, geofence), byte 1 seeds the chunk
//! sizes, the rest is the received byte stream. Each frame's arrival is its
//! header sequence number in milliseconds after the previous one, so the
//! fuzzer controls staleness and timeouts.
#![no_main]

use dflat_fuzz::{Harness, Lcg, check_chunked_equals_whole, config};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [flags, seed, stream @ ..] = data else {
        return;
    };
    let mut h = Harness::new(&config(*flags));
    let mut lcg = Lcg(u64::from(*seed));
    let mut rest = stream;
    while !rest.is_empty() {
        let n = (lcg.next_u32() as usize % 300 + 1).min(rest.len());
        h.push(&rest[..n], &mut |f| f64::from(f.header.sequence) * 1e-3);
        rest = &rest[n..];
    }
    h.finish();
    h.advance(1.0);

    let mut lcg = Lcg(u64::from(*seed) ^ 0x9e37_79b9);
    check_chunked_equals_whole(stream, &mut || lcg.next_u32() as usize % 64 + 1);
});
