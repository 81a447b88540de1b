#!/usr/bin/env bash
# The scale-sim command line: the --json contract of the issue, and sysexits
# codes with a message that names the bad argument.
#   tests/cli/scale_sim_cli.sh PATH/TO/scale-sim
set -euo pipefail
sim=$1
fail() { echo "FAIL: $*" >&2; exit 1; }

json=$("$sim" --json --seed 1)
python3 - "$json" <<'PY' || fail "--json output does not meet the contract"
import json, sys
doc = json.loads(sys.argv[1])
exps = doc["experiments"]
names = [e["name"] for e in exps]
assert names == ["four_bottles_same_height", "microwave", "four_bottles_four_heights"], names
for e in exps:
    for key in ("name", "updates", "converged_at_update", "median_rel_error", "std_rel_error"):
        assert key in e, (e["name"], key)
    assert isinstance(e["updates"], int) and e["updates"] > 0, e
    assert isinstance(e["converged_at_update"], int), e
    assert 0 <= e["median_rel_error"] <= 0.01, e
PY

help=$("$sim" --help) || fail "--help failed"  # whole: grep -q on a pipe may SIGPIPE it
grep -q '^usage: scale-sim' <<< "$help" || fail "--help does not print usage"

set +e
err=$("$sim" --seed x 2>&1 >/dev/null); rc=$?
set -e
[[ $rc -eq 64 ]] || fail "--seed x: exit $rc, expected 64 (EX_USAGE)"
[[ $err == *"'x'"* ]] || fail "--seed x: message does not name the value: $err"

set +e
err=$("$sim" --variance wide 2>&1 >/dev/null); rc=$?
set -e
[[ $rc -eq 64 && $err == *"'wide'"* ]] || fail "--variance wide: exit $rc, message: $err"

set +e
"$sim" --frobnicate >/dev/null 2>&1; rc=$?
set -e
[[ $rc -eq 64 ]] || fail "unknown argument: exit $rc, expected 64"
echo "scale-sim CLI: 5 checks passed"
