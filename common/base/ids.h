// Typed ids of Sandtable, each with an invalid sentinel.
#pragma once

#include <cstdint>
#include <limits>

namespace sandtable {

// A projector unit (projector + camera + computer); one sandtable-node process each.
using NodeId = uint32_t;
constexpr NodeId kInvalidNodeId = std::numeric_limits<NodeId>::max();

// Sender ids reserved on the wire for the site's services (every Envelope names its sender).
// A node's id must be below kFirstReservedSenderId: a node refuses an id that collides.
constexpr uint32_t kFirstReservedSenderId = 0xFFFFFFF0u;
constexpr uint32_t kCoordinatorSenderId = 0xFFFFFFF0u;
constexpr uint32_t kWorldSenderId = 0xFFFFFFF1u;
constexpr uint32_t kLabSenderId = 0xFFFFFFF2u;
constexpr uint32_t kLabPainterSenderId = 0xFFFFFFF3u;  // the lab's annotation client (chaos)
constexpr uint32_t kOperatorSenderId = 0xFFFFFFF4u;    // an operator's command (enrollment)
constexpr uint32_t kConsoleSenderId = 0xFFFFFFF5u;     // the coordinator's browser console
constexpr bool IsValidNodeId(NodeId id) { return id < kFirstReservedSenderId; }

// A projector within a site; today equal to its unit's NodeId.
using ProjectorId = uint32_t;
constexpr ProjectorId kInvalidProjectorId = std::numeric_limits<ProjectorId>::max();

// A camera within a site; today equal to its unit's NodeId.
using CameraId = uint32_t;
constexpr CameraId kInvalidCameraId = std::numeric_limits<CameraId>::max();

// An annotation stroke, sequence numbers of events.
using StrokeId = uint64_t;
constexpr StrokeId kInvalidStrokeId = std::numeric_limits<StrokeId>::max();
using SequenceNumber = uint64_t;
constexpr SequenceNumber kInvalidSequenceNumber = std::numeric_limits<SequenceNumber>::max();

}  // namespace sandtable
