// TestPatternService: the operators' test patterns (docs/render.md), switched for the whole site
// or per node through the coordinator, so the lab and a console can do it.
//
// Requests on the ROUTER: test_pattern_request -> test_pattern_reply {request_sequence, accepted,
// reason}. A site-wide request sets the site's pattern and clears every node's own; a node
// request sets (or with "" clears) that node's. Unknown pattern names are refused, naming them;
// at most kMaxNodePatterns node patterns are held (more is refused).
// Events: test_pattern_state (the whole state) at once after every accepted request
// and every republish_period, so a node that joined late or lost an event has it within a
// period. Nodes apply their own pattern, or the site's (node/events/event_state_service.h).
#pragma once

#include <chrono>
#include <cstdint>

#include "coordinator/membership/coordinator_server.h"
#include "proto/events.pb.h"

namespace sandtable::coordinator {

inline constexpr size_t kMaxNodePatterns = 4096;

// True for the names the renderer knows ("none", "id", "grid", "white", "raw-white", "bars",
// "black").
bool IsTestPatternName(const std::string& name);

class TestPatternService : public CoordinatorService {
 public:
  explicit TestPatternService(std::chrono::milliseconds republish_period = std::chrono::seconds(1))
      : republish_period_(republish_period) {
    state_.set_site_pattern("none");
  }

  bool Serves(wire::Envelope::BodyCase body) const override {
    return body == wire::Envelope::kTestPatternRequest;
  }
  void OnRequest(net::Incoming request, CoordinatorServer& server) override;
  Status OnStep(CoordinatorServer& server) override;

  const wire::TestPatternState& state() const { return state_; }

 private:
  Status Publish(CoordinatorServer& server);

  std::chrono::milliseconds republish_period_;
  wire::TestPatternState state_;
  std::chrono::steady_clock::time_point last_publish_{};
};

}  // namespace sandtable::coordinator
