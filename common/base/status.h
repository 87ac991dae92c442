// Status and Expected<T>: how untrusted input and numerical failure are reported.
//
// Contract: a routine that can fail on its input (files, messages, captures, degenerate
// geometry, non-convergence) returns Status or Expected<T>, never aborts and never throws
// across a module boundary. The message is written for the user who must act on it, e.g.
// "resection: 4 of 200 points given, at least 6 needed", not "invalid argument".
// Programmer errors (broken invariants) use ST_CHECK from common/base/check.h instead.
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <variant>

#include "common/base/check.h"

namespace sandtable {

enum class StatusCode {
  kOk = 0,
  kInvalidArgument,  // input that can never be valid (NaN, Inf, empty, size mismatch)
  kDegenerate,       // geometrically degenerate input (coplanar, collinear, too few points)
  kNotConverged,     // an iterative method did not reach its tolerance
  kOutOfRange,       // a value outside the domain of a model (behind the camera, off the image)
  kNotFound,
  kParseError,  // malformed file or message
  kIoError,
  kUnavailable,  // a device, peer or service is not there (may come back)
  kPermissionDenied,
  kInternal,
};

// Name of a code ("DEGENERATE"), for messages and logs.
std::string_view StatusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
  Status() = default;  // OK
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "DEGENERATE: resection: 3D points are coplanar ..." or "OK".
  std::string ToString() const;

  // Returns a copy whose message is prefixed with `context` ("site.json: " + message).
  Status WithContext(std::string_view context) const;

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status OkStatus() { return Status(); }
inline Status InvalidArgumentError(std::string m) {
  return Status(StatusCode::kInvalidArgument, std::move(m));
}
inline Status DegenerateError(std::string m) {
  return Status(StatusCode::kDegenerate, std::move(m));
}
inline Status NotConvergedError(std::string m) {
  return Status(StatusCode::kNotConverged, std::move(m));
}
inline Status OutOfRangeError(std::string m) {
  return Status(StatusCode::kOutOfRange, std::move(m));
}
inline Status NotFoundError(std::string m) { return Status(StatusCode::kNotFound, std::move(m)); }
inline Status ParseError(std::string m) { return Status(StatusCode::kParseError, std::move(m)); }
inline Status IoError(std::string m) { return Status(StatusCode::kIoError, std::move(m)); }
inline Status UnavailableError(std::string m) {
  return Status(StatusCode::kUnavailable, std::move(m));
}
inline Status InternalError(std::string m) { return Status(StatusCode::kInternal, std::move(m)); }

// Either a value of T or a non-OK Status. Accessing the value of an error is a programmer
// error and aborts with the status message.
template <typename T>
class [[nodiscard]] Expected {
 public:
  Expected(T value) : data_(std::move(value)) {}        // NOLINT(runtime/explicit)
  Expected(Status status) : data_(std::move(status)) {  // NOLINT(runtime/explicit)
    ST_CHECK(!std::get<Status>(data_).ok()) << "Expected<T> built from an OK Status";
  }

  bool ok() const { return std::holds_alternative<T>(data_); }
  explicit operator bool() const { return ok(); }

  // The error; OkStatus() when a value is held.
  Status status() const { return ok() ? OkStatus() : std::get<Status>(data_); }

  const T& value() const& {
    CheckHasValue();
    return std::get<T>(data_);
  }
  T& value() & {
    CheckHasValue();
    return std::get<T>(data_);
  }
  T&& value() && {
    CheckHasValue();
    return std::get<T>(std::move(data_));
  }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

 private:
  void CheckHasValue() const {
    ST_CHECK(ok()) << "value() of an error: " << std::get<Status>(data_).ToString();
  }
  std::variant<T, Status> data_;
};

}  // namespace sandtable

// Returns the status of `expr` from the enclosing function if it is not OK.
#define ST_RETURN_IF_ERROR(expr)             \
  do {                                       \
    ::sandtable::Status st_status_ = (expr); \
    if (!st_status_.ok()) return st_status_; \
  } while (false)
