#include "node/render/overlay_geometry.h"

#include <cmath>

namespace sandtable::node {
namespace {

class Builder {
 public:
  Builder(const Eigen::Vector3d& centre, const OverlayOptions& options,
          std::vector<OverlayVertex>* out)
      : centre_(centre), options_(options), out_(out) {}

  // The point lifted towards the projector by lift_m plus the half size of what is drawn
  // there: a shape facing the projector then stays above a surface it crosses at a slant.
  Eigen::Vector3d Lift(const Eigen::Vector3d& p, double half_size_m) const {
    const Eigen::Vector3d towards = centre_ - p;
    const double n = towards.norm();
    return n > 0 ? Eigen::Vector3d(p + towards / n * (options_.lift_m + half_size_m)) : p;
  }

  void Triangle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                const Eigen::Vector3f& colour) {
    for (const Eigen::Vector3d* p : {&a, &b, &c}) {
      OverlayVertex v;
      for (int i = 0; i < 3; ++i) v.position_in_table_m[i] = static_cast<float>((*p)[i]);
      for (int i = 0; i < 3; ++i) v.colour[i] = colour[i];
      v.colour[3] = 1.0f;
      out_->push_back(v);
    }
  }

  // A disc (or a ring from inner_m to radius_m) facing the projector, centred at `lifted`.
  void Disc(const Eigen::Vector3d& lifted, double radius_m, double inner_m,
            const Eigen::Vector3f& colour) {
    const Eigen::Vector3d view = (lifted - centre_).normalized();
    Eigen::Vector3d a = view.cross(Eigen::Vector3d::UnitZ());
    if (a.norm() < 1e-6) a = view.cross(Eigen::Vector3d::UnitX());
    a.normalize();
    const Eigen::Vector3d b = view.cross(a);
    const int n = options_.round_segments;
    for (int i = 0; i < n; ++i) {
      const double t0 = 2 * M_PI * i / n, t1 = 2 * M_PI * (i + 1) / n;
      const Eigen::Vector3d d0 = std::cos(t0) * a + std::sin(t0) * b;
      const Eigen::Vector3d d1 = std::cos(t1) * a + std::sin(t1) * b;
      if (inner_m <= 0) {
        Triangle(lifted, lifted + radius_m * d0, lifted + radius_m * d1, colour);
      } else {
        const Eigen::Vector3d o0 = lifted + radius_m * d0, o1 = lifted + radius_m * d1;
        const Eigen::Vector3d i0 = lifted + inner_m * d0, i1 = lifted + inner_m * d1;
        Triangle(i0, o0, o1, colour);
        Triangle(i0, o1, i1, colour);
      }
    }
  }

  void Ribbon(const Polyline& line) {
    const double half = 0.5 * line.width_m;
    std::vector<Eigen::Vector3d> lifted;
    lifted.reserve(line.points_in_table_m.size());
    for (const Eigen::Vector3d& p : line.points_in_table_m) {
      if (p.allFinite()) lifted.push_back(Lift(p, half));
    }
    for (size_t i = 0; i + 1 < lifted.size(); ++i) {
      const Eigen::Vector3d& q0 = lifted[i];
      const Eigen::Vector3d& q1 = lifted[i + 1];
      const Eigen::Vector3d dir = q1 - q0;
      const Eigen::Vector3d view = (0.5 * (q0 + q1) - centre_).normalized();
      Eigen::Vector3d side = dir.cross(view);
      if (side.norm() < 1e-12) continue;  // a zero-length segment, or one along the ray
      side = side.normalized() * half;
      Triangle(q0 - side, q0 + side, q1 + side, line.colour);
      Triangle(q0 - side, q1 + side, q1 - side, line.colour);
    }
    // Round joints where the line turns by more than kJointTurn (a smaller turn leaves a gap
    // of at most half x sin(turn / 2) on its outer side) and round caps at both ends.
    constexpr double kJointTurnCos = 0.94;  // cos 20 deg
    for (size_t i = 0; i < lifted.size(); ++i) {
      bool joint = i == 0 || i + 1 == lifted.size();
      if (!joint) {
        const Eigen::Vector3d a = lifted[i] - lifted[i - 1], b = lifted[i + 1] - lifted[i];
        const double n = a.norm() * b.norm();
        joint = n > 0.0 && a.dot(b) < kJointTurnCos * n;
      }
      if (joint) Disc(lifted[i], half, 0.0, line.colour);
    }
  }

 private:
  Eigen::Vector3d centre_;
  OverlayOptions options_;
  std::vector<OverlayVertex>* out_;
};

}  // namespace

std::vector<OverlayVertex> BuildOverlay(const RenderContent& content,
                                        const Eigen::Vector3d& projector_centre_in_table_m,
                                        const OverlayOptions& options) {
  std::vector<OverlayVertex> out;
  Builder builder(projector_centre_in_table_m, options, &out);
  for (const Polyline& line : content.traces) builder.Ribbon(line);
  for (const Polyline& line : content.strokes) builder.Ribbon(line);
  for (const Marker& m : content.markers) {
    if (!m.position_in_table_m.allFinite()) continue;
    builder.Disc(builder.Lift(m.position_in_table_m, m.radius_m), m.radius_m,
                 m.ring ? 0.7 * m.radius_m : 0.0, m.colour);
  }
  return out;
}

Status OverlayOptions::Check() const {
  if (!(lift_m >= 0.0) || !std::isfinite(lift_m)) {
    return InvalidArgumentError("overlay: lift_m must be finite and >= 0");
  }
  if (round_segments < 3 || round_segments > 256) {
    return InvalidArgumentError("overlay: round_segments must be 3-256");
  }
  return OkStatus();
}

}  // namespace sandtable::node
