#include "node/devices/world_link.h"

#include <limits>
#include <map>
#include <random>
#include <utility>

#include "common/base/log.h"
#include "net/socket.h"

namespace sandtable::node {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// How often a waiting request checks that its connection still stands.
constexpr milliseconds kLivenessSlice{50};

uint64_t NewIncarnation() {
  std::random_device device;
  return (uint64_t{device()} << 32) ^ device() ^
         static_cast<uint64_t>(Clock::now().time_since_epoch().count());
}

std::string Ms(milliseconds d) { return std::to_string(d.count()) + " ms"; }

std::string BodyCaseName(wire::Envelope::BodyCase body_case) {
  const google::protobuf::FieldDescriptor* field =
      wire::Envelope::descriptor()->FindFieldByNumber(static_cast<int>(body_case));
  return field ? field->name() : "reply";
}

}  // namespace

Status WorldLinkOptions::Check() const {
  if (endpoint.empty()) return InvalidArgumentError("world link: empty endpoint");
  if (!IsValidNodeId(node_id)) {
    return InvalidArgumentError("world link " + endpoint + ": node id " + std::to_string(node_id) +
                                " is not a valid node id (it is the sender id of requests)");
  }
  if (connect_timeout <= milliseconds(0) || reply_timeout <= milliseconds(0)) {
    return InvalidArgumentError("world link " + endpoint +
                                ": connect_timeout and reply_timeout must be > 0");
  }
  return limits.Check();
}

Expected<std::shared_ptr<WorldLink>> WorldLink::Connect(const WorldLinkOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::shared_ptr<WorldLink> link(new WorldLink(options));
  ST_RETURN_IF_ERROR(link->OpenSocket());
  return link;
}

Expected<std::shared_ptr<WorldLink>> WorldLink::Shared(const WorldLinkOptions& options) {
  static std::mutex registry_mutex;
  static std::map<std::pair<std::string, NodeId>, std::weak_ptr<WorldLink>> registry;
  std::lock_guard<std::mutex> lock(registry_mutex);
  std::weak_ptr<WorldLink>& slot = registry[{options.endpoint, options.node_id}];
  if (std::shared_ptr<WorldLink> existing = slot.lock()) return existing;
  Expected<std::shared_ptr<WorldLink>> link = Connect(options);
  if (link.ok()) slot = *link;
  return link;
}

WorldLink::~WorldLink() { channel_.reset(); }

Status WorldLink::OpenSocket() {
  channel_.reset();
  net::SocketOptions socket_options;
  socket_options.max_message_bytes = static_cast<int64_t>(options_.limits.max_message_bytes);
  if (options_.curve) socket_options.curve = net::ClientCurve(*options_.curve);
  Expected<std::unique_ptr<net::Socket>> socket =
      net::Socket::Create(&context_, net::SocketType::kDealer, socket_options);
  if (!socket.ok()) return socket.status().WithContext("world " + options_.endpoint);
  try {
    // Queue only on completed connections: "can send" then means "the world is connected".
    (*socket)->raw().set(zmq::sockopt::immediate, 1);
  } catch (const zmq::error_t& e) {
    return UnavailableError("world " + options_.endpoint + ": ZMQ_IMMEDIATE: " + e.what());
  }
  const Status connected = (*socket)->Connect(options_.endpoint);
  if (!connected.ok()) {
    return InvalidArgumentError("world " + options_.endpoint +
                                ": cannot connect (malformed endpoint? expected e.g. "
                                "tcp://127.0.0.1:5555): " +
                                connected.message());
  }
  proto::CodecLimits limits = options_.limits;
  if (!options_.compress_requests) {
    limits.compress_threshold_bytes = std::numeric_limits<size_t>::max();
  }
  channel_ = std::make_unique<net::Channel>(std::move(*socket), options_.node_id, NewIncarnation(),
                                            &counters_, limits);
  return OkStatus();
}

Expected<bool> WorldLink::WaitWritable(milliseconds timeout) {
  zmq::pollitem_t item{static_cast<void*>(channel_->socket().raw()), 0, ZMQ_POLLOUT, 0};
  try {
    zmq::poll(&item, 1, timeout);
  } catch (const zmq::error_t& e) {
    if (e.num() == EINTR) return false;
    return UnavailableError("world " + options_.endpoint + ": poll: " + e.what());
  }
  return (item.revents & ZMQ_POLLOUT) != 0;
}

void WorldLink::DiscardStale() {
  for (int i = 0; i < 1000; ++i) {  // bounded: a failing socket must not spin here
    Expected<std::optional<net::Incoming>> in = channel_->TryReceive();
    if (in.ok() && !in->has_value()) return;
    ST_LOG(kDebug) << "world " << options_.endpoint << ": discarded a stale message";
  }
}

net::ChannelStats WorldLink::stats() {
  std::lock_guard<std::mutex> lock(mutex_);
  return channel_ ? channel_->stats() : net::ChannelStats{};
}

Expected<wire::Envelope> WorldLink::Ask(wire::Envelope request,
                                        wire::Envelope::BodyCase reply_case) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string what = proto::BodyName(request);
  const std::string where = "world " + options_.endpoint;
  if (!channel_) ST_RETURN_IF_ERROR(OpenSocket());
  DiscardStale();

  // 1. A connection to queue the request on.
  Expected<bool> writable = WaitWritable(options_.connect_timeout);
  if (!writable.ok()) return writable.status();
  if (!*writable) {
    // Nothing was sent: the socket keeps connecting in the background for the next try.
    return UnavailableError(where + ": not reachable within " + Ms(options_.connect_timeout) +
                            " (is `sandtable-world serve` running there?" +
                            std::string(options_.curve ? " Is it served with the same --curve-keys?"
                                                       : " Does it require CURVE (--curve-keys)?") +
                            ")");
  }
  const Status sent = channel_->Send(std::move(request));
  if (!sent.ok()) {
    channel_.reset();
    return UnavailableError(where + ": " + what + " not sent: " + sent.message());
  }

  // 2. The reply, while the connection stands.
  const Clock::time_point deadline = Clock::now() + options_.reply_timeout;
  constexpr Clock::time_point kConnected = Clock::time_point::max();
  Clock::time_point lost_since = kConnected;  // when the connection was first seen gone
  while (Clock::now() < deadline) {
    std::vector<bool> readable;
    ST_RETURN_IF_ERROR(net::Socket::Poll({&channel_->socket()}, kLivenessSlice, &readable));
    if (readable[0]) {
      Expected<std::optional<net::Incoming>> in = channel_->TryReceive();
      if (!in.ok()) {
        ST_LOG(kDebug) << where << ": refused a message: " << in.status().ToString();
        continue;
      }
      if (!in->has_value()) continue;
      const wire::Envelope& reply = (*in)->envelope;
      if (reply.body_case() == reply_case) return std::move((*in)->envelope);
      if (reply.has_rejected()) {
        return InternalError(where + " rejected " + what + ": " + reply.rejected().reason());
      }
      ST_LOG(kDebug) << where << ": ignored " << proto::BodyName(reply) << " while waiting for "
                     << BodyCaseName(reply_case);
      continue;
    }
    // No reply yet: is the world still connected? (A dropped connection loses the request.)
    Expected<bool> connected = WaitWritable(milliseconds(0));
    if (!connected.ok()) return connected.status();
    if (*connected) {
      lost_since = kConnected;
    } else if (lost_since == kConnected) {
      lost_since = Clock::now();
    } else if (Clock::now() - lost_since >= options_.connect_timeout) {
      channel_.reset();
      return UnavailableError(where + ": went away while answering " + what +
                              " (connection lost for " + Ms(options_.connect_timeout) + ")");
    }
  }
  channel_.reset();
  return UnavailableError(where + ": no " + BodyCaseName(reply_case) + " to " + what + " within " +
                          Ms(options_.reply_timeout));
}

}  // namespace sandtable::node
