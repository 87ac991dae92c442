// EventChecksum: the integrity check of one stored annotation event (a row of the events table
// of coordinator/annotations/annotation_store.h).
//
// 64-bit FNV-1a over every stored field of the row: sequence and time_ns (8 bytes each,
// little endian), kind (its bytes and a NUL) and body (the serialized wire::AnnotationEvent:
// stroke ids, point indices, point coordinates, colours, widths, radii). Each byte step of
// FNV-1a is a bijection of the running state, so a change of any single byte always changes
// the checksum; a random change of several bytes goes undetected with probability ~2^-64.
// It detects damage and edits that bypass the coordinator, not a forger who recomputes it
// (it is not a keyed MAC). Pure function, thread-safe.
#pragma once

#include <cstdint>
#include <string_view>

namespace sandtable::coordinator {

uint64_t EventChecksum(int64_t sequence, int64_t time_ns, std::string_view kind,
                       std::string_view body);

// FNV-1a 64 of `bytes` continuing from `state` (the offset basis by default).
uint64_t Fnv1a64(std::string_view bytes, uint64_t state = 0xcbf29ce484222325ull);

}  // namespace sandtable::coordinator
