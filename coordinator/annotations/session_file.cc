#include "coordinator/annotations/session_file.h"

#include <fstream>

#include <nlohmann/json.hpp>

namespace sandtable::coordinator {
namespace {

using nlohmann::json;
constexpr const char* kFormat = "sandtable-annotation-session";
constexpr int kVersion = 1;
constexpr size_t kExportPage = 10000;

json Xyz(double x, double y, double z) { return json::array({x, y, z}); }

// Reads a [x, y, z] array of numbers; throws json::exception on a wrong shape (caught by the
// caller, which names the line).
void ReadXyz(const json& j, double out[3]) {
  if (!j.is_array() || j.size() != 3) throw std::runtime_error("expected [x, y, z]");
  for (int k = 0; k < 3; ++k) out[k] = j.at(k).get<double>();
}

}  // namespace

std::string AnnotationEventToJsonLine(const wire::AnnotationEvent& event) {
  json j;
  j["event_sequence"] = event.event_sequence();
  j["time_ns"] = event.time_ns();
  j["kind"] = AnnotationKindName(event);
  switch (event.kind_case()) {
    case wire::AnnotationEvent::kStrokeBegin: {
      const auto& b = event.stroke_begin();
      j["stroke_id"] = b.stroke_id();
      j["color_rgb"] = json::array({b.color_r(), b.color_g(), b.color_b()});
      j["width_m"] = b.width_m();
      break;
    }
    case wire::AnnotationEvent::kStrokePoints: {
      const auto& p = event.stroke_points();
      j["stroke_id"] = p.stroke_id();
      j["first_point_index"] = p.first_point_index();
      json points = json::array();
      for (int i = 0; i + 2 < p.points_in_table_m_size(); i += 3) {
        points.push_back(
            Xyz(p.points_in_table_m(i), p.points_in_table_m(i + 1), p.points_in_table_m(i + 2)));
      }
      j["points_in_table_m"] = std::move(points);
      break;
    }
    case wire::AnnotationEvent::kStrokeEnd:
      j["stroke_id"] = event.stroke_end().stroke_id();
      j["point_count"] = event.stroke_end().point_count();
      break;
    case wire::AnnotationEvent::kErase:
      j["stroke_id"] = event.erase().stroke_id();
      break;
    case wire::AnnotationEvent::kClear:
      break;
    case wire::AnnotationEvent::kSpotErase: {
      const auto& c = event.spot_erase().center_in_table_m();
      j["center_in_table_m"] = Xyz(c.x(), c.y(), c.z());
      j["radius_m"] = event.spot_erase().radius_m();
      break;
    }
    case wire::AnnotationEvent::KIND_NOT_SET:
      break;
  }
  return j.dump();
}

Expected<wire::AnnotationEvent> AnnotationEventFromJsonLine(const std::string& line) {
  wire::AnnotationEvent event;
  try {
    const json j = json::parse(line);
    event.set_event_sequence(j.value("event_sequence", uint64_t{0}));
    event.set_time_ns(j.value("time_ns", int64_t{0}));
    const std::string kind = j.at("kind").get<std::string>();
    if (kind == "stroke_begin") {
      auto* b = event.mutable_stroke_begin();
      b->set_stroke_id(j.at("stroke_id").get<uint64_t>());
      double rgb[3];
      ReadXyz(j.at("color_rgb"), rgb);
      b->set_color_r(static_cast<float>(rgb[0]));
      b->set_color_g(static_cast<float>(rgb[1]));
      b->set_color_b(static_cast<float>(rgb[2]));
      b->set_width_m(j.at("width_m").get<float>());
    } else if (kind == "stroke_points") {
      auto* p = event.mutable_stroke_points();
      p->set_stroke_id(j.at("stroke_id").get<uint64_t>());
      p->set_first_point_index(j.at("first_point_index").get<uint32_t>());
      for (const json& point : j.at("points_in_table_m")) {
        double xyz[3];
        ReadXyz(point, xyz);
        for (double v : xyz) p->add_points_in_table_m(static_cast<float>(v));
      }
    } else if (kind == "stroke_end") {
      event.mutable_stroke_end()->set_stroke_id(j.at("stroke_id").get<uint64_t>());
      event.mutable_stroke_end()->set_point_count(j.value("point_count", uint32_t{0}));
    } else if (kind == "erase") {
      event.mutable_erase()->set_stroke_id(j.at("stroke_id").get<uint64_t>());
    } else if (kind == "clear") {
      event.mutable_clear();
    } else if (kind == "spot_erase") {
      double c[3];
      ReadXyz(j.at("center_in_table_m"), c);
      auto* e = event.mutable_spot_erase();
      e->mutable_center_in_table_m()->set_x(c[0]);
      e->mutable_center_in_table_m()->set_y(c[1]);
      e->mutable_center_in_table_m()->set_z(c[2]);
      e->set_radius_m(j.at("radius_m").get<float>());
    } else {
      return ParseError("unknown kind \"" + kind + "\"");
    }
  } catch (const std::exception& e) {
    return ParseError(std::string("not a valid event line: ") + e.what());
  }
  return event;
}

Expected<size_t> ExportSession(const AnnotationStore& store, const std::string& path) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) return IoError("session export " + path + ": cannot open for writing");
  json header;
  header["format"] = kFormat;
  header["version"] = kVersion;
  header["event_count"] = store.last_sequence();  // the log has no gaps: sequences 1..N
  out << header.dump() << "\n";
  size_t written = 0;
  SequenceNumber after = 0;
  while (true) {
    Expected<std::vector<wire::AnnotationEvent>> page = store.EventsAfter(after, kExportPage);
    if (!page.ok()) return page.status().WithContext("session export");
    if (page->empty()) break;
    for (const wire::AnnotationEvent& e : *page) out << AnnotationEventToJsonLine(e) << "\n";
    written += page->size();
    after = page->back().event_sequence();
  }
  out.flush();
  if (!out) return IoError("session export " + path + ": write failed (disk full?)");
  return written;
}

Expected<size_t> ImportSession(const std::string& path, AnnotationStore* store) {
  if (store->last_sequence() != 0) {
    return InvalidArgumentError("session import " + path + ": the annotation database " +
                                store->path() + " already holds " +
                                std::to_string(store->last_sequence()) +
                                " events; import into a new file");
  }
  std::ifstream in(path);
  if (!in) return IoError("session import " + path + ": cannot open");
  std::string line;
  if (!std::getline(in, line)) return ParseError("session import " + path + ": empty file");
  try {
    const json header = json::parse(line);
    if (header.value("format", "") != kFormat || header.value("version", 0) != kVersion) {
      return ParseError("session import " + path + ": line 1 is not a " + kFormat + " version " +
                        std::to_string(kVersion) + " header");
    }
  } catch (const std::exception& e) {
    return ParseError("session import " + path + ": line 1: " + e.what());
  }
  std::vector<wire::AnnotationEvent> events;
  for (int line_number = 2; std::getline(in, line); ++line_number) {
    if (line.empty()) continue;
    Expected<wire::AnnotationEvent> event = AnnotationEventFromJsonLine(line);
    if (!event.ok()) {
      return event.status().WithContext("session import " + path + ": line " +
                                        std::to_string(line_number));
    }
    events.push_back(std::move(*event));
  }
  // Check everything on a scratch state first, so that a bad line imports nothing.
  cluster::AnnotationState scratch;
  for (size_t i = 0; i < events.size(); ++i) {
    wire::AnnotationEvent e = events[i];
    e.set_event_sequence(i + 1);
    Status checked = scratch.Check(e);
    if (!checked.ok()) {
      return checked.WithContext("session import " + path + ": event on line " +
                                 std::to_string(i + 2));
    }
    scratch.Apply(e);
  }
  Expected<CommitReport> report = store->Commit(&events);
  if (!report.ok()) return report.status().WithContext("session import " + path);
  return report->num_committed;
}

}  // namespace sandtable::coordinator
