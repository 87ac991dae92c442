// CPU time of the calling thread (CLOCK_THREAD_CPUTIME_ID), in seconds: what the work of one
// thread cost, whatever else the machine was doing. Used for the compute figures reported
// beside errors (self-calibration, benchmarks).
#pragma once

#include <ctime>

namespace sandtable {

inline double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

}  // namespace sandtable
