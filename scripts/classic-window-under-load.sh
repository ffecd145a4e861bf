#!/usr/bin/env bash
# The end-to-end spatial flight (tests/e2e_spatial_flight.rs: the daemon
# against the in-process SITL, a short L at 10 m altitude) flown beside
# busy loops that starve the machine, with the paper's classic window
# (`multi_rate = false`) and with the shipped multi-rate window; prints
# each flight's largest altitude error (docs/configuration.md, "The
# settings that matter most in flight").
#
#   scripts/classic-window-under-load.sh          # 3 busy loops, 12 flights each
#   LOOPS=2 FLIGHTS=5 scripts/classic-window-under-load.sh
set -euo pipefail
cd "$(dirname "$0")/.."
loops="${LOOPS:-3}"
flights="${FLIGHTS:-12}"
cargo test -q -p dflat-e2e --test e2e_spatial_flight --no-run 2>/dev/null
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT
for _ in $(seq "$loops"); do
    ( while :; do :; done ) &
    pids+=($!)
done
echo "$loops busy loops on $(nproc) cores"
for window in classic multi-rate; do
    if [ "$window" = classic ]; then
        filter=(spatial_model_streams_at_50_hz_and_holds_altitude_classic_window --exact)
    else
        filter=(spatial_model_streams_at_50_hz_and_holds_altitude --exact)
    fi
    errors=()
    for _ in $(seq "$flights"); do
        e=$(cargo test -q -p dflat-e2e --test e2e_spatial_flight -- --nocapture "${filter[@]}" 2>&1 \
            | sed -n 's/.*max altitude error \([0-9.]*\) m.*/\1/p' | head -1 || true)
        errors+=("${e:-?}")
    done
    echo "$window window: largest altitude error per flight [m]: ${errors[*]}"
done
