// SPDX-License-Identifier: MIT
// Backend selection, the Kokkos runtime's lifetime, and dispatch of a
// reconstruction to the execution space of a context.
#pragma once

#include "context.hpp"

namespace nbmc {

const char* version_string();
const char* backend_name(int32_t backend);
bool backend_available(int32_t backend);
int32_t auto_backend();

// Kokkos is initialised by the first context unless the host did it; nbmc
// finalises only what it initialised.
void runtime_acquire(nbmc_context& ctx);
void runtime_release(nbmc_context& ctx);
bool runtime_finalize();
// Upper bound of the OpenMP threads a context gets (4x the cores, at least 16).
int max_threads();

// Validates the user's parameters and converts them to absolute units.
Params resolve_params(const nbmc_params& in);
// Rejects parameter/particle combinations whose grid could not be indexed.
void check_domain(const std::vector<double>& xyz, const Params& p);

void run_backend(nbmc_context& ctx, const Params& p, HostMesh& mesh, RunStats& st);

// Explicit instantiations, one file per backend (pipeline_*.cpp).
void reconstruct_serial(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                        HostMesh& m, RunStats& st);
void reconstruct_openmp(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                        HostMesh& m, RunStats& st);
void reconstruct_cuda(const double* xyz, std::size_t n, const Params& p, MemoryTracker& t, const Progress& pr,
                      HostMesh& m, RunStats& st, int device);

}  // namespace nbmc
