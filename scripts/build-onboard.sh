#!/usr/bin/env bash
# Builds the onboard binary: `dflat` without the SITL, the simulation lab
# and the tuning tools (cargo features `sitl`, `lab`, `tuning` off:
# `--no-default-features`; none of dflat-sim, dflat-sitl, dflat-lab,
# dflat-tuning is linked), with the `onboard` profile
# (release code, no DWARF, symbol names kept), so it never replaces the full
# build in target/release. Prints its size and the wall time of the build.
#
#   scripts/build-onboard.sh                                   # host -> target/onboard/dflat
#   scripts/build-onboard.sh --target aarch64-unknown-linux-gnu
#                                  # arm64 -> target/aarch64-unknown-linux-gnu/onboard/dflat
#   scripts/build-onboard.sh --target aarch64-unknown-linux-gnu --glibc 2.27
#                                  # the same, for an older C library (a TX2 on JetPack 4)
#
# Cross builds: the Rust target is added with `rustup target add` if it is
# missing; the C cross linker comes from Debian (gcc-aarch64-linux-gnu for
# aarch64, gcc-arm-linux-gnueabihf for armv7, gcc-x86-64-linux-gnu for
# x86_64 on an arm64 host): the script names the package when the linker is
# not installed. The linker is passed to cargo in the environment
# (CARGO_TARGET_<TRIPLE>_LINKER) for this build only; no .cargo/config is
# written, so the README's commands are unaffected. An already set
# CARGO_TARGET_<TRIPLE>_LINKER is respected.
#
# --glibc VERSION links against that glibc version's symbols (so the binary
# runs on systems as old as that, e.g. 2.27 for Ubuntu 18.04) with
# cargo-zigbuild, zig as the linker: `pip install ziglang && cargo install
# cargo-zigbuild`; without it, the binary needs the build machine's glibc
# (2.35 or newer here: Debian 12).
#
# CARGO_TARGET_DIR is respected (default: target/). The last line printed
# is `onboard binary: PATH`, for other scripts (package.sh,
# emulated-flight.sh) to read.
#
# A cold build (no target/onboard yet) is what docs/deployment.md reports;
# `rm -rf target/onboard` first to reproduce it (the profile's dependencies
# are built in target/onboard/ too, so this only rebuilds the onboard set).
set -euo pipefail
cd "$(dirname "$0")/.."

target=""
glibc=""
while [ $# -gt 0 ]; do
    case "$1" in
        --target) target=${2:?--target needs a triple}; shift 2 ;;
        --target=*) target=${1#--target=}; shift ;;
        --glibc) glibc=${2:?--glibc needs a version, e.g. 2.27}; shift 2 ;;
        -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
        *) echo "build-onboard.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
    esac
done
host=$(rustc -vV | sed -n 's/^host: //p')
if [ -n "$glibc" ]; then
    target=${target:-$host}
    if ! command -v cargo-zigbuild >/dev/null || ! { command -v zig >/dev/null || python3 -m ziglang version >/dev/null 2>&1; }; then
        echo "build-onboard.sh: --glibc needs cargo-zigbuild and zig:" >&2
        echo "  pip install ziglang && cargo install cargo-zigbuild" >&2
        exit 1
    fi
elif [ "$target" = "$host" ]; then
    target=""
fi

tdir=${CARGO_TARGET_DIR:-target}
args=(--profile onboard -p dflat --no-default-features)
if [ -n "$target" ]; then
    if ! rustup target list --installed 2>/dev/null | grep -qx "$target"; then
        echo "build-onboard.sh: adding the Rust target $target (rustup target add)"
        rustup target add "$target"
    fi
    # The C toolchain that links for the target, and Debian's package for it.
    case "$target" in
        aarch64-unknown-linux-gnu) cc=aarch64-linux-gnu-gcc; pkg=gcc-aarch64-linux-gnu ;;
        armv7-unknown-linux-gnueabihf) cc=arm-linux-gnueabihf-gcc; pkg=gcc-arm-linux-gnueabihf ;;
        x86_64-unknown-linux-gnu) cc=x86_64-linux-gnu-gcc; pkg=gcc-x86-64-linux-gnu ;;
        *) echo "build-onboard.sh: no known cross linker for $target; set CARGO_TARGET_<TRIPLE>_LINKER" >&2; cc=""; pkg="" ;;
    esac
    var="CARGO_TARGET_$(echo "$target" | tr 'a-z-' 'A-Z_')_LINKER"
    if [ -z "${!var:-}" ] && [ -n "$cc" ] && [ -z "$glibc" ]; then
        if ! command -v "$cc" >/dev/null; then
            echo "build-onboard.sh: the linker $cc for $target is not installed." >&2
            echo "  Debian/Ubuntu: sudo apt-get install $pkg" >&2
            exit 1
        fi
        export "$var=$cc"
    fi
    args+=(--target "$target${glibc:+.$glibc}")
    bin="$tdir/$target/onboard/dflat"
else
    bin="$tdir/onboard/dflat"
fi

start=$(date +%s.%N)
if [ -n "$glibc" ]; then
    cargo zigbuild "${args[@]}"
else
    cargo build "${args[@]}"
fi
end=$(date +%s.%N)
size=$(stat -c %s "$bin")
printf 'target: %s\n' "${target:-$host (host)}${glibc:+, glibc $glibc (cargo-zigbuild)}"
printf 'size: %d bytes (%.1f MiB)\n' "$size" "$(echo "$size / 1048576" | bc -l)"
printf 'build wall time: %.0f s on %s cores\n' "$(echo "$end - $start" | bc -l)" "$(nproc)"
if [ -z "$target" ]; then
    printf 'subcommands: %s\n' "$("$bin" --help | sed -n '/^Commands:/,/^$/p' | awk 'NR>1 && $1 != "help" {printf "%s ", $1}')"
elif command -v file >/dev/null; then
    printf 'file: %s\n' "$(file -b "$bin" | cut -d, -f1-2)"
fi
printf 'onboard binary: %s\n' "$bin"
