// The rate limit of the logging facility (common/base/log.h).
//
// Warnings and errors are limited per call site (file and line: one cause): at most
// kLogBurstLines lines per interval (kLogRateInterval by default) from one site; the rest are
// counted, not written, and the next line that site writes after the interval says how many
// were suppressed ("[312 similar lines suppressed (rate limit: 3 lines per 10 s from one
// place)]"). So a flood of bad peers (300 refused handshakes) writes a handful of lines, not
// hundreds. Debug and info are not limited (info is never used in per-message paths of
// servers). The table of call sites is bounded (call sites are fixed at compile time).
// Thread-safe.
#pragma once

#include <chrono>
#include <cstdint>

namespace sandtable {

constexpr int kLogBurstLines = 3;                             // per call site and interval
constexpr std::chrono::milliseconds kLogRateInterval{10000};  // default interval

// Changes the interval (tests); a value <= 0 turns the rate limit off.
void SetLogRateInterval(std::chrono::milliseconds interval);
// Lines not written because of the rate limit, since the start of the process.
uint64_t SuppressedLogLines();

}  // namespace sandtable
