#include "sim/lab/lab_report.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "common/base/file_io.h"
#include "common/io/json_reader.h"
#include "sim/lab/child_process.h"
#include "sim/lab/lab_html.h"
#include "sim/lab/lab_prediction.h"
#include "sim/lab/lab_verdict.h"

namespace sandtable::sim {

namespace {

using nlohmann::json;

json StatsJson(const ErrorStats& s) {
  return {{"count", s.count},     {"rms_mm", s.rms_mm}, {"p99_mm", s.p99_mm}, {"max_mm", s.max_mm},
          {"mean_mm", s.mean_mm}, {"rms_px", s.rms_px}, {"p99_px", s.p99_px}, {"max_px", s.max_px}};
}

// The errors of one scope: the pooled numbers at top level, table and buildings beside them.
json ErrorsJson(const RegistrationErrors& e) {
  json out = StatsJson(e.all);
  out["unmeasured"] = e.unmeasured;
  out["table"] = StatsJson(e.table);
  out["buildings"] = StatsJson(e.buildings);
  return out;
}

// report.json's "calibration": the measured registration per site and unit, the
// self-calibration's own figures, and the lab's join, kill, stall and enrollment checks.
json CalibrationJson(const LabResult& r) {
  json calibration = {{"source", r.calibration_source}};
  if (r.measured_with_true_placement) calibration["placement"] = "true (the nodes found none)";
  if (r.registration) {
    const RegistrationReport& reg = *r.registration;
    calibration.update(ErrorsJson(reg.site));
    json per_unit = json::object();
    for (const auto& [id, errors] : reg.per_unit) {
      json unit = ErrorsJson(errors);
      if (auto it = r.units.find(id); it != r.units.end()) {
        unit["source"] = it->second.source;
        unit["json"] = it->second.json_path;
        unit["yaml"] = it->second.yaml_path;
      }
      per_unit[std::to_string(id)] = unit;
    }
    calibration["per_unit"] = per_unit;
    if (r.self_calibration.contains("runner_report")) {
      calibration["prediction"] =
          PredictionJson(ComparePrediction(reg, r.self_calibration["runner_report"]));
    }
    calibration["metric"] = {{"candidates", reg.num_candidates},
                             {"lit_points", reg.num_lit_points},
                             {"table_points", reg.num_table_points},
                             {"building_points", reg.num_building_points},
                             {"seed", r.metric_options.seed},
                             {"max_incidence_deg", r.metric_options.max_incidence_deg},
                             {"definition", kRegistrationMetricDefinition}};
  }
  // Self-calibration figures (docs/calibration.md).
  const json& sc = r.self_calibration;
  if (sc.contains("runner_report")) {
    const json& rr = sc["runner_report"];
    calibration["device_time_s"] = rr.value("device_time_s", 0.0);
    calibration["frame_period_s"] = rr.value("frame_period_s", 0.0);
    calibration["capture_latency_s"] = rr.value("capture_latency_s", 0.0);
    calibration["site_frames"] = rr.value("site_frames", 0);
    calibration["colours"] = rr.value("colours", 0);
    calibration["path"] = rr.value("path", std::string());
    calibration["path_reason"] = rr.value("path_reason", std::string());
    if (rr.contains("planarity")) calibration["planarity"] = rr["planarity"];
    json frames = json::object(), time = json::object();
    if (rr.contains("projectors") && rr["projectors"].is_object()) {
      for (const auto& [id, p] : rr["projectors"].items()) {
        frames[id] = p.value("frames", 0);
        time[id] = p.value("device_time_s", 0.0);
      }
    }
    calibration["frames_per_projector"] = frames;
    calibration["device_time_per_projector_s"] = time;
    if (rr.contains("bundle")) calibration["refinement"] = rr["bundle"];
    if (rr.contains("table")) calibration["table_plane"] = rr["table"];
    calibration["self_calibration_report"] = rr;
  }
  if (sc.contains("mpcdi")) calibration["mpcdi"] = sc["mpcdi"];
  if (!r.join.is_null()) calibration["join"] = r.join;
  if (!r.kill.is_null()) calibration["kill"] = r.kill;
  if (!r.stall.is_null()) calibration["stall"] = r.stall;
  if (!r.enrollment.is_null()) calibration["enrollment"] = r.enrollment;
  if (sc.contains("verification")) calibration["verification"] = sc["verification"];
  if (sc.contains("round_ran")) calibration["round_ran"] = sc["round_ran"];
  if (sc.contains("compute_time_s")) {
    calibration["compute_time_s"] = sc["compute_time_s"];
    calibration["messages_per_node"] = sc.value("messages_per_node", 0.0);
    calibration["bytes_per_node"] = sc.value("bytes_per_node", 0.0);
    if (calibration.contains("per_unit") && sc.contains("per_unit")) {
      for (const auto& [id, u] : sc["per_unit"].items()) {
        if (calibration["per_unit"].contains(id)) calibration["per_unit"][id].update(u);
      }
    }
  }
  if (!r.unit_failures.empty()) {
    json failures = json::object();
    for (const auto& [id, why] : r.unit_failures) failures[std::to_string(id)] = why;
    calibration["failures"] = failures;
  }
  return calibration;
}

// Why and where the run stopped, with the child that stopped it when one did.
json FailureJson(const LabFailure& f) {
  json failure = {{"phase", f.phase}, {"reason", f.reason}};
  if (!f.child.empty()) {
    failure["child"] = f.child;
    failure["role"] = f.role;
    failure["pid"] = f.pid;
    failure["exit"] = f.exit_text;
    failure["exit_code"] = f.exit_code ? json(*f.exit_code) : json(nullptr);
    failure["signal"] = f.signal ? json(*f.signal) : json(nullptr);
    failure["signal_name"] = f.signal ? json(SignalName(*f.signal)) : json(nullptr);
    failure["log"] = f.log_path;
    failure["log_tail"] = f.log_tail;
  }
  return failure;
}

// (The markdown helpers are in lab_report_markdown.cc.)
}  // namespace

json LabReportJson(const LabResult& r) {
  json out = {{"format", "sandtable.lab_report"},
              {"version", 1},
              {"status", r.status},
              {"command", r.command},
              {"seed", r.seed},
              {"noise_seed", r.noise_seed},
              {"total_s", r.total_s},
              {"machine", {{"load_average", r.load_average}, {"cores", r.cores}}}};
  json reasons = json::array();
  for (const LabReason& reason : r.reasons) {
    reasons.push_back({{"what", reason.what}, {"detail", reason.detail}});
  }
  out["reasons"] = reasons;
  out["max_rms_mm"] = r.max_rms_mm;
  json phases = json::array();
  for (const auto& [name, seconds] : r.phase_seconds) {
    phases.push_back({{"name", name}, {"seconds", seconds}});
  }
  out["phases"] = phases;
  out["site"] = {{"name", r.site_name},
                 {"label", r.site_label},
                 {"units", r.num_units},
                 {"file", r.site_path}};
  out["scene"] = {
      {"label", r.scene_label}, {"file", r.scene_path}, {"triangles", r.scene_triangles}};
  json processes = json::array();
  for (const LabProcess& p : r.processes) {
    processes.push_back({{"name", p.name},
                         {"pid", p.pid},
                         {"role", p.role},
                         {"exit", p.exit_text},
                         {"cpu_s", p.cpu_s},
                         {"max_rss_mb", p.max_rss_mb}});
  }
  out["processes"] = processes;
  out["report_lines"] = {{"parsed", r.report_lines}, {"bad", r.bad_report_lines}};
  if (r.bad_report_lines > 0) out["report_lines"]["last_bad"] = r.last_bad_report_line;
  out["calibration"] = CalibrationJson(r);
  const json& sc = r.self_calibration;
  if (!r.render.empty()) out["render"] = r.render;
  if (!r.photometric.empty()) out["photometric"] = r.photometric;
  if (!r.live.empty()) out["live"] = r.live;
  if (!r.chaos.is_null()) out["chaos"] = r.chaos;
  if (r.model_offset_measured || sc.contains("runner_report")) {
    json registration = json::object();
    if (r.model_offset_measured) {
      registration["model_offset_mm"] = r.model_offset_mm;
      registration["model_offset_deg"] = r.model_offset_deg;
    }
    if (sc.contains("runner_report") && sc["runner_report"].contains("model")) {
      registration["model"] = sc["runner_report"]["model"];
      if (registration["model"].contains("changes")) {
        registration["changes"] = registration["model"]["changes"];
      }
    }
    out["registration"] = registration;
  }
  if (r.baseline_rms_mm) {
    out["registration_baseline"] = {
        {"what", "factory intrinsics at the true pose, the model at its true placement"},
        {"rms_mm", *r.baseline_rms_mm},
        {"p99_mm", r.baseline_p99_mm.value_or(0.0)}};
  }
  if (!r.console_url.empty()) out["console"] = r.console_url;
  out["images"] = {{"top_white", r.top_white_png},
                   {"registration_error", r.heatmap_png},
                   {"registration_error_scale_mm", r.heatmap_scale_mm}};
  if (r.failure) out["failure"] = FailureJson(*r.failure);
  return out;
}

Status WriteLabReport(const LabResult& result, const std::string& out_dir) {
  const std::filesystem::path dir(out_dir);
  ST_RETURN_IF_ERROR(io::WriteJsonFile(LabReportJson(result), (dir / "report.json").string()));
  const std::string markdown = LabReportMarkdown(result);
  ST_RETURN_IF_ERROR(WriteFileAtomically(dir / "report.md", markdown));
  Expected<std::string> html = MarkdownToHtmlPage(
      markdown, dir.string(), "Site lab report: " + result.site_name + " / " + result.scene_label);
  if (!html.ok()) return html.status();
  return WriteFileAtomically(dir / "report.html", *html);
}

}  // namespace sandtable::sim
