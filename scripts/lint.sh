#!/usr/bin/env bash
# Style checks: clang-format on every C++ file, then clang-tidy (.clang-tidy)
# over the project's sources using build/release/compile_commands.json.
#   scripts/lint.sh                 # both
#   scripts/lint.sh --format-only   # clang-format only (what ctest runs)
set -euo pipefail
cd "$(dirname "$0")/.."

mapfile -t files < <(git ls-files '*.cpp' '*.h' 2>/dev/null || find core drivers daemon tools tests -name '*.cpp' -o -name '*.h')
clang-format --dry-run --Werror "${files[@]}"
echo "clang-format: ${#files[@]} files clean"

[[ ${1:-} == --format-only ]] && exit 0

db=build/release
[[ -f $db/compile_commands.json ]] || { echo "lint: configure first: cmake --preset release" >&2; exit 66; }
mapfile -t sources < <(printf '%s\n' "${files[@]}" | grep '\.cpp$')
run-clang-tidy -quiet -p "$db" -j "$(nproc)" "${sources[@]}" 2>/dev/null | grep -vE '^(clang-tidy|[0-9]+ warnings? generated)' || true
# run-clang-tidy's exit status is what counts:
run-clang-tidy -quiet -p "$db" -j "$(nproc)" "${sources[@]}" >/dev/null 2>&1
echo "clang-tidy: clean"
