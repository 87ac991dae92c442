#include "sim/lab/lab_run.h"

#include <unistd.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <future>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "common/io/image_file.h"
#include "common/io/mpcdi.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/gltf_loader.h"
#include "common/scene/ray_caster.h"
#include "net/channel.h"
#include "net/curve.h"
#include "sim/lab/lab_images.h"
#include "sim/lab/lab_inputs.h"
#include "sim/lab/lab_painter.h"
#include "sim/lab/lab_report.h"
#include "sim/lab/lab_sweep.h"
#include "sim/lab/photometric_metric.h"
#include "sim/lab/progress.h"
#include "sim/lab/registration_metric.h"
#include "sim/lab/render_metrics.h"
#include "sim/lab/supervisor.h"
#include "sim/site/site_json.h"
#include "sim/transport/world.h"

namespace sandtable::sim {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using std::chrono::milliseconds;

// The photometric measure (photometric_metric.h): steps over 5 mm, on samples lit above 3x the
// ambient luminance of a white surface.
constexpr double kStepSpacing_m = 0.005;
constexpr double kLitAmbientFactor = 3.0;
// The bound on the table's step over 5 mm: the steps over it are located (PlaceSteps).
constexpr double kTableStepBoundPct = 1.5;

// Mean of an MPCDI region's alpha map in [0, 1] (-1 without one): 1 until the blend fills it.
double AlphaMean(const MpcdiRegion& region) {
  if (!region.alpha || region.alpha->values.empty()) return -1.0;
  double sum = 0.0;
  for (uint8_t v : region.alpha->values) sum += v;
  return sum / (255.0 * static_cast<double>(region.alpha->values.size()));
}

int64_t SteadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2, kExitVerdict = kLabExitVerdict,
              kExitInterrupted = 130;
constexpr int kLogTailLines = 20;

milliseconds ToMs(double seconds) { return milliseconds(static_cast<int64_t>(seconds * 1e3)); }

// The build tree's programs (set by sim/lab/CMakeLists.txt), the last place looked in.
#ifndef SANDTABLE_LAB_WORLD_BIN
#define SANDTABLE_LAB_WORLD_BIN ""
#define SANDTABLE_LAB_COORDINATOR_BIN ""
#define SANDTABLE_LAB_NODE_BIN ""
#endif

// `name` in --bin-dir, else beside this program, else where the build tree put it.
Expected<std::string> FindProgram(const std::string& name, const std::string& bin_dir,
                                  const std::string& built) {
  std::vector<fs::path> candidates;
  if (!bin_dir.empty()) {
    candidates.push_back(fs::path(bin_dir) / name);
  } else {
    std::error_code error;
    const fs::path self = fs::read_symlink("/proc/self/exe", error);
    if (!error) candidates.push_back(self.parent_path() / name);
    if (!built.empty()) candidates.push_back(built);
  }
  std::string looked;
  for (const fs::path& candidate : candidates) {
    if (access(candidate.c_str(), X_OK) == 0) return candidate.string();
    looked += (looked.empty() ? "" : ", ") + candidate.string();
  }
  return NotFoundError("cannot find " + name + " (looked in " + looked +
                       "): build it, or pass --bin-dir DIR");
}

std::string JoinLines(const std::vector<std::string>& lines) {
  std::string out;
  for (const std::string& line : lines) out += "    " + line + "\n";
  return out;
}

class LabRun {
 public:
  LabRun(const LabRunOptions& options, const std::atomic<bool>& stop, std::ostream& out,
         std::ostream& err)
      : options_(options),
        stop_(stop),
        out_(out),
        err_(err),
        progress_(err, options.progress_tty),
        supervisor_((fs::path(options.out_dir) / "processes.json").string()),
        start_(std::chrono::steady_clock::now()) {}

  int Run() {
    result_.command = options_.command_line;
    result_.seed = options_.seed;
    result_.site_label = options_.site;
    result_.scene_label = options_.scene;
    result_.metric_options.num_samples = options_.metric_samples;
    result_.metric_options.seed = options_.seed;
    if (int usage = Prepare(); usage != kExitOk) return usage;
    const bool ok = StartWorld() && StartCoordinator() && StartNodes() && Calibrate() && Join() &&
                    Show() && Blend() && Hold() && Measure();
    (void)ok;  // a failure is in result_.failure
    return Finish();
  }

 private:
  // ---- phases ----

  int Prepare() {
    Phase("prepare", 0);
    Expected<LabInputs> inputs =
        PrepareLabInputs(options_.site, options_.scene, options_.seed, options_.out_dir,
                         options_.model, options_.resolution_scale);
    if (!inputs.ok()) {
      progress_.End("failed");
      err_ << "sandtable-lab run: " << inputs.status().message() << "\n";
      return inputs.status().code() == StatusCode::kInvalidArgument ? kExitUsage : kExitFailure;
    }
    inputs_ = std::move(*inputs);
    if (options_.curve) {
      // One site key for the whole run: world, coordinator and nodes require CURVE with it.
      const std::string key_path = fs::absolute(fs::path(options_.out_dir) / "site.key");
      Expected<net::CurveKeyPair> keys = net::GenerateCurveKeyPair();
      const Status written = keys.ok() ? net::WriteCurveKeyFile(key_path, *keys) : keys.status();
      if (!written.ok()) {
        progress_.End("failed");
        err_ << "sandtable-lab run: --curve: " << written.ToString() << "\n";
        return kExitFailure;
      }
      curve_keys_path_ = key_path;
      site_keys_ = *keys;
    }
    // The personnel tracks the coordinator replays and the nodes draw (docs/render.md).
    tracks_path_ = fs::absolute(fs::path(options_.out_dir) / "tracks.csv").string();
    const double table_radius_m = inputs_.site.table.is_disc
                                      ? 0.5 * inputs_.site.table.diameter_m
                                      : 0.5 * inputs_.site.table.size_m.minCoeff();
    if (Status tracks = WriteLabTracks(tracks_path_, 4, 120.0, 0.65 * table_radius_m);
        !tracks.ok()) {
      progress_.End("failed");
      err_ << "sandtable-lab run: " << tracks.ToString() << "\n";
      return kExitFailure;
    }
    result_.site_name = inputs_.site.name;
    result_.num_units = static_cast<int>(inputs_.site.units.size());
    result_.site_path = RelativeToOut(inputs_.site_path);
    result_.scene_path = RelativeToOut(inputs_.scene_path);
    // The lab's own copy of the truth, read back from the very files the world loads.
    Expected<Scene> scene = LoadGltfScene(inputs_.scene_path);
    if (!scene.ok()) {
      progress_.End("failed");
      err_ << "sandtable-lab run: " << scene.status().ToString() << "\n";
      return kExitFailure;
    }
    result_.scene_triangles = scene->NumTriangles();
    scene_ = std::move(*scene);
    for (auto [name, built, path] :
         {std::tuple{"sandtable-world", SANDTABLE_LAB_WORLD_BIN, &world_bin_},
          std::tuple{"sandtable-coordinator", SANDTABLE_LAB_COORDINATOR_BIN, &coordinator_bin_},
          std::tuple{"sandtable-node", SANDTABLE_LAB_NODE_BIN, &node_bin_}}) {
      Expected<std::string> found = FindProgram(name, options_.bin_dir, built);
      if (!found.ok()) {
        progress_.End("failed");
        err_ << "sandtable-lab run: " << found.status().message() << "\n";
        return kExitFailure;
      }
      *path = *found;
    }
    progress_.End();
    return kExitOk;
  }

  std::string FrameLogPath() const {
    return fs::absolute(fs::path(options_.out_dir) / "world_frames.jsonl").string();
  }
  static int64_t SystemMs() {
    return std::chrono::duration_cast<std::chrono::milliseconds>(
               std::chrono::system_clock::now().time_since_epoch())
        .count();
  }

  bool StartWorld() {
    Phase("start world", 1);
    ChildProcess* world =
        StartChild("world", "world",
                   {world_bin_, "serve", "--site", inputs_.site_path, "--scene", inputs_.scene_path,
                    "--bind", "tcp://127.0.0.1:*", "--frame-log", FrameLogPath()});
    if (!world) return false;
    return Wait(
        "start world", [&] { return !world_endpoint_.empty(); }, ToMs(options_.start_timeout_s),
        "sandtable-world printed no readiness line "
        "{\"ready\":\"sandtable-world\",\"world\":ENDPOINT} on stdout",
        world);
  }

  std::vector<std::string> CoordinatorArgs(const std::string& requests,
                                           const std::string& events) const {
    std::vector<std::string> argv = {
        coordinator_bin_, "--requests",     requests,
        "--events",       events,           "--timeline",
        tracks_path_,     "--heartbeat-ms", std::to_string(HeartbeatMs())};
    if (Chaos()) {
      argv.insert(argv.end(),
                  {"--annotations", fs::absolute(fs::path(options_.out_dir) / "annotations.db")});
    }
    return argv;
  }
  bool Chaos() const { return options_.annotate || options_.kill_coordinator_at_s >= 0; }

  bool StartCoordinator() {
    Phase("start coordinator", 1);
    ChildProcess* coordinator = StartChild(
        "coordinator", "coordinator", CoordinatorArgs("tcp://127.0.0.1:*", "tcp://127.0.0.1:*"));
    if (!coordinator) return false;
    return Wait(
        "start coordinator", [&] { return !coordinator_events_.empty(); },
        ToMs(options_.start_timeout_s),
        "sandtable-coordinator printed no readiness line "
        "{\"ready\":\"sandtable-coordinator\",\"requests\":..,\"events\":..} on stdout",
        coordinator);
  }

  bool Late(NodeId id) const {
    return options_.join_late >= 0 && static_cast<NodeId>(options_.join_late) == id;
  }
  int HeartbeatMs() const {
    if (options_.heartbeat_ms > 0) return options_.heartbeat_ms;
    const int units = static_cast<int>(inputs_.site.units.size());
    return units <= 16 ? 100 : 100 * units / 16;
  }
  int ExpectedUnits() const {
    int n = 0;
    for (const UnitSpec& unit : inputs_.site.units) n += Late(unit.id) ? 0 : 1;
    return n;
  }

  bool StartNodes() {
    const int n = ExpectedUnits();
    Phase("start nodes", n);
    for (const UnitSpec& unit : inputs_.site.units) {
      if (!Late(unit.id) && !StartNode(unit)) return false;
    }
    return Wait(
        "start nodes", [&] { return static_cast<int>(nodes_ready_.size()) == n; },
        ToMs(options_.start_timeout_s),
        "not every sandtable-node printed its readiness line "
        "{\"ready\":\"sandtable-node\",\"id\":N,..}",
        nullptr, [&] { return static_cast<int>(nodes_ready_.size()); },
        [&] { return Missing(nodes_ready_); });
  }

  // The late unit (--join-late): started once the others hold their calibration (and their
  // blend has settled); done when it holds its own, and 2 s more so that a round that
  // recalibrated the others would show. Frames given to the others are counted from its start
  // to its calibration.
  bool Join() {
    if (options_.join_late < 0) return true;
    Phase("join", 1);
    const NodeId late = static_cast<NodeId>(options_.join_late);
    // A calibrated site is also blended: the held units' masks settle first (a blend line from
    // each, then none for 1.5 s), so the frames counted below are the join's own.
    if (options_.render != "off" && options_.blend != "off") {
      const WaitOutcome blended = supervisor_.WaitUntil(
          [&] {
            for (const auto& [id, line] : calibrated_) {
              if (!blend_.count(id) && !render_unavailable_.count(id)) return false;
            }
            return std::chrono::steady_clock::now() - last_blend_line_ > milliseconds(1500);
          },
          ToMs(60), stop_, Handler());
      if (blended != WaitOutcome::kDone && blended != WaitOutcome::kDeadline) {
        return Failed("join", blended, "", nullptr);
      }
    }
    const std::map<NodeId, report::Calibrated> before = calibrated_;
    const auto t0 = std::chrono::steady_clock::now();
    const int64_t t0_ms = SystemMs();
    const UnitSpec* spec = inputs_.site.FindUnit(late);
    if (!spec) {
      return FailedWith("join", "--join-late " + std::to_string(late) + ": the site has no unit " +
                                    std::to_string(late));
    }
    if (!StartNode(*spec)) return false;
    if (!Wait(
            "join", [&] { return calibrated_.count(late) || calibration_failed_.count(late); },
            ToMs(options_.calibration_timeout_s), "the late sandtable-node reported no calibration",
            nullptr, [&] { return static_cast<int>(calibrated_.count(late)); },
            [&] { return "node-" + std::to_string(late); })) {
      return false;
    }
    const double wall_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    // The frames the join itself gave the others: up to the late unit's calibration (after it,
    // its neighbours re-blend with its field: live.join_reblend).
    const int64_t t1_ms = SystemMs();
    const bool never = false;
    const WaitOutcome settled =
        supervisor_.WaitUntil([&] { return never; }, ToMs(2.0), stop_, Handler());
    if (settled != WaitOutcome::kDeadline) return Failed("join", settled, "", nullptr);
    std::vector<NodeId> recalibrated;
    for (const auto& [id, line] : before) {
      if (calibrated_.at(id).round != line.round) recalibrated.push_back(id);
    }
    // What every projector was given meanwhile, from the world's own record.
    std::map<NodeId, int> frames;
    std::map<NodeId, std::set<std::string>> distinct;
    std::map<NodeId, std::string> hash_before, hash_after;
    for (const UnitSpec& unit : inputs_.site.units) frames[unit.id] = 0;
    if (Expected<std::string> log = ReadInputFile(FrameLogPath(), size_t{256} << 20, "256 MiB");
        log.ok()) {
      std::istringstream lines(*log);
      for (std::string text; std::getline(lines, text);) {
        json line = json::parse(text, nullptr, false);
        if (line.is_discarded() || !line.is_object()) continue;
        const int64_t t = line.value("time_ms", int64_t{0});
        const NodeId p = line.value("projector", kInvalidNodeId);
        const std::string hash = line.value("hash", std::string());
        if (t < t0_ms) hash_before[p] = hash;
        if (t < t0_ms || t > t1_ms) continue;
        ++frames[p];
        distinct[p].insert(hash);
        hash_after[p] = hash;
      }
    }
    json frames_json = json::object();
    std::vector<NodeId> unchanged;
    for (const auto& [p, count] : frames) {
      frames_json[std::to_string(p)] = {
          {"frames_set", count},
          {"distinct", distinct[p].size()},
          // Back on the frame it showed before the join (or never given another).
          {"restored", count == 0 || (hash_before.count(p) && hash_after[p] == hash_before[p])}};
      if (p != late && count == 0) unchanged.push_back(p);
    }
    json join = {{"unit", late},
                 {"wall_s", wall_s},
                 {"joined", calibrated_.count(late) > 0},
                 {"others_recalibrated", recalibrated},
                 {"frames_during_join", frames_json},
                 {"units_showing_the_same_frame", unchanged}};
    if (calibrated_.count(late)) {
      const std::string path = calibrated_.at(late).join_report;
      if (!path.empty()) {
        Expected<std::string> text = ReadInputFile(path, size_t{16} << 20, "16 MiB");
        if (text.ok()) {
          json parsed = json::parse(*text, nullptr, false);
          if (!parsed.is_discarded()) join["report"] = parsed;
        }
      }
    } else {
      join["error"] = calibration_failed_.at(late);
    }
    result_.join = join;
    progress_.End();
    return true;
  }

  bool StartNode(const UnitSpec& unit) {
    const std::string export_dir = fs::absolute(fs::path(options_.out_dir) / "calibration");
    {
      const std::string id = std::to_string(unit.id);
      std::vector<std::string> argv = {node_bin_,
                                       "--id",
                                       id,
                                       "--coordinator",
                                       coordinator_requests_ + "," + coordinator_events_,
                                       "--world",
                                       world_endpoint_,
                                       "--factory",
                                       inputs_.factory_paths.at(unit.id),
                                       "--export-dir",
                                       export_dir,
                                       "--heartbeat-ms",
                                       std::to_string(HeartbeatMs())};
      // The model: self-calibration finds where it stands; the renderer draws it there.
      argv.insert(argv.end(), {"--model", inputs_.model_path});
      if (options_.render == "off") {
        argv.insert(argv.end(), {"--render", "off"});
      } else {
        if (options_.blend == "off") argv.insert(argv.end(), {"--blend", "off"});
        if (options_.black_match == "on") argv.insert(argv.end(), {"--black-match", "on"});
        argv.insert(argv.end(),
                    {"--timeline", tracks_path_, "--render-max-fps",
                     std::to_string(options_.render_max_fps), "--render-log",
                     fs::absolute(fs::path(options_.out_dir) / "logs" / ("render-" + id + ".csv"))
                         .string()});
      }
      if (TruePoseMode()) {
        argv.insert(argv.end(), {"--true-pose", inputs_.true_pose_paths.at(unit.id)});
      } else {
        argv.insert(argv.end(), {"--calibration-path", options_.calibration_path, "--expect-units",
                                 std::to_string(ExpectedUnits())});
        if (!options_.saved_calibration.empty()) {
          const std::filesystem::path saved =
              std::filesystem::path(options_.saved_calibration) / ("unit-" + id + ".json");
          if (std::filesystem::exists(saved)) {
            argv.insert(argv.end(), {"--saved-calibration", saved.string()});
            given_saved_.insert(unit.id);
          }
        }
      }
      argv.insert(argv.end(), options_.node_args.begin(), options_.node_args.end());
      if (options_.fault_unit >= 0 && unit.id == static_cast<NodeId>(options_.fault_unit)) {
        argv.insert(argv.end(),
                    {"--fault-drop-share", std::to_string(options_.fault_drop_share),
                     "--fault-corrupt-share", std::to_string(options_.fault_corrupt_share),
                     "--fault-seed", std::to_string(options_.seed)});
      }
      ChildProcess* node = StartChild(
          "node-" + id, "node", argv,
          options_.node_huge_pages == "on" ? NodeHugePagesEnv() : std::vector<std::string>{});
      if (!node) return false;
    }
    return true;
  }

  bool TruePoseMode() const { return options_.calibration == "true-pose"; }

  // --kill-unit: SIGKILL the unit once kill_at_s have passed since the calibration phase began.
  void MaybeKill() {
    const bool holding = hold_started_ != std::chrono::steady_clock::time_point{};
    if (options_.kill_unit < 0 || killed_ || (options_.kill_after_calibration && !holding)) return;
    const auto from = options_.kill_after_calibration ? hold_started_ : calibration_started_;
    if (std::chrono::steady_clock::now() - from <
        std::chrono::duration<double>(options_.kill_at_s)) {
      return;
    }
    const NodeId unit = static_cast<NodeId>(options_.kill_unit);
    for (const auto& child : supervisor_.children()) {
      if (child->name() != "node-" + std::to_string(unit)) continue;
      supervisor_.ExpectExit(child.get());
      intended_kills_.insert(child->name());
      kill_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(
                     std::chrono::steady_clock::now().time_since_epoch())
                     .count();
      child->Signal(SIGKILL);
      killed_ = true;
      kill_at_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - from).count();
      killed_while_calibrating_ = !calibrated_.count(unit);
      calibrated_at_kill_ = calibrated_;
      if (killed_while_calibrating_) {
        calibration_failed_[unit] = "unit " + std::to_string(unit) + ": killed by the lab " +
                                    std::to_string(kill_at_s_) +
                                    " s into the calibration (--kill-unit)";
      }
      ST_LOG(kWarning) << "lab: killed node-" << unit << " (--kill-unit)";
    }
  }

  // --stall-unit: SIGSTOP the unit stall_at_s after the calibration phase began, SIGCONT it
  // stall_for_s later (and at the latest before the teardown).
  void MaybeStall() {
    if (options_.stall_unit < 0 || stall_state_ == StallState::kResumed) return;
    const auto now = std::chrono::steady_clock::now();
    const bool stopped = stall_state_ == StallState::kStopped;
    const bool holding = hold_started_ != std::chrono::steady_clock::time_point{};
    if (options_.stall_after_calibration && !holding) return;
    const auto from = options_.stall_after_calibration ? hold_started_ : calibration_started_;
    if (!stopped && now - from < std::chrono::duration<double>(options_.stall_at_s)) return;
    if (stopped && now - stalled_at_ < std::chrono::duration<double>(options_.stall_for_s)) return;
    Stall(!stopped);
  }
  void Stall(bool stop) {
    const NodeId unit = static_cast<NodeId>(options_.stall_unit);
    for (const auto& child : supervisor_.children()) {
      if (child->name() != "node-" + std::to_string(unit)) continue;
      child->Signal(stop ? SIGSTOP : SIGCONT);
    }
    const auto now = std::chrono::steady_clock::now();
    const auto from = options_.stall_after_calibration ? hold_started_ : calibration_started_;
    const double at_s = std::chrono::duration<double>(now - from).count();
    if (stop) {
      stall_state_ = StallState::kStopped;
      stalled_at_ = now;
      result_.stall = {
          {"unit", unit}, {"stopped_at_s", at_s}, {"during_calibration", !calibrated_.count(unit)}};
      ST_LOG(kWarning) << "lab: stopped node-" << unit << " (--stall-unit)";
    } else {
      stall_state_ = StallState::kResumed;
      result_.stall["resumed_at_s"] = at_s;
      ST_LOG(kWarning) << "lab: resumed node-" << unit << " (--stall-unit)";
    }
  }

  // What the other units did after the kill (their calibrated lines' rounds).
  void RecordKill() {
    if (!killed_) return;
    const NodeId unit = static_cast<NodeId>(options_.kill_unit);
    std::vector<NodeId> recalibrated;
    for (const auto& [id, line] : calibrated_at_kill_) {
      if (id == unit) continue;
      if (calibrated_.at(id).round != line.round) recalibrated.push_back(id);
    }
    std::vector<NodeId> finished;
    for (const auto& [id, line] : calibrated_) {
      if (id != unit) finished.push_back(id);
    }
    // Re-blend: each neighbour's first mask shown without the killed unit, from the kill.
    json reblend = json::object();
    double reblend_max_ms = 0.0;
    for (const report::BlendShown& line : reblends_) {
      if (line.peer != unit) continue;
      const std::string id = std::to_string(line.id);
      if (reblend.contains(id)) continue;
      const double shown_ms = (line.shown_ns - kill_ns_) * 1e-6;
      const double detected_ms = (line.detected_ns - kill_ns_) * 1e-6;
      reblend[id] = {{"detected_ms", detected_ms},
                     {"noticed_by", line.noticed_by},
                     {"shown_ms", shown_ms},
                     {"compose_ms", line.compose_ms},
                     {"frame", report::ToJson(line)["frame"]}};
      reblend_max_ms = std::max(reblend_max_ms, shown_ms);
    }
    if (!reblend.empty()) {
      result_.live["reblend_ms_max"] = reblend_max_ms;
      result_.live["node_huge_pages"] = options_.node_huge_pages == "on";
      result_.live["reblend"] = reblend;
      result_.live["recalibrated_after_the_kill"] = recalibrated.size();
    }
    result_.kill = {{"unit", unit},
                    {"at_s", kill_at_s_},
                    {"counted_from", options_.kill_after_calibration ? "hold" : "calibration"},
                    {"during_calibration", killed_while_calibrating_},
                    {"others_calibrated", finished},
                    {"others_recalibrated_after_the_kill", recalibrated}};
  }

  // --kill-coordinator-at-s: SIGKILL the coordinator that long into the hold and start a new
  // one at once on the same database and endpoints (the nodes reconnect by themselves).
  void MaybeKillCoordinator() {
    if (options_.kill_coordinator_at_s < 0 || coordinator_killed_) return;
    const auto now = std::chrono::steady_clock::now();
    if (now - hold_started_ < std::chrono::duration<double>(options_.kill_coordinator_at_s)) return;
    coordinator_killed_ = true;
    for (const auto& child : supervisor_.children()) {
      if (child->spec().role != "coordinator" || child->exited()) continue;
      supervisor_.ExpectExit(child.get());
      intended_kills_.insert(child->name());
      child->Signal(SIGKILL);
      child->WaitFor(milliseconds(5000));
    }
    coordinator_kill_ms_ = SystemMs();
    ST_LOG(kWarning) << "lab: killed the coordinator (--kill-coordinator-at-s); restarting it";
    const std::string requests = coordinator_requests_, events = coordinator_events_;
    coordinator_events_.clear();
    ChildProcess* restarted =
        StartChild("coordinator-2", "coordinator", CoordinatorArgs(requests, events));
    if (!restarted) return;
    const WaitOutcome ready =
        supervisor_.WaitUntil([&] { return !coordinator_events_.empty(); },
                              ToMs(options_.start_timeout_s), stop_, Handler());
    coordinator_restart_ms_ = ready == WaitOutcome::kDone ? SystemMs() - coordinator_kill_ms_ : -1;
    if (coordinator_events_.empty()) coordinator_events_ = events;
  }

  // Frames each other node showed in [from_ms, from_ms + window_ms) against those it showed in
  // the same span just before from_ms: the frames a fault cost the others (largest per node).
  // Nodes draw on change, so the span before is what the show asked of them; a pace taken from
  // the median interval of the few frames a quiet hold shows (before 2026-12-04) made two frames
  // 36 ms apart predict 83 in 3 s.
  int FramesLost(int64_t from_ms, int64_t window_ms, const std::set<NodeId>& skip) {
    if (options_.render == "off") return -1;
    if (frame_times_.empty()) {
      Expected<std::string> log = ReadInputFile(FrameLogPath(), size_t{256} << 20, "256 MiB");
      if (!log.ok()) return -1;
      std::istringstream lines(*log);
      std::string line;
      while (std::getline(lines, line)) {
        const json j = json::parse(line, nullptr, false);
        if (!j.is_object() || !j.contains("projector") || !j.contains("time_ms")) continue;
        frame_times_[j["projector"].get<NodeId>()].push_back(j["time_ms"].get<int64_t>());
      }
    }
    int worst = 0;
    for (const auto& [id, times] : frame_times_) {
      if (skip.count(id)) continue;
      int before = 0, after = 0;
      for (const int64_t t : times) {
        if (t >= from_ms - window_ms && t < from_ms) ++before;
        if (t >= from_ms && t < from_ms + window_ms) ++after;
      }
      worst = std::max(worst, before - after);
    }
    return worst;
  }

  // The chaos section: every fault of the hold, the annotations, the nodes' link faults.
  void RecordChaos() {
    const bool any = Chaos() || options_.fault_unit >= 0 ||
                     (options_.kill_unit >= 0 && options_.kill_after_calibration) ||
                     options_.stall_unit >= 0;
    if (!any) return;
    json chaos = {{"faults", json::array()}};
    constexpr int64_t kWindowMs = 3000;
    const double hold_ms = static_cast<double>(hold_started_ms_);
    if (killed_ && options_.kill_after_calibration) {
      const NodeId unit = static_cast<NodeId>(options_.kill_unit);
      json f = {{"fault", "SIGKILL node-" + std::to_string(unit)}, {"at_s", kill_at_s_}};
      double detected = -1;
      const json reblends = result_.live.value("reblend", json::object());
      for (const auto& [id, r] : reblends.items()) {
        const double d = r.value("detected_ms", -1.0);
        if (d >= 0 && (detected < 0 || d < detected)) detected = d;
      }
      if (detected >= 0) f["detected_ms"] = detected;
      if (result_.live.contains("reblend_ms_max")) {
        f["recovered_ms"] = result_.live["reblend_ms_max"];
        f["note"] = "recovered: the last neighbour's first re-blended frame";
      }
      const int64_t kill_ms = static_cast<int64_t>(hold_ms + kill_at_s_ * 1e3);
      if (int lost = FramesLost(kill_ms, kWindowMs, {unit}); lost >= 0) f["frames_lost_max"] = lost;
      chaos["faults"].push_back(f);
    }
    if (!result_.stall.is_null()) {
      const NodeId unit = static_cast<NodeId>(options_.stall_unit);
      json f = {{"fault", "SIGSTOP node-" + std::to_string(unit) + " for " +
                              FixedDigits(options_.stall_for_s, 1) + " s"},
                {"at_s", result_.stall.value("stopped_at_s", 0.0)},
                {"note", options_.stall_after_calibration
                             ? "stopped while the site showed"
                             : "at: counted from the calibration phase's start"}};
      if (options_.stall_after_calibration) {
        const int64_t at_ms =
            hold_started_ms_ + static_cast<int64_t>(result_.stall.value("stopped_at_s", 0.0) * 1e3);
        if (int lost = FramesLost(at_ms, kWindowMs, {unit}); lost >= 0) f["frames_lost_max"] = lost;
      }
      chaos["faults"].push_back(f);
    }
    if (coordinator_killed_) {
      json f = {{"fault", "SIGKILL coordinator, restart on the same database"},
                {"at_s", (coordinator_kill_ms_ - hold_started_ms_) * 1e-3}};
      if (coordinator_restart_ms_ >= 0) f["detected_ms"] = coordinator_restart_ms_;
      std::string note = "detected: the new coordinator ready";
      if (painter_) {
        // The painter's clock starts with the hold (within a millisecond).
        const double kill_s = (coordinator_kill_ms_ - hold_started_ms_) * 1e-3;
        const double back_s = painter_->FirstAckAfter(kill_s);
        if (back_s >= 0) {
          f["recovered_ms"] = (back_s - kill_s) * 1e3;
          note += "; recovered: the first annotation acknowledged after it";
        }
      }
      f["note"] = note;
      if (int lost = FramesLost(coordinator_kill_ms_, kWindowMs, {}); lost >= 0) {
        f["frames_lost_max"] = lost;
      }
      chaos["faults"].push_back(f);
    }
    if (options_.fault_unit >= 0) {
      chaos["faults"].push_back(
          {{"fault", "node-" + std::to_string(options_.fault_unit) + " drops " +
                         FixedDigits(options_.fault_drop_share * 100, 1) + " % and corrupts " +
                         FixedDigits(options_.fault_corrupt_share * 100, 1) +
                         " % of what it sends (whole run)"},
           {"at_s", 0.0},
           {"note", "counts: chaos.links"}});
    }
    if (painter_) {
      LabPainterResult painted = painter_->Verify(ToMs(10));
      chaos["annotations"] = painted.ToJson();
    }
    result_.chaos = chaos;
  }

  // After the teardown: the nodes' exit lines (link faults, rejected messages) and crashes.
  void FinishChaos(const std::vector<std::string>& killed_at_teardown) {
    if (result_.chaos.is_null()) return;
    json links = json::object();
    for (const auto& child : supervisor_.children()) {
      if (child->spec().role != "node") continue;
      const fs::path log = fs::path(options_.out_dir) / "logs" / (child->name() + ".log");
      Expected<std::string> text = ReadInputFile(log.string(), size_t{64} << 20, "64 MiB");
      if (!text.ok()) continue;
      std::istringstream lines(*text);
      std::string line;
      while (std::getline(lines, line)) {
        // The node's exit line (report::Messages) among its log's lines.
        if (line.empty() || line[0] != '{') continue;
        Expected<report::ReportLine> parsed = report::ParseReportLineText(line);
        if (parsed.ok() && std::holds_alternative<report::Messages>(*parsed)) {
          links[child->name()] = report::ToJson(*parsed);
        }
      }
    }
    result_.chaos["links"] = links;
    int crashed = 0;
    json crashes = json::array();
    for (const auto& child : supervisor_.children()) {
      if (intended_kills_.count(child->name())) continue;
      const std::string exit = child->DescribeExit();
      const bool hung = std::find(killed_at_teardown.begin(), killed_at_teardown.end(),
                                  child->name()) != killed_at_teardown.end();
      if (exit != "exit status 0" || hung) {
        ++crashed;
        crashes.push_back({{"name", child->name()}, {"exit", exit}, {"hung", hung}});
      }
    }
    result_.chaos["processes_crashed"] = crashed;
    result_.chaos["crashes"] = crashes;
  }

  bool Calibrate() {
    const int n = ExpectedUnits();
    Phase("calibration held", n);
    // A node that reports it could not calibrate is done too: the report names it and why.
    // With saved calibrations: when one does not hold (or a unit has none) a round runs, and
    // every unit's result must then come from it (a unit whose saved one held reports twice).
    calibration_started_ = std::chrono::steady_clock::now();
    auto done = [&] {
      MaybeKill();
      MaybeStall();
      if (static_cast<int>(calibrated_.size() + calibration_failed_.size()) < n) return false;
      bool round_needed = static_cast<int>(given_saved_.size()) < n;
      for (const auto& [id, line] : verification_) round_needed |= !line.holds;
      if (!round_needed) return true;
      for (const auto& [id, line] : calibrated_) {
        if (line.verified) return false;
      }
      return true;
    };
    const bool held = Wait(
        "calibration held", done, ToMs(options_.calibration_timeout_s),
        "not every sandtable-node reported a calibration "
        "{\"calibrated\":N,\"source\":..,\"json\":..,\"yaml\":..}",
        nullptr, [&] { return static_cast<int>(calibrated_.size()); },
        [&] {
          std::set<NodeId> have;
          for (const auto& [id, line] : calibrated_) have.insert(id);
          return Missing(have);
        });
    // A stall that outlasts the calibration ends with it (the show needs every node).
    if (stall_state_ == StallState::kStopped) Stall(false);
    return held;
  }

  // ---- the show (docs/render.md) ----

  // A request to the coordinator or the world from the lab's own DEALER; the reply whose body
  // is `reply_case`, within `timeout`.
  Expected<wire::Envelope> Call(const std::string& endpoint, wire::Envelope request,
                                wire::Envelope::BodyCase reply_case, milliseconds timeout) {
    net::SocketOptions socket_options;
    if (site_keys_) socket_options.curve = net::ClientCurve(*site_keys_);
    Expected<std::unique_ptr<net::Socket>> socket =
        net::Socket::Create(&zmq_context_, net::SocketType::kDealer, socket_options);
    if (!socket.ok()) return socket.status();
    ST_RETURN_IF_ERROR((*socket)->Connect(endpoint));
    net::Channel channel(std::move(*socket), kLabSenderId, ++lab_incarnation_, &lab_counters_);
    ST_RETURN_IF_ERROR(channel.Send(std::move(request)));
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < until) {
      std::vector<bool> readable;
      ST_RETURN_IF_ERROR(net::Socket::Poll({&channel.socket()}, milliseconds(50), &readable));
      Expected<std::optional<net::Incoming>> in = channel.TryReceive();
      if (in.ok() && *in && (*in)->envelope.body_case() == reply_case) {
        return std::move((*in)->envelope);
      }
    }
    return UnavailableError("no reply from " + endpoint + " within " +
                            std::to_string(timeout.count()) + " ms");
  }

  // Runs `work` on a thread while the children are watched; false (failure recorded) when a
  // child dies or the run is interrupted.
  template <typename T>
  bool Watched(const std::string& phase, std::function<T()> work, T* out) {
    std::future<T> future = std::async(std::launch::async, std::move(work));
    const auto ready = [&] {
      return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    };
    const WaitOutcome outcome = supervisor_.WaitUntil(ready, ToMs(3600), stop_, Handler());
    if (outcome != WaitOutcome::kDone) {
      future.wait();
      return Failed(phase, outcome, "", nullptr);
    }
    *out = future.get();
    return true;
  }

  Status SetPattern(const std::string& pattern) {
    wire::Envelope request;
    request.mutable_test_pattern_request()->set_all_nodes(true);
    request.mutable_test_pattern_request()->set_pattern(pattern);
    Expected<wire::Envelope> reply = Call(coordinator_requests_, std::move(request),
                                          wire::Envelope::kTestPatternReply, ToMs(10));
    if (!reply.ok()) return reply.status();
    if (!reply->test_pattern_reply().accepted()) {
      return InvalidArgumentError("pattern refused: " + reply->test_pattern_reply().reason());
    }
    return OkStatus();
  }

  Expected<TopView> TopViewOf(const std::vector<NodeId>& lit) {
    wire::Envelope request;
    for (NodeId id : lit) request.mutable_top_view_request()->add_projector_ids(id);
    request.mutable_top_view_request()->set_width_px(
        static_cast<uint32_t>(options_.grid_view_width_px));
    Expected<wire::Envelope> reply =
        Call(world_endpoint_, std::move(request), wire::Envelope::kTopViewReply, ToMs(300));
    if (!reply.ok()) return reply.status();
    const wire::TopViewReply& r = reply->top_view_reply();
    if (!r.ok()) return UnavailableError(r.message());
    TopView view;
    view.luminance =
        cv::Mat(static_cast<int>(r.height_px()), static_cast<int>(r.width_px()), CV_32FC1);
    if (r.luminance().size() != view.luminance.total() * sizeof(float)) {
      return ParseError("top view: the luminance does not fill the image");
    }
    std::memcpy(view.luminance.data, r.luminance().data(), r.luminance().size());
    view.area_min_m = Eigen::Vector2d(r.area_min_in_table_m().x(), r.area_min_in_table_m().y());
    view.area_max_m = Eigen::Vector2d(r.area_max_in_table_m().x(), r.area_max_in_table_m().y());
    return view;
  }

  // The top view's pixels whose surface seen from above is the table (the truth's scene, cast
  // straight down): the grid is compared there.
  cv::Mat TableMask(const std::map<NodeId, TopView>& views) const {
    if (views.empty()) return cv::Mat();
    const TopView& v = views.begin()->second;
    Expected<std::unique_ptr<RayCaster>> caster =
        RayCaster::Create(std::make_shared<const Scene>(scene_));
    if (!caster.ok()) return cv::Mat();
    cv::Mat mask(v.luminance.size(), CV_8UC1, cv::Scalar(0));
    const Eigen::Vector2d span = v.area_max_m - v.area_min_m;
    const double top_m = scene_.Bounds().max().z() + 1.0;
    for (int y = 0; y < mask.rows; ++y) {
      for (int x = 0; x < mask.cols; ++x) {
        const Eigen::Vector2d xy =
            v.area_min_m + Eigen::Vector2d((x + 0.5) / mask.cols * span.x(),
                                           (1.0 - (y + 0.5) / mask.rows) * span.y());
        const std::optional<RayHit> hit =
            (*caster)->Intersect(Eigen::Vector3d(xy.x(), xy.y(), top_m), -Eigen::Vector3d::UnitZ());
        if (hit && std::abs(hit->point_in_table_m.z()) < 1e-3) mask.at<uint8_t>(y, x) = 255;
      }
    }
    return mask;
  }

  // Waits until every calibrated unit has shown `pattern` (the phase goes on).
  bool WaitForPattern(const std::string& pattern) {
    const auto done = [&] {
      for (const auto& [id, line] : calibrated_) {
        auto it = render_pattern_.find(id);
        if (it == render_pattern_.end() || it->second != pattern) return false;
      }
      return true;
    };
    const WaitOutcome outcome = supervisor_.WaitUntil(done, ToMs(60), stop_, Handler());
    if (outcome == WaitOutcome::kDone) return true;
    return Failed("show", outcome, "not every calibrated node showed the pattern '" + pattern + "'",
                  nullptr);
  }

  bool Show() {
    if (options_.render == "off" || calibrated_.empty()) return true;
    if (!render_unavailable_.empty()) {
      // A node without GL runs without a show: the run goes on, the report says why.
      const auto& [id, why] = *render_unavailable_.begin();
      result_.render["error"] = "node-" + std::to_string(id) + " cannot render: " + why;
      return true;
    }
    Phase("show", 0);
    const fs::path dir(options_.out_dir);
    // 1. The table grid on every projector, seen from above one projector at a time.
    Status set = SetPattern("grid");
    if (!set.ok()) return FailedWith("show", "test pattern: " + set.ToString());
    if (!WaitForPattern("grid")) return false;
    std::vector<NodeId> units;
    for (const auto& [id, line] : calibrated_) units.push_back(id);
    struct Views {
      std::map<NodeId, TopView> each;
      std::optional<TopView> all;
      std::string error;
    };
    Views views;
    if (!Watched<Views>(
            "show",
            [this, units] {
              Views v;
              for (NodeId id : units) {
                Expected<TopView> view = TopViewOf({id});
                if (!view.ok()) {
                  v.error = view.status().ToString();
                  return v;
                }
                v.each[id] = std::move(*view);
              }
              if (Expected<TopView> all = TopViewOf({}); all.ok()) v.all = std::move(*all);
              return v;
            },
            &views)) {
      return false;
    }
    if (!views.error.empty()) return FailedWith("show", "top view: " + views.error);
    Expected<GridCoincidence> grid = MeasureGridCoincidence(views.each, TableMask(views.each));
    result_.render["grid"] =
        grid.ok() ? grid->ToJson() : nlohmann::json{{"error", grid.status().message()}};
    // Each projector's output alone, as it lands on the table (the report's per-projector view).
    for (const auto& [id, view] : views.each) {
      const std::string png = "show_grid_top_unit-" + std::to_string(id) + ".png";
      if (io::WritePngFile((dir / png).string(), LuminancePicture(view.luminance)).ok()) {
        result_.render["unit_grid_top_png"][std::to_string(id)] = png;
      }
    }
    if (views.all) {
      if (io::WritePngFile((dir / "show_grid_top.png").string(),
                           LuminancePicture(views.all->luminance))
              .ok()) {
        result_.render["grid_top_png"] = "show_grid_top.png";
      }
    }
    // 2. The show: the lab's personnel tracks play for show_s.
    set = SetPattern("none");
    if (!set.ok()) return FailedWith("show", "test pattern: " + set.ToString());
    if (!WaitForPattern("none")) return false;
    wire::Envelope play;
    play.mutable_play();
    Expected<wire::Envelope> played =
        Call(coordinator_requests_, std::move(play), wire::Envelope::kTimelineReply, ToMs(10));
    if (!played.ok() || !played->timeline_reply().accepted()) {
      return FailedWith("show", "timeline play: " + (played.ok() ? played->timeline_reply().reason()
                                                                 : played.status().ToString()));
    }
    const WaitOutcome outcome =
        supervisor_.WaitUntil([] { return false; }, ToMs(options_.show_s), stop_, Handler());
    if (outcome != WaitOutcome::kDeadline) return Failed("show", outcome, "", nullptr);
    Views shown;
    if (!Watched<Views>(
            "show",
            [this] {
              Views v;
              Expected<TopView> all = TopViewOf({});
              if (all.ok()) {
                v.all = std::move(*all);
              } else {
                v.error = all.status().ToString();
              }
              return v;
            },
            &shown)) {
      return false;
    }
    if (shown.all &&
        io::WritePngFile((dir / "show_top.png").string(), LuminancePicture(shown.all->luminance))
            .ok()) {
      result_.render["show_top_png"] = "show_top.png";
    }
    wire::Envelope pause;
    pause.mutable_pause();
    (void)Call(coordinator_requests_, std::move(pause), wire::Envelope::kTimelineReply, ToMs(10));
    std::map<NodeId, std::string> logs;
    for (NodeId id : units) {
      logs[id] = (dir / "logs" / ("render-" + std::to_string(id) + ".csv")).string();
    }
    // The logs are flushed once a second: wait for the last frames of the show.
    (void)supervisor_.WaitUntil([] { return false; }, ToMs(1.2), stop_, Handler());
    Expected<TimelineSkew> skew = MeasureTimelineSkew(logs);
    result_.render["timeline_skew"] =
        skew.ok() ? skew->ToJson() : nlohmann::json{{"error", skew.status().message()}};
    if (skew.ok()) result_.render["timeline_skew_ms_p99"] = skew->p99_ms;
    progress_.End();
    return true;
  }

  // The world's truth of one projector at points (one sample per point, in order).
  Expected<wire::GroundTruthReply> GroundTruth(NodeId projector,
                                               const std::vector<Eigen::Vector3d>& points) {
    wire::Envelope request;
    wire::GroundTruthRequest* r = request.mutable_ground_truth_request();
    r->set_projector_id(projector);
    for (const Eigen::Vector3d& p : points) {
      wire::Vector3* v = r->add_points_in_table_m();
      v->set_x(p.x());
      v->set_y(p.y());
      v->set_z(p.z());
    }
    Expected<wire::Envelope> reply =
        Call(world_endpoint_, std::move(request), wire::Envelope::kGroundTruthReply, ToMs(300));
    if (!reply.ok()) return reply.status();
    const wire::GroundTruthReply& g = reply->ground_truth_reply();
    if (!g.ok() || g.samples_size() != static_cast<int>(points.size())) {
      return UnavailableError("ground truth: " + g.message());
    }
    return g;
  }

  // The luminance of each point from that projector (0 where it does not light it).
  Expected<std::vector<double>> TruthLuminance(NodeId projector,
                                               const std::vector<Eigen::Vector3d>& points) {
    Expected<wire::GroundTruthReply> g = GroundTruth(projector, points);
    if (!g.ok()) return g.status();
    std::vector<double> out(points.size(), 0.0);
    for (int i = 0; i < g->samples_size(); ++i) {
      if (g->samples(i).visible()) out[i] = g->samples(i).luminance_cd_per_m2();
    }
    return out;
  }

  // Whether that projector can project at each point, lights it, and its pixel there.
  Expected<std::vector<SampleTruth>> TruthSamples(NodeId projector,
                                                  const std::vector<Eigen::Vector3d>& points) {
    Expected<wire::GroundTruthReply> g = GroundTruth(projector, points);
    if (!g.ok()) return g.status();
    std::vector<SampleTruth> out(points.size());
    for (int i = 0; i < g->samples_size(); ++i) {
      const wire::GroundTruthSample& sample = g->samples(i);
      out[i].projectable = sample.projectable();
      out[i].visible = sample.visible();
      out[i].pixel_px = Eigen::Vector2d(sample.projector_px().x(), sample.projector_px().y());
    }
    return out;
  }

  // Where the table's steps over the bound lie (PlaceSteps), in every calibrated
  // projector's truth.
  Expected<json> PlaceTableSteps(const StepStats& steps, const TopView& view, double bound_pct) {
    const Eigen::Vector2d span = view.area_max_m - view.area_min_m;
    auto at = [&](double x, double y) {
      return Eigen::Vector3d(
          view.area_min_m.x() + (x + 0.5) / view.luminance.cols * span.x(),
          view.area_min_m.y() + (1.0 - (y + 0.5) / view.luminance.rows) * span.y(), 0.0);
    };
    std::vector<ProjectorSize> projectors;
    for (const UnitSpec& unit : inputs_.site.units) {
      if (!calibrated_.count(unit.id)) continue;
      projectors.push_back(
          {unit.id, unit.projector.model.width_px, unit.projector.model.height_px});
    }
    Expected<StepPlaces> places =
        PlaceSteps(steps, bound_pct, at, projectors,
                   [this](NodeId id, const std::vector<Eigen::Vector3d>& points) {
                     return TruthSamples(id, points);
                   });
    if (!places.ok()) return places.status();
    return places->ToJson(bound_pct);
  }

  bool Blend() {
    if (options_.render == "off" || options_.blend == "off" || calibrated_.empty() ||
        !render_unavailable_.empty()) {
      return true;
    }
    Phase("blend", static_cast<int>(calibrated_.size()));
    const fs::path dir(options_.out_dir);
    // 1. Every calibrated node has shown a blend and none has changed it for settle.
    const auto settle = std::chrono::milliseconds(1500);
    // Settled: every node's last mask holds the field of every unit it overlaps (none is
    // `waiting_for` one), and no node has shown a new one for `settle`. A node still waiting
    // after a minute is measured as it is and named in `photometric.unsettled`.
    // Only units that calibrated count: one that failed (or was killed) never shares a field.
    auto waiting = [&](const report::BlendShown& line) {
      for (NodeId unit : line.waiting_for) {
        if (calibrated_.count(unit)) return true;
      }
      return false;
    };
    const WaitOutcome settled = supervisor_.WaitUntil(
        [&] {
          progress_.Update(static_cast<int>(blend_.size()));
          for (const auto& [id, line] : calibrated_) {
            auto it = blend_.find(id);
            if (it == blend_.end() || waiting(it->second)) return false;
          }
          return std::chrono::steady_clock::now() - last_blend_line_ > settle;
        },
        ToMs(60), stop_, Handler());
    if (settled != WaitOutcome::kDone && settled != WaitOutcome::kDeadline) {
      return Failed("blend", settled, "", nullptr);
    }
    json unsettled = json::object();
    for (const auto& [id, line] : calibrated_) {
      auto it = blend_.find(id);
      if (it == blend_.end()) {
        unsettled[std::to_string(id)] = "no blend shown";
      } else if (waiting(it->second)) {
        unsettled[std::to_string(id)] = it->second.waiting_for;
      }
    }
    if (blend_.empty()) return FailedWith("blend", "no node showed a blend within a minute");
    // 2. Raw white, then white through the full pipeline (the blend), seen from above.
    struct Views {
      std::optional<TopView> view;
      std::string error;
    };
    auto top = [this](const std::string& pattern, Views* out) {
      Status set = SetPattern(pattern);
      if (!set.ok()) return FailedWith("blend", "test pattern: " + set.ToString());
      if (!WaitForPattern(pattern)) return false;
      return Watched<Views>(
          "blend",
          [this] {
            Views v;
            Expected<TopView> all = TopViewOf({});
            if (all.ok()) {
              v.view = std::move(*all);
            } else {
              v.error = all.status().ToString();
            }
            return v;
          },
          out);
    };
    Views before, after, black;
    if (!top("raw-white", &before) || !top("black", &black) || !top("white", &after)) {
      return false;
    }
    if (!before.view || !after.view || !black.view) {
      return FailedWith("blend", "top view: " + before.error + black.error + after.error);
    }
    // 3. Walls and roofs: the truth at lattice points, with white still shown.
    struct Measured {
      json photometric = json::object();
      cv::Mat over;
      std::string error;
    };
    Measured measured;
    if (!Watched<Measured>(
            "blend",
            [this, &before, &after, &black] {
              Measured m;
              const auto start = std::chrono::steady_clock::now();
              auto scene = std::make_shared<const Scene>(scene_);
              Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene);
              if (!caster.ok()) {
                m.error = caster.status().ToString();
                return m;
              }
              const FaceGroups faces = GroupFaces(*scene);
              std::vector<StraddleTest::Projector> projectors;
              for (const UnitSpec& unit : inputs_.site.units) {
                if (!calibrated_.count(unit.id)) continue;
                projectors.push_back(
                    {unit.projector.model, unit.projector.table_from_projector.Inverse()});
              }
              const StraddleTest straddle(projectors, **caster, faces);
              const TopView& b = *before.view;
              const TopView& a = *after.view;
              const cv::Mat ids =
                  TopViewFaceIds(**caster, faces, a.area_min_m, a.area_max_m, a.luminance.size());
              const cv::Mat straddled = TopViewStraddled(**caster, straddle, a.area_min_m,
                                                         a.area_max_m, a.luminance.size());
              const double lit = kLitAmbientFactor * inputs_.site.ambient_luminance_nits;
              const int spacing_px =
                  std::max(1, static_cast<int>(std::lround(kStepSpacing_m * 1e3 / a.mm_per_px())));
              json p = json::object();
              const StepStats table =
                  MeasureImageSteps(a.luminance, ids, faces, SurfaceKind::kTable, spacing_px, lit,
                                    &m.over, straddled);
              const StepStats roof_top = MeasureImageSteps(
                  a.luminance, ids, faces, SurfaceKind::kRoof, spacing_px, lit, nullptr, straddled);
              const StepStats table_before =
                  MeasureImageSteps(b.luminance, ids, faces, SurfaceKind::kTable, spacing_px, lit,
                                    nullptr, straddled);
              // Every projector black: where footprints overlap their black levels add up (on top
              // of the site's ambient light). Measured on the table the blended white lights (the
              // display area; outside every footprint nothing can be lifted), every pixel of it.
              cv::Mat black_ids = ids.clone();
              black_ids.setTo(-1, a.luminance <= lit);
              const StepStats black_table =
                  MeasureImageSteps(black.view->luminance, black_ids, faces, SurfaceKind::kTable,
                                    spacing_px, 0.0, nullptr, straddled);
              p["black"] = black_table.ToJson();
              p["black_step_pct"] = black_table.max_pct;
              p["black_match"] = options_.black_match == "on";
              p["table"] = table.ToJson();
              Expected<json> places = PlaceTableSteps(table, a, kTableStepBoundPct);
              if (!places.ok()) {
                m.error = places.status().ToString();
                return m;
              }
              p["table"]["over_bound"] = *places;
              p["roofs_from_above"] = roof_top.ToJson();
              p["table_unblended"] = table_before.ToJson();
              p["uniformity_min_over_max"] =
                  TableUniformity(a.luminance, ids, faces, lit, straddled);
              p["uniformity_unblended"] = TableUniformity(b.luminance, ids, faces, lit, straddled);
              for (SurfaceKind kind : {SurfaceKind::kWall, SurfaceKind::kRoof}) {
                const SurfaceLattice lattice = SampleFaces(*scene, faces, kind, kStepSpacing_m);
                std::vector<double> l(lattice.points_in_table_m.size(),
                                      inputs_.site.ambient_luminance_nits);
                for (const auto& [id, line] : calibrated_) {
                  Expected<std::vector<double>> t = TruthLuminance(id, lattice.points_in_table_m);
                  if (!t.ok()) {
                    m.error = t.status().ToString();
                    return m;
                  }
                  for (size_t i = 0; i < l.size(); ++i) l[i] += (*t)[i];
                }
                const StepStats steps = MeasureSampleSteps(l, lattice, lit, &straddle);
                p[kind == SurfaceKind::kWall ? "walls" : "roofs"] = steps.ToJson();
              }
              p["max_step_pct_per_5mm"] = {{"table", table.max_pct},
                                           {"walls", p["walls"]["max_pct"]},
                                           {"roofs", p["roofs"]["max_pct"]}};
              p["p99_step_pct_per_5mm"] = {{"table", table.p99_pct},
                                           {"walls", p["walls"]["p99_pct"]},
                                           {"roofs", p["roofs"]["p99_pct"]}};
              p["measure_s"] =
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
              m.photometric = p;
              return m;
            },
            &measured)) {
      return false;
    }
    if (!measured.error.empty()) return FailedWith("blend", "measure: " + measured.error);
    json& p = measured.photometric;
    // The nodes' figures: level, cast and compose times, bytes, neighbours.
    json nodes = json::object();
    double cast_ms_max = 0.0, bytes_max = 0.0;
    for (const auto& [id, line] : blend_) {
      nodes[std::to_string(id)] = report::ToJson(line);
      cast_ms_max = std::max(cast_ms_max, line.cast_ms);
      bytes_max = std::max(bytes_max, static_cast<double>(line.bytes_sent + line.bytes_received));
      p["level_per_m2"] = line.level_per_m2;
    }
    p["nodes"] = nodes;
    p["blend_cast_ms_max"] = cast_ms_max;
    p["bytes_per_node_max"] = bytes_max;
    // Pictures.
    auto write = [&](const std::string& name, const cv::Mat& image, const std::string& key) {
      if (io::WritePngFile((dir / name).string(), image).ok()) p["pictures"][key] = name;
    };
    write("blend_before_top.png", LuminancePicture(before.view->luminance), "before");
    write("blend_after_top.png", LuminancePicture(after.view->luminance), "after");
    write("blend_steps_over_1pct.png", measured.over, "steps_over_1pct");
    for (const auto& [id, line] : blend_) {
      const fs::path alpha = dir / "calibration" / ("blend-" + std::to_string(id) + ".png");
      if (fs::exists(alpha)) {
        p["pictures"]["alpha"][std::to_string(id)] = fs::relative(alpha, dir).string();
      }
    }
    // A late unit's join: from its calibrated line to each neighbour's first mask with it.
    if (join_calibrated_ns_ > 0) {
      const NodeId late = static_cast<NodeId>(options_.join_late);
      json join = json::object();
      double join_max_ms = 0.0;
      for (const report::BlendShown& line : blended_lines_) {
        const NodeId id = line.id;
        if (id == late || join.contains(std::to_string(id))) continue;
        const std::vector<NodeId>& n = line.neighbours;
        if (std::find(n.begin(), n.end(), late) == n.end()) continue;
        const double ms = (line.shown_ns - join_calibrated_ns_) * 1e-6;
        join[std::to_string(id)] = ms;
        join_max_ms = std::max(join_max_ms, ms);
      }
      if (!join.empty()) {
        result_.live["join_reblend_ms"] = join_max_ms;
        result_.live["join_reblend"] = join;
      }
    }
    if (!unsettled.empty()) p["unsettled"] = unsettled;
    result_.photometric = p;
    Status set = SetPattern("none");
    if (!set.ok()) return FailedWith("blend", "test pattern: " + set.ToString());
    progress_.End();
    return true;
  }

  bool Hold() {
    if (options_.hold_s <= 0) return true;
    Phase("hold", 0);
    hold_started_ = std::chrono::steady_clock::now();
    hold_started_ms_ = SystemMs();
    if (options_.annotate) {
      LabPainterOptions painter;
      painter.requests_endpoint = coordinator_requests_;
      painter.site_keys = site_keys_;
      if (Status checked = painter.Check(); !checked.ok()) {
        return FailedWith("hold", checked.ToString());
      }
      painter_ = std::make_unique<LabPainter>(painter);
      painter_->Start();
    }
    const WaitOutcome outcome = supervisor_.WaitUntil(
        [&] {
          MaybeKill();
          MaybeStall();
          MaybeKillCoordinator();
          return false;
        },
        ToMs(options_.hold_s), stop_, Handler());
    if (painter_) painter_->Stop();
    if (outcome == WaitOutcome::kDeadline) {
      progress_.End();
      return true;
    }
    return Failed("hold", outcome, "", nullptr);
  }

  bool Measure() {
    RecordKill();
    RecordChaos();
    Phase("metrics", result_.num_units);
    std::vector<EstimatedRegistration> estimates;
    std::set<std::string> sources;
    for (const auto& [id, why] : calibration_failed_) result_.unit_failures[id] = why;
    for (const UnitSpec& unit : inputs_.site.units) {
      if (!calibrated_.count(unit.id)) continue;  // failed: named in the report
      const std::string path = calibrated_.at(unit.id).json;
      Expected<UnitCalibration> calibration = LoadUnitCalibration(path);
      if (!calibration.ok()) {
        return FailedWith("metrics", "unit " + std::to_string(unit.id) +
                                         ": cannot load its exported calibration: " +
                                         calibration.status().ToString());
      }
      if (!calibration->table_from_projector) {
        return FailedWith("metrics", path + ": no table_from_projector (unit not registered)");
      }
      LabUnitResult& unit_result = result_.units[unit.id];
      unit_result.source = calibration->source;
      unit_result.json_path = RelativeToOut(path);
      const std::string& yaml = calibrated_.at(unit.id).yaml;
      unit_result.yaml_path = RelativeToOut(yaml);
      // No OpenCV YAML is written when the model was not found (its R, T are model ->
      // projector); the report says so through the runner's report.
      if (!yaml.empty() && !fs::exists(yaml)) {
        return FailedWith("metrics", "unit " + std::to_string(unit.id) + ": its OpenCV YAML " +
                                         yaml + " is missing");
      }
      sources.insert(calibration->source);
      if (calibration->table_from_model) units_have_model_ = true;
      // The projector's response as its own camera measured it, against the world's.
      if (calibration->projector_response) {
        const ProjectorResponseRecord& r = *calibration->projector_response;
        json response = {{"gamma", r.gamma},
                         {"true_gamma", unit.projector.gamma},
                         {"gamma_error", r.gamma - unit.projector.gamma},
                         {"true_black_level", unit.projector.black_level}};
        if (r.black_level >= 0) {
          response["black_level"] = r.black_level;
          response["black_level_error"] = r.black_level - unit.projector.black_level;
        }
        if (!result_.photometric.is_object()) result_.photometric = json::object();
        json& p = result_.photometric;
        p["response"][std::to_string(unit.id)] = response;
        p["gamma_error"] =
            std::max(p.value("gamma_error", 0.0), std::abs(r.gamma - unit.projector.gamma));
        if (r.black_level >= 0) {
          p["black_level_error"] = std::max(p.value("black_level_error", 0.0),
                                            std::abs(r.black_level - unit.projector.black_level));
        }
      }
      estimates.push_back({unit.id, calibration->projector, *calibration->table_from_projector,
                           calibration->table_from_model.value_or(Rigid3d::Identity())});
    }
    result_.calibration_source = sources.size() == 1 ? *sources.begin() : "mixed";
    if (estimates.empty()) {
      return FailedWith("metrics", "no unit holds a calibration (every node reported a failure)");
    }
    // Where the model truly stands, in the frame the nodes' table_from_model refers to.
    result_.metric_options.true_table_from_model =
        TruePoseMode() ? Rigid3d::Identity() : inputs_.model_from_table.Inverse();
    CollectSelfCalibration();
    // The metric and the pictures run on a worker while the children stay watched.
    struct Work {
      std::optional<RegistrationReport> report;
      cv::Mat top, heatmap;
      double scale_mm = 0;
      std::string error;
      std::optional<ModelPlacementError> placement;
      bool true_placement = false;  // measured with the true model placement (none was found)
    };
    // The model's placement against the truth, when the nodes found it (structured light).
    const bool model_placement = !TruePoseMode() && units_have_model_;
    const Eigen::Vector3d model_centre = inputs_.model_from_table * scene_.Bounds().center();
    const RegistrationMetricOptions metric_options = result_.metric_options;
    const int width = options_.image_width_px;
    std::future<Work> future =
        std::async(std::launch::async,
                   [this, estimates, metric_options, width, model_placement, model_centre,
                    no_placement = !TruePoseMode() && !units_have_model_]() mutable -> Work {
                     Work work;
                     Expected<std::unique_ptr<World>> world = World::Create(inputs_.site, scene_);
                     if (!world.ok()) {
                       work.error = world.status().ToString();
                       return work;
                     }
                     if (no_placement) {
                       // The nodes found no placement of the model (a flat scene whose outline they
                       // do not see whole): the calibration is measured with the TRUE placement
                       // expressed in their table frame (related to the true one through table
                       // pixels), and the report says so (calibration.placement).
                       Expected<ModelPlacementError> frames = MeasureModelPlacement(
                           **world, estimates, metric_options.true_table_from_model, model_centre);
                       if (frames.ok()) {
                         for (EstimatedRegistration& e : estimates) {
                           e.table_from_model = frames->true_table_from_estimated_table.Inverse() *
                                                metric_options.true_table_from_model;
                         }
                         work.true_placement = true;
                       }
                     }
                     Expected<RegistrationReport> report =
                         MeasureRegistration(**world, estimates, metric_options);
                     if (!report.ok()) {
                       work.error = report.status().ToString();
                       return work;
                     }
                     work.report = std::move(*report);
                     if (model_placement) {
                       Expected<ModelPlacementError> placement = MeasureModelPlacement(
                           **world, estimates, metric_options.true_table_from_model, model_centre);
                       if (placement.ok()) work.placement = *placement;
                     }
                     if (Expected<cv::Mat> top = TopViewWhite(world->get(), width); top.ok()) {
                       work.top = *top;
                     }
                     work.scale_mm = std::max(1e-3, work.report->site.all.p99_mm);
                     if (Expected<cv::Mat> heat = RegistrationHeatmap(
                             **world, estimates, metric_options, width, work.scale_mm);
                         heat.ok()) {
                       work.heatmap = *heat;
                     }
                     return work;
                   });
    const auto ready = [&] {
      return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    };
    const WaitOutcome outcome = supervisor_.WaitUntil(ready, ToMs(3600), stop_, Handler());
    if (outcome != WaitOutcome::kDone) {
      future.wait();
      return Failed("metrics", outcome, "", nullptr);
    }
    Work work = future.get();
    if (!work.error.empty()) return FailedWith("metrics", "registration metric: " + work.error);
    result_.registration = std::move(work.report);
    result_.measured_with_true_placement = work.true_placement;
    if (work.placement) {
      result_.model_offset_measured = true;
      result_.model_offset_mm = work.placement->offset_mm;
      result_.model_offset_deg = work.placement->offset_deg;
    }
    result_.heatmap_scale_mm = work.scale_mm;
    const fs::path dir(options_.out_dir);
    // A picture that cannot be written is left out of the report, with the reason logged.
    if (!work.top.empty()) {
      const Status written = io::WritePngFile((dir / "top_white.png").string(), work.top);
      if (written.ok()) {
        result_.top_white_png = "top_white.png";
      } else {
        ST_LOG(kWarning) << written.ToString();
      }
    }
    if (!work.heatmap.empty()) {
      const Status written =
          io::WritePngFile((dir / "registration_error_top.png").string(), work.heatmap);
      if (written.ok()) {
        result_.heatmap_png = "registration_error_top.png";
      } else {
        ST_LOG(kWarning) << written.ToString();
      }
    }
    progress_.End();
    return true;
  }

  // The runner's report and each node's figures (docs/lab.md, "Self-calibration").
  void CollectSelfCalibration() {
    json& sc = result_.self_calibration;
    sc = json::object();
    for (const auto& [id, line] : calibrated_) {
      if (line.report.empty()) continue;
      Expected<std::string> text = ReadInputFile(line.report, size_t{16} << 20, "16 MiB");
      if (!text.ok()) continue;
      json parsed = json::parse(*text, nullptr, false);
      if (!parsed.is_discarded() && parsed.is_object()) sc["runner_report"] = parsed;
    }
    // The runner's MPCDI export, read back with the same reader as the files of other tools.
    for (const auto& [id, line] : calibrated_) {
      const std::string& path = line.mpcdi;
      if (path.empty()) continue;
      Expected<MpcdiSite> site = ReadMpcdi(path);
      if (!site.ok()) {
        sc["mpcdi"] = {{"path", path}, {"error", site.status().message()}};
        continue;
      }
      json regions = json::array();
      for (const MpcdiRegion& region : site->regions) {
        int samples = 0, hits = 0;
        if (region.warp) {
          samples = static_cast<int>(region.warp->samples.size());
          for (const Eigen::Vector3f& v : region.warp->samples) hits += v.allFinite();
        }
        regions.push_back({{"id", region.id},
                           {"resolution_px", {region.x_resolution_px, region.y_resolution_px}},
                           {"warp_samples", samples},
                           {"warp_samples_on_surface", hits},
                           {"alpha", region.alpha.has_value()},
                           {"alpha_mean", AlphaMean(region)}});
      }
      sc["mpcdi"] = {{"path", path}, {"profile", site->profile}, {"regions", regions}};
    }
    json per_unit = json::object();
    double slowest = 0.0;
    double messages = 0, bytes = 0;
    for (const auto& [id, line] : calibrated_) {
      json u = {{"compute_s", line.compute_s},
                {"messages_sent", line.messages_sent},
                {"messages_received", line.messages_received},
                {"bytes_sent", line.bytes_sent},
                {"bytes_received", line.bytes_received}};
      slowest = std::max(slowest, line.compute_s);
      messages += static_cast<double>(line.messages_sent + line.messages_received);
      bytes += static_cast<double>(line.bytes_sent + line.bytes_received);
      per_unit[std::to_string(id)] = u;
    }
    sc["per_unit"] = per_unit;
    if (!verification_.empty()) {
      json checks = json::object();
      for (const auto& [id, line] : verification_)
        checks[std::to_string(id)] = report::ToJson(line);
      sc["verification"] = checks;
    }
    bool round_ran = false;
    for (const auto& [id, line] : calibrated_) round_ran |= line.round != 0;
    sc["round_ran"] = round_ran;
    sc["compute_time_s"] = slowest;
    if (!calibrated_.empty()) {
      sc["messages_per_node"] = messages / calibrated_.size();
      sc["bytes_per_node"] = bytes / calibrated_.size();
    }
  }

  // The nodes' render summaries (their last lines, printed at exit) into the report: the
  // median p50 and floor, the worst p99.
  void CollectRender() {
    if (render_summary_.empty()) return;
    std::vector<double> p50, p99, floor;
    json units = json::object();
    for (const auto& [id, line] : render_summary_) {
      units[std::to_string(id)] = report::ToJson(line);
      if (line.frames > 0) {
        p50.push_back(line.frame_ms_p50);
        p99.push_back(line.frame_ms_p99);
        floor.push_back(line.floor_ms);
      }
    }
    result_.render["units"] = units;
    if (p50.empty()) return;
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    result_.render["frame_ms_p50"] = median(p50);
    result_.render["frame_ms_p99"] = *std::max_element(p99.begin(), p99.end());
    result_.render["floor_ms"] = median(floor);
    result_.render["context"] = render_summary_.begin()->second.context;
  }

  int Finish() {
    Phase("teardown", 0);
    if (stall_state_ == StallState::kStopped) Stall(false);  // a stopped child cannot exit
    const std::vector<std::string> killed = supervisor_.TearDown(ToMs(options_.teardown_grace_s));
    CollectRender();
    FinishChaos(killed);
    progress_.End(killed.empty() ? "ok" : "killed " + std::to_string(killed.size()));
    for (const auto& child : supervisor_.children()) {
      result_.processes.push_back({child->name(), child->spec().role, child->pid(),
                                   child->DescribeExit(), child->cpu_s(), child->max_rss_mb()});
    }
    result_.report_lines = supervisor_.report_lines().parsed;
    result_.bad_report_lines = supervisor_.report_lines().bad;
    result_.last_bad_report_line = supervisor_.report_lines().last_error;
    result_.phase_seconds = progress_.phase_seconds();
    result_.max_rms_mm = options_.verdict.max_rms_mm;
    result_.min_step_pairs = options_.verdict.min_step_pairs;
    result_.reasons = JudgeLabRun(result_, options_.verdict);
    if (!result_.reasons.empty()) result_.status = "failed";
    result_.total_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const Status written = WriteLabReport(result_, options_.out_dir);
    const std::string report_path = (fs::path(options_.out_dir) / "report.json").string();
    report::WriteReportLine(out_, report::LabDone{result_.status, report_path});
    if (!written.ok()) {
      err_ << "sandtable-lab run: " << written.ToString() << "\n";
      return kExitFailure;
    }
    if (result_.failure) {
      const LabFailure& f = *result_.failure;
      err_ << "sandtable-lab run: " << result_.status << " in phase '" << f.phase
           << "': " << f.reason << "\n";
      if (!f.log_tail.empty())
        err_ << "  last lines of " << f.log_path << ":\n" << JoinLines(f.log_tail);
      err_ << "  report: " << report_path << "\n";
      return result_.status == "interrupted" ? kExitInterrupted : kExitFailure;
    }
    if (result_.registration) {
      const ErrorStats& s = result_.registration->site.all;
      err_ << "sandtable-lab run: " << result_.site_name << ", calibration "
           << result_.calibration_source << ": rms " << s.rms_mm << " mm, p99 " << s.p99_mm
           << " mm, max " << s.max_mm << " mm, rms " << s.rms_px << " px\n";
    }
    for (const LabReason& reason : result_.reasons) {
      err_ << "sandtable-lab run: failed: " << reason.what << ": " << reason.detail << "\n";
    }
    err_ << "sandtable-lab run: report " << (fs::path(options_.out_dir) / "report.md").string()
         << "\n";
    return result_.reasons.empty() ? kExitOk : kExitVerdict;
  }

  // ---- helpers ----

  void Phase(const std::string& name, int total) {
    progress_.Begin(name, total);
    progress_phase_ = name;
    report::LabPhase line{name, std::nullopt};
    if (name == "hold") line.hold_s = options_.hold_s;
    report::WriteReportLine(out_, line);
  }

  std::string RelativeToOut(const std::string& path) const {
    std::error_code error;
    const fs::path relative = fs::relative(path, options_.out_dir, error);
    if (error || relative.empty() || *relative.begin() == "..") return path;
    return relative.string();
  }

  // GLIBC_TUNABLES with glibc's malloc on transparent huge pages (LabOptions::node_huge_pages),
  // added to what the lab's environment already tunes: hugetlb=1 puts the main heap (and mmap'd
  // chunks) on huge pages, arena_max=1 keeps every thread's allocations in that heap (the
  // threads' own arenas, ~190 MB of a node's ~360 MB, stayed on 4 KiB pages: a killed node's
  // sockets then closed 25-32 ms after the kill, 10-12 ms with them in the main heap).
  static std::vector<std::string> NodeHugePagesEnv() {
    const char* tunables = std::getenv("GLIBC_TUNABLES");
    std::string value = tunables != nullptr ? tunables : "";
    for (const char* tunable : {"glibc.malloc.hugetlb=1", "glibc.malloc.arena_max=1"}) {
      const std::string name = std::string(tunable).substr(0, std::string(tunable).find('='));
      if (value.find(name) == std::string::npos) {
        value += (value.empty() ? "" : ":") + std::string(tunable);
      }
    }
    return {"GLIBC_TUNABLES=" + value};
  }

  ChildProcess* StartChild(const std::string& name, const std::string& role,
                           std::vector<std::string> argv, std::vector<std::string> env = {}) {
    if (!curve_keys_path_.empty() && (role == "world" || role == "coordinator" || role == "node")) {
      argv.insert(argv.end(), {"--curve-keys", curve_keys_path_});
    }
    ChildSpec spec{name, role, std::move(argv),
                   (fs::path(options_.out_dir) / "logs" / (name + ".log")).string(),
                   std::move(env)};
    Expected<ChildProcess*> child = supervisor_.Start(spec);
    if (!child.ok()) {
      FailedWith(progress_phase_, "cannot start " + name + ": " + child.status().ToString());
      return nullptr;
    }
    return *child;
  }

  // The handler of every report line of every child (cluster/report_lines.h): readiness,
  // calibration, render and blend figures. A line of a kind a child's role does not print is
  // logged and left out.
  Supervisor::LineHandler Handler() {
    return [this](ChildProcess& child, const report::ReportLine& line) {
      const std::string& role = child.spec().role;
      const bool from_node = role == "node";
      std::visit(
          report::Overloaded{
              [&](const report::WorldReady& l) {
                if (role == "world") world_endpoint_ = l.world;
              },
              [&](const report::CoordinatorReady& l) {
                if (role != "coordinator") return;
                coordinator_requests_ = l.requests;
                coordinator_events_ = l.events;
              },
              [&](const report::NodeReady& l) {
                if (!from_node) return;
                nodes_ready_.insert(l.id);
                progress_.Update(static_cast<int>(nodes_ready_.size()));
              },
              [&](const report::CalibrationFailed& l) {
                if (!from_node) return;
                calibration_failed_[l.id] = l.reason.empty() ? "(no reason given)" : l.reason;
                if (progress_phase_ == "calibration held") {
                  progress_.Update(
                      static_cast<int>(calibrated_.size() + calibration_failed_.size()));
                }
              },
              [&](const report::RenderUnavailable& l) {
                if (from_node) render_unavailable_[l.id] = l.reason;
              },
              [&](const report::RenderPattern& l) {
                if (from_node) render_pattern_[l.id] = l.pattern;
              },
              [&](const report::RenderSummary& l) {
                if (from_node) render_summary_[l.id] = l;
              },
              [&](const report::BlendExported&) {
                if (from_node) last_blend_line_ = std::chrono::steady_clock::now();
              },
              [&](const report::BlendShown& l) {
                if (!from_node) return;
                last_blend_line_ = std::chrono::steady_clock::now();
                if (l.reblend) {
                  reblends_.push_back(l);
                } else {
                  blend_[l.id] = l;
                  blended_lines_.push_back(l);
                }
              },
              [&](const report::Verification& l) {
                if (from_node) verification_[l.id] = l;
              },
              [&](const report::Calibrated& l) {
                if (!from_node) return;
                calibrated_[l.id] = l;
                if (options_.join_late >= 0 && l.id == static_cast<NodeId>(options_.join_late)) {
                  join_calibrated_ns_ = SteadyNowNs();
                }
                if (progress_phase_ == "calibration held") {
                  progress_.Update(static_cast<int>(calibrated_.size()));
                }
              },
              [&](const report::Messages&) {},
              [&](const report::LabPhase&) {},
              [&](const report::LabDone&) {},
          },
          line);
    };
  }

  // Waits for `done`; on anything else records the failure (with `what` on a deadline) and
  // returns false.
  bool Wait(const std::string& phase, const std::function<bool()>& done, milliseconds deadline,
            const std::string& what, const ChildProcess* waited_for,
            const std::function<int()>& count = nullptr,
            const std::function<std::string()>& missing = nullptr) {
    if (count) progress_.Update(count());
    const WaitOutcome outcome = supervisor_.WaitUntil(done, deadline, stop_, Handler());
    if (outcome == WaitOutcome::kDone) {
      progress_.End();
      return true;
    }
    const std::string details = outcome == WaitOutcome::kDeadline && missing
                                    ? what + " (missing: " + missing() + ")"
                                    : what;
    return Failed(phase, outcome, details, waited_for);
  }

  // "node-1, node-2": the site's units not in `have`.
  std::string Missing(const std::set<NodeId>& have) const {
    std::string out;
    for (const UnitSpec& unit : inputs_.site.units) {
      if (!have.count(unit.id))
        out += (out.empty() ? "node-" : ", node-") + std::to_string(unit.id);
    }
    return out;
  }

  bool Failed(const std::string& phase, WaitOutcome outcome, const std::string& what,
              const ChildProcess* waited_for) {
    LabFailure f;
    f.phase = phase;
    const ChildProcess* child = nullptr;
    if (outcome == WaitOutcome::kChildDied) {
      child = supervisor_.dead_child();
      f.reason = child->name() + " died (" + child->DescribeExit() + ")";
      result_.status = "failed";
    } else if (outcome == WaitOutcome::kStopped) {
      f.reason = "interrupted (SIGINT/SIGTERM): the site was torn down";
      result_.status = "interrupted";
    } else {
      f.reason = what + " within the deadline (the report lines of cluster/report_lines.h)";
      child = waited_for;
      result_.status = "failed";
    }
    if (child) {
      f.child = child->name();
      f.role = child->spec().role;
      f.pid = child->pid();
      f.exit_text = child->DescribeExit();
      f.exit_code = child->exit_code();
      f.signal = child->term_signal();
      f.log_path = RelativeToOut(child->spec().log_path);
      f.log_tail = child->LogTail(kLogTailLines);
    }
    progress_.End(result_.status);
    result_.failure = std::move(f);
    return false;
  }

  bool FailedWith(const std::string& phase, const std::string& reason) {
    LabFailure f;
    f.phase = phase;
    f.reason = reason;
    result_.status = "failed";
    progress_.End("failed");
    result_.failure = std::move(f);
    return false;
  }

  const LabRunOptions& options_;
  const std::atomic<bool>& stop_;
  std::ostream& out_;
  std::ostream& err_;
  Progress progress_;
  Supervisor supervisor_;
  std::chrono::steady_clock::time_point start_;
  LabInputs inputs_;
  Scene scene_;
  LabResult result_;
  std::string world_bin_, coordinator_bin_, node_bin_;
  std::string curve_keys_path_;  // --curve: the run's site key file
  std::optional<net::CurveKeyPair> site_keys_;
  std::string tracks_path_;
  std::map<NodeId, std::string> render_pattern_;  // the last pattern each node showed
  std::map<NodeId, report::BlendShown> blend_;    // the last blended line of each node
  std::vector<report::BlendShown> reblends_;
  std::unique_ptr<LabPainter> painter_;
  std::set<std::string> intended_kills_;
  bool coordinator_killed_ = false;
  int64_t coordinator_kill_ms_ = 0, coordinator_restart_ms_ = -1, hold_started_ms_ = 0;
  std::map<NodeId, std::vector<int64_t>> frame_times_;  // {"blend":..,"reblend":..} lines
  std::vector<report::BlendShown> blended_lines_;       // every {"blend":..,"blended":..} line
  int64_t join_calibrated_ns_ = 0;  // when the late unit's calibrated line came (--join-late)
  std::chrono::steady_clock::time_point last_blend_line_{};
  int64_t kill_ns_ = 0;                                     // steady time of the kill
  std::map<NodeId, std::string> render_unavailable_;        // nodes that cannot render, and why
  std::map<NodeId, report::RenderSummary> render_summary_;  // each node's last render summary
  zmq::context_t zmq_context_;
  proto::MessageCounters lab_counters_;
  uint64_t lab_incarnation_ = 0;
  std::string progress_phase_;
  std::string world_endpoint_, coordinator_requests_, coordinator_events_;
  std::set<NodeId> nodes_ready_;
  std::chrono::steady_clock::time_point calibration_started_{}, hold_started_{};
  bool killed_ = false, killed_while_calibrating_ = false;
  double kill_at_s_ = 0.0;
  enum class StallState { kNone, kStopped, kResumed };
  StallState stall_state_ = StallState::kNone;
  std::chrono::steady_clock::time_point stalled_at_{};
  std::map<NodeId, report::Calibrated> calibrated_at_kill_;
  std::map<NodeId, report::Calibrated> calibrated_;
  std::map<NodeId, std::string> calibration_failed_;
  std::set<NodeId> given_saved_;                         // nodes started with --saved-calibration
  std::map<NodeId, report::Verification> verification_;  // their check's line
  bool units_have_model_ = false;
};

}  // namespace

Status LabRunOptions::Check() const {
  if (out_dir.empty()) return InvalidArgumentError("--out: an output directory is required");
  if (!(hold_s >= 0)) return InvalidArgumentError("--hold-s must be >= 0");
  if (!(start_timeout_s > 0) || !(calibration_timeout_s > 0) || !(teardown_grace_s >= 0)) {
    return InvalidArgumentError("timeouts must be > 0");
  }
  if (metric_samples < 1) return InvalidArgumentError("--samples must be >= 1");
  ST_RETURN_IF_ERROR(verdict.Check());
  if (image_width_px < 16) return InvalidArgumentError("--image-width must be >= 16");
  if (kill_unit >= 0 && !(kill_at_s >= 0)) return InvalidArgumentError("--kill-at-s must be >= 0");
  if (stall_unit >= 0 && (!(stall_at_s >= 0) || !(stall_for_s > 0))) {
    return InvalidArgumentError("--stall-at-s must be >= 0 and --stall-for-s > 0");
  }
  if (kill_coordinator_at_s >= 0 && !(kill_coordinator_at_s < hold_s)) {
    return InvalidArgumentError("--kill-coordinator-at-s must be inside the hold (--hold-s)");
  }
  if (fault_unit >= 0 && !(fault_drop_share > 0 || fault_corrupt_share > 0)) {
    return InvalidArgumentError("--fault-unit needs --fault-drop-share or --fault-corrupt-share");
  }
  if (!(fault_drop_share >= 0 && fault_corrupt_share >= 0 &&
        fault_drop_share + fault_corrupt_share <= 1)) {
    return InvalidArgumentError("--fault-drop-share + --fault-corrupt-share must be in [0, 1]");
  }
  if (annotate && !(hold_s > 0)) return InvalidArgumentError("--annotate needs a hold (--hold-s)");
  if (stall_unit >= 0 && stall_unit == kill_unit) {
    return InvalidArgumentError("--stall-unit and --kill-unit name the same unit");
  }
  if (join_late >= 0 && (calibration == "true-pose" || !saved_calibration.empty())) {
    return InvalidArgumentError(
        "--join-late: only with structured-light calibration and no --saved-calibration");
  }
  return OkStatus();
}

int RunLab(const LabRunOptions& options, const std::atomic<bool>& stop, std::ostream& out,
           std::ostream& err) {
  if (Status valid = options.Check(); !valid.ok()) {
    err << "sandtable-lab run: " << valid.message() << "\n";
    return kExitUsage;
  }
  LabRun run(options, stop, out, err);
  return run.Run();
}

}  // namespace sandtable::sim
