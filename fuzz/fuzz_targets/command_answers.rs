//! Fuzz target `command_answers`: see [`dflat_fuzz::link_bodies::command_answers`].
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dflat_fuzz::link_bodies::command_answers(data);
});
