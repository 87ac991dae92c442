// The status endpoint over real sockets: in-process HttpStatusServer (answers, malformed
// requests), and the sandtable-coordinator program with --status and --timeline.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "coordinator/status/http_status_server.h"
#include "net/channel.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/net/test_wait.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeadline = 5000ms;

// Sends `request` to 127.0.0.1:port and returns everything received until the server closes
// (empty on connection failure or deadline).
std::string HttpExchange(uint16_t port, const std::string& request) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  ::inet_pton(AF_INET, "127.0.0.1", &addr.sin_addr);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    ::close(fd);
    return {};
  }
  if (!request.empty()) (void)::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  std::string response;
  const auto until = std::chrono::steady_clock::now() + kDeadline;
  while (std::chrono::steady_clock::now() < until) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    char buffer[4096];
    const ssize_t n = ::recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) break;
    response.append(buffer, static_cast<size_t>(n));
  }
  ::close(fd);
  return response;
}

std::string StatusLine(const std::string& response) {
  return response.substr(0, response.find("\r\n"));
}
std::string Body(const std::string& response) {
  const size_t b = response.find("\r\n\r\n");
  return b == std::string::npos ? std::string() : response.substr(b + 4);
}

TEST(StatusServerTest, AnswersGetStatusAndRefusesEverythingElse) {
  Expected<std::unique_ptr<HttpStatusServer>> server = HttpStatusServer::Start("127.0.0.1:0");
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  HttpStatusServer& http = **server;
  ASSERT_NE(http.port(), 0);
  EXPECT_EQ(http.url(), "http://127.0.0.1:" + std::to_string(http.port()) + "/status");
  http.Publish(R"({"members":[],"answer":42})");

  std::string r = HttpExchange(http.port(), "GET /status HTTP/1.1\r\nHost: x\r\n\r\n");
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 200 OK");
  EXPECT_NE(r.find("Content-Type: application/json"), std::string::npos);
  nlohmann::json doc = nlohmann::json::parse(Body(r), nullptr, false);
  ASSERT_FALSE(doc.is_discarded()) << r;
  EXPECT_EQ(doc["answer"], 42);

  EXPECT_EQ(StatusLine(HttpExchange(http.port(), "GET /status?x=1 HTTP/1.0\r\n\r\n")),
            "HTTP/1.1 200 OK");
  EXPECT_EQ(StatusLine(HttpExchange(http.port(), "GET /metrics HTTP/1.1\r\n\r\n")),
            "HTTP/1.1 404 Not Found");
  EXPECT_EQ(StatusLine(HttpExchange(http.port(), "POST /status HTTP/1.1\r\n\r\n")),
            "HTTP/1.1 405 Method Not Allowed");
  // Malformed requests: 400, and the server keeps serving.
  for (const std::string bad :
       {std::string("garbage\r\n\r\n"), std::string("GET /status\r\n\r\n"),
        std::string("GET status HTTP/1.1\r\n\r\n"), std::string("GET /status SPDY/3\r\n\r\n"),
        std::string("G\x01T /status HTTP/1.1\r\n\r\n"), std::string(9000, 'A')}) {
    EXPECT_EQ(StatusLine(HttpExchange(http.port(), bad)), "HTTP/1.1 400 Bad Request")
        << bad.substr(0, 40);
  }
  // A client that connects and leaves without a request, and one that sends half a request.
  EXPECT_TRUE(StatusLine(HttpExchange(http.port(), "")).find("400") != std::string::npos);
  EXPECT_EQ(StatusLine(HttpExchange(http.port(), "GET /status HTTP/1.1\r\nHost")),
            "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(StatusLine(HttpExchange(http.port(), "GET /status HTTP/1.1\r\n\r\n")),
            "HTTP/1.1 200 OK");
  EXPECT_EQ(http.counters().ok.load(), 3u);
  EXPECT_EQ(http.counters().not_found.load(), 1u);
}

TEST(StatusServerTest, BadAddressesAreRefused) {
  EXPECT_EQ(HttpStatusServer::Start("localhost:x").status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(HttpStatusServer::Start("127.0.0.1:70000").status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(HttpStatusServer::Start("not-an-ip:0").status().code(), StatusCode::kInvalidArgument);
  // A port already in use.
  Expected<std::unique_ptr<HttpStatusServer>> first = HttpStatusServer::Start("0");
  ASSERT_TRUE(first.ok());
  Expected<std::unique_ptr<HttpStatusServer>> second =
      HttpStatusServer::Start(std::to_string((*first)->port()));
  EXPECT_EQ(second.status().code(), StatusCode::kUnavailable);
}

std::string FieldOf(const std::string& line, const std::string& key) {
  const size_t at = line.find(key + "=");
  if (at == std::string::npos) return {};
  const size_t end = line.find(' ', at);
  return line.substr(at + key.size() + 1,
                     end == std::string::npos ? end : end - at - key.size() - 1);
}

TEST(StatusServerTest, CoordinatorServesStatusWithTimelineAndRejectedCounters) {
  namespace fs = std::filesystem;
  const fs::path tracks =
      fs::temp_directory_path() / ("sandtable_status_test_" + std::to_string(::getpid()) + ".csv");
  {
    std::ofstream out(tracks);
    out << "track_id,t_s,x_m,y_m,z_m\n1,0,0,0,0\n1,10,1,0,0\n2,0,0,1,0\n2,20,0,2,0\n";
  }
  testing::ChildProcess child(
      {SANDTABLE_COORDINATOR_BIN, "--status", "127.0.0.1:0", "--timeline", tracks.string()});
  std::optional<std::string> line = child.ReadLine(kDeadline);
  ASSERT_TRUE(line.has_value()) << "coordinator printed nothing";
  fs::remove(tracks);
  // The existing fields are still there; status= is appended.
  EXPECT_FALSE(FieldOf(*line, "requests").empty()) << *line;
  EXPECT_FALSE(FieldOf(*line, "events").empty()) << *line;
  const std::string url = FieldOf(*line, "status");
  const std::string prefix = "http://127.0.0.1:";
  ASSERT_EQ(url.rfind(prefix, 0), 0u) << *line;
  const uint16_t port = static_cast<uint16_t>(std::stoi(url.substr(prefix.size())));

  nlohmann::json doc = nlohmann::json::parse(
      Body(HttpExchange(port, "GET /status HTTP/1.1\r\n\r\n")), nullptr, false);
  ASSERT_FALSE(doc.is_discarded());
  EXPECT_TRUE(doc["members"].is_array());
  EXPECT_EQ(doc["timeline"]["tracks"], 2);
  EXPECT_EQ(doc["timeline"]["duration_s"], 20.0);
  EXPECT_EQ(doc["timeline"]["playing"], false);
  EXPECT_TRUE(doc["annotations"].is_object());

  // A garbage message on the ROUTER is counted as rejected and shows up in the status.
  zmq::context_t context;
  auto dealer = net::Socket::Create(&context, net::SocketType::kDealer);
  ASSERT_TRUE(dealer.ok());
  ASSERT_TRUE((*dealer)->Connect(FieldOf(*line, "requests")).ok());
  ASSERT_TRUE((*dealer)->Send({std::string("not an envelope")}).ok());
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        nlohmann::json d = nlohmann::json::parse(
            Body(HttpExchange(port, "GET /status HTTP/1.1\r\n\r\n")), nullptr, false);
        return !d.is_discarded() && d["messages"]["rejected_total"].get<uint64_t>() >= 1;
      },
      kDeadline));
  EXPECT_EQ(StatusLine(HttpExchange(port, "BREW /pot HTTP/1.1\r\n\r\n")), "HTTP/1.1 404 Not Found");
  EXPECT_EQ(StatusLine(HttpExchange(port, "\x16\x03\x01 tls?\r\n\r\n")),
            "HTTP/1.1 400 Bad Request");
  child.Signal(SIGTERM);
  EXPECT_EQ(child.Wait(), 0);
}

}  // namespace
}  // namespace sandtable::coordinator
