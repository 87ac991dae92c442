// Envelope encoding and decoding: the single gate every message passes through.
//
// Encode: fills nothing in for the caller (header fields are the sender's job, see
// EnvelopeStamper in proto/envelope_stamper.h); compresses the body with zlib when it is at
// least `compress_threshold_bytes` and compression saves at least `min_saved_fraction`.
// Decode: bounds the size, parses, checks the version, required header fields, inflates a
// compressed body (bounded by max_body_bytes, so no decompression bombs) and rejects empty
// or unknown bodies. Every rejection returns a Status naming the cause and is counted once in
// `counters` (when given). Never aborts on any input.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "common/base/status.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"

namespace sandtable::proto {

// Bump on any incompatible change; receivers reject other versions (docs/protocol.md).
constexpr uint32_t kProtocolVersion = 1;

struct CodecLimits {
  // Largest message on the wire; the transport sets ZMQ_MAXMSGSIZE to the same value.
  size_t max_message_bytes = size_t{64} << 20;
  // Largest body after decompression.
  size_t max_body_bytes = size_t{64} << 20;
  // Bodies smaller than this are never compressed (not worth the CPU).
  size_t compress_threshold_bytes = 4096;
  // Compressed only when it saves at least this fraction of the body (0..1).
  double min_saved_fraction = 0.1;
  int zlib_level = 1;

  Status Check() const;
};

struct EncodeInfo {
  size_t body_bytes = 0;  // serialized body before compression
  size_t wire_bytes = 0;  // whole envelope on the wire
  bool compressed = false;
};

// Serializes `envelope`; fails (INVALID_ARGUMENT) only when the result would exceed
// max_message_bytes or the envelope has no body.
Expected<std::string> EncodeEnvelope(wire::Envelope envelope, const CodecLimits& limits = {},
                                     EncodeInfo* info = nullptr);

// Parses and validates one message. On success the envelope has compression NONE and its body
// set; on failure the Status says why and `counters` (may be null) counts the reason.
Expected<wire::Envelope> DecodeEnvelope(std::string_view bytes, const CodecLimits& limits = {},
                                        MessageCounters* counters = nullptr);

// The body's name ("hello", "capture_reply"), or "none"/"unknown" for logs and errors.
std::string BodyName(const wire::Envelope& envelope);

}  // namespace sandtable::proto
