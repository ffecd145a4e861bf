# Sourced (not run) by the scripts that fly the SITL and the daemon, from
# the repository's top after `set -euo pipefail`.

# Builds the debug dflat binary unless DFLAT_BIN already names one; sets
# DFLAT_BIN.
need_dflat_bin() {
    if [[ -z "${DFLAT_BIN:-}" ]]; then
        cargo build -q -p dflat --bin dflat
        local target
        target=$(cargo metadata --format-version 1 --no-deps |
            sed -n 's/.*"target_directory":"\([^"]*\)".*/\1/p')
        DFLAT_BIN="$target/debug/dflat"
    fi
}

# The PIDs of the SITL and the daemon once started (empty: not running).
SITL_PID=
DAEMON_PID=

# Sends SIGINT to the daemon, then to the SITL.
stop_daemon_and_sitl() {
    [[ -n "$DAEMON_PID" ]] && kill -INT "$DAEMON_PID" 2>/dev/null || true
    [[ -n "$SITL_PID" ]] && kill -INT "$SITL_PID" 2>/dev/null || true
}
