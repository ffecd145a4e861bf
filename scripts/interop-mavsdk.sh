#!/usr/bin/env bash
# Interop with the real SDK (issue 26): MAVSDK-Python (the native binding,
# `pip install mavsdk`, >= 4; its wheel bundles the MAVSDK library) flies
# `dflat sitl --gcs` while the dflat daemon runs, with MAVSDK's defaults
# (ground station 245/190): connect; telemetry incl. home, landed state,
# in_air; info; parameters; a setpoint to the daemon (1/191) through
# mavlink_direct, flown >= 4 m; hold; goto; RTL; offboard to the autopilot;
# the mission protocol; takeoff (refused in words); disarm. Prints a table.
#
#   scripts/interop-mavsdk.sh                  # builds dflat, venv in target/
#   DFLAT_BIN=target/debug/dflat VENV=/tmp/v scripts/interop-mavsdk.sh
#
# Exit status: 0 passed, 1 a required step failed, 3 skipped (pip could
# not install mavsdk: no network, no wheel for this platform).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)
OUT=${OUT:-$ROOT/target/interop-mavsdk}
VENV=${VENV:-$ROOT/target/mavsdk-venv}
mkdir -p "$OUT"

if [[ ! -x "$VENV/bin/python" ]]; then
    python3 -m venv "$VENV" || { echo "interop-mavsdk: SKIPPED (no python3 venv)"; exit 3; }
fi
if ! "$VENV/bin/python" -c 'import mavsdk' 2>/dev/null; then
    if ! "$VENV/bin/pip" install -q 'mavsdk>=4,<5' >"$OUT/pip.log" 2>&1; then
        echo "interop-mavsdk: SKIPPED (pip cannot install mavsdk; see $OUT/pip.log)"
        exit 3
    fi
fi
echo "interop-mavsdk: mavsdk $("$VENV/bin/python" -c 'import mavsdk; print(mavsdk.__version__)')"

# shellcheck source=scripts/sitl-common.sh
source scripts/sitl-common.sh
need_dflat_bin

cat >"$OUT/interop.toml" <<TOML
# scripts/interop-mavsdk.sh: the daemon holds at the start point (the
# local origin, 10 m up) until a ground station gives it a setpoint.
[mission]
start = "hold"
[logging]
dir = "$OUT"
csv = false
tlog = false
[sitl]
start = [0.0, 0.0, -10.0]
TOML

cleanup() {
    stop_daemon_and_sitl
    wait 2>/dev/null || true
}
trap cleanup EXIT

"$DFLAT_BIN" sitl --config "$OUT/interop.toml" --link udpin:127.0.0.1:0 \
    --gcs udpin:127.0.0.1:0 >"$OUT/sitl.out" 2>"$OUT/sitl.log" &
SITL_PID=$!
for _ in $(seq 100); do
    grep -q "sitl gcs on" "$OUT/sitl.out" 2>/dev/null && break
    sleep 0.1
done
LINK=$(sed -n 's/^sitl listening on udpin://p' "$OUT/sitl.out" | head -1)
GCS=$(sed -n 's/^sitl gcs on udpin://p' "$OUT/sitl.out" | head -1)
[[ -n "$LINK" && -n "$GCS" ]] || { echo "interop-mavsdk: the SITL did not start" >&2; exit 1; }

"$DFLAT_BIN" daemon --config "$OUT/interop.toml" --link "udpout:$LINK" \
    >"$OUT/daemon.out" 2>"$OUT/daemon.log" &
DAEMON_PID=$!
sleep 2

set +e
"$VENV/bin/python" scripts/interop_mavsdk.py "udpout://$GCS" | tee "$OUT/table.txt"
STATUS=${PIPESTATUS[0]}
set -e
echo "interop-mavsdk: logs in $OUT (sitl.log, daemon.log, table.txt)"
exit "$STATUS"
