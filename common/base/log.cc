#include "common/base/log.h"

#include "common/base/log_rate_limit.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <mutex>
#include <utility>

namespace sandtable {
namespace {

LogLevel LevelFromEnvironment() {
  LogLevel level = LogLevel::kInfo;
  if (const char* env = std::getenv("SANDTABLE_LOG_LEVEL")) ParseLogLevel(env, &level);
  return level;
}

std::atomic<int>& LevelStorage() {
  static std::atomic<int> level(static_cast<int>(LevelFromEnvironment()));
  return level;
}

std::mutex& OutputMutex() {
  static std::mutex mutex;
  return mutex;
}

std::string& Tag() {
  static std::string tag;
  return tag;
}

struct SiteWindow {
  std::chrono::steady_clock::time_point start{};
  int written = 0;
  uint64_t suppressed = 0;
};

// Guarded by OutputMutex(). One entry per call site that logged a warning or an error: the
// number of call sites is fixed at compile time, so the map is bounded.
std::map<std::pair<const char*, int>, SiteWindow>& Sites() {
  static std::map<std::pair<const char*, int>, SiteWindow> sites;
  return sites;
}

std::atomic<int64_t>& RateIntervalMs() {
  static std::atomic<int64_t> ms(kLogRateInterval.count());
  return ms;
}

std::atomic<uint64_t>& SuppressedTotal() {
  static std::atomic<uint64_t> total(0);
  return total;
}

const char* Basename(const char* path) {
  const char* base = path;
  for (const char* p = path; *p; ++p) {
    if (*p == '/') base = p + 1;
  }
  return base;
}

}  // namespace

void SetLogLevel(LogLevel level) { LevelStorage().store(static_cast<int>(level)); }
LogLevel GetLogLevel() { return static_cast<LogLevel>(LevelStorage().load()); }

bool ParseLogLevel(std::string_view text, LogLevel* level) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "debug")
    *level = LogLevel::kDebug;
  else if (lower == "info")
    *level = LogLevel::kInfo;
  else if (lower == "warning" || lower == "warn")
    *level = LogLevel::kWarning;
  else if (lower == "error")
    *level = LogLevel::kError;
  else
    return false;
  return true;
}

void SetLogRateInterval(std::chrono::milliseconds interval) {
  RateIntervalMs().store(interval.count());
  std::lock_guard<std::mutex> lock(OutputMutex());
  Sites().clear();
}

uint64_t SuppressedLogLines() { return SuppressedTotal().load(); }

void SetLogTag(std::string tag) {
  std::lock_guard<std::mutex> lock(OutputMutex());
  Tag() = std::move(tag);
}

namespace internal {

LogMessage::LogMessage(LogLevel level, const char* file, int line)
    : level_(level), file_(file), line_(line) {}

LogMessage::~LogMessage() {
  uint64_t suppressed = 0;
  const int64_t interval_ms = RateIntervalMs().load();
  if (level_ >= LogLevel::kWarning && interval_ms > 0) {
    const auto now = std::chrono::steady_clock::now();
    std::lock_guard<std::mutex> lock(OutputMutex());
    SiteWindow& site = Sites()[{file_, line_}];
    if (site.written == 0 || now - site.start >= std::chrono::milliseconds(interval_ms)) {
      // A new interval: report what the last one suppressed on this line.
      suppressed = site.suppressed;
      site = SiteWindow{now, 1, 0};
    } else if (site.written < kLogBurstLines) {
      ++site.written;
    } else {
      ++site.suppressed;
      SuppressedTotal().fetch_add(1);
      return;
    }
  }
  using Clock = std::chrono::system_clock;
  const auto now = Clock::now();
  const std::time_t seconds = Clock::to_time_t(now);
  const auto ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()).count() % 1000;
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y-%m-%dT%H:%M:%S", &utc);
  static constexpr char kLetters[] = {'D', 'I', 'W', 'E'};
  std::lock_guard<std::mutex> lock(OutputMutex());
  std::string text = stream_.str();
  if (suppressed > 0) {
    std::ostringstream note;
    note << " [" << suppressed << " similar lines suppressed (rate limit: " << kLogBurstLines
         << " lines per " << RateIntervalMs().load() / 1000.0 << " s from one place)]";
    text += note.str();
  }
  std::fprintf(stderr, "%s.%03dZ %c %s%s%s:%d] %s\n", stamp, static_cast<int>(ms),
               kLetters[static_cast<int>(level_)], Tag().c_str(), Tag().empty() ? "" : " ",
               Basename(file_), line_, text.c_str());
  std::fflush(stderr);
}

}  // namespace internal
}  // namespace sandtable
