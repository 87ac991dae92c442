// ClockOffsetEstimator: NTP-style offset of the coordinator's clock relative to ours.
//
// Each exchange gives t0 (we send), t1 (coordinator receives), t2 (coordinator replies),
// t3 (we receive), each on its own side's clock:
//   offset = ((t1 - t0) + (t2 - t3)) / 2      coordinator clock - our clock
//   delay  = (t3 - t0) - (t2 - t1)            round trip spent on the wire and in queues
// If the true offset is theta, t1 = t0 + theta + d_out and t3 = t2 - theta + d_back, so the
// sample's error is (d_out - d_back) / 2, bounded by delay / 2. We keep the last `window`
// samples and report the one with the smallest delay (the least queued, hence tightest
// bound), as NTP's clock filter does. Not thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>

namespace sandtable::node {

struct ClockOffsetEstimate {
  double offset_s = 0.0;       // coordinator clock - our clock
  double error_bound_s = 0.0;  // delay / 2 of the chosen sample: |true - estimate| <= this
  double delay_s = 0.0;
  size_t samples = 0;
};

class ClockOffsetEstimator {
 public:
  explicit ClockOffsetEstimator(size_t window = 16) : window_(window) {}

  // Ignores samples with negative delay (clocks stepped, or forged replies) and returns false.
  bool AddSample(int64_t t0_ns, int64_t t1_ns, int64_t t2_ns, int64_t t3_ns);
  std::optional<ClockOffsetEstimate> Estimate() const;

 private:
  struct Sample {
    int64_t offset_ns;
    int64_t delay_ns;
  };
  size_t window_;
  std::deque<Sample> samples_;
};

}  // namespace sandtable::node
