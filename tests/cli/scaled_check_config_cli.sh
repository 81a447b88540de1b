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

# Usage errors are 64, not 78.
set +e; "$scaled" --check-config "$tmp/x.toml" --bogus >/dev/null 2>&1; rc=$?; set -e
[[ $rc -eq 64 ]] || fail "--bogus: exit $rc, expected 64"
echo "scaled --check-config: all checks passed"
