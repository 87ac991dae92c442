#include "coordinator/calibration/recalibration_service.h"

#include <random>

#include "common/base/log.h"

namespace sandtable::coordinator {

RecalibrationService::RecalibrationService(std::chrono::milliseconds republish_period,
                                           uint64_t epoch)
    : republish_period_(republish_period) {
  while (epoch == 0) {
    std::random_device random;
    epoch = (uint64_t{random()} << 32) ^ random();
  }
  ask_.set_epoch(epoch);
}

void RecalibrationService::OnRequest(net::Incoming request, CoordinatorServer& server) {
  const wire::RecalibrateRequest& r = request.envelope.recalibrate_request();
  std::string reason;
  if (!r.all_units() && !IsValidNodeId(r.node_id())) {
    reason = "node id " + std::to_string(r.node_id()) + " is reserved";
  } else if (!r.all_units() && !server.members().Contains(r.node_id())) {
    reason = "unit " + std::to_string(r.node_id()) + " is not a member of the site";
  } else if (server.members().size() == 0) {
    reason = "the site has no members";
  }
  if (reason.empty()) {
    ask_.set_ask_id(ask_.ask_id() + 1);
    ask_.set_all_units(r.all_units());
    ask_.set_node_id(r.all_units() ? 0 : r.node_id());
    ST_LOG(kInfo) << "recalibration asked (ask " << ask_.ask_id() << "): "
                  << (r.all_units() ? std::string("the whole site")
                                    : "unit " + std::to_string(r.node_id()));
  }
  wire::Envelope reply;
  wire::RecalibrateReply* out = reply.mutable_recalibrate_reply();
  out->set_request_sequence(request.envelope.sequence());
  out->set_accepted(reason.empty());
  out->set_reason(reason);
  if (reason.empty()) out->set_ask_id(ask_.ask_id());
  Status sent = server.Reply(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "recalibrate reply dropped: " << sent.ToString();
  if (reason.empty()) {
    Status published = Publish(server);
    if (!published.ok())
      ST_LOG(kDebug) << "recalibrate ask not published: " << published.ToString();
  }
}

Status RecalibrationService::OnStep(CoordinatorServer& server) {
  if (std::chrono::steady_clock::now() - last_publish_ < republish_period_) return OkStatus();
  return Publish(server);
}

Status RecalibrationService::Publish(CoordinatorServer& server) {
  last_publish_ = std::chrono::steady_clock::now();
  wire::Envelope event;
  *event.mutable_recalibrate_ask() = ask_;
  return server.Publish(std::move(event));
}

}  // namespace sandtable::coordinator
