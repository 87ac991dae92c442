// sandtable-lab chaos: faults injected while a site runs (docs/lab.md, "Chaos"), over several
// seeds. One `sandtable-lab run` per seed, each a child process with its own folder; the seed
// draws which unit joins late (a new node started once the others are calibrated), which is
// SIGKILLed and which SIGSTOPped while the site shows, when the coordinator is SIGKILLed and
// restarted on its database, and the node whose links drop and corrupt a share of what it
// sends. The lab paints strokes through the coordinator all through the hold. Per seed: the
// faults' detection and recovery times, frames lost on the other nodes, annotations
// acknowledged against present afterwards, processes crashed; chaos.csv and chaos.md/html.
#pragma once

#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/status.h"

namespace sandtable::sim {

struct ChaosPlan {
  uint64_t seed = 1;
  int join_unit = -1, kill_unit = -1, stall_unit = -1, fault_unit = -1;
  double kill_at_s = 0, stall_at_s = 0, stall_for_s = 0, coordinator_at_s = 0, hold_s = 0;
  double drop_share = 0, corrupt_share = 0;
  std::vector<std::string> RunArgs() const;  // the `sandtable-lab run` flags of the faults
};

// The faults of `seed` on a site of `units` units (ids 0..units-1, at least 3).
ChaosPlan MakeChaosPlan(uint64_t seed, int units);

struct ChaosOutcome {
  ChaosPlan plan;
  bool ran = false;   // the run finished and wrote its report
  std::string error;  // why it did not, or what failed in it
  int crashed = -1;
  long long acknowledged = -1, present = -1, lost = -1;
  double kill_detected_ms = -1, kill_reblend_ms = -1, join_ms = -1, join_reblend_ms = -1;
  double coordinator_ready_ms = -1, annotations_back_ms = -1;
  int frames_lost_max = -1;
  long long dropped = 0, corrupted = 0, rejected = 0;
  bool join_failed = false;
  // 0 crashes, 0 acknowledged annotations lost (and some acknowledged), the newcomer joined.
  bool passed() const {
    return ran && crashed == 0 && lost == 0 && acknowledged > 0 && !join_failed;
  }
};

// Reads a chaos run's report.json into `outcome` (ran, error and the figures).
void ReadChaosRun(const std::string& report_path, ChaosOutcome* outcome);

struct LabChaosOptions {
  std::string site = "sandtable-3";
  std::string scene = "sandtable";
  std::string out_dir;
  uint64_t first_seed = 1;
  int runs = 5;
  int metric_samples = 4000;
  std::string bin_dir;
  // Where each run's children run: "local" or "netns" (sandtable-lab run --hosts).
  std::string hosts = "local";
  std::string command_line;
  // INVALID_ARGUMENT naming the flag: no --out, --runs outside 1..1000, --samples < 1.
  Status Check() const;
};

// Exit codes: 0 every run passed (0 annotations lost, 0 crashes), 1 otherwise, 2 usage,
// 130 interrupted.
int RunChaos(const LabChaosOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err);

}  // namespace sandtable::sim
