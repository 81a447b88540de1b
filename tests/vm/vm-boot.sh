#!/usr/bin/env bash
# vm-boot.sh RESULTS_DIR MANIFEST DEFAULT_CACHE [--share DIR | --share-ro DIR]...
#
# ctest's vm.boot, the fixture that boots the VM once and runs every guest
# test in it (guest-suite.sh), leaving one NAME.rc and NAME.log per test in
# RESULTS_DIR for the vm.NAME checks (check-result.sh).
#
# Cleans RESULTS_DIR first. Passes when the VM booted and the suite ran (test
# failures are the checks' business); exits 77 and leaves RESULTS_DIR/SKIPPED
# when the harness skips (no qemu, no kernel to be had), so that every check
# skips too. The VM gets 1050 s (ctest allows vm.boot 1200; the rest is for a
# first fetch-kernel.sh). The kernel cache is $SCALED_VM_CACHE when set, else
# DEFAULT_CACHE. The shares go to run-vm.sh; a --share-ro directory that does
# not exist (the optional data of ../shared) is left out.
set -euo pipefail

if [[ $# -lt 3 ]]; then
  echo "usage: $0 RESULTS_DIR MANIFEST DEFAULT_CACHE [--share DIR | --share-ro DIR]..." >&2
  exit 2
fi
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd -P)
results=$1
manifest=$2
cache=${SCALED_VM_CACHE:-$3}
shift 3

rm -rf "$results"
mkdir -p "$results"
shares=(--share "$results")
while [[ $# -ge 2 ]]; do
  case $1 in
    --share) shares+=(--share "$2") ;;
    --share-ro) [[ -d $2 ]] && shares+=(--share-ro "$2") ;;
    *)
      echo "vm-boot: error: unknown argument $1" >&2
      exit 2
      ;;
  esac
  shift 2
done
[[ $# -eq 0 ]] || {
  echo "vm-boot: error: stray argument $1" >&2
  exit 2
}

# The models and data: $SCALED_SHARED_DIR when set (shared, and passed on to
# the guest's tests), else the ../shared given on the command line.
if [[ -n ${SCALED_SHARED_DIR:-} && -d $SCALED_SHARED_DIR ]]; then
  shares+=(--share-ro "$SCALED_SHARED_DIR" --env "SCALED_SHARED_DIR=$SCALED_SHARED_DIR")
fi

# Which guest tests run (guest-suite.sh): all unless SCALED_VM_TESTS says.
if [[ -n ${SCALED_VM_TESTS:-} ]]; then
  shares+=(--env "SCALED_VM_TESTS=$SCALED_VM_TESTS")
fi

rc=0
"$here/run-vm.sh" --cache "$cache" --timeout 1050 "${shares[@]}" -- \
  "$here/guest-suite.sh" "$manifest" "$results" || rc=$?
if [[ $rc -eq 77 ]]; then
  echo "the VM harness skipped" >"$results/SKIPPED"
  exit 77
fi
if [[ $rc -ne 0 ]]; then
  echo "vm-boot: the VM suite did not run (run-vm.sh exit $rc)" >&2
  exit "$rc"
fi
if [[ ! -f $results/suite-done ]]; then
  echo "vm-boot: the suite did not finish ($results/suite-done missing)" >&2
  exit 1
fi
