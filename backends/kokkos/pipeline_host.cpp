// SPDX-License-Identifier: MIT
// Explicit instantiation of the pipeline for the host execution spaces.
#include "../../src/backends.hpp"
#include "attributes.hpp"
#include "pipeline.hpp"

namespace nbmc {

void reconstruct_serial(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr, HostMesh& m,
                        RunStats& st) {
  Details::reconstruct(Kokkos::Serial(), in, p, t, pr, false, m, st);
}

void reconstruct_openmp(const ParticleInput& in, const Params& p, MemoryTracker& t, const Progress& pr, HostMesh& m,
                        RunStats& st) {
#if defined(KOKKOS_ENABLE_OPENMP)
  Details::reconstruct(Kokkos::OpenMP(), in, p, t, pr, false, m, st);
#else
  (void)in; (void)p; (void)t; (void)pr; (void)m; (void)st;
  throw Error(7, "the OpenMP backend is not compiled in");
#endif
}

bool interpolate_attributes_serial(const AttributeJob& job, MemoryTracker& t) {
  return Details::interpolate_attributes(Kokkos::Serial(), t, job);
}

bool interpolate_attributes_openmp(const AttributeJob& job, MemoryTracker& t) {
#if defined(KOKKOS_ENABLE_OPENMP)
  return Details::interpolate_attributes(Kokkos::OpenMP(), t, job);
#else
  (void)job; (void)t;
  throw Error(7, "the OpenMP backend is not compiled in");
#endif
}

}  // namespace nbmc
