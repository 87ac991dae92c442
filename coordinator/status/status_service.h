// StatusService: builds the coordinator's status document on the server thread (every
// refresh_period, in OnStep) and hands it to an HttpStatusServer, so the HTTP thread never
// touches coordinator state. It also serves the units' unit_status messages (no reply) into a
// UnitStatusBoard (coordinator/status/unit_status_board.h).
//
// Document (JSON): {"time_ns", "members": [{"node_id", "incarnation", "joined_time_ns",
// "peer_router", "capabilities": {...}, "state"}], "units": [UnitStatusBoard::Json],
// "member_list_version", "messages": {"accepted", "rejected": {reason: count},
// "rejected_total"}, "annotations": {...} or null, "timeline": {...} or null, "tracker":
// {"state": "replaying" | "finished" | ... | "not_running", ...}, "test_patterns":
// {"site", "nodes": {id: pattern}} or null, "enrollment": {"on", "units": [{"fingerprint",
// "host_name", "address", "node_id", "waiting_s", "state"}]}, "http": {"ok", "not_found",
// "bad_request", "unauthorized", "actions"}}. docs/console.md.
#pragma once

#include <chrono>

#include "coordinator/annotations/annotation_service.h"
#include "coordinator/calibration/recalibration_service.h"
#include "coordinator/display/test_pattern_service.h"
#include "coordinator/membership/coordinator_server.h"
#include "coordinator/status/http_status_server.h"
#include "coordinator/status/unit_status_board.h"
#include "coordinator/timeline/timeline_service.h"
#include "coordinator/wand/wand_service.h"

namespace sandtable::coordinator {

struct StatusSources {
  const AnnotationService* annotations = nullptr;  // null: not running
  const TimelineService* timeline = nullptr;
  const WandService* tracker = nullptr;  // null: "tracker": {"state": "not_running"}
  const TestPatternService* patterns = nullptr;
  const RecalibrationService* recalibration = nullptr;  // null: "recalibration": null
};

class StatusService : public CoordinatorService {
 public:
  StatusService(HttpStatusServer* http, StatusSources sources,
                std::chrono::milliseconds refresh_period = std::chrono::milliseconds(200));

  bool Serves(wire::Envelope::BodyCase body) const override {
    return body == wire::Envelope::kUnitStatus;
  }
  void OnRequest(net::Incoming request, CoordinatorServer& server) override;
  Status OnStep(CoordinatorServer& server) override;

  // The document now (also what OnStep publishes).
  std::string BuildJson(CoordinatorServer& server);

  const UnitStatusBoard& board() const { return board_; }

 private:
  HttpStatusServer* http_;
  StatusSources sources_;
  std::chrono::milliseconds refresh_period_;
  std::chrono::steady_clock::time_point last_{};
  UnitStatusBoard board_;
};

}  // namespace sandtable::coordinator
