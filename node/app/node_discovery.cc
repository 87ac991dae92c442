#include "node/app/node_discovery.h"

#include <filesystem>
#include <string>
#include <system_error>

#include "common/base/log.h"
#include "net/curve.h"
#include "net/discovery.h"
#include "net/site_enrollment.h"

namespace sandtable::node {

Status DiscoverCoordinator(NodeConfig& config, const std::atomic<bool>* stop) {
  net::DiscoveryOptions options;
  options.port = config.discovery_port;
  options.site = config.site_name;
  options.accept_open_site = config.insecure;
  const std::string& enroll = config.enroll_keys_path;
  std::error_code ec;
  if (!enroll.empty() && std::filesystem::exists(enroll, ec)) config.curve_keys_path = enroll;
  options.enrolling = !enroll.empty() && config.curve_keys_path.empty();
  if (!config.curve_keys_path.empty()) {
    Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(config.curve_keys_path);
    if (!keys.ok()) {
      return InvalidArgumentError((enroll.empty() ? "--curve-keys: " : "--enroll: ") +
                                  keys.status().ToString());
    }
    options.trusted_key = keys->public_key_z85;
  }
  if (Status s = options.Check(); !s.ok()) return InvalidArgumentError(s.message());
  ST_LOG(kInfo) << "discovery: listening for the site's beacon on UDP port " << options.port
                << (options.enrolling ? " (no site key yet: a site that accepts new units)" : "");
  Expected<net::SiteBeacon> found = net::DiscoverSite(options, stop);
  if (!found.ok()) return found.status();
  ST_LOG(kInfo) << "discovery: site " << found->site << " at " << found->host << " ("
                << (options.enrolling          ? "accepts new units"
                    : found->curve_key.empty() ? "open"
                                               : "CURVE key trusted")
                << ")";
  if (options.enrolling) {
    net::EnrollmentClientOptions ask;
    ask.endpoint = found->EnrollEndpoint();
    ask.site_public_key = found->curve_key;
    ask.key_file = enroll;
    ask.node_id = config.id;
    Expected<net::CurveKeyPair> site =
        net::EnrollWithSite(ask, stop, [](const std::string& line) { ST_LOG(kWarning) << line; });
    if (!site.ok()) return site.status();
    config.curve_keys_path = enroll;
  }
  config.coordinator_requests = found->RequestsEndpoint();
  config.coordinator_events = found->EventsEndpoint();
  config.enroll_keys_path.clear();  // done: the site's key file is curve_keys_path now
  return OkStatus();
}

}  // namespace sandtable::node
