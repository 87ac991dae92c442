#include "sim/lab/render_metrics.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "sim/lab/lab_images.h"
#include "sim/lab/registration_metric.h"
#include "sim/transport/world.h"

namespace sandtable::sim {
namespace {

constexpr int kPatch_px = 128;
constexpr int kStep_px = 32;
constexpr int kSearch_px = 16;     // the largest shift measured (a 1 mm top view: 16 mm)
constexpr double kCoverage = 0.6;  // of a full patch's line pixels

// Line pixels: brighter than the image's dark level by half the lines' contrast.
cv::Mat LineMask(const cv::Mat& luminance) {
  std::vector<float> v(luminance.begin<float>(), luminance.end<float>());
  std::sort(v.begin(), v.end());
  const float dark = v[v.size() / 2];  // most of a grid image is dark
  const float bright = v[std::min(v.size() - 1, v.size() * 995 / 1000)];
  cv::Mat mask = luminance > dark + 0.5f * (bright - dark);
  return mask;
}

}  // namespace

nlohmann::json GridCoincidence::ToJson() const {
  nlohmann::json pairs = nlohmann::json::array();
  for (const auto& [pair, n] : patches_per_pair) {
    pairs.push_back({{"units", {pair.first, pair.second}}, {"patches", n}});
  }
  return {{"patches", patches},
          {"rms_mm", rms_mm},
          {"p99_mm", p99_mm},
          {"max_mm", max_mm},
          {"pairs", pairs}};
}

Expected<GridCoincidence> MeasureGridCoincidence(const std::map<NodeId, TopView>& views,
                                                 const cv::Mat& table_mask) {
  if (views.size() < 2) return NotFoundError("grid coincidence: fewer than two projectors");
  const cv::Size size = views.begin()->second.luminance.size();
  std::map<NodeId, cv::Mat> masks;
  for (const auto& [id, view] : views) {
    if (view.luminance.size() != size || view.luminance.type() != CV_32FC1) {
      return InvalidArgumentError("grid coincidence: top views of different sizes");
    }
    masks[id] = LineMask(view.luminance);
  }
  if (!table_mask.empty() && (table_mask.size() != size || table_mask.type() != CV_8UC1)) {
    return InvalidArgumentError("grid coincidence: the table mask is not the views' size");
  }
  const double mm_per_px = views.begin()->second.mm_per_px();
  // A full patch holds two families of lines every 100 mm, each as wide as the line image.
  GridCoincidence out;
  std::vector<double> shifts_mm;
  for (auto a = views.begin(); a != views.end(); ++a) {
    for (auto b = std::next(a); b != views.end(); ++b) {
      const cv::Mat& ma = masks[a->first];
      const cv::Mat& mb = masks[b->first];
      // The line pixels a full patch holds: the larger of the two images' densest patches.
      int full = 0;
      for (int y = 0; y + kPatch_px <= size.height; y += kStep_px) {
        for (int x = 0; x + kPatch_px <= size.width; x += kStep_px) {
          const cv::Rect r(x, y, kPatch_px, kPatch_px);
          full = std::max({full, cv::countNonZero(ma(r)), cv::countNonZero(mb(r))});
        }
      }
      if (full == 0) continue;
      for (int y = 0; y + kPatch_px <= size.height; y += kStep_px) {
        for (int x = 0; x + kPatch_px <= size.width; x += kStep_px) {
          const cv::Rect r(x, y, kPatch_px, kPatch_px);
          if (!table_mask.empty() && cv::countNonZero(table_mask(r)) < kPatch_px * kPatch_px) {
            continue;
          }
          if (cv::countNonZero(ma(r)) < kCoverage * full ||
              cv::countNonZero(mb(r)) < kCoverage * full) {
            continue;
          }
          // The shift of b against a: b's central part matched over a within +-kSearch_px
          // (normalised cross-correlation; lines repeat every 100 px, far outside the search),
          // refined to sub-pixel by a parabola through the peak and its neighbours.
          const cv::Rect inner(x + kSearch_px, y + kSearch_px, kPatch_px - 2 * kSearch_px,
                               kPatch_px - 2 * kSearch_px);
          cv::Mat score;
          cv::matchTemplate(a->second.luminance(r), b->second.luminance(inner), score,
                            cv::TM_CCOEFF_NORMED);
          double best = 0.0;
          cv::Point peak;
          cv::minMaxLoc(score, nullptr, &best, nullptr, &peak);
          if (best < 0.5) continue;  // not the same pattern
          auto refine = [&](int i, int n, float lo, float mid, float hi) {
            if (i <= 0 || i >= n - 1) return static_cast<double>(i);
            const double d = lo - 2.0 * mid + hi;
            return d < 0.0 ? i + 0.5 * (lo - hi) / d : static_cast<double>(i);
          };
          const double sx =
              refine(peak.x, score.cols, peak.x > 0 ? score.at<float>(peak.y, peak.x - 1) : 0.f,
                     score.at<float>(peak),
                     peak.x + 1 < score.cols ? score.at<float>(peak.y, peak.x + 1) : 0.f) -
              kSearch_px;
          const double sy =
              refine(peak.y, score.rows, peak.y > 0 ? score.at<float>(peak.y - 1, peak.x) : 0.f,
                     score.at<float>(peak),
                     peak.y + 1 < score.rows ? score.at<float>(peak.y + 1, peak.x) : 0.f) -
              kSearch_px;
          const double mm = std::hypot(sx, sy) * mm_per_px;
          shifts_mm.push_back(mm);
          ++out.patches_per_pair[{a->first, b->first}];
        }
      }
    }
  }
  out.patches = static_cast<int>(shifts_mm.size());
  if (shifts_mm.empty()) return NotFoundError("grid coincidence: no overlap patch measured");
  double sum2 = 0.0;
  for (double s : shifts_mm) sum2 += s * s;
  out.rms_mm = std::sqrt(sum2 / shifts_mm.size());
  out.p99_mm = Quantile(shifts_mm, 0.99);
  out.max_mm = *std::max_element(shifts_mm.begin(), shifts_mm.end());
  return out;
}

nlohmann::json TimelineSkew::ToJson() const {
  return {{"instants", instants},
          {"nodes", nodes},
          {"p50_ms", p50_ms},
          {"p99_ms", p99_ms},
          {"max_ms", max_ms}};
}

Expected<TimelineSkew> MeasureTimelineSkew(const std::map<NodeId, std::string>& logs,
                                           const std::map<NodeId, int64_t>& clock_offsets_ns) {
  struct Frame {
    int64_t ns;
    double media_s;
    bool playing;
    double rate;
  };
  std::map<NodeId, std::vector<Frame>> frames;
  for (const auto& [id, path] : logs) {
    const auto offset = clock_offsets_ns.find(id);
    const int64_t offset_ns = offset == clock_offsets_ns.end() ? 0 : offset->second;
    std::ifstream in(path);
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
      std::stringstream s(line);
      std::string f[5];
      for (auto& field : f) std::getline(s, field, ',');
      try {
        Frame fr{std::stoll(f[0]) - offset_ns, std::stod(f[1]), f[2] == "1",
                 f[4].empty() ? 1.0 : std::stod(f[4])};
        if (fr.playing) frames[id].push_back(fr);
      } catch (const std::exception&) {
        continue;  // a line cut short by a killed node
      }
    }
    if (frames[id].empty()) frames.erase(id);
  }
  if (frames.size() < 2) {
    return NotFoundError("timeline skew: fewer than two nodes logged frames while playing");
  }
  int64_t from = 0, to = std::numeric_limits<int64_t>::max();
  for (const auto& [id, f] : frames) {
    from = std::max(from, f.front().ns);
    to = std::min(to, f.back().ns);
  }
  TimelineSkew out;
  out.nodes = static_cast<int>(frames.size());
  std::vector<double> spreads_ms;
  for (int64_t t = from; t <= to; t += 20'000'000) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const auto& [id, f] : frames) {
      auto it = std::upper_bound(f.begin(), f.end(), t,
                                 [](int64_t v, const Frame& fr) { return v < fr.ns; });
      const Frame& last = *std::prev(it);
      const double media = last.media_s + last.rate * 1e-9 * static_cast<double>(t - last.ns);
      lo = std::min(lo, media);
      hi = std::max(hi, media);
    }
    spreads_ms.push_back(1e3 * (hi - lo));
  }
  if (spreads_ms.empty()) return NotFoundError("timeline skew: the nodes never played together");
  out.instants = static_cast<int>(spreads_ms.size());
  out.p50_ms = Quantile(spreads_ms, 0.5);
  out.p99_ms = Quantile(spreads_ms, 0.99);
  out.max_ms = *std::max_element(spreads_ms.begin(), spreads_ms.end());
  return out;
}

Status WriteLabTracks(const std::string& path, int count, double duration_s, double area_radius_m) {
  std::ofstream out(path);
  out << "track_id,t_s,x_m,y_m,z_m\n";
  for (int k = 0; k < count; ++k) {
    const double r = area_radius_m * (0.35 + 0.6 * k / std::max(1, count - 1));
    const double phase = 2.0 * M_PI * k / std::max(1, count);
    for (double t = 0.0; t <= duration_s + 1e-9; t += 0.5) {
      // A slow loop with a wobble: people walking round the site.
      const double a = phase + 2.0 * M_PI * t / duration_s;
      const double wobble = 1.0 + 0.15 * std::sin(5.0 * a + k);
      out << k << "," << t << "," << r * wobble * std::cos(a) << "," << r * wobble * std::sin(a)
          << ",0\n";
    }
  }
  out.close();
  if (!out) return IoError("cannot write the tracks " + path);
  return OkStatus();
}

cv::Mat LuminancePicture(const cv::Mat& luminance) {
  const std::vector<float> values(luminance.begin<float>(), luminance.end<float>());
  return LuminanceToImage(values, luminance.cols, luminance.rows, LitWhiteLevel(values));
}

}  // namespace sandtable::sim
