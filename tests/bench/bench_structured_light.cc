// bench_structured_light: our structured-light decoder against OpenCV's GrayCodePattern on the
// real procam-kamino410 captures, decoder speed, and decoder accuracy without trusting any
// projector calibration. Plain program (not Google Benchmark): it prints tables and writes CSV.
//
//   bench_structured_light [--data DIR] [--out DIR] [--repeats N] [--poses N]
//     --data     procam-kamino410 folder (default ../shared/data/procam-kamino410)
//     --out      where the CSVs go (default .): structured_light_speed.csv,
//                structured_light_peer.csv, structured_light_accuracy.csv
//     --repeats  timed repetitions of our decoder, median reported (default 20)
//     --poses    how many of capture_0..4 to use (default 5)
//
// Accuracy (docs/structured-light.md): per pose, the chessboard's 9x7 inner corners are found
// in the white frame; camera pixels inside their convex hull that a decoder decoded are
// undistorted with the shipped (reproducible) camera intrinsics and one homography is fitted
// from them to the decoded projector pixels (least squares, and least squares on the inliers of
// a 3 px RANSAC). Its residual RMS in projector px measures the decoder (plus projector lens
// distortion, which is the same for every decoder).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/cli/command_line.h"
#include "common/structured_light/capture_io.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/opencv_peer.h"
#include "common/structured_light/pattern_sequence.h"
#include "common/structured_light/plane_mapping_residual.h"

namespace sandtable {
namespace {

constexpr int kProjectorWidth_px = 1024;
constexpr int kProjectorHeight_px = 768;
constexpr int kUpstreamBlack = 40;
constexpr int kUpstreamWhite = 5;
constexpr double kRansacThreshold_px = 3.0;
const cv::Size kBoardInnerCorners(9, 7);

struct Args {
  std::string data = "../shared/data/procam-kamino410";
  std::string out = ".";
  int repeats = 20;
  int poses = 5;
};

double MedianMs(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Median wall time of DecodeStructuredLightInto over `repeats` runs (output reused).
double TimeDecode(const std::vector<cv::Mat>& captures, const PatternOptions& p, DecoderOptions o,
                  int threads, int repeats, DecodeReport* last) {
  o.num_threads = threads;
  std::vector<double> ms;
  Decoding out;  // reused: steady state of a node decoding sequence after sequence
  for (int i = 0; i < repeats; ++i) {
    const auto start = std::chrono::steady_clock::now();
    const Status status = DecodeStructuredLightInto(captures, p, o, &out, last);
    const auto stop = std::chrono::steady_clock::now();
    if (!status.ok()) {
      std::fprintf(stderr, "decode failed: %s\n", status.ToString().c_str());
      std::exit(1);
    }
    ms.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
  }
  return MedianMs(ms);
}

// One pass over all captures (bytewise max into an accumulator, OpenCV's SIMD code): the
// memory-bandwidth floor of any decoder that reads every frame once.
double TimeFloor(const std::vector<cv::Mat>& captures, int repeats) {
  std::vector<double> ms;
  cv::Mat acc(captures[0].size(), CV_8UC1);
  for (int i = 0; i < repeats; ++i) {
    const auto start = std::chrono::steady_clock::now();
    acc.setTo(0);
    for (const cv::Mat& m : captures) cv::max(acc, m, acc);
    const auto stop = std::chrono::steady_clock::now();
    ms.push_back(std::chrono::duration<double, std::milli>(stop - start).count());
  }
  return MedianMs(ms);
}

struct Agreement {
  int64_t both = 0, only_a = 0, only_b = 0, same = 0;
};

// Pixels both decode "agree" when each coordinate of `a` lies within the footprint of `b`'s
// integer pixel (|a - b| <= 0.5 px): exact equality for integer decoders, and the sub-pixel
// estimate staying inside OpenCV's pixel otherwise.
Agreement Compare(const Decoding& a, const Decoding& b) {
  Agreement r;
  for (int y = 0; y < a.valid.rows; ++y) {
    for (int x = 0; x < a.valid.cols; ++x) {
      const bool va = a.valid.at<uint8_t>(y, x) != 0;
      const bool vb = b.valid.at<uint8_t>(y, x) != 0;
      r.only_a += (va && !vb) ? 1 : 0;
      r.only_b += (vb && !va) ? 1 : 0;
      if (!(va && vb)) continue;
      ++r.both;
      const cv::Vec2f p = a.projector_px.at<cv::Vec2f>(y, x);
      const cv::Vec2f q = b.projector_px.at<cv::Vec2f>(y, x);
      r.same += (std::abs(p[0] - q[0]) <= 0.5f && std::abs(p[1] - q[1]) <= 0.5f) ? 1 : 0;
    }
  }
  return r;
}

int Run(const Args& args) {
  std::filesystem::create_directories(args.out);
  const int hw_threads = std::max(1u, std::thread::hardware_concurrency());
  cv::FileStorage fs(args.data + "/calibration_result.xml", cv::FileStorage::READ);
  if (!fs.isOpened()) {
    std::fprintf(stderr, "cannot open %s/calibration_result.xml\n", args.data.c_str());
    return 1;
  }
  cv::Mat k, dist;
  fs["cam_int"] >> k;
  fs["cam_dist"] >> dist;

  const PatternOptions dataset =
      PatternOptions::OpenCvGrayCode(kProjectorWidth_px, kProjectorHeight_px);
  const DecoderOptions upstream = DecoderOptions::OpenCvThresholds(kUpstreamBlack, kUpstreamWhite);
  const DecoderOptions defaults;

  std::ofstream speed_csv(args.out + "/structured_light_speed.csv");
  speed_csv << "input,frames,camera_mpx,threads,decode_ms,mpx_per_s,floor_ms\n";
  std::ofstream peer_csv(args.out + "/structured_light_peer.csv");
  peer_csv << "pose,decoder,decoded_fraction,time_ms,mpx_per_s,both_decoded,only_this,"
              "only_opencv,same_value_fraction\n";
  std::ofstream acc_csv(args.out + "/structured_light_accuracy.csv");
  acc_csv << "pose,decoder,board_px,decoded_board_px,decoded_board_fraction,ls_rms_px,"
             "ransac_inlier_fraction,inlier_ls_rms_px\n";

  std::printf("machine: %d hardware threads; our decoder median of %d runs\n\n", hw_threads,
              args.repeats);
  std::printf("%-5s %-16s %9s %10s %9s %10s %10s\n", "pose", "decoder", "decoded%", "time_ms",
              "Mpx/s", "agree%", "mask_diff");
  std::vector<std::string> accuracy_lines;
  for (int pose = 0; pose < args.poses; ++pose) {
    const std::string folder = args.data + "/capture_" + std::to_string(pose);
    auto captures = LoadCaptureSequence(folder, 42);
    if (!captures.ok()) {
      std::fprintf(stderr, "%s\n", captures.status().ToString().c_str());
      return 1;
    }
    const double mpx = captures->front().total() / 1e6;

    // Speed on this pose (Gray only, 42 frames).
    if (pose == 0) {
      const double floor_ms = TimeFloor(*captures, args.repeats);
      for (int t : {1, hw_threads}) {
        DecodeReport r;
        const double ms = TimeDecode(*captures, dataset, defaults, t, args.repeats, &r);
        speed_csv << "real_capture_0_gray," << 42 << "," << mpx << "," << t << "," << ms << ","
                  << mpx / (ms / 1e3) << "," << floor_ms << "\n";
        std::printf(
            "[speed] capture_0 Gray only 42 frames, %d thread(s): %.2f ms, %.1f Mpx/s "
            "(one read pass over the frames: %.2f ms)\n",
            t, ms, mpx / (ms / 1e3), floor_ms);
      }
    }

    double opencv_ms = 0.0;
    const auto peer = DecodeWithOpenCvGrayCode(
        *captures, {kProjectorWidth_px, kProjectorHeight_px, kUpstreamBlack, kUpstreamWhite},
        &opencv_ms);
    if (!peer.ok()) {
      std::fprintf(stderr, "%s\n", peer.status().ToString().c_str());
      return 1;
    }
    const double peer_fraction =
        cv::countNonZero(peer->valid) / static_cast<double>(peer->valid.total());
    std::printf("%-5d %-16s %9.2f %10.1f %9.2f %10s %10s\n", pose, "opencv_40_5",
                100 * peer_fraction, opencv_ms, mpx / (opencv_ms / 1e3), "-", "-");
    peer_csv << pose << ",opencv_40_5," << peer_fraction << "," << opencv_ms << ","
             << mpx / (opencv_ms / 1e3) << ",,,,\n";

    struct Variant {
      const char* name;
      DecoderOptions options;
    };
    DecoderOptions strict = defaults;  // our shadow/contrast thresholds, OpenCV's 0 weak bits
    strict.max_weak_bits_per_axis = 0;
    DecoderOptions upstream_weak1 = upstream;  // OpenCV's thresholds, one weak bit tolerated
    upstream_weak1.max_weak_bits_per_axis = 1;
    const Variant variants[] = {{"ours_40_5", upstream},
                                {"ours_defaults", defaults},
                                {"ours_10_6_weak0", strict},
                                {"ours_40_5_weak1", upstream_weak1}};
    std::vector<Decoding> ours;
    for (const Variant& v : variants) {
      DecodeReport r;
      const double ms = TimeDecode(*captures, dataset, v.options, 1, args.repeats, &r);
      auto d = DecodeStructuredLight(*captures, dataset, v.options);
      const Agreement a = Compare(*d, *peer);
      const double same = a.both > 0 ? static_cast<double>(a.same) / a.both : NAN;
      std::printf("%-5d %-16s %9.2f %10.2f %9.1f %10.4f %10lld\n", pose, v.name,
                  100 * r.DecodedFraction(), ms, mpx / (ms / 1e3), 100 * same,
                  static_cast<long long>(a.only_a + a.only_b));
      peer_csv << pose << "," << v.name << "," << r.DecodedFraction() << "," << ms << ","
               << mpx / (ms / 1e3) << "," << a.both << "," << a.only_a << "," << a.only_b << ","
               << same << "\n";
      ours.push_back(std::move(*d));
    }

    // Accuracy on the chessboard.
    const auto region = ChessboardRegion((*captures)[40], kBoardInnerCorners);
    if (!region.ok()) {
      std::fprintf(stderr, "pose %d: %s\n", pose, region.status().ToString().c_str());
      continue;
    }
    std::vector<std::pair<const char*, const Decoding*>> decoders = {{"opencv_40_5", &*peer}};
    for (size_t i = 0; i < ours.size(); ++i) decoders.emplace_back(variants[i].name, &ours[i]);
    for (const auto& [name, decoding] : decoders) {
      PlaneMappingOptions fit_options;
      fit_options.ransac_threshold_px = kRansacThreshold_px;
      const auto f = FitPlaneMapping(*decoding, *region, k, dist, fit_options);
      if (!f.ok()) {
        std::fprintf(stderr, "pose %d %s: %s\n", pose, name, f.status().ToString().c_str());
        continue;
      }
      char line[256];
      std::snprintf(line, sizeof(line), "%-5d %-16s %9lld %9.1f %10.4f %9.2f %12.4f", pose, name,
                    static_cast<long long>(f->decoded_pixels),
                    100.0 * f->decoded_pixels / std::max<int64_t>(1, f->region_pixels),
                    f->ls_rms_px, 100 * f->inlier_fraction, f->inlier_rms_px);
      accuracy_lines.push_back(line);
      acc_csv << pose << "," << name << "," << f->region_pixels << "," << f->decoded_pixels << ","
              << static_cast<double>(f->decoded_pixels) / std::max<int64_t>(1, f->region_pixels)
              << "," << f->ls_rms_px << "," << f->inlier_fraction << "," << f->inlier_rms_px
              << "\n";
    }
  }

  std::printf("\nboard homography residual (undistorted camera px -> decoded projector px)\n");
  std::printf("%-5s %-16s %9s %9s %10s %9s %12s\n", "pose", "decoder", "board_px", "board%",
              "ls_rms_px", "inlier%", "inl_rms_px");
  for (const std::string& l : accuracy_lines) std::printf("%s\n", l.c_str());

  // Speed with phase shifting: synthetic 1280x1024 captures (the patterns themselves, resized),
  // content does not change the work of a branch-free decoder.
  for (int steps : {4, 8}) {
    PatternOptions p;
    p.projector_width_px = kProjectorWidth_px;
    p.projector_height_px = kProjectorHeight_px;
    p.phase_steps = steps;
    auto frames = GeneratePatterns(p);
    std::vector<cv::Mat> captures;
    for (const cv::Mat& f : *frames) {
      cv::Mat c;
      cv::resize(f, c, cv::Size(1280, 1024), 0, 0, cv::INTER_LINEAR);
      captures.push_back(c);
    }
    const double mpx = 1280 * 1024 / 1e6;
    const double floor_ms = TimeFloor(captures, args.repeats);
    for (int t : {1, hw_threads}) {
      DecodeReport r;
      const double ms = TimeDecode(captures, p, defaults, t, args.repeats, &r);
      speed_csv << "synthetic_gray_phase" << steps << "," << captures.size() << "," << mpx << ","
                << t << "," << ms << "," << mpx / (ms / 1e3) << "," << floor_ms << "\n";
      std::printf(
          "[speed] 1280x1024 Gray + %d-step phase, %zu frames, %d thread(s): %.2f ms, "
          "%.1f Mpx/s (one read pass: %.2f ms)\n",
          steps, captures.size(), t, ms, mpx / (ms / 1e3), floor_ms);
    }
  }
  std::printf("\nCSV written to %s/structured_light_{speed,peer,accuracy}.csv\n", args.out.c_str());
  return 0;
}

}  // namespace
}  // namespace sandtable

int main(int argc, char** argv) {
  sandtable::Args args;
  CLI::App app(
      "Our structured-light decoder against OpenCV's GrayCodePattern on the real "
      "procam-kamino410 captures: agreement, speed and accuracy (CSV).",
      "bench_structured_light");
  sandtable::cli::Configure(app);
  app.add_option("--data", args.data, "procam-kamino410 folder");
  app.add_option("--out", args.out, "where the CSVs go");
  app.add_option("--repeats", args.repeats, "timed repetitions of our decoder (median)")
      ->check(sandtable::cli::Integer(1, 100000));
  app.add_option("--poses", args.poses, "how many of capture_0..4 to use")
      ->check(sandtable::cli::Integer(1, 5));
  if (std::optional<int> exit = sandtable::cli::Parse(app, argc, argv)) return *exit;
  return sandtable::Run(args);
}
