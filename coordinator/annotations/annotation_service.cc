#include "coordinator/annotations/annotation_service.h"

#include <algorithm>

#include "common/base/log.h"

namespace sandtable::coordinator {

Status AnnotationServiceOptions::Check() const {
  if (max_catch_up_events == 0 || max_batch_events == 0 || max_held_snapshots == 0) {
    return InvalidArgumentError(
        "annotations: max_catch_up_events, max_batch_events and max_held_snapshots must be > 0");
  }
  if (catch_up_page_bytes < 1024 || catch_up_page_bytes > (size_t{32} << 20)) {
    return InvalidArgumentError("annotations: catch_up_page_bytes must be in [1 KiB, 32 MiB]");
  }
  return OkStatus();
}

AnnotationService::AnnotationService(AnnotationStore* store, AnnotationServiceOptions options)
    : store_(store), options_(options) {
  ST_CHECK(store_ != nullptr) << "AnnotationService needs an open AnnotationStore";
  const Status valid = options_.Check();
  ST_CHECK(valid.ok()) << valid.ToString();
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
  if (event.has_stroke_points() &&
      event.stroke_points().points_in_table_m_size() > 3 * kMaxPointsPerRequest) {
    ++counters_.rejected;
    ++counters_.requests_over_point_limit;
    wire::Envelope reply;
    wire::AnnotationAck* ack = reply.mutable_annotation_ack();
    ack->set_request_sequence(request.envelope.sequence());
    ack->set_accepted(false);
    ack->set_reason(
        "stroke_points: " + std::to_string(event.stroke_points().points_in_table_m_size() / 3) +
        " points in one request, more than kMaxPointsPerRequest = " +
        std::to_string(kMaxPointsPerRequest) + "; send them in several requests");
    Status sent = server.Reply(std::move(reply), request.routing_id);
    if (!sent.ok()) ST_LOG(kDebug) << "annotation ack dropped: " << sent.ToString();
    return;
  }
  batch_.push_back(std::move(event));
  pending_.push_back(Pending{std::move(request.routing_id), request.envelope.sequence()});
  if (batch_.size() >= options_.max_batch_events) (void)OnStep(server);
}

Status AnnotationService::OnStep(CoordinatorServer& server) {
  const auto now = std::chrono::steady_clock::now();
  std::erase_if(held_,
                [&](const HeldSnapshot& h) { return now - h.last_used > options_.snapshot_hold; });
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

AnnotationService::HeldSnapshot* AnnotationService::FindHeld(SequenceNumber sequence) {
  for (HeldSnapshot& h : held_) {
    if (h.sequence == sequence) return &h;
  }
  return nullptr;
}

bool AnnotationService::AddEventPage(SequenceNumber last_seen, wire::CatchUpReply* out) {
  // Read in small pages: a page of the log is bounded in bytes, not only in events.
  constexpr size_t kReadEvents = 64;
  size_t bytes = 0, count = 0;
  SequenceNumber after = last_seen;
  while (count < options_.max_catch_up_events) {
    Expected<std::vector<wire::AnnotationEvent>> events =
        store_->EventsAfter(after, std::min(kReadEvents, options_.max_catch_up_events - count));
    if (!events.ok()) {
      ST_LOG(kWarning) << "catch-up from the log failed, sending a snapshot: "
                       << events.status().ToString();
      return false;
    }
    if (events->empty()) break;
    for (wire::AnnotationEvent& e : *events) {
      const size_t size = e.ByteSizeLong() + 8;
      if (count > 0 && bytes + size > options_.catch_up_page_bytes) return true;
      bytes += size;
      ++count;
      after = e.event_sequence();
      *out->add_events() = std::move(e);
    }
  }
  return true;
}

void AnnotationService::AddChunk(const HeldSnapshot& held, uint64_t offset,
                                 wire::CatchUpReply* out) {
  const size_t size = std::min<size_t>(options_.catch_up_page_bytes, held.bytes.size() - offset);
  out->set_snapshot_sent(true);
  out->set_snapshot_sequence(held.sequence);
  out->set_snapshot_total_bytes(held.bytes.size());
  out->set_snapshot_offset_bytes(offset);
  out->set_snapshot_chunk(held.bytes.substr(offset, size));
  ++counters_.snapshot_chunks_sent;
}

void AnnotationService::AddSnapshot(wire::CatchUpReply* out) {
  ++counters_.snapshots_sent;
  const SequenceNumber newest = store_->last_sequence();
  const auto now = std::chrono::steady_clock::now();
  // The newest held snapshot serves new joiners while it is close enough to the log's head
  // (they catch up the rest as events), so joiners arriving together share one copy.
  if (!held_.empty() && newest - held_.back().sequence <= options_.max_catch_up_events) {
    held_.back().last_used = now;
    AddChunk(held_.back(), 0, out);
    return;
  }
  wire::Snapshot snapshot = store_->state().ToSnapshot();
  if (snapshot.ByteSizeLong() <= options_.catch_up_page_bytes) {
    out->set_snapshot_sent(true);
    *out->mutable_snapshot() = std::move(snapshot);  // one message, as before paging
    return;
  }
  if (held_.size() >= options_.max_held_snapshots) held_.erase(held_.begin());
  HeldSnapshot held{newest, snapshot.SerializeAsString(), now};
  snapshot.Clear();
  held_.push_back(std::move(held));
  ST_LOG(kInfo) << "catch-up: snapshot at event " << newest << " of " << held_.back().bytes.size()
                << " bytes sent in chunks of " << options_.catch_up_page_bytes;
  AddChunk(held_.back(), 0, out);
}

void AnnotationService::ReplyCatchUp(const net::Incoming& request, CoordinatorServer& server) {
  ++counters_.catch_ups;
  const wire::CatchUpRequest& in = request.envelope.catch_up_request();
  const SequenceNumber last_seen = in.last_seen_sequence();
  const SequenceNumber newest = store_->last_sequence();
  wire::Envelope reply;
  wire::CatchUpReply* out = reply.mutable_catch_up_reply();
  out->set_last_event_sequence(newest);
  if (in.snapshot_sequence() != 0) {
    HeldSnapshot* held = FindHeld(in.snapshot_sequence());
    if (held == nullptr || in.snapshot_offset_bytes() >= held->bytes.size()) {
      ++counters_.snapshots_expired;
      out->set_snapshot_expired(true);
    } else {
      held->last_used = std::chrono::steady_clock::now();
      AddChunk(*held, in.snapshot_offset_bytes(), out);
    }
  } else {
    bool snapshot =
        last_seen == 0 || last_seen > newest || newest - last_seen > options_.max_catch_up_events;
    if (!snapshot && !AddEventPage(last_seen, out)) {
      snapshot = true;
      out->clear_events();
    }
    if (snapshot) AddSnapshot(out);
  }
  Status sent = server.Reply(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kWarning) << "catch-up reply not sent: " << sent.ToString();
}

}  // namespace sandtable::coordinator
