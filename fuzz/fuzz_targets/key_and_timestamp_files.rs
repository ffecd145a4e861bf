//! Fuzz target `key_and_timestamp_files`: see [`dflat_fuzz::link_bodies::key_and_timestamp_files`].
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dflat_fuzz::link_bodies::key_and_timestamp_files(data);
});
