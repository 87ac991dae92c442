// Run time against error of the structured-light measurement in the simulated world (issue 4):
// Gray bits (full vs skipping the finest), phase steps, phase period and camera noise.
//
//   structured_light_sweep --out DIR [--site sandtable-3] [--width W --height H] [--quick]
//                          [--capture-latency-s 0.05] [--repeats 3]
//
// For every setting: generate the patterns at the projector's resolution, show them on unit 0's
// projector of the site (default scene of the preset), capture each with unit 0's camera
// (World::Capture, noise seeded per frame), decode single-threaded (median of --repeats), and
// compare with the world's ground truth (sim_decode_harness.h). Writes
// DIR/structured_light_sweep.csv, one row per setting:
//   group            which sweep the row belongs to: gray_bits, phase_steps, period, noise
//   gray_skip, phase_steps, period_px
//   noise            label; read_noise_dn, full_well_e, exposure_s: the camera's
//   frames           frames shown (both axes)
//   device_time_s    modeled time on the rig: frames / 60 Hz + capture latency once (pipelined
//                    capture: frame k is read out while frame k + 1 is shown)
//   decode_ms        decoder wall time, one thread, median
//   rms_px, p99_px   2-D error of decoded lit pixels against the true projector pixel
//   rms_interior_px  the same away from depth and shadow edges (sim_decode_harness.h)
//   decoded_fraction decoded lit pixels / lit pixels
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "common/cli/command_line.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/pattern_sequence.h"
#include "tests/common/structured_light/sim_decode_harness.h"

namespace sandtable::sim_decode {
namespace {

constexpr double kRefreshRate_hz = 60.0;
constexpr uint64_t kNoiseSeed = 7;

struct Noise {
  std::string label;
  double read_scale, photon_scale, exposure_scale;
};

struct Setting {
  std::string group;
  int gray_skip = 0;
  int phase_steps = 8;
  double period_px = 16.0;
  Noise noise{"default", 1.0, 1.0, 1.0};
};

struct Args {
  std::string out_dir, site = "sandtable-3";
  int width_px = 0, height_px = 0, repeats = 3;
  double capture_latency_s = 0.05;
  bool quick = false;
};

int Run(const Args& args) {
  std::vector<Noise> noises = {{"off", 0, 0, 1},
                               {"default", 1, 1, 1},
                               {"read2x_photon2x", 2, 2, 1},
                               {"read4x_photon4x", 4, 4, 1},
                               {"exposure_quarter", 1, 1, 0.25},
                               {"read8x_photon8x", 8, 8, 1}};
  std::vector<Setting> settings;
  for (int skip : {0, 1, 2, 3}) {
    settings.push_back({.group = "gray_bits", .gray_skip = skip, .phase_steps = 0});
    settings.push_back({.group = "gray_bits", .gray_skip = skip, .phase_steps = 8});
  }
  for (int steps : {3, 4, 6, 8, 12}) {
    settings.push_back({.group = "phase_steps", .phase_steps = steps});
    settings.push_back({.group = "phase_steps", .gray_skip = 2, .phase_steps = steps});
  }
  for (double period : {8.0, 12.0, 16.0, 24.0, 32.0, 64.0}) {
    settings.push_back({.group = "period", .phase_steps = 8, .period_px = period});
  }
  for (const Noise& n : noises) {
    settings.push_back({.group = "noise", .phase_steps = 0, .noise = n});
    settings.push_back({.group = "noise", .phase_steps = 4, .noise = n});
    settings.push_back({.group = "noise", .phase_steps = 8, .noise = n});
  }
  if (args.quick) settings.resize(4);

  std::filesystem::create_directories(args.out_dir);
  const std::string path = args.out_dir + "/structured_light_sweep.csv";
  std::ofstream csv(path);
  if (!csv) {
    std::cerr << "cannot write " << path << "\n";
    return 1;
  }
  csv << "group,gray_skip,phase_steps,period_px,noise,read_noise_dn,full_well_e,exposure_s,"
         "frames,device_time_s,decode_ms,rms_px,p99_px,rms_interior_px,decoded_fraction,status\n";

  // One world per noise setting (the camera spec is part of the site).
  std::string world_noise;
  Expected<SimDecodeWorld> w = InvalidArgumentError("no world yet");
  std::stable_sort(settings.begin(), settings.end(), [](const Setting& a, const Setting& b) {
    return a.noise.label < b.noise.label;
  });
  for (const Setting& s : settings) {
    if (!w.ok() || world_noise != s.noise.label) {
      SimDecodeSetup setup;
      setup.site_preset = args.site;
      setup.scene_preset = args.site == "sandtable-3" ? "sandtable"
                           : args.site == "flat-4"    ? "flat"
                                                      : "city";
      setup.camera_width_px = args.width_px;
      setup.camera_height_px = args.height_px;
      setup.read_noise_scale = s.noise.read_scale;
      setup.photon_noise_scale = s.noise.photon_scale;
      setup.exposure_scale = s.noise.exposure_scale;
      w = MakeSimDecodeWorld(setup);
      if (!w.ok()) {
        std::cerr << w.status().ToString() << "\n";
        return 1;
      }
      world_noise = s.noise.label;
    }
    PatternOptions base;
    base.gray_lsb_skip = s.gray_skip;
    base.phase_steps = s.phase_steps;
    base.phase_period_px = s.period_px;
    const PatternOptions patterns = PatternsFor(*w, base);
    DecoderOptions decoder;
    decoder.num_threads = 1;
    std::string status = "ok";
    Status check = decoder.CheckAgainst(patterns);
    const sim::CameraSpec& camera = *w->world->site().FindUnit(w->unit)->camera;
    double decode_ms = 0;
    DecodeErrorStats all, interior;
    int frames_shown = 0;
    if (!check.ok()) {
      status = std::string(StatusCodeName(check.code()));
    } else {
      Expected<std::vector<cv::Mat>> frames = GeneratePatterns(patterns);
      Expected<std::vector<cv::Mat>> captures =
          frames.ok() ? CaptureSequence(*w, *frames, s.noise.label != "off", kNoiseSeed)
                      : Expected<std::vector<cv::Mat>>(frames.status());
      if (!captures.ok()) {
        std::cerr << captures.status().ToString() << "\n";
        return 1;
      }
      frames_shown = static_cast<int>(frames->size());
      std::vector<double> times_ms;
      Decoding decoding;
      for (int r = 0; r < args.repeats; ++r) {
        DecodeReport report;
        Status st = DecodeStructuredLightInto(*captures, patterns, decoder, &decoding, &report);
        if (!st.ok()) {
          std::cerr << st.ToString() << "\n";
          return 1;
        }
        times_ms.push_back(report.decode_time_ms);
      }
      std::nth_element(times_ms.begin(), times_ms.begin() + times_ms.size() / 2, times_ms.end());
      decode_ms = times_ms[times_ms.size() / 2];
      all = CompareWithTruth(*w, decoding, w->lit);
      interior = CompareWithTruth(*w, decoding, w->lit_interior);
    }
    const double device_time_s = frames_shown / kRefreshRate_hz + args.capture_latency_s;
    char line[512];
    std::snprintf(
        line, sizeof(line), "%s,%d,%d,%g,%s,%g,%g,%g,%d,%.4f,%.2f,%.4f,%.4f,%.4f,%.5f,%s\n",
        s.group.c_str(), s.gray_skip, s.phase_steps, s.period_px, s.noise.label.c_str(),
        camera.read_noise_dn, camera.full_well_e, camera.exposure_s, frames_shown, device_time_s,
        decode_ms, all.rms_px, all.p99_px, interior.rms_px, all.DecodedFraction(), status.c_str());
    csv << line;
    std::cout << line << std::flush;
  }
  std::cout << "wrote " << path << "\n";
  return 0;
}

}  // namespace
}  // namespace sandtable::sim_decode

int main(int argc, char** argv) {
  sandtable::sim_decode::Args args;
  CLI::App app("Run time against error of structured light in the simulated world (CSV).",
               "structured_light_sweep");
  sandtable::cli::Configure(app);
  app.add_option("--out", args.out_dir, "folder of structured_light_sweep.csv")->required();
  app.add_option("--site", args.site, "site preset (unit 0 is measured)");
  CLI::Option* width = app.add_option("--width", args.width_px, "camera width, px (0: the site's)")
                           ->check(sandtable::cli::Integer(16, 16384));
  CLI::Option* height =
      app.add_option("--height", args.height_px, "camera height, px (0: the site's)")
          ->check(sandtable::cli::Integer(16, 16384));
  width->needs(height);
  height->needs(width);
  app.add_option("--repeats", args.repeats, "decodes per setting (median)")
      ->check(sandtable::cli::Integer(1, 1000));
  app.add_option("--capture-latency-s", args.capture_latency_s, "modeled capture latency, s")
      ->check(sandtable::cli::Real(0.0, 10.0));
  app.add_flag("--quick", args.quick, "fewer settings (a smoke run)");
  if (std::optional<int> exit = sandtable::cli::Parse(app, argc, argv)) return *exit;
  return sandtable::sim_decode::Run(args);
}
