//! dflat command-line interface.
fn main() {}
