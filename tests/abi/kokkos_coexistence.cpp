// SPDX-License-Identifier: MIT
// A host program that uses Kokkos itself and nbmc, in both initialisation
// orders (one order per process: Kokkos 3.4 cannot be initialised twice).
//
//   abi_kokkos_coexistence host-first         host initialises and finalises Kokkos;
//                                             nbmc must neither re-initialise nor finalise it
//   abi_kokkos_coexistence nbmc-first         nbmc initialises Kokkos on the host's thread
//                                             (NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD); the host
//                                             uses that runtime, then calls nbmc_kokkos_finalize()
//   abi_kokkos_coexistence nbmc-first-atexit  as nbmc-first, but the runtime is left to be
//                                             finalised at process exit
#include "nbmc.h"

#include <Kokkos_Core.hpp>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace {

int failures = 0;
void check(bool ok, const char* what, int line) {
  if (!ok) {
    std::fprintf(stderr, "kokkos_coexistence.cpp:%d: check failed: %s\n", line, what);
    ++failures;
  }
}
#define CHECK(cond) check((cond), #cond, __LINE__)

// The host's own kernel: sum of 0..n-1 on the default host execution space.
long host_kernel(long n) {
  Kokkos::View<long*, Kokkos::HostSpace> v("host::values", n);
  Kokkos::parallel_for(
      "host::fill", Kokkos::RangePolicy<Kokkos::DefaultHostExecutionSpace>(0, n),
      KOKKOS_LAMBDA(long i) { v(i) = i; });
  long sum = 0;
  Kokkos::parallel_reduce(
      "host::sum", Kokkos::RangePolicy<Kokkos::DefaultHostExecutionSpace>(0, n),
      KOKKOS_LAMBDA(long i, long& acc) { acc += v(i); }, sum);
  return sum;
}

bool kernel_ok() {
  const long n = 10000;
  return host_kernel(n) == n * (n - 1) / 2;
}

// Creates a context, reconstructs a block of particles, destroys everything.
void use_nbmc(int32_t backend) {
  nbmc_context_desc desc;
  nbmc_context_desc_init(&desc);
  desc.backend = backend;
  nbmc_context* ctx = nullptr;
  int32_t s = nbmc_context_create(&desc, &ctx);
  if (s != NBMC_OK) {
    std::fprintf(stderr, "nbmc_context_create(backend %d): %s: %s\n", int(backend), nbmc_status_string(s),
                 nbmc_context_last_error(nullptr));
    CHECK(s == NBMC_OK);
    return;
  }
  std::vector<double> xyz;
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 6; ++j)
      for (int i = 0; i < 6; ++i) xyz.insert(xyz.end(), {0.1 * i, 0.1 * j, 0.1 * k});
  CHECK(nbmc_context_set_particles_f64(ctx, xyz.data(), xyz.size() / 3, 0) == NBMC_OK);
  nbmc_params params;
  nbmc_params_init(&params);
  params.spacing = 0.1;
  nbmc_mesh* mesh = nullptr;
  s = nbmc_context_reconstruct(ctx, &params, &mesh);
  if (s != NBMC_OK) std::fprintf(stderr, "reconstruct: %s\n", nbmc_context_last_error(ctx));
  CHECK(s == NBMC_OK);
  CHECK(nbmc_mesh_triangle_count(mesh) > 0);
  nbmc_context_destroy(ctx);
  CHECK(nbmc_mesh_triangle_count(mesh) > 0);  // meshes outlive contexts
  nbmc_mesh_destroy(mesh);
}

int host_first() {
  Kokkos::initialize();
  CHECK(Kokkos::is_initialized());
  CHECK(kernel_ok());
  for (int32_t b : {NBMC_BACKEND_AUTO, NBMC_BACKEND_SERIAL, NBMC_BACKEND_OPENMP}) {
    if (!nbmc_backend_available(b)) continue;
    use_nbmc(b);
    // nbmc_context_destroy must not finalise a runtime the host owns.
    CHECK(Kokkos::is_initialized());
    CHECK(kernel_ok());
  }
  // Nor may nbmc_kokkos_finalize: it only finalises what nbmc initialised.
  CHECK(nbmc_kokkos_finalize() == NBMC_OK);
  CHECK(Kokkos::is_initialized());
  CHECK(kernel_ok());
  use_nbmc(NBMC_BACKEND_AUTO);  // still usable afterwards
  CHECK(kernel_ok());
  Kokkos::finalize();
  CHECK(!Kokkos::is_initialized());
  return failures;
}

int nbmc_first(bool explicit_finalize) {
  CHECK(!Kokkos::is_initialized());
  nbmc_context* ctx = nullptr;
  // The host wants to share nbmc's runtime: Kokkos on this thread.
  nbmc_context_desc desc;
  nbmc_context_desc_init(&desc);
  desc.flags = NBMC_CONTEXT_KOKKOS_ON_CALLING_THREAD;
  CHECK(nbmc_context_create(&desc, &ctx) == NBMC_OK);
  // nbmc initialised Kokkos; the host sees it and uses it.
  CHECK(Kokkos::is_initialized());
  CHECK(kernel_ok());
  use_nbmc(NBMC_BACKEND_AUTO);  // a second context while the first is alive
  CHECK(kernel_ok());
  CHECK(nbmc_kokkos_finalize() == NBMC_ERROR_INVALID_ARGUMENT);  // ctx is alive
  CHECK(Kokkos::is_initialized());
  nbmc_context_destroy(ctx);
  CHECK(Kokkos::is_initialized());  // destroying the last context does not finalise
  CHECK(kernel_ok());
  if (explicit_finalize) {
    CHECK(nbmc_kokkos_finalize() == NBMC_OK);
    CHECK(!Kokkos::is_initialized());
    // Kokkos 3.4 cannot start again: a clear error, not a crash.
    nbmc_context* again = nullptr;
    CHECK(nbmc_context_create(nullptr, &again) == NBMC_ERROR_BACKEND_UNAVAILABLE);
    CHECK(again == nullptr);
    CHECK(std::strlen(nbmc_context_last_error(nullptr)) > 0);
    CHECK(nbmc_kokkos_finalize() == NBMC_OK);  // idempotent
  }
  return failures;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string mode = argc > 1 ? argv[1] : "";
  int rc;
  if (mode == "host-first")
    rc = host_first();
  else if (mode == "nbmc-first")
    rc = nbmc_first(true);
  else if (mode == "nbmc-first-atexit")
    rc = nbmc_first(false);
  else {
    std::fprintf(stderr, "usage: %s host-first|nbmc-first|nbmc-first-atexit\n", argv[0]);
    return 2;
  }
  if (rc) {
    std::fprintf(stderr, "%s: %d check(s) failed\n", mode.c_str(), rc);
    return 1;
  }
  std::printf("%s: all checks passed\n", mode.c_str());
  return 0;
}
