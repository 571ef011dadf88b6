// Deterministic parallel loops.
//
// Work is split into chunks whose boundaries depend only on the problem size,
// never on the thread count; each chunk writes its own slot, and the caller
// reduces the slots in chunk order. So results are bit-identical whatever the
// number of threads:
//
//   std::vector<double> partial(NumChunks(n, 64));
//   diffdyn::ParallelForChunks(n, 64, threads, [&](int chunk, int begin, int end) {
//     for (int i = begin; i < end; ++i) partial[chunk] += f(i);
//   });
//   double sum = std::accumulate(partial.begin(), partial.end(), 0.0);
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// Number of chunks of `chunk_size` items covering `n` items: ceil(n / chunk_size).
inline int NumChunks(int n, int chunk_size) {
  DIFFDYN_CHECK(chunk_size > 0, "chunk size must be positive, got ", chunk_size);
  return n <= 0 ? 0 : (n + chunk_size - 1) / chunk_size;
}

/// The thread count to use: `requested` if positive, else the hardware's.
inline int ResolveThreads(int requested) {
  if (requested > 0) return requested;
  const unsigned hw = std::thread::hardware_concurrency();
  return hw == 0 ? 1 : static_cast<int>(hw);
}

namespace internal {

/// Process-wide helper threads for ParallelForChunks, started on first use and
/// reused (a thread start costs ~25 us, as much as a small batched product).
/// One loop at a time: TryRun returns false when the pool is busy (a nested
/// or concurrent loop), and that caller starts threads of its own.
///
/// Hand-over spins before it sleeps: waking a sleeping thread through the
/// kernel costs 50-300 us on a virtual machine (measured here: a batch of 500
/// through a 6-100-100-6 network took 0.9 ms on two threads and 1.0 ms on
/// one), so an idle helper, and the caller waiting for the helpers, poll for
/// up to kSpin (yielding the core to other work between polls) before they
/// block on a condition variable.
class WorkerPool {
 public:
  /// How long an idle thread polls before it sleeps.
  static constexpr std::chrono::microseconds kSpin{2000};

  /// The pool (threads are added when a loop asks for more than it has).
  static WorkerPool& Instance() {
    static WorkerPool pool;
    return pool;
  }

  /// Runs job() on `helpers` pool threads and on the calling thread, and
  /// returns when all have finished; false (nothing run) if the pool is busy.
  /// job must not throw.
  template <typename Job>
  bool TryRun(int helpers, Job& job) {
    if (helpers > 0xffff) return false;
    std::unique_lock<std::mutex> busy(run_mutex_, std::try_to_lock);
    if (!busy.owns_lock()) return false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      while (static_cast<int>(threads_.size()) < helpers) {
        const int index = static_cast<int>(threads_.size());
        threads_.emplace_back([this, index] { Loop(index); });
      }
      job_ = [&job] { job(); };
      running_.store(helpers, std::memory_order_relaxed);
      // Generation and helper count in one word, so a helper never pairs one
      // loop's generation with another loop's count.
      const std::uint64_t generation = (state_.load(std::memory_order_relaxed) >> 16) + 1;
      state_.store((generation << 16) | static_cast<std::uint64_t>(helpers),
                   std::memory_order_release);
    }
    start_.notify_all();
    job();
    if (!SpinUntil([this] { return running_.load(std::memory_order_acquire) == 0; })) {
      std::unique_lock<std::mutex> lock(mutex_);
      done_.wait(lock, [this] { return running_.load(std::memory_order_acquire) == 0; });
    }
    job_ = nullptr;
    return true;
  }

  ~WorkerPool() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_.store(true, std::memory_order_release);
    }
    start_.notify_all();
    for (std::thread& t : threads_) t.join();
  }

 private:
  WorkerPool() = default;

  // Polls ready() for up to kSpin; true as soon as it holds.
  template <typename Ready>
  static bool SpinUntil(Ready ready) {
    const auto deadline = std::chrono::steady_clock::now() + kSpin;
    for (int polls = 0;; ++polls) {
      if (ready()) return true;
      if ((polls & 63) == 63) {
        if (std::chrono::steady_clock::now() > deadline) return ready();
        std::this_thread::yield();
      }
    }
  }

  void Loop(int index) {
    std::uint64_t seen = 0;  // the last generation this thread saw
    for (;;) {
      auto fresh = [&] {
        return stop_.load(std::memory_order_acquire) ||
               (state_.load(std::memory_order_acquire) >> 16) != seen;
      };
      if (!SpinUntil(fresh)) {
        std::unique_lock<std::mutex> lock(mutex_);
        start_.wait(lock, fresh);
      }
      if (stop_.load(std::memory_order_acquire)) return;
      const std::uint64_t state = state_.load(std::memory_order_acquire);
      seen = state >> 16;
      if (index >= static_cast<int>(state & 0xffff)) continue;
      job_();
      if (running_.fetch_sub(1, std::memory_order_acq_rel) == 1) {
        std::lock_guard<std::mutex> lock(mutex_);
        done_.notify_one();
      }
    }
  }

  std::mutex run_mutex_;  // held by the loop using the pool
  std::mutex mutex_;      // guards threads_, job_ writes and the sleeps
  std::condition_variable start_, done_;
  std::vector<std::thread> threads_;
  std::function<void()> job_;
  std::atomic<std::uint64_t> state_{0};  // generation << 16 | helpers wanted
  std::atomic<int> running_{0};          // helpers still in job_
  std::atomic<bool> stop_{false};
};

}  // namespace internal

/// Runs body(chunk, begin, end) for chunk = 0 .. NumChunks(n, chunk_size) - 1 over
/// items [begin, end), on up to `threads` threads (<= 0: all cores). The first
/// exception thrown by a body is rethrown on the calling thread.
template <typename Body>
void ParallelForChunks(int n, int chunk_size, int threads, Body&& body) {
  const int chunks = NumChunks(n, chunk_size);
  const int workers = std::min(ResolveThreads(threads), chunks);
  auto run_chunk = [&](int c) {
    const int begin = c * chunk_size;
    body(c, begin, std::min(n, begin + chunk_size));
  };
  if (workers <= 1) {
    for (int c = 0; c < chunks; ++c) run_chunk(c);
    return;
  }
  std::atomic<int> next{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&] {
    for (int c = next++; c < chunks; c = next++) {
      try {
        run_chunk(c);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        next = chunks;
      }
    }
  };
  // The pool's threads when it is free; else (a nested or concurrent loop)
  // threads of our own.
  if (!internal::WorkerPool::Instance().TryRun(workers - 1, worker)) {
    std::vector<std::thread> pool;
    pool.reserve(workers - 1);
    for (int w = 1; w < workers; ++w) pool.emplace_back(worker);
    worker();
    for (auto& t : pool) t.join();
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace diffdyn
