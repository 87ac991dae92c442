// sandtable-lab scale: the cost of a site as it grows (docs/lab.md, "Scale"). One
// `sandtable-lab run --site grid-N` per N, each a child process with its own folder; per N the
// calibration's modeled site time, colours, the slowest node's compute, messages and bytes per
// node, the coordinator's and the world's CPU, the nodes' peak memory, the registration error
// and, with --reblend, the re-blend time after a node is killed; scale.csv, scale.md (+ html)
// and two gnuplot plots.
#pragma once

#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace sandtable::sim {

struct ScalePoint {
  int nodes = 0;
  bool ok = false;
  std::string error;
  double rms_mm = 0, device_time_s = 0, compute_s = 0, round_wall_s = 0;
  int colours = 0;
  double messages_per_node = 0, bytes_per_node = 0;
  double coordinator_cpu_s = 0, world_cpu_s = 0, node_cpu_s_mean = 0;
  double node_rss_mb_max = 0, world_rss_mb = 0;
  double total_s = 0;
  double reblend_ms = -1;  // -1: not measured
};

// Reads one run's report.json (its processes' CPU and memory included) into `point`.
void ReadScaleRun(const std::string& report_path, ScalePoint* point);

// The ratio of the largest to the smallest messages per node over the points with at least
// `from_nodes` nodes (0 when fewer than two such points are ok).
double MessagesSpread(const std::vector<ScalePoint>& points, int from_nodes);

struct LabScaleOptions {
  std::vector<int> nodes{2, 4, 8};
  std::string scene = "city";
  std::string out_dir;
  std::string bin_dir;
  uint64_t seed = 1;
  int metric_samples = 4000;
  // Every projector and camera at this fraction of its resolution (the world renders every
  // capture of every camera; at full resolution grid-64 would take hours on two cores).
  double resolution_scale = 0.5;
  bool reblend = false;  // render and blend on, a node killed after calibration (slower)
  std::string command_line;
  // INVALID_ARGUMENT naming the flag: no --out, no size or one outside 1..64, --samples < 1,
  // --resolution-scale outside [0.05, 1].
  Status Check() const;
};

// Exit codes: 0 every size measured, 1 one or more failed (the others are reported), 2 usage,
// 130 interrupted.
int RunScale(const LabScaleOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err);

}  // namespace sandtable::sim
