// HandshakeMonitor: logs and counts refused connection attempts on a bound (server) socket.
//
// The ZAP handler (net/curve.h) sees only clients that speak CURVE; a client with no keys at
// all (NULL mechanism) is dropped by libzmq during the ZMTP greeting, before ZAP is asked.
// This monitor listens to the socket's handshake events (zmq_socket_monitor) and logs every
// failed handshake with its cause and the peer address, so each refusal is visible:
//   CURVE: refused connection on tcp://127.0.0.1:5555: security mechanism mismatch
//   (the client does not use CURVE)
// Attach it right after creating the socket, from the socket's own thread; it then runs in its
// own thread until Stop() (or the destructor), which must happen before the context closes.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>

#include <zmq.hpp>

#include "common/base/status.h"

namespace sandtable::net {

class Socket;

class HandshakeMonitor {
 public:
  HandshakeMonitor() = default;
  ~HandshakeMonitor();
  HandshakeMonitor(const HandshakeMonitor&) = delete;
  HandshakeMonitor& operator=(const HandshakeMonitor&) = delete;

  // `name` tags the log lines ("coordinator requests").
  Status Attach(zmq::context_t* context, Socket* socket, std::string name);
  void Stop();

  uint64_t failed_handshakes() const { return failed_.load(); }
  uint64_t succeeded_handshakes() const { return succeeded_.load(); }

 private:
  void Run();
  std::string name_;
  std::unique_ptr<zmq::socket_t> pair_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> failed_{0};
  std::atomic<uint64_t> succeeded_{0};
};

// Human-readable cause of a ZMQ_EVENT_HANDSHAKE_FAILED_* event and its value.
std::string DescribeHandshakeFailure(uint16_t event, uint32_t value);

}  // namespace sandtable::net
