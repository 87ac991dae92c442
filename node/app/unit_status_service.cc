#include "node/app/unit_status_service.h"

#include <cmath>

#include "common/estimation/footprint.h"
#include "node/net/node_runtime.h"

namespace sandtable::node {
namespace {

std::string Clip(const std::string& text) {
  constexpr size_t kMax = 256;  // the coordinator's kMaxStatusTextChars
  return text.size() <= kMax ? text : text.substr(0, kMax - 3) + "...";
}

}  // namespace

UnitStatusService::UnitStatusService(std::string host_name) {
  status_.set_host_name(Clip(host_name).substr(0, 64));
  status_.set_phase("starting");
}

void UnitStatusService::OnLine(const report::ReportLine& line) {
  std::lock_guard<std::mutex> lock(mutex_);
  const wire::UnitStatus before = status_;
  std::visit(report::Overloaded{
                 [&](const report::Calibrated& c) {
                   phase_before_round_.clear();
                   status_.set_phase(c.verified ? "verified" : "calibrated");
                   status_.set_round(c.round);
                 },
                 [&](const report::CalibrationFailed& f) {
                   phase_before_round_.clear();
                   status_.set_phase("failed");
                   status_.set_last_error(Clip("calibration failed: " + f.reason));
                 },
                 [&](const report::Verification& v) {
                   if (!v.holds) status_.set_last_error(Clip("saved calibration: " + v.reason));
                 },
                 [&](const report::RenderUnavailable& r) {
                   status_.set_last_error(Clip("no show: " + r.reason));
                 },
                 [&](const report::RenderPattern& p) { status_.set_pattern(Clip(p.pattern)); },
                 [&](const report::RenderSummary& r) {
                   status_.set_frame_ms_p50(r.frame_ms_p50);
                   status_.set_frame_ms_p99(r.frame_ms_p99);
                 },
                 [&](const report::BlendShown& b) {
                   status_.set_blended(true);
                   status_.clear_neighbours();
                   for (NodeId n : b.neighbours) status_.add_neighbours(n);
                 },
                 [](const auto&) {},
             },
             line);
  // Frame times change every summary; only a change of what the operator reads marks it.
  wire::UnitStatus a = before, b = status_;
  for (wire::UnitStatus* s : {&a, &b}) {
    s->clear_frame_ms_p50();
    s->clear_frame_ms_p99();
  }
  if (a.SerializeAsString() != b.SerializeAsString()) dirty_ = true;
}

void UnitStatusService::SetCalibration(const UnitCalibration& calibration,
                                       const std::optional<std::set<NodeId>>& overlapping) {
  std::lock_guard<std::mutex> lock(mutex_);
  status_.clear_footprint_m();
  if (calibration.table_from_projector) {
    for (const Eigen::Vector2d& p :
         TableFootprint(calibration.projector, *calibration.table_from_projector)) {
      wire::Vector2* out = status_.add_footprint_m();
      out->set_x(p.x());
      out->set_y(p.y());
    }
  }
  status_.set_projector_rms_px(calibration.projector_rms_px);
  const double predicted = calibration.predicted_error ? calibration.predicted_error->rms_mm : -1.0;
  status_.set_predicted_rms_mm(predicted > 0.0 && std::isfinite(predicted) ? predicted : 0.0);
  if (overlapping) {
    status_.clear_neighbours();
    for (NodeId n : *overlapping) status_.add_neighbours(n);
  }
  dirty_ = true;
}

void UnitStatusService::SetCalibratingProbe(std::function<bool()> probe) {
  std::lock_guard<std::mutex> lock(mutex_);
  calibrating_ = std::move(probe);
}

void UnitStatusService::SetProblem(const std::string& phase, const std::string& why) {
  std::lock_guard<std::mutex> lock(mutex_);
  status_.set_phase(Clip(phase));
  status_.set_last_error(Clip(why));
  dirty_ = true;
}

void UnitStatusService::OnRegistered(NodeRuntime&) {
  std::lock_guard<std::mutex> lock(mutex_);
  dirty_ = true;
}

Status UnitStatusService::OnStep(NodeRuntime& node) {
  if (!node.registered()) return OkStatus();
  const auto now = std::chrono::steady_clock::now();
  wire::Envelope envelope;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const bool round = calibrating_ && calibrating_();
    const std::string& phase = status_.phase();
    if (round && (phase == "calibrated" || phase == "verified")) {
      phase_before_round_ = phase;
      status_.set_phase("calibrating");
      dirty_ = true;
    } else if (!round && phase == "calibrating" && !phase_before_round_.empty()) {
      status_.set_phase(phase_before_round_);  // the round ended without a result for it
      phase_before_round_.clear();
      dirty_ = true;
    }
    if (status_.calibration_state() != node.calibration_state()) {
      status_.set_calibration_state(node.calibration_state());
      if (node.calibration_state() == wire::CALIBRATION_STATE_NONE &&
          status_.phase() == "starting") {
        status_.set_phase("calibrating");
      }
      dirty_ = true;
    }
    const auto since = now - last_sent_;
    if (!(dirty_ && since >= kMinSendPeriod) && since < kRefreshPeriod) return OkStatus();
    *envelope.mutable_unit_status() = status_;
    dirty_ = false;
    last_sent_ = now;
  }
  Status sent = node.SendToCoordinator(std::move(envelope));
  if (!sent.ok()) {
    std::lock_guard<std::mutex> lock(mutex_);
    dirty_ = true;  // again at the next step
  }
  return OkStatus();
}

wire::UnitStatus UnitStatusService::Snapshot() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return status_;
}

}  // namespace sandtable::node
