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
// Import re-sequences the events into an EMPTY store (times in the file are informative)
// and checks every event as a live request would be checked.
// Validation (docs/reliability.md): the file is read through ReadInputFile (regular file,
// at most kMaxSessionFileBytes); line 1 must be the header with an event_count in
// [0, kMaxSessionEvents] and the file must hold exactly that many event lines (a file cut at a
// line break is refused, not imported in part); each number is checked against its field's
// type before it is converted (first_point_index and point_count in [0, 2^32), stroke_id in
// [0, 2^64), event_sequence when present equal to the line's place 1..N, time_ns an int64,
// coordinates and sizes finite floats); unknown kinds, missing fields and events that do not
// apply are refused. Errors name the file, the line and the field.
// All or nothing: the events are checked in full before the store is touched, and written in
// one transaction (AnnotationStore::Commit all_or_nothing).
// Export writes the whole file through WriteFileAtomically: on a full disk the previous
// export stays as it was and the error comes back.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/base/status.h"
#include "coordinator/annotations/annotation_store.h"

namespace sandtable::coordinator {

inline constexpr uint64_t kMaxSessionFileBytes = uint64_t{1} << 30;  // 1 GiB
inline constexpr uint64_t kMaxSessionEvents = uint64_t{50} << 20;    // 52 428 800

// Writes every event of `store` to `path` (replaced atomically). Returns the number of events.
Expected<size_t> ExportSession(const AnnotationStore& store, const std::string& path);

// Reads `path` into `store`, which must hold no events. Returns the number of events.
// Equivalent to ReadSessionFile then ImportEvents.
Expected<size_t> ImportSession(const std::string& path, AnnotationStore* store);

// Reads and validates the whole file (every error is bad input: PARSE_ERROR, INVALID_ARGUMENT,
// NOT_FOUND or IO_ERROR for an unreadable or oversized file).
Expected<std::vector<wire::AnnotationEvent>> ReadSessionFile(const std::string& path);
// The same from bytes in memory; `name` is used in messages (the fuzz target's entry point).
Expected<std::vector<wire::AnnotationEvent>> ParseSession(std::string_view text,
                                                          const std::string& name);
// Writes validated events into the empty `store`, one transaction (errors: the store's).
Expected<size_t> ImportEvents(std::vector<wire::AnnotationEvent> events, const std::string& name,
                              AnnotationStore* store);
// The file's text for `events` (header and one line each), as ExportSession writes it.
std::string SessionText(const std::vector<wire::AnnotationEvent>& events);

// One event <-> one JSON line (without the newline); exposed for tests.
std::string AnnotationEventToJsonLine(const wire::AnnotationEvent& event);
Expected<wire::AnnotationEvent> AnnotationEventFromJsonLine(const std::string& line);

}  // namespace sandtable::coordinator
