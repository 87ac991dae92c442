#include "sim/lab/lab_lines.h"

#include <cstdio>
#include <variant>

namespace sandtable::sim {

void LabLines::Take(const std::string& role, const report::ReportLine& line,
                    std::chrono::steady_clock::time_point now) {
  const bool node = role == "node";
  const bool taken =
      std::visit(report::Overloaded{
                     [&](const report::WorldReady& l) {
                       if (role != "world") return false;
                       world_endpoint = l.world;
                       return true;
                     },
                     [&](const report::CoordinatorReady& l) {
                       if (role != "coordinator") return false;
                       coordinator_requests = l.requests;
                       coordinator_events = l.events;
                       coordinator_status = l.status;
                       return true;
                     },
                     [&](const report::NodeReady& l) {
                       if (!node) return false;
                       nodes_ready.insert(l.id);
                       return true;
                     },
                     [&](const report::Calibrated& l) {
                       if (!node) return false;
                       calibrated[l.id] = l;
                       calibrated_at[l.id] = now;
                       return true;
                     },
                     [&](const report::CalibrationFailed& l) {
                       if (!node) return false;
                       calibration_failed[l.id] = l.reason.empty() ? "(no reason given)" : l.reason;
                       return true;
                     },
                     [&](const report::Verification& l) {
                       if (!node) return false;
                       verification[l.id] = l;
                       return true;
                     },
                     [&](const report::RenderUnavailable& l) {
                       if (!node) return false;
                       render_unavailable[l.id] = l.reason;
                       return true;
                     },
                     [&](const report::RenderPattern& l) {
                       if (!node) return false;
                       render_pattern[l.id] = l.pattern;
                       return true;
                     },
                     [&](const report::RenderSummary& l) {
                       if (!node) return false;
                       render_summary[l.id] = l;
                       return true;
                     },
                     [&](const report::BlendExported&) {
                       if (!node) return false;
                       last_blend_line = now;
                       return true;
                     },
                     [&](const report::BlendShown& l) {
                       if (!node) return false;
                       last_blend_line = now;
                       if (l.reblend) {
                         reblends.push_back(l);
                       } else {
                         blend[l.id] = l;
                         blended.push_back(l);
                       }
                       return true;
                     },
                     [&](const report::Messages&) { return node; },
                     [&](const report::RoundProgress& l) {
                       if (!node) return false;
                       round_progress = l;
                       round_progress_at = now;
                       return true;
                     },
                     // The lab's own lines: a child lab (sweep, scale, chaos) prints them.
                     [&](const report::LabPhase&) { return role == "lab"; },
                     [&](const report::LabDone&) { return role == "lab"; },
                 },
                 line);
  if (!taken) ++ignored;
}

std::string RoundProgressText(const report::RoundProgress& progress, bool step_only) {
  std::string units;
  for (NodeId unit : progress.units) units += (units.empty() ? "" : ", ") + std::to_string(unit);
  char elapsed[32];
  std::snprintf(elapsed, sizeof(elapsed), "%.1f s in", progress.elapsed_s);
  const std::string what = step_only || progress.detail.empty() ? progress.step : progress.detail;
  return "round by unit " + std::to_string(progress.id) + ": " + what +
         (units.empty() ? ""
                        : (progress.units.size() == 1 ? " (unit " : " (units ") + units + ")") +
         ", " + elapsed;
}

}  // namespace sandtable::sim
