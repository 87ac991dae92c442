#include "proto/codec.h"

#include <utility>

#include "common/base/log.h"
#include "proto/compression.h"

#include <google/protobuf/stubs/logging.h>

namespace sandtable::proto {
namespace {

// Moves the header (everything but the body and compression fields) from one envelope to
// another, so the body can be serialized on its own.
void CopyHeader(const wire::Envelope& from, wire::Envelope* to) {
  to->set_protocol_version(from.protocol_version());
  to->set_sender_id(from.sender_id());
  to->set_sequence(from.sequence());
  to->set_send_time_ns(from.send_time_ns());
  to->set_sender_incarnation(from.sender_incarnation());
}

void ClearHeader(wire::Envelope* envelope) {
  envelope->clear_protocol_version();
  envelope->clear_sender_id();
  envelope->clear_sequence();
  envelope->clear_send_time_ns();
  envelope->clear_sender_incarnation();
}

bool HasHeaderOrCompression(const wire::Envelope& e) {
  return e.protocol_version() != 0 || e.sender_id() != 0 || e.sequence() != 0 ||
         e.send_time_ns() != 0 || e.sender_incarnation() != 0 ||
         e.compression() != wire::COMPRESSION_NONE || e.body_size_bytes() != 0 ||
         !e.compressed_body().empty();
}

// libprotobuf logs every invalid UTF-8 string it parses at ERROR level: a peer could flood
// our logs. Rejections are already counted and returned as Status, so its messages go to
// debug level.
void ProtobufLogToDebug(google::protobuf::LogLevel, const char* file, int line,
                        const std::string& message) {
  ST_LOG(kDebug) << "libprotobuf " << file << ":" << line << ": " << message;
}

void RouteProtobufLogsOnce() {
  static const bool installed = [] {
    google::protobuf::SetLogHandler(&ProtobufLogToDebug);
    return true;
  }();
  (void)installed;
}

Status Reject(MessageCounters* counters, RejectReason reason, Status status) {
  if (counters != nullptr) counters->CountRejected(reason);
  return status;
}

}  // namespace

Status CodecLimits::Check() const {
  if (max_message_bytes < 64) {
    return InvalidArgumentError("codec: max_message_bytes = " + std::to_string(max_message_bytes) +
                                " is too small for any envelope (>= 64)");
  }
  if (max_body_bytes < 64) {
    return InvalidArgumentError("codec: max_body_bytes = " + std::to_string(max_body_bytes) +
                                " must be >= 64");
  }
  if (!(min_saved_fraction >= 0.0 && min_saved_fraction < 1.0)) {
    return InvalidArgumentError("codec: min_saved_fraction must be in [0, 1)");
  }
  if (zlib_level < 1 || zlib_level > 9) {
    return InvalidArgumentError("codec: zlib_level = " + std::to_string(zlib_level) +
                                " must be in 1..9");
  }
  return OkStatus();
}

std::string BodyName(const wire::Envelope& envelope) {
  if (envelope.body_case() == wire::Envelope::BODY_NOT_SET) {
    return envelope.GetReflection()->GetUnknownFields(envelope).empty() ? "none" : "unknown";
  }
  const auto* field =
      wire::Envelope::descriptor()->FindFieldByNumber(static_cast<int>(envelope.body_case()));
  return field != nullptr ? field->name() : "unknown";
}

Expected<std::string> EncodeEnvelope(wire::Envelope envelope, const CodecLimits& limits,
                                     EncodeInfo* info) {
  if (envelope.body_case() == wire::Envelope::BODY_NOT_SET) {
    return InvalidArgumentError("codec: envelope without a body; set one of its bodies");
  }
  EncodeInfo local;
  std::string wire_bytes;
  const size_t total = envelope.ByteSizeLong();
  if (total >= limits.compress_threshold_bytes) {
    wire::Envelope header;
    CopyHeader(envelope, &header);
    ClearHeader(&envelope);
    std::string body = envelope.SerializeAsString();
    local.body_bytes = body.size();
    std::string compressed = ZlibCompress(body, limits.zlib_level);
    if (static_cast<double>(compressed.size()) <=
        (1.0 - limits.min_saved_fraction) * static_cast<double>(body.size())) {
      header.set_compression(wire::COMPRESSION_ZLIB);
      header.set_body_size_bytes(static_cast<uint32_t>(body.size()));
      header.set_compressed_body(std::move(compressed));
      wire_bytes = header.SerializeAsString();
      local.compressed = true;
    } else {
      CopyHeader(header, &envelope);
      wire_bytes = envelope.SerializeAsString();
    }
  } else {
    local.body_bytes = total;
    wire_bytes = envelope.SerializeAsString();
  }
  local.wire_bytes = wire_bytes.size();
  if (info != nullptr) *info = local;
  if (wire_bytes.size() > limits.max_message_bytes) {
    return InvalidArgumentError(
        "codec: message of " + std::to_string(wire_bytes.size()) +
        " bytes exceeds max_message_bytes = " + std::to_string(limits.max_message_bytes) +
        "; split the payload or raise the limit on both sides");
  }
  return wire_bytes;
}

Expected<wire::Envelope> DecodeEnvelope(std::string_view bytes, const CodecLimits& limits,
                                        MessageCounters* counters) {
  RouteProtobufLogsOnce();
  if (bytes.size() > limits.max_message_bytes) {
    return Reject(counters, RejectReason::kOversized,
                  ParseError("message of " + std::to_string(bytes.size()) +
                             " bytes exceeds max_message_bytes = " +
                             std::to_string(limits.max_message_bytes)));
  }
  wire::Envelope envelope;
  if (!envelope.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return Reject(counters, RejectReason::kMalformed,
                  ParseError("message of " + std::to_string(bytes.size()) +
                             " bytes is not a valid Envelope (truncated or corrupt)"));
  }
  if (envelope.protocol_version() != kProtocolVersion) {
    return Reject(
        counters, RejectReason::kWrongVersion,
        ParseError("protocol_version " + std::to_string(envelope.protocol_version()) +
                   " from sender " + std::to_string(envelope.sender_id()) + ", this build speaks " +
                   std::to_string(kProtocolVersion) + "; run the same release on every machine"));
  }
  if (envelope.sequence() == 0) {
    return Reject(counters, RejectReason::kMalformed,
                  ParseError("envelope from sender " + std::to_string(envelope.sender_id()) +
                             " has no sequence number (required, starts at 1)"));
  }
  switch (envelope.compression()) {
    case wire::COMPRESSION_NONE:
      if (envelope.body_size_bytes() != 0 || !envelope.compressed_body().empty()) {
        return Reject(counters, RejectReason::kBadCompression,
                      ParseError("uncompressed envelope carries a compressed body"));
      }
      break;
    case wire::COMPRESSION_ZLIB: {
      if (envelope.body_case() != wire::Envelope::BODY_NOT_SET) {
        return Reject(counters, RejectReason::kBadCompression,
                      ParseError("compressed envelope also carries a plain body"));
      }
      const size_t body_size = envelope.body_size_bytes();
      if (body_size == 0 || body_size > limits.max_body_bytes) {
        return Reject(counters, RejectReason::kOversized,
                      ParseError("compressed body announces " + std::to_string(body_size) +
                                 " bytes; allowed 1.." + std::to_string(limits.max_body_bytes)));
      }
      Expected<std::string> body = ZlibDecompress(envelope.compressed_body(), body_size);
      if (!body.ok()) {
        return Reject(counters, RejectReason::kBadCompression, body.status());
      }
      wire::Envelope inner;
      if (!inner.ParseFromString(*body)) {
        return Reject(counters, RejectReason::kMalformed,
                      ParseError("compressed body is not a valid Envelope body"));
      }
      if (HasHeaderOrCompression(inner)) {
        return Reject(counters, RejectReason::kMalformed,
                      ParseError("compressed body carries header or nested compression fields"));
      }
      CopyHeader(envelope, &inner);
      envelope = std::move(inner);
      break;
    }
    default:
      return Reject(counters, RejectReason::kBadCompression,
                    ParseError("unknown compression " + std::to_string(envelope.compression())));
  }
  if (envelope.body_case() == wire::Envelope::BODY_NOT_SET) {
    if (!envelope.GetReflection()->GetUnknownFields(envelope).empty()) {
      return Reject(counters, RejectReason::kUnknownType,
                    ParseError("envelope from sender " + std::to_string(envelope.sender_id()) +
                               " carries a body type this build does not know"));
    }
    return Reject(counters, RejectReason::kEmptyBody,
                  ParseError("envelope from sender " + std::to_string(envelope.sender_id()) +
                             " has no body"));
  }
  return envelope;
}

}  // namespace sandtable::proto
