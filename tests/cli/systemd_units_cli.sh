#!/usr/bin/env bash
# The systemd units: `systemd-analyze verify` passes without a single message
# about them, and `systemd-analyze security --offline=yes` keeps the service's
# exposure at or below 1.5 (docs/deploy.md records the score).
#   tests/cli/systemd_units_cli.sh SOURCE/systemd PATH/TO/scaled
# The templates are configured into a temporary directory with ExecStart
# pointing at the built daemon (verify requires the executable to exist).
# Exit 77 (skipped) without systemd-analyze.
set -euo pipefail
src=$1
scaled=$2
fail() { echo "FAIL: $*" >&2; exit 1; }

command -v systemd-analyze >/dev/null || { echo "SKIP: systemd-analyze not installed"; exit 77; }
[[ -x $scaled ]] || fail "no daemon binary at $scaled"

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
sbindir=$(cd "$(dirname "$scaled")" && pwd)
for unit in scaled.service scaled.socket; do
  sed -e "s#@CMAKE_INSTALL_FULL_SBINDIR@#${sbindir}#g" \
      -e "s#@CMAKE_INSTALL_FULL_SYSCONFDIR@#/etc#g" \
      -e "s#@CMAKE_INSTALL_FULL_DOCDIR@#/usr/share/doc/scaled#g" \
      "$src/$unit.in" >"$tmp/$unit"
  ! grep -n '@[A-Z_]*@' "$tmp/$unit" || fail "$unit: unsubstituted @VARIABLE@"
done
# The daemon is called scaled, the binary must keep that name for ExecStart.
[[ $(basename "$scaled") == scaled ]] || fail "the daemon binary must be named scaled"

set +e
out=$(cd "$tmp" && SYSTEMD_LOG_LEVEL=notice systemd-analyze verify --man=no \
  ./scaled.socket ./scaled.service 2>&1)
rc=$?
set -e
# Messages about other units on this machine are not ours to fix.
ours=$(grep -E 'scaled\.(service|socket)' <<<"$out" || true)
[[ $rc -eq 0 ]] || fail "systemd-analyze verify exited $rc: $out"
[[ -z $ours ]] || fail "systemd-analyze verify complained about the units: $ours"

# The hardening does not regress: exposure <= 1.5 (systemd >= 250 has
# --offline and --threshold; older versions skip this part).
if systemd-analyze security --help 2>/dev/null | grep -q -- '--offline'; then
  set +e
  sec=$(cd "$tmp" && systemd-analyze security --offline=yes --threshold=15 ./scaled.service 2>&1)
  rc=$?
  set -e
  score=$(grep -o 'Overall exposure level for scaled.service: [0-9.]*' <<<"$sec" || true)
  [[ $rc -eq 0 ]] || fail "security exposure above 1.5 (${score:-no score}): $(tail -n 20 <<<"$sec")"
  echo "${score}"
fi
echo "systemd units: verify clean"
