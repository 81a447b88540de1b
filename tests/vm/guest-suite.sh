#!/usr/bin/env bash
# guest-suite.sh MANIFEST RESULTS_DIR: runs every guest test of the manifest
# inside the VM (ctest vm.boot runs it through run-vm.sh, in one boot).
#
# MANIFEST (CMake generates it: tests/vm/CMakeLists.txt) has one test a line:
# NAME <tab> TIMEOUT_S <tab> COMMAND, COMMAND being shell words. Each test runs
# in a fresh RESULTS_DIR/work/NAME with its own timeout; its output goes to
# RESULTS_DIR/NAME.log and its exit code to RESULTS_DIR/NAME.rc (124 when it
# timed out), which the per-test ctest checks (check-result.sh) report.
# Exits 0 once every test ran, whatever their results, and writes
# RESULTS_DIR/suite-done; non-zero only when the suite itself cannot run.
# SCALED_VM_TESTS, when set, is an extended regular expression: only the tests
# whose NAME matches it run, the others are skipped (exit 77, their log says
# why); e.g. SCALED_VM_TESTS='^gpio_patterns$' (docs/vm-tests.md).
set -euo pipefail

if [[ $# -ne 2 ]]; then
  echo "usage: $0 MANIFEST RESULTS_DIR" >&2
  exit 2
fi
manifest=$1
results=$2
[[ -f $manifest ]] || {
  echo "guest-suite: error: no manifest $manifest" >&2
  exit 1
}
mkdir -p "$results/work"
command -v timeout >/dev/null || {
  echo "guest-suite: error: timeout (coreutils) not found" >&2
  exit 1
}

summary=()
failed=0
count=0
while IFS=$'\t' read -r name timeout_s cmd; do
  [[ -z $name || $name == \#* ]] && continue
  count=$((count + 1))
  if [[ -n ${SCALED_VM_TESTS:-} ]] && ! [[ $name =~ $SCALED_VM_TESTS ]]; then
    echo "skip: not selected (SCALED_VM_TESTS='$SCALED_VM_TESTS')" >"$results/$name.log"
    echo 77 >"$results/$name.rc"
    summary+=("$(printf '%-24s %-18s %4d s' "$name" "not selected" 0)")
    continue
  fi
  work=$results/work/$name
  rm -rf "$work"
  mkdir -p "$work"
  echo "guest-suite: [$count] $name (timeout ${timeout_s} s)"
  start_s=$(date +%s)
  rc=0
  (cd "$work" && exec timeout -k 10 "$timeout_s" bash -c "$cmd") </dev/null >"$results/$name.log" 2>&1 ||
    rc=$?
  if [[ $rc -eq 124 || $rc -eq 137 ]]; then
    echo "guest-suite: $name timed out after $timeout_s s" >>"$results/$name.log"
    rc=124
  fi
  echo "$rc" >"$results/$name.rc"
  case $rc in
    0) verdict=passed ;;
    77) verdict=skipped ;;
    *)
      verdict="FAILED (exit $rc)"
      failed=$((failed + 1))
      ;;
  esac
  summary+=("$(printf '%-24s %-18s %4d s' "$name" "$verdict" "$(($(date +%s) - start_s))")")
done <"$manifest"

echo "guest-suite: summary ($count tests, $failed failed):"
for line in "${summary[@]}"; do echo "  $line"; done
sync
echo "$count $failed" >"$results/suite-done"
