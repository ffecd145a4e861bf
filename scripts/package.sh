#!/usr/bin/env bash
# Builds the Debian package of the onboard daemon with dpkg-deb (no other
# tool needed):
#
#   scripts/package.sh                                   # host (amd64 here)
#   scripts/package.sh --target aarch64-unknown-linux-gnu # arm64 companion
#   scripts/package.sh --target aarch64-unknown-linux-gnu --glibc 2.27
#                                  # for an older companion (build-onboard.sh --glibc)
#   scripts/package.sh --bin PATH [--target TRIPLE]      # package a built binary
#
# -> target/debian/dflat_<version>_<arch>.deb (CARGO_TARGET_DIR respected),
# then `lintian` on it if lintian is installed (its findings are printed,
# not fatal; the ones that stay are explained in docs/deployment.md;
# DFLAT_PACKAGE_NO_LINTIAN=1 skips it).
#
# The package:
#   /usr/bin/dflat                       the onboard build (scripts/build-onboard.sh)
#   /lib/systemd/system/dflat.service    deploy/dflat.service, ExecStart=/usr/bin/dflat
#   /etc/dflat/dflat.toml                config/default.toml, a conffile (kept on upgrade)
#   /usr/share/doc/dflat/                README, deployment guide, copyright, changelog
# postinst (configure): the system user `dflat` (group dflat, also in
# dialout for the serial port), /etc/dflat/keys (0700 dflat), then
# `dflat check-config /etc/dflat/dflat.toml` (an invalid file fails the
# configure step, naming the field); systemd is reloaded, the service is
# neither enabled nor started (a flight daemon starts when its operator
# says so: `systemctl enable --now dflat`). prerm stops it. postrm purge
# removes the user and group, /etc/dflat/keys, the package's state and
# logs (/var/lib/dflat: flight records, /var/log/dflat).
set -euo pipefail
target=""
glibc=""
bin=""
while [ $# -gt 0 ]; do
    case "$1" in
        --target) target=${2:?--target needs a triple}; shift 2 ;;
        --target=*) target=${1#--target=}; shift ;;
        --bin) bin=${2:?--bin needs a path}; shift 2 ;;
        --glibc) glibc=${2:?--glibc needs a version}; shift 2 ;;
        -h|--help) awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"; exit 0 ;;
        *) echo "package.sh: unknown argument '$1' (try --help)" >&2; exit 2 ;;
    esac
done
[ -n "$bin" ] && bin=$(realpath "$bin")
cd "$(dirname "$0")/.."
command -v dpkg-deb >/dev/null || { echo "package.sh: dpkg-deb not found (Debian's dpkg package)" >&2; exit 1; }
host=$(rustc -vV | sed -n 's/^host: //p')
triple=${target:-$host}
case "$triple" in
    aarch64-unknown-linux-gnu) arch=arm64 ;;
    x86_64-unknown-linux-gnu) arch=amd64 ;;
    armv7-unknown-linux-gnueabihf) arch=armhf ;;
    *) echo "package.sh: no Debian architecture known for $triple" >&2; exit 1 ;;
esac

if [ -z "$bin" ]; then
    log=$(mktemp)
    trap 'rm -f "$log"' EXIT
    scripts/build-onboard.sh ${target:+--target "$target"} ${glibc:+--glibc "$glibc"} 2>&1 | tee "$log" >&2
    bin=$(sed -n 's/^onboard binary: //p' "$log" | tail -1)
fi
[ -x "$bin" ] || { echo "package.sh: no binary at '$bin'" >&2; exit 1; }

version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
tdir=${CARGO_TARGET_DIR:-target}
out="$tdir/debian"
root="$out/dflat_${version}_${arch}"
deb="$out/dflat_${version}_${arch}.deb"
rm -rf "$root"
mkdir -p "$out"

# Files. Directories 0755, files 0644 (the binary 0755), owned by root
# (dpkg-deb --root-owner-group).
install -d -m 0755 "$root/DEBIAN" "$root/usr/bin" "$root/lib/systemd/system" \
    "$root/etc/dflat" "$root/usr/share/doc/dflat" "$root/usr/share/lintian/overrides"
install -m 0755 "$bin" "$root/usr/bin/dflat"
sed -e 's|^ExecStart=/usr/local/bin/dflat |ExecStart=/usr/bin/dflat |' \
    -e 's|^Documentation=file:///usr/local/share/doc/dflat/README.md|Documentation=file:///usr/share/doc/dflat/README.md|' \
    -e 's|^# Installed by deploy/install.sh to /etc/systemd/system/dflat.service.|# Installed by the dflat package to /lib/systemd/system/dflat.service.|' \
    deploy/dflat.service >"$root/lib/systemd/system/dflat.service"
chmod 0644 "$root/lib/systemd/system/dflat.service"
grep -qx 'ExecStart=/usr/bin/dflat daemon --config /etc/dflat/dflat.toml' "$root/lib/systemd/system/dflat.service" \
    || { echo "package.sh: the packaged unit's ExecStart is not /usr/bin/dflat (deploy/dflat.service changed?)" >&2; exit 1; }
install -m 0644 config/default.toml "$root/etc/dflat/dflat.toml"
install -m 0644 README.md "$root/usr/share/doc/dflat/README.md"
install -m 0644 docs/deployment.md "$root/usr/share/doc/dflat/deployment.md"
for f in default px4 ardupilot; do
    install -D -m 0644 "config/$f.toml" "$root/usr/share/doc/dflat/examples/$f.toml"
done

date_r=$(date -R -d "@$(git log -1 --format=%ct 2>/dev/null || date +%s)")
commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
maintainer="dflat maintainers <maintainers@users.noreply.h-seed-ac28ef49.example>"
printf 'dflat (%s) unstable; urgency=medium\n\n  * Built from commit %s with scripts/package.sh.\n\n -- %s  %s\n' \
    "$version" "$commit" "$maintainer" "$date_r" | gzip -9n >"$root/usr/share/doc/dflat/changelog.gz"
cat >"$root/usr/share/doc/dflat/copyright" <<'EOF'
Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/
Upstream-Name: dflat
Source: https://example.invalid/dflat

Files: *
Copyright: 2026 The dflat authors
License: MIT or Apache-2.0

License: MIT
 Permission is hereby granted, free of charge, to any person obtaining a copy
 of this software and associated documentation files (the "Software"), to deal
 in the Software without restriction, including without limitation the rights
 to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
 copies of the Software, and to permit persons to whom the Software is
 furnished to do so, subject to the following conditions:
 .
 The above copyright notice and this permission notice shall be included in
 all copies or substantial portions of the Software.
 .
 THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
 IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
 FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
 AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
 LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
 OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN
 THE SOFTWARE.

License: Apache-2.0
 On Debian systems, the full text of the Apache License, Version 2.0 is in
 /usr/share/common-licenses/Apache-2.0.
EOF
# What lintian would say and why it stays (docs/deployment.md).
cat >"$root/usr/share/lintian/overrides/dflat" <<'EOF'
# The onboard profile keeps symbol names (no DWARF) so a panic's backtrace
# names the functions on the vehicle.
dflat: unstripped-binary-or-object [usr/bin/dflat]
# dflat's manual is `dflat --help` and /usr/share/doc/dflat.
dflat: no-manual-page [usr/bin/dflat]
EOF
chmod 0644 "$root/usr/share/lintian/overrides/dflat"

# glibc: the newest symbol version the binary needs (readelf reads any
# architecture's ELF).
glibc=$({ readelf -V --wide "$bin" 2>/dev/null || true; } | { grep -o 'GLIBC_[0-9.]*' || true; } | sed 's/GLIBC_//' | sort -V | tail -1)
depends="adduser${glibc:+, libc6 (>= $glibc)}, libgcc-s1"
size_kb=$(du -sk --exclude=DEBIAN "$root" | cut -f1)

cat >"$root/DEBIAN/control" <<EOF
Package: dflat
Version: $version
Architecture: $arch
Maintainer: $maintainer
Installed-Size: $size_kb
Depends: $depends
Section: misc
Priority: optional
Homepage: https://example.invalid/dflat
Description: discrete-flatness MPC flight-control daemon for multirotors
 dflat runs on a multirotor's companion computer as a systemd service: it
 reads pose over MAVLink 2 (serial or UDP) from a PX4 or ArduPilot
 autopilot, runs the discrete-flatness model predictive controller at
 50 Hz and streams attitude targets back. This is the onboard build: the
 daemon and check-config, without the simulation lab.
 .
 The service is installed but neither enabled nor started: edit
 /etc/dflat/dflat.toml, check it with dflat check-config, then
 systemctl enable --now dflat.
EOF
echo /etc/dflat/dflat.toml >"$root/DEBIAN/conffiles"

cat >"$root/DEBIAN/postinst" <<'EOF'
#!/bin/sh
set -e
if [ "$1" = configure ]; then
    if ! getent passwd dflat >/dev/null; then
        adduser --system --group --quiet --no-create-home \
            --home /var/lib/dflat --shell /usr/sbin/nologin dflat
    fi
    # The autopilot's serial port belongs to group dialout.
    if getent group dialout >/dev/null; then
        adduser --quiet dflat dialout
    fi
    # MAVLink signing keys (link.signing_key_file): the daemon's user only.
    install -d -m 0700 -o dflat -g dflat /etc/dflat/keys
    if ! dflat check-config /etc/dflat/dflat.toml >/dev/null; then
        echo "dflat: /etc/dflat/dflat.toml does not pass 'dflat check-config' (above); fix it, then: dpkg --configure dflat" >&2
        exit 1
    fi
    if [ -d /run/systemd/system ]; then
        systemctl --system daemon-reload >/dev/null || true
    fi
    echo "dflat: installed, not started. Edit /etc/dflat/dflat.toml, then: systemctl enable --now dflat"
fi
exit 0
EOF

cat >"$root/DEBIAN/prerm" <<'EOF'
#!/bin/sh
set -e
if [ -d /run/systemd/system ] && [ "$1" = remove ]; then
    deb-systemd-invoke stop dflat.service >/dev/null 2>&1 || systemctl stop dflat.service >/dev/null 2>&1 || true
fi
exit 0
EOF

cat >"$root/DEBIAN/postrm" <<'EOF'
#!/bin/sh
set -e
if [ -d /run/systemd/system ]; then
    systemctl --system daemon-reload >/dev/null || true
fi
if [ "$1" = purge ]; then
    if command -v deb-systemd-helper >/dev/null; then
        deb-systemd-helper purge dflat.service >/dev/null || true
    fi
    rm -rf /etc/dflat/keys
    rmdir --ignore-fail-on-non-empty /etc/dflat 2>/dev/null || true
    # Flight records and logs the service wrote (StateDirectory, LogsDirectory).
    rm -rf /var/lib/dflat /var/log/dflat /var/lib/private/dflat /var/log/private/dflat
    if getent passwd dflat >/dev/null; then
        deluser --quiet --system dflat >/dev/null 2>&1 || userdel dflat || true
    fi
    if getent group dflat >/dev/null; then
        delgroup --quiet --system dflat >/dev/null 2>&1 || groupdel dflat || true
    fi
fi
exit 0
EOF
chmod 0755 "$root/DEBIAN/postinst" "$root/DEBIAN/prerm" "$root/DEBIAN/postrm"

dpkg-deb --root-owner-group -Zxz --build "$root" "$deb" >/dev/null
rm -rf "$root"
echo "package: $deb ($(stat -c %s "$deb") bytes; $arch, version $version, Depends: $depends)"
if [ -n "${DFLAT_PACKAGE_NO_LINTIAN:-}" ]; then
    echo "lintian: not run (DFLAT_PACKAGE_NO_LINTIAN)"
elif command -v lintian >/dev/null; then
    echo "lintian:"
    lintian --tag-display-limit 0 --show-overrides "$deb" 2>&1 | grep -v 'running with root privileges' | sed 's/^/  /' || true
    echo "lintian: done (O: overridden, with the reason in /usr/share/lintian/overrides/dflat)"
else
    echo "lintian: not installed (apt-get install lintian), not run"
fi
