// AnnotationService: serves annotation requests on the coordinator's ROUTER and publishes the
// sequenced events on its PUB.
//
// Requests: annotation_request (an AnnotationEvent with event_sequence 0) -> after the batch
// is durable (AnnotationStore::Commit, one transaction per server step: group commit) the
// requester gets annotation_ack{accepted, event_sequence} and then every subscriber gets
// annotation_event. Order: persist -> acknowledge -> publish, so an event anyone has seen is
// on disk. A request that does not apply gets annotation_ack{accepted=false, reason}.
// catch_up_request{last_seen_sequence} -> catch_up_reply with the events after it (at most
// max_catch_up_events), or a snapshot when it is 0, too far behind, or ahead of the log.
// Coordinator-made events (the wand) go through Submit() and the same path, without an ack.
// A failed commit (disk error) is logged; its requests get accepted=false with the reason
// and nothing is published.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "coordinator/annotations/annotation_store.h"
#include "coordinator/membership/coordinator_server.h"

namespace sandtable::coordinator {

struct AnnotationServiceOptions {
  size_t max_catch_up_events = 5000;  // beyond this a snapshot is cheaper
  size_t max_batch_events = 1000;     // per commit
  Status Check() const;
};

struct AnnotationCounters {
  uint64_t accepted = 0;
  uint64_t rejected = 0;
  uint64_t commits = 0;
  uint64_t commit_failures = 0;
  uint64_t catch_ups = 0;
  uint64_t snapshots_sent = 0;
};

class AnnotationService : public CoordinatorService {
 public:
  AnnotationService(AnnotationStore* store, AnnotationServiceOptions options = {});

  bool Serves(wire::Envelope::BodyCase body) const override;
  void OnRequest(net::Incoming request, CoordinatorServer& server) override;
  Status OnStep(CoordinatorServer& server) override;

  // Queues an event made by the coordinator itself (wand strokes); committed at the next step.
  void Submit(wire::AnnotationEvent event);

  const AnnotationStore& store() const { return *store_; }
  const AnnotationCounters& counters() const { return counters_; }

 private:
  struct Pending {
    std::string routing_id;  // empty: coordinator-made, no ack
    uint64_t request_sequence = 0;
  };
  void ReplyCatchUp(const net::Incoming& request, CoordinatorServer& server);

  AnnotationStore* store_;
  AnnotationServiceOptions options_;
  std::vector<wire::AnnotationEvent> batch_;
  std::vector<Pending> pending_;
  AnnotationCounters counters_;
};

}  // namespace sandtable::coordinator
