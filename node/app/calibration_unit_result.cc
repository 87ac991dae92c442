// The unit's calibration (calibration_unit.h): a saved one checked, a round's result taken,
// the calibration it holds shown.
#include <algorithm>

#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "node/app/calibration_unit.h"
#include "node/calibration/display_frames.h"
#include "proto/convert.h"

namespace sandtable::node {

CalibrationUnit::CalibrationUnit(UnitCalibration factory, ProjectorOutput* projector,
                                 std::shared_ptr<const Scene> model,
                                 const SelfCalibrationOptions& options, CalibrationLink* link,
                                 CalibrationLedger* ledger,
                                 SelfCalibrationService::OnCalibrated on_calibrated,
                                 SelfCalibrationService::OnFailed on_failed)
    : factory_(std::move(factory)),
      projector_(projector),
      model_(std::move(model)),
      options_(options),
      link_(link),
      ledger_(ledger),
      on_calibrated_(std::move(on_calibrated)),
      on_failed_(std::move(on_failed)) {}

void CalibrationUnit::SetSavedCalibration(UnitCalibration saved,
                                          SelfCalibrationService::OnVerification on_verification) {
  saved_ = std::move(saved);
  on_verification_ = std::move(on_verification);
}

void CalibrationUnit::OnStep(NodeRuntime& node) {
  RunDeferred(node);
  MaybeVerify(node);
}

SelfCalibrationOutcome CalibrationUnit::Outcome(const UnitCalibration& calibration) const {
  SelfCalibrationOutcome outcome;
  outcome.calibration = calibration;
  outcome.report = nlohmann::json::object();
  outcome.compute_s = ledger_->compute_s;
  outcome.messages_sent = ledger_->messages_sent;
  outcome.messages_received = ledger_->messages_received;
  outcome.bytes_sent = ledger_->bytes_sent;
  outcome.bytes_received = ledger_->bytes_received;
  if (camera_) outcome.capture = camera_->stats();
  return outcome;
}

void CalibrationUnit::MaybeVerify(NodeRuntime& node) {
  if (!saved_ || verify_started_ || !camera_ || !projector_ || !node.registered()) return;
  if (round_ != 0) {  // a round reached this unit first: it calibrates with the others
    verify_started_ = true;
    node.set_calibration_state(wire::CALIBRATION_STATE_NONE);
    ST_LOG(kWarning) << "self-calibration: a round started before the saved calibration was "
                        "checked; calibrating with the others";
    return;
  }
  const std::optional<wire::MemberList>& list = node.member_list();
  if (!list) return;
  // One unit checks at a time (its dots would land in its neighbours' captures): on a member
  // list that has settled (a unit that registers late must not be missed), every member heard
  // from, none checking now, and of those still to check the lowest id first.
  if (node.member_list_age() < options_.settle) return;
  for (const wire::Member& m : list->members()) {
    if (m.node_id() == node.id() || !m.capabilities().has_projector()) continue;
    auto peer = node.peers().find(m.node_id());
    if (peer == node.peers().end() || peer->second.heartbeats_received == 0) return;
    const wire::CalibrationState state = peer->second.calibration_state;
    if (state == wire::CALIBRATION_STATE_VERIFYING) return;
    if (state == wire::CALIBRATION_STATE_SAVED && m.node_id() < node.id()) return;
  }
  verify_started_ = true;
  node.set_calibration_state(wire::CALIBRATION_STATE_VERIFYING);
  struct Checked {
    Expected<CalibrationCheckReport> report = CalibrationCheckReport{};
    int dots_planned = 0;
    double cpu_s = 0.0;
  };
  const UnitCalibration saved = *saved_;
  ProjectorOutput* projector = projector_;
  PacedCamera* camera = camera_.get();
  std::shared_ptr<const Scene> model = model_;
  const CalibrationCheckOptions check = options_.check;
  node.workers().Run<Checked>(
      [saved, projector, camera, model, check, loop = render_loop_] {
        Checked out;
        const double t0 = ThreadCpuSeconds();
        if (loop) loop->Suspend();  // the check's two frames take the projector
        Expected<CalibrationCheckPlan> plan = PlanCalibrationCheck(saved, model.get(), check);
        auto fail = [&](const Status& s) {
          out.report = s;
          out.cpu_s = ThreadCpuSeconds() - t0;
          return out;
        };
        if (!plan.ok()) return fail(plan.status());
        out.dots_planned = static_cast<int>(plan->dots.size());
        const cv::Mat black = cv::Mat::zeros(projector->size(), CV_8UC1);
        const int bits = camera->bit_depth();
        cv::Mat images[2];
        for (int i = 0; i < 2; ++i) {
          Expected<ShownFrame> shown = projector->Show(i == 0 ? black : plan->dots_frame);
          if (!shown.ok()) return fail(shown.status());
          Expected<CapturedFrame> frame = camera->CaptureAfter(shown->shown_time);
          if (!frame.ok()) return fail(frame.status());
          images[i] = To8Bit(frame->image, bits).clone();
        }
        Expected<ShownFrame> dark = projector->Show(black);
        if (!dark.ok()) return fail(dark.status());
        out.report = EvaluateCalibrationCheck(*plan, images[0], images[1], check);
        out.cpu_s = ThreadCpuSeconds() - t0;
        return out;
      },
      [this, &node](Checked c) {
        ledger_->compute_s += c.cpu_s;
        constexpr int kFrames = 2;  // the black reference and the dots
        report::Verification line;
        line.id = node.id();
        line.frames = kFrames;
        line.device_time_s = kFrames * (options_.frame_period_s + options_.capture_latency_s);
        line.compute_s = c.cpu_s;
        const bool holds = c.report.ok() && c.report->holds;
        line.holds = holds;
        if (c.report.ok()) {
          line.dots = c.report->dots;
          line.found = c.report->found;
          line.median_px = c.report->median_px;
          line.p90_px = c.report->p90_px;
          line.wall_dots = c.report->wall_dots;
          line.wall_median_px = c.report->wall_median_px;
          line.threshold_px = options_.check.threshold_px;
          if (!holds) line.reason = c.report->reason;
        } else {
          line.reason = c.report.status().message();
        }
        if (on_verification_) on_verification_(line);
        if (!holds) {
          ST_LOG(kWarning) << "self-calibration: the saved calibration does not hold ("
                           << line.reason << "); calibrating again";
          node.set_calibration_state(wire::CALIBRATION_STATE_NONE);
          return;
        }
        ST_LOG(kInfo) << "self-calibration: the saved calibration holds (p90 " << c.report->p90_px
                      << " px over " << c.report->found << " dots); no round";
        node.set_calibration_state(wire::CALIBRATION_STATE_VERIFIED);
        SelfCalibrationOutcome outcome = Outcome(*saved_);
        outcome.verified = true;
        StartDisplay(*saved_, node, [this, outcome] {
          if (on_calibrated_) on_calibrated_(outcome);
        });
      });
}

void CalibrationUnit::StartDisplay(const UnitCalibration& calibration, NodeRuntime& node,
                                   std::function<void()> then) {
  holding_ = calibration;
  if (!projector_) return then();
  if (render_loop_) {
    // The renderer shows the model registered with this calibration; reported once shown.
    RenderLoop* loop = render_loop_;
    node.workers().Run<Status>([loop, calibration] { return loop->ShowCalibration(calibration); },
                               [then = std::move(then)](Status shown) {
                                 if (!shown.ok()) {
                                   ST_LOG(kWarning)
                                       << "self-calibration: display: " << shown.message();
                                 }
                                 then();
                               });
    return;
  }
  Expected<cv::Mat> grid = TableGridFrame(calibration);
  if (!grid.ok() || grid->size() != projector_->size()) {
    ST_LOG(kWarning) << "self-calibration: no display frame: "
                     << (grid.ok() ? "size" : grid.status().message());
    return then();
  }
  display_ = *grid;
  ProjectorOutput* projector = projector_;
  const cv::Mat frame = display_;
  node.workers().Run<Status>(
      [projector, frame] {
        Expected<ShownFrame> shown = projector->Show(frame);
        return shown.ok() ? OkStatus() : shown.status();
      },
      [then = std::move(then)](Status shown) {
        if (!shown.ok()) ST_LOG(kWarning) << "self-calibration: display: " << shown.message();
        then();
      });
}

void CalibrationUnit::HandleResult(const wire::CalibrationResult& result, NodeId from,
                                   NodeRuntime& node) {
  if (result.projector_id() != node.id()) return;
  calibrated_by_ = from;
  projecting_ = false;
  if (!result.ok()) {
    ST_LOG(kError) << "self-calibration failed: " << result.message();
    if (on_failed_) on_failed_(result.message());
    return;
  }
  UnitCalibration c = factory_;
  c.unit_id = node.id();
  c.source = kSourceStructuredLight;
  Expected<CameraModel> projector = proto::FromWire(result.projector_model());
  Expected<CameraModel> camera = proto::FromWire(result.camera_model());
  Expected<Rigid3d> projector_from_table = proto::FromWire(result.projector_from_table());
  Expected<Rigid3d> camera_from_table = proto::FromWire(result.camera_from_table());
  if (!projector.ok() || !camera.ok() || !projector_from_table.ok() || !camera_from_table.ok()) {
    ST_LOG(kError) << "self-calibration: the runner's result does not convert";
    if (on_failed_) on_failed_("invalid result from the runner");
    return;
  }
  c.projector = *projector;
  c.camera = *camera;
  c.table_from_projector = projector_from_table->Inverse();
  c.projector_from_camera = *projector_from_table * camera_from_table->Inverse();
  c.projector_rms_px = result.reprojection_rms_px();
  c.camera_rms_px = result.camera_rms_px();
  c.projector_response = response_;
  if (result.has_predicted_error()) {
    const wire::PredictedError& w = result.predicted_error();
    PredictedErrorRecord p;
    p.rms_px = w.rms_px();
    p.rms_mm = w.rms_mm();
    p.samples = static_cast<int>(std::min<uint32_t>(w.samples(), 1u << 30));
    p.sigma_px = w.sigma_px();
    p.weak_direction = w.weak_direction();
    p.weak_share = w.weak_share();
    p.undetermined = w.undetermined();
    c.predicted_error = p;
  }
  if (result.has_table_from_model()) {
    Expected<Rigid3d> table_from_model = proto::FromWire(result.table_from_model());
    if (table_from_model.ok()) c.table_from_model = *table_from_model;
  }
  SelfCalibrationOutcome outcome = Outcome(c);
  outcome.report = nlohmann::json::parse(result.report_json(), nullptr, false);
  if (outcome.report.is_discarded()) outcome.report = nlohmann::json::object();
  outcome.site_mpcdi = ledger_->site_mpcdi;
  outcome.round = result.round();
  outcome.overlapping.emplace(result.overlapping_units().begin(), result.overlapping_units().end());
  calibrated_ = true;
  node.set_calibration_state(wire::CALIBRATION_STATE_CALIBRATED);
  ST_LOG(kInfo) << "self-calibration: calibrated (projector rms " << c.projector_rms_px
                << " px, compute " << ledger_->compute_s << " s)";
  // Reported once its display is on the projector (a lab that starts a late unit right after
  // sees the display already there).
  StartDisplay(c, node, [this, outcome] {
    if (on_calibrated_) on_calibrated_(outcome);
  });
}

}  // namespace sandtable::node
