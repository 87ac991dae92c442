#include "sim/lab/lab_report.h"

#include <cstdio>
#include <filesystem>
#include <sstream>

#include "common/base/file_io.h"
#include "common/io/json_reader.h"
#include "sim/lab/child_process.h"

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

std::string Fixed(double value, int digits = 3) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", digits, value);
  return text;
}

std::string StatsRow(const std::string& label, const ErrorStats& s) {
  if (s.count == 0) return "| " + label + " | 0 | - | - | - | - |\n";
  return "| " + label + " | " + std::to_string(s.count) + " | " + Fixed(s.rms_mm) + " | " +
         Fixed(s.p99_mm) + " | " + Fixed(s.max_mm) + " | " + Fixed(s.rms_px) + " |\n";
}

constexpr char kDefinition[] =
    "points X sampled area-weighted on every lit surface where the model truly stands; per "
    "projector that truly lights X at incidence under max_incidence_deg: u_hat = X projected "
    "with the unit's exported calibration (projector intrinsics, table_from_projector, "
    "table_from_model); the TRUE ray of the projector through u_hat meets the plane of X's "
    "triangle at X'; error |X' - X| (mm) and |u_hat - u_true| (projector px). Table faces: "
    "all vertices within 0.1 mm of z = 0 and normal z > 0.999; every other face is building.";

}  // namespace

json LabReportJson(const LabResult& r) {
  json out = {{"format", "sandtable.lab_report"},
              {"version", 1},
              {"status", r.status},
              {"command", r.command},
              {"seed", r.seed},
              {"total_s", r.total_s}};
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
    processes.push_back(
        {{"name", p.name}, {"pid", p.pid}, {"role", p.role}, {"exit", p.exit_text}});
  }
  out["processes"] = processes;
  json calibration = {{"source", r.calibration_source}};
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
    calibration["metric"] = {{"candidates", reg.num_candidates},
                             {"lit_points", reg.num_lit_points},
                             {"table_points", reg.num_table_points},
                             {"building_points", reg.num_building_points},
                             {"seed", r.metric_options.seed},
                             {"max_incidence_deg", r.metric_options.max_incidence_deg},
                             {"definition", kDefinition}};
  }
  out["calibration"] = calibration;
  out["images"] = {{"top_white", r.top_white_png},
                   {"registration_error", r.heatmap_png},
                   {"registration_error_scale_mm", r.heatmap_scale_mm}};
  if (r.failure) {
    const LabFailure& f = *r.failure;
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
    out["failure"] = failure;
  }
  return out;
}

std::string LabReportMarkdown(const LabResult& r) {
  std::ostringstream md;
  md << "# Site lab report: " << r.site_name << " / " << r.scene_label << "\n\n";
  md << "Status: **" << r.status << "**. Command:\n\n    " << r.command << "\n\n";
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
  md << "## Site\n\n| site | units | scene | triangles | seed |\n| --- | --- | --- | --- | --- |\n"
     << "| " << r.site_name << " (`" << r.site_label << "`) | " << r.num_units << " | `"
     << r.scene_label << "` | " << r.scene_triangles << " | " << r.seed << " |\n\n";
  md << "## Run time per phase\n\n| phase | seconds |\n| --- | --- |\n";
  for (const auto& [name, seconds] : r.phase_seconds) {
    md << "| " << name << " | " << Fixed(seconds, 2) << " |\n";
  }
  md << "| total | " << Fixed(r.total_s, 2) << " |\n\n";
  if (r.registration) {
    const RegistrationReport& reg = *r.registration;
    md << "## Registration error (calibration source: `" << r.calibration_source << "`)\n\n"
       << "Measured against the world's truth (docs/lab.md): " << kDefinition << "\n\n"
       << reg.num_lit_points << " lit points of " << reg.num_candidates << " sampled ("
       << reg.num_table_points << " on the table, " << reg.num_building_points << " on buildings); "
       << reg.site.unmeasured << " (point, projector) pairs unmeasurable.\n\n"
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
  }
  if (!r.units.empty()) {
    md << "## Calibration files collected from the nodes\n\n| unit | source | JSON | OpenCV YAML "
          "|\n"
       << "| --- | --- | --- | --- |\n";
    for (const auto& [id, unit] : r.units) {
      md << "| " << id << " | `" << unit.source << "` | `" << unit.json_path << "` | `"
         << unit.yaml_path << "` |\n";
    }
    md << "\n";
  }
  if (!r.top_white_png.empty()) {
    md << "## The world, every projector white (top view)\n\n![top view, all white]("
       << r.top_white_png << ")\n\n";
  }
  if (!r.heatmap_png.empty()) {
    md << "## Registration error seen from above\n\n![registration error](" << r.heatmap_png
       << ")\n\n*Worst projector per point, 0 (dark) to " << Fixed(r.heatmap_scale_mm, 2)
       << " mm (yellow, the site's p99); grey: lit by nobody.*\n\n";
  }
  md << "## Processes\n\n| name | role | pid | exit |\n| --- | --- | --- | --- |\n";
  for (const LabProcess& p : r.processes) {
    md << "| " << p.name << " | " << p.role << " | " << p.pid << " | " << p.exit_text << " |\n";
  }
  md << "\nLogs: `logs/<name>.log`.\n";
  return md.str();
}

Status WriteLabReport(const LabResult& result, const std::string& out_dir) {
  const std::filesystem::path dir(out_dir);
  ST_RETURN_IF_ERROR(io::WriteJsonFile(LabReportJson(result), (dir / "report.json").string()));
  return WriteFileAtomically(dir / "report.md", LabReportMarkdown(result));
}

}  // namespace sandtable::sim
