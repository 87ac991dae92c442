// AnnotationService: serves annotation requests on the coordinator's ROUTER and publishes the
// sequenced events on the events socket.
//
// Requests: annotation_request (an AnnotationEvent with event_sequence 0) -> after the batch
// is durable (AnnotationStore::Commit, one transaction per server step: group commit) the
// requester gets annotation_ack{accepted, event_sequence} and then every subscriber gets
// annotation_event. Order: persist -> acknowledge -> publish, so an event anyone has seen is
// on disk. A request that does not apply gets annotation_ack{accepted=false, reason}.
// A stroke_points request of more than kMaxPointsPerRequest points is refused at once
// (annotation_ack{accepted=false, reason naming the limit}).
// catch_up_request{last_seen_sequence} -> catch_up_reply with the events after it (at most
// max_catch_up_events, and cut at catch_up_page_bytes: the requester asks again after the last
// one), or a snapshot when it is 0, too far behind, or ahead of the log. A snapshot larger than
// catch_up_page_bytes is serialized once, held (at most max_held_snapshots, each dropped
// snapshot_hold after its last use; a fresh request within max_catch_up_events of the newest
// held one reuses it) and sent in chunks the requester asks for one by one
// (events.proto CatchUpReply); a chunk of a snapshot no longer held gets snapshot_expired.
// Every reply therefore stays below the codec's message limit whatever the state's size;
// coordinator memory for catch-up is at most max_held_snapshots serialized snapshots.
// Coordinator-made events (the wand) go through Submit() and the same path, without an ack.
// A failed commit (disk error) is logged; its requests get accepted=false with the reason
// and nothing is published.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include "coordinator/annotations/annotation_store.h"
#include "coordinator/membership/coordinator_server.h"

namespace sandtable::coordinator {

// Points of one stroke_points request from the network (12 bytes each: 120 kB).
inline constexpr int kMaxPointsPerRequest = 10000;

struct AnnotationServiceOptions {
  size_t max_catch_up_events = 5000;  // beyond this a snapshot is cheaper
  size_t max_batch_events = 1000;     // per commit
  // Bytes of events or of snapshot chunk per catch-up reply: 8 MiB, well under the codec's
  // 64 MiB message limit (one event is at most ~1.2 MB: kMaxPointsPerMessage points).
  size_t catch_up_page_bytes = size_t{8} << 20;
  size_t max_held_snapshots = 2;
  std::chrono::milliseconds snapshot_hold{30000};
  Status Check() const;
};

struct AnnotationCounters {
  uint64_t accepted = 0;
  uint64_t rejected = 0;
  uint64_t commits = 0;
  uint64_t commit_failures = 0;
  uint64_t catch_ups = 0;
  uint64_t snapshots_sent = 0;
  uint64_t snapshot_chunks_sent = 0;
  uint64_t snapshots_expired = 0;
  uint64_t requests_over_point_limit = 0;
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
  struct HeldSnapshot {
    SequenceNumber sequence = 0;
    std::string bytes;  // serialized wire::Snapshot
    std::chrono::steady_clock::time_point last_used;
  };
  void ReplyCatchUp(const net::Incoming& request, CoordinatorServer& server);
  // Events after `last_seen` into `out` until the page is full; false on a read error.
  bool AddEventPage(SequenceNumber last_seen, wire::CatchUpReply* out);
  void AddSnapshot(wire::CatchUpReply* out);
  void AddChunk(const HeldSnapshot& held, uint64_t offset, wire::CatchUpReply* out);
  HeldSnapshot* FindHeld(SequenceNumber sequence);

  AnnotationStore* store_;
  AnnotationServiceOptions options_;
  std::vector<wire::AnnotationEvent> batch_;
  std::vector<Pending> pending_;
  std::vector<HeldSnapshot> held_;
  AnnotationCounters counters_;
};

}  // namespace sandtable::coordinator
