# Sourced by the tools' end-to-end scripts in tests/cli: a scratch directory
# removed at exit ($tmp), fail MESSAGE, and expect RC SUBSTRING -- COMMAND...
# (the command exits with RC and says SUBSTRING on stderr).
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
expect() {
    local want=$1 text=$2; shift 3
    local err rc
    set +e; err=$("$@" 2>&1 >/dev/null); rc=$?; set -e
    [[ $rc -eq $want ]] || fail "$*: exit $rc, expected $want ($err)"
    [[ $err == *"$text"* ]] || fail "$*: message '$err' does not mention '$text'"
}
# need_redkitchen SHARED_DIR: $rk (the redkitchen dataset) and $py (python3),
# or exit 77 (skip) when SHARED_DIR has no redkitchen.
need_redkitchen() {
    rk="$1/data/redkitchen"
    if [[ ! -d "$rk" ]]; then
        echo "SKIP: $rk not found (set SCALED_SHARED_DIR)"
        exit 77
    fi
    py=/usr/bin/python3
    [[ -x $py ]] || py=python3
}
