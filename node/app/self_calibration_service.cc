#include "node/app/self_calibration_service.h"

#include "node/calibration/projector_response.h"

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "node/app/calibration_service.h"
#include "node/app/self_calibration_runner.h"
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
  return line;
}

SelfCalibrationService::SelfCalibrationService(UnitCalibration factory, ProjectorOutput* projector,
                                               std::shared_ptr<const Scene> model,
                                               SelfCalibrationOptions options,
                                               OnCalibrated on_calibrated, OnFailed on_failed)
    : factory_(std::move(factory)),
      projector_(projector),
      model_(std::move(model)),
      options_(std::move(options)),
      on_calibrated_(std::move(on_calibrated)),
      on_failed_(std::move(on_failed)) {}

SelfCalibrationService::~SelfCalibrationService() = default;

SelfCalibrationOutcome SelfCalibrationService::Outcome(const UnitCalibration& calibration) const {
  SelfCalibrationOutcome outcome;
  outcome.calibration = calibration;
  outcome.report = nlohmann::json::object();
  outcome.compute_s = compute_s_;
  outcome.messages_sent = messages_sent_;
  outcome.messages_received = messages_received_;
  outcome.bytes_sent = bytes_sent_;
  outcome.bytes_received = bytes_received_;
  return outcome;
}

void SelfCalibrationService::SetCamera(std::unique_ptr<CameraInput> camera) {
  camera_ = std::move(camera);
}

void SelfCalibrationService::SetSavedCalibration(UnitCalibration saved,
                                                 OnVerification on_verification) {
  saved_ = std::move(saved);
  on_verification_ = std::move(on_verification);
}

void SelfCalibrationService::MaybeVerify(NodeRuntime& node) {
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
  CameraInput* camera = camera_.get();
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
          Expected<CapturedFrame> frame = camera->Capture(Seconds(0));
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
        compute_s_ += c.cpu_s;
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

bool SelfCalibrationService::Send(NodeId to, wire::Envelope envelope, NodeRuntime& node) {
  if (to == node.id()) {  // the runner talking to itself: no socket
    Deliver(to, envelope, node);
    return true;
  }
  ++messages_sent_;
  bytes_sent_ += envelope.ByteSizeLong();
  if (Status sent = node.SendToPeer(to, std::move(envelope)); !sent.ok()) {
    ST_LOG(kWarning) << "self-calibration: to node " << to << ": " << sent.ToString();
    return false;
  }
  return true;
}

void SelfCalibrationService::OnPeerMessage(net::Incoming request, NodeRuntime& node) {
  ++messages_received_;
  bytes_received_ += request.envelope.ByteSizeLong();
  Deliver(request.envelope.sender_id(), request.envelope, node);
}

void SelfCalibrationService::Deliver(NodeId from, const wire::Envelope& e, NodeRuntime& node) {
  switch (e.body_case()) {
    case wire::Envelope::kCalibrationStep:
      if (from != node.id()) last_step_from_other_ = std::chrono::steady_clock::now();
      HandleStep(e.calibration_step(), from, node);
      break;
    case wire::Envelope::kCalibrationStepDone:
      RunnerDone(from, e.calibration_step_done(), node);
      break;
    case wire::Envelope::kCorrespondenceSet:
      HandleCorrespondences(e.correspondence_set());
      break;
    case wire::Envelope::kCalibrationInput:
      RunnerInput(from, e.calibration_input(), node);
      break;
    case wire::Envelope::kCalibrationResult:
      if (e.calibration_result().projector_id() == node.id()) calibrated_by_ = from;
      HandleResult(e.calibration_result(), node);
      break;
    default:
      break;
  }
}

void SelfCalibrationService::Answer(NodeId to, wire::CalibrationStepDone done, NodeRuntime& node) {
  wire::Envelope e;
  *e.mutable_calibration_step_done() = std::move(done);
  if (e.calibration_step_done().round() == round_) {
    replies_[e.calibration_step_done().step()].push_back(e);
    working_.erase(e.calibration_step_done().step());
  }
  Send(to, std::move(e), node);
}

void SelfCalibrationService::StartDisplay(const UnitCalibration& calibration, NodeRuntime& node,
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

void SelfCalibrationService::HandleResult(const wire::CalibrationResult& result,
                                          NodeRuntime& node) {
  if (result.projector_id() != node.id()) return;
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
  outcome.site_mpcdi = site_mpcdi_;
  outcome.round = result.round();
  outcome.overlapping.emplace(result.overlapping_units().begin(), result.overlapping_units().end());
  calibrated_ = true;
  node.set_calibration_state(wire::CALIBRATION_STATE_CALIBRATED);
  ST_LOG(kInfo) << "self-calibration: calibrated (projector rms " << c.projector_rms_px
                << " px, compute " << compute_s_ << " s)";
  // Reported once its display is on the projector (a lab that starts a late unit right after
  // sees the display already there).
  StartDisplay(c, node, [this, outcome] {
    if (on_calibrated_) on_calibrated_(outcome);
  });
}

Status SelfCalibrationService::OnStep(NodeRuntime& node) {
  RunDeferred(node);
  MaybeVerify(node);
  MaybeStartRound(node);
  RunnerStep(node);
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
