// SPDX-License-Identifier: MIT
// Transparent huge pages for large host arrays. Plain C++.
//
// Where the kernel gives huge pages only on request ("madvise", Ubuntu's and
// Debian's default), a fresh array's first touch faults once per 4 KiB: the
// 1.65 M frame's 40 MB of particle coordinates took 24-35 ms to read, mostly
// page faults and the kernel's page clearing, and pinning the context's
// upload buffer for the GPU walks every page. advise_huge_pages asks for
// 2 MiB pages over the array's whole 2 MiB pages (before its first touch);
// NBMC_HOST_THP=0 leaves the kernel's default. Only advice: nothing fails.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace nbmc {

// Arrays smaller than this are left alone (they hold at most a few huge pages).
constexpr std::size_t kHugePageMinBytes = std::size_t(8) << 20;

inline void advise_huge_pages(void* p, std::size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  static const bool on = [] {
    const char* e = std::getenv("NBMC_HOST_THP");
    return !(e && std::strcmp(e, "0") == 0);
  }();
  if (!on || p == nullptr || bytes < kHugePageMinBytes) return;
  constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
  const std::uintptr_t a = (reinterpret_cast<std::uintptr_t>(p) + kHuge - 1) & ~(kHuge - 1);
  const std::uintptr_t b = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(kHuge - 1);
  if (b > a) ::madvise(reinterpret_cast<void*>(a), b - a, MADV_HUGEPAGE);  // advice: errors ignored
#else
  (void)p;
  (void)bytes;
#endif
}

// v.resize(n) for a vector that is about to be filled: the storage is
// allocated, advised, then (value-)initialised.
template <class T>
void resize_for_filling(std::vector<T>& v, std::size_t n) {
  if (n > v.capacity()) {
    std::vector<T> fresh;
    fresh.reserve(n);
    advise_huge_pages(fresh.data(), n * sizeof(T));
    fresh.assign(v.begin(), v.end());
    v.swap(fresh);
  }
  v.resize(n);
}

}  // namespace nbmc
