// Raw HTTP/1.1 over a loopback TCP socket for the status endpoint's tests: connect, send bytes
// exactly as given (malformed ones too), read until the server closes, all with deadlines.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <string>

namespace sandtable::testing {

constexpr std::chrono::milliseconds kHttpDeadline{5000};

// A TCP connection to host:port (IPv4; -1 on failure).
inline int ConnectTo(const std::string& host, uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  ::inet_pton(AF_INET, host.c_str(), &addr.sin_addr);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// A TCP connection to 127.0.0.1:port (-1 on failure).
inline int ConnectLoopback(uint16_t port) { return ConnectTo("127.0.0.1", port); }

// True when the server closes `fd` (EOF or reset) within `deadline`; what it sent is dropped.
inline bool ClosedByServerWithin(int fd, std::chrono::milliseconds deadline) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buffer[4096];
    if (::recv(fd, buffer, sizeof(buffer), 0) <= 0) return true;
  }
  return false;
}

// What the server sends on `fd` until it closes, kHttpDeadline passes, or (when given)
// `until_seen` has arrived (a stream the server keeps open).
inline std::string ReadFrom(int fd, const std::string& until_seen = "") {
  std::string got;
  const auto until = std::chrono::steady_clock::now() + kHttpDeadline;
  while (std::chrono::steady_clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 50) <= 0) continue;
    char buffer[4096];
    const ssize_t n = ::recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) break;
    got.append(buffer, static_cast<size_t>(n));
    if (!until_seen.empty() && got.find(until_seen) != std::string::npos) break;
  }
  return got;
}

// Sends `request` to host:port (loopback unless given) and returns what comes back until the
// server closes (empty on connection failure; what came before the deadline at the deadline).
inline std::string HttpExchange(uint16_t port, const std::string& request,
                                const std::string& host = "127.0.0.1") {
  const int fd = ConnectTo(host, port);
  if (fd < 0) return {};
  if (!request.empty()) (void)::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  std::string response = ReadFrom(fd);
  ::close(fd);
  return response;
}

inline std::string StatusLine(const std::string& response) {
  return response.substr(0, response.find("\r\n"));
}

inline std::string Body(const std::string& response) {
  const size_t b = response.find("\r\n\r\n");
  return b == std::string::npos ? std::string() : response.substr(b + 4);
}

}  // namespace sandtable::testing
