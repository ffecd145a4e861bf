#!/usr/bin/env bash
# The Debian package's round trip on this machine, as CI runs it:
#
#   scripts/package-roundtrip.sh [--target TRIPLE]   # default: the host
#
# Builds the package (scripts/package.sh), installs it with dpkg -i, checks
# what it installed (binary, unit with ExecStart=/usr/bin/dflat, the
# conffile, the `dflat` user in group dialout, /etc/dflat/keys, that
# `dflat check-config` ran), runs `systemd-analyze verify` on the unit if
# systemd-analyze is installed, removes it (dpkg -r: the conffile and the
# user stay) and purges it (dpkg -P: nothing it made stays).
#
# Exit status: 0 passed, 1 a check failed, 3 skipped — not root, no dpkg,
# or a dflat package already installed here (never touched); the reason is
# printed.
set -euo pipefail
cd "$(dirname "$0")/.."
skip() { echo "package round trip: skipped: $*"; exit 3; }
[ "$(id -u)" = 0 ] || skip "needs root (dpkg -i)"
command -v dpkg >/dev/null || skip "dpkg is not installed (not a Debian system)"
case "$(dpkg-query -W -f='${Status}' dflat 2>/dev/null || true)" in
    *"ok installed"*|*config-files*|*half-*|*unpacked*)
        skip "a dflat package is already installed (or its configuration is left) on this machine; not touching it" ;;
esac
getent passwd dflat >/dev/null && skip "a user 'dflat' already exists here (not made by the package); not touching it"

fails=0
check() { # $1 = what, then a command
    local what=$1; shift
    if "$@" >/dev/null 2>&1; then echo "  ok   $what"; else echo "  FAIL $what"; fails=$((fails + 1)); fi
}

log=$(mktemp)
trap 'rm -f "$log"' EXIT
scripts/package.sh "$@" 2>&1 | tee "$log"
deb=$(sed -n 's/^package: \([^ ]*\).*/\1/p' "$log" | tail -1)
[ -f "$deb" ] || { echo "package round trip: no package built" >&2; exit 1; }
arch=$(dpkg-deb -f "$deb" Architecture)
if [ "$arch" != "$(dpkg --print-architecture)" ]; then
    echo "package round trip: $deb is for $arch; built and inspected, not installed on $(dpkg --print-architecture)"
    dpkg-deb --info "$deb" | sed 's/^/  /'
    dpkg-deb --contents "$deb" | sed 's/^/  /'
    exit 0
fi

echo "install: dpkg -i $deb"
DEBIAN_FRONTEND=noninteractive dpkg -i "$deb" 2>&1 | sed 's/^/  /'
unit=/lib/systemd/system/dflat.service
check "dpkg: installed" sh -c "dpkg-query -W -f='\${Status}' dflat | grep -q 'install ok installed'"
check "/usr/bin/dflat runs" /usr/bin/dflat --version
check "the unit at $unit" test -f "$unit"
check "ExecStart=/usr/bin/dflat" grep -qx 'ExecStart=/usr/bin/dflat daemon --config /etc/dflat/dflat.toml' "$unit"
check "/etc/dflat/dflat.toml is a conffile" sh -c "dpkg-query -W -f='\${Conffiles}' dflat | grep -q /etc/dflat/dflat.toml"
check "the configuration passes check-config" /usr/bin/dflat check-config /etc/dflat/dflat.toml
check "system user dflat" sh -c 'getent passwd dflat | cut -d: -f3 | { read -r u; [ "$u" -lt 1000 ]; }'
check "dflat in group dialout" sh -c 'id -nG dflat | tr " " "\n" | grep -qx dialout'
check "/etc/dflat/keys 0700 dflat" sh -c '[ "$(stat -c %a:%U /etc/dflat/keys)" = 700:dflat ]'
if command -v systemd-analyze >/dev/null; then
    echo "systemd-analyze verify $unit:"
    if out=$(systemd-analyze verify "$unit" 2>&1); then
        echo "  ok   systemd-analyze verify${out:+ (said: $out)}"
    else
        echo "  FAIL systemd-analyze verify: $out"; fails=$((fails + 1))
    fi
else
    echo "  systemd-analyze: not installed, the unit not verified"
fi

echo "remove: dpkg -r dflat"
dpkg -r dflat 2>&1 | sed 's/^/  /'
check "binary removed" test ! -e /usr/bin/dflat
check "unit removed" test ! -e "$unit"
check "conffile kept on remove" test -f /etc/dflat/dflat.toml
check "user kept on remove" getent passwd dflat

echo "purge: dpkg -P dflat"
dpkg -P dflat 2>&1 | sed 's/^/  /'
check "dpkg: not installed, no configuration left" sh -c "! dpkg-query -W -f='\${Status}' dflat 2>/dev/null | grep -qE 'ok installed|config-files'"
check "/etc/dflat gone" test ! -e /etc/dflat
check "user dflat gone" sh -c '! getent passwd dflat'
check "group dflat gone" sh -c '! getent group dflat'
check "/var/lib/dflat gone" test ! -e /var/lib/dflat

if [ "$fails" -eq 0 ]; then
    echo "package round trip: passed ($deb: install, verify, remove, purge)"
else
    echo "package round trip: $fails check(s) FAILED"
    exit 1
fi
