// Socket: a ZeroMQ socket (cppzmq) whose failures come back as Status, never as exceptions.
//
// Every endpoint is a string ("tcp://127.0.0.1:*", "ipc:///tmp/x", "inproc://y"). Binding to
// port 0 or "*" lets the OS pick a free port; Bind() returns the real endpoint (from
// ZMQ_LAST_ENDPOINT), so many processes can run on one machine. ZMQ_MAXMSGSIZE is always set:
// a peer sending a larger message is disconnected by libzmq before we allocate it. A ROUTER
// never hands a connected routing id over to a new connection (ZMQ_ROUTER_HANDOVER off): a
// second connection claiming a routing id in use is ignored, so no process can take over
// another's connection (membership binds a member to its connection).
// Not thread-safe (ZeroMQ sockets belong to one thread).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <zmq.hpp>

#include "common/base/status.h"

namespace sandtable::net {

// kEventSubscriber: a DEALER that sends one empty message each time its connection is made
// (ZMQ_PROBE_ROUTER with ZMQ_IMMEDIATE, so also after a reconnection), the subscription that a
// net::EventPublisher's ROUTER registers (net/event_publisher.h). It receives the events as a SUB
// would, one frame each.
enum class SocketType { kRouter, kDealer, kPub, kSub, kPair, kEventSubscriber };

// CURVE settings of one socket (net/curve.h loads them from site key files). Keys are Z85
// text (40 characters).
struct CurveSettings {
  bool enabled = false;
  bool server = false;         // servers (binders) hold a secret key and authenticate clients
  std::string public_key_z85;  // own public key
  std::string secret_key_z85;  // own secret key
  std::string server_key_z85;  // clients: the server's public key
  std::string zap_domain = "sandtable";
};

struct SocketOptions {
  int64_t max_message_bytes = int64_t{64} << 20;  // ZMQ_MAXMSGSIZE
  std::chrono::milliseconds linger{0};            // pending messages are dropped on close
  int send_high_water_mark = 1000;
  int receive_high_water_mark = 1000;
  std::string routing_id;     // DEALER: identity the ROUTER sees (empty: random)
  bool subscribe_all = true;  // SUB: subscribe to every message
  // Reconnect interval after a peer goes away (libzmq retries forever).
  std::chrono::milliseconds reconnect_interval{50};
  std::chrono::milliseconds reconnect_interval_max{500};
  CurveSettings curve;

  Status Check() const;
};

class Socket {
 public:
  static Expected<std::unique_ptr<Socket>> Create(zmq::context_t* context, SocketType type,
                                                  const SocketOptions& options = {});

  // Binds; returns the endpoint peers must connect to (port resolved).
  Expected<std::string> Bind(const std::string& endpoint);
  Status Connect(const std::string& endpoint);
  Status Disconnect(const std::string& endpoint);

  // Sends a multipart message without blocking; UNAVAILABLE when the queue is full (high
  // water mark); NOT_FOUND, for ROUTER, when the routing id is not connected.
  Status Send(const std::vector<std::string>& frames);
  // Receives one multipart message if one is waiting (nullopt otherwise); never blocks.
  // `peer`, when given, gets what libzmq knows of the sender from its last frame: the ZAP
  // User-Id (the client's CURVE public key, net/curve.h) and its address (empty when unknown).
  struct PeerInfo {
    std::string user_id;
    std::string address;
  };
  Expected<std::optional<std::vector<std::string>>> TryReceive(PeerInfo* peer = nullptr);

  // Waits up to `timeout` for any of `sockets` to be readable; sets (*readable)[i]. Returns
  // OK also on timeout (all false) and on EINTR (a signal arrived: the caller checks it).
  static Status Poll(const std::vector<Socket*>& sockets, std::chrono::milliseconds timeout,
                     std::vector<bool>* readable);

  zmq::socket_t& raw() { return socket_; }
  SocketType type() const { return type_; }

 private:
  Socket(zmq::socket_t socket, SocketType type) : socket_(std::move(socket)), type_(type) {}
  zmq::socket_t socket_;
  SocketType type_;
};

}  // namespace sandtable::net
