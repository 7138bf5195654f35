// SPDX-License-Identifier: MIT
// NBMC_TRACE=1 (as backends/kokkos/common.hpp's trace for the kernels): the
// host-side steps (the mesh post-processing) print the time since the
// previous host trace point to stderr. Plain C++, no fence.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

namespace nbmc {

// Whether NBMC_TRACE is set (read once).
inline bool host_trace_on() {
  static const bool on = std::getenv("NBMC_TRACE") != nullptr;
  return on;
}

inline void host_trace(const char* what, std::uint64_t n = 0) {
  if (!host_trace_on()) return;
  using clock = std::chrono::steady_clock;
  static thread_local clock::time_point last = clock::now();
  const clock::time_point now = clock::now();
  std::fprintf(stderr, "[nbmc trace] %-28s n=%-10llu %9.3f ms (host)\n", what, (unsigned long long)n,
               std::chrono::duration<double, std::milli>(now - last).count());
  last = now;
}

}  // namespace nbmc
