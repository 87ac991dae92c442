// Builders of annotation events for tests.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "proto/events.pb.h"

namespace sandtable::cluster::testing {

inline wire::AnnotationEvent Begin(uint64_t id, float r = 1.f, float g = 0.f, float b = 0.f,
                                   float width_m = 0.005f) {
  wire::AnnotationEvent e;
  auto* s = e.mutable_stroke_begin();
  s->set_stroke_id(id);
  s->set_color_r(r);
  s->set_color_g(g);
  s->set_color_b(b);
  s->set_width_m(width_m);
  return e;
}

inline wire::AnnotationEvent Points(uint64_t id, uint32_t first,
                                    const std::vector<Eigen::Vector3f>& points_in_table_m) {
  wire::AnnotationEvent e;
  auto* s = e.mutable_stroke_points();
  s->set_stroke_id(id);
  s->set_first_point_index(first);
  for (const Eigen::Vector3f& p : points_in_table_m) {
    s->add_points_in_table_m(p.x());
    s->add_points_in_table_m(p.y());
    s->add_points_in_table_m(p.z());
  }
  return e;
}

inline wire::AnnotationEvent End(uint64_t id, uint32_t count) {
  wire::AnnotationEvent e;
  e.mutable_stroke_end()->set_stroke_id(id);
  e.mutable_stroke_end()->set_point_count(count);
  return e;
}

inline wire::AnnotationEvent SpotErase(const Eigen::Vector3d& c, float radius_m) {
  wire::AnnotationEvent e;
  auto* s = e.mutable_spot_erase();
  s->mutable_center_in_table_m()->set_x(c.x());
  s->mutable_center_in_table_m()->set_y(c.y());
  s->mutable_center_in_table_m()->set_z(c.z());
  s->set_radius_m(radius_m);
  return e;
}

// Point k of a test line along x at height z: (0.01 k, 0.2, z) metres.
inline Eigen::Vector3f LinePoint(int k, float z_m = 0.f) {
  return Eigen::Vector3f(0.01f * static_cast<float>(k), 0.2f, z_m);
}

}  // namespace sandtable::cluster::testing
