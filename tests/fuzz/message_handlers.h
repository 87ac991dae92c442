// The message handlers under fuzzing: everything a process does with an untrusted message
// (decode, sequence order, membership, time sync, wire -> domain conversions). Shared by the
// libFuzzer target (fuzz_message_handlers.cc, clang only) and the corpus replay GoogleTest
// (corpus_replay_test.cc, any compiler). Aborts only on a broken invariant of our own.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "coordinator/membership/membership_table.h"
#include "node/net/clock_offset_estimator.h"
#include "proto/codec.h"
#include "proto/convert.h"
#include "proto/sequence_tracker.h"

namespace sandtable::fuzz {

struct HandlerState {
  proto::MessageCounters counters;
  proto::SequenceTracker tracker;
  coordinator::MembershipTable members{coordinator::MembershipOptions{}};
  node::ClockOffsetEstimator clock;
};

// Returns true when the message was accepted by the codec.
inline bool HandleUntrustedMessage(const uint8_t* data, size_t size, HandlerState* state) {
  proto::CodecLimits limits;
  limits.max_message_bytes = size_t{1} << 20;  // keep fuzzing iterations small
  limits.max_body_bytes = size_t{4} << 20;
  Expected<wire::Envelope> decoded = proto::DecodeEnvelope(
      std::string_view(reinterpret_cast<const char*>(data), size), limits, &state->counters);
  if (!decoded.ok()) return false;
  const wire::Envelope& e = *decoded;
  if (!state->tracker.Accept(e, &state->counters).ok()) return true;
  const auto now = coordinator::Clock::now();
  switch (e.body_case()) {
    case wire::Envelope::kHello:
      if (coordinator::CheckHello(e.hello()).ok()) {
        state->members.OnHello(e.sender_id(), e.hello(), "fuzz", now, nullptr);
      }
      break;
    case wire::Envelope::kHeartbeat:
      state->members.OnHeartbeat(e.sender_id(), e.heartbeat().incarnation(), "fuzz", now);
      break;
    case wire::Envelope::kGoodbye:
      state->members.OnGoodbye(e.sender_id(), e.sender_incarnation(), "fuzz");
      break;
    case wire::Envelope::kTimeReply:
      state->clock.AddSample(e.time_reply().t0_client_send_ns(),
                             e.time_reply().t1_server_receive_ns(),
                             e.time_reply().t2_server_send_ns(), e.send_time_ns());
      (void)state->clock.Estimate();
      break;
    case wire::Envelope::kTrackerPose:
      (void)proto::FromWire(e.tracker_pose().table_from_sensor());
      break;
    case wire::Envelope::kCalibrationResult:
      (void)proto::FromWire(e.calibration_result().projector_model());
      (void)proto::FromWire(e.calibration_result().projector_from_table());
      (void)proto::FromWire(e.calibration_result().camera_model());
      (void)proto::FromWire(e.calibration_result().camera_from_table());
      (void)proto::FromWire(e.calibration_result().table_from_model());
      break;
    case wire::Envelope::kCorrespondenceSet:
      (void)proto::FromWire(e.correspondence_set().camera_model());
      break;
    case wire::Envelope::kCalibrationInput:
      (void)proto::FromWire(e.calibration_input().camera_model());
      (void)proto::FromWire(e.calibration_input().projector_model());
      (void)proto::FromWire(e.calibration_input().projector_from_camera());
      for (const wire::RelativePose& r : e.calibration_input().relative_poses()) {
        (void)proto::FromWire(r.camera_from_projector());
      }
      for (const wire::CorrespondenceSet& c : e.calibration_input().correspondences()) {
        (void)proto::FromWire(c.camera_model());
      }
      break;
    case wire::Envelope::kCursor:
      (void)proto::FromWire(e.cursor().hit_in_table_m());
      break;
    default:
      break;
  }
  (void)state->members.ExpireSilent(now);
  (void)state->members.ToWire();
  // Property: what we accepted we can send again, and it decodes to the same message.
  proto::CodecLimits relaxed = limits;
  relaxed.max_message_bytes = size_t{64} << 20;
  Expected<std::string> again = proto::EncodeEnvelope(e, relaxed);
  ST_CHECK(again.ok()) << "accepted message does not re-encode: " << again.status().ToString();
  Expected<wire::Envelope> twice = proto::DecodeEnvelope(*again, relaxed);
  ST_CHECK(twice.ok()) << "re-encoded message does not decode: " << twice.status().ToString();
  return true;
}

}  // namespace sandtable::fuzz
