#include "coordinator/annotations/session_file.h"

#include <cfloat>
#include <cmath>
#include <limits>

#include <nlohmann/json.hpp>

#include "common/base/file_io.h"

namespace sandtable::coordinator {
namespace {

using nlohmann::json;
constexpr const char* kFormat = "sandtable-annotation-session";
constexpr int kVersion = 1;
constexpr size_t kExportPage = 10000;

json Xyz(double x, double y, double z) { return json::array({x, y, z}); }

// A field that is missing or out of its range: caught in AnnotationEventFromJsonLine, which
// returns it as a Status naming the field (never crosses the module boundary).
struct FieldError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

const json& Field(const json& j, const char* name) {
  auto it = j.find(name);
  if (it == j.end()) throw FieldError(std::string("field ") + name + " is missing");
  return *it;
}

// An integer in [0, max], checked before conversion (nlohmann's get<uint32_t>() of 2^32 would
// silently give 0).
uint64_t ReadUnsigned(const json& v, const char* name, uint64_t max) {
  if (!v.is_number_unsigned() || v.get<uint64_t>() > max) {
    throw FieldError(std::string("field ") + name + ": " + v.dump() + " is not an integer in [0, " +
                     std::to_string(max) + "]");
  }
  return v.get<uint64_t>();
}

int64_t ReadSigned(const json& v, const char* name) {
  if (v.is_number_unsigned()) {
    if (v.get<uint64_t>() > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) {
      throw FieldError(std::string("field ") + name + ": " + v.dump() + " is outside int64");
    }
    return static_cast<int64_t>(v.get<uint64_t>());
  }
  if (!v.is_number_integer()) {
    throw FieldError(std::string("field ") + name + ": " + v.dump() + " is not an integer");
  }
  return v.get<int64_t>();
}

// A number stored as float on the wire: finite and within float range.
float ReadFloat(const json& v, const char* name) {
  if (!v.is_number()) throw FieldError(std::string("field ") + name + ": not a number");
  const double d = v.get<double>();
  if (!std::isfinite(d) || std::fabs(d) > FLT_MAX) {
    throw FieldError(std::string("field ") + name + ": " + v.dump() + " is not a finite float");
  }
  return static_cast<float>(d);
}

double ReadDouble(const json& v, const char* name) {
  if (!v.is_number() || !std::isfinite(v.get<double>())) {
    throw FieldError(std::string("field ") + name + ": not a finite number");
  }
  return v.get<double>();
}

// Reads a [x, y, z] array of numbers.
void ReadXyz(const json& j, const char* name, double out[3]) {
  if (!j.is_array() || j.size() != 3) {
    throw FieldError(std::string("field ") + name + ": expected [x, y, z]");
  }
  for (int k = 0; k < 3; ++k) out[k] = ReadDouble(j[static_cast<size_t>(k)], name);
}

void ReadXyzFloat(const json& j, const char* name, float out[3]) {
  if (!j.is_array() || j.size() != 3) {
    throw FieldError(std::string("field ") + name + ": expected [x, y, z]");
  }
  for (int k = 0; k < 3; ++k) out[k] = ReadFloat(j[static_cast<size_t>(k)], name);
}

constexpr uint64_t kMaxUint32 = std::numeric_limits<uint32_t>::max();
constexpr uint64_t kMaxUint64 = std::numeric_limits<uint64_t>::max();
constexpr uint64_t kMaxSequence = static_cast<uint64_t>(std::numeric_limits<int64_t>::max());

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
    if (!j.is_object()) return ParseError("not a JSON object");
    if (j.contains("event_sequence")) {
      event.set_event_sequence(ReadUnsigned(j["event_sequence"], "event_sequence", kMaxSequence));
    }
    if (j.contains("time_ns")) event.set_time_ns(ReadSigned(j["time_ns"], "time_ns"));
    const json& kind_field = Field(j, "kind");
    if (!kind_field.is_string()) throw FieldError("field kind: not a string");
    const std::string kind = kind_field.get<std::string>();
    if (kind == "stroke_begin") {
      auto* b = event.mutable_stroke_begin();
      b->set_stroke_id(ReadUnsigned(Field(j, "stroke_id"), "stroke_id", kMaxUint64));
      float rgb[3];
      ReadXyzFloat(Field(j, "color_rgb"), "color_rgb", rgb);
      b->set_color_r(rgb[0]);
      b->set_color_g(rgb[1]);
      b->set_color_b(rgb[2]);
      b->set_width_m(ReadFloat(Field(j, "width_m"), "width_m"));
    } else if (kind == "stroke_points") {
      auto* p = event.mutable_stroke_points();
      p->set_stroke_id(ReadUnsigned(Field(j, "stroke_id"), "stroke_id", kMaxUint64));
      p->set_first_point_index(static_cast<uint32_t>(
          ReadUnsigned(Field(j, "first_point_index"), "first_point_index", kMaxUint32)));
      const json& points = Field(j, "points_in_table_m");
      if (!points.is_array()) throw FieldError("field points_in_table_m: not an array");
      if (points.size() > cluster::kMaxPointsPerMessage) {
        throw FieldError("field points_in_table_m: " + std::to_string(points.size()) +
                         " points, more than kMaxPointsPerMessage = " +
                         std::to_string(cluster::kMaxPointsPerMessage));
      }
      p->mutable_points_in_table_m()->Reserve(static_cast<int>(3 * points.size()));
      for (const json& point : points) {
        float xyz[3];
        ReadXyzFloat(point, "points_in_table_m", xyz);
        for (float v : xyz) p->add_points_in_table_m(v);
      }
    } else if (kind == "stroke_end") {
      event.mutable_stroke_end()->set_stroke_id(
          ReadUnsigned(Field(j, "stroke_id"), "stroke_id", kMaxUint64));
      if (j.contains("point_count")) {
        event.mutable_stroke_end()->set_point_count(
            static_cast<uint32_t>(ReadUnsigned(j["point_count"], "point_count", kMaxUint32)));
      }
    } else if (kind == "erase") {
      event.mutable_erase()->set_stroke_id(
          ReadUnsigned(Field(j, "stroke_id"), "stroke_id", kMaxUint64));
    } else if (kind == "clear") {
      event.mutable_clear();
    } else if (kind == "spot_erase") {
      double c[3];
      ReadXyz(Field(j, "center_in_table_m"), "center_in_table_m", c);
      auto* e = event.mutable_spot_erase();
      e->mutable_center_in_table_m()->set_x(c[0]);
      e->mutable_center_in_table_m()->set_y(c[1]);
      e->mutable_center_in_table_m()->set_z(c[2]);
      e->set_radius_m(ReadFloat(Field(j, "radius_m"), "radius_m"));
    } else {
      return ParseError("field kind: unknown kind \"" + kind + "\"");
    }
  } catch (const FieldError& e) {
    return ParseError(e.what());
  } catch (const std::exception& e) {
    return ParseError(std::string("not a valid event line: ") + e.what());
  }
  return event;
}

std::string SessionText(const std::vector<wire::AnnotationEvent>& events) {
  json header;
  header["format"] = kFormat;
  header["version"] = kVersion;
  header["event_count"] = events.size();
  std::string text = header.dump() + "\n";
  for (const wire::AnnotationEvent& e : events) text += AnnotationEventToJsonLine(e) + "\n";
  return text;
}

Expected<size_t> ExportSession(const AnnotationStore& store, const std::string& path) {
  json header;
  header["format"] = kFormat;
  header["version"] = kVersion;
  header["event_count"] = store.last_sequence();  // the log has no gaps: sequences 1..N
  std::string text = header.dump() + "\n";
  size_t written = 0;
  SequenceNumber after = 0;
  while (true) {
    Expected<std::vector<wire::AnnotationEvent>> page = store.EventsAfter(after, kExportPage);
    if (!page.ok()) return page.status().WithContext("session export " + path);
    if (page->empty()) break;
    for (const wire::AnnotationEvent& e : *page) text += AnnotationEventToJsonLine(e) + "\n";
    written += page->size();
    after = page->back().event_sequence();
  }
  if (written != store.last_sequence()) {
    return InternalError("session export " + path + ": read " + std::to_string(written) +
                         " events of " + std::to_string(store.last_sequence()));
  }
  Status stored = WriteFileAtomically(path, text);
  if (!stored.ok()) return stored.WithContext("session export (the previous file is kept)");
  return written;
}

Expected<std::vector<wire::AnnotationEvent>> ParseSession(std::string_view text,
                                                          const std::string& name) {
  const std::string where = "session import " + name + ": ";
  std::vector<wire::AnnotationEvent> events;
  size_t begin = 0;
  auto next_line = [&](std::string* line) {
    if (begin >= text.size()) return false;
    const size_t end = text.find('\n', begin);
    const size_t stop = end == std::string_view::npos ? text.size() : end;
    line->assign(text.substr(begin, stop - begin));
    begin = stop + 1;
    return true;
  };
  std::string line;
  if (!next_line(&line)) return ParseError(where + "empty file");
  uint64_t event_count = 0;
  try {
    const json header = json::parse(line);
    if (!header.is_object() || header.value("format", "") != kFormat ||
        !header.contains("version") || !header["version"].is_number_integer() ||
        header["version"].get<int64_t>() != kVersion) {
      return ParseError(where + "line 1 is not a " + kFormat + " version " +
                        std::to_string(kVersion) + " header");
    }
    event_count = ReadUnsigned(Field(header, "event_count"), "event_count", kMaxSessionEvents);
  } catch (const FieldError& e) {
    return ParseError(where + "line 1 (header): " + e.what() +
                      " (kMaxSessionEvents = " + std::to_string(kMaxSessionEvents) + ")");
  } catch (const std::exception& e) {
    return ParseError(where + "line 1: " + e.what());
  }
  int line_number = 1;
  while (next_line(&line)) {
    ++line_number;
    if (line.empty()) {
      if (begin >= text.size()) break;  // the newline that ends the file
      return ParseError(where + "line " + std::to_string(line_number) + " is empty");
    }
    if (events.size() == event_count) {
      return ParseError(where + "line " + std::to_string(line_number) +
                        ": more event lines than the header's event_count " +
                        std::to_string(event_count));
    }
    Expected<wire::AnnotationEvent> event = AnnotationEventFromJsonLine(line);
    if (!event.ok()) {
      return event.status().WithContext(where + "line " + std::to_string(line_number));
    }
    const uint64_t place = events.size() + 1;
    if (event->event_sequence() != 0 && event->event_sequence() != place) {
      return ParseError(where + "line " + std::to_string(line_number) + ": field event_sequence " +
                        std::to_string(event->event_sequence()) + " but this is event " +
                        std::to_string(place) + " of the file (a line was removed or moved?)");
    }
    events.push_back(std::move(*event));
  }
  if (events.size() != event_count) {
    return ParseError(where + "line 1 (header): event_count " + std::to_string(event_count) +
                      " but the file holds " + std::to_string(events.size()) +
                      " event lines: the file was cut short; nothing imported");
  }
  // Check everything on a scratch state first, so that a bad line imports nothing.
  cluster::AnnotationState scratch;
  for (size_t i = 0; i < events.size(); ++i) {
    wire::AnnotationEvent e = events[i];
    e.set_event_sequence(i + 1);
    Status checked = scratch.Check(e);
    if (!checked.ok()) {
      return checked.WithContext(where + "line " + std::to_string(i + 2) + " (event " +
                                 std::to_string(i + 1) + ")");
    }
    scratch.Apply(e);
  }
  return events;
}

Expected<std::vector<wire::AnnotationEvent>> ReadSessionFile(const std::string& path) {
  Expected<std::string> text = ReadInputFile(path, kMaxSessionFileBytes, "kMaxSessionFileBytes");
  if (!text.ok()) return text.status().WithContext("session import");
  return ParseSession(*text, path);
}

Expected<size_t> ImportEvents(std::vector<wire::AnnotationEvent> events, const std::string& name,
                              AnnotationStore* store) {
  if (store->last_sequence() != 0) {
    return InvalidArgumentError("session import " + name + ": the annotation database " +
                                store->path() + " already holds " +
                                std::to_string(store->last_sequence()) +
                                " events; import into a new file");
  }
  for (wire::AnnotationEvent& e : events) e.set_event_sequence(0);
  Expected<CommitReport> report = store->Commit(&events, /*all_or_nothing=*/true);
  if (!report.ok()) return report.status().WithContext("session import " + name);
  return report->num_committed;
}

Expected<size_t> ImportSession(const std::string& path, AnnotationStore* store) {
  if (store->last_sequence() != 0) return ImportEvents({}, path, store);
  Expected<std::vector<wire::AnnotationEvent>> events = ReadSessionFile(path);
  if (!events.ok()) return events.status();
  return ImportEvents(std::move(*events), path, store);
}

}  // namespace sandtable::coordinator
