#!/usr/bin/env bash
# Installs dflat as a systemd service: binary, configuration, unit.
#
#   sudo deploy/install.sh [path/to/dflat] [path/to/config.toml]
#
# Defaults: target/onboard/dflat (the onboard build without the simulation
# lab: scripts/build-onboard.sh) and config/default.toml. An existing
# /etc/dflat/dflat.toml is kept (the new one is written beside it as
# dflat.toml.new). Run from the repository root.
set -euo pipefail
bin=${1:-target/onboard/dflat}
cfg=${2:-config/default.toml}
[ -x "$bin" ] || { echo "install.sh: $bin not found; run: scripts/build-onboard.sh" >&2; exit 1; }
if "$bin" --help | grep -qE '^ +demo '; then
  echo "install.sh: note: $bin is the full build (with the lab); the onboard one is scripts/build-onboard.sh -> target/onboard/dflat" >&2
fi
[ -f "$cfg" ] || { echo "install.sh: $cfg not found" >&2; exit 1; }
"$bin" check-config "$cfg" >/dev/null

id -u dflat >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin --groups dialout dflat
install -D -m 0755 "$bin" /usr/local/bin/dflat
install -d -m 0755 /etc/dflat
# MAVLink signing keys (link.signing_key_file = "/etc/dflat/keys/…"): a
# directory only the daemon's user can enter; key files mode 0600 inside.
install -d -m 0700 -o dflat -g dflat /etc/dflat/keys
chown dflat:dflat /etc/dflat/keys && chmod 0700 /etc/dflat/keys
if [ -f /etc/dflat/dflat.toml ]; then
  install -m 0644 "$cfg" /etc/dflat/dflat.toml.new
  echo "kept /etc/dflat/dflat.toml; new default written to /etc/dflat/dflat.toml.new"
else
  install -m 0644 "$cfg" /etc/dflat/dflat.toml
fi
install -D -m 0644 "$(dirname "$0")/dflat.service" /etc/systemd/system/dflat.service
install -D -m 0644 README.md /usr/local/share/doc/dflat/README.md 2>/dev/null || true
if command -v systemd-analyze >/dev/null; then systemd-analyze verify /etc/systemd/system/dflat.service; fi
systemctl daemon-reload
echo "installed; start with: systemctl enable --now dflat; logs: journalctl -u dflat -f"
