// Static light transport from every projector to the surface points a view sees.
//
// For each pixel of a View, the nearest surface point (common/scene RayCaster, Embree), its
// normal (turned to face the viewer), its albedo, and for each projector that lights it: the
// projector pixel (through the projector's TRUE model, distortion included), visibility (in
// front, inside the image, facing the projector, shadow ray to the projector centre
// unobstructed), and the geometric gain cos(theta) / d^2 (theta: incidence angle at the
// surface, d: distance to the projector centre, in m). Built once per camera; a capture is then a
// gather (capture.h). Cost: one primary ray + one shadow ray per projector per pixel; rows are
// split over `num_threads` threads (0 = hardware concurrency). Deterministic whatever the thread
// count.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/scene/ray_caster.h"
#include "sim/site/site.h"
#include "sim/transport/view.h"

namespace sandtable::sim {

// What one projector contributes at one surface point.
// `projectable` and `visible` are separate facts: a point can have a true pixel and not be lit
// (outside the image, grazing or facing away, shadowed), and (0, 0) is a valid pixel, so
// pixel_px means something exactly when `projectable` is true.
struct ProjectorSample {
  // The point has a true projector pixel: it lies in front of the projector (z > 0 in the
  // projector frame) and inside the domain of its TRUE model (distortion included).
  bool projectable = false;
  // Lit by the projector: projectable, pixel inside the image, facing the projector
  // (cos(theta) > 0) and the segment to the projector centre unobstructed.
  bool visible = false;
  Eigen::Vector2d pixel_px = Eigen::Vector2d::Zero();  // true pixel; zero unless projectable,
                                                       // may lie outside the image
  double gain_per_m2 = 0.0;                            // cos(theta) / d^2, 0 when not visible
  double distance_m = 0.0;                             // to the projector centre (always set)
  double blur_px = 0.0;  // defocus blur circle diameter, projector pixels (0 unless projectable)
};

// Samples one projector at a surface point. `normal` must face the observer; a projector
// behind the surface (cos(theta) <= 0) does not light it. The pixel is filled whenever the
// point is projectable, lit or not.
ProjectorSample SampleProjector(const ProjectorSpec& projector, const RayCaster& caster,
                                const Eigen::Vector3d& point_in_table_m,
                                const Eigen::Vector3d& normal_in_table);
// The projection alone (projectable, pixel, distance, blur; never visible): what the projector
// would do at the point if nothing else mattered.
ProjectorSample ProjectPoint(const ProjectorSpec& projector,
                             const Eigen::Vector3d& point_in_table_m);

// A camera pixel integrates the projector's piecewise-constant pixels over its footprint
// (point sampling aliases edges and moved checkerboard corners by up to 0.5 px). The footprint
// of the view pixel on the surface, mapped into the projector and widened by the defocus blur,
// is approximated by an axis-aligned box in projector pixels of at most 3 x 3 pixels, so its
// integral is a separable 4 x 4 kernel over the padded frame (capture.h):
//   L += sum_j wv[j] sum_i wu[i] / 65535 * emission[frame_offset + j * padded_width + i].
struct TransportEntry {
  uint32_t pixel;         // y * width + x in the view
  uint32_t frame_offset;  // index of the kernel's top-left texel in the padded frame
  uint16_t wu[4];         // horizontal box weights, sum 65535
  float wv[4];            // vertical box weights x albedo x peak x cos(theta) / d^2 (nits)
};

// Padding of LinearFrame on every side, in pixels (black: no light outside the image).
constexpr int kFramePadding_px = 2;
// The largest footprint box side, in projector pixels.
constexpr double kMaxFootprint_px = 3.0;

struct TransportMap {
  int width_px = 0, height_px = 0;
  std::vector<uint8_t> hit;                          // per pixel: 1 when a surface is seen
  std::vector<float> albedo;                         // per pixel
  std::vector<Eigen::Vector3f> point_in_table_m;     // per pixel (zero where no hit)
  std::vector<Eigen::Vector3f> normal_in_table;      // per pixel, facing the view
  std::vector<std::vector<TransportEntry>> entries;  // per site unit, in view pixel order
  size_t NumEntries() const;
};

struct TransportOptions {
  int num_threads = 0;  // 0 = std::thread::hardware_concurrency()
  Status Check() const;
};

Expected<TransportMap> BuildTransportMap(const Site& site, const RayCaster& caster,
                                         const View& view, const TransportOptions& options = {});

}  // namespace sandtable::sim
