// SPDX-License-Identifier: MIT
// Host-side parallel loops for the plain-C++ parts (stitching, subdomain
// particle selection and packing): std::thread, because the CUDA build of
// the library has no OpenMP. The caller's thread takes part.
#pragma once

#include <algorithm>
#include <cstddef>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace nbmc {

// The most threads the loops below start on this thread (0: one per
// hardware thread). The C API sets it from the context's thread count for
// the duration of a call (ScopedHostThreads), so that a context asked for N
// threads (or the serial backend: one) never runs more in its host steps.
inline std::size_t& host_thread_limit() {
  static thread_local std::size_t limit = 0;
  return limit;
}
class ScopedHostThreads {
 public:
  explicit ScopedHostThreads(std::size_t limit) : old_(host_thread_limit()) { host_thread_limit() = limit; }
  ~ScopedHostThreads() { host_thread_limit() = old_; }
  ScopedHostThreads(const ScopedHostThreads&) = delete;
  ScopedHostThreads& operator=(const ScopedHostThreads&) = delete;

 private:
  std::size_t old_;
};

// Chunks for `count` items: one per hardware thread (at most the limit
// above), each at least `min_items` long (at least one chunk).
inline std::size_t chunk_count(std::size_t count, std::size_t min_items) {
  const std::size_t limit = host_thread_limit();
  const std::size_t hw = limit > 0 ? limit : std::max(1u, std::thread::hardware_concurrency());
  return std::max<std::size_t>(1, std::min(hw, count / std::max<std::size_t>(1, min_items)));
}

// Runs f(t) for t in [0, n) on n threads; rethrows the first exception.
template <class F>
void on_threads(std::size_t n, const F& f) {
  std::exception_ptr err;
  std::mutex m;
  auto guarded = [&](std::size_t t) {
    try {
      f(t);
    } catch (...) {
      std::lock_guard<std::mutex> lock(m);
      if (!err) err = std::current_exception();
    }
  };
  std::vector<std::thread> pool;
  for (std::size_t t = 1; t < n; ++t) pool.emplace_back(guarded, t);
  if (n > 0) guarded(0);
  for (std::thread& th : pool) th.join();
  if (err) std::rethrow_exception(err);
}

// Runs f(chunk, begin, end) over `chunks` contiguous chunks of [0, count).
template <class F>
void for_chunks(std::size_t count, std::size_t chunks, const F& f) {
  on_threads(chunks, [&](std::size_t k) { f(k, count * k / chunks, count * (k + 1) / chunks); });
}

}  // namespace nbmc
