#include "coordinator/status/http_status_server.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>

#include "common/base/log.h"

namespace sandtable::coordinator {
namespace {

constexpr size_t kMaxRequestBytes = 8192;
constexpr auto kRequestTimeout = std::chrono::seconds(2);
constexpr int kAcceptPollMs = 100;  // how often the loop checks stop_

void SendAll(int fd, const std::string& data) {
  size_t sent = 0;
  while (sent < data.size()) {
    const ssize_t n = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return;  // peer gone: nothing to do for a status page
    sent += static_cast<size_t>(n);
  }
}

std::string Response(int code, const char* reason, const std::string& content_type,
                     const std::string& body, bool head_only = false,
                     const std::string& extra_headers = {}) {
  std::string r = "HTTP/1.1 " + std::to_string(code) + " " + reason + "\r\n";
  r += "Content-Type: " + content_type + "\r\n";
  r += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  r += "Cache-Control: no-store\r\nConnection: close\r\n" + extra_headers + "\r\n";
  if (!head_only) r += body;
  return r;
}

}  // namespace

Expected<std::unique_ptr<HttpStatusServer>> HttpStatusServer::Start(const std::string& address) {
  std::string host = "127.0.0.1";
  std::string port_text = address;
  if (const size_t colon = address.rfind(':'); colon != std::string::npos) {
    host = address.substr(0, colon);
    port_text = address.substr(colon + 1);
  }
  char* end = nullptr;
  const long port = std::strtol(port_text.c_str(), &end, 10);
  if (port_text.empty() || *end != '\0' || port < 0 || port > 65535) {
    return InvalidArgumentError("status: '" + address +
                                "' is not PORT or IPv4:PORT (port 0..65535, 0: any free port)");
  }
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(port));
  if (::inet_pton(AF_INET, host.c_str(), &addr.sin_addr) != 1) {
    return InvalidArgumentError("status: '" + host + "' is not an IPv4 address (e.g. 127.0.0.1)");
  }
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return UnavailableError(std::string("status: socket(): ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 || ::listen(fd, 16) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd);
    return UnavailableError("status: cannot listen on " + host + ":" + port_text + ": " + why +
                            " (choose another port, or 0 for any free one)");
  }
  socklen_t length = sizeof(addr);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &length);
  return std::unique_ptr<HttpStatusServer>(new HttpStatusServer(fd, host, ntohs(addr.sin_port)));
}

HttpStatusServer::HttpStatusServer(int listen_fd, std::string host, uint16_t port)
    : listen_fd_(listen_fd), host_(std::move(host)), port_(port) {
  thread_ = std::thread([this] { Loop(); });
}

HttpStatusServer::~HttpStatusServer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  ::close(listen_fd_);
}

std::string HttpStatusServer::url() const {
  return "http://" + host_ + ":" + std::to_string(port_) + "/status";
}

void HttpStatusServer::Publish(std::string json) {
  std::lock_guard<std::mutex> lock(mutex_);
  document_ = std::move(json);
}

void HttpStatusServer::Loop() {
  while (!stop_.load()) {
    pollfd p{listen_fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, kAcceptPollMs);
    if (ready <= 0) continue;  // timeout or EINTR
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno != EINTR && errno != EAGAIN) {
        ST_LOG(kWarning) << "status: accept: " << std::strerror(errno);
      }
      continue;
    }
    Serve(fd);
    // Closing with unread input makes the kernel send RST, which can destroy the response
    // before the client reads it: half-close, then drain briefly until the client closes.
    ::shutdown(fd, SHUT_WR);
    for (int i = 0; i < 10; ++i) {
      pollfd p{fd, POLLIN, 0};
      char sink[4096];
      if (::poll(&p, 1, 20) <= 0 || ::recv(fd, sink, sizeof(sink), 0) <= 0) break;
    }
    ::close(fd);
  }
}

void HttpStatusServer::Serve(int fd) {
  // Read the request head (up to the blank line), bounded in size and time.
  std::string head;
  const auto until = std::chrono::steady_clock::now() + kRequestTimeout;
  bool complete = false;
  while (!complete && head.size() < kMaxRequestBytes && !stop_.load()) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        until - std::chrono::steady_clock::now());
    if (left.count() <= 0) break;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
    char buffer[1024];
    const ssize_t n = ::recv(fd, buffer, sizeof(buffer), 0);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    head.append(buffer, static_cast<size_t>(n));
    complete = head.find("\r\n\r\n") != std::string::npos || head.find("\n\n") != std::string::npos;
  }
  const std::string text = "text/plain; charset=utf-8";
  auto bad = [&](const std::string& why) {
    ++counters_.bad_request;
    SendAll(fd, Response(400, "Bad Request", text, "bad request: " + why + "\n"));
  };
  if (!complete)
    return bad(head.size() >= kMaxRequestBytes ? "request head over 8 KiB"
                                               : "incomplete request head");
  // Request line: METHOD SP TARGET SP HTTP/1.x
  const size_t eol = head.find_first_of("\r\n");
  const std::string line = head.substr(0, eol);
  const size_t s1 = line.find(' ');
  const size_t s2 = s1 == std::string::npos ? s1 : line.find(' ', s1 + 1);
  if (s1 == std::string::npos || s2 == std::string::npos || s1 == 0 || s2 == s1 + 1 ||
      line.find(' ', s2 + 1) != std::string::npos) {
    return bad("request line is not 'METHOD TARGET HTTP/1.1'");
  }
  const std::string method = line.substr(0, s1);
  std::string target = line.substr(s1 + 1, s2 - s1 - 1);
  const std::string version = line.substr(s2 + 1);
  if (version.rfind("HTTP/1.", 0) != 0 || version.size() != 8) {
    return bad("unsupported version '" + version.substr(0, 16) + "'");
  }
  for (char c : method) {
    if (c < 'A' || c > 'Z') return bad("method is not an HTTP token");
  }
  if (target.empty() || target.front() != '/') return bad("target must start with '/'");
  if (const size_t q = target.find('?'); q != std::string::npos) target.resize(q);
  if (target != "/status") {
    ++counters_.not_found;
    return SendAll(
        fd, Response(404, "Not Found", text, "not found: try GET /status\n", method == "HEAD"));
  }
  if (method != "GET" && method != "HEAD") {
    ++counters_.bad_request;
    return SendAll(fd, Response(405, "Method Not Allowed", text, "only GET /status\n", false,
                                "Allow: GET, HEAD\r\n"));
  }
  std::string document;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    document = document_;
  }
  ++counters_.ok;
  SendAll(fd, Response(200, "OK", "application/json", document + "\n", method == "HEAD"));
}

}  // namespace sandtable::coordinator
