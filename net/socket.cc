#include "net/socket.h"

#include <string>

namespace sandtable::net {
namespace {

zmq::socket_type ToZmq(SocketType type) {
  switch (type) {
    case SocketType::kRouter:
      return zmq::socket_type::router;
    case SocketType::kDealer:
      return zmq::socket_type::dealer;
    case SocketType::kPub:
      return zmq::socket_type::pub;
    case SocketType::kSub:
      return zmq::socket_type::sub;
    case SocketType::kPair:
      return zmq::socket_type::pair;
    case SocketType::kEventSubscriber:
      return zmq::socket_type::dealer;
  }
  return zmq::socket_type::pair;
}

Status FromZmq(const zmq::error_t& e, const std::string& what) {
  return UnavailableError(what + ": " + e.what() + " (errno " + std::to_string(e.num()) + ")");
}

}  // namespace

Status SocketOptions::Check() const {
  if (max_message_bytes <= 0) {
    return InvalidArgumentError("socket: max_message_bytes must be > 0");
  }
  if (curve.enabled) {
    if (curve.public_key_z85.size() != 40 || curve.secret_key_z85.size() != 40) {
      return InvalidArgumentError(
          "socket: CURVE enabled but own public/secret key is not 40 Z85 characters; "
          "check the site key file");
    }
    if (!curve.server && curve.server_key_z85.size() != 40) {
      return InvalidArgumentError("socket: CURVE client needs the server's public key");
    }
  }
  return OkStatus();
}

Expected<std::unique_ptr<Socket>> Socket::Create(zmq::context_t* context, SocketType type,
                                                 const SocketOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  try {
    zmq::socket_t socket(*context, ToZmq(type));
    socket.set(zmq::sockopt::maxmsgsize, options.max_message_bytes);
    socket.set(zmq::sockopt::linger, static_cast<int>(options.linger.count()));
    socket.set(zmq::sockopt::sndhwm, options.send_high_water_mark);
    socket.set(zmq::sockopt::rcvhwm, options.receive_high_water_mark);
    socket.set(zmq::sockopt::reconnect_ivl, static_cast<int>(options.reconnect_interval.count()));
    socket.set(zmq::sockopt::reconnect_ivl_max,
               static_cast<int>(options.reconnect_interval_max.count()));
    if (type == SocketType::kRouter) {
      // Fail sends to unknown routing ids instead of dropping them silently. No handover:
      // a connection claiming a routing id in use must not take over (forged membership).
      socket.set(zmq::sockopt::router_mandatory, 1);
      socket.set(zmq::sockopt::router_handover, 0);
    }
    if (type == SocketType::kEventSubscriber) {
      // The probe is written when a pipe is attached; with ZMQ_IMMEDIATE each connection (also
      // after the publisher restarts) gets a new pipe, so it subscribes again.
      socket.set(zmq::sockopt::probe_router, 1);
      socket.set(zmq::sockopt::immediate, 1);
    }
    if (!options.routing_id.empty()) socket.set(zmq::sockopt::routing_id, options.routing_id);
    if (type == SocketType::kSub && options.subscribe_all) socket.set(zmq::sockopt::subscribe, "");
    if (options.curve.enabled) {
      socket.set(zmq::sockopt::zap_domain, options.curve.zap_domain);
      socket.set(zmq::sockopt::curve_publickey, options.curve.public_key_z85);
      socket.set(zmq::sockopt::curve_secretkey, options.curve.secret_key_z85);
      if (options.curve.server) {
        socket.set(zmq::sockopt::curve_server, 1);
      } else {
        socket.set(zmq::sockopt::curve_serverkey, options.curve.server_key_z85);
      }
    }
    return std::unique_ptr<Socket>(new Socket(std::move(socket), type));
  } catch (const zmq::error_t& e) {
    return FromZmq(e, "socket: create/configure");
  }
}

Expected<std::string> Socket::Bind(const std::string& endpoint) {
  try {
    socket_.bind(endpoint);
    return socket_.get(zmq::sockopt::last_endpoint);
  } catch (const zmq::error_t& e) {
    return FromZmq(e, "socket: bind " + endpoint + " (address in use or malformed endpoint?)");
  }
}

Status Socket::Connect(const std::string& endpoint) {
  try {
    socket_.connect(endpoint);
    return OkStatus();
  } catch (const zmq::error_t& e) {
    return FromZmq(e, "socket: connect " + endpoint);
  }
}

Status Socket::Disconnect(const std::string& endpoint) {
  try {
    socket_.disconnect(endpoint);
    return OkStatus();
  } catch (const zmq::error_t& e) {
    return FromZmq(e, "socket: disconnect " + endpoint);
  }
}

Status Socket::Send(const std::vector<std::string>& frames) {
  if (frames.empty()) return InvalidArgumentError("socket: send of an empty multipart message");
  try {
    for (size_t i = 0; i < frames.size(); ++i) {
      zmq::send_flags flags = zmq::send_flags::dontwait;
      if (i + 1 < frames.size()) flags = flags | zmq::send_flags::sndmore;
      zmq::message_t message(frames[i].data(), frames[i].size());
      if (!socket_.send(message, flags)) {
        return UnavailableError("socket: send queue full (high water mark); message dropped");
      }
    }
    return OkStatus();
  } catch (const zmq::error_t& e) {
    if (e.num() == EHOSTUNREACH) {
      return NotFoundError("socket: routing id not connected (peer gone); message dropped");
    }
    return FromZmq(e, "socket: send");
  }
}

Expected<std::optional<std::vector<std::string>>> Socket::TryReceive(PeerInfo* peer) {
  try {
    std::vector<std::string> frames;
    zmq::message_t message;
    if (!socket_.recv(message, zmq::recv_flags::dontwait)) {
      return std::optional<std::vector<std::string>>();
    }
    frames.push_back(message.to_string());
    while (message.more()) {
      // The rest of a multipart message is already here (ZeroMQ delivers it atomically).
      if (!socket_.recv(message, zmq::recv_flags::none)) break;
      frames.push_back(message.to_string());
    }
    if (peer != nullptr) {
      // zmq_msg_gets, not message_t::gets: a property the connection lacks is NULL, not a throw.
      const char* user_id = zmq_msg_gets(message.handle(), "User-Id");
      const char* address = zmq_msg_gets(message.handle(), "Peer-Address");
      peer->user_id = user_id ? user_id : "";
      peer->address = address ? address : "";
    }
    return std::optional<std::vector<std::string>>(std::move(frames));
  } catch (const zmq::error_t& e) {
    return FromZmq(e, "socket: receive");
  }
}

Status Socket::Poll(const std::vector<Socket*>& sockets, std::chrono::milliseconds timeout,
                    std::vector<bool>* readable) {
  std::vector<zmq::pollitem_t> items;
  items.reserve(sockets.size());
  for (Socket* s : sockets) {
    items.push_back({static_cast<void*>(s->socket_), 0, ZMQ_POLLIN, 0});
  }
  readable->assign(sockets.size(), false);
  try {
    zmq::poll(items.data(), items.size(), timeout);
  } catch (const zmq::error_t& e) {
    if (e.num() == EINTR) return OkStatus();
    return FromZmq(e, "socket: poll");
  }
  for (size_t i = 0; i < items.size(); ++i) (*readable)[i] = (items[i].revents & ZMQ_POLLIN) != 0;
  return OkStatus();
}

}  // namespace sandtable::net
