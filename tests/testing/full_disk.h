// FullDisk: a full disk as the kernel reports it, for tests of writers. While an instance lives,
// this process may not grow any file past `max_file_bytes` (RLIMIT_FSIZE) and SIGXFSZ is
// ignored, so a write past it fails with EFBIG instead of killing the process. The previous
// limit and signal action come back when it goes. Child processes inherit both (a program run
// from the test meets the same full disk).
#pragma once

#include <sys/resource.h>

#include <csignal>

namespace sandtable::test_support {

class FullDisk {
 public:
  explicit FullDisk(rlim_t max_file_bytes) {
    struct sigaction ignore = {};
    ignore.sa_handler = SIG_IGN;
    ok_ = ::sigaction(SIGXFSZ, &ignore, &previous_action_) == 0 &&
          ::getrlimit(RLIMIT_FSIZE, &previous_limit_) == 0;
    struct rlimit small = previous_limit_;
    small.rlim_cur = max_file_bytes;
    ok_ = ok_ && ::setrlimit(RLIMIT_FSIZE, &small) == 0;
  }
  ~FullDisk() {
    ::setrlimit(RLIMIT_FSIZE, &previous_limit_);
    ::sigaction(SIGXFSZ, &previous_action_, nullptr);
  }
  FullDisk(const FullDisk&) = delete;
  FullDisk& operator=(const FullDisk&) = delete;

  // False when the limit could not be set (the test should fail on it).
  bool ok() const { return ok_; }

 private:
  struct sigaction previous_action_ = {};
  struct rlimit previous_limit_ = {};
  bool ok_ = false;
};

}  // namespace sandtable::test_support
