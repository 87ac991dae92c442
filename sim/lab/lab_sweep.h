// sandtable-lab sweep: run time against error over the knobs that trade them (docs/lab.md,
// "Sweep"). One `sandtable-lab run` per configuration (the shipped defaults, then one knob
// changed at a time), each a child process with its own output folder; the calibration's
// registration error against its modeled projection time and its compute time goes to
// sweep.csv, sweep.md (+ sweep.html) and two Pareto plots drawn by gnuplot.
#pragma once

#include <atomic>
#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "common/base/status.h"

namespace sandtable::sim {

struct SweepConfig {
  std::string name;                    // "phase-steps=4"; "defaults" for the shipped configuration
  std::string knob;                    // "phase-steps"; empty for the defaults
  std::string value;                   // "4"
  std::vector<std::string> node_args;  // passed to every node (--node-arg=...)
  // A blend configuration: the run shows and blends (its figures: the blend's steps against its
  // cast time), "blend" for the shipped blend.
  bool blend = false;
  std::vector<std::string> lab_args;  // or to `sandtable-lab run` itself, for its own options
};

// The configurations swept: the defaults first, then each calibration knob's values one at a
// time, then the blend's (blend sampling resolution, the shortfall's fill limit).
std::vector<SweepConfig> DefaultSweep();

struct SweepPoint {
  SweepConfig config;
  bool ok = false;
  std::string error;  // why the run gave no figure
  double rms_mm = 0, p99_mm = 0, max_mm = 0;
  double device_time_s = 0;      // modeled projection time of the whole site
  double compute_s = 0;          // slowest node's compute (one core)
  double round_wall_s = 0;       // the round's wall time on this machine
  int frames_per_projector = 0;  // most
  bool front_device = false, front_compute = false;
  // Blend configurations: the steps over 5 mm (%) and the slowest node's cast (surface + field).
  double table_p99_pct = 0, table_max_pct = 0, walls_p99_pct = 0, walls_max_pct = 0;
  double uniformity = 0, cast_ms = 0;
  bool front_blend = false;  // walls' p99 against cast time
};

// Marks the points no other ok point beats on both error and time (front_device against the
// modeled projection time, front_compute against compute; blend points among themselves,
// front_blend: walls' p99 step against cast time).
void MarkParetoFronts(std::vector<SweepPoint>& points);

// The sweep's table as CSV (header + one line per point).
std::string SweepCsv(const std::vector<SweepPoint>& points);

// Shared by sweep and scale (sim/lab/lab_scale.h).
// Runs `sandtable-lab run ARGS` (this program, `run_args` after "run") as a child whose
// stdout and stderr go to `log_path`, until it exits; on `stop` it is sent SIGTERM (it tears
// its site down and writes its report). An empty string when it completed (exit 0, or 3: its
// verdict failed, lab_run.h), else why not.
std::string RunChildLab(const std::vector<std::string>& run_args, const std::string& log_path,
                        const std::atomic<bool>& stop);
// Draws `script` with gnuplot (found on PATH); an empty string when it did, else why not.
std::string RunGnuplot(const std::string& script, const std::string& log_path);
std::string FixedDigits(double value, int digits);

struct LabSweepOptions {
  std::string site = "sandtable-3";
  std::string scene = "sandtable";
  std::string out_dir;
  std::string bin_dir;
  uint64_t seed = 1;
  int metric_samples = 6000;
  std::vector<std::string> only;  // configuration names to run (empty: all)
  std::string command_line;
  // INVALID_ARGUMENT naming the flag: no --out, --samples < 1.
  Status Check() const;
};

// Exit codes: 0 every configuration measured, 1 one or more failed (the others are reported),
// 2 usage, 130 interrupted.
int RunSweep(const LabSweepOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err);

}  // namespace sandtable::sim
