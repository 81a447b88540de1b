#!/usr/bin/env bash
# scaled --check-config: the shipped config/scaled.toml is valid (exit 0, one
# line "FILE: configuration OK" on stdout); broken files exit 78 (EX_CONFIG)
# with an error on stderr naming the file, the line and the key.
#   tests/cli/scaled_check_config_cli.sh PATH/TO/scaled SOURCE_DIR
set -euo pipefail
scaled=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# The shipped file.
set +e
out=$("$scaled" --check-config "$src/config/scaled.toml" 2>"$tmp/err"); rc=$?
set -e
[[ $rc -eq 0 ]] || fail "config/scaled.toml: exit $rc, expected 0 ($(cat "$tmp/err"))"
[[ $out == *"scaled.toml: configuration OK"* ]] || fail "config/scaled.toml: stdout '$out'"

# broken NAME 'TOML TEXT' 'EXPECTED STDERR SUBSTRING...': each substring must appear.
broken() {
    local name=$1 text=$2; shift 2
    local file="$tmp/$name.toml" err rc
    printf '%b' "$text" > "$file"
    set +e; err=$("$scaled" --check-config "$file" 2>&1 >/dev/null); rc=$?; set -e
    [[ $rc -eq 78 ]] || fail "$name: exit $rc, expected 78 ($err)"
    local want
    for want in "$@"; do
        [[ $err == *"$want"* ]] || fail "$name: stderr '$err' does not mention '$want'"
    done
}

broken syntax '[source]\nkind = "sim"\nspeed = = 2\n' "$tmp/syntax.toml:3:"
broken unknown_key '[source]\nkind = "sim"\ncolour = "red"\n' \
    "$tmp/unknown_key.toml:3: source.colour: unknown key" "kind, replay"
broken unknown_section '[source]\nkind = "sim"\n\n[sorce]\n' \
    "$tmp/unknown_section.toml:4: sorce: unknown section"
broken wrong_type '[log]\nenabled = "yes"\n' \
    "$tmp/wrong_type.toml:2: log.enabled: must be true or false (got \"yes\")"
broken out_of_range '# a comment\n[socket]\nmax_clients = 0\n' \
    "$tmp/out_of_range.toml:3: socket.max_clients: must be an integer in [1, 1024] (got 0)"
broken socket_mode '[socket]\nmode = "0666"\n' \
    "$tmp/socket_mode.toml:2: socket.mode: must not let others write" '(got "0666")'
broken replay_without_path '[source]\nkind = "replay"\n' \
    "$tmp/replay_without_path.toml:2: source.replay: required when source.kind = \"replay\""
broken log_total '[log]\nmax_file_bytes = 1000000\nmax_total_bytes = 500000\n' \
    "$tmp/log_total.toml:3: log.max_total_bytes: must be >= log.max_file_bytes = 1000000 (got 500000)"
broken period '[detection]\nperiod_s = 4000\n' \
    "$tmp/period.toml:2: detection.period_s: must be a number in [0, 3600] (got 4000)"

# --check-config runs what start-up checks, not only the syntax (issue 22). The
# shipped file copied elsewhere: its relative priors.toml is not there.
cp "$src/config/scaled.toml" "$tmp/copy.toml"
line=$(grep -n '^priors = "priors.toml"' "$tmp/copy.toml" | cut -d: -f1)
[[ -n $line ]] || fail "config/scaled.toml has no 'priors = \"priors.toml\"' line"
set +e; err=$("$scaled" --check-config "$tmp/copy.toml" 2>&1 >/dev/null); rc=$?; set -e
[[ $rc -eq 78 ]] || fail "copied scaled.toml: exit $rc, expected 78 ($err)"
[[ $err == *"$tmp/copy.toml:$line: estimator.priors: $tmp/priors.toml: cannot open priors file"*"(got \"$tmp/priors.toml\")"* ]] ||
    fail "copied scaled.toml: stderr '$err'"

# checked NAME 'TOML TEXT' EXTRA-ARGS... -- 'EXPECTED STDERR SUBSTRING...'
checked() {
    local name=$1 text=$2; shift 2
    local args=()
    while [[ $1 != -- ]]; do args+=("$1"); shift; done
    shift
    local file="$tmp/$name.toml" err rc
    printf '%b' "$text" > "$file"
    set +e; err=$("$scaled" --check-config "$file" "${args[@]}" 2>&1 >/dev/null); rc=$?; set -e
    [[ $rc -eq 78 ]] || fail "$name: exit $rc, expected 78 ($err)"
    local want
    for want in "$@"; do
        [[ $err == *"$want"* ]] || fail "$name: stderr '$err' does not mention '$want'"
    done
}
cp "$src/config/priors.toml" "$tmp/priors.toml"
mkdir -p "$tmp/run"
ok_socket="[socket]\npath = \"$tmp/run/s.sock\"\n"
checked group "${ok_socket}group = \"nosuchgrp-scaled\"\n" -- \
    "$tmp/group.toml:3: socket.group: $tmp/run/s.sock: unknown group 'nosuchgrp-scaled' (got \"nosuchgrp-scaled\")"
checked replay_dir "[source]\nkind = \"replay\"\nreplay = \"$tmp/no-such-dataset\"\n[detector]\nmodel = \"$tmp/no-such-model.onnx\"\n${ok_socket}" -- \
    "$tmp/replay_dir.toml:3: source.replay: " "(got \"$tmp/no-such-dataset\")" \
    "$tmp/replay_dir.toml:5: detector.model: " "(got \"$tmp/no-such-model.onnx\")" "scaled: $tmp/replay_dir.toml: 2 errors"
checked socket_dir "[socket]\npath = \"$tmp/no-such-dir/s.sock\"\n" -- \
    "$tmp/socket_dir.toml:2: socket.path: the directory \"$tmp/no-such-dir\" does not exist (got \"$tmp/no-such-dir/s.sock\")"
# Every problem, not the first: two bad values, an unknown key and a --set.
checked all "[source]\nspeed = -1\ncolour = 1\n[log]\nenabled = \"yes\"\n${ok_socket}" --set tracker.seed=-5 -- \
    "$tmp/all.toml:2: source.speed:" "$tmp/all.toml:3: source.colour: unknown key" \
    "$tmp/all.toml:5: log.enabled:" "--set tracker.seed=-5: tracker.seed:" "scaled: $tmp/all.toml: 4 errors"
# A configuration that starts checks clean, with the shipped priors beside it.
printf '[estimator]\npriors = "priors.toml"\n[socket]\npath = "%s"\n[log]\ndir = "%s"\n' \
    "$tmp/run/s.sock" "$tmp/log" > "$tmp/good.toml"
set +e; out=$("$scaled" --check-config "$tmp/good.toml" 2>"$tmp/err"); rc=$?; set -e
[[ $rc -eq 0 ]] || fail "good.toml: exit $rc ($(cat "$tmp/err"))"
[[ $out == *"good.toml: configuration OK"* ]] || fail "good.toml: stdout '$out'"

# Start-up: an unknown group is a configuration error (78), not 73, and
# nothing is created.
set +e
err=$("$scaled" --no-tty --config "$tmp/good.toml" --set socket.group=nosuchgrp-scaled 2>&1 >/dev/null)
rc=$?
set -e
[[ $rc -eq 78 ]] || fail "start with an unknown group: exit $rc, expected 78 ($err)"
[[ $err == *"unknown group 'nosuchgrp-scaled'"* ]] || fail "start with an unknown group: '$err'"
[[ ! -e $tmp/run/s.sock && ! -e $tmp/log ]] || fail "start with an unknown group created files"

# Usage errors are 64, not 78.
set +e; "$scaled" --check-config "$tmp/x.toml" --bogus >/dev/null 2>&1; rc=$?; set -e
[[ $rc -eq 64 ]] || fail "--bogus: exit $rc, expected 64"
echo "scaled --check-config: all checks passed"
