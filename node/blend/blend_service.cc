#include "node/blend/blend_service.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <utility>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "common/base/log.h"
#include "common/io/image_file.h"
#include "node/net/node_runtime.h"
#include "proto/convert.h"

namespace sandtable::node {
namespace {

using Clock = std::chrono::steady_clock;

int64_t SteadyNs(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}
double MsSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

}  // namespace

wire::BlendShare ShareFromField(const DistanceField& field, uint64_t round) {
  wire::BlendShare share;
  share.set_projector_id(field.unit);
  share.set_calibration_round(round);
  *share.mutable_projector_model() = proto::ToWire(field.projector);
  *share.mutable_projector_from_table() = proto::ToWire(field.projector_from_table);
  share.set_step_px(static_cast<uint32_t>(field.step_px));
  share.set_cols(static_cast<uint32_t>(field.cols));
  share.set_rows(static_cast<uint32_t>(field.rows));
  share.mutable_distance_m()->Add(field.distance_m.begin(), field.distance_m.end());
  return share;
}

Expected<DistanceField> FieldFromShare(const wire::BlendShare& share) {
  DistanceField field;
  field.unit = share.projector_id();
  Expected<CameraModel> model = proto::FromWire(share.projector_model());
  if (!model.ok()) return model.status().WithContext("blend share: projector_model");
  Expected<Rigid3d> pose = proto::FromWire(share.projector_from_table());
  if (!pose.ok()) return pose.status().WithContext("blend share: projector_from_table");
  field.projector = *model;
  field.projector_from_table = *pose;
  if (share.step_px() > 64 || share.cols() > (1u << 16) || share.rows() > (1u << 16)) {
    return InvalidArgumentError("blend share: grid out of range");
  }
  field.step_px = static_cast<int>(share.step_px());
  field.cols = static_cast<int>(share.cols());
  field.rows = static_cast<int>(share.rows());
  field.distance_m.assign(share.distance_m().begin(), share.distance_m().end());
  ST_RETURN_IF_ERROR(field.Check());
  return field;
}

Expected<std::optional<FaceLevels>> FaceLevelsFromShare(const wire::BlendShare& share) {
  if (!share.has_face_levels()) {
    if (share.face_levels_size() > 0) {
      return InvalidArgumentError("blend share: face levels without has_face_levels");
    }
    return std::optional<FaceLevels>();
  }
  if (share.face_levels_size() > kMaxFaceLevels) {
    return InvalidArgumentError("blend share: " + std::to_string(share.face_levels_size()) +
                                " face levels (at most " + std::to_string(kMaxFaceLevels) + ")");
  }
  FaceLevels levels;
  for (const wire::FaceLevel& f : share.face_levels()) {
    if (f.face() < 0 || !std::isfinite(f.level_per_m2()) || f.level_per_m2() <= 0) {
      return InvalidArgumentError("blend share: face " + std::to_string(f.face()) + " at level " +
                                  std::to_string(f.level_per_m2()));
    }
    if (!levels.emplace(f.face(), f.level_per_m2()).second) {
      return InvalidArgumentError("blend share: face " + std::to_string(f.face()) + " twice");
    }
  }
  return std::optional<FaceLevels>(std::move(levels));
}

struct BlendService::Core {
  std::mutex mutex;
  std::shared_ptr<const Scene> scene;
  std::unique_ptr<RayCaster> caster;
  std::unique_ptr<Blender> blender;
  DistanceField own;
  uint64_t generation = 0;
};

BlendService::BlendService(std::shared_ptr<const Scene> model, RenderLoop* loop,
                           BlendServiceOptions options, Print print)
    : loop_(loop),
      options_(std::move(options)),
      print_(std::move(print)),
      model_(std::move(model)),
      core_(std::make_shared<Core>()) {}

BlendService::~BlendService() = default;

bool BlendService::ServesPeer(wire::Envelope::BodyCase body) const {
  return body == wire::Envelope::kBlendShare || body == wire::Envelope::kBlendAlpha;
}

void BlendService::SetSiteMpcdi(std::shared_ptr<const MpcdiSite> site, std::string path) {
  site_mpcdi_ = site ? std::make_shared<MpcdiSite>(*site) : nullptr;
  site_mpcdi_path_ = std::move(path);
}

void BlendService::HoldSiteMpcdiWrites() { ++mpcdi_holds_; }

void BlendService::ReleaseSiteMpcdiWrites(NodeRuntime& node) {
  if (mpcdi_holds_ > 0) --mpcdi_holds_;
  if (mpcdi_holds_ == 0 && !mpcdi_writing_ && mpcdi_dirty_ && site_mpcdi_ &&
      !site_mpcdi_path_.empty()) {
    WriteSiteMpcdi(node);
  }
}

void BlendService::TakeAlpha(NodeId unit, int width_px, int height_px, std::string values,
                             NodeRuntime& node) {
  if (!site_mpcdi_ || site_mpcdi_path_.empty()) return;
  const std::string id = "unit-" + std::to_string(unit);
  MpcdiRegion* region = nullptr;
  for (MpcdiRegion& r : site_mpcdi_->regions) {
    if (r.id == id) region = &r;
  }
  if (!region || width_px != region->x_resolution_px || height_px != region->y_resolution_px) {
    ++bad_shares_;
    ST_LOG(kWarning) << "blend: an alpha map of " << width_px << "x" << height_px << " for " << id
                     << " fits no region of the site's MPCDI export";
    return;
  }
  MpcdiBlendMap alpha;
  alpha.width_px = width_px;
  alpha.height_px = height_px;
  alpha.values.assign(values.begin(), values.end());
  alpha.gamma_embedded = 1.0;
  region->alpha = std::move(alpha);
  mpcdi_dirty_ = true;
  mpcdi_latest_ = unit;
  if (!mpcdi_writing_ && mpcdi_holds_ == 0)
    WriteSiteMpcdi(node);  // else: written again after the one in flight
}

void BlendService::TakeAlphaPng(NodeId unit, int width_px, int height_px, std::string png,
                                NodeRuntime& node) {
  if (!site_mpcdi_ || site_mpcdi_path_.empty()) return;  // not the runner: nothing to write
  const std::optional<cv::Size> stated = io::ImageHeaderSize(png);
  if (!stated || stated->width != width_px || stated->height != height_px) {
    ++bad_shares_;
    ST_LOG(kWarning) << "blend: an alpha map PNG from node " << unit << " dropped (its header "
                     << (stated ? "states another size" : "is not a PNG's") << ")";
    return;
  }
  node.workers().Run<std::string>(
      [png = std::move(png), width_px, height_px] {
        cv::Mat image;
        try {
          image = cv::imdecode(
              cv::Mat(1, static_cast<int>(png.size()), CV_8UC1, const_cast<char*>(png.data())),
              cv::IMREAD_UNCHANGED);
        } catch (const cv::Exception&) {
          return std::string();
        }
        if (image.type() != CV_8UC1 || image.cols != width_px || image.rows != height_px) {
          return std::string();
        }
        return std::string(reinterpret_cast<const char*>(image.data), image.total());
      },
      [this, unit, width_px, height_px, &node](std::string values) {
        if (values.empty()) {
          ++bad_shares_;
          ST_LOG(kWarning) << "blend: an alpha map PNG from node " << unit
                           << " dropped (not an 8-bit grey image of its stated size)";
          return;
        }
        TakeAlpha(unit, width_px, height_px, std::move(values), node);
      });
}

void BlendService::WriteSiteMpcdi(NodeRuntime& node) {
  const NodeId latest = mpcdi_latest_;
  mpcdi_writing_ = true;
  mpcdi_dirty_ = false;
  node.workers().Run<Status>(
      [site = MpcdiSite(*site_mpcdi_), path = site_mpcdi_path_] { return WriteMpcdi(path, site); },
      [this, latest, &node](Status written) {
        mpcdi_writing_ = false;
        if (!written.ok()) {
          ST_LOG(kWarning) << "blend: the MPCDI export: " << written.ToString();
        } else {
          print_(report::BlendExported{id_, site_mpcdi_path_, latest});
        }
        // Alphas that came in meanwhile: once more, with what the site holds now.
        if (mpcdi_dirty_ && mpcdi_holds_ == 0) WriteSiteMpcdi(node);
      });
}

void BlendService::SetCalibration(const UnitCalibration& calibration, uint64_t round,
                                  std::optional<std::set<NodeId>> neighbours, NodeRuntime& node,
                                  NodeId runner) {
  if (!calibration.table_from_projector) return;
  id_ = node.id();
  own_black_ = calibration.projector_response ? calibration.projector_response->black_level : -1.0;
  round_ = round;
  runner_ = runner;
  const uint64_t generation = ++generation_;
  ready_ = false;
  own_faces_.reset();
  pending_alpha_.reset();
  sent_to_.clear();
  asked_.clear();
  own_share_.reset();
  holding_.clear();
  neighbours_ = std::move(neighbours);
  struct Cast {
    Status status = OkStatus();
    double bound = 0.0, compute_ms = 0.0;
    std::shared_ptr<const wire::BlendShare> share;  // the own field, as sent
  };
  // Fields already received (a neighbour that calibrated first) are applied with the cast.
  auto fields = std::make_shared<std::map<NodeId, DistanceField>>(fields_);
  node.workers().Run<Cast>(
      [core = core_, model = model_, calibration, options = options_.blend, generation, fields,
       id = id_, round] {
        Cast out;
        const Clock::time_point start = Clock::now();
        auto scene = std::make_shared<const Scene>(RenderLoop::SceneFor(model.get(), calibration));
        // The planes of the model in its own frame (SceneFor keeps the triangles' order), so
        // that every node finds the same face ids.
        const bool placed = model && model->NumTriangles() > 0 && calibration.table_from_model;
        const std::vector<int> faces = PlanarFaces(placed ? *model : *scene);
        Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene, "threads=1");
        if (!caster.ok()) {
          out.status = caster.status();
          return out;
        }
        const Rigid3d projector_from_table = calibration.table_from_projector->Inverse();
        DistanceField own = ComputeDistanceField(id, calibration.projector, projector_from_table,
                                                 **caster, options);
        ProjectorSurface surface = CastProjectorSurface(calibration.projector, projector_from_table,
                                                        **caster, options, faces);
        auto blender = std::make_unique<Blender>(std::move(surface), own, caster->get(), options);
        for (const auto& [unit, field] : *fields) {
          if (unit != id) blender->SetNeighbour(field);
        }
        out.bound = blender->LevelBound();
        out.share = std::make_shared<const wire::BlendShare>(ShareFromField(own, round));
        std::lock_guard<std::mutex> lock(core->mutex);
        core->scene = std::move(scene);
        core->caster = std::move(*caster);
        core->blender = std::move(blender);
        core->own = std::move(own);
        core->generation = generation;
        out.compute_ms = MsSince(start);
        return out;
      },
      [this, generation, fields, &node](Cast cast) {
        if (generation != generation_) return;  // a newer calibration is on its way
        if (!cast.status.ok()) {
          ST_LOG(kError) << "blend: " << cast.status.ToString();
          return;
        }
        ready_ = true;
        cast_ms_ = cast.compute_ms;
        own_share_ = std::move(cast.share);
        for (const auto& [unit, field] : *fields) {
          if (unit != id_) holding_.insert(unit);
        }
        // Fields that came in during the cast (new ones, or newer than the cast's).
        for (const auto& [unit, field] : fields_) {
          auto cast_with = fields->find(unit);
          if (unit != id_ && (cast_with == fields->end() || !SameField(cast_with->second, field))) {
            ApplyField(unit, field, node);
          }
        }
        bounds_[id_] = cast.bound;
        ST_LOG(kInfo) << "blend: field and surface cast in " << cast.compute_ms
                      << " ms, level bound " << cast.bound << " / m^2";
        // The own field to the neighbours, asking each for theirs.
        std::set<NodeId> to;
        if (neighbours_) {
          to = *neighbours_;
        } else {
          for (const auto& [peer, info] : node.peers()) to.insert(peer);
        }
        // And to every unit whose field came in before the cast was done: it asked for this
        // one then, when there was none to answer with (its list of overlapping units may not
        // hold this unit: it would wait for ever).
        for (const auto& [unit, field] : fields_) to.insert(unit);
        for (NodeId peer : to) {
          if (peer != id_)
            SendShare(peer, /*with_field=*/true, /*answer=*/!fields_.count(peer), node);
        }
        Compose(node, "calibrated", kInvalidNodeId, Clock::now());
      });
}

void BlendService::SendShare(NodeId to, bool with_field, bool answer, NodeRuntime& node) {
  wire::Envelope envelope;
  wire::BlendShare* share = envelope.mutable_blend_share();
  if (with_field && own_share_) {
    *share = *own_share_;
    sent_to_.insert(to);
    if (answer) {
      Asked& asked = asked_[to];
      asked.at = Clock::now();
      asked.interval = asked.interval.count() == 0
                           ? options_.ask_again
                           : std::min(options_.ask_again_max, 2 * asked.interval);
    }
  } else {
    share->set_projector_id(id_);
    share->set_calibration_round(round_);
  }
  double known = std::numeric_limits<double>::infinity();
  for (const auto& [unit, bound] : bounds_) known = std::min(known, bound);
  share->set_level_bound_per_m2(bounds_.count(id_) ? bounds_.at(id_) : 0.0);
  share->set_level_known_per_m2(std::isfinite(known) ? known : 0.0);
  share->set_answer(answer);
  share->set_black_level(own_black_);
  double black_peak = 0.0;
  for (const auto& [unit, peak] : black_peaks_) black_peak = std::max(black_peak, peak);
  share->set_black_peak_known_per_m2(black_peak);
  if (own_faces_) {
    share->set_has_face_levels(true);
    for (const auto& [face, level] : *own_faces_) {
      wire::FaceLevel* f = share->add_face_levels();
      f->set_face(face);
      f->set_level_per_m2(level);
    }
  }
  bytes_sent_ += envelope.ByteSizeLong();
  if (Status sent = node.SendToPeer(to, std::move(envelope)); !sent.ok()) {
    ST_LOG(kWarning) << "blend: to node " << to << ": " << sent.ToString();
  }
}

void BlendService::OnPeerMessage(net::Incoming request, NodeRuntime& node) {
  const NodeId from = request.envelope.sender_id();
  bytes_received_ += request.envelope.ByteSizeLong();
  if (request.envelope.has_blend_alpha()) {
    const wire::BlendAlpha& a = request.envelope.blend_alpha();
    const uint64_t w = a.width_px(), h = a.height_px();
    const bool png = !a.png().empty();
    if (a.projector_id() != from || w == 0 || h == 0 || w > 8192 || h > 8192 ||
        (png ? !a.values().empty() : a.values().size() != w * h)) {
      ++bad_shares_;
      ST_LOG(kWarning) << "blend: an alpha map from node " << from << " dropped (" << w << "x" << h
                       << ", " << a.values().size() << " bytes, " << a.png().size() << " as PNG)";
      return;
    }
    if (png) {
      TakeAlphaPng(from, static_cast<int>(w), static_cast<int>(h), a.png(), node);
    } else {
      TakeAlpha(from, static_cast<int>(w), static_cast<int>(h), a.values(), node);
    }
    return;
  }
  const wire::BlendShare& share = request.envelope.blend_share();
  if (share.projector_id() != from || from == node.id()) {
    ++bad_shares_;
    ST_LOG(kWarning) << "blend: a share from node " << from << " for projector "
                     << share.projector_id() << " dropped";
    return;
  }
  Expected<std::optional<FaceLevels>> faces = FaceLevelsFromShare(share);
  if (!faces.ok()) {
    ++bad_shares_;
    ST_LOG(kWarning) << "blend: node " << from << ": " << faces.status().ToString();
    return;
  }
  bool faces_news = false;
  if (faces->has_value()) {
    // News only when the levels a face may show change (none held is an empty list).
    auto held = neighbour_faces_.find(from);
    faces_news = held == neighbour_faces_.end() ? !(*faces)->empty() : held->second != **faces;
    neighbour_faces_[from] = std::move(**faces);
  }
  // Levels: the lowest bound anyone has heard of.
  double heard = share.level_known_per_m2();
  if (share.level_bound_per_m2() > 0) heard = std::min(heard, share.level_bound_per_m2());
  const bool level_news =
      heard > 0 && std::isfinite(heard) && (!bounds_.count(from) || heard < bounds_.at(from));
  if (level_news) bounds_[from] = heard;
  // Black levels: the sender's own, and the highest black light anyone has heard of.
  if (share.black_level() >= 0 && share.black_level() < 1) blacks_[from] = share.black_level();
  double black_known = 0.0;
  for (const auto& [unit, peak] : black_peaks_) black_known = std::max(black_known, peak);
  const double black_heard = share.black_peak_known_per_m2();
  const bool black_news = std::isfinite(black_heard) && black_heard > black_known * (1 + 1e-9);
  if (black_news) black_peaks_[from] = black_heard;
  const bool with_field = share.distance_m_size() > 0;
  if (with_field) {
    Expected<DistanceField> field = FieldFromShare(share);
    if (!field.ok()) {
      ++bad_shares_;
      ST_LOG(kWarning) << "blend: node " << from << ": " << field.status().ToString();
      return;
    }
    // The field the blend already holds (a neighbour asking again, or answering twice): no
    // new lookup.
    auto held = fields_.find(from);
    const bool known =
        holding_.count(from) > 0 && held != fields_.end() && SameField(held->second, *field);
    fields_[from] = *field;
    // Asked for the own field: answer, even when it was sent before (a node that dropped this
    // one on a silence asks again; only its answer ends its wait).
    if (ready_ && share.answer()) SendShare(from, /*with_field=*/true, /*answer=*/false, node);
    if (ready_ && !known) ApplyField(from, *field, node);  // else: applied once the cast is done
    return;
  }
  if ((level_news || faces_news || (black_news && options_.black_match)) && ready_) {
    Compose(node, level_news ? "level" : faces_news ? "faces" : "black", from, Clock::now());
  }
}

void BlendService::ApplyField(NodeId from, const DistanceField& field, NodeRuntime& node) {
  const uint64_t generation = generation_;
  node.workers().Run<bool>(
      [core = core_, field, generation] {
        std::lock_guard<std::mutex> lock(core->mutex);
        if (!core->blender || core->generation != generation) return false;
        core->blender->SetNeighbour(field);
        return true;
      },
      [this, from, generation, &node](bool applied) {
        if (!applied || generation != generation_) return;
        holding_.insert(from);
        Compose(node, "share", from, Clock::now());
      });
}

void BlendService::SendAlpha(NodeRuntime& node) {
  PendingAlpha alpha = std::move(*pending_alpha_);
  pending_alpha_.reset();
  if (runner_ == id_) {
    if (!alpha.values.empty()) {
      TakeAlpha(id_, alpha.width_px, alpha.height_px, std::move(alpha.values), node);
    } else {
      TakeAlphaPng(id_, alpha.width_px, alpha.height_px, std::move(alpha.png), node);
    }
    return;
  }
  wire::Envelope envelope;
  wire::BlendAlpha* a = envelope.mutable_blend_alpha();
  a->set_projector_id(id_);
  a->set_calibration_round(round_);
  a->set_width_px(static_cast<uint32_t>(alpha.width_px));
  a->set_height_px(static_cast<uint32_t>(alpha.height_px));
  if (!alpha.png.empty()) {
    a->set_png(std::move(alpha.png));
  } else {  // composed while this node was the runner; the runner has changed since
    a->set_values(std::move(alpha.values));
  }
  bytes_sent_ += envelope.ByteSizeLong();
  if (Status sent = node.SendToPeer(runner_, std::move(envelope)); !sent.ok()) {
    ST_LOG(kWarning) << "blend: alpha to node " << runner_ << ": " << sent.ToString();
  }
}

Status BlendService::OnStep(NodeRuntime& node) {
  if (!ready_) return OkStatus();
  const Clock::time_point now = Clock::now();
  if (pending_alpha_ && now - pending_alpha_->composed >= options_.alpha_quiet) SendAlpha(node);
  // A neighbour dropped on a connection loss that is heard again: ask for its field anew.
  for (auto it = dropped_.begin(); it != dropped_.end();) {
    auto info = node.peers().find(it->first);
    if (info != node.peers().end() && info->second.disconnected_at == Clock::time_point{} &&
        info->second.last_heard > it->second) {
      ST_LOG(kInfo) << "blend: node " << it->first << " is back; asking for its field";
      SendShare(it->first, /*with_field=*/true, /*answer=*/true, node);
      it = dropped_.erase(it);
    } else {
      ++it;
    }
  }
  // Overlapping units whose field has not come although it was asked for: the share or the
  // answer may have been lost while a link was down (a unit declared dead for a moment).
  if (neighbours_) {
    for (NodeId n : *neighbours_) {
      if (n == id_ || holding_.count(n) || dropped_.count(n) || fields_.count(n)) continue;
      auto asked = asked_.find(n);
      if (asked != asked_.end() && now - asked->second.at < asked->second.interval) continue;
      if (!node.peers().count(n)) continue;  // not linked (yet): asked once it is
      if (asked != asked_.end()) {
        ST_LOG(kInfo) << "blend: no field from node " << n << " yet; asking again";
      }
      SendShare(n, /*with_field=*/true, /*answer=*/true, node);
    }
  }
  // Neighbours that left: their connection dropped (a process that dies closes its socket),
  // silent past peer_silence, or no longer a peer.
  for (auto it = holding_.begin(); it != holding_.end();) {
    const NodeId peer = *it;
    auto info = node.peers().find(peer);
    // How it was noticed (the JSON line's "noticed_by"): a killed process closes its sockets
    // once its memory is unmapped; the member list drops it after the coordinator's silence.
    const char* noticed_by = nullptr;
    if (info == node.peers().end()) {
      noticed_by = "member list";
    } else if (info->second.disconnected_at != Clock::time_point{}) {
      noticed_by = "connection";
    } else if (info->second.last_heard != Clock::time_point{} &&
               now - info->second.last_heard >
                   NodeRuntime::PeerSilence(info->second, options_.peer_silence)) {
      noticed_by = "silence";
    }
    if (noticed_by == nullptr) {
      ++it;
      continue;
    }
    it = holding_.erase(it);
    fields_.erase(peer);
    neighbour_faces_.erase(peer);
    sent_to_.erase(peer);
    dropped_[peer] = now;
    // The mask prepared for this (docs/blend.md, "Prepared masks") goes out at once; the
    // composition below makes the same mask (shown already: nothing more to show) and the
    // masks for the next neighbour to leave.
    const bool prepared = loop_ && loop_->ShowPreparedBlend(peer);
    ST_LOG(kInfo) << "blend: node " << peer << " left (noticed by its " << noticed_by
                  << "); re-blending without it" << (prepared ? " (its prepared mask shown)" : "");
    const uint64_t generation = generation_;
    node.workers().Run<bool>(
        [core = core_, peer, generation] {
          std::lock_guard<std::mutex> lock(core->mutex);
          if (!core->blender || core->generation != generation) return false;
          return core->blender->RemoveNeighbour(peer);
        },
        [this, peer, now, noticed_by, &node](bool removed) {
          if (removed) Compose(node, "left", peer, now, noticed_by);
        });
  }
  return OkStatus();
}

void BlendService::TellLevel(NodeRuntime& node) {
  double known = std::numeric_limits<double>::infinity();
  for (const auto& [unit, bound] : bounds_) known = std::min(known, bound);
  double black = 0.0;
  for (const auto& [unit, peak] : black_peaks_) black = std::max(black, peak);
  const bool level_news = std::isfinite(known) && (level_told_ <= 0 || known < level_told_);
  const bool black_news = options_.black_match && black > black_told_ * (1 + 1e-9);
  if (!level_news && !black_news) return;
  if (level_news) level_told_ = known;
  if (black_news) black_told_ = black;
  for (NodeId peer : sent_to_) SendShare(peer, /*with_field=*/false, /*answer=*/false, node);
}

// What a worker needs to compose this node's blend and show it (a copy: the worker does not
// touch the service).
struct BlendService::ComposeJob {
  std::shared_ptr<Core> core;
  RenderLoop* loop = nullptr;
  double level = 0.0;
  uint64_t generation = 0;
  std::string png;  // the alpha mask's picture to write (empty: none)
  bool to_runner = false, runner_is_self = false;
  bool match = false;  // black-level matching
  double black_target = 0.0, own_black = -1.0, max_lift = 0.0;
  std::map<NodeId, double> blacks;
  std::map<NodeId, FaceLevels> neighbour_faces;
};

struct BlendService::ComposedBlend {
  bool stale = false;        // a newer calibration replaced the blender
  std::string alpha_png;     // the mask, 8-bit grey PNG (for the MPCDI export at the runner)
  std::string alpha_values;  // or its values, when this node is the runner (no PNG round trip)
  int width_px = 0, height_px = 0;
  Status status = OkStatus();
  int64_t shown_ns = 0;
  MaskFrameTimes frame;  // where the time went for the frame that showed it
  double compose_ms = 0.0;
  double black_peak = 0.0, black_target = 0.0, lift_max = 0.0;
  FaceLevels own_faces;  // Blender::FaceLevelBounds at this blend
  size_t faces_lower = 0;
  double face_level_min = 0.0;
};

void BlendService::Compose(NodeRuntime& node, const std::string& cause, NodeId peer,
                           Clock::time_point detected, const char* noticed_by) {
  TellLevel(node);
  ComposeJob job;
  job.level = std::numeric_limits<double>::infinity();
  for (const auto& [unit, bound] : bounds_) job.level = std::min(job.level, bound);
  if (!std::isfinite(job.level) || job.level <= 0) return;
  // Black-level matching: the highest black light heard; the worker raises it to its own peak.
  job.match = options_.black_match && own_black_ >= 0;
  for (const auto& [unit, peak] : black_peaks_) job.black_target = std::max(job.black_target, peak);
  job.core = core_;
  job.loop = loop_;
  job.generation = generation_;
  if (!options_.export_dir.empty() && cause != "left") {
    job.png =
        (std::filesystem::path(options_.export_dir) / ("blend-" + std::to_string(id_) + ".png"))
            .string();
  }
  job.to_runner = runner_ != kInvalidNodeId;
  job.runner_is_self = runner_ == id_;
  job.own_black = own_black_;
  job.blacks = blacks_;
  job.max_lift = options_.max_lift;
  job.neighbour_faces = neighbour_faces_;
  const double level = job.level;
  node.workers().Run<ComposedBlend>(
      [job = std::move(job)] { return ComposeAndShow(job); },
      [this, cause, peer, detected, level, noticed_by, &node](ComposedBlend shown) {
        OnBlendShown(node, cause, peer, detected, level, noticed_by, std::move(shown));
      });
}

// On a worker: the blend factor (and lift) at the level, sent on to the runner's export, shown,
// then the masks for each neighbour's leaving prepared in the renderer ahead of time.
BlendService::ComposedBlend BlendService::ComposeAndShow(const ComposeJob& job) {
  ComposedBlend out;
  const Clock::time_point start = Clock::now();
  cv::Mat factor, alpha, lift;
  {
    std::lock_guard<std::mutex> lock(job.core->mutex);
    if (!job.core->blender || job.core->generation != job.generation) {
      out.stale = true;
      return out;
    }
    const Blender& blender = *job.core->blender;
    const double fill = blender.options().fill_limit;
    out.own_faces = blender.FaceLevelBounds(job.level, fill);
    const FaceLevels faces = LowestFaceLevels(job.neighbour_faces, out.own_faces);
    out.faces_lower = faces.size();
    out.face_level_min = job.level;
    for (const auto& [face, l] : faces) out.face_level_min = std::min(out.face_level_min, l);
    factor = blender.Factor(job.level, fill, kInvalidNodeId, faces);
    if (!job.png.empty()) alpha = blender.Alpha();
    if (job.match) {
      out.black_peak = blender.BlackPeak(job.own_black, job.blacks);
      out.black_target = std::max(job.black_target, out.black_peak);
      lift = blender.Lift(out.black_target, job.own_black, job.blacks, job.max_lift);
      cv::minMaxLoc(lift, nullptr, &out.lift_max);
    }
  }
  out.compose_ms = MsSince(start);
  if (job.to_runner) {
    cv::Mat bytes;
    factor.convertTo(bytes, CV_8UC1, 255.0);
    out.width_px = bytes.cols;
    out.height_px = bytes.rows;
    std::vector<uchar> encoded;
    // zlib's fastest level: the masks are smooth and compress well at any level.
    if (job.runner_is_self) {
      out.alpha_values.assign(reinterpret_cast<const char*>(bytes.data), bytes.total());
    } else if (cv::imencode(".png", bytes, encoded, {cv::IMWRITE_PNG_COMPRESSION, 1})) {
      out.alpha_png.assign(encoded.begin(), encoded.end());
    }
  }
  if (!alpha.empty()) {
    cv::Mat picture;
    alpha.convertTo(picture, CV_8UC1, 255.0);
    if (Status written = io::WritePngFile(job.png, picture); !written.ok()) {
      ST_LOG(kWarning) << "blend: " << written.ToString();
    }
  }
  if (!job.loop) return out;
  uint64_t blend_generation = 0;
  Expected<int64_t> shown =
      job.loop->ShowBlend(factor, lift, std::chrono::seconds(10), &blend_generation);
  if (!shown.ok()) {
    out.status = shown.status();
    return out;
  }
  out.shown_ns = *shown;
  out.frame = job.loop->LastMaskFrame();
  // The masks for a neighbour leaving: the same composition without it (the level and the
  // black target as now), prepared in the renderer ahead of time.
  std::map<NodeId, std::pair<cv::Mat, cv::Mat>> standby;
  {
    std::lock_guard<std::mutex> lock(job.core->mutex);
    if (!job.core->blender || job.core->generation != job.generation) return out;
    const Blender& blender = *job.core->blender;
    const double fill = blender.options().fill_limit;
    for (NodeId left : blender.neighbours()) {
      std::pair<cv::Mat, cv::Mat>& masks = standby[left];
      const FaceLevels faces = LowestFaceLevels(
          job.neighbour_faces, blender.FaceLevelBounds(job.level, fill, left), left);
      masks.first = blender.Factor(job.level, fill, left, faces);
      if (job.match) {
        const double target =
            std::max(job.black_target, blender.BlackPeak(job.own_black, job.blacks, left));
        masks.second = blender.Lift(target, job.own_black, job.blacks, job.max_lift, left);
      }
    }
  }
  job.loop->PrepareBlends(blend_generation, std::move(standby));
  return out;
}

// On the network thread: the blend shown is told (a black peak, the faces' levels to the
// neighbours, the alpha to the runner's export) and reported.
void BlendService::OnBlendShown(NodeRuntime& node, const std::string& cause, NodeId peer,
                                Clock::time_point detected, double level, const char* noticed_by,
                                ComposedBlend shown) {
  if (shown.stale) return;
  if (!shown.status.ok()) {
    ST_LOG(kWarning) << "blend: " << shown.status.ToString();
    return;
  }
  if (shown.black_peak > 0) {
    black_peaks_[id_] = std::max(black_peaks_[id_], shown.black_peak);
    TellLevel(node);
  }
  if (!own_faces_ || *own_faces_ != shown.own_faces) {
    own_faces_ = std::move(shown.own_faces);
    for (NodeId to : sent_to_) SendShare(to, /*with_field=*/false, /*answer=*/false, node);
  }
  if (!shown.alpha_png.empty() || !shown.alpha_values.empty()) {
    pending_alpha_ = PendingAlpha{shown.width_px, shown.height_px, std::move(shown.alpha_png),
                                  std::move(shown.alpha_values), Clock::now()};
  }
  report::BlendShown line;
  line.id = id_;
  if (cause == "left") {
    line.reblend = true;
    line.cause = "left";
    line.peer = peer;
    line.detected_ns = SteadyNs(detected);
    if (noticed_by != nullptr) line.noticed_by = noticed_by;
  } else {
    line.cause = cause;
  }
  line.neighbours.assign(holding_.begin(), holding_.end());
  // The overlapping units whose field it does not hold yet (a blend still to come).
  if (neighbours_) {
    for (NodeId n : *neighbours_) {
      if (n != id_ && !holding_.count(n) && !dropped_.count(n)) line.waiting_for.push_back(n);
    }
  }
  line.level_per_m2 = level;
  // Faces shown below the level (walls met past the correction limit), the lowest.
  line.faces_below_level = shown.faces_lower;
  line.face_level_min_per_m2 = shown.face_level_min;
  if (shown.black_target > 0) {
    line.black_target_per_m2 = shown.black_target;
    line.lift_max = shown.lift_max;
  }
  line.compose_ms = shown.compose_ms;
  line.cast_ms = cast_ms_;
  line.shown_ns = shown.shown_ns;
  line.frame = {shown.frame.wait_ms, shown.frame.set_mask_ms, shown.frame.render_ms,
                shown.frame.read_ms, shown.frame.show_ms,     shown.frame.rewarped,
                shown.frame.late,    shown.frame.prepared};
  line.bytes_sent = bytes_sent_;
  line.bytes_received = bytes_received_;
  print_(line);
}

Status BlendServiceOptions::Check() const {
  ST_RETURN_IF_ERROR(blend.Check());
  if (peer_silence.count() <= 0 || ask_again.count() <= 0 || ask_again_max < ask_again ||
      alpha_quiet.count() < 0) {
    return InvalidArgumentError(
        "blend service: peer_silence, ask_again > 0; ask_again_max >= ask_again; alpha_quiet "
        ">= 0");
  }
  if (!(max_lift >= 0.0 && max_lift <= 1.0)) {
    return InvalidArgumentError("blend service: max_lift must be in [0, 1]");
  }
  return OkStatus();
}

}  // namespace sandtable::node
