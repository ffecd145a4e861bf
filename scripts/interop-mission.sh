#!/usr/bin/env bash
# Missions to the daemon (1/191) from third-party ground-station software:
# pymavlink's mission messages, and MAVProxy's `wp` module aimed at
# component 191. For each, the SITL (with its ground-station port) and the
# daemon are started on loopback, the mission is uploaded, started with
# MAV_CMD_MISSION_START, and every MISSION_ITEM_REACHED is waited for.
# Prints one table row per client.
#
#   scripts/interop-mission.sh
#   DFLAT_BIN=/path/to/dflat scripts/interop-mission.sh   # skip the build
#   VENV=/tmp/venv scripts/interop-mission.sh             # reuse a venv
#
# Needs python3 with venv and PyPI (pip install pymavlink MAVProxy). CI
# runs it only where pip works. MAVProxy (and pymavlink's mavwp) scale the
# x / y of every MISSION_ITEM_INT by 1e7, local frames included (the
# MAVLink specification says 1e4 for local frames), so its run sets
# `mission.local_xy_scale = 1e7`.
set -euo pipefail

cd "$(dirname "$0")/.."
OUT=$(mktemp -d "${TMPDIR:-/tmp}/dflat-interop-XXXXXX")
VENV=${VENV:-$OUT/venv}

if [[ ! -x "$VENV/bin/python" ]]; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q pymavlink MAVProxy
fi
PY="$VENV/bin/python"
MAVPROXY="$VENV/bin/mavproxy.py"

if [[ -z "${DFLAT_BIN:-}" ]]; then
    cargo build -q -p dflat --bin dflat
    TARGET=$(cargo metadata --format-version 1 --no-deps |
        sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
    DFLAT_BIN="$TARGET/debug/dflat"
fi

PIDS=()
cleanup() {
    for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# Starts the SITL and the daemon with `local_xy_scale`; sets GCS_PORT.
start_vehicle() {
    local name=$1 scale=$2
    cat >"$OUT/$name.toml" <<TOML
[link]
url = "udpout:127.0.0.1:1"
[mission]
start = "hold"
local_xy_scale = $scale
[logging]
dir = ""
[sitl]
start = [0.0, 0.0, -10.0]
engage = "auto"
TOML
    "$DFLAT_BIN" sitl --config "$OUT/$name.toml" --link udpin:127.0.0.1:0 \
        --gcs udpin:127.0.0.1:0 >"$OUT/$name.sitl.out" 2>"$OUT/$name.sitl.err" &
    PIDS+=($!)
    local link="" gcs=""
    for _ in $(seq 100); do
        link=$(sed -n 's/.*sitl listening on udpin:\([0-9.:]*\).*/\1/p' "$OUT/$name.sitl.out")
        gcs=$(sed -n 's/.*sitl gcs on udpin:\([0-9.:]*\).*/\1/p' "$OUT/$name.sitl.out")
        [[ -n "$link" && -n "$gcs" ]] && break
        sleep 0.1
    done
    "$DFLAT_BIN" daemon --config "$OUT/$name.toml" --link "udpout:$link" \
        >/dev/null 2>"$OUT/$name.daemon.err" &
    PIDS+=($!)
    GCS_PORT=${gcs##*:}
    sleep 2
}

# The mission: a 6 m × 4 m L at 3 m/s from the start, facing east on the
# second leg. Written for pymavlink (items) and as a QGC WPL file (MAVProxy).
cat >"$OUT/mission.txt" <<'WPL'
QGC WPL 110
0	0	1	178	1	3	-1	0	0	0	0	1
1	0	1	16	0	0.5	0	0	6	0	-10	1
2	0	1	16	0	0.5	0	90	6	4	-10	1
WPL

cat >"$OUT/client.py" <<'PY'
"""Ground-station side of scripts/interop-mission.sh."""
import sys, time
from pymavlink import mavutil

mode, port = sys.argv[1], int(sys.argv[2])
m = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                               source_component=190)
M = mavutil.mavlink
def beat():
    m.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
beat()
m.wait_heartbeat(timeout=10)
t0 = time.time()
upload = "mavproxy"
if mode == "pymavlink":
    upload = "?"
    items = [  # (command, params, x, y, z) in metres, LOCAL_NED
        (M.MAV_CMD_DO_CHANGE_SPEED, (1, 3, -1, 0), 0, 0, 0),
        (M.MAV_CMD_NAV_WAYPOINT, (0, 0.5, 0, float("nan")), 6, 0, -10),
        (M.MAV_CMD_NAV_WAYPOINT, (0, 0.5, 0, 90), 6, 4, -10),
    ]
    m.mav.mission_count_send(1, 191, len(items), M.MAV_MISSION_TYPE_MISSION)
    while time.time() - t0 < 15:
        msg = m.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"],
                           blocking=True, timeout=1)
        if msg is None or msg.get_srcComponent() != 191:
            continue
        if msg.get_type() == "MISSION_ACK":
            upload = M.enums["MAV_MISSION_RESULT"][msg.type].name
            break
        cmd, p, x, y, z = items[msg.seq]
        m.mav.mission_item_int_send(1, 191, msg.seq, M.MAV_FRAME_LOCAL_NED, cmd, 0, 1,
                                    *p, int(round(x * 1e4)), int(round(y * 1e4)), z,
                                    M.MAV_MISSION_TYPE_MISSION)
# Download: the count the daemon holds.
m.mav.mission_request_list_send(1, 191, M.MAV_MISSION_TYPE_MISSION)
count = None
t1 = time.time()
while time.time() - t1 < 5 and count is None:
    msg = m.recv_match(type="MISSION_COUNT", blocking=True, timeout=1)
    if msg is not None and msg.get_srcComponent() == 191:
        count = msg.count
m.mav.mission_ack_send(1, 191, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
m.mav.command_long_send(1, 191, M.MAV_CMD_MISSION_START, 0, 0, 0, 0, 0, 0, 0, 0)
ack, reached, t2, last_beat = None, [], time.time(), 0
while time.time() - t2 < 30 and 2 not in reached:
    if time.time() - last_beat > 1:
        beat(); last_beat = time.time()
    msg = m.recv_match(type=["COMMAND_ACK", "MISSION_ITEM_REACHED"], blocking=True, timeout=1)
    if msg is None or msg.get_srcComponent() != 191:
        continue
    if msg.get_type() == "COMMAND_ACK" and msg.command == M.MAV_CMD_MISSION_START:
        ack = M.enums["MAV_RESULT"][msg.result].name
    elif msg.get_type() == "MISSION_ITEM_REACHED":
        reached.append(msg.seq)
ok = count == 3 and ack == "MAV_RESULT_ACCEPTED" and reached[-1:] == [2]
print(f"{mode}|{upload}|{count}|{ack}|{reached}|{time.time() - t2:.1f}|{'PASS' if ok else 'FAIL'}")
sys.exit(0 if ok else 1)
PY

ROWS=()
STATUS=0

# 1. pymavlink's mission messages (x, y × 1e4 as the specification says).
start_vehicle pymavlink 1e4
ROWS+=("$("$PY" "$OUT/client.py" pymavlink "$GCS_PORT" || STATUS=1)")
cleanup
PIDS=()

# 2. MAVProxy's wp module aimed at component 191 (uploads, then exits; its
#    mav.tlog goes to $OUT);
#    the start and the MISSION_ITEM_REACHED by pymavlink.
start_vehicle mavproxy 1e7
(cd "$OUT" && exec timeout 25 "$MAVPROXY" --master="udpout:127.0.0.1:$GCS_PORT" --source-system=255 \
    --target-system=1 --target-component=191 --non-interactive \
    --cmd="wp load $OUT/mission.txt") >"$OUT/mavproxy.out" 2>&1 &
MP=$!
for _ in $(seq 200); do
    grep -qE "Sent all|waypoints in" "$OUT/mavproxy.out" 2>/dev/null && break
    sleep 0.1
done
sleep 1
kill "$MP" 2>/dev/null || true
wait "$MP" 2>/dev/null || true
UPLOAD=$(grep -oE "Loaded [0-9]+ waypoints|Sent all [0-9]+ waypoints" "$OUT/mavproxy.out" | tail -1 || true)
ROWS+=("$("$PY" "$OUT/client.py" mavproxy "$GCS_PORT" | sed "s/|mavproxy|/|${UPLOAD:-no upload}|/" || STATUS=1)")

printf '\n%-10s | %-24s | %-5s | %-22s | %-10s | %-6s | %s\n' \
    client upload count MISSION_START reached "s" result
printf '%s\n' "-----------+--------------------------+-------+------------------------+------------+--------+-------"
for r in "${ROWS[@]}"; do
    IFS='|' read -r a b c d e f g <<<"$r"
    printf '%-10s | %-24s | %-5s | %-22s | %-10s | %-6s | %s\n' "$a" "$b" "$c" "$d" "$e" "$f" "$g"
done
echo "logs: $OUT"
grep -q FAIL <<<"${ROWS[*]}" && STATUS=1
exit $STATUS
