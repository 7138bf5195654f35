// SPDX-License-Identifier: MIT
// Explicit instantiation of the pipeline for the host execution spaces.
#include "../../src/backends.hpp"
#include "pipeline.hpp"

namespace nbmc {

void reconstruct_serial(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                        HostMesh& m, RunStats& st) {
  Details::reconstruct(Kokkos::Serial(), xyz, n, p, t, pr, m, st);
}

void reconstruct_openmp(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                        HostMesh& m, RunStats& st) {
#if defined(KOKKOS_ENABLE_OPENMP)
  Details::reconstruct(Kokkos::OpenMP(), xyz, n, p, t, pr, m, st);
#else
  (void)xyz; (void)n; (void)p; (void)t; (void)pr; (void)m; (void)st;
  throw Error(7, "the OpenMP backend is not compiled in");
#endif
}

}  // namespace nbmc
