#!/usr/bin/env bash
# Sandtable main job: installs dependencies, builds, and runs what the project can run today,
# writing a report under out/demo/ (report.md plus CSV and PNG files).
#
# The site lab (sandtable-lab: world + coordinator + N nodes on localhost, measured against the
# world's ground truth) does not exist yet. Until it does, this runs the parts that exist and
# says so in the report.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Its own build directory: deploy/test.sh configures build/ (tests on, -Werror); sharing it
# would reconfigure each other's build.
build="${DEMO_BUILD_DIR:-$root/build-demo}"
out="${OUT_DIR:-$root/out/demo}"

bash "$root/deploy/install-deps.sh"
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSANDTABLE_BUILD_TESTS=OFF -DSANDTABLE_BUILD_BENCHMARKS=ON
cmake --build "$build" -j "$(nproc)"
mkdir -p "$out"
exec bash "$root/deploy/demo_run.sh" "$build" "$out"
