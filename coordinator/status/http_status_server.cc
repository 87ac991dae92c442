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

namespace sandtable::coordinator {
namespace {

constexpr size_t kMaxPayloadBytes = 64 * 1024;  // bodies are never read; refuse big ones early
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
      return "not found: try GET /status\n";
    case 405:
      return "only GET /status\n";
    case 413:
      return "request body too large\n";
    case 401:
      return "unauthorized: send Authorization: Bearer TOKEN\n";
    default:
      return "bad request: not an HTTP/1.x request for GET /status\n";
  }
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
  if (read_timeout.count() <= 0 || write_timeout.count() <= 0) {
    return InvalidArgumentError("status: read_timeout and write_timeout must be > 0");
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
  return std::unique_ptr<HttpStatusServer>(new HttpStatusServer(
      std::move(server), parsed->host, static_cast<uint16_t>(port), std::move(options.token)));
}

HttpStatusServer::HttpStatusServer(std::unique_ptr<httplib::Server> server, std::string host,
                                   uint16_t port, std::string token)
    : server_(std::move(server)), host_(std::move(host)), port_(port), token_(std::move(token)) {
  // Routing of its own before httplib's: the path decides 404 before the method decides 405,
  // and a target that is not a path is a bad request.
  server_->set_pre_routing_handler(
      [this](const httplib::Request& request, httplib::Response& response) {
        using Result = httplib::Server::HandlerResponse;
        if (!token_.empty() &&
            !SameToken(request.get_header_value("Authorization"), "Bearer " + token_)) {
          response.status = 401;
          response.set_header("WWW-Authenticate", "Bearer");
          return Result::Handled;
        }
        if (request.path.empty() || request.path.front() != '/') {
          response.status = 400;
          return Result::Handled;
        }
        if (request.path != "/status") {
          response.status = 404;
          return Result::Handled;
        }
        if (request.method != "GET" && request.method != "HEAD") {
          response.status = 405;
          response.set_header("Allow", "GET, HEAD");
          return Result::Handled;
        }
        return Result::Unhandled;
      });
  server_->Get("/status", [this](const httplib::Request&, httplib::Response& response) {
    ++counters_.ok;
    response.set_content(Document() + "\n", "application/json");
  });
  // Every answer >= 400 (ours above, and httplib's for requests it cannot parse) passes here.
  server_->set_error_handler(httplib::Server::HandlerWithResponse(
      [this](const httplib::Request&, httplib::Response& response) {
        if (response.status == 404) {
          ++counters_.not_found;
        } else if (response.status == 401) {
          ++counters_.unauthorized;
        } else {
          ++counters_.bad_request;
        }
        response.set_content(ErrorBody(response.status), kText);
        return httplib::Server::HandlerResponse::Handled;
      }));
  server_->set_exception_handler(
      [](const httplib::Request&, httplib::Response& response, std::exception_ptr) {
        response.status = 500;
        response.set_content("internal error\n", kText);
      });
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

HttpStatusServer::~HttpStatusServer() {
  server_->stop();
  if (thread_.joinable()) thread_.join();
}

std::string HttpStatusServer::url() const {
  return "http://" + host_ + ":" + std::to_string(port_) + "/status";
}

void HttpStatusServer::Publish(std::string json) {
  std::lock_guard<std::mutex> lock(mutex_);
  document_ = std::move(json);
}

std::string HttpStatusServer::Document() {
  std::lock_guard<std::mutex> lock(mutex_);
  return document_;
}

}  // namespace sandtable::coordinator
