#!/usr/bin/env bash
# The main job's steps, run by deploy/demo.sh after the build:
#   deploy/demo_run.sh BUILD_DIR OUT_DIR
# Each step prints what it does and how long it took; deploy/demo_report.py then writes
# OUT_DIR/report.md from the files the steps left. A failing step is reported, not hidden:
# the script exits non-zero after writing the report.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="$1"
out="$2"
cd "$root"
mkdir -p "$out"
: > "$out/steps.tsv"
failed=0

step() {  # step NAME COMMAND... ; logs to OUT/NAME.log, records status and seconds
  local name="$1"; shift
  echo "demo: [$name] $*"
  local start end rc
  start=$(date +%s.%N)
  "$@" > "$out/$name.log" 2>&1
  rc=$?
  end=$(date +%s.%N)
  local secs
  secs=$(python3 -c "print(f'{$end - $start:.1f}')")
  printf '%s\t%s\t%s\n' "$name" "$rc" "$secs" >> "$out/steps.tsv"
  if [ "$rc" -ne 0 ]; then
    echo "demo: [$name] FAILED (exit $rc), log: $out/$name.log"
    failed=1
  else
    echo "demo: [$name] ok in ${secs} s"
  fi
}

lab="$build/sim/lab/sandtable-lab"
world="$build/sim/app/sandtable-world"
node="$build/node/sandtable-node"
bench="$build/tests/bench"

# 1. The site lab: the default site and scene as real processes (world, coordinator, one node
#    per unit) on localhost, measured against the world's truth (docs/lab.md); then the
#    ceiling-grid site over the city table.
step lab "$lab" run --site sandtable-3 --scene sandtable --out "$out/lab" --progress plain
# The true-pose baseline (factory intrinsics) is measured, not held to the self-calibration's bar.
step lab_true_pose "$lab" run --site sandtable-3 --scene sandtable --calibration true-pose \
  --max-rms-mm 0 --out "$out/lab-true-pose" --progress plain
step lab_grid8 "$lab" run --site grid-8 --scene city --out "$out/lab-grid8" --progress plain

# The lab's other commands, small enough for the demo (docs/results.md has the full ones): run
# time against error over four calibration configurations and two of the blend, the cost of
# grid-2/4/8 at half resolution, and
# one seeded chaos run (kills, a join over faulty links, a stall, the coordinator restarted).
step sweep "$lab" sweep --out "$out/sweep" --only defaults --only gray-cell-px=8 \
  --only phase-steps=4 --only grid-step-px=32 --only blend --only blend-fill-limit=1
step scale "$lab" scale --nodes 2,4,8 --out "$out/scale"
step chaos "$lab" chaos --runs 1 --out "$out/chaos"

# 2. The simulated world alone: a TR09-017 sand table lit white by three projectors.
step scene "$world" make-scene --preset sandtable --seed 1 -o "$out/scene.gltf"
step site "$world" make-site --preset sandtable-3 --seed 1 -o "$out/site.json"
step render_top "$world" render --site "$out/site.json" --scene "$out/scene.gltf" --white \
  --view top -o "$out/world_top_white.png"
step render_camera0 "$world" render --site "$out/site.json" --scene "$out/scene.gltf" --white \
  --view camera:0 -o "$out/world_camera0_white.png"

# 3. Structured light and unit calibration on the real procam captures.
step structured_light "$bench/bench_structured_light" --data ../shared/data/procam-kamino410 \
  --out "$out" --repeats 5
step calibrate_unit "$node" calibrate-unit --poses ../shared/data/procam-kamino410 \
  -o "$out/unit.json" --report "$out/unit_report.json"

# 4. Geometry core: run time against error and breakdown sweeps, plotted.
step numerics "$bench/sandtable_numerics_sweep" --out "$out/numerics"
step numerics_plots bash tests/bench/plot_sweeps.sh "$out/numerics"

# 5. Protocol: event fan-out latency coordinator -> 3 nodes at 120 Hz over loopback.
step event_latency "$bench/bench_event_latency" 1200 120 3

python3 "$root/deploy/demo_report.py" "$out"
# The same report as one page, every picture inlined.
"$lab" html "$out/report.md" --title "Sandtable demo report" || failed=1
echo "demo: report written to $out/report.md and $out/report.html"
exit "$failed"
