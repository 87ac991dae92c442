#include "coordinator/display/test_pattern_service.h"

#include "common/base/log.h"

namespace sandtable::coordinator {

bool IsTestPatternName(const std::string& name) {
  for (const char* known : {"none", "id", "grid", "white", "raw-white", "bars", "black"}) {
    if (name == known) return true;
  }
  return false;
}

void TestPatternService::OnRequest(net::Incoming request, CoordinatorServer& server) {
  const wire::TestPatternRequest& r = request.envelope.test_pattern_request();
  std::string reason;
  const bool clear = !r.all_nodes() && r.pattern().empty();
  if (!clear && !IsTestPatternName(r.pattern())) {
    reason = "unknown test pattern '" + r.pattern().substr(0, 64) +
             "' (none, id, grid, white, raw-white, bars, black)";
  } else if (!r.all_nodes() && !IsValidNodeId(r.node_id())) {
    reason = "node id " + std::to_string(r.node_id()) + " is reserved";
  } else if (!r.all_nodes() && !clear && state_.node_patterns().size() >= kMaxNodePatterns &&
             !state_.node_patterns().contains(r.node_id())) {
    reason = "more than " + std::to_string(kMaxNodePatterns) + " node patterns";
  }
  if (reason.empty()) {
    if (r.all_nodes()) {
      state_.set_site_pattern(r.pattern());
      state_.mutable_node_patterns()->clear();
    } else if (clear) {
      state_.mutable_node_patterns()->erase(r.node_id());
    } else {
      (*state_.mutable_node_patterns())[r.node_id()] = r.pattern();
    }
    state_.set_change_count(state_.change_count() + 1);
    ST_LOG(kInfo) << "test pattern: "
                  << (r.all_nodes() ? std::string("site") : "node " + std::to_string(r.node_id()))
                  << " -> " << (clear ? std::string("(site's)") : r.pattern());
  }
  wire::Envelope reply;
  wire::TestPatternReply* out = reply.mutable_test_pattern_reply();
  out->set_request_sequence(request.envelope.sequence());
  out->set_accepted(reason.empty());
  out->set_reason(reason);
  Status sent = server.Reply(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "test pattern reply dropped: " << sent.ToString();
  if (reason.empty()) {
    Status published = Publish(server);
    if (!published.ok())
      ST_LOG(kDebug) << "test pattern state not published: " << published.ToString();
  }
}

Status TestPatternService::OnStep(CoordinatorServer& server) {
  if (std::chrono::steady_clock::now() - last_publish_ < republish_period_) return OkStatus();
  return Publish(server);
}

Status TestPatternService::Publish(CoordinatorServer& server) {
  last_publish_ = std::chrono::steady_clock::now();
  wire::Envelope event;
  *event.mutable_test_pattern_state() = state_;
  return server.Publish(std::move(event));
}

}  // namespace sandtable::coordinator
