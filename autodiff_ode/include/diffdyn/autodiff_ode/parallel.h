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
#include <exception>
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
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (int w = 1; w < workers; ++w) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace diffdyn
