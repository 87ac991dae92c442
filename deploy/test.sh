#!/usr/bin/env bash
# Sandtable test entry point: installs dependencies, configures, builds (all cores) and runs
# every test through CTest, printing the output of any failing test.
#   deploy/test.sh                 # build dir: build/
#   BUILD_DIR=/tmp/b deploy/test.sh
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${BUILD_DIR:-$root/build}"
jobs="$(nproc)"

bash "$root/deploy/install-deps.sh"

echo "test.sh: configuring $build"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSANDTABLE_BUILD_TESTS=ON -DSANDTABLE_BUILD_BENCHMARKS=ON
echo "test.sh: building with $jobs jobs"
cmake --build "$build" -j "$jobs"

# Bounded libFuzzer run over the message handlers (clang + libFuzzer from Debian); falls back
# to replaying the checked-in corpus when libFuzzer is missing. FUZZ_SECONDS=0 skips it.
if [ "${FUZZ_SECONDS:-60}" != 0 ]; then
  FUZZ_JOBS="$jobs" bash "$root/deploy/fuzz.sh" "${FUZZ_SECONDS:-60}" "${build}-fuzz"
fi

echo "test.sh: running tests"
cd "$build"
ctest --output-on-failure -j "$jobs" --timeout 600
