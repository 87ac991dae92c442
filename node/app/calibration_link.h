// What the two sides of a node's self-calibration (calibration_unit.h, calibration_runner.h)
// share through the service that owns them (self_calibration_service.h). Internal to node/app.
#pragma once

#include <cstdint>
#include <memory>

#include "cluster/report_lines.h"
#include "common/base/ids.h"
#include "common/io/mpcdi.h"
#include "node/net/node_runtime.h"
#include "proto/envelope.pb.h"

namespace sandtable::node {

// The way out: to a peer over its socket, or at once to this node's own side (the runner
// talking to its own unit).
class CalibrationLink {
 public:
  virtual ~CalibrationLink() = default;
  // False when the message could not be queued (the peer is not linked).
  virtual bool Send(NodeId to, wire::Envelope envelope, NodeRuntime& node) = 0;
  // The runner's progress through a round, for the node's report lines (dropped by default).
  virtual void Progress(const report::RoundProgress& progress) { (void)progress; }
};

// This node's figures over both sides, reported with its calibration.
struct CalibrationLedger {
  double compute_s = 0.0;  // thread CPU time of its steps and, on the runner, the solve
  uint64_t messages_sent = 0, messages_received = 0;
  uint64_t bytes_sent = 0, bytes_received = 0;
  // The runner's site as MPCDI, of the last round it solved (null elsewhere).
  std::shared_ptr<const MpcdiSite> site_mpcdi;
};

}  // namespace sandtable::node
