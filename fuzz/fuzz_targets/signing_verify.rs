//! Fuzz target `signing_verify`: see [`dflat_fuzz::link_bodies::signing_verify`].
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dflat_fuzz::link_bodies::signing_verify(data);
});
