#!/usr/bin/env bash
# Builds the onboard binary: `dflat` without the SITL, the simulation lab
# and the tuning tools (cargo features `sitl`, `lab`, `tuning` off:
# `--no-default-features`; none of dflat-sim, dflat-sitl, dflat-lab,
# dflat-tuning is linked), with the `onboard` profile
# (release code, no DWARF, symbol names kept), into target/onboard/dflat so
# it never replaces the full build in target/release. Prints its size and
# the wall time of the build.
#
#   scripts/build-onboard.sh            # -> target/onboard/dflat
#
# A cold build (no target/onboard yet) is what docs/deployment.md reports;
# `rm -rf target/onboard` first to reproduce it (the profile's dependencies
# are built in target/onboard/ too, so this only rebuilds the onboard set).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s.%N)
cargo build --profile onboard -p dflat --no-default-features
end=$(date +%s.%N)
bin="${CARGO_TARGET_DIR:-target}/onboard/dflat"
size=$(stat -c %s "$bin")
printf 'onboard binary: %s\n' "$bin"
printf 'size: %d bytes (%.1f MiB)\n' "$size" "$(echo "$size / 1048576" | bc -l)"
printf 'build wall time: %.0f s on %s cores\n' "$(echo "$end - $start" | bc -l)" "$(nproc)"
printf 'subcommands: %s\n' "$("$bin" --help | sed -n '/^Commands:/,/^$/p' | awk 'NR>1 && $1 != "help" {printf "%s ", $1}')"
