// HostNowNs: this host's clock, in ns since the steady clock's epoch: the time base of every
// timestamp a process puts on the wire (send_time_ns, time sync) and of the node's timeline.
//
// Separate hosts' clocks disagree; the processes of a simulated site share one machine's, so a
// test can give a process an offset (SetHostClockOffsetForTest: sandtable-node
// --test-clock-offset-s, LAB TEST ONLY), and every timestamp it makes with HostNowNs then reads as
// another host's would. Durations and timers keep using std::chrono::steady_clock directly (an
// offset changes no duration). Thread-safe.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>

namespace sandtable {

inline std::atomic<int64_t> g_host_clock_offset_ns{0};

inline void SetHostClockOffsetForTest(int64_t offset_ns) {
  g_host_clock_offset_ns.store(offset_ns, std::memory_order_relaxed);
}

inline int64_t HostNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
             .count() +
         g_host_clock_offset_ns.load(std::memory_order_relaxed);
}

}  // namespace sandtable
