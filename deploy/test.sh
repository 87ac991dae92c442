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

echo "test.sh: running tests"
cd "$build"
ctest --output-on-failure -j "$jobs" --timeout 600
