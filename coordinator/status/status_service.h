// StatusService: builds the coordinator's status document on the server thread (every
// refresh_period, in OnStep) and hands it to an HttpStatusServer, so the HTTP thread never
// touches coordinator state.
//
// Document (JSON): {"time_ns", "members": [{"node_id", "incarnation", "joined_time_ns",
// "peer_router", "calibration": null}], "member_list_version", "messages": {"accepted",
// "rejected": {reason: count}, "rejected_total"}, "annotations": {...} or null,
// "timeline": {...} or null, "tracker": {"state": "replaying" | "finished" | ... |
// "not_running", "source", "rate_hz", "samples", "poses_published", ...}, "http": {"ok",
// "not_found", "bad_request"}}. calibration is null: nodes do not report calibration state to the
// coordinator yet.
#pragma once

#include <chrono>

#include "coordinator/annotations/annotation_service.h"
#include "coordinator/membership/coordinator_server.h"
#include "coordinator/status/http_status_server.h"
#include "coordinator/timeline/timeline_service.h"
#include "coordinator/wand/wand_service.h"

namespace sandtable::coordinator {

struct StatusSources {
  const AnnotationService* annotations = nullptr;  // null: not running
  const TimelineService* timeline = nullptr;
  const WandService* tracker = nullptr;  // null: "tracker": {"state": "not_running"}
};

class StatusService : public CoordinatorService {
 public:
  StatusService(HttpStatusServer* http, StatusSources sources,
                std::chrono::milliseconds refresh_period = std::chrono::milliseconds(200));

  bool Serves(wire::Envelope::BodyCase) const override { return false; }
  void OnRequest(net::Incoming, CoordinatorServer&) override {}
  Status OnStep(CoordinatorServer& server) override;

  // The document now (also what OnStep publishes).
  std::string BuildJson(const CoordinatorServer& server) const;

 private:
  HttpStatusServer* http_;
  StatusSources sources_;
  std::chrono::milliseconds refresh_period_;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace sandtable::coordinator
