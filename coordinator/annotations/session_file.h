// Session export and import: an annotation session as a JSON-lines file, for after-action
// review and for moving sessions between sites. Format (docs/coordinator.md):
//   line 1: {"format":"sandtable-annotation-session","version":1,"event_count":N}
//   then one event per line, in sequence order, e.g.
//   {"event_sequence":1,"time_ns":123,"kind":"stroke_begin","stroke_id":7,
//    "color_rgb":[1,0,0],"width_m":0.004}
//   {"event_sequence":2,...,"kind":"stroke_points","stroke_id":7,"first_point_index":0,
//    "points_in_table_m":[[0.1,0.2,0.0],[0.11,0.2,0.0]]}
//   {"kind":"stroke_end","stroke_id":7,"point_count":2}   {"kind":"erase","stroke_id":7}
//   {"kind":"clear"}   {"kind":"spot_erase","center_in_table_m":[x,y,z],"radius_m":0.02}
// Units are in the field names (metres, ns of the coordinator's steady clock).
// Import re-sequences the events into an EMPTY store (sequence numbers and times in the file
// are informative) and checks every event as a live request would be checked.
// Failure: unreadable file, bad JSON, unknown kind, missing field, or an event that does not
// apply: an error naming the file and line; nothing is half-imported (one transaction).
#pragma once

#include <string>

#include "common/base/status.h"
#include "coordinator/annotations/annotation_store.h"

namespace sandtable::coordinator {

// Writes every event of `store` to `path` (overwritten). Returns the number of events.
Expected<size_t> ExportSession(const AnnotationStore& store, const std::string& path);

// Reads `path` into `store`, which must hold no events. Returns the number of events.
Expected<size_t> ImportSession(const std::string& path, AnnotationStore* store);

// One event <-> one JSON line (without the newline); exposed for tests.
std::string AnnotationEventToJsonLine(const wire::AnnotationEvent& event);
Expected<wire::AnnotationEvent> AnnotationEventFromJsonLine(const std::string& line);

}  // namespace sandtable::coordinator
