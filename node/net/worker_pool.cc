#include "node/net/worker_pool.h"

#include <exception>

#include "common/base/check.h"
#include "common/base/log.h"

namespace sandtable::node {

WorkerPool::WorkerPool(int num_threads) {
  ST_CHECK(num_threads >= 1) << "WorkerPool needs at least one thread";
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
}

size_t WorkerPool::RunCompletions() {
  std::deque<Completion> ready;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ready.swap(completions_);
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
    if (completion) completions_.push_back(std::move(completion));
  }
}

}  // namespace sandtable::node
