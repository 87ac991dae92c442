// The status endpoint through the sandtable-coordinator program with --status and --timeline
// (the HTTP server alone: http_status_server_test.cc).
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <vector>

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

std::string Post(const std::string& body, const std::string& token) {
  std::string request = "POST /api/action HTTP/1.1\r\nContent-Type: application/json\r\n";
  if (!token.empty()) request += "Authorization: Bearer " + token + "\r\n";
  return request + "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body;
}

nlohmann::json GetStatus(uint16_t port) {
  return nlohmann::json::parse(Body(HttpExchange(port, "GET /status HTTP/1.1\r\n\r\n")), nullptr,
                               false);
}

// A coordinator with its console on loopback and an operator token (its file removed once the
// coordinator read it).
struct TokenCoordinator {
  static inline const std::string kToken = "console-test-token-0123456789";
  std::unique_ptr<testing::ChildProcess> child;
  std::optional<nlohmann::json> ready;
  uint16_t port = 0;

  void Start(const std::string& name) {
    namespace fs = std::filesystem;
    const fs::path token_file = fs::temp_directory_path() / (name + std::to_string(::getpid()));
    {
      std::ofstream out(token_file);
      out << kToken << "\n";
    }
    fs::permissions(token_file, fs::perms::owner_read | fs::perms::owner_write);
    child = std::make_unique<testing::ChildProcess>(
        std::vector<std::string>{SANDTABLE_COORDINATOR_BIN, "--status", "127.0.0.1:0",
                                 "--status-token-file", token_file.string()});
    std::string error;
    ready = testing::ReadReadyLine(*child, "sandtable-coordinator", kDeadline, &error);
    ASSERT_TRUE(ready.has_value()) << error;
    fs::remove(token_file);
    const std::string url = testing::ReadyString(*ready, "status");
    port = static_cast<uint16_t>(std::stoi(url.substr(std::string("http://127.0.0.1:").size())));
  }
};

// The console through the program: a member's unit_status shows in the document with its state,
// the page's actions (with the operator token) become the coordinator's own requests and are
// answered with its verdict, and a member that leaves is shown lost.
TEST(StatusServerTest, ConsoleShowsUnitsAndItsActionsReachTheCoordinator) {
  TokenCoordinator site;
  ASSERT_NO_FATAL_FAILURE(site.Start("sandtable_console_token_"));
  const std::string& token = TokenCoordinator::kToken;
  const uint16_t port = site.port;
  const std::optional<nlohmann::json>& ready = site.ready;
  testing::ChildProcess& child = *site.child;

  // Node 7 joins and reports a footprint.
  zmq::context_t context;
  auto dealer = net::Socket::Create(&context, net::SocketType::kDealer);
  ASSERT_TRUE(dealer.ok());
  ASSERT_TRUE((*dealer)->Connect(testing::ReadyString(*ready, "requests")).ok());
  proto::MessageCounters counters;
  net::Channel node(std::move(*dealer), 7, 1, &counters);
  wire::Envelope hello;
  hello.mutable_hello()->set_role(wire::ROLE_NODE);
  hello.mutable_hello()->set_incarnation(1);
  hello.mutable_hello()->mutable_endpoints()->set_peer_router("tcp://127.0.0.1:45007");
  ASSERT_TRUE(node.Send(std::move(hello)).ok());
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        nlohmann::json d = GetStatus(port);
        return !d.is_discarded() && d["members"].size() == 1u;
      },
      kDeadline));
  wire::Envelope status;
  wire::UnitStatus* unit = status.mutable_unit_status();
  unit->set_calibration_state(wire::CALIBRATION_STATE_CALIBRATED);
  unit->set_phase("calibrated");
  unit->set_blended(true);
  unit->set_host_name("table-pc-7");
  for (const auto& [x, y] : {std::pair{-0.5, -0.3}, {0.5, -0.3}, {0.5, 0.3}, {-0.5, 0.3}}) {
    wire::Vector2* p = unit->add_footprint_m();
    p->set_x(x);
    p->set_y(y);
  }
  ASSERT_TRUE(node.Send(std::move(status)).ok());
  nlohmann::json doc;
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        doc = GetStatus(port);
        return !doc.is_discarded() && doc["units"].size() == 1u &&
               doc["units"][0]["state"] == "blending";
      },
      kDeadline))
      << doc.dump();
  EXPECT_EQ(doc["units"][0]["host_name"], "table-pc-7");
  EXPECT_EQ(doc["units"][0]["footprint_m"].size(), 4u);
  EXPECT_EQ(doc["members"][0]["state"], "blending");

  // Actions: with the token they reach the coordinator and come back with its verdict.
  std::string r =
      HttpExchange(port, Post(R"({"action":"test_pattern","pattern":"grid","node_id":7})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        doc = GetStatus(port);
        return !doc.is_discarded() && doc["test_patterns"]["nodes"].value("7", "") == "grid";
      },
      kDeadline))
      << doc.dump();
  // Recalibration: of the member, published as the site's ask; of a stranger, refused.
  r = HttpExchange(port, Post(R"({"action":"recalibrate","node_id":7})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        doc = GetStatus(port);
        return !doc.is_discarded() && doc["recalibration"].value("ask_id", 0) == 1 &&
               doc["recalibration"]["node_id"] == 7;
      },
      kDeadline))
      << doc.dump();
  r = HttpExchange(port, Post(R"({"action":"recalibrate","node_id":8})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 409 Conflict") << r;
  EXPECT_NE(Body(r).find("unit 8 is not a member"), std::string::npos) << r;
  r = HttpExchange(port, Post(R"({"action":"recalibrate","node_id":-1})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 400 Bad Request") << r;
  r = HttpExchange(port, Post(R"({"action":"test_pattern","pattern":"plaid"})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 409 Conflict") << r;
  EXPECT_NE(Body(r).find("plaid"), std::string::npos) << r;
  r = HttpExchange(port, Post(R"({"action":"timeline","op":"seek"})", token));
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 400 Bad Request") << r;
  EXPECT_NE(Body(r).find("value"), std::string::npos) << r;
  EXPECT_EQ(StatusLine(HttpExchange(port, Post("not json", token))), "HTTP/1.1 400 Bad Request");
  EXPECT_EQ(StatusLine(HttpExchange(port, Post(R"({"action":"annotations_clear"})", token))),
            "HTTP/1.1 200 OK");
  EXPECT_EQ(StatusLine(HttpExchange(port, Post(R"({"action":"annotations_clear"})", ""))),
            "HTTP/1.1 401 Unauthorized");

  // The member leaves: shown lost, with its last status.
  wire::Envelope bye;
  bye.mutable_goodbye()->set_reason("test");
  ASSERT_TRUE(node.Send(std::move(bye)).ok());
  EXPECT_TRUE(net::testing::WaitFor(
      [&] {
        doc = GetStatus(port);
        return !doc.is_discarded() && doc["units"].size() == 1u &&
               doc["units"][0]["state"] == "lost";
      },
      kDeadline))
      << doc.dump();
  EXPECT_EQ(doc["members"].size(), 0u);
  child.Signal(SIGTERM);
  EXPECT_EQ(child.Wait(), 0);
}

// Annotations from the console: a stroke drawn, the session exported, the stroke erased with
// the spot eraser, the exported session imported back, and bad bodies refused whole.
TEST(StatusServerTest, ConsoleDrawsErasesExportsAndImportsAnnotations) {
  TokenCoordinator site;
  ASSERT_NO_FATAL_FAILURE(site.Start("sandtable_console_notes_token_"));
  const std::string& token = TokenCoordinator::kToken;
  const uint16_t port = site.port;
  testing::ChildProcess& child = *site.child;
  auto strokes = [&] {
    const nlohmann::json d = GetStatus(port);
    return d.is_discarded() ? -1 : d["annotations"].value("strokes", -1);
  };
  auto act = [&](const nlohmann::json& body) {
    return HttpExchange(port, Post(body.dump(), token));
  };

  const nlohmann::json stroke = {
      {"action", "annotation_stroke"},
      {"color_rgb", {0.9, 0.2, 0.1}},
      {"width_m", 0.006},
      {"points_in_table_m", {{0.10, 0.20, 0.0}, {0.12, 0.20, 0.0}, {0.14, 0.21, 0.0}}}};
  std::string r = act(stroke);
  ASSERT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  EXPECT_TRUE(net::testing::WaitFor([&] { return strokes() == 1; }, kDeadline));

  r = act({{"action", "annotations_export"}});
  ASSERT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  const nlohmann::json exported = nlohmann::json::parse(Body(r), nullptr, false);
  ASSERT_FALSE(exported.is_discarded()) << r;
  EXPECT_EQ(exported["strokes"], 1);
  const std::string session = exported.value("session", "");
  EXPECT_NE(session.find("\"kind\":\"stroke_begin\""), std::string::npos) << session;
  EXPECT_NE(session.find("\"point_count\":3"), std::string::npos) << session;

  r = act({{"action", "annotation_erase"},
           {"center_in_table_m", {0.12, 0.20, 0.0}},
           {"radius_m", 0.1}});
  ASSERT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  EXPECT_TRUE(net::testing::WaitFor([&] { return strokes() == 0; }, kDeadline));

  r = act({{"action", "annotations_import"}, {"session", session}});
  ASSERT_EQ(StatusLine(r), "HTTP/1.1 200 OK") << r;
  EXPECT_NE(Body(r).find("1 stroke imported"), std::string::npos) << r;
  EXPECT_TRUE(net::testing::WaitFor([&] { return strokes() == 1; }, kDeadline));

  // Refused whole, nothing changed: a cut session, a colour out of range, no points.
  r = act({{"action", "annotations_import"}, {"session", session.substr(0, session.size() / 2)}});
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 400 Bad Request") << r;
  nlohmann::json bad = stroke;
  bad["color_rgb"] = {2, 0, 0};
  EXPECT_EQ(StatusLine(act(bad)), "HTTP/1.1 400 Bad Request");
  bad = stroke;
  bad["points_in_table_m"] = nlohmann::json::array();
  EXPECT_EQ(StatusLine(act(bad)), "HTTP/1.1 400 Bad Request");
  r = act({{"action", "annotation_erase"}, {"center_in_table_m", {0, 0, 0}}, {"radius_m", 9}});
  EXPECT_EQ(StatusLine(r), "HTTP/1.1 400 Bad Request") << r;
  EXPECT_EQ(strokes(), 1);
  child.Signal(SIGTERM);
  EXPECT_EQ(child.Wait(), 0);
}

}  // namespace
}  // namespace sandtable::coordinator
