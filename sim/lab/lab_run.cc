#include "sim/lab/lab_run.h"

#include "sim/lab/lab_run_internal.h"

#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <thread>

namespace sandtable::sim {
namespace lab_internal {
namespace {

// A fresh operator token for the run's console: 32 hex characters from /dev/urandom in a file
// only its owner reads (as the coordinator requires).
Status WriteConsoleToken(const std::string& path) {
  unsigned char bytes[16];
  std::FILE* random = std::fopen("/dev/urandom", "rb");
  const bool read =
      random != nullptr && std::fread(bytes, 1, sizeof(bytes), random) == sizeof(bytes);
  if (random != nullptr) std::fclose(random);
  if (!read) return IoError("console token: cannot read /dev/urandom");
  std::string token;
  for (unsigned char b : bytes) {
    static const char kHex[] = "0123456789abcdef";
    token += kHex[b >> 4];
    token += kHex[b & 15];
  }
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) return IoError("console token: cannot write " + path);
  token += "\n";
  const bool written =
      ::write(fd, token.data(), token.size()) == static_cast<ssize_t>(token.size());
  ::close(fd);
  return written ? OkStatus() : IoError("console token: cannot write " + path);
}

}  // namespace

int LabRun::Run() {
  result_.command = options_.command_line;
  result_.seed = options_.seed;
  result_.noise_seed = options_.noise_seed;
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

int LabRun::Prepare() {
  Phase("prepare", 0);
  Expected<LabInputs> inputs =
      PrepareLabInputs(options_.site, options_.scene, options_.seed, options_.out_dir,
                       options_.model, options_.resolution_scale, options_.device_timing);
  if (!inputs.ok()) {
    progress_.End("failed");
    err_ << "sandtable-lab run: " << inputs.status().message() << "\n";
    return inputs.status().code() == StatusCode::kInvalidArgument ? kExitUsage : kExitFailure;
  }
  inputs_ = std::move(*inputs);
  if (options_.hosts == "netns") {
    if (Status made = MakeHosts(); !made.ok()) {
      progress_.End("failed");
      err_ << "sandtable-lab run: " << made.ToString() << "\n";
      return kExitFailure;
    }
  }
  if (options_.curve || hosts_ != nullptr) {
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
  if (!hosts_) {
    const std::string token_path = fs::absolute(fs::path(options_.out_dir) / "console.token");
    if (Status written = WriteConsoleToken(token_path); !written.ok()) {
      progress_.End("failed");
      err_ << "sandtable-lab run: " << written.ToString() << "\n";
      return kExitFailure;
    }
    console_token_path_ = token_path;
  }
  // The personnel tracks the coordinator replays and the nodes draw (docs/render.md).
  tracks_path_ = fs::absolute(fs::path(options_.out_dir) / "tracks.csv").string();
  const double table_radius_m = inputs_.site.table.is_disc
                                    ? 0.5 * inputs_.site.table.diameter_m
                                    : 0.5 * inputs_.site.table.size_m.minCoeff();
  if (Status tracks = WriteLabTracks(tracks_path_, 4, 120.0, 0.65 * table_radius_m); !tracks.ok()) {
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

std::string LabRun::FrameLogPath() const {
  return fs::absolute(fs::path(options_.out_dir) / "world_frames.jsonl").string();
}

int64_t LabRun::SystemMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Status LabRun::MakeHosts() {
  Expected<std::unique_ptr<NetnsHosts>> hosts = NetnsHosts::Create();
  if (!hosts.ok()) return hosts.status();
  hosts_ = std::move(*hosts);
  std::vector<std::string> names = {"world", "coordinator"};
  for (const UnitSpec& unit : inputs_.site.units)
    names.push_back("node-" + std::to_string(unit.id));
  for (const std::string& name : names) {
    Expected<std::string> address = hosts_->AddHost(name);
    if (!address.ok()) return address.status();
  }
  if (options_.cap_unit >= 0) {
    ST_RETURN_IF_ERROR(
        hosts_->CapBandwidth("node-" + std::to_string(options_.cap_unit), options_.cap_kbit));
  }
  return OkStatus();
}

bool LabRun::StartWorld() {
  Phase("start world", 1);
  const std::string bind =
      hosts_ ? "tcp://" + hosts_->Address("world") + ":*" : std::string("tcp://127.0.0.1:*");
  ChildProcess* world = StartChild(
      "world", "world",
      {world_bin_, "serve", "--site", inputs_.site_path, "--scene", inputs_.scene_path, "--bind",
       bind, "--frame-log", FrameLogPath(), "--noise-seed", std::to_string(options_.noise_seed)});
  if (!world) return false;
  return Wait(
      "start world", [&] { return !lines_.world_endpoint.empty(); }, ToMs(options_.start_timeout_s),
      "sandtable-world printed no readiness line "
      "{\"ready\":\"sandtable-world\",\"world\":ENDPOINT} on stdout",
      world);
}

std::vector<std::string> LabRun::CoordinatorArgs(const std::string& requests,
                                                 const std::string& events) const {
  std::vector<std::string> argv = {
      coordinator_bin_, "--requests",     requests,
      "--events",       events,           "--timeline",
      tracks_path_,     "--heartbeat-ms", std::to_string(HeartbeatMs())};
  if (Chaos()) {
    argv.insert(argv.end(),
                {"--annotations", fs::absolute(fs::path(options_.out_dir) / "annotations.db")});
  }
  if (!hosts_ && !console_token_path_.empty()) {
    // The operator's console on loopback (docs/console.md); its token for actions.
    argv.insert(argv.end(),
                {"--status", "127.0.0.1:0", "--status-token-file", console_token_path_});
  }
  if (hosts_) {
    argv.insert(argv.end(),
                {"--beacon", std::to_string(kLabDiscoveryPort), "--site-name", kLabSiteName});
    if (options_.enroll_unit >= 0) argv.insert(argv.end(), {"--enroll", "tcp://*:*"});
  }
  return argv;
}

bool LabRun::StartCoordinator() {
  Phase("start coordinator", 1);
  // Across hosts the coordinator listens on every interface of its host and beacons the site;
  // no node is given its address.
  const std::vector<std::string> argv =
      hosts_ ? CoordinatorArgs("tcp://*:*", "tcp://*:*")
             : CoordinatorArgs("tcp://127.0.0.1:*", "tcp://127.0.0.1:*");
  ChildProcess* coordinator = StartChild("coordinator", "coordinator", argv);
  if (!coordinator) return false;
  const bool ready = Wait(
      "start coordinator", [&] { return !lines_.coordinator_events.empty(); },
      ToMs(options_.start_timeout_s),
      "sandtable-coordinator printed no readiness line "
      "{\"ready\":\"sandtable-coordinator\",\"requests\":..,\"events\":..} on stdout",
      coordinator);
  if (ready) WriteConsoleFile();
  return ready;
}

// OUT/console.json: where the site's console is while the run lasts, and its token's file.
void LabRun::WriteConsoleFile() {
  const std::string& status = lines_.coordinator_status;
  const std::string suffix = "/status";
  if (status.size() <= suffix.size() || status.rfind(suffix) != status.size() - suffix.size()) {
    return;
  }
  result_.console_url = status.substr(0, status.size() - suffix.size()) + "/";
  const nlohmann::json console = {
      {"url", result_.console_url}, {"status", status}, {"token_file", console_token_path_}};
  const fs::path path = fs::path(options_.out_dir) / "console.json";
  if (Status written = WriteFileAtomically(path, console.dump(2) + "\n"); !written.ok()) {
    ST_LOG(kWarning) << "console: " << written.ToString();
    return;
  }
  ST_LOG(kInfo) << "console: " << result_.console_url << " while the run lasts (operator token in "
                << console_token_path_ << ")";
}

bool LabRun::Late(NodeId id) const {
  return options_.join_late >= 0 && static_cast<NodeId>(options_.join_late) == id;
}

int LabRun::HeartbeatMs() const {
  if (options_.heartbeat_ms > 0) return options_.heartbeat_ms;
  const int units = static_cast<int>(inputs_.site.units.size());
  return units <= 16 ? 100 : 100 * units / 16;
}

int LabRun::ExpectedUnits() const {
  int n = 0;
  for (const UnitSpec& unit : inputs_.site.units) n += Late(unit.id) ? 0 : 1;
  return n;
}

bool LabRun::StartNodes() {
  const int n = ExpectedUnits();
  Phase("start nodes", n);
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!Late(unit.id) && !StartNode(unit)) return false;
  }
  return Wait(
      "start nodes",
      [&] {
        MaybeAcceptEnrollment();
        return static_cast<int>(lines_.nodes_ready.size()) == n;
      },
      ToMs(options_.start_timeout_s),
      "not every sandtable-node printed its readiness line "
      "{\"ready\":\"sandtable-node\",\"id\":N,..}",
      nullptr, [&] { return static_cast<int>(lines_.nodes_ready.size()); },
      [&] { return Missing(lines_.nodes_ready); });
}

bool LabRun::StartNode(const UnitSpec& unit) {
  const std::string export_dir = fs::absolute(fs::path(options_.out_dir) / "calibration");
  {
    const std::string id = std::to_string(unit.id);
    std::vector<std::string> argv = {
        node_bin_,
        "--id",
        id,
        "--coordinator",
        hosts_ ? std::string("discover")
               : lines_.coordinator_requests + "," + lines_.coordinator_events,
        "--world",
        lines_.world_endpoint,
        "--factory",
        inputs_.factory_paths.at(unit.id),
        "--export-dir",
        export_dir,
        "--heartbeat-ms",
        std::to_string(HeartbeatMs())};
    if (hosts_) {
      // Its address is the one of its host that faces the coordinator (found by the node).
      argv.insert(argv.end(), {"--discovery-port", std::to_string(kLabDiscoveryPort), "--site-name",
                               kLabSiteName, "--bind", "tcp://*:*"});
    }
    // The model: self-calibration finds where it stands; the renderer draws it there.
    argv.insert(argv.end(), {"--model", inputs_.model_path});
    if (options_.render == "off") {
      argv.insert(argv.end(), {"--render", "off"});
    } else {
      if (options_.blend == "off") argv.insert(argv.end(), {"--blend", "off"});
      if (options_.black_match == "on") argv.insert(argv.end(), {"--black-match", "on"});
      argv.insert(
          argv.end(),
          {"--timeline", tracks_path_, "--render-max-fps", std::to_string(options_.render_max_fps),
           "--render-log",
           fs::absolute(fs::path(options_.out_dir) / "logs" / ("render-" + id + ".csv")).string()});
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
    if (options_.clock_offset_s != 0.0) {
      argv.insert(argv.end(), {"--test-clock-offset-s", std::to_string(ClockOffsetS(unit.id))});
    }
    if (options_.link_latency_ms > 0 || options_.link_loss > 0) {
      argv.insert(argv.end(), {"--fault-delay-ms", std::to_string(options_.link_latency_ms),
                               "--fault-jitter-ms", std::to_string(options_.link_jitter_ms),
                               "--fault-drop-share", std::to_string(options_.link_loss),
                               "--fault-seed", std::to_string(options_.seed)});
    }
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

double LabRun::ClockOffsetS(NodeId id) const {
  int index = 0;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (unit.id == id) break;
    ++index;
  }
  const double magnitude = options_.clock_offset_s * (1 + index / 2);
  return index % 2 == 0 ? magnitude : -magnitude;
}

bool LabRun::Calibrate() {
  const int n = ExpectedUnits();
  Phase("calibration held", n);
  // A node that reports it could not calibrate is done too: the report names it and why.
  // With saved calibrations: when one does not hold (or a unit has none) a round runs, and
  // every unit's result must then come from it (a unit whose saved one held reports twice).
  calibration_started_ = std::chrono::steady_clock::now();
  auto done = [&] {
    MaybeKill();
    MaybeStall();
    if (static_cast<int>(lines_.calibrated.size() + lines_.calibration_failed.size()) < n)
      return false;
    bool round_needed = static_cast<int>(given_saved_.size()) < n;
    for (const auto& [id, line] : lines_.verification) round_needed |= !line.holds;
    if (!round_needed) return true;
    for (const auto& [id, line] : lines_.calibrated) {
      if (line.verified) return false;
    }
    return true;
  };
  const bool held = Wait(
      "calibration held", done, ToMs(options_.calibration_timeout_s),
      "not every sandtable-node reported a calibration "
      "{\"calibrated\":N,\"source\":..,\"json\":..,\"yaml\":..}",
      nullptr, [&] { return static_cast<int>(lines_.calibrated.size()); },
      [&] {
        std::set<NodeId> have;
        for (const auto& [id, line] : lines_.calibrated) have.insert(id);
        return Missing(have);
      });
  // A stall that outlasts the calibration ends with it (the show needs every node).
  if (stall_state_ == StallState::kStopped) Stall(false);
  return held;
}

Expected<wire::Envelope> LabRun::Call(const std::string& endpoint, wire::Envelope request,
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
    ST_RETURN_IF_ERROR(
        net::Socket::Poll({&channel.socket()}, options_.timings.reply_poll, &readable));
    Expected<std::optional<net::Incoming>> in = channel.TryReceive();
    if (in.ok() && *in && (*in)->envelope.body_case() == reply_case) {
      return std::move((*in)->envelope);
    }
  }
  return UnavailableError("no reply from " + endpoint + " within " +
                          std::to_string(timeout.count()) + " ms");
}

int LabRun::Finish() {
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
  double load[1] = {-1.0};
  if (::getloadavg(load, 1) == 1) result_.load_average = load[0];
  result_.cores = static_cast<int>(std::thread::hardware_concurrency());
  const Status written = WriteLabReport(result_, options_.out_dir);
  const std::string report_path = (fs::path(options_.out_dir) / "report.json").string();
  report::WriteReportLine(out_, report::LabDone{result_.status, report_path});
  if (!written.ok()) {
    err_ << "sandtable-lab run: " << written.ToString() << "\n";
    return kExitFailure;
  }
  if (result_.failure) {
    const LabFailure& f = *result_.failure;
    err_ << "sandtable-lab run: " << result_.status << " in phase '" << f.phase << "': " << f.reason
         << "\n";
    if (!f.log_tail.empty())
      err_ << "  last lines of " << f.log_path << ":\n" << JoinLines(f.log_tail);
    err_ << "  report: " << report_path << "\n";
    return result_.status == "interrupted" ? kExitInterrupted : kExitFailure;
  }
  if (result_.registration) {
    const ErrorStats& s = result_.registration->site.all;
    char figures[160];
    std::snprintf(figures, sizeof(figures), "rms %.3f mm, p99 %.2f mm, max %.2f mm, rms %.3f px",
                  s.rms_mm, s.p99_mm, s.max_mm, s.rms_px);
    err_ << "sandtable-lab run: " << result_.site_name << ", calibration "
         << result_.calibration_source << ": " << figures << "\n";
  }
  for (const LabReason& reason : result_.reasons) {
    err_ << "sandtable-lab run: failed: " << reason.what << ": " << reason.detail << "\n";
  }
  err_ << "sandtable-lab run: report " << (fs::path(options_.out_dir) / "report.md").string()
       << "\n";
  return result_.reasons.empty() ? kExitOk : kExitVerdict;
}

void LabRun::Phase(const std::string& name, int total) {
  progress_.Begin(name, total);
  progress_phase_ = name;
  report::LabPhase line{name, std::nullopt};
  if (name == "hold") line.hold_s = options_.hold_s;
  if (options_.phase_lines) report::WriteReportLine(out_, line);
}

std::string LabRun::RelativeToOut(const std::string& path) const {
  std::error_code error;
  const fs::path relative = fs::relative(path, options_.out_dir, error);
  if (error || relative.empty() || *relative.begin() == "..") return path;
  return relative.string();
}

std::vector<std::string> LabRun::NodeHugePagesEnv() {
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

ChildProcess* LabRun::StartChild(const std::string& name, const std::string& role,
                                 std::vector<std::string> argv, std::vector<std::string> env) {
  if (!curve_keys_path_.empty() && (role == "world" || role == "coordinator" || role == "node")) {
    if (role == "node" && options_.enroll_unit >= 0 &&
        name == "node-" + std::to_string(options_.enroll_unit)) {
      // No site key: it asks the operator (MaybeAcceptEnrollment) and keeps the key it is handed.
      const fs::path keys = fs::absolute(fs::path(options_.out_dir) / "enroll" / (name + ".keys"));
      std::error_code ec;
      fs::create_directories(keys.parent_path(), ec);
      argv.insert(argv.end(), {"--enroll", keys.string()});
      enroll_started_ = std::chrono::steady_clock::now();
    } else {
      argv.insert(argv.end(), {"--curve-keys", curve_keys_path_});
    }
  }
  // A restarted coordinator ("coordinator-2") runs on the coordinator's host.
  if (hosts_) argv = hosts_->Wrap(role == "coordinator" ? "coordinator" : name, std::move(argv));
  ChildSpec spec{name, role, std::move(argv),
                 (fs::path(options_.out_dir) / "logs" / (name + ".log")).string(), std::move(env)};
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
Supervisor::LineHandler LabRun::Handler() {
  return [this](ChildProcess& child, const report::ReportLine& line) {
    lines_.Take(child.spec().role, line, std::chrono::steady_clock::now());
    if (hosts_) {
      // Programs bound to every interface of their host print 0.0.0.0: the lab needs the
      // host's address to reach them.
      lines_.coordinator_requests = hosts_->Reachable("coordinator", lines_.coordinator_requests);
      lines_.coordinator_events = hosts_->Reachable("coordinator", lines_.coordinator_events);
    }
    if (std::holds_alternative<report::NodeReady>(line)) {
      progress_.Update(static_cast<int>(lines_.nodes_ready.size()));
    }
    // A round's steps on the bar, and a plain line when its step changes.
    if (const auto* round = std::get_if<report::RoundProgress>(&line)) {
      progress_.Note(std::to_string(round->round) + " " + round->step, RoundProgressText(*round),
                     RoundProgressText(*round, /*step_only=*/true));
    }
    if ((std::holds_alternative<report::Calibrated>(line) ||
         std::holds_alternative<report::CalibrationFailed>(line)) &&
        progress_phase_ == "calibration held") {
      progress_.Update(
          static_cast<int>(lines_.calibrated.size() + lines_.calibration_failed.size()));
    }
  };
}

bool LabRun::Wait(const std::string& phase, const std::function<bool()>& done,
                  milliseconds deadline, const std::string& what, const ChildProcess* waited_for,
                  const std::function<int()>& count, const std::function<std::string()>& missing) {
  if (count) progress_.Update(count());
  // While it waits the progress line says for how long and for whom.
  const auto waiting = [&] {
    if (missing) progress_.Tick(missing);
    return done();
  };
  const WaitOutcome outcome = supervisor_.WaitUntil(waiting, deadline, stop_, Handler());
  if (outcome == WaitOutcome::kDone) {
    progress_.End();
    return true;
  }
  const std::string details =
      outcome == WaitOutcome::kDeadline && missing ? what + " (missing: " + missing() + ")" : what;
  return Failed(phase, outcome, details, waited_for);
}

std::string LabRun::Missing(const std::set<NodeId>& have) const {
  std::string out;
  for (const UnitSpec& unit : inputs_.site.units) {
    if (!have.count(unit.id)) out += (out.empty() ? "node-" : ", node-") + std::to_string(unit.id);
  }
  return out;
}

bool LabRun::Failed(const std::string& phase, WaitOutcome outcome, const std::string& what,
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

bool LabRun::FailedWith(const std::string& phase, const std::string& reason) {
  LabFailure f;
  f.phase = phase;
  f.reason = reason;
  result_.status = "failed";
  progress_.End("failed");
  result_.failure = std::move(f);
  return false;
}

}  // namespace lab_internal

using lab_internal::kExitUsage;
using lab_internal::LabRun;

Status LabTimings::Check() const {
  for (const auto& [name, value] :
       {std::pair<const char*, std::chrono::milliseconds>{"blend_settle", blend_settle},
        {"blend_wait", blend_wait},
        {"pattern_wait", pattern_wait},
        {"join_settle", join_settle},
        {"request_timeout", request_timeout},
        {"world_render_timeout", world_render_timeout},
        {"render_log_flush", render_log_flush},
        {"work_limit", work_limit},
        {"reap_after_kill", reap_after_kill},
        {"reply_poll", reply_poll}}) {
    if (value.count() <= 0) {
      return InvalidArgumentError(std::string("lab timings: ") + name + " must be > 0");
    }
  }
  return OkStatus();
}

Status LabRunOptions::Check() const {
  ST_RETURN_IF_ERROR(timings.Check());
  if (out_dir.empty()) return InvalidArgumentError("--out: an output directory is required");
  if (hosts != "local" && hosts != "netns") {
    return InvalidArgumentError("--hosts must be local or netns, not " + hosts);
  }
  if (!(link_latency_ms >= 0) || !(link_jitter_ms >= 0) || link_jitter_ms > link_latency_ms ||
      !(link_loss >= 0 && link_loss < 1)) {
    return InvalidArgumentError(
        "--link-latency-ms, --link-jitter-ms, --link-loss: 0 <= jitter <= latency, loss in [0, 1)");
  }
  if ((link_latency_ms > 0 || link_loss > 0) && fault_unit >= 0) {
    return InvalidArgumentError("--link-* and --fault-unit both set the nodes' --fault-* flags");
  }
  if (stall_by != "signal" && stall_by != "link") {
    return InvalidArgumentError("--stall-by must be signal or link");
  }
  if (cap_unit >= 0 && (hosts != "netns" || cap_kbit <= 0)) {
    return InvalidArgumentError("--cap-unit needs --hosts netns and a --cap-kbit > 0");
  }
  if (enroll_unit >= 0 && hosts != "netns") {
    return InvalidArgumentError(
        "--enroll-unit needs --hosts netns (the unit finds the site by its "
        "beacon and asks its operator)");
  }
  if (stall_by == "link" && hosts != "netns") {
    return InvalidArgumentError("--stall-by link needs --hosts netns (a host's link to cut)");
  }
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
