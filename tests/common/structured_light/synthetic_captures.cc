#include "tests/common/structured_light/synthetic_captures.h"

#include <cmath>

#include <opencv2/imgproc.hpp>

namespace sandtable::testing {

SyntheticCamera DefaultSyntheticCamera() {
  SyntheticCamera cam;
  // Affine part: scale about 1.05, 8 degree rotation, offset into the projector image; plus a
  // mild perspective term so the scale changes across the image.
  const double angle_rad = 8.0 * M_PI / 180.0;
  const double scale = 1.05;
  cam.projector_from_camera = cv::Matx33d(scale * std::cos(angle_rad), -scale * std::sin(angle_rad),
                                          120.0, scale * std::sin(angle_rad),
                                          scale * std::cos(angle_rad), 60.0, 1.2e-4, -0.8e-4, 1.0);
  return cam;
}

cv::Point2d TrueProjectorPixel(const SyntheticCamera& cam, int x, int y) {
  const cv::Vec3d p = cam.projector_from_camera * cv::Vec3d(x, y, 1.0);
  return {p[0] / p[2], p[1] / p[2]};
}

std::vector<cv::Mat> RenderCaptures(const std::vector<cv::Mat>& patterns,
                                    const SyntheticCamera& cam, uint64_t seed) {
  cv::RNG rng(seed);
  const cv::Size size(cam.width_px, cam.height_px);
  std::vector<cv::Mat> captures;
  for (const cv::Mat& pattern : patterns) {
    cv::Mat radiance;
    pattern.convertTo(radiance, CV_32F, 1.0 / 255.0);
    cv::pow(radiance, cam.gamma, radiance);
    cv::Mat seen;
    cv::warpPerspective(radiance, seen, cv::Mat(cam.projector_from_camera), size,
                        cv::INTER_LINEAR | cv::WARP_INVERSE_MAP, cv::BORDER_CONSTANT, 0.0);
    cv::Mat blurred;
    cv::GaussianBlur(seen, blurred, cv::Size(), cam.blur_sigma_px);
    if (!cam.heavy_blur.empty()) {
      cv::Mat heavy;
      cv::GaussianBlur(seen, heavy, cv::Size(), 4.0);
      heavy(cam.heavy_blur).copyTo(blurred(cam.heavy_blur));
    }
    cv::Mat light = blurred * cam.gain;
    if (!cam.shadow.empty()) light(cam.shadow).setTo(0.0);
    if (!cam.saturated.empty()) light(cam.saturated) *= 4.0;
    cv::Mat noise(size, CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, cam.noise_sigma);
    cv::Mat image = light + cam.ambient + noise;
    cv::Mat capture;
    image.convertTo(capture, CV_8U);  // rounds and clips to [0, 255]
    captures.push_back(capture);
  }
  return captures;
}

}  // namespace sandtable::testing
