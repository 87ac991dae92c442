// WorldLink: a node's request/reply connection to `sandtable-world serve` (proto/world.proto
// inside the Envelope, docs/protocol.md). One DEALER socket (net::Socket + net::Channel) whose
// envelopes carry the node's id as sender id; the world's ROUTER answers each request to the
// socket that sent it. A node's projector and camera share one link (Shared()), so the world
// sees one sender with one sequence.
//
// Deadlines, so that a dead world is a clear UNAVAILABLE and never a hang:
//   - connect_timeout: the socket is opened with ZMQ_IMMEDIATE, so a request can only be
//     queued on a completed connection; no connection within connect_timeout is UNAVAILABLE
//     ("not reachable"). The same bound applies when the connection drops while waiting for
//     a reply (the world died): UNAVAILABLE ("went away") within about connect_timeout.
//   - reply_timeout: a connected world that does not answer in time is UNAVAILABLE. The first
//     capture of a camera builds the world's transport map, which can take seconds on a large
//     site: hence a generous default.
// After a deadline the socket is replaced by a fresh one (new routing id and incarnation), so a
// late reply can never be taken for the answer to a later request.
//
// CURVE (options.curve, the site key pair): the DEALER is a CURVE client with the site key as
// its own pair and as the world's server key (net::ClientCurve), for a world served with
// `serve --curve-keys`. Against a world with another key, or a CURVE world without keys, the
// handshake never completes: the request is UNAVAILABLE ("not reachable") after
// connect_timeout, the message naming CURVE as a possible cause.
//
// Threading: Ask() is serialised by a mutex; one request is in flight at a time.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <zmq.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "net/channel.h"
#include "net/curve.h"
#include "proto/codec.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"

namespace sandtable::node {

struct WorldLinkOptions {
  std::string endpoint;             // the world's ROUTER, e.g. "tcp://127.0.0.1:5555"
  NodeId node_id = kInvalidNodeId;  // sender id of every request (a valid node id)
  std::chrono::milliseconds connect_timeout{2000};
  std::chrono::milliseconds reply_timeout{60000};
  proto::CodecLimits limits;
  // Deflate large requests (limits.compress_threshold_bytes). Off: what the node sends the world
  // that is large is its projector frames (3 MB at 1280x800), to a world on the same machine; zlib
  // at level 1 cost ~15-20 ms a frame between the node's deflate and the world's inflate on this
  // 2-core machine, most of a frame's show time (docs/render.md).
  bool compress_requests = false;
  std::optional<net::CurveKeyPair> curve;  // site keys: connect with CURVE

  Status Check() const;
};

class WorldLink {
 public:
  // Opens the socket and starts connecting (libzmq connects in the background, so this does
  // not wait for the world). INVALID_ARGUMENT for bad options or a malformed endpoint.
  static Expected<std::shared_ptr<WorldLink>> Connect(const WorldLinkOptions& options);
  // The process's link for (endpoint, node_id) while anyone holds it, else a new one (made
  // with `options`; a link already open keeps the options it was made with).
  static Expected<std::shared_ptr<WorldLink>> Shared(const WorldLinkOptions& options);

  ~WorldLink();
  WorldLink(const WorldLink&) = delete;
  WorldLink& operator=(const WorldLink&) = delete;

  // Sends `request` (its body set) and returns the world's reply whose body is `reply_case`.
  // UNAVAILABLE when the world is not reachable, goes away, or does not answer in time;
  // INTERNAL when it answers Rejected (the reason is in the message).
  Expected<wire::Envelope> Ask(wire::Envelope request, wire::Envelope::BodyCase reply_case);
  // Bytes and messages sent on the current connection (reset when a deadline reopens it).
  net::ChannelStats stats();

  const std::string& endpoint() const { return options_.endpoint; }
  NodeId node_id() const { return options_.node_id; }
  const WorldLinkOptions& options() const { return options_; }

 private:
  explicit WorldLink(WorldLinkOptions options) : options_(std::move(options)) {}
  Status OpenSocket();
  // Waits up to `timeout` until a request can be queued on a connection.
  Expected<bool> WaitWritable(std::chrono::milliseconds timeout);
  void DiscardStale();

  WorldLinkOptions options_;
  std::mutex mutex_;
  zmq::context_t context_{1};
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> channel_;  // null after a deadline until the next Ask()
};

}  // namespace sandtable::node
