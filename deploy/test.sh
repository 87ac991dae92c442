#!/usr/bin/env bash
# Sandtable test entry point: installs dependencies, configures (warnings are errors), builds
# (all cores), runs every test through CTest printing the output of any failing test, and
# checks that every tracked C++ source is clang-formatted (.clang-format at the root).
#   deploy/test.sh                 # build dir: build/ (deploy/demo.sh uses build-demo/)
#   BUILD_DIR=/tmp/b deploy/test.sh
#   FORMAT_ONLY=1 deploy/test.sh   # only the clang-format check
# Exits non-zero when the build, a test or the format check fails; the format check runs even
# when tests fail, and lists every unformatted file (fix: clang-format -i FILE...).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build}"
jobs="$(nproc)"

# Every tracked *.h / *.cc (or, outside a git checkout, every one under the source folders)
# must be unchanged by clang-format.
check_format() {
  local files=() unformatted=() f
  if git -C "$root" rev-parse --is-inside-work-tree > /dev/null 2>&1; then
    mapfile -d '' files < <(git -C "$root" ls-files -z -- '*.h' '*.cc')
  else
    mapfile -d '' files < <(cd "$root" && find common proto net cluster node coordinator sim \
      tests \( -name '*.h' -o -name '*.cc' \) -print0 2> /dev/null)
  fi
  for f in "${files[@]}"; do
    [ -f "$root/$f" ] || continue  # deleted in the work tree, not yet committed
    clang-format --dry-run --Werror "$root/$f" > /dev/null 2>&1 || unformatted+=("$f")
  done
  if [ "${#unformatted[@]}" -ne 0 ]; then
    echo "test.sh: ${#unformatted[@]} of ${#files[@]} sources are not clang-formatted:"
    printf '  %s\n' "${unformatted[@]}"
    echo "test.sh: fix with: clang-format -i FILE... (style: $root/.clang-format)"
    return 1
  fi
  echo "test.sh: clang-format: all ${#files[@]} sources formatted"
}

if [ "${FORMAT_ONLY:-0}" != 0 ]; then
  check_format
  exit $?
fi

bash "$root/deploy/install-deps.sh"

echo "test.sh: configuring $build"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSANDTABLE_BUILD_TESTS=ON -DSANDTABLE_BUILD_BENCHMARKS=ON -DSANDTABLE_WERROR=ON
echo "test.sh: building with $jobs jobs"
cmake --build "$build" -j "$jobs"

# Bounded libFuzzer run over the message handlers (clang + libFuzzer from Debian); falls back
# to replaying the checked-in corpus when libFuzzer is missing. FUZZ_SECONDS=0 skips it.
if [ "${FUZZ_SECONDS:-60}" != 0 ]; then
  FUZZ_JOBS="$jobs" bash "$root/deploy/fuzz.sh" "${FUZZ_SECONDS:-60}" "${build}-fuzz"
fi

echo "test.sh: running tests"
tests_rc=0
(cd "$build" && ctest --output-on-failure -j "$jobs" --timeout 600) || tests_rc=$?

echo "test.sh: checking formatting"
format_rc=0
check_format || format_rc=$?

if [ "$tests_rc" -ne 0 ]; then
  echo "test.sh: tests FAILED (ctest exit $tests_rc)"
fi
[ "$tests_rc" -eq 0 ] && [ "$format_rc" -eq 0 ]
