// HttpStatusServer: the coordinator's HTTP side, served by cpp-httplib on its own threads: the
// status document (GET /status, JSON), its live stream (GET /events, server-sent events: the
// document each time it changes, at most every publish) and the operator's console (GET /, the
// page and its script and style, built into the program; docs/console.md), whose actions come
// back as POST /api/action with a JSON body and go to the ActionHandler.
//
// Answers: GET or HEAD of a known path (a query string is ignored) -> 200; another path -> 404;
// another method -> 405 (Allow); a request that is not HTTP/1.x (no version, a method HTTP does
// not define, a target not starting with '/', headers over 8 KiB, a head cut short by the read
// timeout) -> 400; a request line over 8 KiB -> 414; more than max_streams streams at once ->
// 503. Every response but a stream closes the connection.
//
// Concurrency: up to `worker_threads` clients (default 128) are served at once (one thread each,
// httplib's model; a stream holds one while open), so slow or held-open clients do not block
// the page as long as fewer than that many hold connections (tested: 50 held open and 8 slow
// clients, a real request answered within 1 s); a client silent for `read_timeout` (1 s) is
// dropped without an answer, one cut short in its head gets 400. Publish() is thread-safe.
// Never throws or aborts on input. Bind address: "PORT" (loopback) or "IPv4:PORT"; port 0 lets
// the OS choose, port() reports it.
//
// Access: the page, script and style hold no site data and are served to anyone who reaches the
// port. The document and the stream: to a client with the token ("Authorization: Bearer
// TOKEN"), or without it from loopback (127.0.0.0/8: read-only), else 401. Actions: only with
// the token, else 401 (403 when the server has no token: a read-only console). Without a token
// the server binds loopback only: Start() refuses any other address. The coordinator requires a
// token on a CURVE site (--status-token-file).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "common/base/status.h"

namespace httplib {
class Server;
}

namespace sandtable::coordinator {

// The status socket's listen backlog: a burst of connections (held-open clients, a scanner)
// while the accept loop is busy waits in the kernel's queue instead of being made to retry its
// SYN a second later (5, httplib's own, made 2 000 connects take 175 s).
inline constexpr int kListenBacklog = 1024;

struct HttpStatusCounters {
  std::atomic<uint64_t> ok{0};
  std::atomic<uint64_t> not_found{0};
  std::atomic<uint64_t> bad_request{0};   // every other 4xx answer (400, 405, ...)
  std::atomic<uint64_t> unauthorized{0};  // 401: no or wrong token
  std::atomic<uint64_t> actions{0};       // POST /api/action handed to the ActionHandler
  std::atomic<uint64_t> streams{0};       // GET /events streams opened
};

struct HttpStatusOptions {
  int worker_threads = 128;                       // kStatusWorkerThreads: clients at once
  std::chrono::milliseconds read_timeout{1000};   // per read of a request, and idle wait
  std::chrono::milliseconds write_timeout{2000};  // per write of a response
  std::string token;                              // empty: no token, loopback only
  int max_streams = 16;                           // GET /events open at once (then 503)
  std::chrono::milliseconds keep_alive{1000};     // a stream's comment line when nothing changed
  Status Check() const;
};

// Reads a status token file (--status-token-file): one line of 16..256 printable characters,
// the file at most 4 KiB and not readable by group or others (like an ssh key). INVALID_ARGUMENT
// / IO_ERROR / NOT_FOUND naming the file otherwise.
Expected<std::string> LoadStatusToken(const std::string& path);

// True when `address` ("PORT" or "IPv4:PORT") binds loopback only (127.0.0.0/8).
bool IsLoopbackAddress(const std::string& address);

// An operator's action (the body of POST /api/action) and what to answer: an HTTP status and a
// JSON body. Called on an HTTP thread; it may block (up to the handler's own deadline).
struct ActionResult {
  int http_status = 200;
  std::string json = "{}";
};
using ActionHandler = std::function<ActionResult(const std::string& body)>;

class HttpStatusServer {
 public:
  // OK when `address` is "PORT" or "IPv4:PORT" with PORT in 0..65535, else INVALID_ARGUMENT
  // saying what is expected (what --status checks before anything starts).
  static Status CheckAddress(const std::string& address);

  // Binds and starts serving. INVALID_ARGUMENT for a bad address or options, UNAVAILABLE when
  // the port cannot be bound (the message names it).
  static Expected<std::unique_ptr<HttpStatusServer>> Start(const std::string& address,
                                                           HttpStatusOptions options = {});
  ~HttpStatusServer();  // stops, waits for the requests in progress, joins
  HttpStatusServer(const HttpStatusServer&) = delete;
  HttpStatusServer& operator=(const HttpStatusServer&) = delete;

  uint16_t port() const { return port_; }
  std::string url() const;  // http://HOST:PORT/status

  // Replaces the document served at /status and sent to every stream (thread-safe; called by
  // the coordinator loop).
  void Publish(std::string json);

  // Where actions go (thread-safe). Without one, POST /api/action answers 503.
  void SetActionHandler(ActionHandler handler);

  const HttpStatusCounters& counters() const { return counters_; }

 private:
  HttpStatusServer(std::unique_ptr<httplib::Server> server, std::string host, uint16_t port,
                   const HttpStatusOptions& options);
  std::string Document();
  void AddRoutes();
  bool StreamNext(uint64_t* last_version, std::string* out);
  ActionResult Act(const std::string& body);

  std::unique_ptr<httplib::Server> server_;
  std::string host_;
  uint16_t port_;
  std::string token_;
  int max_streams_;
  std::chrono::milliseconds keep_alive_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::string document_ = "{}";
  uint64_t version_ = 0;
  bool stopping_ = false;
  int open_streams_ = 0;
  ActionHandler action_handler_;
  HttpStatusCounters counters_;
  std::thread thread_;
};

}  // namespace sandtable::coordinator
