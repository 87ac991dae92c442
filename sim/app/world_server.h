// WorldServer: the simulated world behind the project protocol (proto/world.proto in the
// Envelope, docs/protocol.md). One ROUTER socket serves any number of nodes; every request is
// answered to the identity that sent it, in arrival order (requests are serialised: the World
// is not thread-safe).
//
// Requests and replies:
//   SetFrameRequest    -> SetFrameReply      (GRAY8 or RGB8 frame at the projector's size)
//   CaptureRequest     -> CaptureReply       (GRAY8 for bit_depth <= 8, else GRAY16 LE)
//   GroundTruthRequest -> GroundTruthReply   (per point: true pixel, lit, luminance)
//   TopViewRequest -> TopViewReply           (the lab's top view with some projectors lit)
//   anything else      -> Rejected           (counted wrong_type)
// Bad requests never crash the server: an unknown projector or camera, a frame of the wrong
// size or encoding, pixels that do not match the announced size, non-finite points all get
// their reply with ok = false and a message naming the cause, and are counted (stats()
// .bad_requests, and MessageCounters kInvalidContent). A message that is not a valid Envelope
// (garbage, wrong version, out of order) is counted by reason and answered with Rejected when
// the sender's identity is known.
// CURVE (options.curve, `serve --curve-keys site.key`): the ROUTER is a CURVE server with the
// site key pair and a ZAP handler admits only clients holding the site key (net/curve.h), as
// the coordinator does; a client without CURVE or with another key gets no connection, and
// the refusal is logged (rate-limited by the handshake monitor) and counted. Without it any
// local process may ask the world for frames and captures.
// Noise: capture k (0, 1, 2, ...) of camera c uses the seed CaptureSeed(noise_seed, c, k), so a
// server run is reproducible for a request sequence.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <zmq.hpp>

#include "common/base/ids.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/handshake_monitor.h"
#include "net/server_loop.h"
#include "proto/codec.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"
#include "proto/sequence_tracker.h"
#include "sim/transport/device_clock.h"
#include "sim/transport/world.h"

namespace sandtable::sim {

struct WorldServerOptions {
  std::string bind_endpoint = "tcp://127.0.0.1:*";
  bool noise = true;
  uint64_t noise_seed = 1;
  proto::CodecLimits limits;
  std::optional<net::CurveKeyPair> curve;  // site keys: require CURVE from every client
  // Every frame a projector is given, one JSON line each (appended, flushed):
  // {"projector":N,"frame_index":I,"hash":"<HashBytes64 of the pixels, hex>","time_ms":T}
  // (T: system clock, ms since the epoch; common/base/bytes_hash.h). Empty: none.
  std::string frame_log_path;
  Status Check() const;
};

struct WorldServerStats {
  uint64_t frames_set = 0;
  uint64_t captures = 0;
  uint64_t truth_queries = 0;
  uint64_t bad_requests = 0;  // well-formed envelopes whose content was refused
  uint64_t rejected = 0;      // not a valid envelope, or a body the world does not serve
};

uint64_t CaptureSeed(uint64_t noise_seed, uint32_t camera_id, uint64_t capture_index);

class WorldServer {
 public:
  WorldServer(std::unique_ptr<World> world, WorldServerOptions options);
  ~WorldServer();

  // Binds the ROUTER; endpoint() then names the real port.
  Status Start();
  const std::string& endpoint() const { return endpoint_; }

  // Serves what arrives within `max_wait` (at most 1000 messages).
  Status Step(std::chrono::milliseconds max_wait);
  // Steps until `stop` becomes true (checked at least every 50 ms).
  Status Run(const std::atomic<bool>& stop);

  const WorldServerStats& stats() const { return stats_; }
  const proto::MessageCounters& counters() const { return counters_; }
  // CURVE clients admitted / refused by the ZAP handler (0 without CURVE).
  uint64_t curve_accepted() const { return zap_ ? zap_->accepted() : 0; }
  uint64_t curve_refused() const { return zap_ ? zap_->refused() : 0; }
  // Failed handshakes seen on the ROUTER (with CURVE: clients without keys, wrong keys).
  uint64_t failed_handshakes() const { return monitor_ ? monitor_->failed_handshakes() : 0; }
  World& world() { return *world_; }

 private:
  void HandleMessage(net::Incoming message);
  void Reply(const std::string& routing_id, wire::Envelope reply);
  void Reject(const std::string& routing_id, uint64_t sequence, const std::string& reason);
  wire::Envelope SetFrame(const wire::SetFrameRequest& request);
  // The reply, or nothing when the camera's next frame is not readable yet (a streaming
  // camera, sim/site/device_timing.h): it is then answered by Step() when it is.
  std::optional<wire::Envelope> Capture(const std::string& routing_id,
                                        const wire::CaptureRequest& request);
  // A capture refused (counted), its message naming the camera.
  wire::Envelope CaptureRefused(uint32_t camera_id, const std::string& message);
  // The picture exposed at `exposed_s` (the previous picture again when `repeat`).
  wire::Envelope CaptureAt(const wire::CaptureRequest& request, double exposed_s, bool repeat);
  // Loads into the world what each lagged projector has on the table at `t_s`.
  void SyncProjectors(double t_s);
  void ServeDueCaptures();
  wire::Envelope GroundTruth(const wire::GroundTruthRequest& request);
  wire::Envelope TopView(const wire::TopViewRequest& request);

  std::unique_ptr<World> world_;
  std::ofstream frame_log_;
  WorldServerOptions options_;
  zmq::context_t context_;
  std::unique_ptr<net::ZapHandler> zap_;
  std::unique_ptr<net::HandshakeMonitor> monitor_;
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> channel_;
  net::ServerLoop loop_;
  std::string endpoint_;
  std::map<uint32_t, uint64_t> captures_per_camera_;
  // Device timing: the timelines of projectors with a lag, the clocks of streaming cameras,
  // the pictures they last delivered (for repeats) and the reads waiting for a frame.
  struct PendingCapture {
    double ready_s = 0;
    std::string routing_id;
    wire::CaptureRequest request;
    double exposed_s = 0;
    bool repeat = false;
  };
  std::map<NodeId, ProjectorTimeline> timelines_;
  std::map<NodeId, uint64_t> loaded_version_;
  std::map<NodeId, CameraClock> clocks_;
  std::map<NodeId, cv::Mat> last_pictures_;
  std::vector<PendingCapture> pending_;
  double history_s_ = 0.0;  // how far back a read can look
  WorldServerStats stats_;
};

}  // namespace sandtable::sim
