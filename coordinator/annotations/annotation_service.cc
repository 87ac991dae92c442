#include "coordinator/annotations/annotation_service.h"

#include "common/base/log.h"

namespace sandtable::coordinator {

Status AnnotationServiceOptions::Check() const {
  if (max_catch_up_events == 0 || max_batch_events == 0) {
    return InvalidArgumentError(
        "annotations: max_catch_up_events and max_batch_events must be > 0");
  }
  return OkStatus();
}

AnnotationService::AnnotationService(AnnotationStore* store, AnnotationServiceOptions options)
    : store_(store), options_(options) {
  ST_CHECK(store_ != nullptr) << "AnnotationService needs an open AnnotationStore";
}

bool AnnotationService::Serves(wire::Envelope::BodyCase body) const {
  return body == wire::Envelope::kAnnotationRequest || body == wire::Envelope::kCatchUpRequest;
}

void AnnotationService::Submit(wire::AnnotationEvent event) {
  batch_.push_back(std::move(event));
  pending_.push_back(Pending{});
}

void AnnotationService::OnRequest(net::Incoming request, CoordinatorServer& server) {
  if (request.envelope.body_case() == wire::Envelope::kCatchUpRequest) {
    ReplyCatchUp(request, server);
    return;
  }
  wire::AnnotationEvent event = std::move(*request.envelope.mutable_annotation_request());
  event.set_event_sequence(0);  // the coordinator sequences
  batch_.push_back(std::move(event));
  pending_.push_back(Pending{std::move(request.routing_id), request.envelope.sequence()});
  if (batch_.size() >= options_.max_batch_events) (void)OnStep(server);
}

Status AnnotationService::OnStep(CoordinatorServer& server) {
  if (batch_.empty()) return OkStatus();
  std::vector<wire::AnnotationEvent> batch = std::move(batch_);
  std::vector<Pending> pending = std::move(pending_);
  batch_.clear();
  pending_.clear();
  Expected<CommitReport> report = store_->Commit(&batch);
  ++counters_.commits;
  if (!report.ok()) {
    ++counters_.commit_failures;
    ST_LOG(kError) << "annotations not stored: " << report.status().ToString();
  }
  // 1. Acknowledge (only now: the commit has returned).
  for (size_t i = 0; i < batch.size(); ++i) {
    const bool accepted = report.ok() && report->results[i].ok();
    accepted ? ++counters_.accepted : ++counters_.rejected;
    if (pending[i].routing_id.empty()) {
      if (!accepted) {
        ST_LOG(kWarning) << "coordinator annotation rejected: "
                         << (report.ok() ? report->results[i] : report.status()).ToString();
      }
      continue;
    }
    wire::Envelope reply;
    wire::AnnotationAck* ack = reply.mutable_annotation_ack();
    ack->set_request_sequence(pending[i].request_sequence);
    ack->set_accepted(accepted);
    if (accepted) {
      ack->set_event_sequence(batch[i].event_sequence());
    } else {
      ack->set_reason((report.ok() ? report->results[i] : report.status()).ToString());
    }
    Status sent = server.Reply(std::move(reply), pending[i].routing_id);
    if (!sent.ok()) ST_LOG(kDebug) << "annotation ack dropped: " << sent.ToString();
  }
  // 2. Publish the committed events, in sequence order.
  if (!report.ok()) return OkStatus();
  for (size_t i = 0; i < batch.size(); ++i) {
    if (!report->results[i].ok()) continue;
    wire::Envelope event;
    *event.mutable_annotation_event() = std::move(batch[i]);
    Status sent = server.Publish(std::move(event));
    if (!sent.ok()) ST_LOG(kDebug) << "annotation event not published: " << sent.ToString();
  }
  return OkStatus();
}

void AnnotationService::ReplyCatchUp(const net::Incoming& request, CoordinatorServer& server) {
  ++counters_.catch_ups;
  const SequenceNumber last_seen = request.envelope.catch_up_request().last_seen_sequence();
  const SequenceNumber newest = store_->last_sequence();
  wire::Envelope reply;
  wire::CatchUpReply* out = reply.mutable_catch_up_reply();
  out->set_last_event_sequence(newest);
  bool snapshot =
      last_seen == 0 || last_seen > newest || newest - last_seen > options_.max_catch_up_events;
  if (!snapshot) {
    Expected<std::vector<wire::AnnotationEvent>> events =
        store_->EventsAfter(last_seen, options_.max_catch_up_events);
    if (events.ok()) {
      for (wire::AnnotationEvent& e : *events) *out->add_events() = std::move(e);
    } else {
      ST_LOG(kWarning) << "catch-up from the log failed, sending a snapshot: "
                       << events.status().ToString();
      snapshot = true;
      out->clear_events();
    }
  }
  if (snapshot) {
    ++counters_.snapshots_sent;
    out->set_snapshot_sent(true);
    *out->mutable_snapshot() = store_->state().ToSnapshot();
  }
  Status sent = server.Reply(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "catch-up reply dropped: " << sent.ToString();
}

}  // namespace sandtable::coordinator
