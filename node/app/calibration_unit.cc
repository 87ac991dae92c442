// The unit's side of the self-calibration (calibration_unit.h): the steps a runner
// sends (SHOW, RESPONSE, CAPTURE, DECODE, BLANK, LOCAL), each answered once done, and the
// correspondences its neighbours send it.
#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "node/app/calibration_runner.h"
#include "node/app/calibration_unit.h"
#include "node/app/self_calibration_service.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/display_frames.h"
#include "node/calibration/projector_response.h"
#include "proto/convert.h"

namespace sandtable::node {
namespace {

// The bounds a received correspondence set must keep (docs/calibration.md).
constexpr int kMaxCorrespondencesPerSet = 1 << 20;
constexpr auto kLocalWaitForSets = std::chrono::seconds(20);

}  // namespace

const std::vector<cv::Mat>* CalibrationUnit::PatternFrames(const wire::PatternPlan& plan) {
  const std::string key = plan.SerializeAsString();
  auto it = pattern_cache_.find(key);
  if (it != pattern_cache_.end()) return &it->second;
  Expected<std::vector<cv::Mat>> frames = GeneratePatterns(PatternOptionsFromWire(plan));
  if (!frames.ok()) return nullptr;
  return &(pattern_cache_[key] = std::move(*frames));
}

bool CalibrationUnit::being_calibrated() const {
  constexpr std::chrono::seconds kRoundSilence{60};
  return projecting_ && std::chrono::steady_clock::now() - last_step_ < kRoundSilence;
}

void CalibrationUnit::HandleStep(const wire::CalibrationStep& step, NodeId from,
                                 NodeRuntime& node) {
  if (from != node.id()) last_step_from_other_ = std::chrono::steady_clock::now();
  last_step_ = std::chrono::steady_clock::now();
  if (step.action() == wire::CALIBRATION_ACTION_RESPONSE) projecting_ = true;
  if (step.round() != round_) {
    // A new round: forget the last one's captures and correspondences.
    round_ = step.round();
    slots_.clear();
    lit_masks_.clear();
    received_.clear();
    pending_local_.reset();
    replies_.clear();
    working_.clear();
  }
  // A step sent again (its answer was lost, or the runner lost patience): the same answer
  // again, or nothing while it is still being worked on.
  if (auto answered = replies_.find(step.step()); answered != replies_.end()) {
    ST_LOG(kInfo) << "self-calibration: step " << step.step() << " again; answering again";
    for (const wire::Envelope& e : answered->second) link_->Send(from, e, node);
    return;
  }
  if (!working_.insert(step.step()).second) {
    ST_LOG(kInfo) << "self-calibration: step " << step.step() << " again; still working on it";
    return;
  }
  wire::CalibrationStepDone done;
  done.set_round(step.round());
  done.set_step(step.step());
  switch (step.action()) {
    case wire::CALIBRATION_ACTION_SHOW:
      return StepShow(step, from, std::move(done), node);
    case wire::CALIBRATION_ACTION_RESPONSE:
      return StepResponse(step, from, std::move(done), node);
    case wire::CALIBRATION_ACTION_CAPTURE:
      return StepCapture(step, from, std::move(done), node);
    case wire::CALIBRATION_ACTION_DECODE:
      return StepDecode(step, from, std::move(done), node);
    case wire::CALIBRATION_ACTION_BLANK:
      return StepBlank(step, from, std::move(done), node);
    case wire::CALIBRATION_ACTION_LOCAL:
      pending_local_ = std::make_pair(step, from);
      pending_local_since_ = std::chrono::steady_clock::now();
      RunDeferred(node);
      return;
    default:
      return FailStep(from, done, node, "unknown calibration action");
  }
}

void CalibrationUnit::FailStep(NodeId from, wire::CalibrationStepDone done, NodeRuntime& node,
                               const std::string& why) {
  done.set_ok(false);
  done.set_message("unit " + std::to_string(node.id()) + ": " + why);
  ST_LOG(kWarning) << "self-calibration step " << done.step() << ": " << why;
  Answer(from, done, node);
}

// SHOW: black, white, a grey level, a pattern frame or the light cut, on a worker.
void CalibrationUnit::StepShow(const wire::CalibrationStep& step, NodeId from,
                               wire::CalibrationStepDone done, NodeRuntime& node) {
  if (!projector_) return FailStep(from, done, node, "no projector");
  cv::Mat frame;
  const cv::Size size = projector_->size();
  const bool mute = step.show() == wire::SHOW_WHAT_MUTED;
  if (step.show() == wire::SHOW_WHAT_GREY) {
    if (step.grey_level() > 255) return FailStep(from, done, node, "grey level over 255");
    frame = cv::Mat(size, CV_8UC1, cv::Scalar(static_cast<int>(step.grey_level())));
  } else if (step.show() == wire::SHOW_WHAT_WHITE) {
    frame = cv::Mat(size, CV_8UC1, cv::Scalar(255));
  } else if (step.show() == wire::SHOW_WHAT_PATTERN) {
    const std::vector<cv::Mat>* frames = PatternFrames(step.plan());
    if (!frames || step.frame() >= frames->size())
      return FailStep(from, done, node, "no such pattern frame");
    frame = (*frames)[step.frame()];
    if (frame.size() != size)
      return FailStep(from, done, node, "pattern plan is not this projector's size");
  } else {
    frame = cv::Mat::zeros(size, CV_8UC1);
  }
  ProjectorOutput* projector = projector_;
  struct Shown {
    Status status = OkStatus();
    bool muted = false;  // the light was cut (not black instead)
  };
  node.workers().Run<Shown>(
      [projector, frame, mute, loop = render_loop_] {
        if (loop) loop->Suspend();  // calibration takes the projector from the show
        Shown out;
        Expected<ShownFrame> shown = mute ? projector->Mute() : projector->Show(frame);
        out.muted = mute && shown.ok();
        if (mute && !shown.ok()) {
          // No AV mute: black instead; the response step then leaves the black level out.
          ST_LOG(kWarning) << "self-calibration: " << shown.status().message();
          shown = projector->Show(cv::Mat::zeros(projector->size(), CV_8UC1));
        }
        if (!shown.ok()) out.status = shown.status();
        return out;
      },
      [this, from, done, mute, &node](Shown result) mutable {
        if (mute) muted_ok_ = result.muted;
        const Status& shown = result.status;
        done.set_ok(shown.ok());
        if (!shown.ok()) done.set_message(shown.message());
        Answer(from, done, node);
      });
  return;
}

// RESPONSE: the own projector's response from the pre-pass captures (projector_response.h).
void CalibrationUnit::StepResponse(const wire::CalibrationStep& step, NodeId from,
                                   wire::CalibrationStepDone done, NodeRuntime& node) {
  // The own projector's response from the pre-pass captures (projector_response.h).
  auto slot = [&](uint32_t s) {
    auto it = slots_.find(s);
    return it == slots_.end() ? cv::Mat() : it->second;
  };
  const cv::Mat black = slot(step.reference_slot()), white = slot(step.white_slot());
  cv::Mat muted = step.muted_slot() != 0 && muted_ok_ ? slot(step.muted_slot()) : cv::Mat();
  std::vector<std::pair<int, cv::Mat>> greys;
  for (int i = 0; i < step.grey_levels_size(); ++i) {
    greys.emplace_back(static_cast<int>(step.grey_levels(i)),
                       slot(step.slot() + static_cast<uint32_t>(i)));
  }
  cv::Mat lit;
  if (auto m = lit_masks_.find(node.id()); m != lit_masks_.end()) lit = m->second;
  node.workers().Run<Expected<ProjectorResponse>>(
      [black, white, muted, greys, lit] {
        return FitProjectorResponse(black, white, muted, greys, lit);
      },
      [this, from, done, &node](Expected<ProjectorResponse> fitted) mutable {
        // A response that cannot be measured is not a failed calibration: the renderer
        // keeps its default (2.2) and the report says why.
        if (!fitted.ok()) {
          ST_LOG(kWarning) << "self-calibration: projector response: "
                           << fitted.status().ToString();
          response_.reset();
          done.set_message(fitted.status().message());
        } else {
          response_ = ProjectorResponseRecord{fitted->gamma, fitted->black_level};
          done.set_response_gamma(fitted->gamma);
          done.set_response_black_level(fitted->black_level);
          done.set_response_pixels(static_cast<uint32_t>(fitted->pixels));
          ST_LOG(kInfo) << "self-calibration: projector response gamma " << fitted->gamma
                        << ", black level " << fitted->black_level << " (" << fitted->pixels
                        << " camera px, fit rms " << fitted->fit_rms << ")";
        }
        done.set_ok(true);
        Answer(from, done, node);
      });
  return;
}

// CAPTURE: a picture kept under a slot; with a reference slot, the pixels lit against it.
void CalibrationUnit::StepCapture(const wire::CalibrationStep& step, NodeId from,
                                  wire::CalibrationStepDone done, NodeRuntime& node) {
  if (!camera_) {
    deferred_.emplace_back(step, from);  // the camera is still opening
    working_.erase(step.step());         // handled afresh when it has
    return;
  }
  PacedCamera* camera = camera_.get();
  const int bits = camera->bit_depth();
  // The pattern was asked for before this step came (the runner sends it once the projectors
  // showed theirs). This unit's own projector turning white against the black reference is a
  // flash: the camera measures its latency there (paced_camera.h).
  const DeviceClock::time_point since = DeviceClock::now();
  cv::Mat flash_reference;
  if (step.has_about_projector() && step.about_projector() == node.id() &&
      step.reference_slot() != 0) {
    if (auto ref = slots_.find(step.reference_slot()); ref != slots_.end()) {
      flash_reference = ref->second;
    }
  }
  const int lit_threshold = options_.lit_threshold, min_lit = options_.min_lit_pixels;
  node.workers().Run<Expected<cv::Mat>>(
      [camera, bits, since, flash_reference, lit_threshold, min_lit]() -> Expected<cv::Mat> {
        auto lit = [&](const cv::Mat& image) {
          const cv::Mat eight = To8Bit(image, bits);
          return eight.size() == flash_reference.size() &&
                 cv::countNonZero(LitMask(eight, flash_reference, lit_threshold)) >= min_lit;
        };
        Expected<CapturedFrame> frame = flash_reference.empty() ? camera->CaptureAfter(since)
                                                                : camera->CaptureFlash(since, lit);
        if (!frame.ok()) return frame.status();
        return To8Bit(frame->image, bits).clone();
      },
      [this, from, done, step, &node](Expected<cv::Mat> image) mutable {
        if (!image.ok()) {
          done.set_ok(false);
          done.set_message("unit " + std::to_string(node.id()) +
                           " camera: " + image.status().message());
          Answer(from, done, node);
          return;
        }
        if (step.reference_slot() != 0) {
          auto ref = slots_.find(step.reference_slot());
          if (ref != slots_.end() && ref->second.size() == image->size()) {
            cv::Mat mask = LitMask(*image, ref->second, options_.lit_threshold);
            const int lit = cv::countNonZero(mask);
            done.set_lit_pixels(static_cast<uint32_t>(lit));
            if (step.has_about_projector() && lit >= options_.min_lit_pixels) {
              for (const auto& [other, other_mask] : lit_masks_) {
                if (other != step.about_projector() &&
                    MasksOverlap(mask, other_mask, options_.mask_margin_px,
                                 options_.min_overlap_pixels)) {
                  done.add_overlapping_projectors(other);
                }
              }
              lit_masks_[step.about_projector()] = mask;
            }
          }
        }
        slots_[step.slot()] = std::move(*image);
        done.set_ok(true);
        Answer(from, done, node);
      });
  return;
}

// DECODE: the captures of one projector's sequence into grid correspondences, sent to it.
void CalibrationUnit::StepDecode(const wire::CalibrationStep& step, NodeId from,
                                 wire::CalibrationStepDone done, NodeRuntime& node) {
  std::vector<cv::Mat> captures;
  for (uint32_t i = 0; i < step.frames(); ++i) {
    auto it = slots_.find(step.slot() + i);
    if (it == slots_.end())
      return FailStep(from, done, node,
                      "capture slot " + std::to_string(step.slot() + i) + " missing");
    captures.push_back(it->second);
  }
  if (step.release_slots()) {
    slots_.erase(slots_.lower_bound(step.slot()), slots_.lower_bound(step.slot() + 1000));
  }
  const PatternOptions patterns = PatternOptionsFromWire(step.plan());
  ProjectorGridOptions grid;
  grid.projector_width_px = patterns.projector_width_px;
  grid.projector_height_px = patterns.projector_height_px;
  grid.step_px = step.grid_step_px() > 0 ? step.grid_step_px() : options_.grid_step_px;
  grid.offset_px = grid.step_px / 2;
  grid.support_radius_px = std::min(3.0, grid.step_px / 2 - 0.5);
  grid.wide_support_radius_px = std::max(grid.support_radius_px, grid.step_px / 2 - 0.5);
  struct Decoded {
    Expected<std::vector<ProjectorGridPoint>> points = std::vector<ProjectorGridPoint>{};
    CameraDecodeReport report;
    double cpu_s = 0.0;
  };
  cv::Mat mask;
  if (auto m = lit_masks_.find(step.projector_id()); m != lit_masks_.end()) mask = m->second;
  node.workers().Run<Decoded>(
      [captures = std::move(captures), patterns, grid, mask] {
        Decoded d;
        const double t0 = ThreadCpuSeconds();
        d.points = DecodeToProjectorGrid(captures, patterns, grid, &d.report,
                                         mask.empty() ? nullptr : &mask);
        d.cpu_s = ThreadCpuSeconds() - t0;
        return d;
      },
      [this, from, done, step, &node](Decoded d) mutable {
        ledger_->compute_s += d.cpu_s;
        done.set_compute_s(d.cpu_s);
        if (!d.points.ok()) {
          done.set_ok(false);
          done.set_message("unit " + std::to_string(node.id()) + " decoding projector " +
                           std::to_string(step.projector_id()) + ": " +
                           d.points.status().message());
          Answer(from, done, node);
          return;
        }
        wire::Envelope e;
        wire::CorrespondenceSet* set = e.mutable_correspondence_set();
        set->set_round(step.round());
        set->set_camera_id(node.id());
        set->set_projector_id(step.projector_id());
        *set->mutable_camera_model() = proto::ToWire(factory_.camera);
        GridPointsToWire(*d.points, set);
        ST_LOG(kInfo) << "self-calibration: projector " << step.projector_id() << " decoded "
                      << d.report.decode.decoded_pixels << " camera px -> " << d.points->size()
                      << " grid points (" << d.cpu_s << " s)";
        link_->Send(step.projector_id(), std::move(e), node);  // to the projecting node only
        done.set_ok(true);
        done.set_points(static_cast<uint32_t>(d.points->size()));
        Answer(from, done, node);
      });
  return;
}

// BLANK: during a neighbour's join, its light blanked from what this unit displays.
void CalibrationUnit::StepBlank(const wire::CalibrationStep& step, NodeId from,
                                wire::CalibrationStepDone done, NodeRuntime& node) {
  // A calibrated unit while a joining neighbour captures: its display blanked where that
  // neighbour's light fell in this unit's camera, or restored.
  auto lit = lit_masks_.find(step.about_projector());
  if (!projector_ || (display_.empty() && !render_loop_) || !holding_ ||
      (step.blank_on() && lit == lit_masks_.end())) {
    done.set_ok(true);  // nothing shown, or nothing of it seen: nothing to blank
    Answer(from, done, node);
    return;
  }
  ProjectorOutput* projector = projector_;
  const cv::Mat display = display_;
  const cv::Mat camera_mask = step.blank_on() ? lit->second : cv::Mat();
  const UnitCalibration holding = *holding_;
  std::shared_ptr<const Scene> model = model_;
  struct Blanked {
    Status status = OkStatus();
    int pixels = 0;
    double cpu_s = 0.0;
  };
  node.workers().Run<Blanked>(
      [projector, display, camera_mask, holding, model, loop = render_loop_] {
        Blanked b;
        const double t0 = ThreadCpuSeconds();
        cv::Mat frame = display;
        cv::Mat factor;  // for the renderer: 255 shown, 0 blank (empty: restored)
        if (!camera_mask.empty()) {
          Expected<cv::Mat> mask = JoinBlankMask(holding, model.get(), camera_mask);
          if (!mask.ok()) {
            b.status = mask.status();
            return b;
          }
          if (loop) {
            factor = cv::Mat(mask->size(), CV_8UC1, cv::Scalar(255));
            factor.setTo(0, *mask);
          } else {
            frame = display.clone();
            frame.setTo(0, *mask);
          }
          b.pixels = cv::countNonZero(*mask);
        }
        b.cpu_s = ThreadCpuSeconds() - t0;
        if (loop) {
          // The show goes on around the blanked area (the renderer's mask pass).
          b.status = loop->ShowMask(factor);
          return b;
        }
        Expected<ShownFrame> shown = projector->Show(frame);
        if (!shown.ok()) b.status = shown.status();
        return b;
      },
      [this, from, done, step, &node](Blanked b) mutable {
        ledger_->compute_s += b.cpu_s;
        done.set_compute_s(b.cpu_s);
        done.set_ok(b.status.ok());
        if (!b.status.ok()) done.set_message(b.status.message());
        done.set_blanked_pixels(static_cast<uint32_t>(b.pixels));
        if (step.blank_on()) {
          ST_LOG(kInfo) << "self-calibration: display blanked on " << b.pixels << " px while unit "
                        << step.about_projector() << " captures";
        }
        Answer(from, done, node);
      });
  return;
}

void CalibrationUnit::HandleCorrespondences(const wire::CorrespondenceSet& set) {
  if (set.projector_id() != factory_.unit_id) return;  // not ours
  if (set.camera_px_xy_size() != set.projector_px_xy_size() || set.camera_px_xy_size() % 2 ||
      set.camera_px_xy_size() > 2 * kMaxCorrespondencesPerSet) {
    ST_LOG(kWarning) << "self-calibration: refused a correspondence set from camera "
                     << set.camera_id() << " (array sizes)";
    return;
  }
  if (set.round() != round_ && round_ != 0) return;
  received_[set.camera_id()] = set;
}

void CalibrationUnit::RunDeferred(NodeRuntime& node) {
  if (camera_) {
    while (!deferred_.empty()) {
      auto [step, from] = deferred_.front();
      deferred_.pop_front();
      HandleStep(step, from, node);
    }
  }
  if (pending_local_) {
    const uint32_t expected = pending_local_->first.frames();  // sets expected (runner knows)
    const bool waited = std::chrono::steady_clock::now() - pending_local_since_ > kLocalWaitForSets;
    if (received_.size() >= expected || waited) {
      auto [step, from] = *pending_local_;
      pending_local_.reset();
      RunLocal(step, from, node);
    }
  }
}

void CalibrationUnit::RunLocal(const wire::CalibrationStep& step, NodeId from, NodeRuntime& node) {
  // Tracks of our projector from every camera's set; factory cameras of the senders.
  std::map<NodeId, std::vector<ProjectorGridPoint>> by_camera;
  std::map<NodeId, CameraModel> cameras;
  cameras[node.id()] = factory_.camera;
  wire::Envelope e;
  wire::CalibrationInput* input = e.mutable_calibration_input();
  input->set_round(step.round());
  input->set_unit_id(node.id());
  *input->mutable_camera_model() = proto::ToWire(factory_.camera);
  *input->mutable_projector_model() = proto::ToWire(factory_.projector);
  *input->mutable_projector_from_camera() = proto::ToWire(factory_.projector_from_camera);
  for (const auto& [camera, set] : received_) {
    Expected<CameraModel> model = proto::FromWire(set.camera_model());
    if (!model.ok()) {
      ST_LOG(kWarning) << "self-calibration: camera " << camera
                       << " sent an invalid model: " << model.status().message();
      continue;
    }
    cameras[camera] = *model;
    by_camera[camera] = GridPointsFromWire(set);
    *input->add_correspondences() = set;
  }
  received_.clear();
  UnitModel self{node.id(), factory_.camera, factory_.projector, factory_.projector_from_camera};
  struct Local {
    Expected<LocalGeometry> geometry = LocalGeometry{};
    Expected<PlanarityProbe> probe = PlanarityProbe{};
    double cpu_s = 0.0;
  };
  const PlanarityOptions planarity = options_.planar.planarity;
  node.workers().Run<Local>(
      [self, cameras, by_camera, planarity] {
        Local l;
        const double t0 = ThreadCpuSeconds();
        l.geometry = EstimateLocalGeometry(self, cameras, BuildTracks(self.unit, by_camera));
        // Its own footprint's planarity, from its own camera's points of its projector.
        auto own = by_camera.find(self.unit);
        l.probe = own == by_camera.end() ? Expected<PlanarityProbe>(NotFoundError(
                                               "unit " + std::to_string(self.unit) +
                                               ": its camera decoded none of its projector"))
                                         : ProbePlanarity(self, own->second, planarity);
        l.cpu_s = ThreadCpuSeconds() - t0;
        return l;
      },
      [this, e = std::move(e), step, from, &node](Local l) mutable {
        ledger_->compute_s += l.cpu_s;
        wire::CalibrationInput* in = e.mutable_calibration_input();
        wire::PlanarityProbe* probe = in->mutable_planarity();
        probe->set_ok(l.probe.ok());
        probe->set_threshold_mm(options_.planar.planarity.threshold_mm);
        if (l.probe.ok()) {
          probe->set_planar(l.probe->planar);
          probe->set_max_height_mm(l.probe->max_height_mm);
          probe->set_surface_rms_mm(l.probe->surface_rms_mm);
          probe->set_points(static_cast<uint32_t>(l.probe->points));
          probe->set_points_over_threshold(static_cast<uint32_t>(l.probe->points_over_threshold));
          ST_LOG(kInfo) << "self-calibration: footprint "
                        << (l.probe->planar ? "planar" : "not planar") << " (max height "
                        << l.probe->max_height_mm << " mm over its surface, "
                        << l.probe->points_over_threshold << " of " << l.probe->points
                        << " points over " << options_.planar.planarity.threshold_mm << " mm)";
        } else {
          probe->set_message(l.probe.status().message());
        }
        if (!l.geometry.ok()) {
          // The correspondences still go to the runner: other units' relative poses may reach
          // this one.
          in->set_ok(true);
          in->set_message(l.geometry.status().message());
          ST_LOG(kWarning) << "self-calibration: " << l.geometry.status().message();
        } else {
          in->set_ok(true);
          in->set_triangulated(static_cast<uint32_t>(l.geometry->triangulated));
          for (const auto& [camera, relative] : l.geometry->neighbours) {
            wire::RelativePose* r = in->add_relative_poses();
            r->set_camera_id(camera);
            *r->mutable_camera_from_projector() = proto::ToWire(relative.camera_from_projector);
            r->set_points(static_cast<uint32_t>(relative.points));
            r->set_rms_px(relative.rms_px);
          }
          for (const std::string& note : l.geometry->notes) {
            ST_LOG(kInfo) << "self-calibration: " << note;
          }
        }
        if (step.round() == round_) replies_[step.step()].push_back(e);
        link_->Send(from, std::move(e), node);
        wire::CalibrationStepDone done;
        done.set_round(step.round());
        done.set_step(step.step());
        done.set_ok(true);
        done.set_compute_s(l.cpu_s);
        Answer(from, done, node);
      });
}

void CalibrationUnit::Answer(NodeId to, wire::CalibrationStepDone done, NodeRuntime& node) {
  wire::Envelope e;
  *e.mutable_calibration_step_done() = std::move(done);
  if (e.calibration_step_done().round() == round_) {
    replies_[e.calibration_step_done().step()].push_back(e);
    working_.erase(e.calibration_step_done().step());
  }
  link_->Send(to, std::move(e), node);
}

}  // namespace sandtable::node
