#include "sim/transport/capture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "sim/transport/noise_rng.h"

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

}  // namespace

Expected<LinearFrame> DecodeProjectorFrame(const ProjectorSpec& projector, const cv::Mat& frame) {
  if (frame.cols != projector.model.width_px || frame.rows != projector.model.height_px) {
    return InvalidArgumentError("projector frame is " + std::to_string(frame.cols) + "x" +
                                std::to_string(frame.rows) + ", projector is " +
                                std::to_string(projector.model.width_px) + "x" +
                                std::to_string(projector.model.height_px));
  }
  if (frame.type() != CV_8UC1 && frame.type() != CV_8UC3 && frame.type() != CV_16UC1) {
    return InvalidArgumentError(
        "projector frame must be 8-bit grey (CV_8UC1), BGR (CV_8UC3) or 16-bit grey (CV_16UC1)");
  }
  const std::array<float, 256> table = EmissionTable(projector);
  LinearFrame out;
  out.width_px = frame.cols;
  out.height_px = frame.rows;
  out.emission.assign(static_cast<size_t>(out.padded_width()) * out.padded_height(), 0.0f);
  if (frame.type() == CV_16UC1) {
    // A deeper input (the same response over v / 65535): what 8-bit quantisation costs.
    for (int y = 0; y < frame.rows; ++y) {
      const uint16_t* row = frame.ptr<uint16_t>(y);
      float* dst = &out.emission[static_cast<size_t>(y + kFramePadding_px) * out.padded_width() +
                                 kFramePadding_px];
      for (int x = 0; x < frame.cols; ++x) {
        dst[x] = static_cast<float>(projector.black_level +
                                    (1.0 - projector.black_level) *
                                        std::pow(row[x] / 65535.0, projector.gamma));
      }
    }
    return out;
  }
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
  out.emission.assign(static_cast<size_t>(out.padded_width()) * out.padded_height(), 0.0f);
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
    if (f->emission.size() != static_cast<size_t>(f->padded_width()) * f->padded_height()) {
      return InvalidArgumentError("gather: frame of projector " + std::to_string(p) + " has " +
                                  std::to_string(f->emission.size()) +
                                  " values, expected the padded size");
    }
    const size_t stride = f->padded_width();
    const float* emission = f->emission.data();
    constexpr float kWeightScale = 1.0f / 65535.0f;
    for (const TransportEntry& e : map.entries[p]) {
      const float* base = emission + e.frame_offset;
      // Columns first (c = sum_j wv[j] row_j, four independent lanes the compiler keeps in
      // one SIMD register), then one dot product with wu: one horizontal sum per entry.
      float c[4] = {0.0f, 0.0f, 0.0f, 0.0f};
      for (int j = 0; j < 4; ++j) {
        const float* row = base + j * stride;
        const float w = e.wv[j];
        for (int i = 0; i < 4; ++i) c[i] += w * row[i];
      }
      const float sum = static_cast<float>(e.wu[0]) * c[0] + static_cast<float>(e.wu[1]) * c[1] +
                        static_cast<float>(e.wu[2]) * c[2] + static_cast<float>(e.wu[3]) * c[3];
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
  const double well = camera.full_well_e;
  const bool shot = noise.enabled && well > 0;
  const bool read = noise.enabled && camera.read_noise_dn > 0;
  // Per pixel in float (24-bit mantissa: exact to 1e-7 of full scale, far below 1 DN of 16
  // bits): linear DN = L * dn_per_nit.
  const float dn_per_nit = static_cast<float>(camera.exposure_s / camera.saturation_nit_s * max_dn);
  const float electrons_per_dn = static_cast<float>(well / max_dn);
  const float dn_per_electron = static_cast<float>(max_dn / well);
  const float read_dn = static_cast<float>(camera.read_noise_dn);
  const float read_variance_dn2 = read ? read_dn * read_dn : 0.0f;
  // Shot noise variance in DN^2 of a signal of `dn` DN: electrons dn e/DN, Poisson variance
  // = electrons, times (DN/e)^2 = dn * max_dn / well.
  const float shot_variance_per_dn = shot ? dn_per_electron : 0.0f;
  const float max_dn_f = static_cast<float>(max_dn);
  const bool linear = camera.gamma == 1.0;
  const double inverse_gamma = 1.0 / camera.gamma;
  // Below this many expected electrons the Gaussian limit of Poisson is poor: exact Poisson.
  constexpr float kSmallPoissonElectrons = 32.0f;
  const float small_poisson_dn = kSmallPoissonElectrons * dn_per_electron;
  // Per row, in passes that the compiler vectorises except the draws themselves:
  //   1. linear DN of every pixel;
  //   2. one standard normal per pixel (a tight loop: the ziggurat's fast path);
  //   3. noise: pixels below the small-Poisson limit draw an exact Poisson count (+ read
  //      noise from their normal), the others add sigma(dn) times their normal;
  //   4. clamp, encode, round, store.
  // The draws of a row come in a fixed order from the row's own generator, so the image is
  // deterministic for a seed whatever the thread count.
  std::vector<float> dn_row(width), normal_row(width);
  for (int y = 0; y < height; ++y) {
    const float* l = &luminance[static_cast<size_t>(y) * width];
    float* dn = dn_row.data();
    for (int x = 0; x < width; ++x) dn[x] = l[x] * dn_per_nit;
    if (shot || read) {
      NoiseRng rng(noise.seed * 0x100000001B3ull + static_cast<uint64_t>(y) + 1);
      float* z = normal_row.data();
      for (int x = 0; x < width; ++x) z[x] = rng.Normal();
      for (int x = 0; x < width; ++x) {
        // Poisson (Gaussian limit, variance = electrons) and read noise are independent
        // Gaussians: one draw with the summed variance, in DN.
        const float sigma =
            std::sqrt(std::max(0.0f, dn[x]) * shot_variance_per_dn + read_variance_dn2);
        dn[x] += sigma * z[x];
      }
      if (shot) {
        for (int x = 0; x < width; ++x) {
          const float signal_dn = l[x] * dn_per_nit;
          if (signal_dn >= small_poisson_dn) continue;
          dn[x] =
              static_cast<float>(rng.SmallPoisson(std::max(0.0f, signal_dn) * electrons_per_dn)) *
                  dn_per_electron +
              read_dn * z[x];
        }
      }
    }
    uint8_t* row8 = eight_bit ? out.ptr<uint8_t>(y) : nullptr;
    uint16_t* row16 = eight_bit ? nullptr : out.ptr<uint16_t>(y);
    for (int x = 0; x < width; ++x) {
      float v = std::clamp(dn[x], 0.0f, max_dn_f);
      if (!linear) v = static_cast<float>(std::pow(v / max_dn, inverse_gamma) * max_dn);
      // Round to nearest (v >= 0, so truncating v + 0.5 rounds halves up).
      const int rounded = static_cast<int>(v + 0.5f);
      if (eight_bit) {
        row8[x] = static_cast<uint8_t>(rounded);
      } else {
        row16[x] = static_cast<uint16_t>(rounded);
      }
    }
  }
  return out;
}

}  // namespace sandtable::sim
