// ServerLoop: the one receive loop of every server of a site (node, coordinator, world).
//
// It waits on its channels (at most `max_wait`), drains each up to `max_drain` messages per
// turn (so one flooding sender cannot starve the others or the periodic work), hands every
// accepted message to that channel's handler, and answers a refused request on a ROUTER
// with Rejected (reason and the refused sequence when it could be read) to the routing id
// that sent it, so a sender of a bad request learns why instead of waiting for a reply.
// Refusals are counted by the channel (MessageCounters); the optional on_refused hook lets a
// server keep its own statistics. Single-threaded, like the sockets it polls.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <vector>

#include "common/base/status.h"
#include "net/channel.h"

namespace sandtable::net {

// A random number that changes on every process start (Envelope.sender_incarnation).
uint64_t NewIncarnation();

class ServerLoop {
 public:
  using Handler = std::function<void(Incoming)>;
  using RefusalHook = std::function<void(const Refusal&)>;

  explicit ServerLoop(int max_drain = 1000) : max_drain_(max_drain) {}

  // Adds a channel (not owned; must outlive the loop). `answer_refusals` needs a ROUTER.
  void Add(Channel* channel, Handler handler, bool answer_refusals = false,
           RefusalHook on_refused = nullptr);

  // Waits up to `max_wait` for any channel to become readable, then drains every readable
  // one. OK also on timeout and on EINTR (the caller checks its stop flag); an error only
  // when a socket itself fails.
  Status RunOnce(std::chrono::milliseconds max_wait);
  // The same, also waking when one of `extra` (sockets or file descriptors the caller drains
  // itself) is ready; their revents are set on return.
  // (`extra` may be null.) One poll path for every server.
  Status RunOnce(std::chrono::milliseconds max_wait, std::vector<zmq::pollitem_t>* extra);
  // When the last RunOnce's poll returned (its handlers ran after): a caller measures how long
  // its thread was busy since.
  std::chrono::steady_clock::time_point last_woke() const { return last_woke_; }

  // Messages handed to handlers and refusals answered, since construction.
  uint64_t messages_handled() const { return handled_; }
  uint64_t refusals_answered() const { return refusals_answered_; }

 private:
  struct Entry {
    Channel* channel;
    Handler handler;
    bool answer_refusals;
    RefusalHook on_refused;
  };
  void Drain(Entry& entry);

  int max_drain_;
  std::vector<Entry> entries_;
  uint64_t handled_ = 0;
  uint64_t refusals_answered_ = 0;
  std::chrono::steady_clock::time_point last_woke_{};
};

}  // namespace sandtable::net
