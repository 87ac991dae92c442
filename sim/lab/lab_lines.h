// LabLines: what the lab learns from its children's report lines (cluster/report_lines.h): the
// endpoints they bound, which units are ready, calibrated or failed, their render and blend
// figures. Fed every line the supervisor reads, with the role of the child that printed it; a
// line of a kind that role does not print is counted in `ignored` and otherwise left out.
// Not thread-safe: the lab's supervisor thread feeds and reads it.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "cluster/report_lines.h"
#include "common/base/ids.h"

namespace sandtable::sim {

struct LabLines {
  // `role`: "world", "coordinator", "node" or "lab"; `now`: when the line came.
  void Take(const std::string& role, const report::ReportLine& line,
            std::chrono::steady_clock::time_point now);

  std::string world_endpoint;
  std::string coordinator_requests, coordinator_events;
  std::string coordinator_status;  // its status page's URL (empty: not served)
  std::set<NodeId> nodes_ready;
  std::map<NodeId, report::Calibrated> calibrated;  // each unit's last calibrated line
  std::map<NodeId, std::chrono::steady_clock::time_point> calibrated_at;  // ... and when
  std::map<NodeId, std::string> calibration_failed;                       // and why
  std::map<NodeId, report::Verification> verification;
  std::map<NodeId, std::string> render_unavailable;        // nodes that cannot render, and why
  std::map<NodeId, std::string> render_pattern;            // the last pattern each node showed
  std::map<NodeId, report::RenderSummary> render_summary;  // each node's last summary
  std::map<NodeId, report::BlendShown> blend;              // each node's last blended line
  std::vector<report::BlendShown> blended;                 // every blended line
  std::vector<report::BlendShown> reblends;                // every re-blend after a leave
  std::chrono::steady_clock::time_point last_blend_line{};
  // The last progress line of a calibration round's runner, and when it came.
  std::optional<report::RoundProgress> round_progress;
  std::chrono::steady_clock::time_point round_progress_at{};
  uint64_t ignored = 0;
};

// A round's progress line for a person: "round by unit 0: colour 1 frame 12 capture (units 0,
// 2), 14.2 s in"; with `step_only`, the part of the round instead of the stage ("round by unit
// 0: structured light, colour 1 (units 0, 2), 14.2 s in").
std::string RoundProgressText(const report::RoundProgress& progress, bool step_only = false);

}  // namespace sandtable::sim
