#!/usr/bin/env bash
# The install layout and the DEB (cmake/Install.cmake): `cmake --install` into a
# temporary DESTDIR with the prefix /usr gives the expected files, and
# `cpack -G DEB` a package with those files, the conffiles, the maintainer
# scripts and library dependencies from dpkg-shlibdeps.
#   tests/cli/package_cli.sh BUILD_DIR [CMAKE [CPACK]]
# Needs a complete build (the binaries are installed). Exit 77 (skipped)
# without dpkg-deb or cpack.
set -euo pipefail
build=$1
cmake=${2:-cmake}
cpack=${3:-cpack}
fail() { echo "FAIL: $*" >&2; exit 1; }

command -v dpkg-deb >/dev/null || { echo "SKIP: dpkg-deb not installed"; exit 77; }
command -v "$cpack" >/dev/null || { echo "SKIP: cpack not installed"; exit 77; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

expected=(
  usr/sbin/scaled
  usr/bin/scalectl
  etc/scaled/scaled.toml
  etc/scaled/priors.toml
  lib/systemd/system/scaled.service
  lib/systemd/system/scaled.socket
  usr/lib/sysusers.d/scaled.conf
  usr/share/doc/scaled/README.md
)
# The systemd unit directory comes from pkg-config when systemd's .pc is there.
if unitdir=$(pkg-config --variable=systemdsystemunitdir systemd 2>/dev/null) && [[ -n $unitdir ]]; then
  expected[4]=${unitdir#/}/scaled.service
  expected[5]=${unitdir#/}/scaled.socket
fi
if sysusersdir=$(pkg-config --variable=sysusersdir systemd 2>/dev/null) && [[ -n $sysusersdir ]]; then
  expected[6]=${sysusersdir#/}/scaled.conf
fi
[[ -x $build/bin/field-log ]] && expected+=(usr/bin/field-log)
expected+=(usr/share/doc/scaled/deploy.md)

# ---- cmake --install ----------------------------------------------------------
DESTDIR=$tmp/root "$cmake" --install "$build" --prefix /usr >"$tmp/install.log" 2>&1 ||
  fail "cmake --install failed: $(tail -n 20 "$tmp/install.log")"
for f in "${expected[@]}"; do
  [[ -f $tmp/root/$f ]] || fail "install: $f missing (installed: $(cd "$tmp/root" && find . -type f | sort | tr '\n' ' '))"
done
for f in usr/sbin/scaled usr/bin/scalectl; do
  [[ -x $tmp/root/$f ]] || fail "install: $f is not executable"
done
service=$tmp/root/${expected[4]}
grep -qx 'ExecStart=/usr/sbin/scaled --no-tty --config /etc/scaled/scaled.toml' "$service" ||
  fail "installed scaled.service: ExecStart does not use /usr/sbin and /etc: $(grep ExecStart "$service")"
! grep -n '@[A-Z_]*@' "$service" "$tmp/root/${expected[5]}" || fail "unsubstituted @VARIABLE@ in the units"
grep -qx 'ListenStream=/run/scaled/scaled.sock' "$tmp/root/${expected[5]}" ||
  fail "scaled.socket does not listen on /run/scaled/scaled.sock"
grep -qE '^u +scaled ' "$tmp/root/${expected[6]}" || fail "sysusers file does not create the user scaled"

# ---- cpack -G DEB -------------------------------------------------------------
(cd "$tmp" && "$cpack" --config "$build/CPackConfig.cmake" -G DEB -B "$tmp/pkg" >"$tmp/cpack.log" 2>&1) ||
  fail "cpack failed: $(tail -n 20 "$tmp/cpack.log")"
debs=("$tmp"/pkg/scaled_*.deb)
[[ -f ${debs[0]} ]] || fail "cpack made no scaled_*.deb: $(ls "$tmp/pkg")"
deb=${debs[0]}

contents=$(dpkg-deb -c "$deb")
for f in "${expected[@]}"; do
  grep -q " \./$f\$" <<<"$contents" || fail "deb: $f missing"
done
[[ $(dpkg-deb -f "$deb" Package) == scaled ]] || fail "deb: package name is not scaled"
depends=$(dpkg-deb -f "$deb" Depends)
for dep in libc6 libstdc++6 libopencv-core systemd; do
  grep -q "$dep" <<<"$depends" || fail "deb: Depends lacks $dep: $depends"
done
conffiles=$(dpkg-deb -I "$deb" conffiles)
for f in /etc/scaled/scaled.toml /etc/scaled/priors.toml; do
  grep -qx "$f" <<<"$conffiles" || fail "deb: $f is not a conffile: $conffiles"
done
dpkg-deb -e "$deb" "$tmp/control"
for script in postinst prerm postrm; do
  [[ -x $tmp/control/$script ]] || fail "deb: no executable $script"
  sh -n "$tmp/control/$script" || fail "deb: $script is not valid sh"
done
grep -q systemd-sysusers "$tmp/control/postinst" || fail "postinst does not run systemd-sysusers"
grep -q '/var/log/scaled' "$tmp/control/postinst" || fail "postinst does not create /var/log/scaled"
echo "package: install layout and $(basename "$deb") as expected (${#expected[@]} files)"
