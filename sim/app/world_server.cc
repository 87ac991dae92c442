#include "sim/app/world_server.h"

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
  return loop_.RunOnce(max_wait);
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
      Reply(routing_id, Capture(in.capture_request()));
      break;
    case wire::Envelope::kGroundTruthRequest:
      Reply(routing_id, GroundTruth(in.ground_truth_request()));
      break;
    case wire::Envelope::kTopViewRequest:
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
  if (request.muted()) {  // the light cut; the frame it showed is kept for the next unmute
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
  const Status set = world_->SetProjectorFrame(request.projector_id(), channels == 3 ? bgr : frame);
  if (!set.ok()) return fail(set.message());
  if (Status on = world_->SetProjectorOn(request.projector_id(), true); !on.ok()) {
    return fail(on.message());
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

wire::Envelope WorldServer::Capture(const wire::CaptureRequest& request) {
  wire::Envelope envelope;
  wire::CaptureReply* reply = envelope.mutable_capture_reply();
  reply->set_camera_id(request.camera_id());
  auto fail = [&](const std::string& message) {
    ++stats_.bad_requests;
    counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kInvalidContent);
    reply->set_ok(false);
    reply->set_message("capture camera " + std::to_string(request.camera_id()) + ": " + message);
    return envelope;
  };
  const UnitSpec* unit = world_->site().FindUnit(request.camera_id());
  if (!unit || !unit->camera) return fail("no such camera in site '" + world_->site().name + "'");
  if (!std::isfinite(request.exposure_s()) || request.exposure_s() < 0.0 ||
      request.exposure_s() > 60.0) {
    return fail("exposure_s must be in [0, 60] (0 = the camera's own)");
  }
  uint64_t& index = captures_per_camera_[request.camera_id()];
  const CaptureNoise noise{.enabled = options_.noise,
                           .seed = CaptureSeed(options_.noise_seed, request.camera_id(), index)};
  Expected<cv::Mat> image = world_->Capture(request.camera_id(), noise, request.exposure_s());
  if (!image.ok()) return fail(image.status().message());
  ++index;
  ++stats_.captures;
  const bool eight_bit = image->depth() == CV_8U;
  reply->set_ok(true);
  reply->set_width_px(static_cast<uint32_t>(image->cols));
  reply->set_height_px(static_cast<uint32_t>(image->rows));
  reply->set_bit_depth(static_cast<uint32_t>(unit->camera->bit_depth));
  reply->set_encoding(eight_bit ? wire::PIXEL_ENCODING_GRAY8 : wire::PIXEL_ENCODING_GRAY16);
  reply->set_capture_time_ns(NowNs());
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
