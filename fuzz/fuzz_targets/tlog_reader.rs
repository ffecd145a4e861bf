//! Fuzz target `tlog_reader`: see [`dflat_fuzz::link_bodies::tlog_reader`].
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dflat_fuzz::link_bodies::tlog_reader(data);
});
