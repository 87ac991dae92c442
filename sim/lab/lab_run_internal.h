// The lab's run (lab_run.h) inside: the LabRun class and the helpers its files share. Its
// member functions are spread over lab_run.cc (the start, calibration, the report lines, the
// finish), lab_run_faults.cc (the late join, kills, the stall, the coordinator's restart, the
// chaos figures, the hold), lab_run_show.cc (the show and the blend) and lab_run_measure.cc (the
// registration metric and the collected figures). Nothing outside sim/lab includes it.
#pragma once

#include <unistd.h>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <future>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <sstream>

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "common/io/image_file.h"
#include "common/io/mpcdi.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/gltf_loader.h"
#include "common/scene/ray_caster.h"
#include "net/channel.h"
#include "net/curve.h"
#include "sim/lab/lab_hosts.h"
#include "sim/lab/lab_images.h"
#include "sim/lab/lab_inputs.h"
#include "sim/lab/lab_lines.h"
#include "sim/lab/lab_painter.h"
#include "sim/lab/lab_report.h"
#include "sim/lab/lab_run.h"
#include "sim/lab/lab_sweep.h"
#include "sim/lab/photometric_metric.h"
#include "sim/lab/progress.h"
#include "sim/lab/registration_metric.h"
#include "sim/lab/render_metrics.h"
#include "sim/lab/supervisor.h"
#include "sim/site/site_json.h"
#include "sim/transport/world.h"

namespace sandtable::sim::lab_internal {

namespace fs = std::filesystem;
using nlohmann::json;
using std::chrono::milliseconds;

// The photometric measure (photometric_metric.h): steps over 5 mm, on samples lit above 3x the
// ambient luminance of a white surface.
inline constexpr double kStepSpacing_m = 0.005;
inline constexpr double kLitAmbientFactor = 3.0;
// The bound on the table's step over 5 mm: the steps over it are located (PlaceSteps).
inline constexpr double kTableStepBoundPct = 1.5;

// Mean of an MPCDI region's alpha map in [0, 1] (-1 without one): 1 until the blend fills it.
inline double AlphaMean(const MpcdiRegion& region) {
  if (!region.alpha || region.alpha->values.empty()) return -1.0;
  double sum = 0.0;
  for (uint8_t v : region.alpha->values) sum += v;
  return sum / (255.0 * static_cast<double>(region.alpha->values.size()));
}

inline constexpr int kExitOk = 0, kExitFailure = 1, kExitUsage = 2, kExitVerdict = kLabExitVerdict,
                     kExitInterrupted = 130;
inline constexpr int kLogTailLines = 20;
// --hosts netns: the beacon's UDP port and the site's name (each run has a network of its own).
inline constexpr int kLabDiscoveryPort = 5670;
inline constexpr const char* kLabSiteName = "lab";

inline milliseconds ToMs(double seconds) {
  return milliseconds(static_cast<int64_t>(seconds * 1e3));
}

// The build tree's programs (set by sim/lab/CMakeLists.txt), the last place looked in.
#ifndef SANDTABLE_LAB_WORLD_BIN
#define SANDTABLE_LAB_WORLD_BIN ""
#define SANDTABLE_LAB_COORDINATOR_BIN ""
#define SANDTABLE_LAB_NODE_BIN ""
#endif

// `name` in --bin-dir, else beside this program, else where the build tree put it.
inline Expected<std::string> FindProgram(const std::string& name, const std::string& bin_dir,
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

inline std::string JoinLines(const std::vector<std::string>& lines) {
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

  int Run();

 private:
  // ---- phases ----

  int Prepare();

  std::string FrameLogPath() const;
  static int64_t SystemMs();

  // --hosts netns: the run's hosts (world, coordinator, one per unit).
  Status MakeHosts();
  bool StartWorld();

  std::vector<std::string> CoordinatorArgs(const std::string& requests,
                                           const std::string& events) const;
  bool Chaos() const { return options_.annotate || options_.kill_coordinator_at_s >= 0; }

  bool StartCoordinator();
  void WriteConsoleFile();

  bool Late(NodeId id) const;
  int HeartbeatMs() const;
  int ExpectedUnits() const;

  bool StartNodes();

  // The late unit (--join-late): started once the others hold their calibration (and their
  // blend has settled); done when it holds its own, and 2 s more so that a round that
  // recalibrated the others would show. Frames given to the others are counted from its start
  // to its calibration.
  bool Join();

  bool StartNode(const UnitSpec& unit);
  // The clock offset (s) the lab gives this unit's node (--clock-offset-s), 0 without.
  double ClockOffsetS(NodeId id) const;

  bool TruePoseMode() const { return options_.calibration == "true-pose"; }

  // --kill-unit: SIGKILL the unit once kill_at_s have passed since the calibration phase began.
  void MaybeKill();

  // --stall-unit: SIGSTOP the unit stall_at_s after the calibration phase began, SIGCONT it
  // stall_for_s later (and at the latest before the teardown).
  void MaybeStall();
  // --enroll-unit: as the site's operator, accepts that unit once it asks (result_.enrollment).
  void MaybeAcceptEnrollment();
  void Stall(bool stop);

  // What the other units did after the kill (their calibrated lines' rounds).
  void RecordKill();

  // --kill-coordinator-at-s: SIGKILL the coordinator that long into the hold and start a new
  // one at once on the same database and endpoints (the nodes reconnect by themselves).
  void MaybeKillCoordinator();

  // Frames each other node showed in [from_ms, from_ms + window_ms) against those it showed in
  // the same span just before from_ms: the frames a fault cost the others (largest per node).
  // Nodes draw on change, so the span before is what the show asked of them; a pace taken from
  // the median interval of the few frames a quiet hold shows would overstate the loss (two frames
  // 36 ms apart predict 83 in 3 s).
  int FramesLost(int64_t from_ms, int64_t window_ms, const std::set<NodeId>& skip);

  // The chaos section: every fault of the hold, the annotations, the nodes' link faults.
  void RecordChaos();

  // After the teardown: the nodes' exit lines (link faults, rejected messages) and crashes.
  void FinishChaos(const std::vector<std::string>& killed_at_teardown);

  bool Calibrate();

  // ---- the show (docs/render.md) ----

  // A request to the coordinator or the world from the lab's own DEALER; the reply whose body
  // is `reply_case`, within `timeout`.
  Expected<wire::Envelope> Call(const std::string& endpoint, wire::Envelope request,
                                wire::Envelope::BodyCase reply_case, milliseconds timeout);

  // Runs `work` on a thread while the children are watched; false (failure recorded) when a
  // child dies or the run is interrupted.
  template <typename T>
  bool Watched(const std::string& phase, std::function<T()> work, T* out) {
    std::future<T> future = std::async(std::launch::async, std::move(work));
    const auto ready = [&] {
      return future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    };
    const WaitOutcome outcome =
        supervisor_.WaitUntil(ready, options_.timings.work_limit, stop_, Handler());
    if (outcome != WaitOutcome::kDone) {
      future.wait();
      return Failed(phase, outcome, "", nullptr);
    }
    *out = future.get();
    return true;
  }

  Status SetPattern(const std::string& pattern);

  Expected<TopView> TopViewOf(const std::vector<NodeId>& lit);

  // The top view's pixels whose surface seen from above is the table (the truth's scene, cast
  // straight down): the grid is compared there.
  cv::Mat TableMask(const std::map<NodeId, TopView>& views) const;

  // Waits until every calibrated unit has shown `pattern` (the phase goes on).
  bool WaitForPattern(const std::string& pattern);

  struct TopViews {
    std::map<NodeId, TopView> each;
    std::optional<TopView> all;
    std::string error;
  };
  bool ShowGrid(const std::vector<NodeId>& units);
  bool Show();

  // The world's truth of one projector at points (one sample per point, in order).
  Expected<wire::GroundTruthReply> GroundTruth(NodeId projector,
                                               const std::vector<Eigen::Vector3d>& points);

  // The luminance of each point from that projector (0 where it does not light it).
  Expected<std::vector<double>> TruthLuminance(NodeId projector,
                                               const std::vector<Eigen::Vector3d>& points);

  // Whether that projector can project at each point, lights it, and its pixel there.
  Expected<std::vector<SampleTruth>> TruthSamples(NodeId projector,
                                                  const std::vector<Eigen::Vector3d>& points);

  // Where the table's steps over the bound lie (PlaceSteps), in every calibrated
  // projector's truth.
  Expected<json> PlaceTableSteps(const StepStats& steps, const TopView& view, double bound_pct);

  bool WaitForBlendSettled(json* unsettled);
  struct BlendMeasure {
    json photometric = json::object();
    cv::Mat over;  // the table's steps over 1 % (a picture)
    std::string error;
  };
  BlendMeasure MeasureBlend(const TopView& b, const TopView& a, const TopView& black);
  void RecordJoinReblend();
  bool Blend();

  bool Hold();

  bool LoadEstimates(std::vector<EstimatedRegistration>* estimates);
  void RecordResponse(const UnitSpec& unit, const ProjectorResponseRecord& r);
  bool Measure();

  // The runner's report and each node's figures (docs/lab.md, "Self-calibration").
  void CollectSelfCalibration();

  // The nodes' render summaries (their last lines, printed at exit) into the report: the
  // median p50 and floor, the worst p99.
  void CollectRender();

  int Finish();

  // ---- helpers ----

  void Phase(const std::string& name, int total);

  std::string RelativeToOut(const std::string& path) const;

  // GLIBC_TUNABLES with glibc's malloc on transparent huge pages (LabOptions::node_huge_pages),
  // added to what the lab's environment already tunes: hugetlb=1 puts the main heap (and mmap'd
  // chunks) on huge pages, arena_max=1 keeps every thread's allocations in that heap (the
  // threads' own arenas, ~190 MB of a node's ~360 MB, stayed on 4 KiB pages: a killed node's
  // sockets then closed 25-32 ms after the kill, 10-12 ms with them in the main heap).
  static std::vector<std::string> NodeHugePagesEnv();

  ChildProcess* StartChild(const std::string& name, const std::string& role,
                           std::vector<std::string> argv, std::vector<std::string> env = {});

  // The handler of every report line of every child (cluster/report_lines.h): into lines_
  // (LabLines), and the progress.
  Supervisor::LineHandler Handler();

  // Waits for `done`; on anything else records the failure (with `what` on a deadline) and
  // returns false.
  bool Wait(const std::string& phase, const std::function<bool()>& done, milliseconds deadline,
            const std::string& what, const ChildProcess* waited_for,
            const std::function<int()>& count = nullptr,
            const std::function<std::string()>& missing = nullptr);

  // "node-1, node-2": the site's units not in `have`.
  std::string Missing(const std::set<NodeId>& have) const;

  bool Failed(const std::string& phase, WaitOutcome outcome, const std::string& what,
              const ChildProcess* waited_for);

  bool FailedWith(const std::string& phase, const std::string& reason);

  const LabRunOptions& options_;
  const std::atomic<bool>& stop_;
  std::ostream& out_;
  std::ostream& err_;
  Progress progress_;
  // --hosts netns: destroyed after the supervisor (whose children run on these hosts).
  std::unique_ptr<NetnsHosts> hosts_;
  Supervisor supervisor_;
  std::chrono::steady_clock::time_point start_;
  LabInputs inputs_;
  Scene scene_;
  LabResult result_;
  std::string world_bin_, coordinator_bin_, node_bin_;
  std::string curve_keys_path_;     // --curve: the run's site key file
  std::string console_token_path_;  // the console's operator token (local runs)
  std::optional<net::CurveKeyPair> site_keys_;
  std::string tracks_path_;
  LabLines lines_;  // what the children reported
  std::unique_ptr<LabPainter> painter_;
  std::set<std::string> intended_kills_;
  bool coordinator_killed_ = false;
  int64_t coordinator_kill_ms_ = 0, coordinator_restart_ms_ = -1, hold_started_ms_ = 0;
  std::map<NodeId, std::vector<int64_t>> frame_times_;  // {"blend":..,"reblend":..} lines
  int64_t kill_ns_ = 0;                                 // steady time of the kill
  zmq::context_t zmq_context_;
  proto::MessageCounters lab_counters_;
  uint64_t lab_incarnation_ = 0;
  std::string progress_phase_;
  std::chrono::steady_clock::time_point calibration_started_{}, hold_started_{};
  bool killed_ = false, killed_while_calibrating_ = false;
  double kill_at_s_ = 0.0;
  enum class StallState { kNone, kStopped, kResumed };
  StallState stall_state_ = StallState::kNone;
  std::chrono::steady_clock::time_point stalled_at_{};
  // --enroll-unit: when its node started, when the lab next looks at the coordinator's list.
  std::chrono::steady_clock::time_point enroll_started_{}, next_enroll_poll_{};
  bool enroll_accepted_ = false;
  std::map<NodeId, report::Calibrated> calibrated_at_kill_;
  std::set<NodeId> given_saved_;  // nodes started with --saved-calibration
  bool units_have_model_ = false;
};

}  // namespace sandtable::sim::lab_internal
