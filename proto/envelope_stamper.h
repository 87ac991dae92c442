// EnvelopeStamper: fills the header of outgoing envelopes for one sender (one per socket
// that sends, so each receiver sees strictly increasing sequences). Not thread-safe.
#pragma once

#include <chrono>
#include <cstdint>

#include "common/base/host_clock.h"
#include "proto/codec.h"
#include "proto/envelope.pb.h"

namespace sandtable::proto {

// This host's clock now, in ns (common/base/host_clock.h): the time base of send_time_ns and
// time sync.
inline int64_t SteadyNowNs() { return HostNowNs(); }

class EnvelopeStamper {
 public:
  EnvelopeStamper(uint32_t sender_id, uint64_t incarnation)
      : sender_id_(sender_id), incarnation_(incarnation) {}

  // A new envelope with version, sender, incarnation, next sequence and send time set.
  wire::Envelope Next() {
    wire::Envelope envelope;
    envelope.set_protocol_version(kProtocolVersion);
    envelope.set_sender_id(sender_id_);
    envelope.set_sender_incarnation(incarnation_);
    envelope.set_sequence(++sequence_);
    envelope.set_send_time_ns(SteadyNowNs());
    return envelope;
  }

  uint32_t sender_id() const { return sender_id_; }
  uint64_t incarnation() const { return incarnation_; }

 private:
  uint32_t sender_id_;
  uint64_t incarnation_;
  uint64_t sequence_ = 0;
};

}  // namespace sandtable::proto
