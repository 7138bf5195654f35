// SPDX-License-Identifier: MIT
// The clean-up's per-vertex scratch for its repair passes, kept from one
// clean-up to the next. Plain C++.
//
// Why: the repair passes (mesh_cleanup.hpp) need per vertex a reservation,
// a stamp, the round it was last written in and the time it last changed,
// 16 bytes. A fresh array had to be filled before each clean-up: 13.5 MB
// for the 1.65 M frame's mesh at r/2, 108 MB for the 13.2 M frame's, which
// took 0.55-1.7 ms and 2.8-30 ms of the H200 machine's 16 host threads
// (NBMC_TRACE's "setup" of the first pass; bench/RESULTS.md, session 41).
// Every stamp, round and time in it is relative to counters that only grow
// (kept with it), and a pass that ends leaves every reservation free, so a
// block that one clean-up gives back is valid for the next as it is: only
// a new block is filled, and a kept one whose counters would wrap.
//
// What it keeps: at most kKept blocks of at least kMinVertices vertices
// (smaller ones are made and filled each time, which costs little); a
// clean-up takes the smallest kept block that holds its vertices and is at
// most twice as large. A block whose pass ended with an error is not kept.
// release() drops them all (the library's last context destroyed, as the
// host block cache); NBMC_HOST_CACHE=0 keeps none. (Unlike the host block
// cache, it keeps blocks under AddressSanitizer too: a kept block is never
// freed while kept, so it hides no use after free, and the sanitized tests
// run the reuse.)
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "host_cache.hpp"
#include "parallel.hpp"
#include "params.hpp"

namespace nbmc {
namespace mesh {
namespace detail {

struct RepairSlot {
  // The first item of the current round whose region holds the vertex
  // (kFree: none).
  std::atomic<std::uint32_t> reserve;
  // The last item that committed with the vertex in its region (a stamp),
  // and the last round in which such an item wrote something.
  std::uint32_t stamp, wrote;
  // The time of the last repair that changed the vertex's position or
  // triangles.
  std::uint32_t mod;
};

struct RepairScratch {
  static constexpr std::uint32_t kFree = 0xffffffffu;
  NoInitArray<RepairSlot> slots;
  std::size_t vertices = 0;
  // The counters: the last stamp and round handed out, the next time.
  std::uint32_t stamp_base = 0, round_base = 0, time_next = 1;
  // False while a pass may hold reservations (between its rounds' start
  // and their normal end).
  bool clean = true;

  // A new block for nv vertices, filled on the host threads.
  explicit RepairScratch(std::size_t nv) : slots(nv), vertices(nv) {
    fill([](RepairSlot& s) {
      s.reserve.store(kFree, std::memory_order_relaxed);
      s.stamp = s.wrote = s.mod = 0;
    });
  }
  // When the stamps or rounds would wrap: every stamp and round back to 0.
  void reset_stamps() {
    fill([](RepairSlot& s) { s.stamp = s.wrote = 0; });
    stamp_base = round_base = 0;
  }
  // When the times would wrap: every time back to 0 (the caller forgets
  // the failures it recorded with the old times).
  void reset_times() {
    fill([](RepairSlot& s) { s.mod = 0; });
    time_next = 1;
  }

 private:
  template <class F>
  void fill(const F& f) {
    for_chunks(vertices, chunk_count(vertices, 65536), [&](std::size_t, std::size_t b, std::size_t e) {
      for (std::size_t x = b; x < e; ++x) f(slots[x]);
    });
  }
};

class RepairScratchPool {
 public:
  static constexpr std::size_t kKept = 2;
  static constexpr std::size_t kMinVertices = std::size_t(1) << 16;

  // False with NBMC_HOST_CACHE=0 in the environment (the host block
  // cache's switch, without its AddressSanitizer exception).
  static bool enabled() { return HostBlockCache::switched_on(); }

  static RepairScratchPool& instance() {
    static RepairScratchPool* p = new RepairScratchPool();  // never destroyed, as the host block cache
    return *p;
  }

  // A block for nv vertices: a kept one, or a new one filled here.
  std::unique_ptr<RepairScratch> take(std::size_t nv) {
    if (nv >= kMinVertices && enabled()) {
      std::lock_guard<std::mutex> lock(m_);
      std::size_t best = kept_.size();
      for (std::size_t k = 0; k < kept_.size(); ++k)
        if (kept_[k]->vertices >= nv && kept_[k]->vertices / 2 <= nv &&
            (best == kept_.size() || kept_[k]->vertices < kept_[best]->vertices))
          best = k;
      if (best != kept_.size()) {
        std::unique_ptr<RepairScratch> s = std::move(kept_[best]);
        kept_.erase(kept_.begin() + std::ptrdiff_t(best));
        return s;
      }
    }
    return std::unique_ptr<RepairScratch>(new RepairScratch(nv));
  }

  // Takes back a block that holds no reservation (else it is freed); the
  // oldest kept block goes when there are more than kKept.
  void give(std::unique_ptr<RepairScratch> s) noexcept {
    if (!s || !s->clean || s->vertices < kMinVertices || !enabled()) return;
    std::unique_ptr<RepairScratch> dropped;
    std::lock_guard<std::mutex> lock(m_);
    try {
      kept_.push_back(std::move(s));
    } catch (...) {
      return;  // (no room to keep it: freed)
    }
    if (kept_.size() > kKept) {
      dropped = std::move(kept_.front());
      kept_.erase(kept_.begin());
    }
  }

  void release() noexcept {
    std::vector<std::unique_ptr<RepairScratch>> dropped;
    std::lock_guard<std::mutex> lock(m_);
    dropped.swap(kept_);
  }

 private:
  RepairScratchPool() = default;
  std::mutex m_;
  std::vector<std::unique_ptr<RepairScratch>> kept_;
};

}  // namespace detail
}  // namespace mesh
}  // namespace nbmc
