#include "net/handshake_monitor.h"

#include <atomic>
#include <cstring>
#include <sstream>

#include "common/base/log.h"
#include "net/socket.h"

namespace sandtable::net {
namespace {

std::string UniqueMonitorEndpoint() {
  static std::atomic<uint64_t> counter{0};
  std::ostringstream s;
  s << "inproc://sandtable-handshake-monitor-" << counter.fetch_add(1);
  return s.str();
}

}  // namespace

std::string DescribeHandshakeFailure(uint16_t event, uint32_t value) {
  if (event == ZMQ_EVENT_HANDSHAKE_FAILED_AUTH) {
    std::ostringstream s;
    s << "authentication refused (ZAP status " << value << ")";
    return s.str();
  }
  if (event == ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL) {
    switch (value) {
      case ZMQ_PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH:
        return "security mechanism mismatch (the client does not use CURVE, or the server does "
               "not)";
      case ZMQ_PROTOCOL_ERROR_ZMTP_CRYPTOGRAPHIC:
        return "cryptographic error (the client holds the wrong server key)";
      default: {
        std::ostringstream s;
        s << "protocol error 0x" << std::hex << value;
        return s.str();
      }
    }
  }
  std::ostringstream s;
  s << "handshake failed (errno " << value << ": " << std::strerror(static_cast<int>(value)) << ")";
  return s.str();
}

HandshakeMonitor::~HandshakeMonitor() { Stop(); }

Status HandshakeMonitor::Attach(zmq::context_t* context, Socket* socket, std::string name) {
  name_ = std::move(name);
  const std::string endpoint = UniqueMonitorEndpoint();
  const int events = ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                     ZMQ_EVENT_HANDSHAKE_FAILED_AUTH | ZMQ_EVENT_HANDSHAKE_SUCCEEDED;
  if (zmq_socket_monitor(static_cast<void*>(socket->raw()), endpoint.c_str(), events) != 0) {
    return UnavailableError("handshake monitor for " + name_ + ": " + zmq_strerror(zmq_errno()));
  }
  try {
    pair_ = std::make_unique<zmq::socket_t>(*context, zmq::socket_type::pair);
    pair_->set(zmq::sockopt::linger, 0);
    pair_->connect(endpoint);
  } catch (const zmq::error_t& e) {
    pair_.reset();
    return UnavailableError("handshake monitor for " + name_ + ": " + e.what());
  }
  thread_ = std::thread([this] { Run(); });
  return OkStatus();
}

void HandshakeMonitor::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  pair_.reset();
}

void HandshakeMonitor::Run() {
  // Each event is two frames: 6 bytes (uint16 event id, uint32 value, native byte order) and
  // the peer's endpoint.
  while (!stop_) {
    try {
      zmq::pollitem_t item{static_cast<void*>(*pair_), 0, ZMQ_POLLIN, 0};
      zmq::poll(&item, 1, std::chrono::milliseconds(50));
      if (!(item.revents & ZMQ_POLLIN)) continue;
      zmq::message_t header;
      zmq::message_t address;
      if (!pair_->recv(header, zmq::recv_flags::none)) continue;
      if (header.more()) (void)pair_->recv(address, zmq::recv_flags::none);
      if (header.size() < 6) continue;
      uint16_t event = 0;
      uint32_t value = 0;
      std::memcpy(&event, header.data(), sizeof(event));
      std::memcpy(&value, static_cast<const char*>(header.data()) + 2, sizeof(value));
      if (event == ZMQ_EVENT_HANDSHAKE_SUCCEEDED) {
        ++succeeded_;
        continue;
      }
      ++failed_;
      ST_LOG(kWarning) << "CURVE: refused connection on " << name_ << " (" << address.to_string()
                       << "): " << DescribeHandshakeFailure(event, value);
    } catch (const zmq::error_t& e) {
      if (e.num() == ETERM) return;
      if (e.num() != EINTR) ST_LOG(kError) << "handshake monitor: " << e.what();
    }
  }
}

}  // namespace sandtable::net
