//! `dflat` — discrete-flatness MPC flight-control daemon for multirotors.
//!
//! One binary, several subcommands: `daemon`, `check-config`, and (with the
//! default `lab` feature) `sitl`, `demo`, `experiment`. See the README.

fn main() -> std::process::ExitCode {
    dflat::main()
}
