#include "sim/app/world_server.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <set>

#include <opencv2/imgproc.hpp>

#include "common/base/bytes_hash.h"
#include "common/base/log.h"

namespace sandtable::sim {
namespace {

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

double NowS() { return static_cast<double>(NowNs()) * 1e-9; }

// A unit's fixed phase in [0, period): where its refreshes or exposures start.
double UnitPhase(NodeId id, double period_s, uint64_t salt) {
  const double golden = 0.6180339887498949;
  const double f =
      std::fmod(golden * static_cast<double>(id + 1) + 0.37 * static_cast<double>(salt), 1.0);
  return f * period_s;
}

uint64_t Mix(uint64_t z) {  // splitmix64 finaliser
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

}  // namespace

uint64_t CaptureSeed(uint64_t noise_seed, uint32_t camera_id, uint64_t capture_index) {
  return Mix(Mix(noise_seed + 0x9E3779B97F4A7C15ull * (camera_id + 1)) + capture_index);
}

Status WorldServerOptions::Check() const {
  if (bind_endpoint.empty()) return InvalidArgumentError("world server: empty bind endpoint");
  return limits.Check();
}

WorldServer::WorldServer(std::unique_ptr<World> world, WorldServerOptions options)
    : world_(std::move(world)), options_(std::move(options)) {
  ST_CHECK(world_ != nullptr) << "WorldServer needs a World";
  for (const UnitSpec& unit : world_->site().units) {
    const DeviceTiming& t = unit.timing;
    if (t.lag_frames > 0) {
      timelines_.emplace(unit.id, ProjectorTimeline(t, UnitPhase(unit.id, 1.0 / t.refresh_hz, 0)));
      history_s_ = std::max(history_s_, 0.1);
    }
    if (unit.camera && t.camera_fps > 0) {
      clocks_.emplace(unit.id, CameraClock(t, UnitPhase(unit.id, 1.0 / t.camera_fps, 1),
                                           CaptureSeed(options_.noise_seed, unit.id, 0)));
      history_s_ =
          std::max(history_s_, (t.queue_frames + 1) / t.camera_fps + t.camera_latency_s + 0.1);
    }
  }
}

WorldServer::~WorldServer() {
  if (monitor_) monitor_->Stop();
  channel_.reset();
  if (zap_) zap_->Stop();
}

Status WorldServer::Start() {
  if (!options_.frame_log_path.empty()) {
    frame_log_.open(options_.frame_log_path, std::ios::app);
    if (!frame_log_) {
      return InvalidArgumentError("--frame-log: cannot open " + options_.frame_log_path);
    }
  }
  ST_RETURN_IF_ERROR(options_.Check());
  net::SocketOptions socket_options;
  socket_options.max_message_bytes = static_cast<int64_t>(options_.limits.max_message_bytes);
  if (options_.curve) {
    zap_ = std::make_unique<net::ZapHandler>(&context_,
                                             std::set<std::string>{options_.curve->public_key_z85});
    ST_RETURN_IF_ERROR(zap_->Start());
    socket_options.curve = net::ServerCurve(*options_.curve);
  }
  Expected<std::unique_ptr<net::Socket>> router =
      net::Socket::Create(&context_, net::SocketType::kRouter, socket_options);
  if (!router.ok()) return router.status();
  if (options_.curve) {
    // A client without keys is dropped in the ZMTP greeting and never reaches ZAP: the monitor
    // is what logs and counts its refusal.
    monitor_ = std::make_unique<net::HandshakeMonitor>();
    ST_RETURN_IF_ERROR(monitor_->Attach(&context_, router->get(), "world"));
  }
  Expected<std::string> endpoint = (*router)->Bind(options_.bind_endpoint);
  if (!endpoint.ok()) return endpoint.status().WithContext("world: bind");
  endpoint_ = *endpoint;
  channel_ = std::make_unique<net::Channel>(std::move(*router), kWorldSenderId,
                                            net::NewIncarnation(), &counters_, options_.limits);
  // Refused messages are counted by the channel and answered by the loop (net/server_loop.h).
  loop_.Add(
      channel_.get(), [this](net::Incoming in) { HandleMessage(std::move(in)); },
      /*answer_refusals=*/true, [this](const net::Refusal&) { ++stats_.rejected; });
  return OkStatus();
}

Status WorldServer::Step(std::chrono::milliseconds max_wait) {
  ST_CHECK(channel_ != nullptr) << "WorldServer::Step before a successful Start()";
  std::chrono::milliseconds wait = max_wait;
  if (!pending_.empty()) {
    double next = pending_.front().ready_s;
    for (const PendingCapture& p : pending_) next = std::min(next, p.ready_s);
    const auto until = std::chrono::milliseconds(
        static_cast<int64_t>(std::ceil(std::max(0.0, next - NowS()) * 1000.0)));
    wait = std::min(wait, until);
  }
  ST_RETURN_IF_ERROR(loop_.RunOnce(wait));
  ServeDueCaptures();
  return OkStatus();
}

Status WorldServer::Run(const std::atomic<bool>& stop) {
  while (!stop.load()) ST_RETURN_IF_ERROR(Step(std::chrono::milliseconds(50)));
  return OkStatus();
}

void WorldServer::HandleMessage(net::Incoming message) {
  const std::string& routing_id = message.routing_id;
  const wire::Envelope& in = message.envelope;
  // Each message is counted once: accepted by the channel, or moved to invalid_content by
  // the handler that refuses its content.
  switch (in.body_case()) {
    case wire::Envelope::kSetFrameRequest:
      Reply(routing_id, SetFrame(in.set_frame_request()));
      break;
    case wire::Envelope::kCaptureRequest:
      if (std::optional<wire::Envelope> reply = Capture(routing_id, in.capture_request())) {
        Reply(routing_id, std::move(*reply));
      }
      break;
    case wire::Envelope::kGroundTruthRequest:
      SyncProjectors(NowS());
      Reply(routing_id, GroundTruth(in.ground_truth_request()));
      break;
    case wire::Envelope::kTopViewRequest:
      SyncProjectors(NowS());
      Reply(routing_id, TopView(in.top_view_request()));
      break;
    default:
      counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kWrongType);
      ++stats_.rejected;
      Reject(routing_id, in.sequence(),
             "the world does not serve " + proto::BodyName(in) +
                 " (set_frame_request, capture_request, ground_truth_request)");
      return;
  }
}

void WorldServer::Reply(const std::string& routing_id, wire::Envelope reply) {
  const Status sent = channel_->Send(std::move(reply), routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "reply not sent: " << sent.ToString();
}

void WorldServer::Reject(const std::string& routing_id, uint64_t sequence,
                         const std::string& reason) {
  wire::Envelope reply;
  reply.mutable_rejected()->set_rejected_sequence(sequence);
  reply.mutable_rejected()->set_reason(reason);
  Reply(routing_id, std::move(reply));
}

wire::Envelope WorldServer::SetFrame(const wire::SetFrameRequest& request) {
  wire::Envelope envelope;
  wire::SetFrameReply* reply = envelope.mutable_set_frame_reply();
  auto fail = [&](const std::string& message) {
    ++stats_.bad_requests;
    counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kInvalidContent);
    reply->set_ok(false);
    reply->set_message("set_frame projector " + std::to_string(request.projector_id()) + ": " +
                       message);
    return envelope;
  };
  int channels = 0;
  switch (request.encoding()) {
    case wire::PIXEL_ENCODING_GRAY8:
      channels = 1;
      break;
    case wire::PIXEL_ENCODING_RGB8:
      channels = 3;
      break;
    default:
      return fail("encoding must be GRAY8 or RGB8");
  }
  const UnitSpec* unit = world_->site().FindUnit(request.projector_id());
  if (!unit) return fail("no such projector in site '" + world_->site().name + "'");
  auto timeline = timelines_.find(request.projector_id());
  if (request.muted()) {  // the light cut; the frame it showed is kept for the next unmute
    if (timeline != timelines_.end()) {
      const double now = NowS();
      timeline->second.Send(now, cv::Mat(), false);
      timeline->second.ForgetBefore(now - history_s_);
      ++stats_.frames_set;
      reply->set_ok(true);
      return envelope;
    }
    const Status off = world_->SetProjectorOn(request.projector_id(), false);
    if (!off.ok()) return fail(off.message());
    ++stats_.frames_set;
    reply->set_ok(true);
    return envelope;
  }
  const uint64_t expected_bytes =
      uint64_t{request.width_px()} * request.height_px() * static_cast<uint64_t>(channels);
  if (request.pixels().size() != expected_bytes) {
    return fail(std::to_string(request.pixels().size()) + " pixel bytes for " +
                std::to_string(request.width_px()) + "x" + std::to_string(request.height_px()) +
                " x " + std::to_string(channels) + " (expected " + std::to_string(expected_bytes) +
                ")");
  }
  if (static_cast<int>(request.width_px()) != unit->projector.model.width_px ||
      static_cast<int>(request.height_px()) != unit->projector.model.height_px) {
    return fail("frame is " + std::to_string(request.width_px()) + "x" +
                std::to_string(request.height_px()) + ", projector is " +
                std::to_string(unit->projector.model.width_px) + "x" +
                std::to_string(unit->projector.model.height_px));
  }
  // Wraps the bytes (no copy); RGB on the wire, BGR for OpenCV.
  cv::Mat frame(static_cast<int>(request.height_px()), static_cast<int>(request.width_px()),
                channels == 1 ? CV_8UC1 : CV_8UC3, const_cast<char*>(request.pixels().data()));
  cv::Mat bgr;
  if (channels == 3) cv::cvtColor(frame, bgr, cv::COLOR_RGB2BGR);
  if (timeline != timelines_.end()) {  // on the table after the projector's lag
    const double now = NowS();
    timeline->second.Send(now, channels == 3 ? bgr : frame.clone(), true);
    timeline->second.ForgetBefore(now - history_s_);
  } else {
    const Status set =
        world_->SetProjectorFrame(request.projector_id(), channels == 3 ? bgr : frame);
    if (!set.ok()) return fail(set.message());
    if (Status on = world_->SetProjectorOn(request.projector_id(), true); !on.ok()) {
      return fail(on.message());
    }
  }
  ++stats_.frames_set;
  if (frame_log_.is_open()) {
    const uint64_t hash = HashBytes64(request.pixels().data(), request.pixels().size());
    char hex[17];
    std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(hash));
    const int64_t now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
    frame_log_ << "{\"projector\":" << request.projector_id()
               << ",\"frame_index\":" << request.frame_index() << ",\"hash\":\"" << hex
               << "\",\"time_ms\":" << now_ms << "}\n";
    frame_log_.flush();
  }
  reply->set_ok(true);
  return envelope;
}

wire::Envelope WorldServer::CaptureRefused(uint32_t camera_id, const std::string& message) {
  ++stats_.bad_requests;
  counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kInvalidContent);
  wire::Envelope envelope;
  wire::CaptureReply* reply = envelope.mutable_capture_reply();
  reply->set_camera_id(camera_id);
  reply->set_ok(false);
  reply->set_message("capture camera " + std::to_string(camera_id) + ": " + message);
  return envelope;
}

std::optional<wire::Envelope> WorldServer::Capture(const std::string& routing_id,
                                                   const wire::CaptureRequest& request) {
  auto fail = [&](const std::string& message) {
    return CaptureRefused(request.camera_id(), message);
  };
  const UnitSpec* unit = world_->site().FindUnit(request.camera_id());
  if (!unit || !unit->camera) return fail("no such camera in site '" + world_->site().name + "'");
  if (!std::isfinite(request.exposure_s()) || request.exposure_s() < 0.0 ||
      request.exposure_s() > 60.0) {
    return fail("exposure_s must be in [0, 60] (0 = the camera's own)");
  }
  const double now = NowS();
  auto clock = clocks_.find(request.camera_id());
  if (clock == clocks_.end()) return CaptureAt(request, now, false);
  const CameraClock::Read read = clock->second.Next(now);
  if (read.ready_s <= now) return CaptureAt(request, read.exposure_start_s, read.repeat);
  pending_.push_back({read.ready_s, routing_id, request, read.exposure_start_s, read.repeat});
  return std::nullopt;
}

void WorldServer::ServeDueCaptures() {
  while (!pending_.empty()) {
    const double now = NowS();
    auto due = std::min_element(
        pending_.begin(), pending_.end(),
        [](const PendingCapture& a, const PendingCapture& b) { return a.ready_s < b.ready_s; });
    if (due->ready_s > now) return;
    PendingCapture p = std::move(*due);
    pending_.erase(due);
    Reply(p.routing_id, CaptureAt(p.request, p.exposed_s, p.repeat));
  }
}

void WorldServer::SyncProjectors(double t_s) {
  for (auto& [id, timeline] : timelines_) {
    const ProjectorTimeline::Entry* e = timeline.At(t_s);
    const uint64_t version = e ? e->version : 0;
    uint64_t& loaded = loaded_version_[id];
    if (loaded == version) continue;
    // (Errors cannot come: the unit exists and the frame was checked when it was sent.)
    if (!e) {
      (void)world_->SetProjectorUniform(id, 0);
      (void)world_->SetProjectorOn(id, true);
    } else {
      if (!e->frame.empty()) (void)world_->SetProjectorFrame(id, e->frame);
      (void)world_->SetProjectorOn(id, e->on);
    }
    loaded = version;
  }
}

wire::Envelope WorldServer::CaptureAt(const wire::CaptureRequest& request, double exposed_s,
                                      bool repeat) {
  const UnitSpec* unit = world_->site().FindUnit(request.camera_id());
  const bool timed = !unit->timing.Ideal();
  SyncProjectors(exposed_s);
  double exposure_s = request.exposure_s();
  if (exposure_s == 0.0 && unit->timing.auto_exposure_drift > 0) {  // auto exposure, unlocked
    const double kTwoPi = 6.283185307179586;
    exposure_s = unit->camera->exposure_s *
                 (1.0 + unit->timing.auto_exposure_drift *
                            std::sin(kTwoPi * exposed_s / unit->timing.auto_exposure_period_s));
  }
  uint64_t& index = captures_per_camera_[request.camera_id()];
  const CaptureNoise noise{.enabled = options_.noise,
                           .seed = CaptureSeed(options_.noise_seed, request.camera_id(), index)};
  auto last = last_pictures_.find(request.camera_id());
  Expected<cv::Mat> image = repeat && last != last_pictures_.end()
                                ? Expected<cv::Mat>(last->second)
                                : world_->Capture(request.camera_id(), noise, exposure_s);
  if (!image.ok()) return CaptureRefused(request.camera_id(), image.status().message());
  if (timed) last_pictures_[request.camera_id()] = *image;
  ++index;
  ++stats_.captures;
  const bool eight_bit = image->depth() == CV_8U;
  wire::Envelope envelope;
  wire::CaptureReply* reply = envelope.mutable_capture_reply();
  reply->set_camera_id(request.camera_id());
  reply->set_ok(true);
  reply->set_width_px(static_cast<uint32_t>(image->cols));
  reply->set_height_px(static_cast<uint32_t>(image->rows));
  reply->set_bit_depth(static_cast<uint32_t>(unit->camera->bit_depth));
  reply->set_encoding(eight_bit ? wire::PIXEL_ENCODING_GRAY8 : wire::PIXEL_ENCODING_GRAY16);
  reply->set_capture_time_ns(static_cast<int64_t>(std::llround(exposed_s * 1e9)));
  std::string* pixels = reply->mutable_pixels();
  const size_t row_bytes = image->cols * image->elemSize();
  pixels->resize(row_bytes * image->rows);
  for (int y = 0; y < image->rows; ++y) {
    // GRAY16 is little endian on the wire; so is every machine this runs on (x86-64, arm64).
    std::memcpy(pixels->data() + y * row_bytes, image->ptr(y), row_bytes);
  }
  return envelope;
}

wire::Envelope WorldServer::GroundTruth(const wire::GroundTruthRequest& request) {
  wire::Envelope envelope;
  wire::GroundTruthReply* reply = envelope.mutable_ground_truth_reply();
  reply->set_projector_id(request.projector_id());
  auto fail = [&](const std::string& message) {
    ++stats_.bad_requests;
    counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kInvalidContent);
    reply->clear_samples();
    reply->set_ok(false);
    reply->set_message("ground_truth projector " + std::to_string(request.projector_id()) + ": " +
                       message);
    return envelope;
  };
  if (!world_->site().FindUnit(request.projector_id())) {
    return fail("no such projector in site '" + world_->site().name + "'");
  }
  for (int i = 0; i < request.points_in_table_m_size(); ++i) {
    const wire::Vector3& p = request.points_in_table_m(i);
    const Eigen::Vector3d point(p.x(), p.y(), p.z());
    if (!point.allFinite())
      return fail("points_in_table_m[" + std::to_string(i) + "] is not finite");
    Expected<ProjectorTruth> truth = world_->ProjectorTruthAtPoint(request.projector_id(), point);
    if (!truth.ok()) return fail(truth.status().message());
    wire::GroundTruthSample* sample = reply->add_samples();
    sample->set_projectable(truth->sample.projectable);
    if (truth->sample.projectable) {
      sample->mutable_projector_px()->set_x(truth->sample.pixel_px.x());
      sample->mutable_projector_px()->set_y(truth->sample.pixel_px.y());
    }
    sample->set_visible(truth->sample.visible);
    sample->set_luminance_cd_per_m2(truth->luminance_nits);
  }
  ++stats_.truth_queries;
  reply->set_ok(true);
  return envelope;
}

wire::Envelope WorldServer::TopView(const wire::TopViewRequest& request) {
  wire::Envelope envelope;
  wire::TopViewReply* reply = envelope.mutable_top_view_reply();
  auto fail = [&](const std::string& message) {
    ++stats_.bad_requests;
    counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kInvalidContent);
    reply->set_ok(false);
    reply->set_message("top_view: " + message);
    return envelope;
  };
  if (request.width_px() < 16 || request.width_px() > 4096) {
    return fail("width_px " + std::to_string(request.width_px()) + " is outside 16..4096");
  }
  if (request.projector_ids_size() > static_cast<int>(kMaxSiteUnits)) {
    return fail("more projectors than a site holds");
  }
  std::vector<NodeId> lit(request.projector_ids().begin(), request.projector_ids().end());
  for (NodeId id : lit) {
    if (!world_->site().FindUnit(id)) {
      return fail("no projector " + std::to_string(id) + " in site '" + world_->site().name + "'");
    }
  }
  Expected<View> view =
      View::TopOver(world_->scene().Bounds(), static_cast<int>(request.width_px()), 0);
  if (!view.ok()) return fail(view.status().message());
  Expected<std::vector<float>> luminance = world_->RenderLuminanceLit(*view, lit);
  if (!luminance.ok()) return fail(luminance.status().message());
  const Eigen::AlignedBox3d bounds = world_->scene().Bounds();
  reply->set_ok(true);
  reply->set_width_px(static_cast<uint32_t>(view->width_px()));
  reply->set_height_px(static_cast<uint32_t>(view->height_px()));
  reply->mutable_area_min_in_table_m()->set_x(bounds.min().x());
  reply->mutable_area_min_in_table_m()->set_y(bounds.min().y());
  reply->mutable_area_max_in_table_m()->set_x(bounds.max().x());
  reply->mutable_area_max_in_table_m()->set_y(bounds.max().y());
  reply->set_luminance(std::string(reinterpret_cast<const char*>(luminance->data()),
                                   luminance->size() * sizeof(float)));
  return envelope;
}

}  // namespace sandtable::sim
