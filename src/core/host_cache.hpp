// SPDX-License-Identifier: MIT
// Large host blocks kept after they are freed, for the next frame's arrays
// of about the same size (NoInitAllocator in params.hpp). Plain C++.
//
// Why: glibc maps every block of 32 MiB or more afresh and unmaps it on
// free, so each frame's mesh (and each large clean-up array) first-touches
// fresh pages, one page fault each. On the H100 machines the GPU's mesh
// download was bound by those faults: the host's copies out of the pinned
// ring took 3.2-6.4 ms for the 1.65 M frame's 40 MB mesh and 32-37 ms for
// the 13.2 M frame's 324 MB, while the host waited for the GPU's copies
// 0.1-0.5 ms (NBMC_TRACE=1; bench/RESULTS.md, session 26). A sequence's
// next frame now writes into pages that are already there.
//
// What it keeps: freed blocks of at least kMinBytes, at most kCapacity bytes
// in all (the oldest go first); a request takes the smallest kept block
// that holds it and is at most a quarter larger. Blocks come from
// std::malloc (advised for huge pages: huge_pages.hpp) and go back with
// std::free, so a block freed through another copy of this header (another
// shared object) is simply freed. Off under AddressSanitizer (kept blocks
// would hide use-after-free) and with NBMC_HOST_CACHE=0.
#pragma once

#include "huge_pages.hpp"

#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <new>
#include <unordered_map>
#include <utility>

namespace nbmc {

class HostBlockCache {
 public:
  static constexpr std::size_t kMinBytes = std::size_t(16) << 20;
  static constexpr std::size_t kCapacity = std::size_t(1) << 30;

  static HostBlockCache& instance() {
    static HostBlockCache* c = new HostBlockCache();  // never destroyed: blocks may be freed at exit
    return *c;
  }

  static bool enabled() {
#if defined(__SANITIZE_ADDRESS__)
    return false;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
    return false;
#endif
#endif
    static const bool on = [] {
      const char* e = std::getenv("NBMC_HOST_CACHE");
      return !(e && std::strcmp(e, "0") == 0);
    }();
    return on;
  }

  void* allocate(std::size_t bytes) {
    {
      std::lock_guard<std::mutex> lock(m_);
      std::size_t best = kept_.size();
      for (std::size_t k = 0; k < kept_.size(); ++k)
        if (kept_[k].second >= bytes && kept_[k].second - bytes <= bytes / 4 &&
            (best == kept_.size() || kept_[k].second < kept_[best].second))
          best = k;
      if (best != kept_.size()) {
        const std::pair<void*, std::size_t> b = kept_[best];
        kept_.erase(kept_.begin() + std::ptrdiff_t(best));
        kept_bytes_ -= b.second;
        live_[b.first] = b.second;
        return b.first;
      }
    }
    void* p = std::malloc(bytes);
    if (!p) throw std::bad_alloc();
    advise_huge_pages(p, bytes);
    std::lock_guard<std::mutex> lock(m_);
    live_[p] = bytes;
    return p;
  }

  void deallocate(void* p) noexcept {
    std::size_t size = 0;
    {
      std::lock_guard<std::mutex> lock(m_);
      const auto it = live_.find(p);
      if (it != live_.end()) {
        size = it->second;
        live_.erase(it);
        if (size <= kCapacity) {
          while (kept_bytes_ + size > kCapacity) {
            std::free(kept_.front().first);
            kept_bytes_ -= kept_.front().second;
            kept_.pop_front();
          }
          kept_.emplace_back(p, size);
          kept_bytes_ += size;
          return;
        }
      }
    }
    std::free(p);
  }

  // Frees every kept block (the blocks in use stay theirs).
  void release() noexcept {
    std::lock_guard<std::mutex> lock(m_);
    for (const auto& b : kept_) std::free(b.first);
    kept_.clear();
    kept_bytes_ = 0;
  }

  std::size_t kept_bytes() {
    std::lock_guard<std::mutex> lock(m_);
    return kept_bytes_;
  }

 private:
  std::mutex m_;
  std::deque<std::pair<void*, std::size_t>> kept_;  // oldest first
  std::size_t kept_bytes_ = 0;
  std::unordered_map<void*, std::size_t> live_;  // handed out: their real sizes
};

}  // namespace nbmc
