#include "node/net/clock_offset_estimator.h"

namespace sandtable::node {

bool ClockOffsetEstimator::AddSample(int64_t t0_ns, int64_t t1_ns, int64_t t2_ns, int64_t t3_ns) {
  const int64_t delay_ns = (t3_ns - t0_ns) - (t2_ns - t1_ns);
  if (delay_ns < 0 || t3_ns < t0_ns || t2_ns < t1_ns) return false;
  // Halve each difference before adding: no overflow for clocks far apart.
  const int64_t offset_ns = (t1_ns - t0_ns) / 2 + (t2_ns - t3_ns) / 2;
  samples_.push_back({offset_ns, delay_ns});
  while (samples_.size() > window_) samples_.pop_front();
  return true;
}

std::optional<ClockOffsetEstimate> ClockOffsetEstimator::Estimate() const {
  if (samples_.empty()) return std::nullopt;
  const Sample* best = &samples_.front();
  for (const Sample& s : samples_) {
    if (s.delay_ns < best->delay_ns) best = &s;
  }
  ClockOffsetEstimate estimate;
  estimate.offset_s = static_cast<double>(best->offset_ns) * 1e-9;
  estimate.delay_s = static_cast<double>(best->delay_ns) * 1e-9;
  estimate.error_bound_s = estimate.delay_s / 2.0;
  estimate.samples = samples_.size();
  return estimate;
}

}  // namespace sandtable::node
