// SPDX-License-Identifier: MIT
// Host-side parallel loops for the plain-C++ parts (stitching, subdomain
// particle selection and packing): std::thread, because the CUDA build of
// the library has no OpenMP. The caller's thread takes part.
#pragma once

#include <algorithm>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
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

// A team of host threads for a series of parallel steps: started once
// (size - 1 threads beside the caller's), then woken for each step instead
// of started and joined anew (on_threads: about 0.2-0.7 ms for 16 threads a
// call, as much as a short step of the fairing flips). run(n, f): f(t) for
// t in [0, n), on the caller and at most size - 1 of the team (each takes
// t, t + m, ... for m = min(n, size)); rethrows the first exception. One
// step at a time, from the thread that made the team.
class HostTeam {
 public:
  explicit HostTeam(std::size_t size) : size_(std::max<std::size_t>(1, size)) {
    try {
      for (std::size_t p = 1; p < size_; ++p) threads_.emplace_back([this, p] { work(p); });
    } catch (...) {
      stop();  // (a thread that could not start: the others end first)
      throw;
    }
  }
  ~HostTeam() { stop(); }
  HostTeam(const HostTeam&) = delete;
  HostTeam& operator=(const HostTeam&) = delete;

  template <class F>
  void run(std::size_t n, const F& f) {
    const std::size_t m = std::min(n, size_);
    if (m == 0) return;
    auto part = [&f, n, m](std::size_t p) {
      for (std::size_t t = p; t < n; t += m) f(t);
    };
    if (m == 1) {
      part(0);
      return;
    }
    {
      std::lock_guard<std::mutex> lock(m_);
      job_ = part;
      want_ = m;
      left_ = m - 1;
      err_ = nullptr;
      ++step_;
    }
    wake_.notify_all();
    std::exception_ptr mine;
    try {
      part(0);
    } catch (...) {
      mine = std::current_exception();
    }
    std::unique_lock<std::mutex> lock(m_);
    done_.wait(lock, [&] { return left_ == 0; });
    job_ = nullptr;
    if (!mine) mine = err_;
    lock.unlock();
    if (mine) std::rethrow_exception(mine);
  }
  // f(chunk, begin, end) over `chunks` contiguous chunks of [0, count), as
  // for_chunks.
  template <class F>
  void chunks(std::size_t count, std::size_t chunks, const F& f) {
    run(chunks, [&](std::size_t k) { f(k, count * k / chunks, count * (k + 1) / chunks); });
  }

 private:
  void stop() {
    {
      std::lock_guard<std::mutex> lock(m_);
      stop_ = true;
    }
    wake_.notify_all();
    for (std::thread& th : threads_) th.join();
  }
  void work(std::size_t p) {
    std::uint64_t seen = 0;
    for (;;) {
      std::function<void(std::size_t)> job;
      {
        std::unique_lock<std::mutex> lock(m_);
        wake_.wait(lock, [&] { return stop_ || step_ != seen; });
        if (stop_) return;
        seen = step_;
        if (p >= want_) continue;  // (not in this step)
        job = job_;
      }
      std::exception_ptr e;
      try {
        job(p);
      } catch (...) {
        e = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(m_);
      if (e && !err_) err_ = e;
      if (--left_ == 0) done_.notify_one();
    }
  }
  const std::size_t size_;
  std::mutex m_;
  std::condition_variable wake_, done_;
  std::function<void(std::size_t)> job_;
  std::size_t want_ = 0, left_ = 0;
  std::uint64_t step_ = 0;
  bool stop_ = false;
  std::exception_ptr err_;
  std::vector<std::thread> threads_;  // (last: started once the rest is set)
};

}  // namespace nbmc
