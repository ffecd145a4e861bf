#!/usr/bin/env bash
# Pose → command latency and tick jitter of the daemon against the SITL on
# loopback (separate processes, 50 Hz LOCAL_POSITION_NED), idle and with a
# CPU hog on both cores, with and without [realtime]:
#
#   scripts/latency-under-load.sh [SECONDS=30] [TICK=pose]
#
# Cases: idle / hog × rt off / rt on (fifo_priority 80, cpus [1],
# lock_memory). The hog is `stress-ng --cpu 2` (apt-get install stress-ng),
# else two busy-loop shells. The SITL stands in for the autopilot — another
# computer in a real vehicle — so it runs at SCHED_FIFO 90 (`chrt`) in every
# case: its pose stream stays on time and what is measured is the daemon.
# Needs root (or CAP_SYS_NICE) for the rt cases; prints the daemon's and the
# SITL's figures per case.
set -euo pipefail
secs=${1:-30}
tick=${2:-pose}
cd "$(dirname "$0")/.."
cargo build --release -p dflat >/dev/null
bin=${CARGO_TARGET_DIR:-target}/release/dflat
work=$(mktemp -d)
trap 'kill $(jobs -p) 2>/dev/null || true; rm -rf "$work"' EXIT

config() { # $1 = rt on/off
    sed -e "s|^dir = \"flights\"|dir = \"$work/flights\"|" \
        -e "s|^tick = \"pose\"|tick = \"$tick\"|" \
        -e 's|^start = "path"|start = "hold"|' config/sitl.toml >"$work/$1.toml"
    if [ "$1" = on ]; then
        sed -i -e 's|^fifo_priority = 0|fifo_priority = 80|' \
            -e 's|^cpus = \[\]|cpus = [1]|' \
            -e 's|^lock_memory = false|lock_memory = true|' "$work/$1.toml"
    fi
}

hog_start() {
    if command -v stress-ng >/dev/null; then
        stress-ng --cpu 2 --timeout $((secs + 10))s >/dev/null 2>&1 &
    else
        for _ in 1 2; do (while :; do :; done) & done
    fi
}

run_case() { # $1 = idle/hog, $2 = rt on/off
    config "$2"
    local hog_pids=""
    if [ "$1" = hog ]; then
        hog_start
        hog_pids=$(jobs -p)
        sleep 1
    fi
    chrt -f 90 "$bin" sitl --config "$work/$2.toml" >"$work/sitl.out" 2>/dev/null &
    local sitl=$!
    sleep 0.5
    "$bin" daemon --config "$work/$2.toml" >"$work/daemon.out" 2>"$work/daemon.err" &
    local daemon=$!
    sleep "$secs"
    kill -INT "$daemon"; wait "$daemon" || true
    kill -INT "$sitl"; wait "$sitl" || true
    [ -n "$hog_pids" ] && kill $hog_pids 2>/dev/null && wait $hog_pids 2>/dev/null || true
    echo "== $1, realtime $2, tick = $tick, ${secs} s"
    grep -E "tick jitter|pose→command|tick→command|tick = |realtime|duration" "$work/daemon.out" || tail -3 "$work/daemon.err"
    grep -E "pose→command" "$work/sitl.out" || true
}

for load in idle hog; do
    for rt in off on; do
        run_case "$load" "$rt"
    done
done
