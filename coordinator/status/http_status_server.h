// HttpStatusServer: a minimal HTTP/1.1 server on a POSIX socket, its own thread, serving one
// JSON document at GET /status (for operators' dashboards and curl).
//
// Answers: GET or HEAD /status (a query string is ignored) -> 200 application/json with the
// latest document given to Publish(); another path -> 404; another method -> 405; a request
// line that is not "METHOD SP TARGET SP HTTP/1.x", headers over 8 KiB or not complete within
// 2 s -> 400. Every response closes the connection. One connection at a time (a status page,
// not a web server). Never throws or aborts on input; socket errors are logged and the loop
// goes on. Bind address: "PORT" (loopback) or "IPv4:PORT"; port 0 lets the OS choose, port()
// reports it.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "common/base/status.h"

namespace sandtable::coordinator {

struct HttpStatusCounters {
  std::atomic<uint64_t> ok{0};
  std::atomic<uint64_t> not_found{0};
  std::atomic<uint64_t> bad_request{0};
};

class HttpStatusServer {
 public:
  // Binds and starts the thread. INVALID_ARGUMENT for a bad address, UNAVAILABLE when the
  // port cannot be bound (the message names it).
  static Expected<std::unique_ptr<HttpStatusServer>> Start(const std::string& address);
  ~HttpStatusServer();  // stops and joins the thread
  HttpStatusServer(const HttpStatusServer&) = delete;
  HttpStatusServer& operator=(const HttpStatusServer&) = delete;

  uint16_t port() const { return port_; }
  std::string url() const;  // http://HOST:PORT/status

  // Replaces the document served at /status (thread-safe; called by the coordinator loop).
  void Publish(std::string json);

  const HttpStatusCounters& counters() const { return counters_; }

 private:
  HttpStatusServer(int listen_fd, std::string host, uint16_t port);
  void Loop();
  void Serve(int fd);

  int listen_fd_;
  std::string host_;
  uint16_t port_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  std::string document_ = "{}";
  HttpStatusCounters counters_;
  std::thread thread_;
};

}  // namespace sandtable::coordinator
