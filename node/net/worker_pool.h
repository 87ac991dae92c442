// WorkerPool: long work of a node (decoding, solving, blending) off the network thread.
//
// Submit() runs a job on one of the pool's threads; the job returns a completion (a closure)
// that the network thread runs in its next RunCompletions(), so results are applied where
// the node's state lives and no service needs a lock. The network thread never waits for a
// job: a 10 s solve does not delay heartbeats (tests/node/net/node_services_test.cc).
// Destruction waits for running jobs to finish and drops queued ones (their completions are
// never run).
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace sandtable::node {

class WorkerPool {
 public:
  using Completion = std::function<void()>;
  using Job = std::function<Completion()>;

  explicit WorkerPool(int num_threads = 1);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Thread-safe. `job` runs on a worker; what it returns (may be empty) runs on the network
  // thread in RunCompletions().
  void Submit(Job job);
  // Convenience: `work` on a worker, then `done(result)` on the network thread.
  template <typename Result>
  void Run(std::function<Result()> work, std::function<void(Result)> done) {
    Submit([work = std::move(work), done = std::move(done)]() mutable -> Completion {
      // Held by a shared_ptr so that move-only results (Expected<std::unique_ptr<...>>) fit
      // in a std::function.
      auto result = std::make_shared<Result>(work());
      return [done = std::move(done), result]() mutable { done(std::move(*result)); };
    });
  }
  // Thread-safe: queue a closure for the network thread (e.g. from a device callback).
  void Post(Completion completion);

  // On the network thread: runs every completion that is ready; returns how many ran.
  size_t RunCompletions();
  // Jobs queued or running.
  size_t busy() const;
  // A file descriptor that is readable while completions wait (an eventfd; -1 when the
  // system has none): the network thread polls it beside its sockets, so a finished job wakes
  // it at once instead of at its next timer. RunCompletions() clears it.
  int wake_fd() const { return wake_fd_; }

 private:
  void WorkerMain();
  void SignalCompletion();  // with mutex_ held

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<Job> jobs_;
  std::deque<Completion> completions_;
  size_t running_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
  int wake_fd_ = -1;
  bool signalled_ = false;  // wake_fd_ holds a count not yet read
};

}  // namespace sandtable::node
