// RecalibrationService: an operator's "calibrate again" (the console's Recalibrate buttons, the
// lab), for the whole site or one unit (docs/console.md).
//
// Requests on the ROUTER: recalibrate_request -> recalibrate_reply {request_sequence, accepted,
// reason, ask_id}. Refused: a unit that is not a member, a reserved id. Accepted requests
// become the next ask (ask_id + 1), published as recalibrate_ask at once and every
// republish_period, so a unit that lost the event has it within a period. The unit that runs
// the site's rounds carries the ask out (node/app/round_policy.h); the units' states on the
// console show its progress. A newer ask replaces an older one not yet carried out.
#pragma once

#include <chrono>
#include <cstdint>

#include "coordinator/membership/coordinator_server.h"
#include "proto/calibration.pb.h"

namespace sandtable::coordinator {

class RecalibrationService : public CoordinatorService {
 public:
  // `epoch`: drawn at the coordinator's start (0 draws one here).
  explicit RecalibrationService(
      std::chrono::milliseconds republish_period = std::chrono::seconds(1), uint64_t epoch = 0);

  bool Serves(wire::Envelope::BodyCase body) const override {
    return body == wire::Envelope::kRecalibrateRequest;
  }
  void OnRequest(net::Incoming request, CoordinatorServer& server) override;
  Status OnStep(CoordinatorServer& server) override;

  const wire::RecalibrateAsk& ask() const { return ask_; }

 private:
  Status Publish(CoordinatorServer& server);

  std::chrono::milliseconds republish_period_;
  wire::RecalibrateAsk ask_;
  std::chrono::steady_clock::time_point last_publish_{};
};

}  // namespace sandtable::coordinator
