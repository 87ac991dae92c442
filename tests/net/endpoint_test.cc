// Endpoints across hosts (net/endpoint.h): parsing, and the address a socket bound to every
// interface advertises: never 0.0.0.0, on a host with two interfaces the one facing the
// coordinator (checked in a network namespace of its own with two veth interfaces).
#include "net/endpoint.h"

#include <string>

#include <gtest/gtest.h>

#include "tests/testing/network_namespace.h"

namespace sandtable::net {
namespace {

TEST(EndpointTest, ParsesTcpEndpointsAndRefusesTheRest) {
  std::optional<TcpEndpoint> e = ParseTcpEndpoint("tcp://127.0.0.1:5555");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->host, "127.0.0.1");
  EXPECT_EQ(e->port, "5555");
  e = ParseTcpEndpoint("tcp://*:*");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->host, "*");
  EXPECT_EQ(e->port, "*");
  e = ParseTcpEndpoint("tcp://[fe80::1]:80");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->host, "fe80::1");
  EXPECT_EQ(e->ToString(), "tcp://[fe80::1]:80");
  e = ParseTcpEndpoint("tcp://site-coordinator.local:7000");
  ASSERT_TRUE(e);
  EXPECT_EQ(e->host, "site-coordinator.local");
  for (const char* bad :
       {"ipc:///tmp/x", "inproc://a", "tcp://host", "tcp://::1:80", "tcp://h:99999", "tcp://h:8a",
        "tcp://:80", "tcp://h:", "udp://h:1", "tcp://[::1]80"}) {
    EXPECT_FALSE(ParseTcpEndpoint(bad)) << bad;
  }
  EXPECT_TRUE(IsWildcardHost("0.0.0.0"));
  EXPECT_TRUE(IsWildcardHost("*"));
  EXPECT_FALSE(IsWildcardHost("10.0.0.1"));
  EXPECT_TRUE(IsLoopbackHost("127.0.0.1"));
  EXPECT_TRUE(IsLoopbackHost("::1"));
  EXPECT_FALSE(IsLoopbackHost("10.0.0.1"));
}

TEST(EndpointTest, AdvertisesWhatPeersCanReach) {
  // Not tcp: unchanged.
  Expected<Advertised> a = AdvertisedEndpoint("ipc:///tmp/peer", "tcp://127.0.0.1:7000");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->endpoint, "ipc:///tmp/peer");
  // One address bound: itself.
  a = AdvertisedEndpoint("tcp://127.0.0.1:41000", "tcp://127.0.0.1:7000");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->endpoint, "tcp://127.0.0.1:41000");
  EXPECT_TRUE(a->note.empty());
  // Loopback while the coordinator is elsewhere: kept, and said.
  a = AdvertisedEndpoint("tcp://127.0.0.1:41000", "tcp://10.20.0.1:7000");
  ASSERT_TRUE(a.ok());
  EXPECT_NE(a->note.find("cannot reach"), std::string::npos) << a->note;
  // Every interface with the coordinator on this host: loopback, never 0.0.0.0.
  a = AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://127.0.0.1:7000");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->endpoint, "tcp://127.0.0.1:41000");
  // An operator's host wins; a wildcard one is refused.
  a = AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://127.0.0.1:7000", "unit-4.site.lan");
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a->endpoint, "tcp://unit-4.site.lan:41000");
  EXPECT_FALSE(AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://127.0.0.1:7000", "0.0.0.0").ok());
  // Every interface and no tcp coordinator to face: an error naming the way out.
  a = AdvertisedEndpoint("tcp://0.0.0.0:41000", "ipc:///tmp/coordinator");
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.status().message().find("give one"), std::string::npos);
  // A coordinator name that does not resolve: an error, not 0.0.0.0.
  a = AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://no-such-host.invalid:7000");
  ASSERT_FALSE(a.ok());
  EXPECT_NE(a.status().message().find("no-such-host.invalid"), std::string::npos);
}

TEST(EndpointTest, BeyondLoopbackAndTheOpenSiteNoticeRepeats) {
  EXPECT_TRUE(BeyondLoopback("tcp://*:7000"));
  EXPECT_TRUE(BeyondLoopback("tcp://0.0.0.0:7000"));
  EXPECT_TRUE(BeyondLoopback("tcp://10.0.0.1:7000"));
  EXPECT_FALSE(BeyondLoopback("tcp://127.0.0.1:7000"));
  EXPECT_FALSE(BeyondLoopback("tcp://localhost:7000"));
  EXPECT_FALSE(BeyondLoopback("ipc:///tmp/x"));
  EXPECT_FALSE(BeyondLoopback("inproc://x"));
  InsecureNotice notice("open site", std::chrono::seconds(60));
  const auto t0 = std::chrono::steady_clock::time_point{} + std::chrono::hours(1);
  notice.Tick(t0);  // said at once
  notice.Tick(t0 + std::chrono::seconds(59));
  EXPECT_EQ(notice.times_said(), 1);
  notice.Tick(t0 + std::chrono::seconds(60));  // and every period after
  notice.Tick(t0 + std::chrono::seconds(61));
  EXPECT_EQ(notice.times_said(), 2);
}

// In a network namespace of its own, two interfaces on two subnets: the advertised address is
// the one on the coordinator's subnet, whichever it is.
TEST(EndpointTest, OnTwoInterfacesAdvertisesTheOneFacingTheCoordinator) {
  // Two veth pairs (both ends up, so each subnet has its route), one address on each.
  const test_support::NamespaceRun run = test_support::InOwnNetworkNamespace(
      "ip link add site0 type veth peer name site0p && "
      "ip link add site1 type veth peer name site1p && "
      "ip addr add 10.61.0.2/24 dev site0 && ip addr add 10.62.0.2/24 dev site1 && "
      "ip link set site0p up && ip link set site1p up && "
      "ip link set site0 up && ip link set site1 up",
      [](std::string* text) {
        Expected<Advertised> first =
            AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://10.61.0.1:7000");
        Expected<Advertised> second =
            AdvertisedEndpoint("tcp://0.0.0.0:41000", "tcp://10.62.0.1:7000");
        if (!first.ok() || !second.ok()) {
          *text = (first.ok() ? second : first).status().ToString();
          return 1;
        }
        *text = first->endpoint + " " + second->endpoint;
        return 0;
      });
  if (run.code == test_support::NamespaceRun::kSkipped) GTEST_SKIP() << run.text;
  ASSERT_EQ(run.code, 0) << run.text;
  EXPECT_EQ(run.text, "tcp://10.61.0.2:41000 tcp://10.62.0.2:41000");
}

}  // namespace
}  // namespace sandtable::net
