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
// that holds it and is at most a quarter larger. Blocks are whole pages
// from std::aligned_alloc (advised for huge pages: huge_pages.hpp) and go
// back with std::free, so a block freed through another copy of this header
// (another shared object) is simply freed. Off under AddressSanitizer (kept blocks
// would hide use-after-free) and with NBMC_HOST_CACHE=0.
//
// Page-locked blocks (pin_for_device): the CUDA backend's mesh download
// asks for each destination array whether its block may be page-locked;
// a block that serves its second request or a later one is locked once and
// stays locked while the cache holds it, so the GPU copies a sequence's
// next meshes straight into it instead of through the pinned staging ring
// and the host threads' copies out of it. NBMC_HOST_PIN=0 locks nothing.
// A locked block must come back through this copy of the cache (which
// unlocks it before freeing it); the library's arrays do.
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
  static constexpr std::size_t kMinBytes = std::size_t(4) << 20;
  static constexpr std::size_t kCapacity = std::size_t(1) << 30;
  // Page-locked blocks (pin_for_device), kept or in use, at most this many bytes.
  static constexpr std::size_t kPinnedCapacity = kCapacity;

  // Page-locks and unlocks host memory for a device's copies (the CUDA
  // backend's cudaHostRegister and cudaHostUnregister): pin returns whether
  // the range is locked now. Plain function pointers: this header knows no
  // device.
  using PinFn = bool (*)(void* p, std::size_t bytes);
  using UnpinFn = void (*)(void* p);

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
    return switched_on();
  }
  // False with NBMC_HOST_CACHE=0 in the environment (read once); enabled()
  // also asks for AddressSanitizer.
  static bool switched_on() {
    static const bool on = [] {
      const char* e = std::getenv("NBMC_HOST_CACHE");
      return !(e && std::strcmp(e, "0") == 0);
    }();
    return on;
  }

  // NBMC_HOST_PIN=0: no block is page-locked (pin_for_device says no).
  static bool pinning_enabled() {
    static const bool on = [] {
      const char* e = std::getenv("NBMC_HOST_PIN");
      return !(e && std::strcmp(e, "0") == 0);
    }();
    return on && enabled();
  }

  void* allocate(std::size_t bytes) {
    {
      std::lock_guard<std::mutex> lock(m_);
      std::size_t best = kept_.size();
      for (std::size_t k = 0; k < kept_.size(); ++k)
        if (kept_[k].bytes >= bytes && kept_[k].bytes - bytes <= bytes / 4 &&
            (best == kept_.size() || kept_[k].bytes < kept_[best].bytes))
          best = k;
      if (best != kept_.size()) {
        Block b = kept_[best];
        kept_.erase(kept_.begin() + std::ptrdiff_t(best));
        kept_bytes_ -= b.bytes;
        b.reused = true;
        live_[b.p] = b;
        return b.p;
      }
    }
    // Whole pages of their own (page-locking works on whole pages: two
    // blocks sharing one could not both be locked).
    bytes = (bytes + kPage - 1) / kPage * kPage;
    void* p = std::aligned_alloc(kPage, bytes);
    if (!p) throw std::bad_alloc();
    advise_huge_pages(p, bytes);
    std::lock_guard<std::mutex> lock(m_);
    live_[p] = Block{p, bytes, false, false};
    return p;
  }

  void deallocate(void* p) noexcept {
    {
      std::lock_guard<std::mutex> lock(m_);
      const auto it = live_.find(p);
      if (it != live_.end()) {
        const Block b = it->second;
        live_.erase(it);
        if (b.bytes <= kCapacity) {
          while (kept_bytes_ + b.bytes > kCapacity) {
            drop(kept_.front());
            kept_bytes_ -= kept_.front().bytes;
            kept_.pop_front();
          }
          kept_.push_back(b);
          kept_bytes_ += b.bytes;
          return;
        }
        drop(b);
        return;
      }
    }
    std::free(p);
  }

  // Frees every kept block (the blocks in use stay theirs), unlocking the
  // page-locked ones first.
  void release() noexcept {
    std::lock_guard<std::mutex> lock(m_);
    for (const Block& b : kept_) drop(b);
    kept_.clear();
    kept_bytes_ = 0;
  }

  std::size_t kept_bytes() {
    std::lock_guard<std::mutex> lock(m_);
    return kept_bytes_;
  }
  std::size_t pinned_bytes() {
    std::lock_guard<std::mutex> lock(m_);
    return pinned_bytes_;
  }

  // Whether [p, p + bytes) may be a device copy's direct destination: true
  // where p is a block this cache handed out that is page-locked, now or
  // by this call. A block is locked (through pin, once) only when it serves
  // a request for the second time or later: its pages are then in memory
  // (locking untouched pages costs about five times as much, and a single
  // frame would pay it for nothing), and a sequence's next frame, which
  // takes the same blocks, copies straight into them. unpin unlocks it
  // before it is freed (release, or the oldest leaving a full cache).
  bool pin_for_device(const void* p, std::size_t bytes, PinFn pin, UnpinFn unpin) {
    if (!pinning_enabled() || p == nullptr || bytes == 0) return false;
    std::lock_guard<std::mutex> lock(m_);
    const auto it = live_.find(const_cast<void*>(p));
    if (it == live_.end() || it->second.bytes < bytes) return false;
    Block& b = it->second;
    if (b.pinned) return true;
    if (!b.reused || pinned_bytes_ + b.bytes > kPinnedCapacity) return false;
    if (!pin(b.p, b.bytes)) return false;
    unpin_ = unpin;
    b.pinned = true;
    pinned_bytes_ += b.bytes;
    return true;
  }

 private:
  static constexpr std::size_t kPage = 4096;
  struct Block {
    void* p;
    std::size_t bytes;  // its real size
    bool reused;        // handed out more than once
    bool pinned;        // page-locked (pin_for_device)
  };
  // Frees a block that has left the cache's lists (under m_).
  void drop(const Block& b) noexcept {
    if (b.pinned) {
      unpin_(b.p);
      pinned_bytes_ -= b.bytes;
    }
    std::free(b.p);
  }

  std::mutex m_;
  std::deque<Block> kept_;  // oldest first
  std::size_t kept_bytes_ = 0, pinned_bytes_ = 0;
  std::unordered_map<void*, Block> live_;  // handed out
  UnpinFn unpin_ = nullptr;  // set with the first locked block
};

}  // namespace nbmc
