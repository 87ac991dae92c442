// --coordinator discover: the node finds its site's coordinator by its beacon
// (net/discovery.h) and, with --enroll and no site key yet, asks the site's operator to accept
// it (net/site_enrollment.h). docs/deploy.md.
#pragma once

#include <atomic>

#include "common/base/status.h"
#include "node/app/node_config.h"

namespace sandtable::node {

// Listens for the site's beacon until one it trusts is heard (the key of the --curve-keys or
// --enroll file, or an open site with --insecure) and fills `config`'s coordinator endpoints
// from it. With --enroll and no key file yet it takes a site that accepts new units and asks;
// accepted, the key file is written and becomes `config.curve_keys_path`. Errors:
// INVALID_ARGUMENT for a bad key file or discovery option (a usage error), UNAVAILABLE when
// `stop` was set or nothing trusted answered, others when the site refused the unit.
Status DiscoverCoordinator(NodeConfig& config, const std::atomic<bool>* stop);

}  // namespace sandtable::node
