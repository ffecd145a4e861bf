//! `dflat` as the end-to-end tests run it: the same `main` as the shipped
//! binary (`dflat::main`), built in this package so the tests find it.

fn main() -> std::process::ExitCode {
    dflat::main()
}
