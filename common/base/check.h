// ST_CHECK: programmer-error assertions that abort with a message saying what went wrong.
//
// Use only for broken invariants (a bad id from our own code, a size mismatch between our own
// buffers). Untrusted input must be reported through Status/Expected (common/base/status.h).
//   ST_CHECK(k > 0) << "homography RANSAC needs a positive sample size, got " << k;
#pragma once

#include <sstream>

namespace sandtable::internal {

class CheckFailure {
 public:
  CheckFailure(const char* file, int line, const char* condition);
  [[noreturn]] ~CheckFailure();
  template <typename T>
  CheckFailure& operator<<(const T& v) {
    stream_ << v;
    return *this;
  }

 private:
  std::ostringstream stream_;
};

// Lets `ST_CHECK(c) << ...` be an expression of type void in both branches.
struct Voidify {
  void operator&(const CheckFailure&) {}
};

}  // namespace sandtable::internal

#define ST_CHECK(condition)                        \
  (condition) ? (void)0                            \
              : ::sandtable::internal::Voidify() & \
                    ::sandtable::internal::CheckFailure(__FILE__, __LINE__, #condition)
