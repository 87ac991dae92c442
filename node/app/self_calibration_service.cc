#include "node/app/self_calibration_service.h"

#include "node/calibration/projector_response.h"

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "node/app/calibration_runner.h"
#include "node/app/calibration_service.h"
#include "node/app/calibration_unit.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/display_frames.h"
#include "node/calibration/projector_response.h"
#include "proto/convert.h"

namespace sandtable::node {

PatternOptions PatternOptionsFromWire(const wire::PatternPlan& plan) {
  PatternOptions p;
  p.projector_width_px = static_cast<int>(plan.projector_width_px());
  p.projector_height_px = static_cast<int>(plan.projector_height_px());
  p.gray_lsb_skip = static_cast<int>(plan.gray_lsb_skip());
  p.phase_steps = static_cast<int>(plan.phase_steps());
  p.phase_period_px = plan.phase_period_px();
  return p;
}

wire::PatternPlan PatternPlanToWire(const PatternOptions& p) {
  wire::PatternPlan plan;
  plan.set_projector_width_px(static_cast<uint32_t>(p.projector_width_px));
  plan.set_projector_height_px(static_cast<uint32_t>(p.projector_height_px));
  plan.set_gray_lsb_skip(static_cast<uint32_t>(p.gray_lsb_skip));
  plan.set_phase_steps(static_cast<uint32_t>(p.phase_steps));
  plan.set_phase_period_px(p.phase_period_px);
  plan.set_frames(static_cast<uint32_t>(MakePatternLayout(p).frame_count));
  return plan;
}

std::vector<ProjectorGridPoint> GridPointsFromWire(const wire::CorrespondenceSet& set) {
  std::vector<ProjectorGridPoint> points;
  if (set.camera_px_xy_size() != set.projector_px_xy_size()) return points;
  for (int i = 0; i + 1 < set.camera_px_xy_size(); i += 2) {
    ProjectorGridPoint p;
    p.camera_px = Eigen::Vector2f(set.camera_px_xy(i), set.camera_px_xy(i + 1));
    p.projector_px = Eigen::Vector2f(set.projector_px_xy(i), set.projector_px_xy(i + 1));
    if (p.camera_px.allFinite() && p.projector_px.allFinite()) points.push_back(p);
  }
  return points;
}

void GridPointsToWire(const std::vector<ProjectorGridPoint>& points, wire::CorrespondenceSet* set) {
  for (const ProjectorGridPoint& p : points) {
    set->add_camera_px_xy(p.camera_px.x());
    set->add_camera_px_xy(p.camera_px.y());
    set->add_projector_px_xy(p.projector_px.x());
    set->add_projector_px_xy(p.projector_px.y());
  }
}

Expected<report::Calibrated> ExportSelfCalibration(const SelfCalibrationOutcome& outcome, NodeId id,
                                                   const std::string& export_dir) {
  Expected<ExportedCalibration> exported = ExportCalibration(outcome.calibration, export_dir);
  if (!exported.ok()) return exported.status();
  // The round's report under `name`; "" when it cannot be written (logged).
  auto write_report = [&](const std::string& name) {
    const std::string path = export_dir + "/" + name;
    if (Status written = WriteFileAtomically(path, outcome.report.dump(2) + "\n"); !written.ok()) {
      ST_LOG(kError) << "cannot write " << name << ": " << written.ToString();
      return std::string();
    }
    return path;
  };
  const std::string report_path = outcome.report.value("runner", kInvalidNodeId) == id
                                      ? write_report("self_calibration_report.json")
                                      : std::string();
  // A unit that joined a calibrated site keeps its join round's report.
  const std::string join_report_path =
      outcome.report.value("path", std::string()) == "join"
          ? write_report("join_report-unit-" + std::to_string(id) + ".json")
          : std::string();
  std::string mpcdi_path;
  if (outcome.site_mpcdi) {
    mpcdi_path = export_dir + "/site.mpcdi";
    if (Status written = WriteMpcdi(mpcdi_path, *outcome.site_mpcdi); !written.ok()) {
      ST_LOG(kError) << "cannot write the MPCDI export: " << written.ToString();
      mpcdi_path.clear();
    }
  }
  report::Calibrated line;
  line.id = id;
  line.source = outcome.calibration.source;
  line.json = exported->json_path;
  line.yaml = exported->yaml_path;
  line.report = report_path;
  line.mpcdi = mpcdi_path;
  line.join_report = join_report_path;
  line.round = outcome.round;
  line.verified = outcome.verified;
  line.compute_s = outcome.compute_s;
  line.messages_sent = outcome.messages_sent;
  line.messages_received = outcome.messages_received;
  line.bytes_sent = outcome.bytes_sent;
  line.bytes_received = outcome.bytes_received;
  line.capture_latency_ms = outcome.capture.latency_s < 0 ? -1.0 : outcome.capture.latency_s * 1e3;
  line.capture_settle_ms = outcome.capture.settle_s * 1e3;
  line.captures = outcome.capture.captures;
  line.captures_stale = outcome.capture.stale;
  line.captures_repeated = outcome.capture.repeated;
  return line;
}

SelfCalibrationService::SelfCalibrationService(UnitCalibration factory, ProjectorOutput* projector,
                                               std::shared_ptr<const Scene> model,
                                               SelfCalibrationOptions options,
                                               OnCalibrated on_calibrated, OnFailed on_failed)
    : options_(std::move(options)),
      unit_(std::make_unique<CalibrationUnit>(std::move(factory), projector, model, options_,
                                              static_cast<CalibrationLink*>(this), &ledger_,
                                              std::move(on_calibrated), std::move(on_failed))),
      runner_(std::make_unique<CalibrationRunner>(options_, std::move(model), *unit_,
                                                  static_cast<CalibrationLink*>(this), &ledger_)) {}

SelfCalibrationService::~SelfCalibrationService() = default;

void SelfCalibrationService::SetCamera(std::unique_ptr<CameraInput> camera) {
  unit_->SetCamera(std::move(camera));
}

void SelfCalibrationService::SetRenderLoop(RenderLoop* loop) { unit_->SetRenderLoop(loop); }

void SelfCalibrationService::SetSavedCalibration(UnitCalibration saved,
                                                 OnVerification on_verification) {
  unit_->SetSavedCalibration(std::move(saved), std::move(on_verification));
}

bool SelfCalibrationService::calibrated() const { return unit_->calibrated(); }

bool SelfCalibrationService::being_calibrated() const { return unit_->being_calibrated(); }

bool SelfCalibrationService::ServesPeer(wire::Envelope::BodyCase body) const {
  switch (body) {
    case wire::Envelope::kCalibrationStep:
    case wire::Envelope::kCalibrationStepDone:
    case wire::Envelope::kCorrespondenceSet:
    case wire::Envelope::kCalibrationInput:
    case wire::Envelope::kCalibrationResult:
      return true;
    default:
      return false;
  }
}

bool SelfCalibrationService::ServesCoordinator(wire::Envelope::BodyCase body) const {
  return body == wire::Envelope::kRecalibrateAsk;
}

void SelfCalibrationService::OnCoordinatorMessage(const wire::Envelope& message,
                                                  NodeRuntime& /*node*/) {
  if (message.body_case() == wire::Envelope::kRecalibrateAsk) {
    runner_->OnAsk(message.recalibrate_ask());
  }
}

bool SelfCalibrationService::Send(NodeId to, wire::Envelope envelope, NodeRuntime& node) {
  if (to == node.id()) {  // the runner talking to itself: no socket
    Deliver(to, envelope, node);
    return true;
  }
  ++ledger_.messages_sent;
  ledger_.bytes_sent += envelope.ByteSizeLong();
  if (Status sent = node.SendToPeer(to, std::move(envelope)); !sent.ok()) {
    ST_LOG(kWarning) << "self-calibration: to node " << to << ": " << sent.ToString();
    return false;
  }
  return true;
}

void SelfCalibrationService::OnPeerMessage(net::Incoming request, NodeRuntime& node) {
  ++ledger_.messages_received;
  ledger_.bytes_received += request.envelope.ByteSizeLong();
  Deliver(request.envelope.sender_id(), request.envelope, node);
}

void SelfCalibrationService::Deliver(NodeId from, const wire::Envelope& e, NodeRuntime& node) {
  switch (e.body_case()) {
    case wire::Envelope::kCalibrationStep:
      unit_->HandleStep(e.calibration_step(), from, node);
      break;
    case wire::Envelope::kCalibrationStepDone:
      runner_->HandleDone(from, e.calibration_step_done(), node);
      break;
    case wire::Envelope::kCorrespondenceSet:
      unit_->HandleCorrespondences(e.correspondence_set());
      break;
    case wire::Envelope::kCalibrationInput:
      runner_->HandleInput(from, e.calibration_input(), node);
      break;
    case wire::Envelope::kCalibrationResult:
      unit_->HandleResult(e.calibration_result(), from, node);
      break;
    default:
      break;
  }
}

Status SelfCalibrationService::OnStep(NodeRuntime& node) {
  unit_->OnStep(node);
  runner_->OnStep(node);
  return OkStatus();
}

Status SelfCalibrationOptions::Check() const {
  ST_RETURN_IF_ERROR(plan.Check());
  ST_RETURN_IF_ERROR(solve.Check());
  ST_RETURN_IF_ERROR(check.Check());
  ST_RETURN_IF_ERROR(planar.Check());
  if (settle.count() < 0 || expect_wait.count() < 0 || join_wait.count() < 0 ||
      step_timeout.count() <= 0 || member_grace.count() < 0 || step_retry.count() <= 0) {
    return InvalidArgumentError(
        "self-calibration: settle, expect_wait, join_wait, member_grace >= 0; step_timeout, "
        "step_retry > 0");
  }
  if (expected_units < 0 || !(frame_period_s > 0.0) || !(capture_latency_s >= 0.0) ||
      !(neighbour_resolution_factor >= 1.0) || grid_step_px < 1 || lit_threshold < 1 ||
      lit_threshold > 255 || min_lit_pixels < 1 || mask_margin_px < 0 || min_overlap_pixels < 0) {
    return InvalidArgumentError(
        "self-calibration: expected_units >= 0; frame period > 0; capture latency >= 0; "
        "neighbour_resolution_factor >= 1; grid step, lit pixels >= 1; lit_threshold 1-255; "
        "margins and overlaps >= 0");
  }
  for (int level : response_levels) {
    if (level < 1 || level > 254) {
      return InvalidArgumentError("self-calibration: response_levels must be in 1..254");
    }
  }
  return OkStatus();
}

RoundPolicyOptions SelfCalibrationOptions::RoundPolicy() const {
  RoundPolicyOptions o;
  o.settle = settle;
  o.join_wait = join_wait;
  o.expected_units = expected_units;
  o.expect_wait = expect_wait;
  return o;
}

}  // namespace sandtable::node
