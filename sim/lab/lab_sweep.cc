#include "sim/lab/lab_sweep.h"

#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <limits>
#include <memory>
#include <ostream>
#include <set>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "sim/lab/child_process.h"
#include "sim/lab/lab_html.h"
#include "sim/lab/lab_run.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

SweepConfig Knob(const std::string& knob, const std::string& value) {
  return {knob + "=" + value, knob, value, {"--" + knob + "=" + value}, false};
}
// A knob that `sandtable-lab run` has an option for (and hands on to its nodes itself).
SweepConfig LabKnob(const std::string& knob, const std::string& value) {
  SweepConfig c = Knob(knob, value);
  c.lab_args = std::move(c.node_args);
  c.node_args.clear();
  return c;
}
SweepConfig BlendKnob(const std::string& knob, const std::string& value) {
  SweepConfig c = Knob(knob, value);
  c.blend = true;
  return c;
}

std::string Fixed(double v, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

std::string SelfExe() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : p.string();
}

// An executable `name` on PATH, or empty.
std::string OnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "/usr/bin:/bin");
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    const fs::path candidate = fs::path(dir.empty() ? "." : dir) / name;
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
  }
  return {};
}

// Reads a finished run's report.json into `point`.
void ReadRun(const fs::path& report_path, SweepPoint* point) {
  std::ifstream in(report_path);
  if (!in) {
    point->error = "no report at " + report_path.string();
    return;
  }
  const json report = json::parse(in, nullptr, false);
  if (report.is_discarded() || !report.contains("calibration")) {
    point->error = "unreadable report " + report_path.string();
    return;
  }
  const json& c = report["calibration"];
  auto number = [&c](const char* key) {
    return c.contains(key) && c[key].is_number() ? c[key].get<double>()
                                                 : std::numeric_limits<double>::quiet_NaN();
  };
  point->rms_mm = number("rms_mm");
  point->p99_mm = number("p99_mm");
  point->max_mm = number("max_mm");
  point->device_time_s = number("device_time_s");
  point->compute_s = number("compute_time_s");
  if (c.contains("self_calibration_report") && c["self_calibration_report"].contains("wall_s")) {
    point->round_wall_s = c["self_calibration_report"]["wall_s"].get<double>();
  }
  if (c.contains("frames_per_projector") && c["frames_per_projector"].is_object()) {
    for (const auto& [id, frames] : c["frames_per_projector"].items()) {
      if (frames.is_number())
        point->frames_per_projector = std::max(point->frames_per_projector, frames.get<int>());
    }
  }
  const bool failures = c.contains("failures") && !c["failures"].empty();
  point->ok = std::isfinite(point->rms_mm) && std::isfinite(point->device_time_s) &&
              std::isfinite(point->compute_s) && !failures;
  if (!point->ok) {
    point->error = failures ? "units failed: " + c["failures"].dump() : "no calibration figures";
    return;
  }
  if (!point->config.blend) return;
  const json p = report.value("photometric", json::object());
  auto steps = [&p](const char* surface, const char* key) {
    return p.contains(surface) && p[surface].contains(key) && p[surface][key].is_number()
               ? p[surface][key].get<double>()
               : std::numeric_limits<double>::quiet_NaN();
  };
  point->table_p99_pct = steps("table", "p99_pct");
  point->table_max_pct = steps("table", "max_pct");
  point->walls_p99_pct = steps("walls", "p99_pct");
  point->walls_max_pct = steps("walls", "max_pct");
  point->uniformity = p.value("uniformity_min_over_max", 0.0);
  point->cast_ms = p.value("blend_cast_ms_max", std::numeric_limits<double>::quiet_NaN());
  if (!std::isfinite(point->table_p99_pct) || !std::isfinite(point->walls_p99_pct) ||
      !std::isfinite(point->cast_ms)) {
    point->ok = false;
    point->error = "no blend figures (photometric) in the report";
  }
}

// One plot of the points `in` keeps: y against x, every point labelled, the front (`on_front`)
// as a step line, the shipped defaults circled.
struct PlotAxes {
  std::function<bool(const SweepPoint&)> in, on_front;
  std::function<double(const SweepPoint&)> x, y;
  std::string title, x_label, y_label;
  bool log_y = false;
};

std::string PlotScript(const std::vector<SweepPoint>& points, const PlotAxes& axes,
                       const fs::path& dir, const std::string& png) {
  const std::string data = (dir / (png + ".dat")).string();
  const std::string front = (dir / (png + ".front.dat")).string();
  const std::string defaults = (dir / (png + ".defaults.dat")).string();
  std::ofstream all(data), on(front), def(defaults);
  std::vector<const SweepPoint*> sorted;
  for (const SweepPoint& p : points) {
    if (!p.ok || !axes.in(p)) continue;
    all << axes.x(p) << " " << axes.y(p) << " " << p.config.name << "\n";
    if (p.config.knob.empty()) def << axes.x(p) << " " << axes.y(p) << "\n";
    if (axes.on_front(p)) sorted.push_back(&p);
  }
  std::sort(sorted.begin(), sorted.end(),
            [&axes](const SweepPoint* a, const SweepPoint* b) { return axes.x(*a) < axes.x(*b); });
  for (const SweepPoint* p : sorted) on << axes.x(*p) << " " << axes.y(*p) << "\n";
  std::ostringstream s;
  s << "set terminal png size 1000,640\n"
    << "set output '" << (dir / (png + ".png")).string() << "'\n"
    << "set title '" << axes.title << "'\n"
    << "set xlabel '" << axes.x_label << "'\n"
    << "set ylabel '" << axes.y_label << "'\n"
    << (axes.log_y ? "set logscale y\n" : "") << "set grid\nset key top right\n"
    << "plot '" << data << "' using 1:2 with points pt 7 ps 1.2 lc rgb '#4477aa' title "
    << "'configurations', '" << data
    << "' using 1:2:3 with labels offset char 0.5,0.6 left font ',8' notitle, '" << front
    << "' using 1:2 with steps lw 2 lc rgb '#cc3311' title 'Pareto front', '" << defaults
    << "' using 1:2 with points pt 6 ps 3 lw 2 lc rgb '#228833' title 'shipped defaults'\n";
  return s.str();
}

// Registration error against the modeled projection time (device) or the compute time.
PlotAxes CalibrationAxes(bool device) {
  PlotAxes a;
  a.in = [](const SweepPoint& p) { return !p.config.blend; };
  a.on_front = [device](const SweepPoint& p) { return device ? p.front_device : p.front_compute; };
  a.x = [device](const SweepPoint& p) { return device ? p.device_time_s : p.compute_s; };
  a.y = [](const SweepPoint& p) { return p.rms_mm; };
  a.title =
      std::string("registration error against ") +
      (device ? "modeled projection time (whole site)" : "compute time (slowest node, one core)");
  a.x_label = device ? "modeled projection time (s)" : "compute time (s)";
  a.y_label = "registration rms (mm)";
  a.log_y = true;
  return a;
}

// The blend's: the walls' p99 step against the slowest node's cast time.
PlotAxes BlendAxes() {
  PlotAxes a;
  a.in = [](const SweepPoint& p) { return p.config.blend; };
  a.on_front = [](const SweepPoint& p) { return p.front_blend; };
  a.x = [](const SweepPoint& p) { return p.cast_ms; };
  a.y = [](const SweepPoint& p) { return p.walls_p99_pct; };
  a.title = "blend: walls 99th-percentile step over 5 mm against cast time (slowest node)";
  a.x_label = "cast: surface + distance field (ms)";
  a.y_label = "walls p99 step (%)";
  return a;
}

}  // namespace

std::string FixedDigits(double value, int digits) { return Fixed(value, digits); }

std::string RunChildLab(const std::vector<std::string>& run_args, const std::string& log_path,
                        const std::atomic<bool>& stop) {
  const std::string self = SelfExe();
  if (self.empty()) return "cannot find this program (/proc/self/exe)";
  std::vector<std::string> argv = {self, "run"};
  argv.insert(argv.end(), run_args.begin(), run_args.end());
  Expected<std::unique_ptr<ChildProcess>> child =
      ChildProcess::Spawn({"sandtable-lab run", "lab", argv, log_path});
  if (!child.ok()) return child.status().ToString();
  ChildProcess& c = **child;
  bool interrupted = false;
  while (!c.Reap()) {
    c.ReadLines();
    if (stop && !interrupted) {
      c.Signal(SIGTERM);
      interrupted = true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  c.ReadLines();
  // The run completed and its report holds a verdict that failed: its figures are what a
  // sweep or a scale compares.
  return c.exit_code() == 0 || c.exit_code() == kLabExitVerdict
             ? std::string()
             : "sandtable-lab run: " + c.DescribeExit();
}

std::string RunGnuplot(const std::string& script, const std::string& log_path) {
  const std::string gnuplot = OnPath("gnuplot");
  if (gnuplot.empty()) return "gnuplot not found on PATH";
  Expected<std::unique_ptr<ChildProcess>> plot =
      ChildProcess::Spawn({"gnuplot", "plot", {gnuplot, script}, log_path});
  if (!plot.ok()) return plot.status().ToString();
  if (!(*plot)->WaitFor(std::chrono::milliseconds(30000))) return "gnuplot ran past 30 s";
  return (*plot)->exit_code() == 0 ? std::string()
                                   : "gnuplot: " + (*plot)->DescribeExit() + " (" + log_path + ")";
}

std::vector<SweepConfig> DefaultSweep() {
  std::vector<SweepConfig> c;
  c.push_back({"defaults", "", "", {}});
  for (const char* v : {"4", "6", "12"}) c.push_back(Knob("phase-steps", v));
  for (const char* v : {"2", "8"}) c.push_back(Knob("gray-cell-px", v));
  for (const char* v : {"8", "32"}) c.push_back(Knob("grid-step-px", v));
  for (const char* v : {"3", "10"}) c.push_back(Knob("bundle-iterations", v));
  c.push_back(Knob("bundle-free", "poses"));
  // The planar path off (on a site that is not planar `auto` takes the full path anyway: this
  // point then measures what the planarity probe costs).
  c.push_back(LabKnob("calibration-path", "full"));
  SweepConfig blend{"blend", "", "", {}, true};
  c.push_back(blend);
  for (const char* v : {"4", "16"}) c.push_back(BlendKnob("blend-step-px", v));
  for (const char* v : {"1", "3"}) c.push_back(BlendKnob("blend-fill-limit", v));
  // The face-area threshold of the soft edges (0: every face; 100: no face of a table model).
  for (const char* v : {"0", "100"}) c.push_back(BlendKnob("blend-soft-face-m2", v));
  return c;
}

void MarkParetoFronts(std::vector<SweepPoint>& points) {
  for (SweepPoint& p : points) {
    p.front_device = p.front_compute = p.front_blend = false;
    if (!p.ok) continue;
    if (p.config.blend) {
      bool beaten = false;
      for (const SweepPoint& q : points) {
        if (&q == &p || !q.ok || !q.config.blend) continue;
        beaten |= q.walls_p99_pct <= p.walls_p99_pct && q.cast_ms <= p.cast_ms &&
                  (q.walls_p99_pct < p.walls_p99_pct || q.cast_ms < p.cast_ms);
      }
      p.front_blend = !beaten;
      continue;
    }
    bool beaten_device = false, beaten_compute = false;
    for (const SweepPoint& q : points) {
      if (&q == &p || !q.ok || q.config.blend) continue;
      const bool q_error = q.rms_mm <= p.rms_mm;
      beaten_device |= q_error && q.device_time_s <= p.device_time_s &&
                       (q.rms_mm < p.rms_mm || q.device_time_s < p.device_time_s);
      beaten_compute |= q_error && q.compute_s <= p.compute_s &&
                        (q.rms_mm < p.rms_mm || q.compute_s < p.compute_s);
    }
    p.front_device = !beaten_device;
    p.front_compute = !beaten_compute;
  }
}

std::string SweepCsv(const std::vector<SweepPoint>& points) {
  std::ostringstream s;
  s << "config,knob,value,ok,frames_per_projector,device_time_s,compute_s,round_wall_s,rms_mm,"
       "p99_mm,max_mm,front_device,front_compute,blend,table_p99_pct,table_max_pct,walls_p99_pct,"
       "walls_max_pct,uniformity,cast_ms,front_blend,error\n";
  for (const SweepPoint& p : points) {
    std::string error = p.error;
    std::replace(error.begin(), error.end(), ',', ';');
    std::replace(error.begin(), error.end(), '"', '\'');
    s << p.config.name << "," << p.config.knob << "," << p.config.value << "," << (p.ok ? 1 : 0)
      << "," << p.frames_per_projector << "," << Fixed(p.device_time_s, 4) << ","
      << Fixed(p.compute_s, 3) << "," << Fixed(p.round_wall_s, 2) << "," << Fixed(p.rms_mm, 4)
      << "," << Fixed(p.p99_mm, 4) << "," << Fixed(p.max_mm, 4) << "," << (p.front_device ? 1 : 0)
      << "," << (p.front_compute ? 1 : 0) << "," << (p.config.blend ? 1 : 0) << ","
      << Fixed(p.table_p99_pct, 3) << "," << Fixed(p.table_max_pct, 2) << ","
      << Fixed(p.walls_p99_pct, 3) << "," << Fixed(p.walls_max_pct, 2) << ","
      << Fixed(p.uniformity, 3) << "," << Fixed(p.cast_ms, 0) << "," << (p.front_blend ? 1 : 0)
      << ",\"" << error << "\"\n";
  }
  return s.str();
}

Status LabSweepOptions::Check() const {
  if (out_dir.empty()) return InvalidArgumentError("--out: an output directory is required");
  if (metric_samples < 1) return InvalidArgumentError("--samples must be >= 1");
  return OkStatus();
}

namespace {

// sweep.md: the calibration configurations against their fronts, the blend's, the plots.
std::string SweepMarkdown(const LabSweepOptions& options, const std::vector<SweepPoint>& points,
                          double wall_s, const std::vector<std::string>& plot_notes,
                          bool any_calibration) {
  std::ostringstream md;
  md << "# Sweep: run time against registration error\n\n"
     << "Site `" << options.site << "`, scene `" << options.scene << "`, seed " << options.seed
     << "; one `sandtable-lab run` per configuration (`--render off`, metric on "
     << options.metric_samples << " samples), the shipped defaults and one knob changed at a "
     << "time. Command:\n\n    " << options.command_line << "\n\n"
     << "Wall time of the sweep: " << Fixed(wall_s, 0)
     << " s. Projection: the site's modeled projection time (frames x (frame period + capture "
        "latency)); compute: the slowest node's CPU time in the round (one core); wall: the "
        "round on this machine. Front: on the Pareto front of error against projection (P) "
        "or compute (C).\n\n"
     << "| configuration | frames / projector | projection (s) | compute (s) | round wall (s) "
        "| rms (mm) | p99 (mm) | max (mm) | front |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  const SweepPoint* defaults = nullptr;
  for (const SweepPoint& p : points) {
    if (p.config.blend) continue;
    if (p.config.knob.empty()) defaults = &p;
    if (!p.ok) {
      md << "| " << p.config.name << " | failed: " << p.error << " | | | | | | | |\n";
      continue;
    }
    std::string front = std::string(p.front_device ? "P" : "") + (p.front_compute ? "C" : "");
    md << "| " << (p.config.knob.empty() ? "**defaults**" : "`" + p.config.name + "`") << " | "
       << p.frames_per_projector << " | " << Fixed(p.device_time_s, 3) << " | "
       << Fixed(p.compute_s, 2) << " | " << Fixed(p.round_wall_s, 1) << " | " << Fixed(p.rms_mm, 3)
       << " | " << Fixed(p.p99_mm, 3) << " | " << Fixed(p.max_mm, 3) << " | "
       << (front.empty() ? "-" : front) << " |\n";
  }
  md << "\n";
  if (defaults && defaults->ok) {
    md << "The shipped defaults are " << (defaults->front_device ? "on" : "**not** on")
       << " the projection front and " << (defaults->front_compute ? "on" : "**not** on")
       << " the compute front.";
    for (const SweepPoint& p : points) {
      if (&p == defaults || !p.ok || p.config.blend || p.rms_mm > defaults->rms_mm) continue;
      if (p.device_time_s <= defaults->device_time_s || p.compute_s <= defaults->compute_s) {
        md << " `" << p.config.name << "` is as accurate or better (" << Fixed(p.rms_mm, 3)
           << " mm) at " << Fixed(p.device_time_s, 3) << " s projection, " << Fixed(p.compute_s, 2)
           << " s compute.";
      }
    }
    md << " (docs/results.md says why the defaults stay where they are not on a front.)\n\n";
  }
  for (const std::string& note : plot_notes) md << "- " << note << "\n";
  if (any_calibration) {
    md << "\n![error against projection time](sweep_projection.png)\n\n"
       << "![error against compute time](sweep_compute.png)\n\n";
  }
  if (std::any_of(points.begin(), points.end(),
                  [](const SweepPoint& p) { return p.config.blend; })) {
    md << "## The blend\n\n"
       << "Each run shows and blends (the default run); steps over 5 mm through the world's "
          "truth (docs/blend.md), the cast is the slowest node's surface and distance field. "
          "Knobs: the blend's sampling resolution (`blend-step-px`, the distance field's grid "
          "step) and how far the others make up a clipped projector's shortfall "
          "(`blend-fill-limit`). Front (B): walls' p99 against cast time.\n\n"
       << "| configuration | table p99 (%) | table max (%) | walls p99 (%) | walls max (%) | "
          "uniformity | cast (ms) | front |\n"
       << "| --- | --- | --- | --- | --- | --- | --- | --- |\n";
    const SweepPoint* blend_defaults = nullptr;
    for (const SweepPoint& p : points) {
      if (!p.config.blend) continue;
      if (p.config.knob.empty()) blend_defaults = &p;
      if (!p.ok) {
        md << "| " << p.config.name << " | failed: " << p.error << " | | | | | | |\n";
        continue;
      }
      md << "| " << (p.config.knob.empty() ? "**blend defaults**" : "`" + p.config.name + "`")
         << " | " << Fixed(p.table_p99_pct, 2) << " | " << Fixed(p.table_max_pct, 1) << " | "
         << Fixed(p.walls_p99_pct, 2) << " | " << Fixed(p.walls_max_pct, 1) << " | "
         << Fixed(p.uniformity, 3) << " | " << Fixed(p.cast_ms, 0) << " | "
         << (p.front_blend ? "B" : "-") << " |\n";
    }
    if (blend_defaults && blend_defaults->ok) {
      md << "\nThe shipped blend is " << (blend_defaults->front_blend ? "on" : "**not** on")
         << " the blend's front.\n";
    }
    md << "\n![blend: walls step against cast time](sweep_blend.png)\n\n";
  }
  md << "Each run's report: `runs/<configuration>/report.md`; the figures: `sweep.csv`.\n";
  return md.str();
}

}  // namespace

int RunSweep(const LabSweepOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err) {
  if (Status checked = options.Check(); !checked.ok()) {
    err << "sandtable-lab sweep: " << checked.message() << "\n";
    return 2;
  }
  std::vector<SweepConfig> configs;
  for (const SweepConfig& c : DefaultSweep()) {
    if (options.only.empty() ||
        std::find(options.only.begin(), options.only.end(), c.name) != options.only.end()) {
      configs.push_back(c);
    }
  }
  if (configs.empty()) {
    err << "sandtable-lab sweep: --only names no configuration (see docs/lab.md, \"Sweep\")\n";
    return 2;
  }
  const fs::path dir = fs::absolute(options.out_dir);
  std::error_code ec;
  fs::create_directories(dir / "runs", ec);
  if (ec) {
    err << "sandtable-lab sweep: cannot create " << (dir / "runs").string() << ": " << ec.message()
        << "\n";
    return 1;
  }
  const auto started = std::chrono::steady_clock::now();
  std::vector<SweepPoint> points;
  for (size_t i = 0; i < configs.size(); ++i) {
    if (stop) break;
    SweepPoint point;
    point.config = configs[i];
    const fs::path run_dir = dir / "runs" / point.config.name;
    fs::remove_all(run_dir, ec);
    std::vector<std::string> args = {"--site",        options.site,
                                     "--scene",       options.scene,
                                     "--seed",        std::to_string(options.seed),
                                     "--out",         run_dir.string(),
                                     "--samples",     std::to_string(options.metric_samples),
                                     "--image-width", "200",
                                     "--progress",    "plain"};
    // Calibration configurations need no show; blend ones show and blend (the default run).
    if (!point.config.blend) args.insert(args.end(), {"--render", "off"});
    if (!options.bin_dir.empty()) args.insert(args.end(), {"--bin-dir", options.bin_dir});
    for (const std::string& a : point.config.node_args) args.push_back("--node-arg=" + a);
    args.insert(args.end(), point.config.lab_args.begin(), point.config.lab_args.end());
    err << "sweep: " << (i + 1) << "/" << configs.size() << " " << point.config.name << " ..."
        << std::endl;
    point.error = RunChildLab(args, (dir / "runs" / (point.config.name + ".log")).string(), stop);
    const std::string exit_error = point.error;
    ReadRun(run_dir / "report.json", &point);
    if (!exit_error.empty()) {
      point.ok = false;
      point.error = exit_error;
    }
    err << "sweep: " << point.config.name << ": "
        << (!point.ok ? "FAILED (" + point.error + ")"
            : point.config.blend
                ? "walls p99 " + Fixed(point.walls_p99_pct, 2) + " %, table p99 " +
                      Fixed(point.table_p99_pct, 2) + " %, cast " + Fixed(point.cast_ms, 0) + " ms"
                : "rms " + Fixed(point.rms_mm, 3) + " mm, projection " +
                      Fixed(point.device_time_s, 3) + " s, compute " + Fixed(point.compute_s, 2) +
                      " s")
        << std::endl;
    points.push_back(std::move(point));
  }
  MarkParetoFronts(points);

  std::ofstream(dir / "sweep.csv") << SweepCsv(points);
  // Plots (gnuplot: docs/lab.md); the CSV stands without them.
  std::vector<std::string> plot_notes;
  const bool any_calibration = std::any_of(
      points.begin(), points.end(), [](const SweepPoint& p) { return !p.config.blend && p.ok; });
  for (const bool device : {true, false}) {
    if (!any_calibration) break;
    const std::string png = device ? "sweep_projection" : "sweep_compute";
    const fs::path script = dir / (png + ".gp");
    std::ofstream(script) << PlotScript(points, CalibrationAxes(device), dir, png);
    const std::string why = RunGnuplot(script.string(), (dir / (png + ".log")).string());
    if (!why.empty()) plot_notes.push_back(png + ".png not drawn: " + why);
  }
  const bool any_blend = std::any_of(points.begin(), points.end(),
                                     [](const SweepPoint& p) { return p.config.blend && p.ok; });
  if (any_blend) {
    const fs::path script = dir / "sweep_blend.gp";
    std::ofstream(script) << PlotScript(points, BlendAxes(), dir, "sweep_blend");
    const std::string why = RunGnuplot(script.string(), (dir / "sweep_blend.log").string());
    if (!why.empty()) plot_notes.push_back("sweep_blend.png not drawn: " + why);
  }

  // sweep.md and sweep.html.
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::ostringstream md;
  md << SweepMarkdown(options, points, wall_s, plot_notes, any_calibration);
  std::ofstream(dir / "sweep.md") << md.str();
  Expected<std::string> html = MarkdownToHtmlPage(md.str(), dir.string(), "Sandtable sweep");
  if (html.ok()) std::ofstream(dir / "sweep.html") << *html;

  int failed = 0;
  for (const SweepPoint& p : points) failed += p.ok ? 0 : 1;
  out << "sandtable-lab sweep: " << points.size() << " configurations, " << failed << " failed; "
      << (dir / "sweep.md").string() << std::endl;
  if (stop) return 130;
  return failed == 0 ? 0 : 1;
}

}  // namespace sandtable::sim
