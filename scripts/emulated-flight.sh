#!/usr/bin/env bash
# The arm64 onboard daemon, under emulation, flies the SITL: a check anyone
# can run without an arm64 board.
#
#   scripts/emulated-flight.sh [--no-build] [--glibc VERSION] [SECONDS=25]
#
# Builds the onboard binary for aarch64-unknown-linux-gnu and for the host
# (scripts/build-onboard.sh), then flies the L path of config/sitl.toml
# twice against the native SITL (`dflat sitl`) on loopback, SECONDS each
# (at least 20): once with the native onboard daemon, once with the arm64
# one under qemu-aarch64 (Debian's qemu-user, `-L /usr/aarch64-linux-gnu`).
# The rate held is the autopilot's view: 1 / the SITL's median interval
# between the commands it received (and the longest gap); every other
# figure is the daemon's own (`dflat daemon --summary-json`): missed
# ticks, solve time and pose→command latency, p50 / p99, side by side with
# the slow-down factor; then the budget under qemu: 50.0 Hz, 0 missed
# ticks, pose→command p99 <= 5 ms.
#
# Exit status: 0 within the budget, 1 outside it (or a run failed), 3
# skipped: qemu-aarch64 or the cross linker (gcc-aarch64-linux-gnu) is not
# installed — the reason is printed; 4 inconclusive: the native run missed
# the same budget (the machine was too loaded for the figures to mean
# anything about the arm64 build).
#
# --glibc VERSION builds the arm64 binary against that glibc's symbols
# (build-onboard.sh --glibc: cargo-zigbuild), as for an older companion.
# --no-build flies the onboard binaries already built (by an earlier run or
# scripts/build-onboard.sh) instead of building them first.
# DFLAT_SITL_BIN: the `dflat` that runs the SITL (default: the release
# build, `cargo build --release -p dflat`; CI passes its test build).
# CARGO_TARGET_DIR is respected. Summaries and logs are kept in
# $CARGO_TARGET_DIR/emulated-flight/ (default target/emulated-flight/).
set -euo pipefail
no_build=""
glibc=()
while [ $# -gt 0 ]; do
    case "$1" in
        --no-build) no_build=1; shift ;;
        --glibc) glibc=(--glibc "${2:?--glibc needs a version}"); shift 2 ;;
        *) break ;;
    esac
done
secs=${1:-25}
cd "$(dirname "$0")/.."
if [ "$secs" -lt 20 ]; then
    echo "emulated-flight.sh: fly at least 20 s (got $secs)" >&2
    exit 2
fi
target=aarch64-unknown-linux-gnu
sysroot=/usr/aarch64-linux-gnu
skip() { echo "emulated flight: skipped: $*"; exit 3; }
command -v qemu-aarch64 >/dev/null || skip "qemu-aarch64 is not installed (apt-get install qemu-user)"
command -v aarch64-linux-gnu-gcc >/dev/null || skip "the aarch64 cross linker is not installed (apt-get install gcc-aarch64-linux-gnu)"
[ -d "$sysroot/lib" ] || skip "no arm64 C library at $sysroot (apt-get install libc6-dev-arm64-cross)"

tdir=${CARGO_TARGET_DIR:-target}
out="$tdir/emulated-flight"
mkdir -p "$out"
build() { # $@: build-onboard.sh arguments; prints the binary's path
    scripts/build-onboard.sh "$@" >"$out/build.log" 2>&1 || { cat "$out/build.log" >&2; return 1; }
    sed -n 's/^onboard binary: //p' "$out/build.log" | tail -1
}
if [ -n "$no_build" ]; then
    arm_bin=$tdir/$target/onboard/dflat
    native_bin=$tdir/onboard/dflat
    for b in "$arm_bin" "$native_bin"; do
        [ -x "$b" ] || { echo "emulated-flight.sh: --no-build, but $b is not built" >&2; exit 1; }
    done
else
    echo "building the onboard daemon for $target and for the host ..."
    arm_bin=$(build --target "$target" ${glibc[@]+"${glibc[@]}"})
    native_bin=$(build)
fi
if [ -n "${DFLAT_SITL_BIN:-}" ]; then
    sitl_bin=$DFLAT_SITL_BIN
else
    cargo build --release -p dflat >"$out/build.log" 2>&1 || { cat "$out/build.log" >&2; exit 1; }
    sitl_bin=$tdir/release/dflat
fi
echo "arm64 daemon: $arm_bin ($(file -b "$arm_bin" 2>/dev/null | cut -d, -f1-2 || echo ELF))"
echo "native daemon: $native_bin; SITL: $sitl_bin"

work=$(mktemp -d)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
    rm -rf "$work"
}
trap cleanup EXIT
sed -e "s|^dir = \"flights\"|dir = \"$work/flights\"|" config/sitl.toml >"$work/flight.toml"

fly() { # $1 = case name, then the daemon's command line
    local name=$1; shift
    "$sitl_bin" sitl --config "$work/flight.toml" --link udpin:127.0.0.1:0 >"$out/$name.sitl.out" 2>"$out/$name.sitl.err" &
    local sitl=$!
    pids+=("$sitl")
    local addr=""
    for _ in $(seq 100); do
        addr=$(sed -n 's/^sitl listening on udpin://p' "$out/$name.sitl.out")
        [ -n "$addr" ] && break
        sleep 0.1
    done
    [ -n "$addr" ] || { echo "$name: the SITL did not start" >&2; cat "$out/$name.sitl.err" >&2; return 1; }
    rm -f "$out/$name.json"
    "$@" daemon --config "$work/flight.toml" --link "udpout:$addr" \
        --summary-json "$out/$name.json" >"$out/$name.daemon.out" 2>"$out/$name.daemon.err" &
    local daemon=$!
    pids+=("$daemon")
    sleep "$secs"
    kill -INT "$daemon" 2>/dev/null || true
    wait "$daemon" || echo "$name: the daemon exited with $? (see $out/$name.daemon.err)" >&2
    kill -INT "$sitl" 2>/dev/null || true
    wait "$sitl" || true
    [ -s "$out/$name.json" ] || { echo "$name: no summary (see $out/$name.daemon.err)" >&2; tail -5 "$out/$name.daemon.err" >&2; return 1; }
}

echo "flying ${secs} s natively ..."
fly native "$native_bin"
echo "flying ${secs} s with the arm64 daemon under qemu-aarch64 ..."
fly qemu qemu-aarch64 -L "$sysroot" "$arm_bin"

python3 - "$out/native.json" "$out/qemu.json" "$secs" "$out/native.sitl.out" "$out/qemu.sitl.out" <<'EOF'
import json, re, sys
native, qemu = (json.load(open(p)) for p in sys.argv[1:3])
secs = sys.argv[3]
# The autopilot's view of the stream: the SITL's median command interval
# (its last line, "... command interval p50 N µs, ... max interval M µs").
for s, path in ((native, sys.argv[4]), (qemu, sys.argv[5])):
    text = open(path).read()
    m = re.search(r"command interval p50 (\d+) µs, jitter p99 (\d+) µs, max interval (\d+) µs", text)
    s["sitl_interval"] = tuple(int(x) for x in m.groups()) if m else (0, 0, 0)

def rate(s):
    # The rate the autopilot saw: 1 / the median interval between the
    # commands it received.
    p50 = s["sitl_interval"][0]
    return 1e6 / p50 if p50 else 0.0

rows = [
    ("rate held [Hz]", rate, "{:.1f}", False),
    ("longest gap [ms]", lambda s: s["sitl_interval"][2] / 1000, "{:.1f}", False),
    ("missed ticks", lambda s: s["missed_ticks"], "{}", False),
    ("solve p50 [µs]", lambda s: s["solve_us"]["p50"], "{}", True),
    ("solve p99 [µs]", lambda s: s["solve_us"]["p99"], "{}", True),
    ("pose→command p50 [µs]", lambda s: s["latency_us"]["p50"], "{}", True),
    ("pose→command p99 [µs]", lambda s: s["latency_us"]["p99"], "{}", True),
    ("tick→command p50 [µs]", lambda s: s["tick_to_send_us"]["p50"], "{}", True),
    ("tick→command p99 [µs]", lambda s: s["tick_to_send_us"]["p99"], "{}", True),
    ("tick jitter p99 [µs]", lambda s: s["jitter_us"]["p99"], "{}", False),
]
print(f"emulated flight: {secs} s each against the native SITL (config/sitl.toml, the L path), "
      f"{native['ticks']} / {qemu['ticks']} ticks, {native['commands']} / {qemu['commands']} commands")
print(f"  {'':24}{'native':>12}{'arm64 qemu':>14}{'slow-down':>12}")
for name, get, fmt, factor in rows:
    a, b = get(native), get(qemu)
    f = f"{b / a:.1f}x" if factor and a else ""
    print(f"  {name:24}{fmt.format(a):>12}{fmt.format(b):>14}{f:>12}")
def cpu(s):
    c = s.get("cpu_percent")
    return f"{c:.1f} %" if c else "n/a"
print(f"  flight: {qemu['time_in_state_s']['tracking']:.1f} s tracking the path / "
      f"{native['time_in_state_s']['tracking']:.1f} s natively, engagements {qemu['engagements']} / "
      f"{native['engagements']}, control errors {qemu['control_errors']} / {native['control_errors']}, "
      f"CPU {cpu(qemu)} / {cpu(native)} (qemu-user does not emulate the process's CPU time), "
      f"peak RSS {qemu['peak_rss_kib']} / {native['peak_rss_kib']} KiB")
def within(s):
    return (round(rate(s), 1) >= 50.0 and s["missed_ticks"] == 0
            and s["latency_us"]["p99"] <= 5000 and s["engagements"] >= 1)
r, missed, p99 = rate(qemu), qemu["missed_ticks"], qemu["latency_us"]["p99"]
ok = within(qemu)
print(f"budget under qemu: 50.0 Hz (got {r:.1f}), 0 missed ticks (got {missed}), "
      f"pose→command p99 <= 5000 µs (got {p99}, margin {5000 - p99} µs): {'PASS' if ok else 'FAIL'}")
if not ok and not within(native):
    # The native run is the control: when it misses the same budget, the
    # host was too busy for the figures to say anything about the build.
    print("inconclusive: the native daemon missed the same budget in this run "
          f"({native['missed_ticks']} missed ticks, pose→command p99 {native['latency_us']['p99']} µs): "
          "the machine is loaded; run again on a quiet one")
    sys.exit(4)
sys.exit(0 if ok else 1)
EOF
