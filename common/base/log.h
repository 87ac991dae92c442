// The one logging facility of Sandtable. Thread-safe; writes one line per message to stderr:
//   2026-11-22T10:15:02.123Z I node-3 calibration.cc:88] decoded 812345 pixels
// The threshold comes from SetLogLevel() or the environment variable SANDTABLE_LOG_LEVEL
// (debug, info, warning, error; default info). Never log at INFO inside a per-frame loop.
#pragma once

#include <sstream>
#include <string>
#include <string_view>

namespace sandtable {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
// Parses "debug" / "info" / "warning" / "error" (case-insensitive); false if unknown.
bool ParseLogLevel(std::string_view text, LogLevel* level);
// A short tag printed on every line (process role and id, e.g. "node-3").
void SetLogTag(std::string tag);

namespace internal {

class LogMessage {
 public:
  LogMessage(LogLevel level, const char* file, int line);
  ~LogMessage();
  template <typename T>
  LogMessage& operator<<(const T& v) {
    stream_ << v;
    return *this;
  }

 private:
  LogLevel level_;
  const char* file_;
  int line_;
  std::ostringstream stream_;
};

struct LogVoidify {
  void operator&(const LogMessage&) {}
};

}  // namespace internal
}  // namespace sandtable

#define ST_LOG_IS_ON(level) (::sandtable::LogLevel::level >= ::sandtable::GetLogLevel())
// ST_LOG(kInfo) << "text" << value;
#define ST_LOG(level)                         \
  !ST_LOG_IS_ON(level)                        \
      ? (void)0                               \
      : ::sandtable::internal::LogVoidify() & \
            ::sandtable::internal::LogMessage(::sandtable::LogLevel::level, __FILE__, __LINE__)
