// A small site for node tests: a real CoordinatorServer and real NodeRuntimes over loopback
// TCP, stepped in turn on the test's thread (no fixed sleeps: loops end on events or deadlines).
#pragma once

#include <chrono>
#include <functional>
#include <vector>

#include "coordinator/membership/coordinator_server.h"
#include "node/net/node_runtime.h"

namespace sandtable::node::test_site {

// A coordinator that heartbeats every `heartbeat` and declares a node dead after
// `misses_allowed` missed ones.
inline coordinator::CoordinatorOptions SiteCoordinatorOptions(std::chrono::milliseconds heartbeat,
                                                              int misses_allowed) {
  coordinator::CoordinatorOptions o;
  o.membership.heartbeat_period = heartbeat;
  o.membership.misses_allowed = misses_allowed;
  o.republish_period = std::chrono::milliseconds(200);
  return o;
}

// Node `id` of that coordinator; it gives up on the coordinator and a peer after `timeout`.
inline NodeOptions SiteNodeOptions(NodeId id, const coordinator::CoordinatorServer& c,
                                   std::chrono::milliseconds heartbeat,
                                   std::chrono::milliseconds timeout) {
  NodeOptions o;
  o.id = id;
  o.coordinator_requests = c.request_endpoint();
  o.coordinator_events = c.event_endpoint();
  o.heartbeat_period = heartbeat;
  o.coordinator_timeout = timeout;
  o.peer_timeout = timeout;
  return o;
}

// Steps the coordinator and every node in turn until `done` or the deadline; false on a failed
// step or the deadline.
inline bool StepUntil(coordinator::CoordinatorServer& c, const std::vector<NodeRuntime*>& nodes,
                      const std::function<bool()>& done, std::chrono::milliseconds deadline) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < until) {
    if (!c.Step(std::chrono::milliseconds(2)).ok()) return false;
    for (NodeRuntime* n : nodes) {
      if (!n->Step(std::chrono::milliseconds(2)).ok()) return false;
    }
    if (done()) return true;
  }
  return done();
}

}  // namespace sandtable::node::test_site
