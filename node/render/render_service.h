// RenderService: the node's show (docs/render.md), a NodeService that feeds the render loop
// what the coordinator publishes. Every step it hands the loop the operator's test pattern for
// this node, the annotation strokes (rebuilt when their sequence moves), the wand's cursor, the
// and the timeline clock converted with the node's clock
// offset. (The tracks themselves are draped and drawn by the loop, render_loop.h.) It prints a JSON
// line (cluster/report_lines.h) each time a new test pattern is first shown,
// {"render":ID,"pattern":"grid"}, and a summary every summary_period:
//   {"render":ID,"frames":N,"frame_ms_p50":..,"frame_ms_p99":..,"floor_ms":..,"show_ms_p50":..,
//    "failed":N,"passes":{"shadow":N,...},"context":"..."}
// Network thread only (the loop has its own thread).
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "cluster/report_lines.h"

#include "cluster/personnel_tracks.h"
#include "node/events/event_state_service.h"
#include "node/net/node_service.h"
#include "node/render/render_loop.h"

namespace sandtable::node {

struct RenderServiceOptions {
  SunOptions sun;
  std::chrono::milliseconds summary_period{2000};
  Status Check() const;
};

class RenderService : public NodeService {
 public:
  // `events`, `loop` outlive the service. `print` writes one JSON line (stdout in the program).
  RenderService(const EventStateService* events, RenderLoop* loop, RenderServiceOptions options,
                std::function<void(const report::ReportLine&)> print);

  const char* name() const override { return "render"; }
  Status OnStep(NodeRuntime& node) override;

  report::RenderSummary Summary(NodeId id) const;

 private:
  const EventStateService* events_;
  RenderLoop* loop_;
  RenderServiceOptions options_;
  std::function<void(const report::ReportLine&)> print_;

  ShowInputs inputs_;
  bool inputs_sent_ = false;
  SequenceNumber strokes_sequence_ = kInvalidSequenceNumber;
  std::string announced_pattern_;
  std::chrono::steady_clock::time_point last_summary_{};
};

}  // namespace sandtable::node
