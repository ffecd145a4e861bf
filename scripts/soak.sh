#!/usr/bin/env bash
# Soak test (not in CI): the SITL and the daemon fly a closed path in loops
# (`mission.repeat = true`) for MINUTES (default 30) with position noise,
# vision-rate poses (30 Hz, 60 ms latency) and pose dropouts (the whole pose
# stream paused for 60 ms — below the 100 ms pose timeout — every 10 s, via
# the SITL's SIGUSR1 / SIGUSR2). Every SAMPLE seconds (default 10) it
# records the daemon's resident memory (VmRSS from /proc/PID/status) and the
# tick jitter of the interval (p50 / p99 / max from the daemon's per-flight
# CSV) into soak.csv, and prints a summary at the end.
#
#   scripts/soak.sh [MINUTES]         # e.g. scripts/soak.sh 5
#   SAMPLE=5 OUT=/tmp/soak scripts/soak.sh 2
#   DFLAT_BIN=/path/to/dflat scripts/soak.sh   # skip the build
#
# Output directory: $OUT (default soak-YYYYmmdd-HHMMSS/): soak.csv, the
# daemon's flight CSV and summary.json, both processes' logs. Linux only
# (/proc). The binary is copied first, so rebuilding meanwhile is harmless.
set -euo pipefail

MINUTES=${1:-30}
SAMPLE=${SAMPLE:-10}
OUT=${OUT:-soak-$(date -u +%Y%m%d-%H%M%S)}
cd "$(dirname "$0")/.."
ROOT=$(pwd)
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)

# shellcheck source=scripts/sitl-common.sh
source scripts/sitl-common.sh
need_dflat_bin
cp "$DFLAT_BIN" "$OUT/dflat"
BIN="$OUT/dflat"

cat >"$OUT/soak.toml" <<TOML
# scripts/soak.sh: a closed 20 m × 30 m rectangle at 5 m/s, flown in loops.
[link]
pose_source = "vision_position_estimate"
[controller.dfmpc]
multi_rate = true
[mission]
start = "path"
path = [[-20.0, -30.0, -10.0], [0.0, -30.0, -10.0], [0.0, 0.0, -10.0], [-20.0, 0.0, -10.0], [-20.0, -30.0, -10.0]]
speed = 5.0
repeat = true
[logging]
dir = "$OUT"
csv = true
tlog = false
[sitl]
start = [-20.0, -30.0, -10.0]
noise_sigma = 0.02
vision_rate_hz = 30.0
vision_latency_ms = 60.0
vision_noise_sigma = 0.02
TOML

trap stop_daemon_and_sitl EXIT

"$BIN" sitl --config "$OUT/soak.toml" --link udpin:127.0.0.1:0 \
    >"$OUT/sitl.out" 2>"$OUT/sitl.log" &
SITL_PID=$!
for _ in $(seq 100); do
    grep -q "sitl listening on" "$OUT/sitl.out" 2>/dev/null && break
    sleep 0.1
done
ADDR=$(sed -n 's/^sitl listening on udpin://p' "$OUT/sitl.out" | head -1)
[[ -n "$ADDR" ]] || { echo "soak: the SITL did not start" >&2; exit 1; }

"$BIN" daemon --config "$OUT/soak.toml" --link "udpout:$ADDR" \
    --summary-json "$OUT/summary.json" >"$OUT/daemon.out" 2>"$OUT/daemon.log" &
DAEMON_PID=$!
sleep 1
FLIGHT_CSV=$(ls -t "$OUT"/*.csv 2>/dev/null | grep -v '/soak.csv$' | head -1 || true)
[[ -n "$FLIGHT_CSV" ]] || { echo "soak: no flight CSV in $OUT" >&2; exit 1; }
# The CSV is written through a buffer: wait for its header.
for _ in $(seq 300); do
    head -1 "$FLIGHT_CSV" | grep -q jitter_us && break
    sleep 0.1
done
JCOL=$(head -1 "$FLIGHT_CSV" | tr ',' '\n' | grep -n '^jitter_us$' | cut -d: -f1)
SCOL=$(head -1 "$FLIGHT_CSV" | tr ',' '\n' | grep -n '^state$' | cut -d: -f1)

echo "soak: $MINUTES min, sampling every $SAMPLE s → $OUT/soak.csv"
echo "t_s,rss_kib,ticks,jitter_p50_us,jitter_p99_us,jitter_max_us,max_tick_gap,failsafe_ticks" >"$OUT/soak.csv"
START=$(date +%s)
END=$((START + MINUTES * 60))
DONE_LINES=1
NEXT_DROPOUT=$((START + 10))
while (( $(date +%s) < END )); do
    sleep "$SAMPLE"
    kill -0 "$DAEMON_PID" 2>/dev/null || { echo "soak: the daemon died" >&2; exit 1; }
    NOW=$(date +%s)
    if (( NOW >= NEXT_DROPOUT )); then
        # Dropouts: 60 ms without any pose, once per 10 s since the last sample.
        while (( NEXT_DROPOUT <= NOW )); do
            kill -USR1 "$SITL_PID"; sleep 0.06; kill -USR2 "$SITL_PID"
            NEXT_DROPOUT=$((NEXT_DROPOUT + 10))
            (( NEXT_DROPOUT <= NOW )) && sleep 1
        done
    fi
    RSS=$(awk '/^VmRSS:/ {print $2}' "/proc/$DAEMON_PID/status")
    TOTAL=$(wc -l <"$FLIGHT_CSV")
    # The complete rows written since the last sample.
    SEG=$(sed -n "$((DONE_LINES + 1)),$((TOTAL - 1))p" "$FLIGHT_CSV")
    DONE_LINES=$((TOTAL - 1))
    N=$(printf '%s\n' "$SEG" | grep -c . || true)
    if (( N > 0 )); then
        STATS=$(printf '%s\n' "$SEG" | cut -d, -f"$JCOL" | sort -n |
            awk '{a[NR] = $1} END {
                p50 = a[int(0.50 * (NR - 1)) + 1]; p99 = a[int(0.99 * (NR - 1)) + 1]
                printf "%d,%d,%d", p50, p99, a[NR] }')
        GAP=$(printf '%s\n' "$SEG" | awk -F, 'NR > 1 && $1 - p > g { g = $1 - p } { p = $1 } END { print g + 0 }')
        FS=$(printf '%s\n' "$SEG" | awk -F, -v s="$SCOL" '$s == "FAILSAFE" { n++ } END { print n + 0 }')
    else
        STATS=",,"; GAP=0; FS=0
    fi
    LINE="$((NOW - START)),$RSS,$N,$STATS,$GAP,$FS"
    echo "$LINE" >>"$OUT/soak.csv"
    echo "  $LINE"
done

kill -INT "$DAEMON_PID"
wait "$DAEMON_PID" || echo "soak: the daemon exited with $?" >&2
DAEMON_PID=
kill -INT "$SITL_PID"
wait "$SITL_PID" || true
SITL_PID=

echo
echo "soak summary ($MINUTES min, $OUT):"
awk -F, 'NR == 2 { first = $2 } NR > 1 {
        last = $2; if ($2 > max) max = $2; if ($5 > p99) p99 = $5; if ($6 > jmax) jmax = $6
        if ($7 > gap) gap = $7; fs += $8; ticks += $3; n++ }
    END {
        printf "  RSS            first %.1f MiB, last %.1f MiB, max %.1f MiB (growth %+.1f MiB)\n",
            first / 1024, last / 1024, max / 1024, (last - first) / 1024
        printf "  tick jitter    worst interval p99 %d µs, max %d µs (%d intervals, %d ticks)\n",
            p99, jmax, n, ticks
        printf "  tick gaps      largest %d (1 = none missed); FAILSAFE ticks %d\n", gap, fs
    }' "$OUT/soak.csv"
sed -n '/^flight summary\|^  /p' "$OUT/daemon.out" | head -40
