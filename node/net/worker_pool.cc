#include "node/net/worker_pool.h"

#include <sys/eventfd.h>
#include <unistd.h>

#include <cstdint>
#include <exception>

#include "common/base/check.h"
#include "common/base/log.h"

namespace sandtable::node {

WorkerPool::WorkerPool(int num_threads) {
  ST_CHECK(num_threads >= 1) << "WorkerPool needs at least one thread";
  wake_fd_ = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (wake_fd_ < 0) ST_LOG(kWarning) << "worker pool: no eventfd; completions wait for a timer";
  for (int i = 0; i < num_threads; ++i) threads_.emplace_back([this] { WorkerMain(); });
}

WorkerPool::~WorkerPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    jobs_.clear();
  }
  wake_.notify_all();
  for (std::thread& t : threads_) t.join();
  if (wake_fd_ >= 0) close(wake_fd_);
}

void WorkerPool::SignalCompletion() {
  if (wake_fd_ < 0 || signalled_) return;
  const uint64_t one = 1;
  signalled_ = write(wake_fd_, &one, sizeof(one)) == sizeof(one);
}

void WorkerPool::Submit(Job job) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    jobs_.push_back(std::move(job));
  }
  wake_.notify_one();
}

void WorkerPool::Post(Completion completion) {
  std::lock_guard<std::mutex> lock(mutex_);
  completions_.push_back(std::move(completion));
  SignalCompletion();
}

size_t WorkerPool::RunCompletions() {
  std::deque<Completion> ready;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ready.swap(completions_);
    if (signalled_) {
      uint64_t count = 0;
      (void)!read(wake_fd_, &count, sizeof(count));
      signalled_ = false;
    }
  }
  for (Completion& c : ready) {
    if (c) c();
  }
  return ready.size();
}

size_t WorkerPool::busy() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return jobs_.size() + running_;
}

void WorkerPool::WorkerMain() {
  for (;;) {
    Job job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stopping_ || !jobs_.empty(); });
      if (stopping_) return;
      job = std::move(jobs_.front());
      jobs_.pop_front();
      ++running_;
    }
    Completion completion;
    // A job is project code; an exception escaping it is a bug, but it must not take the
    // node down silently: log it and carry on without a completion.
    try {
      completion = job();
    } catch (const std::exception& e) {
      ST_LOG(kError) << "worker job threw: " << e.what();
    }
    std::lock_guard<std::mutex> lock(mutex_);
    --running_;
    if (completion) {
      completions_.push_back(std::move(completion));
      SignalCompletion();
    }
  }
}

}  // namespace sandtable::node
