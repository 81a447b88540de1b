#!/usr/bin/env bash
# check-result.sh RESULTS_DIR NAME: ctest's vm.NAME, the result of one guest
# test that vm.boot ran in the VM. Prints its log and exits with its exit code;
# 77 (skip) when the VM harness skipped. A missing result after a boot that
# did not skip is a failure.
set -euo pipefail

if [[ $# -ne 2 ]]; then
  echo "usage: $0 RESULTS_DIR NAME" >&2
  exit 2
fi
results=$1
name=$2
if [[ -f $results/SKIPPED ]]; then
  echo "skip: $(<"$results/SKIPPED") (see vm.boot)"
  exit 77
fi
if [[ ! -f $results/$name.rc ]]; then
  echo "FAIL: no result for $name in $results (did vm.boot run and finish?)"
  exit 1
fi
if [[ -f $results/$name.log ]]; then cat "$results/$name.log"; fi
rc=$(<"$results/$name.rc")
[[ $rc =~ ^[0-9]+$ ]] || {
  echo "FAIL: $results/$name.rc holds '$rc', not an exit code"
  exit 1
}
exit "$rc"
