#include "sim/lab/lab_scale.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "sim/lab/lab_html.h"
#include "sim/lab/lab_sweep.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string F(double v, int digits) { return FixedDigits(v, digits); }

double Number(const json& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>()
                                               : std::numeric_limits<double>::quiet_NaN();
}

std::string PlotScript(const fs::path& dir, const std::string& png, const std::string& title,
                       const std::string& ylabel, const std::string& data,
                       const std::vector<std::pair<int, std::string>>& columns, bool log_y) {
  std::ostringstream s;
  s << "set terminal png size 1000,640\n"
    << "set output '" << (dir / (png + ".png")).string() << "'\n"
    << "set title '" << title << "'\nset xlabel 'nodes (grid-N)'\nset ylabel '" << ylabel
    << "'\nset logscale x 2\n"
    << (log_y ? "set logscale y\n" : "") << "set grid\nset key top left\nplot ";
  for (size_t i = 0; i < columns.size(); ++i) {
    s << (i ? ", " : "") << "'" << data << "' using 1:" << columns[i].first
      << " with linespoints pt 7 lw 2 title '" << columns[i].second << "'";
  }
  s << "\n";
  return s.str();
}

}  // namespace

void ReadScaleRun(const std::string& report_path, ScalePoint* point) {
  std::ifstream in(report_path);
  if (!in) {
    point->error = "no report at " + report_path;
    return;
  }
  const json report = json::parse(in, nullptr, false);
  if (report.is_discarded() || !report.contains("calibration")) {
    point->error = "unreadable report " + report_path;
    return;
  }
  const json& c = report["calibration"];
  point->rms_mm = Number(c, "rms_mm");
  point->device_time_s = Number(c, "device_time_s");
  point->compute_s = Number(c, "compute_time_s");
  point->messages_per_node = Number(c, "messages_per_node");
  point->bytes_per_node = Number(c, "bytes_per_node");
  point->colours = c.contains("colours") && c["colours"].is_number() ? c["colours"].get<int>() : 0;
  if (c.contains("self_calibration_report") && c["self_calibration_report"].contains("wall_s")) {
    point->round_wall_s = Number(c["self_calibration_report"], "wall_s");
  }
  point->total_s = Number(report, "total_s");
  double node_cpu = 0;
  int nodes = 0;
  if (report.contains("processes") && report["processes"].is_array()) {
    for (const json& p : report["processes"]) {
      const std::string role = p.value("role", std::string());
      const double cpu = Number(p, "cpu_s"), rss = Number(p, "max_rss_mb");
      if (role == "coordinator") point->coordinator_cpu_s = cpu;
      if (role == "world") {
        point->world_cpu_s = cpu;
        point->world_rss_mb = rss;
      }
      if (role == "node") {
        node_cpu += cpu;
        ++nodes;
        point->node_rss_mb_max = std::max(point->node_rss_mb_max, rss);
      }
    }
  }
  point->node_cpu_s_mean = nodes ? node_cpu / nodes : 0.0;
  if (report.contains("live") && report["live"].contains("reblend_ms_max")) {
    point->reblend_ms = Number(report["live"], "reblend_ms_max");
  }
  const bool failures = c.contains("failures") && !c["failures"].empty();
  point->ok = std::isfinite(point->rms_mm) && std::isfinite(point->messages_per_node) &&
              std::isfinite(point->device_time_s) && !failures;
  if (!point->ok) {
    point->error = failures ? "units failed: " + c["failures"].dump() : "no calibration figures";
  }
}

double MessagesSpread(const std::vector<ScalePoint>& points, int from_nodes) {
  double lo = std::numeric_limits<double>::infinity(), hi = 0;
  int n = 0;
  for (const ScalePoint& p : points) {
    if (!p.ok || p.nodes < from_nodes || !(p.messages_per_node > 0)) continue;
    lo = std::min(lo, p.messages_per_node);
    hi = std::max(hi, p.messages_per_node);
    ++n;
  }
  return n >= 2 ? hi / lo : 0.0;
}

Status LabScaleOptions::Check() const {
  if (out_dir.empty()) return InvalidArgumentError("--out: an output directory is required");
  if (nodes.empty()) return InvalidArgumentError("--nodes: at least one site size is needed");
  for (int n : nodes) {
    if (n < 1 || n > 64) {
      return InvalidArgumentError("--nodes: " + std::to_string(n) + " is not in 1..64");
    }
  }
  if (metric_samples < 1) return InvalidArgumentError("--samples must be >= 1");
  if (!(resolution_scale >= 0.05 && resolution_scale <= 1.0)) {
    return InvalidArgumentError("--resolution-scale must be in [0.05, 1]");
  }
  return OkStatus();
}

int RunScale(const LabScaleOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err) {
  if (Status checked = options.Check(); !checked.ok()) {
    err << "sandtable-lab scale: " << checked.message() << "\n";
    return 2;
  }
  const fs::path dir = fs::absolute(options.out_dir);
  std::error_code ec;
  fs::create_directories(dir / "runs", ec);
  if (ec) {
    err << "sandtable-lab scale: cannot create " << (dir / "runs").string() << ": " << ec.message()
        << "\n";
    return 1;
  }
  const auto started = std::chrono::steady_clock::now();
  std::vector<ScalePoint> points;
  for (size_t i = 0; i < options.nodes.size() && !stop; ++i) {
    ScalePoint point;
    point.nodes = options.nodes[i];
    const std::string name = "grid-" + std::to_string(point.nodes);
    const fs::path run_dir = dir / "runs" / name;
    fs::remove_all(run_dir, ec);
    std::vector<std::string> args = {
        "--site", name, "--scene", options.scene, "--seed", std::to_string(options.seed), "--out",
        run_dir.string(), "--samples", std::to_string(options.metric_samples), "--image-width",
        "200", "--resolution-scale", F(options.resolution_scale, 3), "--progress", "plain",
        // grid-64 on two cores: the world renders many minutes of
        // captures
        "--calibration-timeout-s", "3600"};
    if (options.reblend) {
      // A node killed 1 s into the hold after the show and the blend: its neighbours re-blend.
      args.insert(args.end(), {"--kill-unit", "0", "--kill-after-calibration", "--kill-at-s", "1",
                               "--hold-s", "4", "--show-s", "1"});
    } else {
      args.insert(args.end(), {"--render", "off"});
    }
    if (!options.bin_dir.empty()) args.insert(args.end(), {"--bin-dir", options.bin_dir});
    err << "scale: " << (i + 1) << "/" << options.nodes.size() << " " << name << " ..."
        << std::endl;
    const std::string exit_error =
        RunChildLab(args, (dir / "runs" / (name + ".log")).string(), stop);
    ReadScaleRun((run_dir / "report.json").string(), &point);
    if (!exit_error.empty()) {
      point.ok = false;
      point.error = exit_error;
    }
    err << "scale: " << name << ": "
        << (point.ok ? F(point.messages_per_node, 0) + " messages/node, " +
                           F(point.bytes_per_node / 1024.0, 0) + " KiB/node, site " +
                           F(point.device_time_s, 2) + " s (" + std::to_string(point.colours) +
                           " colours), compute " + F(point.compute_s, 2) + " s, rms " +
                           F(point.rms_mm, 2) + " mm"
                     : "FAILED (" + point.error + ")")
        << std::endl;
    points.push_back(std::move(point));
  }

  // scale.csv, the plots' data and scripts.
  std::ostringstream csv;
  csv << "nodes,ok,colours,device_time_s,compute_s,round_wall_s,messages_per_node,"
         "bytes_per_node,coordinator_cpu_s,world_cpu_s,node_cpu_s_mean,node_rss_mb_max,"
         "world_rss_mb,total_s,reblend_ms,rms_mm\n";
  std::ofstream dat(dir / "scale.dat");
  for (const ScalePoint& p : points) {
    csv << p.nodes << "," << (p.ok ? 1 : 0) << "," << p.colours << "," << F(p.device_time_s, 4)
        << "," << F(p.compute_s, 3) << "," << F(p.round_wall_s, 2) << ","
        << F(p.messages_per_node, 1) << "," << F(p.bytes_per_node, 0) << ","
        << F(p.coordinator_cpu_s, 2) << "," << F(p.world_cpu_s, 2) << "," << F(p.node_cpu_s_mean, 2)
        << "," << F(p.node_rss_mb_max, 0) << "," << F(p.world_rss_mb, 0) << "," << F(p.total_s, 1)
        << "," << F(p.reblend_ms, 1) << "," << F(p.rms_mm, 3) << "\n";
    if (!p.ok) continue;
    dat << p.nodes << " " << p.messages_per_node << " " << p.bytes_per_node / 1024.0 << " "
        << p.device_time_s << " " << p.compute_s << " " << p.round_wall_s << " "
        << p.coordinator_cpu_s << " " << p.node_cpu_s_mean << "\n";
  }
  dat.close();
  std::ofstream(dir / "scale.csv") << csv.str();
  std::vector<std::string> plot_notes;
  const std::string data = (dir / "scale.dat").string();
  const std::vector<std::pair<std::string, std::string>> plots = {
      {"scale_per_node",
       PlotScript(dir, "scale_per_node", "what each node sends and receives in the round",
                  "per node (log)", data, {{2, "messages per node"}, {3, "KiB per node"}}, true)},
      {"scale_time",
       PlotScript(dir, "scale_time", "time against the size of the site", "seconds (log)", data,
                  {{4, "modeled site projection"},
                   {5, "slowest node compute"},
                   {6, "round wall time (this machine)"},
                   {7, "coordinator CPU (whole run)"},
                   {8, "mean node CPU (whole run)"}},
                  true)}};
  for (const auto& [png, script] : plots) {
    const fs::path path = dir / (png + ".gp");
    std::ofstream(path) << script;
    const std::string why = RunGnuplot(path.string(), (dir / (png + ".log")).string());
    if (!why.empty()) plot_notes.push_back(png + ".png not drawn: " + why);
  }

  std::ostringstream md;
  md << "# Scale: the cost of a site as it grows\n\n"
     << "One `sandtable-lab run --site grid-N --scene " << options.scene << " --resolution-scale "
     << F(options.resolution_scale, 3) << "` per N, seed " << options.seed
     << (options.reblend ? ", with the show, the blend and unit 0 killed 1 s into "
                           "the hold (re-blend)"
                         : ", `--render off` (calibration only)")
     << ". Command:\n\n    " << options.command_line << "\n\nWall time: "
     << F(std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(), 0)
     << " s on this machine. Per node: the mean over the nodes of what each sent and received "
        "in the calibration round. CPU: user + system over each process's whole life "
        "(wait4). Memory: peak resident set.\n\n"
     << "| nodes | colours | site projection (s) | slowest compute (s) | round wall (s) | "
        "messages / node | KiB / node | coordinator CPU (s) | world CPU (s) | node CPU mean (s) "
        "| node peak MiB | world peak MiB | re-blend (ms) | rms (mm) |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const ScalePoint& p : points) {
    if (!p.ok) {
      md << "| " << p.nodes << " | failed: " << p.error << " | | | | | | | | | | | | |\n";
      continue;
    }
    md << "| " << p.nodes << " | " << p.colours << " | " << F(p.device_time_s, 2) << " | "
       << F(p.compute_s, 2) << " | " << F(p.round_wall_s, 1) << " | " << F(p.messages_per_node, 0)
       << " | " << F(p.bytes_per_node / 1024.0, 0) << " | " << F(p.coordinator_cpu_s, 2) << " | "
       << F(p.world_cpu_s, 1) << " | " << F(p.node_cpu_s_mean, 1) << " | "
       << F(p.node_rss_mb_max, 0) << " | " << F(p.world_rss_mb, 0) << " | "
       << (p.reblend_ms >= 0 ? F(p.reblend_ms, 0) : "-") << " | " << F(p.rms_mm, 2) << " |\n";
  }
  const double spread = MessagesSpread(points, 4);
  md << "\n";
  if (spread > 0) {
    md << "Messages per node from 4 nodes up vary by " << F(spread, 2)
       << "x (target: within 2x): " << (spread <= 2.0 ? "**pass**" : "**fail**") << ".\n\n";
  }
  for (const std::string& note : plot_notes) md << "- " << note << "\n";
  md << "\n![per node](scale_per_node.png)\n\n![time](scale_time.png)\n\n"
     << "Each run's report: `runs/grid-N/report.md`; the figures: `scale.csv`.\n";
  std::ofstream(dir / "scale.md") << md.str();
  Expected<std::string> html = MarkdownToHtmlPage(md.str(), dir.string(), "Sandtable scale");
  if (html.ok()) std::ofstream(dir / "scale.html") << *html;

  int failed = 0;
  for (const ScalePoint& p : points) failed += p.ok ? 0 : 1;
  out << "sandtable-lab scale: " << points.size() << " sizes, " << failed << " failed; "
      << (dir / "scale.md").string() << std::endl;
  if (stop) return 130;
  return failed == 0 ? 0 : 1;
}

}  // namespace sandtable::sim
