#include "node/app/doctor_command.h"

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

#include <zmq.hpp>

#include "common/base/log.h"
#include "common/cli/command_line.h"
#include "common/cli/config_file.h"
#include "common/io/unit_calibration_file.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/server_loop.h"
#include "node/app/node_app.h"
#include "node/app/node_discovery.h"
#include "node/devices/device_factory.h"
#include "proto/envelope_stamper.h"
#include "proto/message_counters.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string Size(cv::Size s) { return std::to_string(s.width) + "x" + std::to_string(s.height); }

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(digits);
  out << value;
  return out.str();
}

DoctorCheck Check(std::string name, CheckVerdict verdict, std::string detail,
                  std::string todo = "") {
  return {std::move(name), verdict, std::move(detail), std::move(todo)};
}

DoctorCheck Skip(std::string name, std::string why) {
  return Check(std::move(name), CheckVerdict::kSkipped, std::move(why));
}

// What the checks share: the factory file, the devices once opened.
struct Bench {
  std::optional<UnitCalibration> factory;
  std::unique_ptr<ProjectorOutput> projector;
  std::unique_ptr<CameraInput> camera;
  std::optional<net::CurveKeyPair> keys;
  // The camera's images with the projector black and white, as doubles in [0, 1] of full scale.
  cv::Mat black, white;
  cv::Mat lit;  // where white is brighter than black by the contrast asked
};

DoctorCheck CheckFactory(const NodeConfig& c, Bench& bench) {
  const std::string name = "factory file";
  if (c.factory_path.empty()) {
    return Check(name, CheckVerdict::kFail, "no --factory",
                 "calibrate the unit (sandtable-node calibrate-unit, docs/unit-calibration.md) "
                 "and give its file with --factory");
  }
  Expected<UnitCalibration> loaded = LoadUnitCalibration(c.factory_path);
  if (!loaded.ok()) {
    return Check(name, CheckVerdict::kFail, loaded.status().message(),
                 "give the unit's own factory file, or calibrate the unit again");
  }
  bench.factory = *loaded;
  std::error_code error;
  const auto written = fs::last_write_time(c.factory_path, error);
  const double days =
      error ? 0.0
            : std::chrono::duration<double>(fs::file_time_type::clock::now() - written).count() /
                  86400.0;
  std::string detail = c.factory_path + ": projector " +
                       Size({loaded->projector.width_px, loaded->projector.height_px}) +
                       ", camera " + Size({loaded->camera.width_px, loaded->camera.height_px}) +
                       ", projector residual " + Fixed(loaded->projector_rms_px, 3) + " px, " +
                       Fixed(days, 0) + " days old";
  if (days > kFactoryOldDays) {
    return Check(name, CheckVerdict::kWarn, detail,
                 "older than " + std::to_string(kFactoryOldDays) +
                     " days: lenses and mounts drift; calibrate the unit again when it is moved "
                     "or its error grows");
  }
  return Check(name, CheckVerdict::kOk, detail);
}

DoctorCheck CheckKeys(const NodeConfig& c, Bench& bench) {
  const std::string name = "key file";
  const std::string path = !c.curve_keys_path.empty() ? c.curve_keys_path : c.enroll_keys_path;
  if (path.empty()) {
    return Check(name, c.insecure ? CheckVerdict::kOk : CheckVerdict::kWarn,
                 "no --curve-keys: the unit talks to the site unencrypted",
                 c.insecure ? "" : "on a shared network give the site's key (docs/deploy.md)");
  }
  if (!c.enroll_keys_path.empty() && !fs::exists(path)) {
    return Check(name, CheckVerdict::kWarn, path + " does not exist yet: the unit is not enrolled",
                 "start the unit with --enroll and accept it on the console or with "
                 "sandtable-coordinator enroll (docs/deploy.md)");
  }
  Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(path);
  if (!keys.ok()) {
    const bool mode = keys.status().code() == StatusCode::kPermissionDenied;
    return Check(name, CheckVerdict::kFail, keys.status().message(),
                 mode ? "chmod 600 " + path : "copy the site's key file again (docs/deploy.md)");
  }
  bench.keys = *keys;
  return Check(name, CheckVerdict::kOk,
               path + ": mode 0600, key " + net::KeyFingerprint(keys->public_key_z85));
}

// The camera is opened without the factory file's size (it is learnt from the device and then
// compared, so that a mismatch is named as one).
DeviceOptions Devices(const NodeConfig& c, const Bench& bench) {
  DeviceOptions o;
  o.node_id = c.id;
  o.world_curve = bench.keys;
  if (bench.factory) {
    o.projector_size_px =
        cv::Size(bench.factory->projector.width_px, bench.factory->projector.height_px);
  }
  return o;
}

DoctorCheck CheckDisplay(const NodeConfig& c, Bench& bench) {
  const std::string name = "display";
  const std::string spec = c.ProjectorSpec();
  if (spec.empty()) {
    return Check(name, CheckVerdict::kFail, "no --projector", "give --projector window:N");
  }
  Expected<std::unique_ptr<ProjectorOutput>> opened = MakeProjectorOutput(spec, Devices(c, bench));
  if (!opened.ok()) {
    return Check(name, CheckVerdict::kFail, spec + ": " + opened.status().message(),
                 "connect the projector and switch it on (is DISPLAY set, is the monitor index "
                 "right?)");
  }
  bench.projector = std::move(*opened);
  const cv::Size size = bench.projector->size();
  std::string detail = bench.projector->description() + ", " + Size(size);
  if (bench.factory) {
    const cv::Size want(bench.factory->projector.width_px, bench.factory->projector.height_px);
    if (size != want) {
      return Check(name, CheckVerdict::kFail,
                   detail + "; the factory file's projector is " + Size(want),
                   "set the display's mode to " + Size(want) +
                       " (xrandr), or calibrate the unit again at this mode");
    }
    detail += ", as the factory file";
  }
  return Check(name, CheckVerdict::kOk, detail);
}

DoctorCheck CheckCamera(const NodeConfig& c, Bench& bench) {
  const std::string name = "camera";
  const std::string spec = c.CameraSpec();
  if (spec.empty()) return Check(name, CheckVerdict::kFail, "no --camera", "give --camera video:N");
  Expected<std::unique_ptr<CameraInput>> opened = MakeCameraInput(spec, Devices(c, bench));
  if (!opened.ok()) {
    return Check(name, CheckVerdict::kFail, spec + ": " + opened.status().message(),
                 "connect the camera (ls /dev/video*; v4l2-ctl --list-devices) and check that "
                 "no other program holds it");
  }
  bench.camera = std::move(*opened);
  Expected<CapturedFrame> frame = bench.camera->Capture(Seconds(0));
  if (!frame.ok()) {
    return Check(
        name, CheckVerdict::kFail,
        bench.camera->description() + ": opened, but a capture failed: " + frame.status().message(),
        "check the cable and the camera's power; try another USB port");
  }
  std::string detail = bench.camera->description() + ", " + Size(frame->image.size()) + " at " +
                       std::to_string(bench.camera->bit_depth()) + " bits";
  if (bench.factory) {
    if (Status same = CheckCameraMatchesFactory(frame->image.size(), bench.camera->description(),
                                                bench.factory->camera);
        !same.ok()) {
      bench.camera.reset();
      return Check(name, CheckVerdict::kFail, same.message(),
                   "set the camera to " +
                       Size({bench.factory->camera.width_px, bench.factory->camera.height_px}) +
                       ", or give this unit's own factory file");
    }
    detail += ", as the factory file";
  }
  return Check(name, CheckVerdict::kOk, detail);
}

// One capture as doubles in [0, 1] of the camera's full scale.
Expected<cv::Mat> Normalised(CameraInput& camera, Seconds exposure, Clock::time_point* when) {
  Expected<CapturedFrame> frame = camera.Capture(exposure);
  if (!frame.ok()) return frame.status();
  if (when) *when = frame->capture_time;
  cv::Mat out;
  frame->image.convertTo(out, CV_64F, 1.0 / ((1 << camera.bit_depth()) - 1));
  return out;
}

Status ShowLevel(ProjectorOutput& projector, int level, Clock::time_point* shown) {
  Expected<ShownFrame> s = projector.Show(cv::Mat(projector.size(), CV_8UC1, cv::Scalar(level)));
  if (!s.ok()) return s.status();
  if (shown) *shown = s->shown_time;
  return OkStatus();
}

double MeanIn(const cv::Mat& image, const cv::Mat& mask) { return cv::mean(image, mask)[0]; }

DoctorCheck CheckLight(Bench& bench, const DoctorOptions& o) {
  const std::string name = "light";
  if (!bench.projector || !bench.camera) return Skip(name, "needs the display and the camera");
  // Settle on each level for a while (a real projector lags a few frames).
  for (int level : {0, 255}) {
    if (Status shown = ShowLevel(*bench.projector, level, nullptr); !shown.ok()) {
      return Check(name, CheckVerdict::kFail, "the display refused a frame: " + shown.message());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    Expected<cv::Mat> image = Normalised(*bench.camera, Seconds(0), nullptr);
    if (!image.ok()) {
      return Check(name, CheckVerdict::kFail, "a capture failed: " + image.status().message());
    }
    (level == 0 ? bench.black : bench.white) = *image;
  }
  cv::Mat difference = bench.white - bench.black;
  bench.lit = difference > o.min_contrast_of_full_scale;
  const double share = cv::countNonZero(bench.lit) / static_cast<double>(bench.lit.total());
  const double white = share > 0 ? MeanIn(bench.white, bench.lit) : 0.0;
  const double black = share > 0 ? MeanIn(bench.black, bench.lit) : 0.0;
  std::string detail =
      "white against black lights " + Fixed(100.0 * share, 1) + " % of the camera image";
  if (share < o.min_lit_share) {
    bench.lit = cv::Mat();  // nothing to time a flash or an exposure on
    return Check(name, CheckVerdict::kFail,
                 detail + " (at least " + Fixed(100.0 * o.min_lit_share, 1) + " % needed)",
                 "the camera does not see this projector's light: aim the camera at the table "
                 "the projector lights, open its lens cap, check the projector's input");
  }
  detail += "; there white " + Fixed(100.0 * white, 1) + " %, black " + Fixed(100.0 * black, 1) +
            " % of full scale";
  if (white > 0.98) {
    return Check(name, CheckVerdict::kWarn, detail + " (white clipped)",
                 "lower the camera's exposure or gain so that white stays below full scale");
  }
  return Check(name, CheckVerdict::kOk, detail);
}

DoctorCheck CheckLatency(Bench& bench, const DoctorOptions& o) {
  const std::string name = "latency";
  if (bench.lit.empty()) return Skip(name, "needs the camera to see the projector (light)");
  const double black = MeanIn(bench.black, bench.lit);
  const double halfway = black + 0.5 * (MeanIn(bench.white, bench.lit) - black);
  std::vector<double> seen_ms;
  int missed = 0;
  for (int flash = 0; flash < o.latency_flashes; ++flash) {
    if (!ShowLevel(*bench.projector, 0, nullptr).ok()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    Clock::time_point shown{};
    if (!ShowLevel(*bench.projector, 255, &shown).ok()) break;
    std::optional<double> ms;
    while (Clock::now() - shown < o.latency_window) {
      Clock::time_point at{};
      Expected<cv::Mat> image = Normalised(*bench.camera, Seconds(0), &at);
      if (!image.ok()) break;
      if (MeanIn(*image, bench.lit) > halfway) {
        ms = std::max(0.0, std::chrono::duration<double, std::milli>(at - shown).count());
        break;
      }
    }
    if (ms) {
      seen_ms.push_back(*ms);
    } else {
      ++missed;
    }
  }
  (void)ShowLevel(*bench.projector, 0, nullptr);
  if (seen_ms.empty()) {
    return Check(name, CheckVerdict::kFail,
                 "a white flash was not seen within " + std::to_string(o.latency_window.count()) +
                     " ms in " + std::to_string(o.latency_flashes) + " tries",
                 "the camera's frames are stale (a deep driver queue?) or it stopped: lower its "
                 "buffer count, check its frame rate");
  }
  std::sort(seen_ms.begin(), seen_ms.end());
  const double median = seen_ms[seen_ms.size() / 2];
  std::string detail = "a white flash seen after " + Fixed(median, 1) + " ms (median of " +
                       std::to_string(seen_ms.size()) + ", " + Fixed(seen_ms.front(), 1) + "-" +
                       Fixed(seen_ms.back(), 1) + " ms)";
  if (missed > 0) {
    return Check(name, CheckVerdict::kWarn,
                 detail + "; " + std::to_string(missed) + " flash(es) not seen",
                 "the camera drops frames now and then: check its frame rate and USB bandwidth");
  }
  return Check(name, CheckVerdict::kOk, detail);
}

DoctorCheck CheckExposure(Bench& bench, const DoctorOptions& o) {
  const std::string name = "exposure";
  if (bench.lit.empty()) return Skip(name, "needs the camera to see the projector (light)");
  // Grey, not white: the longer exposure must have room above it.
  if (!ShowLevel(*bench.projector, 96, nullptr).ok()) return Skip(name, "the display failed");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const Seconds shorter(o.exposure_short_s), longer(o.exposure_short_s * o.exposure_ratio);
  Expected<cv::Mat> dark = Normalised(*bench.camera, shorter, nullptr);
  Expected<cv::Mat> bright = Normalised(*bench.camera, longer, nullptr);
  (void)ShowLevel(*bench.projector, 0, nullptr);
  if (!dark.ok() || !bright.ok()) {
    return Check(name, CheckVerdict::kFail,
                 "a capture at a set exposure failed: " +
                     (dark.ok() ? bright.status() : dark.status()).message(),
                 "the camera refuses exposure settings: check that its driver offers manual "
                 "exposure (v4l2-ctl -l)");
  }
  const double a = MeanIn(*dark, bench.lit), b = MeanIn(*bright, bench.lit);
  const double gain = a > 0 ? b / a : 0.0;
  const std::string detail = Fixed(1e3 * shorter.count(), 1) + " ms -> " + Fixed(100.0 * a, 1) +
                             " %, " + Fixed(1e3 * longer.count(), 1) + " ms -> " +
                             Fixed(100.0 * b, 1) + " % of full scale (x" + Fixed(gain, 2) + ")";
  if (gain < o.min_exposure_gain) {
    return Check(name, CheckVerdict::kWarn, detail + ": the exposure setting has little effect",
                 "the camera chooses its own exposure (auto exposure on?): switch auto exposure "
                 "off, or structured light sees the levels drift");
  }
  return Check(name, CheckVerdict::kOk, detail + ": under control");
}

DoctorCheck CheckCoordinator(NodeConfig c, const Bench& bench, const DoctorOptions& o) {
  const std::string name = "coordinator";
  if (c.coordinator_requests.empty()) return Skip(name, "no --coordinator");
  if (c.coordinator_requests == kDiscover) {
    std::atomic<bool> stop{false};
    std::thread timer([&] {
      const auto until = Clock::now() + o.discovery_timeout;
      while (!stop && Clock::now() < until)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      stop = true;
    });
    if (!c.enroll_keys_path.empty() && fs::exists(c.enroll_keys_path)) {
      c.curve_keys_path = c.enroll_keys_path;
    }
    c.enroll_keys_path.clear();  // the doctor never asks to be accepted
    const Status found = DiscoverCoordinator(c, &stop);
    stop = true;
    timer.join();
    if (!found.ok()) {
      return Check(name, CheckVerdict::kFail,
                   "discover: no coordinator this unit trusts answered within " +
                       std::to_string(o.discovery_timeout.count()) + " ms: " + found.message(),
                   "is the coordinator running with --beacon on this network (UDP port " +
                       std::to_string(c.discovery_port) +
                       ")? or give --coordinator REQUESTS,EVENTS");
    }
  }
  zmq::context_t context;
  net::SocketOptions options;
  if (bench.keys) options.curve = net::ClientCurve(*bench.keys);
  Expected<std::unique_ptr<net::Socket>> dealer =
      net::Socket::Create(&context, net::SocketType::kDealer, options);
  if (!dealer.ok()) return Check(name, CheckVerdict::kFail, dealer.status().message());
  if (Status connected = (*dealer)->Connect(c.coordinator_requests); !connected.ok()) {
    return Check(name, CheckVerdict::kFail, connected.message(),
                 "check --coordinator (tcp://HOST:PORT,tcp://HOST:PORT)");
  }
  proto::MessageCounters counters;
  net::Channel channel(std::move(*dealer), kOperatorSenderId, net::NewIncarnation(), &counters);
  wire::Envelope request;
  request.mutable_time_request()->set_t0_client_send_ns(proto::SteadyNowNs());
  const Clock::time_point sent = Clock::now();
  if (Status s = channel.Send(std::move(request)); !s.ok()) {
    return Check(name, CheckVerdict::kFail, "not sent: " + s.message());
  }
  while (Clock::now() - sent < o.coordinator_timeout) {
    std::vector<bool> readable;
    if (!net::Socket::Poll({&channel.socket()}, std::chrono::milliseconds(20), &readable).ok()) {
      break;
    }
    if (!readable[0]) continue;
    Expected<std::optional<net::Incoming>> in = channel.TryReceive();
    if (in.ok() && in->has_value() && (*in)->envelope.has_time_reply()) {
      const double ms = std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
      return Check(name, CheckVerdict::kOk,
                   c.coordinator_requests + " answered a time request in " + Fixed(ms, 1) + " ms" +
                       (bench.keys ? " (CURVE, the site key)" : ""));
    }
  }
  return Check(name, CheckVerdict::kFail,
               c.coordinator_requests + " did not answer within " +
                   std::to_string(o.coordinator_timeout.count()) + " ms",
               bench.keys ? "is the coordinator running, reachable (firewall: its two TCP ports) "
                            "and of this site (the key file)?"
                          : "is the coordinator running and reachable (firewall: its two TCP "
                            "ports)? a site with keys answers only with --curve-keys");
}

}  // namespace

const char* CheckVerdictName(CheckVerdict verdict) {
  switch (verdict) {
    case CheckVerdict::kOk:
      return "ok";
    case CheckVerdict::kWarn:
      return "warn";
    case CheckVerdict::kFail:
      return "FAIL";
    case CheckVerdict::kSkipped:
      return "skip";
  }
  return "?";
}

std::vector<DoctorCheck> RunDoctorChecks(NodeConfig config, const DoctorOptions& options) {
  Bench bench;
  std::vector<DoctorCheck> checks;
  checks.push_back(CheckFactory(config, bench));
  checks.push_back(CheckKeys(config, bench));
  checks.push_back(CheckDisplay(config, bench));
  checks.push_back(CheckCamera(config, bench));
  checks.push_back(CheckLight(bench, options));
  checks.push_back(CheckLatency(bench, options));
  checks.push_back(CheckExposure(bench, options));
  checks.push_back(CheckCoordinator(config, bench, options));
  return checks;
}

bool Ready(const std::vector<DoctorCheck>& checks) {
  return std::none_of(checks.begin(), checks.end(),
                      [](const DoctorCheck& c) { return c.verdict == CheckVerdict::kFail; });
}

std::string FormatChecklist(const std::vector<DoctorCheck>& checks) {
  std::ostringstream out;
  size_t width = 0;
  for (const DoctorCheck& c : checks) width = std::max(width, c.name.size());
  int failed = 0;
  for (const DoctorCheck& c : checks) {
    const std::string verdict = std::string("[") + CheckVerdictName(c.verdict) + "]";
    out << verdict << std::string(7 - verdict.size(), ' ') << c.name
        << std::string(width + 2 - c.name.size(), ' ') << c.detail << "\n";
    if (!c.todo.empty() && (c.verdict == CheckVerdict::kFail || c.verdict == CheckVerdict::kWarn)) {
      out << std::string(7 + width + 2, ' ') << "-> " << c.todo << "\n";
    }
    failed += c.verdict == CheckVerdict::kFail ? 1 : 0;
  }
  if (failed == 0) {
    out << "ready: yes\n";
  } else {
    out << "ready: no (" << failed << " of " << checks.size() << " checks failed)\n";
  }
  return out.str();
}

int RunDoctor(const std::vector<std::string>& args) {
  CLI::App app{
      "sandtable-node doctor: checks this unit's set-up (its devices, factory file, keys "
      "and coordinator) and says what to fix; the unit's own flags",
      "sandtable-node doctor"};
  cli::Configure(app);
  NodeConfig config;
  AddNodeFlags(app, config);
  cli::AddConfigFileFlags(app, cli::ConfigProgram::kNode);
  Expected<std::vector<std::string>> expanded =
      cli::ExpandConfigFiles(args, cli::ConfigProgram::kNode);
  if (!expanded.ok()) return cli::UsageError(app, expanded.status().message());
  if (std::optional<int> exit = cli::Parse(app, *expanded)) return *exit;
  // Without --coordinator the coordinator's check is skipped, not a usage error.
  NodeConfig checked = config;
  if (checked.coordinator_requests.empty() && checked.coordinator_events.empty()) {
    checked.coordinator_requests = kDiscover;
  }
  if (Status valid = checked.Check(); !valid.ok()) return cli::UsageError(app, valid.message());
  std::cout << "sandtable-node doctor: unit " << config.id << "\n" << std::flush;
  const std::vector<DoctorCheck> checks = RunDoctorChecks(config, DoctorOptions{});
  std::cout << FormatChecklist(checks) << std::flush;
  return Ready(checks) ? 0 : cli::kExitFailure;
}

}  // namespace sandtable::node
