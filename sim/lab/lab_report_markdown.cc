// The lab's report.md (lab_report.h, LabReportMarkdown): one function per section.
#include <algorithm>
#include <cstdio>
#include <sstream>

#include "sim/lab/lab_prediction.h"
#include "sim/lab/lab_report.h"
#include "sim/lab/lab_verdict.h"

namespace sandtable::sim {
namespace {

using json = nlohmann::json;
constexpr const char* kDefinition = kRegistrationMetricDefinition;

std::string Fixed(double value, int digits = 3) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", digits, value);
  return text;
}

// The runner's change report (model.changes of self_calibration_report.json) as a table.
std::string ModelChangesMarkdown(const json& c) {
  std::ostringstream md;
  md << "\nWhat the scan shows against the model: " << c.value("present", 0)
     << " buildings present, " << c.value("moved", 0) << " moved, " << c.value("missing", 0)
     << " missing, " << c.value("unobserved", 0) << " unobserved; "
     << c.value("not_in_model", json::array()).size() << " structures not in the model.\n\n";
  bool header = false;
  for (const json& b : c.value("buildings", json::array())) {
    const std::string state = b.value("state", std::string());
    if (state == "present") continue;
    if (!header) {
      md << "| building | centre in the model (mm) | state | moved by (mm) | yaw (deg) |\n"
         << "| --- | --- | --- | --- | --- |\n";
      header = true;
    }
    const json centre = b.value("centre_in_model_mm", json::array());
    md << "| " << b.value("building", -1) << " | "
       << (centre.size() >= 2
               ? Fixed(centre[0].get<double>(), 0) + ", " + Fixed(centre[1].get<double>(), 0)
               : std::string("?"))
       << " | " << state << " | "
       << (b.contains("moved_mm") ? Fixed(b["moved_mm"].get<double>(), 1) : std::string("-"))
       << " | "
       << (b.contains("moved_yaw_deg") ? Fixed(b["moved_yaw_deg"].get<double>(), 2)
                                       : std::string("-"))
       << " |\n";
  }
  for (const json& e : c.value("not_in_model", json::array())) {
    const json centre = e.value("centre_in_model_mm", json::array());
    const json size = e.value("size_mm", json::array());
    if (centre.size() < 2 || size.size() < 2) continue;
    md << "\nNot in the model: a structure at (" << Fixed(centre[0].get<double>(), 0) << ", "
       << Fixed(centre[1].get<double>(), 0) << ") mm, " << Fixed(size[0].get<double>(), 0) << " x "
       << Fixed(size[1].get<double>(), 0) << " mm, " << Fixed(e.value("height_mm", 0.0), 0)
       << " mm high.\n";
  }
  return md.str();
}

std::string StatsRow(const std::string& label, const ErrorStats& s) {
  if (s.count == 0) return "| " + label + " | 0 | - | - | - | - |\n";
  return "| " + label + " | " + std::to_string(s.count) + " | " + Fixed(s.rms_mm) + " | " +
         Fixed(s.p99_mm) + " | " + Fixed(s.max_mm) + " | " + Fixed(s.rms_px) + " |\n";
}

struct SummaryRow {
  std::string figure, value, target, verdict;
  bool timing = false;  // a figure that depends on the machine's load
};

// Every headline figure beside its target (the issues' acceptance numbers; "-" where a figure
// has none), pass or fail.
std::vector<SummaryRow> SummaryRows(const LabResult& r) {
  using Row = SummaryRow;
  std::vector<Row> rows;
  auto add = [&](const std::string& figure, double value, int digits, const std::string& unit,
                 double target, bool below, bool timing = false) {
    Row row{figure, Fixed(value, digits) + unit, "-", "-", timing};
    if (target > 0) {
      row.target = (below ? "< " : "> ") + Fixed(target, digits) + unit;
      row.verdict = (below ? value < target : value > target) ? "pass" : "**fail**";
    }
    rows.push_back(row);
  };
  // A figure from too few samples: its value is not shown as one.
  auto not_measured = [&](const std::string& figure, const std::string& target,
                          const std::string& why) {
    rows.push_back({figure, "not measured", target, why});
  };
  if (r.registration) {
    const RegistrationReport& reg = *r.registration;
    add("registration rms (site)", reg.site.all.rms_mm, 3, " mm", r.max_rms_mm, true);
    add("registration max (site)", reg.site.all.max_mm, 2, " mm", 0, true);
  }
  if (r.baseline_rms_mm) {
    add("baseline: factory intrinsics at the true pose, rms", *r.baseline_rms_mm, 3, " mm", 0,
        true);
  }
  if (r.self_calibration.contains("runner_report")) {
    const json& rr = r.self_calibration["runner_report"];
    add("modeled projection, whole site", rr.value("device_time_s", 0.0), 2, " s", 0, true);
    double per_projector = 0.0;
    if (rr.contains("projectors") && rr["projectors"].is_object()) {
      for (const auto& [id, p] : rr["projectors"].items()) {
        per_projector = std::max(per_projector, p.value("device_time_s", 0.0));
      }
      add("modeled projection per projector (most)", per_projector, 3, " s", 1.0, true);
      // The same stages timed on the devices (show, settle, capture and the steps' messages).
      double measured = 0.0;
      for (const auto& [id, p] : rr["projectors"].items()) {
        measured = std::max(measured, p.value("measured_device_time_s", 0.0));
      }
      if (measured > 0) {
        add("measured projection per projector (most)", measured, 3, " s", 1.5, true,
            /*timing=*/true);
      }
    }
    add("calibration round, wall time", rr.value("wall_s", 0.0), 1, " s", 0, true);
  }
  if (r.self_calibration.contains("per_unit") && r.self_calibration["per_unit"].is_object()) {
    // The cameras' timing (docs/devices.md, "Timing"): the worst flash latency, and the reads
    // thrown away as stale or repeated among all reads.
    double latency = -1.0;
    double kept = 0, stale = 0, repeated = 0;
    for (const auto& [id, u] : r.self_calibration["per_unit"].items()) {
      latency = std::max(latency, u.value("capture_latency_ms", -1.0));
      kept += u.value("captures", 0.0);
      stale += u.value("captures_stale", 0.0);
      repeated += u.value("captures_repeated", 0.0);
    }
    if (latency >= 0) {
      add("camera flash latency (worst unit)", latency, 1, " ms", 0, true, /*timing=*/true);
    }
    if (kept > 0) {
      add("captures read again, stale", 100.0 * stale / (kept + stale + repeated), 1, " %", 0,
          true);
      add("captures read again, repeated", 100.0 * repeated / (kept + stale + repeated), 1, " %", 0,
          true);
    }
  }
  if (r.render.contains("frame_ms_p50")) {
    const bool software =
        r.render.value("context", std::string()).find("llvmpipe") != std::string::npos;
    add(software ? "frame time p50 (llvmpipe)" : "frame time p50 (GPU)",
        r.render.value("frame_ms_p50", 0.0), 1, " ms", 16, true, /*timing=*/true);
    const double floor = r.render.value("floor_ms", 0.0);
    if (floor > 0) {
      add("frame time p50 / floor", r.render.value("frame_ms_p50", 0.0) / floor, 2, "x", 2, true,
          /*timing=*/true);
    }
  }
  if (r.render.contains("timeline_skew_ms_p99")) {
    add("timeline skew p99", r.render.value("timeline_skew_ms_p99", 0.0), 2, " ms", 0, true);
  }
  const json& p = r.photometric;
  if (p.contains("max_step_pct_per_5mm")) {
    const json& m = p["max_step_pct_per_5mm"];
    const std::string table_missing = StepNotMeasured(p, "table", r.min_step_pairs);
    const std::string walls_missing = StepNotMeasured(p, "walls", r.min_step_pairs);
    if (table_missing.empty()) {
      add("largest step per 5 mm, table", m.value("table", 0.0), 2, " %", 1.5, true);
    } else {
      not_measured("largest step per 5 mm, table", "< 1.50 %", table_missing);
    }
    if (walls_missing.empty()) {
      add("largest step per 5 mm, walls", m.value("walls", 0.0), 2, " %", 2, true);
    } else {
      not_measured("largest step per 5 mm, walls", "< 2.00 %", walls_missing);
    }
    if (p.contains("p99_step_pct_per_5mm")) {
      if (table_missing.empty()) {
        add("p99 step per 5 mm, table", p["p99_step_pct_per_5mm"].value("table", 0.0), 2, " %", 0,
            true);
      }
      if (walls_missing.empty()) {
        add("p99 step per 5 mm, walls", p["p99_step_pct_per_5mm"].value("walls", 0.0), 2, " %", 0,
            true);
      }
    }
    if (table_missing.empty()) {
      add("table uniformity min/max", p.value("uniformity_min_over_max", 0.0), 3, "", 0, true);
    } else {
      not_measured("table uniformity min/max", "-", table_missing);
    }
  }
  if (p.contains("black_step_pct")) {
    add("black level step, table", p.value("black_step_pct", 0.0), 1, " %", 0, true);
  }
  if (p.contains("gamma_error"))
    add("gamma error (largest)", p.value("gamma_error", 0.0), 3, "", 0, true);
  if (r.live.contains("reblend_ms_max")) {
    add("re-blend after a kill", r.live.value("reblend_ms_max", 0.0), 0, " ms", 100, true,
        /*timing=*/true);
  }
  if (r.live.contains("join_reblend_ms")) {
    add("re-blend after a join", r.live.value("join_reblend_ms", 0.0), 0, " ms", 0, true);
  }
  return rows;
}

// The machine's load in words, for timing figures ("load average 1.42 on 2 cores").
std::string LoadWords(const LabResult& r) {
  if (r.load_average < 0) return "load not known";
  return "load average " + Fixed(r.load_average, 2) + " on " + std::to_string(r.cores) +
         (r.cores == 1 ? " core" : " cores");
}

// The one-screen summary table.
std::string SummaryMarkdown(const LabResult& r) {
  const std::vector<SummaryRow> rows = SummaryRows(r);
  if (rows.empty()) return "";
  std::ostringstream md;
  md << "## Summary\n\n| figure | value | target | |\n| --- | --- | --- | --- |\n";
  bool timing = false;
  for (const SummaryRow& row : rows) {
    md << "| " << row.figure << (row.timing ? " *" : "") << " | " << row.value << " | "
       << row.target << " | " << row.verdict << " |\n";
    timing |= row.timing;
  }
  if (timing) {
    md << "\n\\* A timing: it depends on the machine and its load (" << LoadWords(r)
       << " at the end of the run).\n";
  }
  md << "\n";
  return md.str();
}

// The report's the title, the status and why it failed.
void HeaderMarkdown(const LabResult& r, std::ostringstream& md) {
  md << "# Site lab report: " << r.site_name << " / " << r.scene_label << "\n\n";
  md << "Status: **" << r.status << "**";
  if (!r.reasons.empty()) {
    md << ": " << r.reasons.size() << (r.reasons.size() == 1 ? " reason" : " reasons");
  }
  // Targets of the summary that were missed, named, whatever the status (the status fails only
  // on the verdict's reasons: docs/lab.md).
  int targets = 0;
  std::vector<std::string> missed;
  for (const SummaryRow& row : SummaryRows(r)) {
    if (row.target == "-") continue;
    ++targets;
    if (row.verdict == "**fail**" || row.value == "not measured") {
      missed.push_back(row.figure + (row.value == "not measured" ? " (not measured)" : ""));
    }
  }
  if (targets > 0) {
    md << "; " << missed.size() << " of " << targets << " targets missed";
    for (size_t i = 0; i < missed.size(); ++i) md << (i == 0 ? ": " : ", ") << missed[i];
  }
  md << ". Command:\n\n    " << r.command << "\n\n";
  if (!r.reasons.empty()) {
    md << "## Why it failed\n\n";
    for (const LabReason& reason : r.reasons) {
      md << "- **" << reason.what << "**: " << reason.detail << "\n";
    }
    md << "\n";
  }
  if (r.failure) {
    const LabFailure& f = *r.failure;
    md << "## Failure\n\n" << f.reason << " (phase: " << f.phase << ")\n\n";
    if (!f.child.empty()) {
      md << "Child `" << f.child << "` (" << f.role << ", pid " << f.pid << "): " << f.exit_text
         << ". Last lines of `" << f.log_path << "`:\n\n```\n";
      for (const std::string& line : f.log_tail) md << line << "\n";
      md << "```\n\n";
    }
  }
}

// The report's the summary, the site and the run time per phase.
void SiteMarkdown(const LabResult& r, std::ostringstream& md) {
  md << SummaryMarkdown(r);
  md << "## Site\n\n| site | units | scene | triangles | seed |\n| --- | --- | --- | --- | --- |\n"
     << "| " << r.site_name << " (`" << r.site_label << "`) | " << r.num_units << " | `"
     << r.scene_label << "` | " << r.scene_triangles << " | " << r.seed << " |\n\n";
  md << "## Run time per phase\n\n| phase | seconds |\n| --- | --- |\n";
  for (const auto& [name, seconds] : r.phase_seconds) {
    md << "| " << name << " | " << Fixed(seconds, 2) << " |\n";
  }
  md << "| total | " << Fixed(r.total_s, 2) << " |\n\n";
}

// The report's the registration error, and units that could not calibrate.
void RegistrationMarkdown(const LabResult& r, std::ostringstream& md) {
  if (r.registration) {
    const RegistrationReport& reg = *r.registration;
    md << "## Registration error (calibration source: `" << r.calibration_source << "`)\n\n"
       << "Measured against the world's truth (docs/lab.md): " << kDefinition << "\n\n"
       << reg.num_lit_points << " lit points of " << reg.num_candidates << " sampled ("
       << reg.num_table_points << " on the table, " << reg.num_building_points << " on buildings); "
       << reg.site.unmeasured << " (point, projector) pairs unmeasurable.\n\n"
       << (r.measured_with_true_placement
               ? "**The nodes found no placement of the model** (see the notes under "
                 "Self-calibration): these figures use the TRUE placement expressed in their "
                 "table frame, i.e. what the calibration gives once the model is placed.\n\n"
               : "")
       << "| scope | pairs | rms (mm) | p99 (mm) | max (mm) | rms (px) |\n"
       << "| --- | --- | --- | --- | --- | --- |\n";
    md << StatsRow("site", reg.site.all) << StatsRow("site: table", reg.site.table)
       << StatsRow("site: buildings", reg.site.buildings);
    for (const auto& [id, errors] : reg.per_unit) {
      const std::string unit = "unit " + std::to_string(id);
      md << StatsRow(unit, errors.all) << StatsRow(unit + ": table", errors.table)
         << StatsRow(unit + ": buildings", errors.buildings);
    }
    md << "\n";
    if (r.self_calibration.contains("runner_report")) {
      md << PredictionMarkdown(ComparePrediction(reg, r.self_calibration["runner_report"]));
    }
  }
  if (!r.unit_failures.empty()) {
    md << "## Units that could not calibrate\n\n| unit | cause |\n| --- | --- |\n";
    for (const auto& [id, why] : r.unit_failures) md << "| " << id << " | " << why << " |\n";
    md << "\n";
  }
}

// The report's the saved calibrations checked, and a live join.
void RestartAndJoinMarkdown(const LabResult& r, std::ostringstream& md) {
  if (r.self_calibration.contains("verification")) {
    md << "## Restart: the saved calibrations checked\n\n"
       << (r.self_calibration.value("round_ran", false)
               ? "A saved calibration did not hold: the site calibrated again.\n\n"
               : "Every saved calibration held: no calibration round.\n\n")
       << "| unit | holds | frames | projection (s) | dots found | p90 (px) | walls: median (px) | "
          "why not |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n";
    for (const auto& [id, v] : r.self_calibration["verification"].items()) {
      md << "| " << id << " | " << (v.value("holds", false) ? "yes" : "**no**") << " | "
         << v.value("frames", 0) << " | " << Fixed(v.value("device_time_s", 0.0), 3) << " | "
         << v.value("found", 0) << " of " << v.value("dots", 0) << " | "
         << Fixed(v.value("p90_px", 0.0), 3) << " | " << Fixed(v.value("wall_median_px", 0.0), 3)
         << " (" << v.value("wall_dots", 0) << ") | " << v.value("reason", std::string()) << " |\n";
    }
    md << "\n";
  }
  if (!r.enrollment.is_null()) {
    const json& e = r.enrollment;
    md << "## A unit with no key\n\n"
       << "Unit " << e.value("unit", 0) << " started with no site key (`--enroll`): it asked "
       << Fixed(e.value("asked_after_s", 0.0), 2) << " s after it started, the lab accepted it "
       << "as the operator at " << Fixed(e.value("accepted_after_s", 0.0), 2)
       << " s, and it was ready at "
       << (e.contains("ready_after_s") ? Fixed(e.value("ready_after_s", 0.0), 2) + " s"
                                       : std::string("**never**"))
       << " (fingerprint " << e.value("fingerprint", std::string()) << ").\n\n";
  }
  if (!r.join.is_null()) {
    const json& j = r.join;
    md << "## Live join\n\n"
       << "Unit " << j.value("unit", 0) << " started once the others held their calibration: "
       << (j.value("joined", false) ? "calibrated against them" : "**not calibrated**") << " in "
       << Fixed(j.value("wall_s", 0.0), 1) << " s of wall time; units recalibrated "
       << "meanwhile: "
       << (j.contains("others_recalibrated") && !j["others_recalibrated"].empty()
               ? j["others_recalibrated"].dump()
               : std::string("none"))
       << "; projectors given no new frame meanwhile (world's frame log): "
       << (j.contains("units_showing_the_same_frame") ? j["units_showing_the_same_frame"].dump()
                                                      : std::string("?"))
       << ".";
    if (j.contains("report")) {
      const json& jr = j["report"];
      md << " Its round: " << jr.value("site_frames", 0) << " frames ("
         << Fixed(jr.value("device_time_s", 0.0), 3) << " s of modeled projection), solve "
         << Fixed(jr.value("solve_compute_s", 0.0), 2) << " s.";
    }
    md << " Its registration error is in the unit rows above.\n\n";
  }
}

// The report's the runner's report of the round.
void SelfCalibrationMarkdown(const LabResult& r, std::ostringstream& md) {
  if (r.self_calibration.contains("runner_report")) {
    const json& rr = r.self_calibration["runner_report"];
    md << "## Self-calibration\n\n"
       << "Modeled projection time of the site: **" << Fixed(rr.value("device_time_s", 0.0), 3)
       << " s** (" << rr.value("site_frames", 0) << " frames x ("
       << Fixed(rr.value("frame_period_s", 0.0) * 1e3, 2) << " ms frame + "
       << Fixed(rr.value("capture_latency_s", 0.0) * 1e3, 1) << " ms capture latency)), "
       << rr.value("colours", 0) << " colours; slowest node's compute "
       << Fixed(r.self_calibration.value("compute_time_s", 0.0), 2) << " s (one core); "
       << Fixed(r.self_calibration.value("messages_per_node", 0.0), 0) << " messages and "
       << Fixed(r.self_calibration.value("bytes_per_node", 0.0) / 1024.0, 0) << " KiB per node.\n\n"
       << "Path: **" << rr.value("path", std::string("?")) << "** ("
       << rr.value("path_reason", std::string()) << ").\n\n";
    if (rr.contains("planarity") && rr["planarity"].is_object()) {
      md << "| unit | footprint planar | max height over its surface (mm) | surface rms (mm) | "
            "points over the threshold |\n| --- | --- | --- | --- | --- |\n";
      for (const auto& [id, p] : rr["planarity"].items()) {
        md << "| " << id << " | " << (p.value("planar", false) ? "yes" : "no") << " | "
           << Fixed(p.value("max_height_mm", 0.0), 2) << " | "
           << Fixed(p.value("surface_rms_mm", 0.0), 2) << " | "
           << p.value("points_over_threshold", 0) << " of " << p.value("points", 0) << " (over "
           << Fixed(p.value("threshold_mm", 0.0), 1) << " mm) |\n";
      }
      md << "\n";
    }
    md << "| projector | colour | cameras | frames | projection (s) | Gray bits skipped | phase "
          "steps x period (px) | compute (s) |\n| --- | --- | --- | --- | --- | --- | --- | --- "
          "|\n";
    if (rr.contains("projectors") && rr["projectors"].is_object()) {
      for (const auto& [id, p] : rr["projectors"].items()) {
        std::string cameras;
        if (p.contains("cameras")) {
          for (const auto& c : p["cameras"]) cameras += (cameras.empty() ? "" : " ") + c.dump();
        }
        md << "| " << id << " | " << p.value("colour", 0) << " | " << cameras << " | "
           << p.value("frames", 0) << " | " << Fixed(p.value("device_time_s", 0.0), 3) << " | "
           << p.value("gray_lsb_skip", 0) << " | " << p.value("phase_steps", 0) << " x "
           << Fixed(p.value("phase_period_px", 0.0), 0) << " | "
           << Fixed(p.value("compute_s", 0.0), 2) << " |\n";
      }
    }
    if (rr.contains("bundle")) {
      const json& b = rr["bundle"];
      md << "\nJoint refinement (Ceres): " << b.value("termination", std::string()) << ", "
         << b.value("iterations", 0) << " iterations, " << b.value("tracks", 0) << " tracks, rms "
         << Fixed(b.value("initial_rms_px", 0.0), 3) << " -> "
         << Fixed(b.value("final_rms_px", 0.0), 3) << " px.\n\n"
         << "| unit | projector rms (px) | camera rms (px) | free parameters |\n"
         << "| --- | --- | --- | --- |\n";
      if (b.contains("units")) {
        for (const auto& [id, u] : b["units"].items()) {
          std::string free;
          for (const auto& f : u["free_parameters"]) {
            free += (free.empty() ? "" : ", ") + f.get<std::string>();
          }
          md << "| " << id << " | " << Fixed(u.value("projector_rms_px", 0.0), 3) << " | "
             << Fixed(u.value("camera_rms_px", 0.0), 3) << " | " << free << " |\n";
        }
      }
    }
    if (rr.contains("table")) {
      const json& t = rr["table"];
      md << "\nTable plane: " << t.value("points", 0) << " points, rms "
         << Fixed(t.value("plane_rms_mm", 0.0), 3) << " mm; highest point "
         << Fixed(t.value("max_height_mm", 0.0), 1) << " mm"
         << (t.value("planar", false) ? " (planar site)" : "") << ".\n";
    }
    if (rr.contains("model")) {
      const json& m = rr["model"];
      if (m.value("found", false)) {
        md << "\nModel found on the scanned surface: rms " << Fixed(m.value("rms_mm", 0.0), 3)
           << " mm over " << m.value("inliers", 0) << " of " << m.value("points", 0)
           << " points; scale of the scan " << Fixed(m.value("scale", 1.0), 5);
        if (m.value("relief_scale", 1.0) != 1.0) {
          md << " in plan, its heights " << Fixed(m.value("relief_scale", 1.0), 5) << " times that";
        }
        md << ".";
        if (r.model_offset_measured) {
          md << " Placement against the truth: **" << Fixed(r.model_offset_mm, 3) << " mm, "
             << Fixed(r.model_offset_deg, 4) << " deg**.";
        }
        md << "\n";
        if (m.contains("changes")) md << ModelChangesMarkdown(m["changes"]);
      } else {
        md << "\nThe model was not found on the scanned surface.\n";
      }
    }
    if (rr.contains("notes") && !rr["notes"].empty()) {
      md << "\nNotes:\n\n";
      for (const auto& n : rr["notes"]) md << "- " << n.get<std::string>() << "\n";
    }
    md << "\n";
  }
}

// The report's the files collected from the nodes and the pictures.
void UnitsMarkdown(const LabResult& r, std::ostringstream& md) {
  if (!r.units.empty()) {
    md << "## Calibration files collected from the nodes\n\n| unit | source | JSON | OpenCV YAML "
          "|\n"
       << "| --- | --- | --- | --- |\n";
    for (const auto& [id, unit] : r.units) {
      md << "| " << id << " | `" << unit.source << "` | `" << unit.json_path << "` | `"
         << unit.yaml_path << "` |\n";
    }
    md << "\n";
    const json& sc = r.self_calibration;
    if (sc.contains("mpcdi")) {
      const json& m = sc["mpcdi"];
      md << "MPCDI export (profile `sl`, read back by the lab): `" << m.value("path", std::string())
         << "`";
      if (m.contains("error")) {
        md << ": **does not read back**: " << m.value("error", std::string()) << "\n\n";
      } else {
        md << ", regions:";
        for (const json& region : m.value("regions", json::array())) {
          md << " `" << region.value("id", std::string()) << "` ("
             << region.value("warp_samples_on_surface", 0) << " of "
             << region.value("warp_samples", 0) << " warp samples on the surface)";
        }
        md << ".\n\n";
      }
    }
  }
  if (!r.top_white_png.empty()) {
    md << "## The world, every projector white (top view)\n\n![top view, all white]("
       << r.top_white_png
       << ")\n*The world seen from above (orthographic) with every projector white and no "
          "blend: the footprints and their overlaps.*\n\n";
  }
  if (!r.heatmap_png.empty()) {
    md << "## Registration error seen from above\n\n![registration error](" << r.heatmap_png
       << ")\n\n*Worst projector per point, 0 (dark) to " << Fixed(r.heatmap_scale_mm, 2)
       << " mm (yellow, the site's p99); grey: lit by nobody.*\n\n";
  }
}

// The report's the faults of a chaos run.
void ChaosMarkdown(const LabResult& r, std::ostringstream& md) {
  if (!r.chaos.is_null()) {
    const json& c = r.chaos;
    md << "## Chaos (docs/lab.md)\n\nFaults injected during the hold, seed "
       << r.metric_options.seed << ". Processes crashed: **" << c.value("processes_crashed", 0)
       << "**";
    if (c.contains("annotations")) {
      const json& a = c["annotations"];
      md << "; annotations acknowledged " << a.value("points_acknowledged", 0) << ", present "
         << a.value("points_present", 0) << ", lost **" << a.value("points_lost", 0) << "**";
      if (!a.value("verify_error", std::string()).empty()) {
        md << " (not verified: " << a.value("verify_error", std::string()) << ")";
      }
    }
    md << ".\n\n| fault | at (s into the hold) | detected (ms) | recovered (ms) | frames lost "
          "on the others (max per node) | note |\n| --- | --- | --- | --- | --- | --- |\n";
    const json faults = c.value("faults", json::array());
    for (const json& f : faults) {
      auto ms = [&](const char* key) {
        return f.contains(key) && f[key].is_number() ? Fixed(f[key].get<double>(), 0) : "-";
      };
      md << "| " << f.value("fault", std::string()) << " | " << Fixed(f.value("at_s", 0.0), 1)
         << " | " << ms("detected_ms") << " | " << ms("recovered_ms") << " | "
         << (f.contains("frames_lost_max") ? std::to_string(f["frames_lost_max"].get<int>()) : "-")
         << " | " << f.value("note", std::string()) << " |\n";
    }
    md << "\n";
  }
}

// The report's the children.
void ProcessesMarkdown(const LabResult& r, std::ostringstream& md) {
  md << "## Processes\n\n| name | role | pid | exit | CPU (s) | peak memory (MiB) |\n"
        "| --- | --- | --- | --- | --- | --- |\n";
  for (const LabProcess& p : r.processes) {
    md << "| " << p.name << " | " << p.role << " | " << p.pid << " | " << p.exit_text << " | "
       << Fixed(p.cpu_s, 2) << " | " << Fixed(p.max_rss_mb, 0) << " |\n";
  }
  md << "\nLogs: `logs/<name>.log`.";
  if (r.bad_report_lines > 0) {
    md << " " << r.bad_report_lines << " line(s) the children printed looked like report lines "
       << "and did not parse (cluster/report_lines.h); the last: " << r.last_bad_report_line << ".";
  }
  md << "\n";
}

// The report's the show.
void RenderMarkdown(const LabResult& r, std::ostringstream& md) {
  if (!r.render.empty()) {
    const json& rd = r.render;
    md << "## The show (docs/render.md)\n\n";
    if (rd.contains("frame_ms_p50")) {
      md << "Frame time per node (1280x800 unless the site says otherwise; all nodes share this "
            "machine's cores with the world): p50 "
         << Fixed(rd.value("frame_ms_p50", 0.0), 1) << " ms (median of the nodes), p99 "
         << Fixed(rd.value("frame_ms_p99", 0.0), 1)
         << " ms (worst node); each node's first frame, which compiles its shaders and fills "
            "its surface cache, apart: at most "
         << Fixed(rd.value("first_frame_ms_max", 0.0), 1)
         << " ms; the floor (one full-screen textured pass) " << Fixed(rd.value("floor_ms", 0.0), 1)
         << " ms; " << rd.value("context", std::string()) << ".\n\n";
    }
    if (rd.contains("timeline_skew") && rd["timeline_skew"].contains("p99_ms")) {
      const json& k = rd["timeline_skew"];
      md << "Timeline skew between nodes (media time at the same instant): p50 "
         << Fixed(k.value("p50_ms", 0.0), 3) << " ms, p99 " << Fixed(k.value("p99_ms", 0.0), 3)
         << " ms, max " << Fixed(k.value("max_ms", 0.0), 3) << " ms over " << k.value("instants", 0)
         << " instants.\n\n";
    }
    if (rd.contains("grid") && rd["grid"].contains("rms_mm")) {
      const json& g = rd["grid"];
      md << "Table grid seen from above, lines of overlapping projectors against each other: rms "
         << Fixed(g.value("rms_mm", 0.0), 2) << " mm, p99 " << Fixed(g.value("p99_mm", 0.0), 2)
         << " mm, max " << Fixed(g.value("max_mm", 0.0), 2) << " mm over " << g.value("patches", 0)
         << " patches.\n\n";
    }
    if (rd.contains("grid_top_png")) {
      md << "![table grid from above](" << rd["grid_top_png"].get<std::string>()
         << ")\n*The table grid every unit draws, seen from above through the world "
            "(orthographic, the whole table): where two projectors' lines do not coincide they "
            "show doubled.*\n\n";
    }
    if (rd.contains("unit_grid_top_png") && rd["unit_grid_top_png"].is_object()) {
      md << "Each projector's output alone, seen from above (its table grid):\n\n";
      for (const auto& [id, png] : rd["unit_grid_top_png"].items()) {
        if (png.is_string()) {
          md << "![unit " << id << " alone](" << png.get<std::string>() << ")\n*unit " << id
             << "*\n\n";
        }
      }
    }
    if (rd.contains("show_top_png")) {
      md << "![the show from above](" << rd["show_top_png"].get<std::string>()
         << ")\n*The show seen from above through the world: every projector's output with the "
            "model's colours and cast shadows.*\n\n";
    }
  }
}

// The report's the projectors' response.
void ResponseMarkdown(const LabResult& r, std::ostringstream& md) {
  if (!r.photometric.empty() && r.photometric.contains("response")) {
    const json& p = r.photometric;
    md << "## Projector response (docs/calibration.md, \"Response\")\n\n"
       << "Each projector's gamma and black level as its own camera measured them in the "
          "pre-pass (grey levels, then the light cut), against the world's truth. The renderer "
          "encodes with the measured gamma.\n\n"
       << "| unit | gamma | true | black level | true |\n| --- | --- | --- | --- | --- |\n";
    for (const auto& [id, u] : p["response"].items()) {
      md << "| " << id << " | " << Fixed(u.value("gamma", 0.0), 3) << " | "
         << Fixed(u.value("true_gamma", 0.0), 3) << " | "
         << (u.contains("black_level") ? Fixed(u.value("black_level", 0.0) * 100.0, 3) + " %"
                                       : std::string("not measured"))
         << " | " << Fixed(u.value("true_black_level", 0.0) * 100.0, 3) << " % |\n";
    }
    md << "\nLargest gamma error " << Fixed(p.value("gamma_error", 0.0), 3)
       << "; largest black level error " << Fixed(p.value("black_level_error", 0.0) * 100.0, 4)
       << " % of peak.\n\n";
  }
}

// The report's the blend's steps and uniformity, and the re-blend after a kill.
void BlendMarkdown(const LabResult& r, std::ostringstream& md) {
  if (!r.photometric.empty() && r.photometric.contains("table")) {
    const json& p = r.photometric;
    auto steps = [&](const char* key) {
      if (!p.contains(key)) return std::string("-");
      const json& k = p[key];
      return Fixed(k.value("max_pct", 0.0), 2) + " | " + Fixed(k.value("p99_pct", 0.0), 2) + " | " +
             std::to_string(k.value("pairs", 0)) + " | " +
             std::to_string(k.value("pairs_straddled", 0));
    };
    md << "## The blend (docs/blend.md)\n\n"
       << "Every node showing white through the full pipeline (its blend mask times the "
          "intensity correction), luminance from the world's truth. Step: the relative "
          "luminance change between two samples 5 mm apart on one surface, both lit; samples in a "
          "projector pixel that straddles two surfaces are left out (counted).\n\n"
       << "| surface | max step % | p99 step % | pairs | pairs straddled |\n"
       << "| --- | --- | --- | --- | --- |\n"
       << "| table, raw white (no blend) | " << steps("table_unblended") << " |\n"
       << "| table | " << steps("table") << " |\n"
       << "| roofs (from above) | " << steps("roofs_from_above") << " |\n"
       << "| roofs (lattice) | " << steps("roofs") << " |\n"
       << "| walls (lattice) | " << steps("walls") << " |\n"
       << "| table, every projector black | " << steps("black") << " |\n\n"
       << "The black row: every projector showing black through the full pipeline; where "
          "footprints overlap their black levels add up over the site's ambient light "
          "(`photometric.black_step_pct`), "
       << (p.value("black_match", false)
               ? "matched: each node raises its black where fewer projectors overlap "
                 "(`--black-match on`).\n\n"
               : "not matched (`--black-match off`).\n\n")
       << (p["table"].contains("over_bound")
               ? [&] {
                   const json& o = p["table"]["over_bound"];
                   return "Where the table's " + std::to_string(o.value("pairs", 0)) +
                          " pairs over " + Fixed(o.value("bound_pct", 0.0), 1) +
                          " % lie: " + std::to_string(o.value("two_edges", 0)) +
                          " near the edges of two projectors' light (where two edges meet every "
                          "alpha must go from 0 to 1 within a pixel or two), " +
                          std::to_string(o.value("one_edge", 0)) + " near one projector's edge, " +
                          std::to_string(o.value("interior", 0)) +
                          " away from every edge (largest " +
                          Fixed(o.value("interior_max_pct", 0.0), 2) + " %)" +
                          (o.value("pairs_capped", false) ? " (the largest " +
                                                                std::to_string(o.value("pairs", 0)) +
                                                                " only)"
                                                          : std::string()) +
                          ".\n\n";
                 }()
               : std::string())
       << "Table uniformity (min / max): " << Fixed(p.value("uniformity_min_over_max", 0.0), 3)
       << " blended, " << Fixed(p.value("uniformity_unblended", 0.0), 3)
       << " raw white. Level: " << Fixed(p.value("level_per_m2", 0.0), 4)
       << " / m^2 (cd/m^2 per nit at 1 m); cast per node at most "
       << Fixed(p.value("blend_cast_ms_max", 0.0), 0) << " ms; bytes per node at most "
       << Fixed(p.value("bytes_per_node_max", 0.0), 0) << ".\n\n";
    if (p.contains("pictures")) {
      const json& pic = p["pictures"];
      if (pic.contains("before")) {
        md << "![raw white from above](" << pic["before"].get<std::string>()
           << ")\n*Raw white: every projector at full white, seen from above (brighter where "
              "footprints overlap).*\n\n";
      }
      if (pic.contains("after")) {
        md << "![blended white from above](" << pic["after"].get<std::string>()
           << ")\n*White through the full pipeline (blend masks, intensity correction), seen "
              "from above.*\n\n";
      }
      if (pic.contains("steps_over_1pct")) {
        md << "![where the step exceeds 1 %](" << pic["steps_over_1pct"].get<std::string>()
           << ")\n*From above: the blended white dimmed, in red where its luminance changes by "
              "more than 1 % between samples 5 mm apart, each projector's true footprint "
              "outlined; legend and scale bar below the view.*\n\n";
      }
      if (pic.contains("alpha")) {
        md << "\nAlpha masks, each in its own projector's pixels (white: 1, the unit gives full "
              "light; black: 0, a neighbour lights that part):\n\n";
        for (const auto& [id, path] : pic["alpha"].items()) {
          md << "![alpha of unit " << id << "](" << path.get<std::string>() << ")\n";
        }
      }
      md << "\n";
    }
  }
  if (!r.live.empty() && r.live.contains("reblend_ms_max")) {
    md << "Re-blend after the kill (SIGKILL to the neighbours' first mask without it, shown): "
       << Fixed(r.live.value("reblend_ms_max", 0.0), 1) << " ms at most.\n\n";
    // Where each neighbour's time went (docs/blend.md, "Results and limits").
    const json reblends = r.live.value("reblend", json::object());
    if (!reblends.empty()) {
      md << "| neighbour | noticed (ms) | by | mask | mask in (ms) | frame (ms) | read back (ms) | "
            "world's show (ms) | first re-blended frame (ms) | compose (ms) |\n"
         << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
      for (const auto& [id, n] : reblends.items()) {
        const json frame = n.value("frame", json::object());
        const bool prepared = frame.value("prepared", false);
        md << "| " << id << " | " << Fixed(n.value("detected_ms", 0.0), 1) << " | "
           << n.value("noticed_by", std::string("?")) << " | "
           << (prepared ? "prepared" : "composed") << " | "
           << Fixed(frame.value("set_mask_ms", 0.0), 2) << " | "
           << Fixed(frame.value("render_ms", 0.0), 1)
           << (frame.value("rewarped", false) ? " (rewarp)" : "") << " | "
           << Fixed(frame.value("read_ms", 0.0), 1) << " | "
           << Fixed(frame.value("show_ms", 0.0), 1) << " | " << Fixed(n.value("shown_ms", 0.0), 1)
           << " | " << Fixed(n.value("compose_ms", 0.0), 1) << (prepared ? " (after)" : "")
           << " |\n";
      }
      md << "\n*prepared*: the mask for this neighbour's leaving was made ahead of time and "
            "swapped "
            "in; the composition ran after the frame, off the path. *composed*: composed and "
            "uploaded once the kill was noticed. *by*: the dead node's connection closing (its "
            "memory unmapped first), its silence, or the member list dropping it.\n\n";
    }
  }
}

}  // namespace

std::string LabReportMarkdown(const LabResult& r) {
  std::ostringstream md;
  HeaderMarkdown(r, md);
  SiteMarkdown(r, md);
  RegistrationMarkdown(r, md);
  RestartAndJoinMarkdown(r, md);
  SelfCalibrationMarkdown(r, md);
  UnitsMarkdown(r, md);
  ChaosMarkdown(r, md);
  ProcessesMarkdown(r, md);
  RenderMarkdown(r, md);
  ResponseMarkdown(r, md);
  BlendMarkdown(r, md);
  return md.str();
}

}  // namespace sandtable::sim
