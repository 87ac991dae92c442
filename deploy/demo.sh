#!/usr/bin/env bash
# Sandtable main job: installs dependencies, builds, and runs the site lab and the other demo
# sections, writing a report under out/demo/ (report.md plus CSV and PNG files).
#
# First section (deploy/demo_run.sh): the site lab on the default site and scene,
#   sandtable-lab run --site sandtable-3 --scene sandtable --out out/demo/lab
# (world + coordinator + one node per unit on localhost, measured against the world's ground
# truth; its report is out/demo/lab/report.md, docs/lab.md). Then grid-8 over the city, the
# world alone, structured light and unit calibration on real captures, the numerics sweeps and
# the event latency, all summarised in out/demo/report.md.
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
