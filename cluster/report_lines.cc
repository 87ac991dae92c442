#include "cluster/report_lines.h"

#include <limits>
#include <type_traits>

namespace sandtable::report {
namespace {

using json = nlohmann::json;

// Reads the fields of one line, remembering the first thing wrong.
class Reader {
 public:
  Reader(const json& j, const char* kind) : j_(j), kind_(kind) {}

  template <typename T>
  void Required(const char* key, T* out) {
    Read(key, out, /*required=*/true);
  }
  template <typename T>
  void Optional(const char* key, T* out) {
    Read(key, out, /*required=*/false);
  }
  template <typename T>
  void Optional(const char* key, std::optional<T>* out) {
    if (!j_.contains(key)) return;
    T value{};
    Read(key, &value, /*required=*/true);
    *out = value;
  }

  Status status() const {
    if (error_.empty()) return OkStatus();
    return InvalidArgumentError(std::string("report line (") + kind_ + "): " + error_);
  }

 private:
  template <typename T>
  void Read(const char* key, T* out, bool required) {
    if (!error_.empty()) return;
    auto it = j_.find(key);
    if (it == j_.end()) {
      if (required) error_ = std::string("no \"") + key + "\"";
      return;
    }
    if (!Convert(*it, out)) error_ = std::string("\"") + key + "\" is " + it->dump();
  }

  static bool Convert(const json& v, std::string* out) {
    if (!v.is_string()) return false;
    *out = v.get<std::string>();
    return true;
  }
  static bool Convert(const json& v, bool* out) {
    if (!v.is_boolean()) return false;
    *out = v.get<bool>();
    return true;
  }
  static bool Convert(const json& v, double* out) {
    if (!v.is_number()) return false;
    *out = v.get<double>();
    return true;
  }
  template <typename T>
  requires std::is_integral_v<T>
  static bool Convert(const json& v, T* out) {
    if (v.is_number_unsigned()) {
      const uint64_t u = v.get<uint64_t>();
      if (u > static_cast<uint64_t>(std::numeric_limits<T>::max())) return false;
      *out = static_cast<T>(u);
      return true;
    }
    if (!v.is_number_integer() || !std::is_signed_v<T>) return false;
    const int64_t i = v.get<int64_t>();
    if (i < static_cast<int64_t>(std::numeric_limits<T>::min()) ||
        i > static_cast<int64_t>(std::numeric_limits<T>::max())) {
      return false;
    }
    *out = static_cast<T>(i);
    return true;
  }
  template <typename T>
  static bool Convert(const json& v, std::vector<T>* out) {
    if (!v.is_array()) return false;
    out->clear();
    for (const json& e : v) {
      T value{};
      if (!Convert(e, &value)) return false;
      out->push_back(value);
    }
    return true;
  }
  template <typename T>
  static bool Convert(const json& v, std::map<std::string, T>* out) {
    if (!v.is_object()) return false;
    out->clear();
    for (auto it = v.begin(); it != v.end(); ++it) {
      T value{};
      if (!Convert(it.value(), &value)) return false;
      (*out)[it.key()] = value;
    }
    return true;
  }

  const json& j_;
  const char* kind_;
  std::string error_;
};

template <typename T>
Expected<ReportLine> Done(const Reader& r, T line) {
  if (Status s = r.status(); !s.ok()) return s;
  return ReportLine(std::move(line));
}

Expected<ReportLine> ParseReady(const json& j) {
  const auto& ready = j["ready"];
  if (!ready.is_string()) return InvalidArgumentError("report line: \"ready\" is not a string");
  const std::string program = ready.get<std::string>();
  if (program == "sandtable-world") {
    WorldReady line;
    Reader r(j, "world ready");
    r.Required("world", &line.world);
    r.Optional("curve", &line.curve);
    return Done(r, line);
  }
  if (program == "sandtable-coordinator") {
    CoordinatorReady line;
    Reader r(j, "coordinator ready");
    r.Required("requests", &line.requests);
    r.Required("events", &line.events);
    r.Optional("status", &line.status);
    return Done(r, line);
  }
  if (program == "sandtable-node") {
    NodeReady line;
    Reader r(j, "node ready");
    r.Required("id", &line.id);
    r.Required("peer", &line.peer);
    return Done(r, line);
  }
  return InvalidArgumentError("report line: ready line of an unknown program \"" + program + "\"");
}

Expected<ReportLine> ParseCalibrated(const json& j) {
  Calibrated line;
  Reader r(j, "calibrated");
  r.Required("calibrated", &line.id);
  r.Required("source", &line.source);
  r.Required("json", &line.json);
  r.Required("yaml", &line.yaml);
  r.Optional("report", &line.report);
  r.Optional("mpcdi", &line.mpcdi);
  r.Optional("join_report", &line.join_report);
  r.Optional("round", &line.round);
  r.Optional("verified", &line.verified);
  r.Optional("compute_s", &line.compute_s);
  r.Optional("messages_sent", &line.messages_sent);
  r.Optional("messages_received", &line.messages_received);
  r.Optional("bytes_sent", &line.bytes_sent);
  r.Optional("bytes_received", &line.bytes_received);
  r.Optional("capture_latency_ms", &line.capture_latency_ms);
  r.Optional("capture_settle_ms", &line.capture_settle_ms);
  r.Optional("captures", &line.captures);
  r.Optional("captures_stale", &line.captures_stale);
  r.Optional("captures_repeated", &line.captures_repeated);
  return Done(r, line);
}

Expected<ReportLine> ParseVerification(const json& j) {
  Verification line;
  Reader r(j, "verification");
  r.Required("verification", &line.id);
  r.Required("holds", &line.holds);
  r.Optional("frames", &line.frames);
  r.Optional("device_time_s", &line.device_time_s);
  r.Optional("compute_s", &line.compute_s);
  r.Optional("dots", &line.dots);
  r.Optional("found", &line.found);
  r.Optional("median_px", &line.median_px);
  r.Optional("p90_px", &line.p90_px);
  r.Optional("wall_dots", &line.wall_dots);
  r.Optional("wall_median_px", &line.wall_median_px);
  r.Optional("threshold_px", &line.threshold_px);
  r.Optional("reason", &line.reason);
  return Done(r, line);
}

Expected<ReportLine> ParseRender(const json& j) {
  if (j.contains("unavailable")) {
    RenderUnavailable line;
    Reader r(j, "render unavailable");
    r.Required("render", &line.id);
    r.Required("unavailable", &line.reason);
    return Done(r, line);
  }
  if (j.contains("pattern")) {
    RenderPattern line;
    Reader r(j, "render pattern");
    r.Required("render", &line.id);
    r.Required("pattern", &line.pattern);
    return Done(r, line);
  }
  RenderSummary line;
  Reader r(j, "render summary");
  r.Required("render", &line.id);
  r.Required("frames", &line.frames);
  r.Optional("failed", &line.failed);
  r.Optional("unchanged", &line.unchanged);
  r.Optional("rewarped", &line.rewarped);
  r.Optional("groups_culled", &line.groups_culled);
  r.Optional("frame_ms_p50", &line.frame_ms_p50);
  r.Optional("frame_ms_p99", &line.frame_ms_p99);
  r.Optional("first_frame_ms", &line.first_frame_ms);
  r.Optional("floor_ms", &line.floor_ms);
  r.Optional("show_ms_p50", &line.show_ms_p50);
  r.Optional("passes", &line.passes);
  r.Optional("context", &line.context);
  return Done(r, line);
}

Expected<ReportLine> ParseBlend(const json& j) {
  if (j.contains("mpcdi")) {
    BlendExported line;
    Reader r(j, "blend exported");
    r.Required("blend", &line.id);
    r.Required("mpcdi", &line.mpcdi);
    r.Optional("alpha_from", &line.alpha_from);
    return Done(r, line);
  }
  BlendShown line;
  Reader r(j, "blend shown");
  r.Required("blend", &line.id);
  if (j.contains("reblend")) {
    line.reblend = true;
    r.Required("reblend", &line.cause);
    r.Required("peer", &line.peer);
    r.Optional("detected_ns", &line.detected_ns);
    r.Optional("noticed_by", &line.noticed_by);
  } else {
    bool blended = false;
    r.Required("blended", &blended);
    r.Optional("cause", &line.cause);
  }
  r.Optional("neighbours", &line.neighbours);
  r.Optional("waiting_for", &line.waiting_for);
  r.Optional("level_per_m2", &line.level_per_m2);
  r.Optional("faces_below_level", &line.faces_below_level);
  r.Optional("face_level_min_per_m2", &line.face_level_min_per_m2);
  r.Optional("black_target_per_m2", &line.black_target_per_m2);
  r.Optional("lift_max", &line.lift_max);
  r.Optional("compose_ms", &line.compose_ms);
  r.Optional("cast_ms", &line.cast_ms);
  r.Optional("shown_ns", &line.shown_ns);
  r.Optional("bytes_sent", &line.bytes_sent);
  r.Optional("bytes_received", &line.bytes_received);
  if (Status s = r.status(); !s.ok()) return s;
  if (j.contains("frame")) {
    const json& f = j["frame"];
    if (!f.is_object())
      return InvalidArgumentError("report line (blend shown): \"frame\" is " + f.dump());
    Reader fr(f, "blend shown, frame");
    fr.Optional("wait_ms", &line.frame.wait_ms);
    fr.Optional("set_mask_ms", &line.frame.set_mask_ms);
    fr.Optional("render_ms", &line.frame.render_ms);
    fr.Optional("read_ms", &line.frame.read_ms);
    fr.Optional("show_ms", &line.frame.show_ms);
    fr.Optional("rewarped", &line.frame.rewarped);
    fr.Optional("late", &line.frame.late);
    fr.Optional("prepared", &line.frame.prepared);
    return Done(fr, line);
  }
  return ReportLine(std::move(line));
}

Expected<ReportLine> ParseLab(const json& j) {
  const auto& what = j["lab"];
  if (what == "phase") {
    LabPhase line;
    Reader r(j, "lab phase");
    r.Required("phase", &line.phase);
    r.Optional("hold_s", &line.hold_s);
    return Done(r, line);
  }
  if (what == "done") {
    LabDone line;
    Reader r(j, "lab done");
    r.Required("status", &line.status);
    r.Optional("report", &line.report);
    return Done(r, line);
  }
  return InvalidArgumentError("report line: unknown lab line " + what.dump());
}

}  // namespace

const char* KindName(const ReportLine& line) {
  static constexpr const char* kNames[] = {
      "world ready",        "coordinator ready",  "node ready",
      "calibrated",         "calibration failed", "verification",
      "render unavailable", "render pattern",     "render summary",
      "blend exported",     "blend shown",        "messages",
      "round progress",     "lab phase",          "lab done"};
  static_assert(std::size(kNames) == std::variant_size_v<ReportLine>);
  return kNames[line.index()];
}

json ToJson(const ReportLine& line) {
  return std::visit(
      Overloaded{
          [](const WorldReady& l) -> json {
            return {{"ready", "sandtable-world"}, {"world", l.world}, {"curve", l.curve}};
          },
          [](const CoordinatorReady& l) -> json {
            json j = {
                {"ready", "sandtable-coordinator"}, {"requests", l.requests}, {"events", l.events}};
            if (!l.status.empty()) j["status"] = l.status;
            return j;
          },
          [](const NodeReady& l) -> json {
            return {{"ready", "sandtable-node"}, {"id", l.id}, {"peer", l.peer}};
          },
          [](const Calibrated& l) -> json {
            return {{"calibrated", l.id},
                    {"source", l.source},
                    {"json", l.json},
                    {"yaml", l.yaml},
                    {"report", l.report},
                    {"mpcdi", l.mpcdi},
                    {"join_report", l.join_report},
                    {"round", l.round},
                    {"verified", l.verified},
                    {"compute_s", l.compute_s},
                    {"messages_sent", l.messages_sent},
                    {"messages_received", l.messages_received},
                    {"bytes_sent", l.bytes_sent},
                    {"bytes_received", l.bytes_received},
                    {"capture_latency_ms", l.capture_latency_ms},
                    {"capture_settle_ms", l.capture_settle_ms},
                    {"captures", l.captures},
                    {"captures_stale", l.captures_stale},
                    {"captures_repeated", l.captures_repeated}};
          },
          [](const CalibrationFailed& l) -> json {
            return {{"calibration_failed", l.id}, {"reason", l.reason}};
          },
          [](const Verification& l) -> json {
            json j = {{"verification", l.id},
                      {"frames", l.frames},
                      {"device_time_s", l.device_time_s},
                      {"compute_s", l.compute_s},
                      {"holds", l.holds},
                      {"dots", l.dots},
                      {"found", l.found},
                      {"median_px", l.median_px},
                      {"p90_px", l.p90_px},
                      {"wall_dots", l.wall_dots},
                      {"wall_median_px", l.wall_median_px},
                      {"threshold_px", l.threshold_px}};
            if (!l.reason.empty()) j["reason"] = l.reason;
            return j;
          },
          [](const RenderUnavailable& l) -> json {
            return {{"render", l.id}, {"unavailable", l.reason}};
          },
          [](const RenderPattern& l) -> json {
            return {{"render", l.id}, {"pattern", l.pattern}};
          },
          [](const RenderSummary& l) -> json {
            return {{"render", l.id},
                    {"frames", l.frames},
                    {"failed", l.failed},
                    {"unchanged", l.unchanged},
                    {"rewarped", l.rewarped},
                    {"frame_ms_p50", l.frame_ms_p50},
                    {"frame_ms_p99", l.frame_ms_p99},
                    {"first_frame_ms", l.first_frame_ms},
                    {"floor_ms", l.floor_ms},
                    {"show_ms_p50", l.show_ms_p50},
                    {"passes", l.passes},
                    {"groups_culled", l.groups_culled},
                    {"context", l.context}};
          },
          [](const BlendExported& l) -> json {
            return {{"blend", l.id}, {"mpcdi", l.mpcdi}, {"alpha_from", l.alpha_from}};
          },
          [](const BlendShown& l) -> json {
            json j = {{"blend", l.id}};
            if (l.reblend) {
              j["reblend"] = l.cause;
              j["peer"] = l.peer;
              j["detected_ns"] = l.detected_ns;
              if (!l.noticed_by.empty()) j["noticed_by"] = l.noticed_by;
            } else {
              j["blended"] = true;
              j["cause"] = l.cause;
            }
            j["neighbours"] = l.neighbours;
            j["waiting_for"] = l.waiting_for;
            j["level_per_m2"] = l.level_per_m2;
            j["faces_below_level"] = l.faces_below_level;
            j["face_level_min_per_m2"] = l.face_level_min_per_m2;
            if (l.black_target_per_m2) j["black_target_per_m2"] = *l.black_target_per_m2;
            if (l.lift_max) j["lift_max"] = *l.lift_max;
            j["compose_ms"] = l.compose_ms;
            j["cast_ms"] = l.cast_ms;
            j["shown_ns"] = l.shown_ns;
            j["frame"] = ToJson(l.frame);
            j["bytes_sent"] = l.bytes_sent;
            j["bytes_received"] = l.bytes_received;
            return j;
          },
          [](const Messages& l) -> json {
            return {{"messages", l.id},
                    {"accepted", l.accepted},
                    {"rejected", l.rejected},
                    {"faults_dropped", l.faults_dropped},
                    {"faults_corrupted", l.faults_corrupted}};
          },
          [](const RoundProgress& l) -> json {
            return {{"round_progress", l.id},  {"round", l.round},   {"stage", l.stage},
                    {"step", l.step},          {"detail", l.detail}, {"units", l.units},
                    {"elapsed_s", l.elapsed_s}};
          },
          [](const LabPhase& l) -> json {
            json j = {{"lab", "phase"}, {"phase", l.phase}};
            if (l.hold_s) j["hold_s"] = *l.hold_s;
            return j;
          },
          [](const LabDone& l) -> json {
            return {{"lab", "done"}, {"status", l.status}, {"report", l.report}};
          },
      },
      line);
}

json ToJson(const BlendFrame& f) {
  return {{"wait_ms", f.wait_ms}, {"set_mask_ms", f.set_mask_ms}, {"render_ms", f.render_ms},
          {"read_ms", f.read_ms}, {"show_ms", f.show_ms},         {"rewarped", f.rewarped},
          {"late", f.late},       {"prepared", f.prepared}};
}

std::string ToText(const ReportLine& line) { return ToJson(line).dump(); }

void WriteReportLine(std::ostream& out, const ReportLine& line) {
  out << ToText(line) << std::endl;
}

Expected<ReportLine> ParseReportLine(const json& j) {
  if (!j.is_object()) return InvalidArgumentError("report line: not a JSON object");
  if (j.contains("ready")) return ParseReady(j);
  if (j.contains("calibrated")) return ParseCalibrated(j);
  if (j.contains("calibration_failed")) {
    CalibrationFailed line;
    Reader r(j, "calibration failed");
    r.Required("calibration_failed", &line.id);
    r.Required("reason", &line.reason);
    return Done(r, line);
  }
  if (j.contains("verification")) return ParseVerification(j);
  if (j.contains("render")) return ParseRender(j);
  if (j.contains("blend")) return ParseBlend(j);
  if (j.contains("messages")) {
    Messages line;
    Reader r(j, "messages");
    r.Required("messages", &line.id);
    r.Optional("accepted", &line.accepted);
    r.Optional("rejected", &line.rejected);
    r.Optional("faults_dropped", &line.faults_dropped);
    r.Optional("faults_corrupted", &line.faults_corrupted);
    return Done(r, line);
  }
  if (j.contains("round_progress")) {
    RoundProgress line;
    Reader r(j, "round progress");
    r.Required("round_progress", &line.id);
    r.Required("round", &line.round);
    r.Optional("stage", &line.stage);
    r.Required("step", &line.step);
    r.Optional("detail", &line.detail);
    r.Optional("units", &line.units);
    r.Optional("elapsed_s", &line.elapsed_s);
    return Done(r, line);
  }
  if (j.contains("lab")) return ParseLab(j);
  std::string keys;
  for (auto it = j.begin(); it != j.end(); ++it) keys += (keys.empty() ? "" : ", ") + it.key();
  return InvalidArgumentError("report line: no kind of line has the keys " + keys);
}

Expected<ReportLine> ParseReportLineText(std::string_view text) {
  const json j = json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) {
    return InvalidArgumentError("report line: not JSON: " +
                                std::string(text.substr(0, std::min<size_t>(text.size(), 120))));
  }
  return ParseReportLine(j);
}

}  // namespace sandtable::report
