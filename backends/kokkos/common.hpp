// SPDX-License-Identifier: MIT
// Shared building blocks of the Kokkos pipeline: resolved parameters, tracked
// buffers (every allocation is labelled "nbmc::..." and counted against the
// context), Morton keys, an open-addressing hash map for sparse grids, scans.
#pragma once

#include <Kokkos_Core.hpp>

#include "core/trace.hpp"
#include <type_traits>
#include <utility>
#include <memory>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstdint>
#include <functional>
#include <new>
#include <stdexcept>
#include <string>

#include "../../src/core/grid.hpp"
#include "../../src/core/params.hpp"

namespace nbmc {

// Counts the bytes nbmc allocates per context (host and device together).
struct MemoryTracker {
  std::atomic<std::uint64_t> current{0};
  std::atomic<std::uint64_t> peak{0};
  std::uint64_t budget = 0;  // 0 = unlimited
  void add(std::uint64_t b) {
    const std::uint64_t now = current.fetch_add(b) + b;
    std::uint64_t p = peak.load();
    while (now > p && !peak.compare_exchange_weak(p, now)) {}
  }
  void sub(std::uint64_t b) { current.fetch_sub(b); }
  // Throws NBMC_ERROR_MEMORY_BUDGET if `bytes` more would pass the budget.
  void require(std::uint64_t bytes, const std::string& what) const;
  void reset_peak() { peak.store(current.load()); }
};

inline void MemoryTracker::require(std::uint64_t bytes, const std::string& what) const {
  if (!budget || current.load() + bytes <= budget) return;
  const double mib = 1.0 / (1024.0 * 1024.0);
  char msg[512];
  std::snprintf(msg, sizeof msg, "%s needs %.1f MiB more (%.1f MiB in use), over the memory budget of %.1f MiB",
                what.c_str(), double(bytes) * mib, double(current.load()) * mib, double(budget) * mib);
  throw Error(10 /*NBMC_ERROR_MEMORY_BUDGET*/, msg);
}

// Progress/cancellation hook supplied by the C API layer.
struct Progress {
  std::function<bool(int stage, double fraction)> fn;  // returns false to cancel
  void operator()(int stage, double fraction) const;
};

namespace Details {

// NBMC_TRACE=1 prints the time since the previous trace point (after a
// fence) to stderr: a poor man's profiler for machines without tools.
inline void trace(const char* what, std::uint64_t n = 0) {
  if (!host_trace_on()) return;
  static Kokkos::Timer timer;
  Kokkos::fence();
  std::fprintf(stderr, "[nbmc trace] %-28s n=%-10llu %9.3f ms\n", what, (unsigned long long)n, timer.seconds() * 1e3);
  timer.reset();
}

// Names a region for Kokkos Tools ("nbmc::..."); Kokkos 3.4 has no RAII form.
struct ScopedRegion {
  explicit ScopedRegion(const std::string& name) { Kokkos::Profiling::pushRegion(name); }
  ~ScopedRegion() { Kokkos::Profiling::popRegion(); }
  ScopedRegion(const ScopedRegion&) = delete;
  ScopedRegion& operator=(const ScopedRegion&) = delete;
};

#if defined(KOKKOS_ENABLE_CUDA)
// Device buffers come from a stream-ordered memory pool of nbmc's own
// (pipeline_cuda.cpp), allocated and freed in the order of Kokkos' default
// CUDA stream: a frame makes dozens of buffers, and cudaMalloc with
// cudaFree (which also waits for the device) cost 70-110 us each on an
// H100 machine (bench/alloc_micro.cu). NBMC_DEVICE_POOL=0 in the
// environment (read once) allocates with cudaMalloc instead.
void* device_pool_allocate(std::size_t bytes, const std::string& what, bool zero);
void device_pool_free(void* p) noexcept;
#endif

// A labelled, tracked 1-D allocation in a memory space.
template <class T, class MemSpace>
class Buffer {
 public:
  using view_type = Kokkos::View<T*, MemSpace>;
  Buffer() = default;
  Buffer(MemoryTracker& tracker, const std::string& label, std::size_t n, bool zero = false)
      : tracker_(&tracker) {
    const std::uint64_t bytes = std::uint64_t(n) * sizeof(T);
    tracker.require(bytes, "nbmc::" + label);
#if defined(KOKKOS_ENABLE_CUDA)
    if constexpr (std::is_same<MemSpace, Kokkos::CudaSpace>::value) {
      if (n > 0) {
        pooled_ = device_pool_allocate(bytes, "nbmc::" + label, zero);
        view_ = view_type(static_cast<T*>(pooled_), n);  // (unmanaged: the Buffer owns it)
      }
      bytes_ = bytes;
      tracker.add(bytes_);
      return;
    }
#endif
    if (zero)
      view_ = view_type("nbmc::" + label, n);
    else
      view_ = view_type(Kokkos::view_alloc(Kokkos::WithoutInitializing, "nbmc::" + label), n);
    bytes_ = bytes;
    tracker.add(bytes_);
  }
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  Buffer(Buffer&& o) noexcept { swap(o); }
  Buffer& operator=(Buffer&& o) noexcept {
    if (this != &o) { release(); swap(o); }
    return *this;
  }
  ~Buffer() { release(); }
  void release() {
    if (tracker_ && bytes_) tracker_->sub(bytes_);
    view_ = view_type();
    bytes_ = 0;
#if defined(KOKKOS_ENABLE_CUDA)
    if (pooled_) device_pool_free(pooled_);
#endif
    pooled_ = nullptr;
  }
  const view_type& view() const { return view_; }
  std::size_t size() const { return view_.extent(0); }
  T* data() const { return view_.data(); }

 private:
  void swap(Buffer& o) noexcept {
    std::swap(view_, o.view_);
    std::swap(tracker_, o.tracker_);
    std::swap(bytes_, o.bytes_);
    std::swap(pooled_, o.pooled_);
  }
  view_type view_;
  MemoryTracker* tracker_ = nullptr;
  std::uint64_t bytes_ = 0;
  void* pooled_ = nullptr;  // (CUDA: the pool's allocation that view_ shows)
};

// ------------------------------------------------------------ Morton keys
// 21 bits per axis, 63-bit keys (bit 63 stays clear: ~0 marks empty slots):
// morton3, spread3, compact3 in src/core/grid.hpp.
constexpr std::uint64_t kEmptyKey = ~std::uint64_t(0);

KOKKOS_INLINE_FUNCTION std::uint64_t hash64(std::uint64_t k) {
  k ^= k >> 33;
  k *= 0xff51afd7ed558ccdULL;
  k ^= k >> 33;
  k *= 0xc4ceb9fe1a85ec53ULL;
  k ^= k >> 33;
  return k;
}

KOKKOS_INLINE_FUNCTION int popcount64(std::uint64_t x) {
#if defined(__CUDA_ARCH__)
  return __popcll(x);
#elif defined(__POPCNT__) || !(defined(__GNUC__) || defined(__clang__))
  return __builtin_popcountll(x);
#else
  // Without the POPCNT instruction (plain x86-64), __builtin_popcountll is a
  // call into libgcc; this inline form is several times faster (the band
  // index of every vertex access goes through here).
  x = x - ((x >> 1) & 0x5555555555555555ULL);
  x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
  return int((x * 0x0101010101010101ULL) >> 56);
#endif
}

KOKKOS_INLINE_FUNCTION int ctz64(std::uint64_t x) {
#if defined(__CUDA_ARCH__)
  return __ffsll((long long)x) - 1;
#else
  return __builtin_ctzll(x);
#endif
}

inline std::size_t next_pow2(std::size_t n) {
  std::size_t p = 1;
  while (p < n) p <<= 1;
  return p;
}

// Open-addressing hash map uint64 key -> uint32 value (linear probing). Keys are
// inserted in parallel with CAS; the set of keys (not their slots) is what the
// pipeline depends on, so results are independent of the insertion order.
template <class MemSpace>
struct HashMap {
  Kokkos::View<std::uint64_t*, MemSpace> keys;
  Kokkos::View<std::uint32_t*, MemSpace> values;
  std::uint64_t mask = 0;

  // Returns true if the key was newly inserted.
  KOKKOS_INLINE_FUNCTION bool insert(std::uint64_t key) const {
    std::uint64_t slot = hash64(key) & mask;
    while (true) {
      const std::uint64_t empty = ~std::uint64_t(0);  // kEmptyKey, by value for device code
      const std::uint64_t prev = Kokkos::atomic_compare_exchange(&keys(slot), empty, key);
      if (prev == empty) return true;
      if (prev == key) return false;
      slot = (slot + 1) & mask;
    }
  }
  // Whether the key is in the map while other threads may be inserting: a
  // key seen is there for good, a false may be stale (the caller then
  // inserts). Passes whose inserts mostly find their key call it first:
  // insert's compare-and-swap takes the slot exclusively even for a key
  // already there (host: its cache line, contended between threads; GPU:
  // atomics on one address serialise).
  KOKKOS_INLINE_FUNCTION bool seen(std::uint64_t key) const {
    std::uint64_t slot = hash64(key) & mask;
    while (true) {
      const std::uint64_t k = Kokkos::volatile_load(&keys(slot));
      if (k == key) return true;
      if (k == ~std::uint64_t(0)) return false;
      slot = (slot + 1) & mask;
    }
  }
  // Slot of the key, or -1.
  KOKKOS_INLINE_FUNCTION std::int64_t find_slot(std::uint64_t key) const {
    std::uint64_t slot = hash64(key) & mask;
    while (true) {
      const std::uint64_t k = keys(slot);
      if (k == key) return std::int64_t(slot);
      if (k == ~std::uint64_t(0)) return -1;
      slot = (slot + 1) & mask;
    }
  }
  // Value of the key, or ~0u.
  KOKKOS_INLINE_FUNCTION std::uint32_t find(std::uint64_t key) const {
    const std::int64_t s = find_slot(key);
    return s < 0 ? ~0u : values(s);
  }
};

template <class MemSpace>
struct HashMapStorage {
  Buffer<std::uint64_t, MemSpace> keys;
  Buffer<std::uint32_t, MemSpace> values;
  HashMap<MemSpace> map;
  template <class ExecSpace>
  void allocate(const ExecSpace& space, MemoryTracker& t, const std::string& label, std::size_t expected) {
    const std::size_t cap = next_pow2(std::max<std::size_t>(16, expected + expected / 2 + 1));
    keys = Buffer<std::uint64_t, MemSpace>(t, label + "::keys", cap);
    values = Buffer<std::uint32_t, MemSpace>(t, label + "::values", cap);
    Kokkos::deep_copy(space, keys.view(), kEmptyKey);
    map.keys = keys.view();
    map.values = values.view();
    map.mask = cap - 1;
  }
};

#if defined(KOKKOS_ENABLE_CUDA)
// Stable radix sort of (key, value) pairs by the key bits [0, end_bit), on
// the GPU (CUB, pipeline_cuda.cpp). The sorted pairs are written to
// keys_out/vals_out; keys_in/vals_in are left unspecified.
void device_sort_pairs(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint64_t* keys_in,
                       std::uint64_t* keys_out, std::uint32_t* vals_in, std::uint32_t* vals_out, std::size_t n,
                       int end_bit);

// In-place exclusive prefix sum of n values on the GPU (CUB's single-pass
// scan, pipeline_cuda.cpp; queued on `space`, not fenced). Kokkos 3.4's
// parallel_scan runs two passes over its functor: about 160 µs for the
// 6.8 M band vertices of the 1.65 M frame at r/2 (ncu, H100), several times
// this one. uint32 sums wrap modulo 2^32 as the truncated uint64 prefix of
// the Kokkos path does.
void device_exclusive_sum(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint32_t* data, std::size_t n);
void device_exclusive_sum(const Kokkos::Cuda& space, MemoryTracker& tracker, std::uint64_t* data, std::size_t n);

// One device array to copy into host memory.
struct DownloadSegment {
  void* host;
  const void* device;
  std::size_t bytes;
};
// Copies `bytes` on the host threads: kokkos_host_copy on Kokkos' host
// space's (only on the thread that initialised Kokkos: the pipeline's).
using HostCopy = void (*)(char* dst, const char* src, std::size_t bytes);
void kokkos_host_copy(char* dst, const char* src, std::size_t bytes);
// Copies the segments from device to (pageable, possibly untouched) host
// memory after the work queued on `space`: through a pinned staging ring,
// the GPU's copy of one chunk overlapping the host threads' copy of the
// previous one (pipeline_cuda.cpp).
void download_segments(const Kokkos::Cuda& space, const DownloadSegment* segments, std::size_t n,
                       HostCopy copy = kokkos_host_copy);
// One host array to copy into device memory.
struct UploadSegment {
  void* device;
  const void* host;
  std::size_t bytes;
};
// Copies the segments from (pageable) host to device memory through the
// same ring, the host threads' copy of one chunk into it overlapping the
// GPU's copy of the previous one; returns when the GPU has them all.
void upload_segments(const Kokkos::Cuda& space, const UploadSegment* segments, std::size_t n,
                     HostCopy copy = kokkos_host_copy);
#endif

// Exclusive prefix sums of count(i), i < n, into offsets (a view of uint32 or
// uint64): offsets(i) = count(0) + ... + count(i - 1), truncated to the
// view's type; returns the total, exact in 64 bits (also where 32-bit
// offsets wrap). `count` may read offsets(i) itself (it is read before that
// is written). Host: one Kokkos scan. GPU: one pass writes the counts and
// sums them, then device_exclusive_sum scans them in place. With
// need_total false: returns 0, and on the GPU nothing waits for the device.
template <class ExecSpace, class OffsetView, class Count>
std::uint64_t prefix_counts(const ExecSpace& space, MemoryTracker& tracker, const std::string& label, std::size_t n,
                            const OffsetView& offsets, const Count& count, bool need_total = true) {
  using value_t = typename OffsetView::value_type;
  static_assert(std::is_same<value_t, std::uint32_t>::value || std::is_same<value_t, std::uint64_t>::value,
                "offsets of uint32 or uint64");
  std::uint64_t total = 0;
  if (n == 0) return 0;
#if defined(KOKKOS_ENABLE_CUDA)
  if constexpr (std::is_same<ExecSpace, Kokkos::Cuda>::value) {
    if (!need_total) {
      Kokkos::parallel_for(
          label, Kokkos::RangePolicy<ExecSpace>(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t i) { offsets(i) = value_t(count(i)); });
      device_exclusive_sum(space, tracker, offsets.data(), n);
      return 0;
    }
    Kokkos::parallel_reduce(
        label, Kokkos::RangePolicy<ExecSpace>(space, 0, n),
        KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& acc) {
          const std::uint64_t c = std::uint64_t(count(i));
          offsets(i) = value_t(c);
          acc += c;
        },
        total);
    device_exclusive_sum(space, tracker, offsets.data(), n);
    space.fence();
    return total;
  }
#endif
  (void)tracker;
  const auto scan = KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& update, const bool final) {
    const std::uint64_t c = std::uint64_t(count(i));  // read first: count may read offsets(i)
    if (final) offsets(i) = value_t(update);
    update += c;
  };
  if (!need_total) {
    Kokkos::parallel_scan(label, Kokkos::RangePolicy<ExecSpace>(space, 0, n), scan);
    return 0;
  }
  Kokkos::parallel_scan(label, Kokkos::RangePolicy<ExecSpace>(space, 0, n), scan, total);
  space.fence();
  return total;
}

// Exclusive scan of counts into offsets (which may be the same view); returns the total.
template <class ExecSpace, class CountView, class OffsetView>
std::uint64_t exclusive_scan(const ExecSpace& space, MemoryTracker& tracker, const std::string& label,
                             const CountView& counts, const OffsetView& offsets) {
  return prefix_counts(space, tracker, label, counts.extent(0), offsets,
                       KOKKOS_LAMBDA(const std::size_t i) { return counts(i); });
}

}  // namespace Details
}  // namespace nbmc
