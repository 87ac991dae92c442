#include "cluster/annotation_state.h"

#include <cmath>
#include <string>

#include "proto/convert.h"

namespace sandtable::cluster {
namespace {

bool InUnitRange(float v) { return std::isfinite(v) && v >= 0.f && v <= 1.f; }

std::string IdText(StrokeId id) { return "stroke " + std::to_string(id); }

}  // namespace

Status AnnotationState::Check(const wire::AnnotationEvent& event) const {
  switch (event.kind_case()) {
    case wire::AnnotationEvent::kStrokeBegin: {
      const wire::StrokeBegin& b = event.stroke_begin();
      if (b.stroke_id() == 0 || (b.stroke_id() & kDerivedStrokeIdBit) != 0) {
        return InvalidArgumentError("stroke_begin: stroke_id must be in [1, 2^63)");
      }
      if (strokes_.count(b.stroke_id()) != 0) {
        return InvalidArgumentError("stroke_begin: " + IdText(b.stroke_id()) + " already exists");
      }
      if (!InUnitRange(b.color_r()) || !InUnitRange(b.color_g()) || !InUnitRange(b.color_b())) {
        return InvalidArgumentError("stroke_begin: colour components must be in [0, 1]");
      }
      if (!(b.width_m() > 0.f && b.width_m() <= kMaxStrokeWidth_m)) {
        return InvalidArgumentError("stroke_begin: width_m " + std::to_string(b.width_m()) +
                                    " outside (0, " + std::to_string(kMaxStrokeWidth_m) + "]");
      }
      return OkStatus();
    }
    case wire::AnnotationEvent::kStrokePoints: {
      const wire::StrokePoints& p = event.stroke_points();
      auto it = strokes_.find(p.stroke_id());
      if (it == strokes_.end()) {
        return InvalidArgumentError("stroke_points: unknown " + IdText(p.stroke_id()));
      }
      if (it->second.ended) {
        return InvalidArgumentError("stroke_points: " + IdText(p.stroke_id()) + " has ended");
      }
      if (p.points_in_table_m_size() == 0 || p.points_in_table_m_size() % 3 != 0 ||
          p.points_in_table_m_size() / 3 > static_cast<int>(kMaxPointsPerMessage)) {
        return InvalidArgumentError("stroke_points: points_in_table_m must hold 1.." +
                                    std::to_string(kMaxPointsPerMessage) + " xyz triples");
      }
      if (p.first_point_index() != it->second.points_in_table_m.size()) {
        return InvalidArgumentError(
            "stroke_points: first_point_index " + std::to_string(p.first_point_index()) + " but " +
            IdText(p.stroke_id()) + " has " + std::to_string(it->second.points_in_table_m.size()) +
            " points");
      }
      for (float v : p.points_in_table_m()) {
        if (!std::isfinite(v)) return InvalidArgumentError("stroke_points: non-finite coordinate");
      }
      return OkStatus();
    }
    case wire::AnnotationEvent::kStrokeEnd: {
      auto it = strokes_.find(event.stroke_end().stroke_id());
      if (it == strokes_.end() || it->second.ended) {
        return InvalidArgumentError("stroke_end: no open " +
                                    IdText(event.stroke_end().stroke_id()));
      }
      return OkStatus();
    }
    case wire::AnnotationEvent::kErase:
      if (strokes_.count(event.erase().stroke_id()) == 0) {
        return InvalidArgumentError("erase: unknown " + IdText(event.erase().stroke_id()));
      }
      return OkStatus();
    case wire::AnnotationEvent::kClear:
      return OkStatus();
    case wire::AnnotationEvent::kSpotErase: {
      const wire::SpotErase& e = event.spot_erase();
      Expected<Eigen::Vector3d> center = proto::FromWire(e.center_in_table_m());
      if (!e.has_center_in_table_m() || !center.ok()) {
        return InvalidArgumentError("spot_erase: center_in_table_m missing or not finite");
      }
      if (!(e.radius_m() > 0.f && e.radius_m() <= kMaxEraseRadius_m)) {
        return InvalidArgumentError("spot_erase: radius_m outside (0, " +
                                    std::to_string(kMaxEraseRadius_m) + "]");
      }
      return OkStatus();
    }
    case wire::AnnotationEvent::KIND_NOT_SET:
      break;
  }
  return InvalidArgumentError("annotation event has no kind");
}

void AnnotationState::Apply(const wire::AnnotationEvent& event) {
  const Status checked = Check(event);
  ST_CHECK(checked.ok()) << "AnnotationState::Apply of an unchecked event: " << checked.ToString();
  ST_CHECK(event.event_sequence() > last_sequence_)
      << "annotation events must be applied in sequence order (" << event.event_sequence()
      << " after " << last_sequence_ << ")";
  switch (event.kind_case()) {
    case wire::AnnotationEvent::kStrokeBegin: {
      const wire::StrokeBegin& b = event.stroke_begin();
      Stroke& s = strokes_[b.stroke_id()];
      s.id = b.stroke_id();
      s.color_rgb = Eigen::Vector3f(b.color_r(), b.color_g(), b.color_b());
      s.width_m = b.width_m();
      break;
    }
    case wire::AnnotationEvent::kStrokePoints: {
      const wire::StrokePoints& p = event.stroke_points();
      Stroke& s = strokes_.at(p.stroke_id());
      for (int i = 0; i + 2 < p.points_in_table_m_size(); i += 3) {
        s.points_in_table_m.emplace_back(p.points_in_table_m(i), p.points_in_table_m(i + 1),
                                         p.points_in_table_m(i + 2));
      }
      break;
    }
    case wire::AnnotationEvent::kStrokeEnd:
      strokes_.at(event.stroke_end().stroke_id()).ended = true;
      break;
    case wire::AnnotationEvent::kErase:
      strokes_.erase(event.erase().stroke_id());
      break;
    case wire::AnnotationEvent::kClear:
      strokes_.clear();
      break;
    case wire::AnnotationEvent::kSpotErase:
      ApplySpotErase(event.spot_erase(), event.event_sequence());
      break;
    case wire::AnnotationEvent::KIND_NOT_SET:
      break;
  }
  last_sequence_ = event.event_sequence();
}

// A stroke is a polyline; erasing the points inside the disc leaves runs of consecutive
// surviving points. The first run keeps the stroke's id (so an open stroke can go on growing
// only if its last point survived: otherwise it is closed, since new points would join across
// the erased gap); later runs become new, ended strokes with derived ids. Runs of one point
// are kept (a dot).
void AnnotationState::ApplySpotErase(const wire::SpotErase& erase, SequenceNumber sequence) {
  const Eigen::Vector3f center(static_cast<float>(erase.center_in_table_m().x()),
                               static_cast<float>(erase.center_in_table_m().y()),
                               static_cast<float>(erase.center_in_table_m().z()));
  const float radius2_m2 = erase.radius_m() * erase.radius_m();
  std::map<StrokeId, Stroke> result;
  for (auto& [id, stroke] : strokes_) {
    std::vector<std::vector<Eigen::Vector3f>> runs(1);
    bool any_erased = false;
    for (const Eigen::Vector3f& p : stroke.points_in_table_m) {
      if ((p - center).squaredNorm() <= radius2_m2) {
        any_erased = true;
        if (!runs.back().empty()) runs.emplace_back();
      } else {
        runs.back().push_back(p);
      }
    }
    if (!any_erased) {
      result.emplace(id, std::move(stroke));
      continue;
    }
    const bool last_point_survived =
        !stroke.points_in_table_m.empty() && !runs.back().empty() &&
        (stroke.points_in_table_m.back() - center).squaredNorm() > radius2_m2;
    if (runs.back().empty()) runs.pop_back();
    for (size_t k = 0; k < runs.size(); ++k) {
      Stroke piece = stroke;
      piece.points_in_table_m = std::move(runs[k]);
      if (k == 0) {
        piece.ended = stroke.ended || !(last_point_survived && runs.size() == 1);
        result.emplace(id, std::move(piece));
      } else {
        piece.id = kDerivedStrokeIdBit | (sequence << 16) | static_cast<StrokeId>(k);
        piece.ended = stroke.ended || !(last_point_survived && k + 1 == runs.size());
        result.emplace(piece.id, std::move(piece));
      }
    }
  }
  strokes_ = std::move(result);
}

size_t AnnotationState::NumPoints() const {
  size_t n = 0;
  for (const auto& [id, s] : strokes_) n += s.points_in_table_m.size();
  return n;
}

wire::Snapshot AnnotationState::ToSnapshot() const {
  wire::Snapshot snapshot;
  for (const auto& [id, s] : strokes_) {
    wire::Snapshot::Stroke* out = snapshot.add_strokes();
    wire::StrokeBegin* b = out->mutable_begin();
    b->set_stroke_id(id);
    b->set_color_r(s.color_rgb.x());
    b->set_color_g(s.color_rgb.y());
    b->set_color_b(s.color_rgb.z());
    b->set_width_m(s.width_m);
    out->mutable_points_in_table_m()->Reserve(static_cast<int>(3 * s.points_in_table_m.size()));
    for (const Eigen::Vector3f& p : s.points_in_table_m) {
      out->add_points_in_table_m(p.x());
      out->add_points_in_table_m(p.y());
      out->add_points_in_table_m(p.z());
    }
    out->set_ended(s.ended);
  }
  snapshot.set_last_event_sequence(last_sequence_);
  return snapshot;
}

Expected<AnnotationState> AnnotationState::FromSnapshot(const wire::Snapshot& snapshot) {
  AnnotationState state;
  for (int i = 0; i < snapshot.strokes_size(); ++i) {
    const wire::Snapshot::Stroke& in = snapshot.strokes(i);
    const wire::StrokeBegin& b = in.begin();
    const std::string where = "snapshot stroke " + std::to_string(b.stroke_id()) + ": ";
    if (b.stroke_id() == 0 || b.stroke_id() == kInvalidStrokeId) {
      return InvalidArgumentError(where + "invalid stroke id");
    }
    if (state.strokes_.count(b.stroke_id())) return InvalidArgumentError(where + "listed twice");
    if (!(b.width_m() > 0.f && b.width_m() <= kMaxStrokeWidth_m)) {
      return InvalidArgumentError(where + "width_m out of (0, " +
                                  std::to_string(kMaxStrokeWidth_m) + "]");
    }
    for (float c : {b.color_r(), b.color_g(), b.color_b()}) {
      if (!(c >= 0.f && c <= 1.f)) return InvalidArgumentError(where + "colour outside [0, 1]");
    }
    if (in.points_in_table_m_size() % 3 != 0) {
      return InvalidArgumentError(where + "points are not whole xyz triples");
    }
    Stroke stroke;
    stroke.id = b.stroke_id();
    stroke.color_rgb = Eigen::Vector3f(b.color_r(), b.color_g(), b.color_b());
    stroke.width_m = b.width_m();
    stroke.ended = in.ended();
    stroke.points_in_table_m.reserve(static_cast<size_t>(in.points_in_table_m_size() / 3));
    for (int k = 0; k + 2 < in.points_in_table_m_size(); k += 3) {
      const Eigen::Vector3f p(in.points_in_table_m(k), in.points_in_table_m(k + 1),
                              in.points_in_table_m(k + 2));
      if (!p.allFinite()) return InvalidArgumentError(where + "a point is not finite");
      stroke.points_in_table_m.push_back(p);
    }
    state.strokes_.emplace(stroke.id, std::move(stroke));
  }
  state.last_sequence_ = snapshot.last_event_sequence();
  return state;
}

}  // namespace sandtable::cluster
