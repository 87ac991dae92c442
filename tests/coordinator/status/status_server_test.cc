// The status endpoint through the sandtable-coordinator program with --status and --timeline
// (the HTTP server alone: http_status_server_test.cc).
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "net/channel.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/coordinator/status/http_exchange.h"
#include "tests/net/test_wait.h"

namespace sandtable::coordinator {
namespace {

using namespace std::chrono_literals;
constexpr auto kDeadline = 5000ms;

using testing::Body;
using testing::HttpExchange;
using testing::StatusLine;

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
  std::string error;
  const std::optional<nlohmann::json> ready =
      testing::ReadReadyLine(child, "sandtable-coordinator", kDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  fs::remove(tracks);
  // The endpoints, and the status URL with --status.
  EXPECT_FALSE(testing::ReadyString(*ready, "requests").empty()) << ready->dump();
  EXPECT_FALSE(testing::ReadyString(*ready, "events").empty()) << ready->dump();
  const std::string url = testing::ReadyString(*ready, "status");
  const std::string prefix = "http://127.0.0.1:";
  ASSERT_EQ(url.rfind(prefix, 0), 0u) << ready->dump();
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
  ASSERT_TRUE((*dealer)->Connect(testing::ReadyString(*ready, "requests")).ok());
  ASSERT_TRUE((*dealer)->Send({std::string("not an envelope")}).ok());
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        nlohmann::json d = nlohmann::json::parse(
            Body(HttpExchange(port, "GET /status HTTP/1.1\r\n\r\n")), nullptr, false);
        return !d.is_discarded() && d["messages"]["rejected_total"].get<uint64_t>() >= 1;
      },
      kDeadline));
  EXPECT_EQ(StatusLine(HttpExchange(port, "GET /pot HTTP/1.1\r\n\r\n")), "HTTP/1.1 404 Not Found");
  EXPECT_EQ(StatusLine(HttpExchange(port, "BREW /pot HTTP/1.1\r\n\r\n")),
            "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(StatusLine(HttpExchange(port, "\x16\x03\x01 tls?\r\n\r\n")),
            "HTTP/1.1 400 Bad Request");
  child.Signal(SIGTERM);
  EXPECT_EQ(child.Wait(), 0);
}

}  // namespace
}  // namespace sandtable::coordinator
