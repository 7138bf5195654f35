// SPDX-License-Identifier: MIT
// NBMC_TRACE=1 (as backends/kokkos/common.hpp's trace for the kernels): the
// host-side steps (the mesh post-processing) print the time since the
// previous host trace point to stderr, and the process' minor page faults
// since then (all threads: first writes to fresh pages, a few microseconds
// each). Plain C++, no fence.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#if defined(__unix__)
#include <sys/resource.h>
#endif

namespace nbmc {

// Whether NBMC_TRACE is set (read once).
inline bool host_trace_on() {
  static const bool on = std::getenv("NBMC_TRACE") != nullptr;
  return on;
}

// The process' minor page faults so far (0 where unknown).
inline long host_minor_faults() {
#if defined(__unix__)
  rusage u{};
  if (getrusage(RUSAGE_SELF, &u) == 0) return long(u.ru_minflt);
#endif
  return 0;
}
inline void host_trace(const char* what, std::uint64_t n = 0) {
  if (!host_trace_on()) return;
  using clock = std::chrono::steady_clock;
  static thread_local clock::time_point last = clock::now();
  static thread_local long last_faults = host_minor_faults();
  const clock::time_point now = clock::now();
  const long faults = host_minor_faults();
  std::fprintf(stderr, "[nbmc trace] %-28s n=%-10llu %9.3f ms (host, %ld faults)\n", what, (unsigned long long)n,
               std::chrono::duration<double, std::milli>(now - last).count(), faults - last_faults);
  last = now;
  last_faults = faults;
}

}  // namespace nbmc
