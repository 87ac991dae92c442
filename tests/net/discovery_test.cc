// LAN discovery (net/discovery.h): the beacon's bytes both ways, malformed beacons refused,
// and, in a network namespace of its own with a real interface, a unit that hears two sites
// joins the one whose CURVE key it trusts and says why it refused the other.
#include "net/discovery.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "net/curve.h"
#include "tests/testing/network_namespace.h"

namespace sandtable::net {
namespace {

SiteBeacon Lab(const std::string& key) {
  SiteBeacon b;
  b.site = "lab-1";
  b.curve_key = key;
  b.requests_port = 7000;
  b.events_port = 7001;
  return b;
}

TEST(DiscoveryTest, BeaconsRoundTripAndMalformedOnesAreRefused) {
  Expected<CurveKeyPair> keys = GenerateCurveKeyPair();
  ASSERT_TRUE(keys.ok());
  const std::string data = EncodeBeacon(Lab(keys->public_key_z85));
  EXPECT_LE(data.size(), 255u);
  Expected<SiteBeacon> back = DecodeBeacon(data, "10.0.0.1");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->site, "lab-1");
  EXPECT_EQ(back->curve_key, keys->public_key_z85);
  EXPECT_EQ(back->RequestsEndpoint(), "tcp://10.0.0.1:7000");
  EXPECT_EQ(back->EventsEndpoint(), "tcp://10.0.0.1:7001");
  Expected<SiteBeacon> open = DecodeBeacon(EncodeBeacon(Lab("")), "10.0.0.1");
  ASSERT_TRUE(open.ok());
  EXPECT_TRUE(open->curve_key.empty());
  EXPECT_EQ(back->enroll_port, 0);
  EXPECT_EQ(back->EnrollEndpoint(), "");
  SiteBeacon enrolling = Lab(keys->public_key_z85);
  enrolling.enroll_port = 7002;
  Expected<SiteBeacon> with_enroll = DecodeBeacon(EncodeBeacon(enrolling), "10.0.0.1");
  ASSERT_TRUE(with_enroll.ok()) << with_enroll.status().ToString();
  EXPECT_EQ(with_enroll->EnrollEndpoint(), "tcp://10.0.0.1:7002");
  EXPECT_LE(EncodeBeacon(enrolling).size(), 255u);
  for (const char* bad :
       {"", "HELLO site=a key=- requests=1 events=2", "SANDTABLE1 site=a key=- requests=1",
        "SANDTABLE1 site=a key=- requests=0 events=2",
        "SANDTABLE1 site=a key=- requests=1 events=70000",
        "SANDTABLE1 site=a/b key=- requests=1 events=2",
        "SANDTABLE1 site=a key=short requests=1 events=2",
        "SANDTABLE1 site=a key=- requests=1 events=2 extra=3",
        "SANDTABLE1 site=a key=- requests=1 events=2 enroll=0",
        "SANDTABLE1 site=a key=- requests=1 events=2 enroll=1 enroll=2",
        "SANDTABLE1 site=a site=b key=- requests=1 events=2",
        "SANDTABLE1 site=a key=- requests=1 events=2 junk"}) {
    EXPECT_FALSE(DecodeBeacon(bad, "h").ok()) << bad;
  }
  EXPECT_FALSE(DecodeBeacon(std::string(300, 'S'), "h").ok());
  DiscoveryOptions options;
  options.trusted_key = "short";
  EXPECT_FALSE(options.Check().ok());
}

TEST(DiscoveryTest, AUnitJoinsTheSiteItTrustsAndSaysWhyNotTheOther) {
  Expected<CurveKeyPair> ours = GenerateCurveKeyPair();
  Expected<CurveKeyPair> theirs = GenerateCurveKeyPair();
  ASSERT_TRUE(ours.ok() && theirs.ok());
  const test_support::NamespaceRun run = test_support::InOwnNetworkNamespace(
      "ip link add site0 type veth peer name site0p && "
      "ip addr add 10.63.0.1/24 dev site0 && ip addr add 10.63.0.2/24 dev site0p && "
      "ip link set site0p up && ip link set site0 up",
      [&](std::string* text) {
        constexpr int kPort = 5671;
        SiteBeacon other = Lab(theirs->public_key_z85);
        other.site = "other-site";
        SiteBeacon lab = Lab(ours->public_key_z85);
        lab.requests_port = 7100;
        lab.events_port = 7101;
        lab.enroll_port = 7102;  // this site accepts new units; the other does not
        Expected<std::unique_ptr<BeaconPublisher>> a =
            BeaconPublisher::Start(kPort, other, "site0", std::chrono::milliseconds(100));
        Expected<std::unique_ptr<BeaconPublisher>> b =
            BeaconPublisher::Start(kPort, lab, "site0", std::chrono::milliseconds(300));
        if (!a.ok() || !b.ok()) {
          *text = (a.ok() ? b.status() : a.status()).ToString();
          return 1;
        }
        DiscoveryOptions options;
        options.port = kPort;
        options.trusted_key = ours->public_key_z85;
        options.interface_name = "site0";
        options.timeout = std::chrono::milliseconds(10000);
        std::vector<std::string> refused;
        Expected<SiteBeacon> found =
            DiscoverSite(options, nullptr, [&](const SiteBeacon& s, const std::string& why) {
              refused.push_back(s.site + ": " + why);
            });
        if (!found.ok()) {
          *text = found.status().ToString();
          return 1;
        }
        for (const std::string& r : refused) {
          if (r.find("other-site") == std::string::npos ||
              r.find("not the one") == std::string::npos) {
            *text = "refused for the wrong reason: " + r;
            return 1;
          }
        }
        *text = found->site + " " + found->RequestsEndpoint() + " " + found->EventsEndpoint();
        // Only sites of other names on the air: not found, and the message says what was heard.
        options.site = "no-such-site";
        options.timeout = std::chrono::milliseconds(1500);
        Expected<SiteBeacon> none = DiscoverSite(options);
        if (none.ok()) {
          *text = "found a site that is not there";
          return 1;
        }
        *text += " | " + none.status().message();
        // A unit with no key yet takes only a site that accepts new units.
        DiscoveryOptions enrolling;
        enrolling.port = kPort;
        enrolling.interface_name = "site0";
        enrolling.enrolling = true;
        enrolling.timeout = std::chrono::milliseconds(10000);
        std::vector<std::string> passed_over;
        Expected<SiteBeacon> asked =
            DiscoverSite(enrolling, nullptr, [&](const SiteBeacon& s, const std::string& why) {
              passed_over.push_back(s.site + ": " + why);
            });
        if (!asked.ok() || asked->EnrollEndpoint() != "tcp://10.63.0.1:7102") {
          *text =
              "enrolling: " + (asked.ok() ? asked->EnrollEndpoint() : asked.status().ToString());
          return 1;
        }
        for (const std::string& r : passed_over) {
          if (r.find("other-site") == std::string::npos ||
              r.find("does not accept new units") == std::string::npos) {
            *text = "enrolling: passed over for the wrong reason: " + r;
            return 1;
          }
        }
        return 0;
      });
  if (run.code == test_support::NamespaceRun::kSkipped) GTEST_SKIP() << run.text;
  ASSERT_EQ(run.code, 0) << run.text;
  EXPECT_EQ(run.text.rfind("lab-1 tcp://10.63.0.1:7100 tcp://10.63.0.1:7101", 0), 0u) << run.text;
  EXPECT_NE(run.text.find("no site no-such-site"), std::string::npos) << run.text;
  EXPECT_NE(run.text.find("last refused"), std::string::npos) << run.text;
}

}  // namespace
}  // namespace sandtable::net
