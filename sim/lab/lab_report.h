// The lab's report: DIR/report.json (for programs; fields in docs/lab.md) and DIR/report.md
// (tables and pictures for people), written from one LabResult whether the run succeeded or
// not (a failed run's report says which child failed, how, and the end of its log).
//
// report.json (format "sandtable.lab_report", version 1):
//   status: "ok" | "failed" | "interrupted"; reasons: [{what, detail}] (a completed run's
//   failures, lab_verdict.h); max_rms_mm; command; seed; total_s; phases: [{name, seconds}]
//   site: {name, label, units, file}; scene: {label, file, triangles}
//   processes: [{name, pid, role, exit}]
//   calibration: {source, rms_mm, p99_mm, max_mm, rms_px, p99_px, max_px, count, unmeasured,
//                 table: {...same...}, buildings: {...same...},
//                 per_unit: {"<id>": {source, json, yaml, ...same..., table, buildings}},
//                 metric: {candidates, lit_points, table_points, building_points, seed,
//                          max_incidence_deg, definition}}
//   images: {top_white, registration_error}; failure: {phase, reason, child, role, pid,
//   exit, exit_code, signal, signal_name, log, log_tail}
// Failure: IO_ERROR naming the path when a file cannot be written.
#pragma once

#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "sim/lab/registration_metric.h"

namespace sandtable::sim {

struct LabFailure {
  std::string phase;   // the phase it happened in ("start nodes")
  std::string reason;  // one line a person can act on
  // When a child caused it:
  std::string child, role;
  int pid = -1;
  std::string exit_text;  // "killed by signal 9 (SIGKILL)"
  std::optional<int> exit_code, signal;
  std::string log_path;  // relative to the output directory
  std::vector<std::string> log_tail;
};

struct LabProcess {
  std::string name, role;
  int pid = -1;
  std::string exit_text;
  double cpu_s = 0.0;       // user + system CPU time over its life (the coordinator's load)
  double max_rss_mb = 0.0;  // peak resident memory
};

struct LabUnitResult {
  std::string source;
  std::string json_path, yaml_path;  // relative to the output directory
};

// Why a completed run failed (sim/lab/lab_verdict.h): what, and the figures behind it.
struct LabReason {
  std::string what;
  std::string detail;
};

struct LabResult {
  std::string status = "ok";  // ok | failed | interrupted
  std::string command;
  uint64_t seed = 1;
  uint64_t noise_seed = 1;  // the world's capture noise
  std::string site_name, site_label, scene_label, site_path, scene_path;
  int num_units = 0;
  int scene_triangles = 0;
  std::vector<std::pair<std::string, double>> phase_seconds;
  double total_s = 0.0;
  // The machine's 1-minute load average at the end of the run (-1: not known) and its cores:
  // every timing figure depends on them.
  double load_average = -1.0;
  int cores = 0;
  std::vector<LabProcess> processes;
  // The children's report lines read, and those that did not parse (cluster/report_lines.h).
  uint64_t report_lines = 0, bad_report_lines = 0;
  std::string last_bad_report_line;
  std::string calibration_source;  // the units' common source, or "mixed"
  std::map<NodeId, LabUnitResult> units;
  std::optional<RegistrationReport> registration;
  // The baseline the self-calibration is compared with: each calibrated unit's factory
  // intrinsics at its true pose, the model at its true placement (site rms and p99, mm).
  std::optional<double> baseline_rms_mm, baseline_p99_mm;
  RegistrationMetricOptions metric_options;
  std::string top_white_png, heatmap_png;  // relative; empty when not made
  std::string console_url;                 // the site's console while the run lasted
  double heatmap_scale_mm = 0.0;
  std::optional<LabFailure> failure;
  // A completed run's verdict (status "failed" when any): first in report.md, "reasons" in
  // report.json. Step figures from fewer than min_step_pairs pairs show "not measured".
  std::vector<LabReason> reasons;
  int min_step_pairs = 1;
  double max_rms_mm = 0.0;  // the bar the registration was judged by (0: none)
  // Self-calibration (docs/calibration.md): the runner's report, per-unit compute, messages
  // and bytes; units that could not calibrate and why; the model's placement against the truth.
  nlohmann::json self_calibration = nlohmann::json::object();
  nlohmann::json join;   // --join-late: the late unit's join (null when none)
  nlohmann::json kill;   // --kill-unit: what the others did (null when none)
  nlohmann::json stall;  // --stall-unit: when the unit was stopped and resumed (null when none)
  // --enroll-unit: when the unit with no key asked, was accepted, and was ready (null when none)
  nlohmann::json enrollment;
  // Faults during the hold (docs/lab.md, "Chaos"): the annotations painted and found, the
  // coordinator's restart, faults on a node's links, frames lost, crashes (null when none).
  nlohmann::json chaos;
  // The show (docs/render.md): frame times, the floor, timeline skew, grid coincidence, and
  // per-unit summaries; empty when the nodes did not render.
  nlohmann::json render = nlohmann::json::object();
  // The blend (docs/blend.md): steps per surface kind, uniformity, level, cost; empty when the
  // nodes did not blend. `live`: re-blend after a kill.
  nlohmann::json photometric = nlohmann::json::object();
  nlohmann::json live = nlohmann::json::object();
  std::map<NodeId, std::string> unit_failures;
  bool model_offset_measured = false;
  // The nodes found no placement of the model: the registration was measured with the true one
  // expressed in their table frame (calibration.placement "true").
  bool measured_with_true_placement = false;
  double model_offset_mm = 0.0, model_offset_deg = 0.0;
};

// The registration metric in words (report.json "definition", report.md).
inline constexpr char kRegistrationMetricDefinition[] =
    "points X sampled area-weighted on every lit surface where the model truly stands; per "
    "projector that truly lights X at incidence under max_incidence_deg: u_hat = X projected "
    "with the unit's exported calibration (projector intrinsics, table_from_projector, "
    "table_from_model); the TRUE ray of the projector through u_hat meets the plane of X's "
    "triangle at X'; error |X' - X| (mm) and |u_hat - u_true| (projector px). Table faces: "
    "all vertices within 0.1 mm of z = 0 and normal z > 0.999; every other face is building.";

nlohmann::json LabReportJson(const LabResult& result);
std::string LabReportMarkdown(const LabResult& result);
Status WriteLabReport(const LabResult& result, const std::string& out_dir);

}  // namespace sandtable::sim
