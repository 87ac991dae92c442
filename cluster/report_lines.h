// The JSON lines every Sandtable program prints on stdout for its supervisor (sandtable-lab,
// tests, an operator's script), as types: one struct per kind of line, written with ToJson and
// read back with ParseReportLine. docs/lab.md lists them with an example of each.
//
// The first line of a program that serves something is its ready line, naming the program and
// the endpoints it bound; later lines report a state change (a unit calibrated, a blend shown)
// or a summary at exit. A line's kind is told by its first key ("ready" and its value,
// "calibrated", "render" with "frames" / "pattern" / "unavailable", ...). Every other line on
// stdout is free text for people; a line that starts with '{' and is not one of these is an error
// the reader counts and logs (ReportLineCounts).
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <ostream>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"

namespace sandtable::report {

// {"ready":"sandtable-world","world":"tcp://127.0.0.1:40111","curve":false}
struct WorldReady {
  std::string world;   // the world's request endpoint
  bool curve = false;  // it asks for CURVE
};

// {"ready":"sandtable-coordinator","requests":"tcp://..","events":"tcp://..","status":"http://.."}
struct CoordinatorReady {
  std::string requests, events;
  std::string status;  // the status page's URL; empty: not served
};

// {"ready":"sandtable-node","id":3,"peer":"tcp://.."}
struct NodeReady {
  NodeId id = kInvalidNodeId;
  std::string peer;  // the endpoint its peers connect to
};

// {"calibrated":3,"source":"self","json":"DIR/unit-3.json","yaml":..,...}: a unit holds a
// calibration and exported it. A held calibration (factory, the lab's true pose) fills the first
// four; a self-calibration round the rest (empty, 0: none).
struct Calibrated {
  NodeId id = kInvalidNodeId;
  std::string source, json, yaml;
  std::string report, mpcdi, join_report;  // files written beside it
  uint64_t round = 0;                      // the round that placed it (0: none)
  bool verified = false;                   // a saved calibration checked, no round
  double compute_s = 0.0;
  uint64_t messages_sent = 0, messages_received = 0, bytes_sent = 0, bytes_received = 0;
  // Its camera's timing (node/devices/paced_camera.h): the flash latency measured (< 0: none),
  // what captures waited, pictures kept, and reads thrown away as stale or repeated.
  double capture_latency_ms = -1.0, capture_settle_ms = 0.0;
  uint64_t captures = 0, captures_stale = 0, captures_repeated = 0;
};

// {"calibration_failed":3,"reason":".."}
struct CalibrationFailed {
  NodeId id = kInvalidNodeId;
  std::string reason;
};

// {"verification":3,"holds":true,...}: a saved calibration checked against a few dots.
struct Verification {
  NodeId id = kInvalidNodeId;
  int frames = 0;
  double device_time_s = 0.0, compute_s = 0.0;
  bool holds = false;
  int dots = 0, found = 0, wall_dots = 0;
  double median_px = 0.0, p90_px = 0.0, wall_median_px = 0.0, threshold_px = 0.0;
  std::string reason;  // why it does not hold (empty when it does)
};

// {"render":3,"unavailable":".."}: the unit cannot show anything.
struct RenderUnavailable {
  NodeId id = kInvalidNodeId;
  std::string reason;
};

// {"render":3,"pattern":"white"}: an operator's test pattern first shown.
struct RenderPattern {
  NodeId id = kInvalidNodeId;
  std::string pattern;
};

// {"render":3,"frames":..,...}: the render loop's summary (periodically and at exit).
struct RenderSummary {
  NodeId id = kInvalidNodeId;
  int64_t frames = 0, failed = 0, unchanged = 0, rewarped = 0, groups_culled = 0;
  double frame_ms_p50 = 0.0, frame_ms_p99 = 0.0, floor_ms = 0.0, show_ms_p50 = 0.0;
  // The first frame drawn (its shaders compiled, its surface cache filled), kept out of the
  // percentiles above; 0 when none was drawn.
  double first_frame_ms = 0.0;
  std::map<std::string, int64_t> passes;  // frames each pass ran in, by PassName
  std::string context;                    // the GL renderer's description
};

// {"blend":3,"mpcdi":"DIR/site.mpcdi","alpha_from":2}: the site's MPCDI export written.
struct BlendExported {
  NodeId id = kInvalidNodeId;
  std::string mpcdi;
  NodeId alpha_from = kInvalidNodeId;  // the unit whose alpha maps it holds last
};

// The timing of the frame that showed a blend.
struct BlendFrame {
  double wait_ms = 0.0, set_mask_ms = 0.0, render_ms = 0.0, read_ms = 0.0, show_ms = 0.0;
  bool rewarped = false, late = false, prepared = false;
};

// {"blend":3,"blended":true,"cause":"..",...} or {"blend":3,"reblend":"left","peer":2,...}: a
// blend mask shown, after a neighbour's field came (blended) or after a neighbour left (reblend).
struct BlendShown {
  NodeId id = kInvalidNodeId;
  bool reblend = false;          // after a neighbour left
  std::string cause;             // blended: what brought it; reblend: "left"
  NodeId peer = kInvalidNodeId;  // reblend: the unit that left
  int64_t detected_ns = 0;       // reblend: when it was noticed (steady clock)
  std::string noticed_by;        // reblend: "member list", "connection", "silence"
  std::vector<NodeId> neighbours, waiting_for;
  double level_per_m2 = 0.0;
  int faces_below_level = 0;
  double face_level_min_per_m2 = 0.0;
  std::optional<double> black_target_per_m2, lift_max;
  double compose_ms = 0.0, cast_ms = 0.0;
  int64_t shown_ns = 0;
  BlendFrame frame;
  uint64_t bytes_sent = 0, bytes_received = 0;
};

// {"messages":3,"accepted":..,...}: a node's message counts at exit.
struct Messages {
  NodeId id = kInvalidNodeId;
  uint64_t accepted = 0, rejected = 0, faults_dropped = 0, faults_corrupted = 0;
};

// {"round_progress":3,"round":1,"stage":57,"step":"structured light, colour 1","detail":"colour 1
// frame 12 capture","units":[0,2],"elapsed_s":14.2}: the runner of a calibration round (unit
// `id`) started a stage: `step` is the part of the round it belongs to (changes a few times a
// round), `detail` the stage itself, `units` the units whose projectors' light it shows or
// captures (empty: none, e.g. the solve), `elapsed_s` since the round started. Printed when the
// step changes, else at most about once a second.
struct RoundProgress {
  NodeId id = kInvalidNodeId;
  uint64_t round = 0;
  int stage = 0;  // stages started in this round, this one included
  std::string step, detail;
  std::vector<NodeId> units;
  double elapsed_s = 0.0;
};

// {"lab":"phase","phase":"hold","hold_s":10}
struct LabPhase {
  std::string phase;
  std::optional<double> hold_s;
};

// {"lab":"done","status":"ok","report":"OUT/report.md"}
struct LabDone {
  std::string status, report;
};

using ReportLine =
    std::variant<WorldReady, CoordinatorReady, NodeReady, Calibrated, CalibrationFailed,
                 Verification, RenderUnavailable, RenderPattern, RenderSummary, BlendExported,
                 BlendShown, Messages, RoundProgress, LabPhase, LabDone>;

// For std::visit over a ReportLine: one callable per kind.
template <class... F>
struct Overloaded : F... {
  using F::operator()...;
};
template <class... F>
Overloaded(F...) -> Overloaded<F...>;

// The line's kind in words ("calibrated", "render summary", ...).
const char* KindName(const ReportLine& line);

nlohmann::json ToJson(const ReportLine& line);
// A blend line's frame timing as it appears in the line ("frame").
nlohmann::json ToJson(const BlendFrame& frame);
// One compact line, no newline.
std::string ToText(const ReportLine& line);
// Writes the line and a newline, and flushes (a supervisor waits for it).
void WriteReportLine(std::ostream& out, const ReportLine& line);

// A JSON object as one of the kinds above. INVALID_ARGUMENT names what is wrong (not an object,
// no kind this reader knows, a field missing or of the wrong type). Unknown extra fields are
// ignored (a newer writer may add some).
Expected<ReportLine> ParseReportLine(const nlohmann::json& object);
// The same from a line of text (not JSON: INVALID_ARGUMENT).
Expected<ReportLine> ParseReportLineText(std::string_view text);

// What a reader made of the lines it was given: the report lines, and those that looked like
// one (they start with '{') but did not parse, with the last such error.
struct ReportLineCounts {
  uint64_t parsed = 0;
  uint64_t bad = 0;
  std::string last_error;
};

}  // namespace sandtable::report
