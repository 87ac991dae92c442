// Waiting on network events with deadlines (never fixed sleeps) for tests of net/.
#pragma once

#include <chrono>
#include <functional>
#include <optional>
#include <thread>

#include "net/channel.h"

namespace sandtable::net::testing {

// Receives on `channel` until a valid message arrives or `deadline` passes. Rejected messages
// are skipped (they are counted by the channel).
inline std::optional<Incoming> ReceiveWithin(Channel* channel, std::chrono::milliseconds deadline) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < until) {
    std::vector<bool> readable;
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        until - std::chrono::steady_clock::now());
    if (!Socket::Poll({&channel->socket()}, std::max(left, std::chrono::milliseconds(1)), &readable)
             .ok()) {
      return std::nullopt;
    }
    if (!readable[0]) continue;
    Expected<std::optional<Incoming>> in = channel->TryReceive();
    if (in.ok() && in->has_value()) return std::move(**in);
  }
  return std::nullopt;
}

// Polls `condition` until it holds or `deadline` passes.
inline bool WaitFor(const std::function<bool()>& condition, std::chrono::milliseconds deadline) {
  const auto until = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < until) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));  // polling interval
  }
  return condition();
}

}  // namespace sandtable::net::testing
