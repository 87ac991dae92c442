#include "coordinator/status/http_status_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <memory>

// Only this file includes httplib.h. Its listen backlog (5) is compiled into Debian's
// libcpp-httplib, so a define here does not change it: HttpStatusServer::Start listens again on
// the bound socket with kListenBacklog.
#include <httplib.h>

#include "common/base/file_io.h"
#include "common/base/log.h"
#include "coordinator/console/assets.h"

namespace sandtable::coordinator {
namespace {

// Actions are small JSON but for an imported annotation session; refuse bigger bodies early.
constexpr size_t kMaxPayloadBytes = 8 * 1024 * 1024;
constexpr auto kStartDeadline = std::chrono::seconds(5);
const char* const kText = "text/plain; charset=utf-8";

struct Address {
  std::string host;
  int port = 0;
};

Expected<Address> ParseAddress(const std::string& address) {
  Address out{"127.0.0.1", 0};
  std::string port_text = address;
  if (const size_t colon = address.rfind(':'); colon != std::string::npos) {
    out.host = address.substr(0, colon);
    port_text = address.substr(colon + 1);
  }
  char* end = nullptr;
  const long port = std::strtol(port_text.c_str(), &end, 10);
  if (port_text.empty() || *end != '\0' || port < 0 || port > 65535) {
    return InvalidArgumentError("status: '" + address +
                                "' is not PORT or IPv4:PORT (port 0..65535, 0: any free port)");
  }
  in_addr parsed{};
  if (::inet_pton(AF_INET, out.host.c_str(), &parsed) != 1) {
    return InvalidArgumentError("status: '" + out.host +
                                "' is not an IPv4 address (e.g. 127.0.0.1)");
  }
  out.port = static_cast<int>(port);
  return out;
}

// SO_REUSEADDR only: httplib's default also sets SO_REUSEPORT, which would let a second
// server bind a port that is in use instead of failing.
void SocketOptions(int fd) {
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
}

std::string ErrorBody(int status) {
  switch (status) {
    case 404:
      return "not found: try GET / (the console) or GET /status\n";
    case 405:
      return "method not allowed here (see the Allow header)\n";
    case 413:
      return "request body too large\n";
    case 401:
      return "unauthorized: send Authorization: Bearer TOKEN (the site's operator token)\n";
    case 403:
      return "the console is read-only: the coordinator has no operator token "
             "(--status-token-file)\n";
    case 503:
      return "too many live streams open; close a console tab\n";
    default:
      return "bad request: not an HTTP/1.x request\n";
  }
}

// The paths served, and the methods each allows.
enum class Access { kPublic, kRead, kAction };
struct Route {
  const char* path;
  Access access;
  const char* allow;
};
constexpr Route kRoutes[] = {
    {"/", Access::kPublic, "GET, HEAD"},
    {"/console.js", Access::kPublic, "GET, HEAD"},
    {"/console.css", Access::kPublic, "GET, HEAD"},
    {"/status", Access::kRead, "GET, HEAD"},
    {"/events", Access::kRead, "GET"},
    {"/api/action", Access::kAction, "POST"},
};

const Route* FindRoute(const std::string& path) {
  for (const Route& r : kRoutes) {
    if (path == r.path) return &r;
  }
  return nullptr;
}

bool Allows(const Route& route, const std::string& method) {
  const std::string allow = route.allow;
  return method == "GET"    ? allow.find("GET") != std::string::npos
         : method == "HEAD" ? allow.find("HEAD") != std::string::npos
         : method == "POST" ? allow == "POST"
                            : false;
}

// Compares without an early exit, so the time taken does not tell how much of a guess matched.
bool SameToken(const std::string& a, const std::string& b) {
  unsigned diff = a.size() == b.size() ? 0u : 1u;
  for (size_t i = 0; i < a.size(); ++i) diff |= unsigned(a[i] ^ (i < b.size() ? b[i] : 0));
  return diff == 0;
}

constexpr uint64_t kMaxStatusTokenFileBytes = 4096;
constexpr size_t kMinStatusTokenChars = 16, kMaxStatusTokenChars = 256;

// Connects to the server, half-closes and waits until the server closes too: proof that its
// accept loop and a worker thread run (httplib creates its pool of worker_threads only once
// listening; on a loaded machine that took a second, and the first clients waited for it).
// Best effort: false at the deadline. No request is sent, so nothing is counted.
bool ProbeServing(const std::string& host, uint16_t port, std::chrono::milliseconds deadline) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return false;
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(port);
  if (::inet_pton(AF_INET, host == "0.0.0.0" ? "127.0.0.1" : host.c_str(), &address.sin_addr) !=
          1 ||
      ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
    ::close(fd);
    return false;
  }
  ::shutdown(fd, SHUT_WR);
  pollfd p{fd, POLLIN, 0};
  bool closed = false;
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (!closed && std::chrono::steady_clock::now() < until) {
    if (::poll(&p, 1, 50) <= 0) continue;
    char byte;
    closed = ::recv(fd, &byte, 1, 0) <= 0;
  }
  ::close(fd);
  return closed;
}

}  // namespace

bool IsLoopbackAddress(const std::string& address) {
  Expected<Address> parsed = ParseAddress(address);
  return parsed.ok() && parsed->host.rfind("127.", 0) == 0;
}

Expected<std::string> LoadStatusToken(const std::string& path) {
  Expected<std::string> text =
      ReadInputFile(path, kMaxStatusTokenFileBytes, "kMaxStatusTokenFileBytes");
  if (!text.ok()) return text.status().WithContext("status token");
  struct stat info {};
  if (::stat(path.c_str(), &info) == 0 && (info.st_mode & 077) != 0) {
    return InvalidArgumentError("status token " + path +
                                ": readable by group or others; chmod 600 it");
  }
  std::string token = *text;
  while (!token.empty() && (token.back() == '\n' || token.back() == '\r' || token.back() == ' ')) {
    token.pop_back();
  }
  bool printable = true;
  for (const char c : token) printable = printable && c > ' ' && c < 127;
  if (!printable || token.size() < kMinStatusTokenChars || token.size() > kMaxStatusTokenChars) {
    return InvalidArgumentError(
        "status token " + path + ": must be one line of " + std::to_string(kMinStatusTokenChars) +
        ".." + std::to_string(kMaxStatusTokenChars) + " printable characters without spaces");
  }
  return token;
}

Status HttpStatusOptions::Check() const {
  if (worker_threads < 1 || worker_threads > 256) {
    return InvalidArgumentError("status: worker_threads must be in [1, 256]");
  }
  if (read_timeout.count() <= 0 || write_timeout.count() <= 0 || keep_alive.count() <= 0) {
    return InvalidArgumentError("status: read_timeout, write_timeout and keep_alive must be > 0");
  }
  if (max_streams < 0 || max_streams >= worker_threads) {
    return InvalidArgumentError("status: max_streams must be in [0, worker_threads)");
  }
  return OkStatus();
}

Status HttpStatusServer::CheckAddress(const std::string& address) {
  Expected<Address> parsed = ParseAddress(address);
  return parsed.ok() ? OkStatus() : parsed.status();
}

Expected<std::unique_ptr<HttpStatusServer>> HttpStatusServer::Start(const std::string& address,
                                                                    HttpStatusOptions options) {
  Expected<Address> parsed = ParseAddress(address);
  if (!parsed.ok()) return parsed.status();
  if (Status valid = options.Check(); !valid.ok()) return valid;
  if (options.token.empty() && parsed->host.rfind("127.", 0) != 0) {
    return InvalidArgumentError("status: " + parsed->host +
                                " is beyond loopback; serving it needs a token "
                                "(--status-token-file), or bind 127.0.0.1");
  }
  auto server = std::make_unique<httplib::Server>();
  const int threads = options.worker_threads;
  server->new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  server->set_address_family(AF_INET);
  server->set_socket_options(SocketOptions);
  const auto seconds = [](std::chrono::milliseconds t) {
    return std::pair<time_t, time_t>(t.count() / 1000, (t.count() % 1000) * 1000);
  };
  server->set_read_timeout(seconds(options.read_timeout).first,
                           seconds(options.read_timeout).second);
  server->set_write_timeout(seconds(options.write_timeout).first,
                            seconds(options.write_timeout).second);
  // One request per connection ("Connection: close"); a connected client that never sends is
  // dropped after the keep-alive wait (whole seconds in httplib, at least 1).
  server->set_keep_alive_max_count(1);
  server->set_keep_alive_timeout(
      std::max<time_t>(1, std::chrono::ceil<std::chrono::seconds>(options.read_timeout).count()));
  server->set_payload_max_length(kMaxPayloadBytes);
  server->set_default_headers({{"Cache-Control", "no-store"}});

  // The listening socket, seen as it is made: SO_REUSEADDR (a restart binds again at once),
  // not httplib's SO_REUSEPORT, which would let a second process bind the same port and take a
  // share of its connections.
  auto listening_fd = std::make_shared<int>(-1);
  server->set_socket_options([listening_fd](socket_t sock) {
    int yes = 1;
    ::setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
    *listening_fd = sock;
  });
  int port = -1;
  if (parsed->port == 0) {
    port = server->bind_to_any_port(parsed->host);
  } else if (server->bind_to_port(parsed->host, parsed->port)) {
    port = parsed->port;
  }
  if (port <= 0) {
    return UnavailableError("status: cannot listen on " + parsed->host + ":" +
                            std::to_string(parsed->port) +
                            " (in use? choose another port, or 0 for any free one)");
  }
  // Listening again on a listening socket sets its backlog (Linux listen(2)).
  if (*listening_fd < 0 || ::listen(*listening_fd, kListenBacklog) != 0) {
    return UnavailableError("status: cannot set the listen backlog of " + parsed->host + ":" +
                            std::to_string(port) + " to " + std::to_string(kListenBacklog));
  }
  return std::unique_ptr<HttpStatusServer>(
      new HttpStatusServer(std::move(server), parsed->host, static_cast<uint16_t>(port), options));
}

HttpStatusServer::HttpStatusServer(std::unique_ptr<httplib::Server> server, std::string host,
                                   uint16_t port, const HttpStatusOptions& options)
    : server_(std::move(server)),
      host_(std::move(host)),
      port_(port),
      token_(options.token),
      max_streams_(options.max_streams),
      keep_alive_(options.keep_alive) {
  AddRoutes();
  thread_ = std::thread([this] {
    if (!server_->listen_after_bind()) ST_LOG(kWarning) << "status: the server stopped early";
  });
  // stop() is a no-op until the accept loop runs: wait for it, so ~HttpStatusServer can stop.
  const auto until = std::chrono::steady_clock::now() + kStartDeadline;
  while (!server_->is_running() && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  // Serving, not only listening, before Start() returns.
  if (!ProbeServing(host_, port_, kStartDeadline)) {
    ST_LOG(kWarning) << "status: " << url() << " did not answer a probe within "
                     << kStartDeadline.count() << " s";
  }
}

void HttpStatusServer::AddRoutes() {
  // Routing of its own before httplib's: the path decides 404 before the method decides 405,
  // a target that is not a path is a bad request, and access is decided per route.
  server_->set_pre_routing_handler([this](const httplib::Request& request,
                                          httplib::Response& response) {
    using Result = httplib::Server::HandlerResponse;
    if (request.path.empty() || request.path.front() != '/') {
      response.status = 400;
      return Result::Handled;
    }
    const Route* route = FindRoute(request.path);
    const bool has_token =
        !token_.empty() && SameToken(request.get_header_value("Authorization"), "Bearer " + token_);
    const bool loopback = request.remote_addr.rfind("127.", 0) == 0;
    if (route == nullptr) {
      // Nothing here to find for a client that may not read the site.
      response.status = has_token || loopback ? 404 : 401;
    } else if (!Allows(*route, request.method)) {
      response.status = 405;
      response.set_header("Allow", route->allow);
    } else if (route->access == Access::kRead && !has_token && !loopback) {
      response.status = 401;
    } else if (route->access == Access::kAction && !has_token) {
      response.status = token_.empty() ? 403 : 401;
    } else {
      return Result::Unhandled;
    }
    if (response.status == 401) response.set_header("WWW-Authenticate", "Bearer");
    return Result::Handled;
  });
  server_->Get("/status", [this](const httplib::Request&, httplib::Response& response) {
    ++counters_.ok;
    response.set_content(Document() + "\n", "application/json");
  });
  server_->Get("/", [this](const httplib::Request&, httplib::Response& response) {
    ++counters_.ok;
    response.set_content(console::kIndexHtml, "text/html; charset=utf-8");
  });
  server_->Get("/console.js", [this](const httplib::Request&, httplib::Response& response) {
    ++counters_.ok;
    response.set_content(console::kConsoleJs, "text/javascript; charset=utf-8");
  });
  server_->Get("/console.css", [this](const httplib::Request&, httplib::Response& response) {
    ++counters_.ok;
    response.set_content(console::kConsoleCss, "text/css; charset=utf-8");
  });
  server_->Get("/events", [this](const httplib::Request&, httplib::Response& response) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (open_streams_ >= max_streams_) {
        response.status = 503;
        return;
      }
      ++open_streams_;
    }
    ++counters_.streams;
    auto last = std::make_shared<uint64_t>(0);
    response.set_header("X-Accel-Buffering", "no");
    response.set_chunked_content_provider(
        "text/event-stream",
        [this, last](size_t, httplib::DataSink& sink) {
          std::string chunk;
          if (!StreamNext(last.get(), &chunk)) {
            sink.done();
            return true;
          }
          return sink.write(chunk.data(), chunk.size());
        },
        [this](bool) {
          std::lock_guard<std::mutex> lock(mutex_);
          --open_streams_;
        });
  });
  server_->Post("/api/action",
                [this](const httplib::Request& request, httplib::Response& response) {
                  ++counters_.actions;
                  const ActionResult result = Act(request.body);
                  response.status = result.http_status;
                  response.set_content(result.json + "\n", "application/json");
                });
  // Every answer >= 400 (ours above, and httplib's for requests it cannot parse) passes here;
  // an action's own answer (a JSON body saying why) is kept.
  server_->set_error_handler(httplib::Server::HandlerWithResponse(
      [this](const httplib::Request&, httplib::Response& response) {
        if (response.status == 404) {
          ++counters_.not_found;
        } else if (response.status == 401) {
          ++counters_.unauthorized;
        } else {
          ++counters_.bad_request;
        }
        if (response.get_header_value("Content-Type") == "application/json") {
          return httplib::Server::HandlerResponse::Unhandled;
        }
        response.set_content(ErrorBody(response.status), kText);
        return httplib::Server::HandlerResponse::Handled;
      }));
  server_->set_exception_handler(
      [](const httplib::Request&, httplib::Response& response, std::exception_ptr) {
        response.status = 500;
        response.set_content("internal error\n", kText);
      });
}

// The next chunk of a stream: the document when it changed since `last_version`, else a
// comment line after keep_alive (so a dead client is noticed). False when the server stops.
bool HttpStatusServer::StreamNext(uint64_t* last_version, std::string* out) {
  std::unique_lock<std::mutex> lock(mutex_);
  changed_.wait_for(lock, keep_alive_, [&] { return stopping_ || version_ != *last_version; });
  if (stopping_) return false;
  if (version_ == *last_version) {
    *out = ": nothing new\n\n";
    return true;
  }
  *last_version = version_;
  *out = "data: " + document_ + "\n\n";
  return true;
}

ActionResult HttpStatusServer::Act(const std::string& body) {
  ActionHandler handler;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    handler = action_handler_;
  }
  if (!handler) return {503, R"({"ok":false,"message":"actions are not served yet"})"};
  return handler(body);
}

void HttpStatusServer::SetActionHandler(ActionHandler handler) {
  std::lock_guard<std::mutex> lock(mutex_);
  action_handler_ = std::move(handler);
}

HttpStatusServer::~HttpStatusServer() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  server_->stop();
  if (thread_.joinable()) thread_.join();
}

std::string HttpStatusServer::url() const {
  return "http://" + host_ + ":" + std::to_string(port_) + "/status";
}

void HttpStatusServer::Publish(std::string json) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    document_ = std::move(json);
    ++version_;
  }
  changed_.notify_all();
}

std::string HttpStatusServer::Document() {
  std::lock_guard<std::mutex> lock(mutex_);
  return document_;
}

}  // namespace sandtable::coordinator
