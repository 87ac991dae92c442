// NodeService: one concern of a node (events, calibration, rendering, blending ...) hosted by
// NodeRuntime, like the coordinator's CoordinatorService.
//
// A service declares the bodies it consumes from the coordinator (replies on the request link
// and events on the SUB) and the requests it answers on the node's peer ROUTER; the runtime
// routes each message to the first service that declares it (in AddService order) and rejects
// (counted, answered with Rejected) peer requests nobody serves. OnStep runs after every
// drain, at least every kServiceTick (30 ms). Everything is called on the network thread;
// long work goes to NodeRuntime::workers() and comes back as a completion on this thread.
#pragma once

#include "net/channel.h"
#include "proto/envelope.pb.h"

namespace sandtable::node {

class NodeRuntime;

class NodeService {
 public:
  virtual ~NodeService() = default;
  virtual const char* name() const = 0;

  virtual bool ServesCoordinator(wire::Envelope::BodyCase /*body*/) const { return false; }
  virtual bool ServesPeer(wire::Envelope::BodyCase /*body*/) const { return false; }

  // A coordinator reply or event this service declared.
  virtual void OnCoordinatorMessage(const wire::Envelope& /*message*/, NodeRuntime& /*node*/) {}
  // A peer request (or peer message) this service declared; reply with
  // NodeRuntime::ReplyToPeer(request.routing_id, ...).
  virtual void OnPeerMessage(net::Incoming /*request*/, NodeRuntime& /*node*/) {}
  // The node registered with the coordinator (first time, or again after the coordinator
  // restarted or declared it dead).
  virtual void OnRegistered(NodeRuntime& /*node*/) {}
  // Periodic work.
  virtual Status OnStep(NodeRuntime& /*node*/) { return OkStatus(); }
};

}  // namespace sandtable::node
