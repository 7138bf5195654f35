// SPDX-License-Identifier: MIT
// Host-side parallel loops for the plain-C++ parts (stitching, subdomain
// particle selection and packing, the mesh post-processing): std::thread,
// because the CUDA build of the library has no OpenMP. The caller's thread
// takes part.
//
// The loops run on a persistent pool of worker threads (one per process,
// grown to the most threads a loop has asked for): the mesh clean-up alone
// runs dozens of short parallel loops per frame, and starting and joining
// 15 threads for each costs about as much as the work of the short ones. A
// loop that finds the pool busy (a loop inside a loop's task, or another
// thread of the application in another context at the same time) starts its
// own threads as before. Chunks and results do not depend on which threads
// run them.
//  - fork(): the child has none of the parent's workers; the pool records
//    its process id and a child builds a new one on its first loop (the
//    parent's is left alone: its mutexes may have been held at the fork).
//  - Unloading (exit, dlclose): a static object stops and joins the
//    workers, so no thread is left running the library's code.
//  - Idle workers spin (yielding) for a few tens of microseconds (the next
//    loop of a sequence usually comes within that), then sleep on a
//    condition variable; none spin when the pool has more threads than the
//    machine. A loop costs 2-4 us to start on 2 threads of an idle 2-core
//    machine, against 20-80 us for starting and joining a thread.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <memory>
#include <mutex>
#include <system_error>
#include <thread>
#include <vector>

#if defined(_WIN32)
#include <process.h>
#else
#include <unistd.h>
#endif

namespace nbmc {

// Sets this thread's Slot() to a value for the life of the object.
template <class T, T& (*Slot)()>
class ScopedSetting {
 public:
  explicit ScopedSetting(T value) : old_(Slot()) { Slot() = value; }
  ~ScopedSetting() { Slot() = old_; }
  ScopedSetting(const ScopedSetting&) = delete;
  ScopedSetting& operator=(const ScopedSetting&) = delete;

 private:
  T old_;
};

// The most threads the loops below start on this thread (0: one per
// hardware thread). The C API sets it from the context's thread count for
// the duration of a call (ScopedHostThreads), so that a context asked for N
// threads (or the serial backend: one) never runs more in its host steps.
inline std::size_t& host_thread_limit() {
  static thread_local std::size_t limit = 0;
  return limit;
}
using ScopedHostThreads = ScopedSetting<std::size_t, host_thread_limit>;

// Another way to run a loop's tasks on this thread: run(n, task, ctx) runs
// task(ctx, t) for every t in [0, n), each on a thread of its own at the
// same time (tasks may wait for each other), and returns true, or runs
// nothing and returns false. The C API sets one for the duration of a call
// on its Kokkos thread (ScopedHostExecutor): the OpenMP threads Kokkos has
// just used, which spin for a while after each of its loops and would
// compete with the pool's threads for the cores.
using HostTask = void (*)(const void*, std::size_t);
using HostExecutor = bool (*)(std::size_t n, HostTask task, const void* ctx);
inline HostExecutor& host_executor() {
  static thread_local HostExecutor executor = nullptr;
  return executor;
}
using ScopedHostExecutor = ScopedSetting<HostExecutor, host_executor>;

// Chunks for `count` items: one per hardware thread (at most the limit
// above), each at least `min_items` long (at least one chunk).
inline std::size_t chunk_count(std::size_t count, std::size_t min_items) {
  const std::size_t limit = host_thread_limit();
  const std::size_t hw = limit > 0 ? limit : std::max(1u, std::thread::hardware_concurrency());
  return std::max<std::size_t>(1, std::min(hw, count / std::max<std::size_t>(1, min_items)));
}

namespace detail {

inline long process_id() {
#if defined(_WIN32)
  return long(_getpid());
#else
  return long(getpid());
#endif
}

// Spins on ready() for at most `spin` (checking the clock every 64 tries);
// true when it became ready.
template <class Ready>
bool spin_until(const Ready& ready, std::chrono::microseconds spin) {
  if (spin.count() <= 0) return ready();
  const auto end = std::chrono::steady_clock::now() + spin;
  for (unsigned i = 1;; ++i) {
    if (ready()) return true;
    std::this_thread::yield();  // (not a pause: on a loaded machine the thread that is awaited gets the core)
    if (i % 64 == 0 && std::chrono::steady_clock::now() >= end) return ready();
  }
}

class ThreadPool {
 public:
  using Task = HostTask;
  static constexpr std::size_t kMaxWorkers = 1024;

  ThreadPool() : pid_(process_id()), hardware_(std::max(1u, std::thread::hardware_concurrency())) {}
  ~ThreadPool() {
    for (auto& w : workers_) {
      {
        std::lock_guard<std::mutex> lock(w->m);
        w->stop = true;
      }
      w->cv.notify_one();
    }
    for (auto& w : workers_) w->thread.join();
  }
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  long pid() const { return pid_; }

  // Runs task(ctx, t) for t in [0, n), t = 0 on the calling thread; false
  // (nothing run) when the pool is busy or cannot have n - 1 workers.
  bool run(std::size_t n, Task task, const void* ctx) {
    if (n < 2 || n - 1 > kMaxWorkers) return false;
    if (busy_.exchange(true, std::memory_order_acquire)) return false;
    struct Release {
      std::atomic<bool>& busy;
      ~Release() { busy.store(false, std::memory_order_release); }
    } release{busy_};
    try {
      while (workers_.size() < n - 1) add_worker();
    } catch (const std::system_error&) {
      if (workers_.size() < n - 1) return false;
    }
    spin_us_.store(workers_.size() < hardware_ ? 50 : 0, std::memory_order_relaxed);
    pending_.store(n - 1, std::memory_order_relaxed);
    for (std::size_t t = 1; t < n; ++t) {
      Worker& w = *workers_[t - 1];
      w.task = task;
      w.ctx = ctx;
      w.index = t;
      w.job.fetch_add(1, std::memory_order_seq_cst);
      if (w.sleeping.load(std::memory_order_seq_cst)) {
        std::lock_guard<std::mutex> lock(w.m);
        w.cv.notify_one();
      }
    }
    task(ctx, 0);
    // Wait for the workers: spin, then sleep (same handshake as theirs).
    auto done = [&] { return pending_.load(std::memory_order_acquire) == 0; };
    if (!spin_until(done, spin())) {
      std::unique_lock<std::mutex> lock(done_m_);
      caller_sleeping_.store(true, std::memory_order_seq_cst);
      done_cv_.wait(lock, done);
      caller_sleeping_.store(false, std::memory_order_relaxed);
    }
    return true;
  }

 private:
  struct Worker {
    std::atomic<std::uint64_t> job{0};  // bumped once per task given
    std::atomic<bool> sleeping{false};
    Task task = nullptr;
    const void* ctx = nullptr;
    std::size_t index = 0;
    bool stop = false;  // (under m)
    std::mutex m;
    std::condition_variable cv;
    std::thread thread;
  };

  std::chrono::microseconds spin() const {
    return std::chrono::microseconds(spin_us_.load(std::memory_order_relaxed));
  }

  void add_worker() {
    auto w = std::make_unique<Worker>();
    Worker* p = w.get();
    p->thread = std::thread([this, p] { work(*p); });
    workers_.push_back(std::move(w));
  }

  void work(Worker& w) {
    std::uint64_t seen = 0;
    for (;;) {
      auto given = [&] { return w.job.load(std::memory_order_acquire) != seen; };
      if (!spin_until(given, spin())) {
        std::unique_lock<std::mutex> lock(w.m);
        w.sleeping.store(true, std::memory_order_seq_cst);
        w.cv.wait(lock, [&] { return w.stop || given(); });
        w.sleeping.store(false, std::memory_order_relaxed);
        if (w.stop && !given()) return;
      }
      seen = w.job.load(std::memory_order_acquire);
      w.task(w.ctx, w.index);
      if (pending_.fetch_sub(1, std::memory_order_acq_rel) == 1 &&
          caller_sleeping_.load(std::memory_order_seq_cst)) {
        std::lock_guard<std::mutex> lock(done_m_);
        done_cv_.notify_one();
      }
    }
  }

  const long pid_;
  const std::size_t hardware_;
  std::atomic<bool> busy_{false};
  std::vector<std::unique_ptr<Worker>> workers_;  // (changed only while busy)
  std::atomic<int> spin_us_{0};                   // how long idle threads spin
  std::atomic<std::size_t> pending_{0};
  std::atomic<bool> caller_sleeping_{false};
  std::mutex done_m_;
  std::condition_variable done_cv_;
};

inline std::atomic<ThreadPool*>& pool_slot() {
  static std::atomic<ThreadPool*> slot{nullptr};
  return slot;
}

// Joins the workers when the library (or program) is unloaded; a pool of a
// parent process (after fork) is left alone.
struct PoolReaper {
  ~PoolReaper() {
    ThreadPool* p = pool_slot().exchange(nullptr);
    if (p != nullptr && p->pid() == process_id()) delete p;
  }
};
inline PoolReaper pool_reaper;

// This process' pool (a new one in a child after fork); null when
// NBMC_HOST_POOL=0 (read once) asks for threads started per loop.
inline ThreadPool* host_pool() {
  static const bool off = [] {
    const char* e = std::getenv("NBMC_HOST_POOL");
    return e != nullptr && e[0] == '0' && e[1] == '\0';
  }();
  if (off) return nullptr;
  std::atomic<ThreadPool*>& slot = pool_slot();
  ThreadPool* p = slot.load(std::memory_order_acquire);
  const long pid = process_id();
  while (p == nullptr || p->pid() != pid) {
    auto fresh = std::make_unique<ThreadPool>();
    if (slot.compare_exchange_strong(p, fresh.get(), std::memory_order_acq_rel)) return fresh.release();
  }
  return p;
}

}  // namespace detail

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
  using Guarded = decltype(guarded);
  const auto task = [](const void* ctx, std::size_t t) { (*static_cast<const Guarded*>(ctx))(t); };
  if (n == 1) {
    guarded(0);
  } else if (n > 1 && !(host_executor() != nullptr && host_executor()(n, task, &guarded))) {
    detail::ThreadPool* p = detail::host_pool();
    if (p == nullptr || !p->run(n, task, &guarded)) {
      std::vector<std::thread> threads;
      for (std::size_t t = 1; t < n; ++t) threads.emplace_back(guarded, t);
      guarded(0);
      for (std::thread& th : threads) th.join();
    }
  }
  if (err) std::rethrow_exception(err);
}

// Runs f(chunk, begin, end) over `chunks` contiguous chunks of [0, count).
template <class F>
void for_chunks(std::size_t count, std::size_t chunks, const F& f) {
  on_threads(chunks, [&](std::size_t k) { f(k, count * k / chunks, count * (k + 1) / chunks); });
}

}  // namespace nbmc
