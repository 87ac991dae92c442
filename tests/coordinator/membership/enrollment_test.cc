// First-time acceptance of a unit (coordinator/membership/enrollment_desk.h,
// net/site_enrollment.h): the desk's rules, then the whole exchange over real CURVE sockets
// against a CoordinatorServer on its own thread.
#include <sys/stat.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "common/base/ids.h"
#include "coordinator/membership/coordinator_server.h"
#include "coordinator/membership/enrollment_desk.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/server_loop.h"
#include "net/site_enrollment.h"
#include "net/socket.h"

namespace sandtable {
namespace {

using coordinator::EnrollmentDesk;
using coordinator::EnrollmentDeskOptions;
using coordinator::EnrollState;
using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

constexpr milliseconds kReplyDeadline{5000};  // a reply on loopback, on a loaded CI machine
constexpr milliseconds kEnrollDeadline{20000};

std::string NewKey() {
  Expected<net::CurveKeyPair> keys = net::GenerateCurveKeyPair();
  EXPECT_TRUE(keys.ok());
  return keys.ok() ? keys->public_key_z85 : "";
}

TEST(EnrollmentDeskTest, AUnitWaitsUntilTheOperatorDecidesByItsFingerprintOrKey) {
  EnrollmentDesk desk;
  const Clock::time_point t0 = Clock::now();
  const std::string a = NewKey(), b = NewKey();
  ASSERT_EQ(*desk.OnRequest(a, "pc-4", "10.0.0.14", 4, t0), EnrollState::kPending);
  ASSERT_EQ(*desk.OnRequest(b, "pc-5", "10.0.0.15", 5, t0), EnrollState::kPending);
  EXPECT_EQ(*desk.OnRequest(a, "pc-4", "10.0.0.14", 4, t0 + milliseconds(1000)),
            EnrollState::kPending);
  EXPECT_EQ(desk.pending(), 2u);

  Expected<coordinator::EnrollingUnit> accepted =
      desk.Accept(net::KeyFingerprint(a), t0 + milliseconds(1500));
  ASSERT_TRUE(accepted.ok()) << accepted.status().ToString();
  EXPECT_EQ(accepted->host_name, "pc-4");
  EXPECT_EQ(accepted->requests, 2u);
  EXPECT_EQ(*desk.OnRequest(a, "pc-4", "10.0.0.14", 4, t0 + milliseconds(2000)),
            EnrollState::kAccepted);
  ASSERT_TRUE(desk.Refuse(b, t0 + milliseconds(2000)).ok());  // by the whole key
  EXPECT_EQ(*desk.OnRequest(b, "pc-5", "10.0.0.15", 5, t0 + milliseconds(2500)),
            EnrollState::kRefused);
  EXPECT_EQ(desk.pending(), 0u);

  EXPECT_EQ(desk.Accept("0000-0000-0000-0000", t0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(desk.Accept("", t0).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(desk.OnRequest("not a key", "x", "10.0.0.1", 1, t0).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(EnrollmentDeskTest, AskersAreBoundedPerAddressAndInAllAndForgottenWhenSilent) {
  EnrollmentDeskOptions options;
  options.max_pending = 6;
  options.max_pending_per_address = 2;
  options.forget_after = milliseconds(5000);
  ASSERT_TRUE(options.Check().ok());
  EnrollmentDesk desk(options);
  Clock::time_point t = Clock::now();
  const std::string honest = NewKey();
  ASSERT_TRUE(desk.OnRequest(honest, "pc-4", "10.0.0.14", 4, t).ok());
  // One hostile address with many keys keeps at most two of them and never pushes out others.
  for (int i = 0; i < 50; ++i) {
    t += milliseconds(10);
    ASSERT_TRUE(desk.OnRequest(NewKey(), "x", "10.0.0.66", 100, t).ok());
  }
  EXPECT_EQ(desk.pending(), 3u);
  EXPECT_TRUE(desk.Knows(honest));
  // Many addresses: the desk keeps max_pending, dropping the least recently asked.
  for (int i = 0; i < 10; ++i) {
    t += milliseconds(10);
    ASSERT_TRUE(desk.OnRequest(honest, "pc-4", "10.0.0.14", 4, t).ok());  // still asking
    ASSERT_TRUE(desk.OnRequest(NewKey(), "y", "10.0.1." + std::to_string(i), 200, t).ok());
  }
  EXPECT_EQ(desk.pending(), 6u);
  EXPECT_TRUE(desk.Knows(honest));
  // A unit that stops asking is forgotten; a name with control characters is shown cleaned.
  const std::string quiet = NewKey();
  ASSERT_TRUE(
      desk.OnRequest(quiet, std::string("evil\n\x1b[2J") + std::string(100, 'x'), "10.0.2.1", 7, t)
          .ok());
  for (const coordinator::EnrollingUnit& unit : desk.Units(t)) {
    if (unit.public_key != quiet) continue;
    EXPECT_EQ(unit.host_name.size(), 64u);
    EXPECT_EQ(unit.host_name.substr(0, 8), "evil??[2");
  }
  EXPECT_TRUE(desk.Knows(quiet));
  (void)desk.Units(t + milliseconds(6000));  // nobody asked for 6 s
  EXPECT_FALSE(desk.Knows(quiet));
  EXPECT_EQ(desk.pending(), 0u);
  // Both decisions in one request are refused.
  wire::EnrollmentRequest both;
  both.set_accept(honest);
  both.set_refuse(honest);
  EXPECT_FALSE(desk.Serve(both, t).ok());
}

TEST(EnrollmentDeskTest, OptionsOutsideTheirRangesAreRefused) {
  EnrollmentDeskOptions options;
  options.max_pending = 0;
  EXPECT_FALSE(options.Check().ok());
  options = {};
  options.max_pending_per_address = options.max_pending + 1;
  EXPECT_FALSE(options.Check().ok());
  options = {};
  options.forget_after = milliseconds(10);
  EXPECT_FALSE(options.Check().ok());
}

// A CoordinatorServer with CURVE and an enrollment socket, stepping on its own thread.
class EnrollingCoordinator {
 public:
  explicit EnrollingCoordinator(const net::CurveKeyPair& site) {
    coordinator::CoordinatorOptions options;
    options.curve = site;
    options.enroll_endpoint = "tcp://127.0.0.1:*";
    server_ = std::make_unique<coordinator::CoordinatorServer>(options);
    started_ = server_->Start();
    if (!started_.ok()) return;
    thread_ = std::thread([this] { ran_ = server_->Run(stop_); });
  }
  ~EnrollingCoordinator() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  const Status& started() const { return started_; }
  const std::string& requests() const { return server_->request_endpoint(); }
  const std::string& enroll() const { return server_->enroll_endpoint(); }

 private:
  std::unique_ptr<coordinator::CoordinatorServer> server_;
  Status started_, ran_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// One request on a DEALER with these CURVE settings; the reply, or nullopt after the deadline.
std::optional<wire::Envelope> AskOnce(const std::string& endpoint, const net::CurveSettings& curve,
                                      wire::Envelope request, uint32_t sender) {
  zmq::context_t context;
  net::SocketOptions options;
  options.curve = curve;
  Expected<std::unique_ptr<net::Socket>> dealer =
      net::Socket::Create(&context, net::SocketType::kDealer, options);
  if (!dealer.ok() || !(*dealer)->Connect(endpoint).ok()) return std::nullopt;
  proto::MessageCounters counters;
  net::Channel channel(std::move(*dealer), sender, net::NewIncarnation(), &counters);
  if (!channel.Send(std::move(request)).ok()) return std::nullopt;
  const Clock::time_point until = Clock::now() + kReplyDeadline;
  while (Clock::now() < until) {
    std::vector<bool> readable;
    if (!net::Socket::Poll({&channel.socket()}, milliseconds(50), &readable).ok()) break;
    if (!readable[0]) continue;
    Expected<std::optional<net::Incoming>> in = channel.TryReceive();
    if (in.ok() && in->has_value()) return (*in)->envelope;
  }
  return std::nullopt;
}

std::optional<wire::EnrollmentReply> Operator(const EnrollingCoordinator& site,
                                              const net::CurveKeyPair& keys,
                                              const std::string& accept = "",
                                              const std::string& refuse = "") {
  wire::Envelope request;
  request.mutable_enrollment_request()->set_accept(accept);
  request.mutable_enrollment_request()->set_refuse(refuse);
  std::optional<wire::Envelope> reply =
      AskOnce(site.requests(), net::ClientCurve(keys), std::move(request), kOperatorSenderId);
  if (!reply || !reply->has_enrollment_reply()) return std::nullopt;
  return reply->enrollment_reply();
}

class EnrollmentExchangeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("enrollment_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    Expected<net::CurveKeyPair> site = net::GenerateCurveKeyPair();
    ASSERT_TRUE(site.ok());
    site_ = *site;
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // Runs EnrollWithSite on a thread; the result lands in result_.
  void StartUnit(const EnrollingCoordinator& coordinator, const std::string& key_file) {
    net::EnrollmentClientOptions options;
    options.endpoint = coordinator.enroll();
    options.site_public_key = site_.public_key_z85;
    options.key_file = key_file;
    options.node_id = 4;
    options.host_name = "pc-4";
    options.ask_period = milliseconds(100);
    options.timeout = kEnrollDeadline;
    unit_ = std::thread([this, options] {
      result_ = net::EnrollWithSite(options, &stop_unit_, [](const std::string&) {});
      unit_done_ = true;
    });
  }
  // The fingerprint of the first pending unit, once one asks.
  std::string WaitForPending(const EnrollingCoordinator& coordinator) {
    const Clock::time_point until = Clock::now() + kReplyDeadline;
    while (Clock::now() < until) {
      std::optional<wire::EnrollmentReply> list = Operator(coordinator, site_);
      if (list && list->units_size() > 0 && list->units(0).state() == "pending") {
        EXPECT_EQ(list->units(0).host_name(), "pc-4");
        EXPECT_EQ(list->units(0).node_id(), 4u);
        EXPECT_EQ(list->units(0).address(), "127.0.0.1");
        return list->units(0).fingerprint();
      }
      std::this_thread::sleep_for(milliseconds(20));  // polling interval
    }
    return "";
  }
  // A unit started and seen asking by the operator: its fingerprint (empty if it never asked).
  std::string UnitThatAsks(const EnrollingCoordinator& coordinator, const std::string& key_file) {
    StartUnit(coordinator, key_file);
    return WaitForPending(coordinator);
  }
  void JoinUnit() {
    if (unit_.joinable()) unit_.join();
  }

  std::filesystem::path dir_;
  net::CurveKeyPair site_;
  std::thread unit_;
  std::atomic<bool> stop_unit_{false}, unit_done_{false};
  Expected<net::CurveKeyPair> result_ = UnavailableError("not run");
};

TEST_F(EnrollmentExchangeTest, AnAcceptedUnitIsHandedTheSiteKeyAndWritesItPrivately) {
  EnrollingCoordinator coordinator(site_);
  ASSERT_TRUE(coordinator.started().ok()) << coordinator.started().ToString();
  const std::string key_file = (dir_ / "site.keys").string();
  const std::string fingerprint = UnitThatAsks(coordinator, key_file);
  ASSERT_FALSE(fingerprint.empty()) << "no unit asked";
  // Asking is all a stranger's key may do: it is not let onto the requests socket.
  Expected<net::CurveKeyPair> own = net::ReadCurveKeyFile(key_file + ".request");
  ASSERT_TRUE(own.ok()) << own.status().ToString();
  EXPECT_EQ(net::KeyFingerprint(own->public_key_z85), fingerprint);
  net::CurveSettings stranger = net::ClientCurve(*own);
  stranger.server_key_z85 = site_.public_key_z85;
  wire::Envelope time;
  time.mutable_time_request()->set_t0_client_send_ns(1);
  EXPECT_FALSE(AskOnce(coordinator.requests(), stranger, time, 4).has_value());
  // Nor anything but an enroll request on the enrollment socket.
  std::optional<wire::Envelope> hello = AskOnce(coordinator.enroll(), stranger, time, 4);
  ASSERT_TRUE(hello.has_value());
  EXPECT_TRUE(hello->has_rejected());
  EXPECT_FALSE(unit_done_.load());  // still waiting for the operator

  std::optional<wire::EnrollmentReply> decided = Operator(coordinator, site_, fingerprint);
  ASSERT_TRUE(decided.has_value());
  EXPECT_TRUE(decided->ok()) << decided->message();
  JoinUnit();
  ASSERT_TRUE(result_.ok()) << result_.status().ToString();
  EXPECT_EQ(result_->public_key_z85, site_.public_key_z85);
  Expected<net::CurveKeyPair> written = net::ReadCurveKeyFile(key_file);  // checks mode 0600
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  EXPECT_EQ(written->secret_key_z85, site_.secret_key_z85);
  EXPECT_FALSE(std::filesystem::exists(key_file + ".request"));
}

TEST_F(EnrollmentExchangeTest, ARefusedUnitIsToldSoAndWritesNothing) {
  EnrollingCoordinator coordinator(site_);
  ASSERT_TRUE(coordinator.started().ok()) << coordinator.started().ToString();
  const std::string key_file = (dir_ / "site.keys").string();
  const std::string fingerprint = UnitThatAsks(coordinator, key_file);
  ASSERT_FALSE(fingerprint.empty()) << "no unit asked";
  std::optional<wire::EnrollmentReply> unknown =
      Operator(coordinator, site_, "1234-5678-9abc-def0");
  ASSERT_TRUE(unknown.has_value());
  EXPECT_FALSE(unknown->ok());
  EXPECT_NE(unknown->message().find("no unit that asked"), std::string::npos) << unknown->message();
  std::optional<wire::EnrollmentReply> refused = Operator(coordinator, site_, "", fingerprint);
  ASSERT_TRUE(refused.has_value());
  EXPECT_TRUE(refused->ok()) << refused->message();
  JoinUnit();
  EXPECT_EQ(result_.status().code(), StatusCode::kPermissionDenied) << result_.status().ToString();
  EXPECT_FALSE(std::filesystem::exists(key_file));
}

TEST_F(EnrollmentExchangeTest, AUnitAskingAnImpostorWithAnotherKeyIsNeverAnswered) {
  // The beacon named the site's key; a coordinator holding another key cannot complete the
  // CURVE handshake, so the unit hears nothing and says so when it gives up.
  Expected<net::CurveKeyPair> other = net::GenerateCurveKeyPair();
  ASSERT_TRUE(other.ok());
  EnrollingCoordinator impostor(*other);
  ASSERT_TRUE(impostor.started().ok());
  net::EnrollmentClientOptions options;
  options.endpoint = impostor.enroll();
  options.site_public_key = site_.public_key_z85;
  options.key_file = (dir_ / "site.keys").string();
  options.ask_period = milliseconds(100);
  options.timeout = milliseconds(1500);
  Expected<net::CurveKeyPair> result = net::EnrollWithSite(options, nullptr, nullptr);
  EXPECT_EQ(result.status().code(), StatusCode::kUnavailable) << result.status().ToString();
  EXPECT_FALSE(std::filesystem::exists(options.key_file));
}

TEST_F(EnrollmentExchangeTest, EnrollmentNeedsCurveAndAnOperatorWithTheSiteKey) {
  coordinator::CoordinatorOptions open;
  open.enroll_endpoint = "tcp://127.0.0.1:*";
  EXPECT_FALSE(open.Check().ok());
  EnrollingCoordinator coordinator(site_);
  ASSERT_TRUE(coordinator.started().ok());
  Expected<net::CurveKeyPair> other = net::GenerateCurveKeyPair();
  ASSERT_TRUE(other.ok());
  net::CurveSettings outsider = net::ClientCurve(*other);
  outsider.server_key_z85 = site_.public_key_z85;
  wire::Envelope accept;
  accept.mutable_enrollment_request()->set_accept("anything");
  EXPECT_FALSE(AskOnce(coordinator.requests(), outsider, accept, kOperatorSenderId).has_value());
}

}  // namespace
}  // namespace sandtable
