// UnitStatusService: tells the coordinator what its operator console shows of this unit
// (wire::UnitStatus, proto/membership.proto): its calibration state, the footprint of its
// projector on the table, its predicted registration error, its show's frame time and test
// pattern, whether it blends, and the last thing that went wrong. Fed from the node's report
// lines (any thread) and its calibration; sent on the network thread when it changed (at most
// every kMinSendPeriod) and every kRefreshPeriod, and again on every registration.
#pragma once

#include <chrono>
#include <functional>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "cluster/report_lines.h"
#include "common/io/unit_calibration_file.h"
#include "node/net/node_service.h"
#include "proto/membership.pb.h"

namespace sandtable::node {

inline constexpr std::chrono::milliseconds kMinSendPeriod{200};
inline constexpr std::chrono::milliseconds kRefreshPeriod{2000};
class UnitStatusService : public NodeService {
 public:
  explicit UnitStatusService(std::string host_name);
  const char* name() const override { return "unit_status"; }

  // Any thread.
  void OnLine(const report::ReportLine& line);
  void SetCalibration(const UnitCalibration& calibration,
                      const std::optional<std::set<NodeId>>& overlapping);
  // Something that keeps the unit from doing its job: its phase in words and why.
  void SetProblem(const std::string& phase, const std::string& why);
  // Asked on the network thread at every step: true while a round calibrates this unit again
  // (its phase says "calibrating" until the round's result, then what it was).
  void SetCalibratingProbe(std::function<bool()> probe);

  void OnRegistered(NodeRuntime& node) override;
  Status OnStep(NodeRuntime& node) override;

  wire::UnitStatus Snapshot() const;

 private:
  mutable std::mutex mutex_;
  wire::UnitStatus status_;
  bool dirty_ = true;
  std::function<bool()> calibrating_;  // network thread only
  std::string phase_before_round_;     // the phase a round's "calibrating" stands in for
  std::chrono::steady_clock::time_point last_sent_{};
};

}  // namespace sandtable::node
