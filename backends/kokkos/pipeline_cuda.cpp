// SPDX-License-Identifier: MIT
// Explicit instantiation of the pipeline for the CUDA execution space.
#include "../../src/backends.hpp"
#include "pipeline.hpp"

namespace nbmc {

void reconstruct_cuda(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                      HostMesh& m, RunStats& st, int device) {
#if defined(KOKKOS_ENABLE_CUDA)
  (void)device;  // Kokkos 3.4 binds one device at initialisation
  Details::reconstruct(Kokkos::Cuda(), xyz, n, p, t, pr, m, st);
#else
  (void)xyz; (void)n; (void)p; (void)t; (void)pr; (void)m; (void)st; (void)device;
  throw Error(7, "the CUDA backend is not compiled in");
#endif
}

}  // namespace nbmc
