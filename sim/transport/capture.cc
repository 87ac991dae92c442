#include "sim/transport/capture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

namespace sandtable::sim {

namespace {

// Emission per 8-bit code for a projector.
std::array<float, 256> EmissionTable(const ProjectorSpec& projector) {
  std::array<float, 256> table;
  for (int v = 0; v < 256; ++v) {
    table[v] = static_cast<float>(projector.black_level + (1.0 - projector.black_level) *
                                                              std::pow(v / 255.0, projector.gamma));
  }
  return table;
}

// xoshiro256** seeded by splitmix64: fast, portable, well distributed.
class Rng {
 public:
  explicit Rng(uint64_t seed) {
    for (uint64_t& s : s_) {
      seed += 0x9E3779B97F4A7C15ull;
      uint64_t z = seed;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      s = z ^ (z >> 31);
    }
  }
  uint64_t Next() {
    const uint64_t result = Rotl(s_[1] * 5, 7) * 9;
    const uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }  // [0, 1)
  double Gaussian() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    const double u1 = 1.0 - Uniform();  // (0, 1]
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * std::numbers::pi * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * std::numbers::pi * u2);
  }
  // Poisson by multiplication of uniforms (Knuth); used below 32 expected events only.
  int SmallPoisson(double mean) {
    const double limit = std::exp(-mean);
    double product = Uniform();
    int k = 0;
    while (product > limit) {
      ++k;
      product *= Uniform();
    }
    return k;
  }

 private:
  static uint64_t Rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  uint64_t s_[4];
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace

Expected<LinearFrame> DecodeProjectorFrame(const ProjectorSpec& projector, const cv::Mat& frame) {
  if (frame.cols != projector.model.width_px || frame.rows != projector.model.height_px) {
    return InvalidArgumentError("projector frame is " + std::to_string(frame.cols) + "x" +
                                std::to_string(frame.rows) + ", projector is " +
                                std::to_string(projector.model.width_px) + "x" +
                                std::to_string(projector.model.height_px));
  }
  if (frame.type() != CV_8UC1 && frame.type() != CV_8UC3) {
    return InvalidArgumentError("projector frame must be 8-bit grey (CV_8UC1) or BGR (CV_8UC3)");
  }
  const std::array<float, 256> table = EmissionTable(projector);
  LinearFrame out;
  out.width_px = frame.cols;
  out.height_px = frame.rows;
  out.emission.assign(static_cast<size_t>(out.padded_width()) * (frame.rows + 2 * kFramePadding_px),
                      0.0f);
  for (int y = 0; y < frame.rows; ++y) {
    const uint8_t* row = frame.ptr<uint8_t>(y);
    float* dst = &out.emission[static_cast<size_t>(y + kFramePadding_px) * out.padded_width() +
                               kFramePadding_px];
    if (frame.type() == CV_8UC1) {
      for (int x = 0; x < frame.cols; ++x) dst[x] = table[row[x]];
    } else {
      // Luminance of the emitted linear light (Rec. 709 weights on B, G, R).
      for (int x = 0; x < frame.cols; ++x) {
        dst[x] = 0.0722f * table[row[3 * x]] + 0.7152f * table[row[3 * x + 1]] +
                 0.2126f * table[row[3 * x + 2]];
      }
    }
  }
  return out;
}

LinearFrame UniformFrame(const ProjectorSpec& projector, int value) {
  LinearFrame out;
  out.width_px = projector.model.width_px;
  out.height_px = projector.model.height_px;
  out.emission.assign(
      static_cast<size_t>(out.padded_width()) * (out.height_px + 2 * kFramePadding_px), 0.0f);
  const float e = EmissionTable(projector)[std::clamp(value, 0, 255)];
  for (int y = 0; y < out.height_px; ++y) {
    float* row = &out.emission[static_cast<size_t>(y + kFramePadding_px) * out.padded_width() +
                               kFramePadding_px];
    std::fill(row, row + out.width_px, e);
  }
  return out;
}

Status GatherLuminance(const TransportMap& map, const std::vector<const LinearFrame*>& frames,
                       double ambient_luminance_nits, std::vector<float>* luminance) {
  if (frames.size() != map.entries.size()) {
    return InvalidArgumentError("gather: " + std::to_string(frames.size()) + " frames for " +
                                std::to_string(map.entries.size()) + " projectors");
  }
  const size_t n = static_cast<size_t>(map.width_px) * map.height_px;
  luminance->resize(n);
  const float ambient = static_cast<float>(ambient_luminance_nits);
  for (size_t i = 0; i < n; ++i) (*luminance)[i] = map.albedo[i] * ambient;
  float* out = luminance->data();
  for (size_t p = 0; p < frames.size(); ++p) {
    const LinearFrame* f = frames[p];
    if (!f) continue;
    if (f->emission.empty())
      return InvalidArgumentError("gather: empty frame for projector " + std::to_string(p));
    const size_t stride = f->padded_width();
    const float* emission = f->emission.data();
    constexpr float kWeightScale = 1.0f / 65535.0f;
    for (const TransportEntry& e : map.entries[p]) {
      const float* base = emission + e.frame_offset;
      const float wu0 = e.wu[0], wu1 = e.wu[1], wu2 = e.wu[2], wu3 = e.wu[3];
      float sum = 0.0f;
      for (int j = 0; j < 4; ++j) {
        const float* row = base + j * stride;
        sum += e.wv[j] * (wu0 * row[0] + wu1 * row[1] + wu2 * row[2] + wu3 * row[3]);
      }
      out[e.pixel] += kWeightScale * sum;
    }
  }
  return OkStatus();
}

Expected<cv::Mat> SynthesizeCapture(const CameraSpec& camera, int width, int height,
                                    const std::vector<float>& luminance,
                                    const CaptureNoise& noise) {
  if (luminance.size() != static_cast<size_t>(width) * height) {
    return InvalidArgumentError("capture: luminance has " + std::to_string(luminance.size()) +
                                " values for " + std::to_string(width) + "x" +
                                std::to_string(height));
  }
  const bool eight_bit = camera.bit_depth <= 8;
  cv::Mat out(height, width, eight_bit ? CV_8UC1 : CV_16UC1);
  const double max_dn = camera.MaxDn();
  const double scale = camera.exposure_s / camera.saturation_nit_s;  // 1 = full scale
  const double inverse_gamma = 1.0 / camera.gamma;
  const bool linear = camera.gamma == 1.0;
  const double well = camera.full_well_e;
  const bool shot = noise.enabled && well > 0;
  const bool read = noise.enabled && camera.read_noise_dn > 0;
  const double read_variance_dn2 = read ? camera.read_noise_dn * camera.read_noise_dn : 0.0;
  for (int y = 0; y < height; ++y) {
    Rng rng(noise.seed * 0x100000001B3ull + static_cast<uint64_t>(y) + 1);
    const float* l = &luminance[static_cast<size_t>(y) * width];
    for (int x = 0; x < width; ++x) {
      const double s = l[x] * scale;  // linear, full scale = 1
      double dn_linear = s * max_dn;
      if (shot) {
        const double electrons = s * well;
        if (electrons < 32.0) {
          dn_linear = rng.SmallPoisson(electrons) / well * max_dn;
          if (read) dn_linear += camera.read_noise_dn * rng.Gaussian();
        } else {
          // Poisson (Gaussian limit, variance = electrons) and read noise are independent
          // Gaussians: one draw with the summed variance, in DN.
          const double shot_dn = std::sqrt(electrons) / well * max_dn;
          dn_linear += std::sqrt(shot_dn * shot_dn + read_variance_dn2) * rng.Gaussian();
        }
      } else if (read) {
        dn_linear += camera.read_noise_dn * rng.Gaussian();
      }
      double encoded = std::clamp(dn_linear / max_dn, 0.0, 1.0);
      if (!linear) encoded = std::pow(encoded, inverse_gamma);
      const double dn = std::nearbyint(encoded * max_dn);
      if (eight_bit) {
        out.at<uint8_t>(y, x) = static_cast<uint8_t>(dn);
      } else {
        out.at<uint16_t>(y, x) = static_cast<uint16_t>(dn);
      }
    }
  }
  return out;
}

}  // namespace sandtable::sim
