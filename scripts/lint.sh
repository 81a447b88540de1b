#!/usr/bin/env bash
# Style checks: clang-format (.clang-format) on every C++ file, clang-tidy
# (.clang-tidy) on every source file, using a build's compile_commands.json.
#   scripts/lint.sh                     # both, with build/release
#   scripts/lint.sh --format-only       # clang-format only
#   scripts/lint.sh --tidy-only [DIR]   # clang-tidy only, with DIR/compile_commands.json
#   scripts/lint.sh --tidy-product [DIR]  # clang-tidy on the product's code only (not tests/)
# ctest runs style.clang_format (every file) and style.clang_tidy (--tidy-product):
# clang-tidy on the 61 test files costs as much again (15-25 s each on 2 cores,
# GoogleTest, Eigen and OpenCV parsed per file) and CI has 45 minutes; run
# scripts/lint.sh before committing changes to tests.
set -euo pipefail
cd "$(dirname "$0")/.."

mode=both
tests=yes
db=build/release
case ${1:-} in
  --format-only) mode=format ;;
  --tidy-only) mode=tidy; db=${2:-$db} ;;
  --tidy-product) mode=tidy; tests=no; db=${2:-$db} ;;
  "") ;;
  *) echo "usage: scripts/lint.sh [--format-only | --tidy-only [BUILD_DIR] | --tidy-product [BUILD_DIR]]" >&2; exit 64 ;;
esac

if [[ -d .git ]]; then
  mapfile -t files < <(git ls-files --cached --others --exclude-standard '*.cpp' '*.h')
else
  mapfile -t files < <(find core drivers daemon tools tests -name '*.cpp' -o -name '*.h')
fi

if [[ $mode != tidy ]]; then
  clang-format --dry-run --Werror "${files[@]}"
  echo "clang-format: ${#files[@]} files clean"
fi
[[ $mode == format ]] && exit 0

[[ -f $db/compile_commands.json ]] || { echo "lint: no $db/compile_commands.json: configure first (cmake --preset release)" >&2; exit 66; }
mapfile -t sources < <(printf '%s\n' "${files[@]}" | grep '\.cpp$' | grep -v '^tests/')
test_sources=()
if [[ $tests == yes ]]; then
  mapfile -t test_sources < <(printf '%s\n' "${files[@]}" | grep '\.cpp$' | grep '^tests/')
fi
log=$db/clang-tidy.log
# compile_commands.json holds GCC-only flags (-Wno-restrict): clang must not trip on them.
# The product's code gets every check of .clang-tidy. The tests get all but the
# clang static analyzer (clang-analyzer-*), which is four fifths of the time on
# a gtest file and finds little there: it keeps CI on 2 cores within budget.
status=0
run-clang-tidy -quiet -p "$db" -j "$(nproc)" -extra-arg=-Wno-unknown-warning-option \
  "${sources[@]}" >"$log" 2>&1 || status=1
if ((${#test_sources[@]} > 0)); then
  run-clang-tidy -quiet -p "$db" -j "$(nproc)" -extra-arg=-Wno-unknown-warning-option \
    -checks='-clang-analyzer-*' "${test_sources[@]}" >>"$log" 2>&1 || status=1
fi
if ((status != 0)); then
  grep -E 'warning:|error:' -A3 "$log" >&2 || cat "$log" >&2
  echo "clang-tidy: findings above (full log: $log)" >&2
  exit 1
fi
if [[ $tests == yes ]]; then
  echo "clang-tidy: ${#sources[@]} files clean, ${#test_sources[@]} test files clean (without clang-analyzer)"
else
  echo "clang-tidy: ${#sources[@]} files clean (test files not checked: scripts/lint.sh does)"
fi
