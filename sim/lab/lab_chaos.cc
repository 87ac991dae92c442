#include "sim/lab/lab_chaos.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <random>
#include <sstream>

#include "sim/lab/lab_html.h"
#include "sim/lab/lab_sweep.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string F(double v, int digits) { return FixedDigits(v, digits); }
std::string Ms(double v) { return v >= 0 ? F(v, 0) : "-"; }

double Num(const json& j, const char* key, double otherwise = -1) {
  return j.is_object() && j.contains(key) && j[key].is_number() ? j[key].get<double>() : otherwise;
}

}  // namespace

std::vector<std::string> ChaosPlan::RunArgs() const {
  return {"--join-late",
          std::to_string(join_unit),
          "--kill-unit",
          std::to_string(kill_unit),
          "--kill-after-calibration",
          "--kill-at-s",
          F(kill_at_s, 2),
          "--stall-unit",
          std::to_string(stall_unit),
          "--stall-after-calibration",
          "--stall-at-s",
          F(stall_at_s, 2),
          "--stall-for-s",
          F(stall_for_s, 2),
          "--kill-coordinator-at-s",
          F(coordinator_at_s, 2),
          "--fault-unit",
          std::to_string(fault_unit),
          "--fault-drop-share",
          F(drop_share, 3),
          "--fault-corrupt-share",
          F(corrupt_share, 3),
          "--annotate",
          "--hold-s",
          F(hold_s, 1)};
}

ChaosPlan MakeChaosPlan(uint64_t seed, int units) {
  std::mt19937_64 random(seed);
  auto uniform = [&](double lo, double hi) {
    return lo + (hi - lo) * std::uniform_real_distribution<double>(0.0, 1.0)(random);
  };
  std::vector<int> ids(static_cast<size_t>(std::max(units, 3)));
  for (size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<int>(i);
  std::shuffle(ids.begin(), ids.end(), random);
  ChaosPlan plan;
  plan.seed = seed;
  plan.join_unit = ids[0];   // started late: joins the calibrated site
  plan.kill_unit = ids[1];   // SIGKILL while the site shows
  plan.stall_unit = ids[2];  // SIGSTOP, SIGCONT
  plan.fault_unit = ids[0];  // the newcomer's links drop and corrupt (its join goes through them)
  plan.kill_at_s = uniform(1.0, 2.0);
  plan.stall_at_s = uniform(3.5, 4.5);
  plan.stall_for_s = uniform(1.0, 2.0);
  plan.coordinator_at_s = uniform(7.5, 8.5);
  plan.hold_s = 13.0;
  plan.drop_share = uniform(0.02, 0.05);
  plan.corrupt_share = uniform(0.005, 0.02);
  return plan;
}

void ReadChaosRun(const std::string& report_path, ChaosOutcome* o) {
  std::ifstream in(report_path);
  if (!in) {
    if (o->error.empty()) o->error = "no report at " + report_path;
    return;
  }
  const json r = json::parse(in, nullptr, false);
  if (r.is_discarded()) {
    o->error = "unreadable report " + report_path;
    return;
  }
  if (r.value("status", std::string()) != "ok") {
    if (r.contains("failure") && r["failure"].is_object()) {
      const json& f = r["failure"];
      o->error = "run " + r.value("status", std::string("?")) + " in phase '" +
                 f.value("phase", std::string()) + "': " + f.value("reason", std::string());
    } else {
      // A run that completed and failed its verdict: its reasons.
      std::string reasons;
      for (const json& reason : r.value("reasons", json::array())) {
        reasons += (reasons.empty() ? "" : "; ") + reason.value("what", std::string()) + ": " +
                   reason.value("detail", std::string());
      }
      o->error = "run " + r.value("status", std::string("?")) +
                 " its verdict: " + (reasons.empty() ? std::string("(no reason given)") : reasons);
    }
  }
  const json& chaos = r.contains("chaos") ? r["chaos"] : json::object();
  o->ran = chaos.is_object() && chaos.contains("processes_crashed");
  o->crashed = static_cast<int>(Num(chaos, "processes_crashed"));
  if (chaos.contains("annotations")) {
    const json& a = chaos["annotations"];
    o->acknowledged = static_cast<long long>(Num(a, "points_acknowledged"));
    o->present = static_cast<long long>(Num(a, "points_present"));
    o->lost = static_cast<long long>(Num(a, "points_lost"));
    if (!a.value("verify_error", std::string()).empty()) {
      o->error += (o->error.empty() ? "" : "; ") + std::string("annotations not verified: ") +
                  a.value("verify_error", std::string());
      o->lost = -1;
    }
  }
  const json faults = chaos.value("faults", json::array());
  for (const json& f : faults) {
    const std::string what = f.value("fault", std::string());
    o->frames_lost_max = std::max(o->frames_lost_max, static_cast<int>(Num(f, "frames_lost_max")));
    if (what.rfind("SIGKILL node", 0) == 0) {
      o->kill_detected_ms = Num(f, "detected_ms");
      o->kill_reblend_ms = Num(f, "recovered_ms");
    } else if (what.rfind("SIGKILL coordinator", 0) == 0) {
      o->coordinator_ready_ms = Num(f, "detected_ms");
      o->annotations_back_ms = Num(f, "recovered_ms");
    }
  }
  const json links = chaos.value("links", json::object());
  for (const auto& [name, line] : links.items()) {
    o->dropped += static_cast<long long>(Num(line, "faults_dropped", 0));
    o->corrupted += static_cast<long long>(Num(line, "faults_corrupted", 0));
    o->rejected += static_cast<long long>(Num(line, "rejected", 0));
  }
  const json& calibration = r.contains("calibration") ? r["calibration"] : json::object();
  if (calibration.contains("join")) {
    const json& j = calibration["join"];
    if (j.value("joined", false)) {
      o->join_ms = Num(j, "wall_s") * 1e3;
    } else {
      o->join_failed = true;
      o->error += (o->error.empty() ? "" : "; ") + std::string("the late unit did not join: ") +
                  j.value("error", std::string("(no reason)"));
    }
  }
  if (r.contains("live")) o->join_reblend_ms = Num(r["live"], "join_reblend_ms");
}

Status LabChaosOptions::Check() const {
  if (out_dir.empty()) return InvalidArgumentError("--out: an output directory is required");
  if (runs < 1 || runs > 1000) return InvalidArgumentError("--runs must be in 1..1000");
  if (metric_samples < 1) return InvalidArgumentError("--samples must be >= 1");
  if (hosts != "local" && hosts != "netns") {
    return InvalidArgumentError("--hosts must be local or netns");
  }
  return OkStatus();
}

int RunChaos(const LabChaosOptions& options, const std::atomic<bool>& stop, std::ostream& out,
             std::ostream& err) {
  if (Status checked = options.Check(); !checked.ok()) {
    err << "sandtable-lab chaos: " << checked.message() << "\n";
    return 2;
  }
  const fs::path dir = fs::absolute(options.out_dir);
  std::error_code ec;
  fs::create_directories(dir / "runs", ec);
  if (ec) {
    err << "sandtable-lab chaos: cannot create " << (dir / "runs").string() << ": " << ec.message()
        << "\n";
    return 1;
  }
  // The site's unit count, from the preset or file the runs will use.
  Expected<Site> site =
      fs::is_regular_file(options.site) ? LoadSiteFile(options.site) : MakeSitePreset(options.site);
  if (!site.ok()) {
    err << "sandtable-lab chaos: --site " << options.site << ": " << site.status().message()
        << "\n";
    return 2;
  }
  const int units = static_cast<int>(site->units.size());
  if (units < 3) {
    err << "sandtable-lab chaos: the site needs at least 3 units (a newcomer, a unit killed, one "
           "stalled)\n";
    return 2;
  }
  const auto started = std::chrono::steady_clock::now();
  std::vector<ChaosOutcome> outcomes;
  for (int i = 0; i < options.runs && !stop; ++i) {
    ChaosOutcome o;
    o.plan = MakeChaosPlan(options.first_seed + static_cast<uint64_t>(i), units);
    const std::string name = "seed-" + std::to_string(o.plan.seed);
    const fs::path run_dir = dir / "runs" / name;
    fs::remove_all(run_dir, ec);
    std::vector<std::string> args = {"--site",        options.site,
                                     "--scene",       options.scene,
                                     "--seed",        std::to_string(o.plan.seed),
                                     "--out",         run_dir.string(),
                                     "--samples",     std::to_string(options.metric_samples),
                                     "--image-width", "320",
                                     "--progress",    "plain"};
    const std::vector<std::string> faults = o.plan.RunArgs();
    args.insert(args.end(), faults.begin(), faults.end());
    if (!options.bin_dir.empty()) args.insert(args.end(), {"--bin-dir", options.bin_dir});
    if (options.hosts != "local") args.insert(args.end(), {"--hosts", options.hosts});
    err << "chaos: " << (i + 1) << "/" << options.runs << " " << name << " ..." << std::endl;
    const std::string exit_error =
        RunChildLab(args, (dir / "runs" / (name + ".log")).string(), stop);
    ReadChaosRun((run_dir / "report.json").string(), &o);
    if (!exit_error.empty() && o.error.empty()) o.error = exit_error;
    err << "chaos: " << name << ": " << (o.passed() ? "passed" : "FAILED") << " (crashed "
        << o.crashed << ", annotations acknowledged " << o.acknowledged << ", lost " << o.lost
        << ", re-blend " << Ms(o.kill_reblend_ms) << " ms, join " << Ms(o.join_ms)
        << " ms, coordinator back " << Ms(o.coordinator_ready_ms) << " ms"
        << (o.error.empty() ? "" : "; " + o.error) << ")" << std::endl;
    outcomes.push_back(std::move(o));
  }

  std::ostringstream csv;
  csv << "seed,passed,crashed,annotations_acknowledged,annotations_present,annotations_lost,"
         "kill_unit,kill_detected_ms,kill_reblend_ms,join_unit,join_ms,join_reblend_ms,"
         "stall_unit,coordinator_ready_ms,annotations_back_ms,frames_lost_max,fault_unit,"
         "dropped,corrupted,rejected,error\n";
  for (const ChaosOutcome& o : outcomes) {
    std::string error = o.error;
    std::replace(error.begin(), error.end(), ',', ';');
    std::replace(error.begin(), error.end(), '\n', ' ');
    csv << o.plan.seed << "," << (o.passed() ? 1 : 0) << "," << o.crashed << "," << o.acknowledged
        << "," << o.present << "," << o.lost << "," << o.plan.kill_unit << ","
        << F(o.kill_detected_ms, 1) << "," << F(o.kill_reblend_ms, 1) << "," << o.plan.join_unit
        << "," << F(o.join_ms, 0) << "," << F(o.join_reblend_ms, 1) << "," << o.plan.stall_unit
        << "," << F(o.coordinator_ready_ms, 0) << "," << F(o.annotations_back_ms, 0) << ","
        << o.frames_lost_max << "," << o.plan.fault_unit << "," << o.dropped << "," << o.corrupted
        << "," << o.rejected << "," << error << "\n";
  }
  std::ofstream(dir / "chaos.csv") << csv.str();

  int passed = 0;
  long long lost = 0, crashed = 0;
  for (const ChaosOutcome& o : outcomes) {
    passed += o.passed() ? 1 : 0;
    lost += std::max(o.lost, 0LL);
    crashed += std::max(o.crashed, 0);
  }
  std::ostringstream md;
  md << "# Chaos: faults while the site runs\n\n"
     << "Site `" << options.site << "`, scene `" << options.scene << "`; one `sandtable-lab run` "
     << "per seed with every fault below, drawn from the seed (docs/lab.md). Command:\n\n    "
     << options.command_line << "\n\nWall time: "
     << F(std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(), 0)
     << " s. **" << passed << " of " << outcomes.size() << " runs passed**; annotations lost "
     << "in all: **" << lost << "**, processes crashed: **" << crashed
     << "** (targets: 0 and 0).\n\n"
     << "Per seed: a unit started late joins the calibrated site through links that drop and "
        "corrupt a share of what it sends; once the site shows, the lab paints strokes through "
        "the coordinator, SIGKILLs a unit, SIGSTOPs another, SIGKILLs the coordinator and "
        "restarts it on its database and endpoints.\n\n"
     << "| seed | passed | crashed | annotations acked / present / lost | killed (detected, "
        "re-blended ms) | joined (calibrated, re-blended ms) | stalled | coordinator back / "
        "annotations back (ms) | frames lost (max per node) | link faults: dropped / corrupted "
        "/ rejected | note |\n"
     << "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n";
  for (const ChaosOutcome& o : outcomes) {
    md << "| " << o.plan.seed << " | " << (o.passed() ? "yes" : "**no**") << " | " << o.crashed
       << " | " << o.acknowledged << " / " << o.present << " / " << o.lost << " | "
       << o.plan.kill_unit << " at " << F(o.plan.kill_at_s, 1) << " s (" << Ms(o.kill_detected_ms)
       << ", " << Ms(o.kill_reblend_ms) << ") | " << o.plan.join_unit << " (" << Ms(o.join_ms)
       << ", " << Ms(o.join_reblend_ms) << ") | " << o.plan.stall_unit << " for "
       << F(o.plan.stall_for_s, 1) << " s | " << Ms(o.coordinator_ready_ms) << " / "
       << Ms(o.annotations_back_ms) << " | " << o.frames_lost_max << " | " << o.dropped << " / "
       << o.corrupted << " / " << o.rejected << " (unit " << o.plan.fault_unit << ", "
       << F(o.plan.drop_share * 100, 1) << " % / " << F(o.plan.corrupt_share * 100, 1) << " %) | "
       << o.error << " |\n";
  }
  md << "\nReplay a seed (`sandtable-lab chaos --seed N --runs 1`, or the run itself):\n\n";
  for (const ChaosOutcome& o : outcomes) {
    md << "    sandtable-lab run --site " << options.site << " --scene " << options.scene
       << " --seed " << o.plan.seed << " --out OUT";
    for (const std::string& a : o.plan.RunArgs()) md << " " << a;
    md << "\n";
  }
  md << "\nEach run's report: `runs/seed-N/report.md` (its Chaos section).\n";
  std::ofstream(dir / "chaos.md") << md.str();
  Expected<std::string> html = MarkdownToHtmlPage(md.str(), dir.string(), "Sandtable chaos");
  if (html.ok()) std::ofstream(dir / "chaos.html") << *html;
  out << "sandtable-lab chaos: " << passed << " of " << outcomes.size() << " runs passed; "
      << (dir / "chaos.md").string() << std::endl;
  if (stop) return 130;
  return passed == static_cast<int>(outcomes.size()) ? 0 : 1;
}

}  // namespace sandtable::sim
