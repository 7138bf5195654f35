// SPDX-License-Identifier: MIT
// Mesh post-processing behind the C API (src/capi_mesh.cpp): the clean-up
// and smoothing that nbmc_context_reconstruct applies to a finished mesh.
#pragma once

#include "nbmc.h"

#include "context.hpp"
#include "core/mesh_postprocess.hpp"

namespace nbmc {

// Throws Error(NBMC_ERROR_INVALID_PARAMETER) for post-processing parameters
// out of range (before the reconstruction runs).
void check_postprocess_params(const nbmc_params& params);

// The particles that feature-weighted smoothing counts around each vertex
// (host memory, 3 doubles each) and the lengths it uses (absolute).
struct FeatureParticles {
  const double* xyz = nullptr;
  std::size_t count = 0;
  double radius = 0;   // the influence radius R
  double spacing = 0;  // r
};

// Cleans (params.cleanup), smooths (params.smooth_iterations, weighted by
// params.smooth_weighting) and decimates (params.decimate_fraction) the mesh
// on the host (the result depends only on the mesh, and for feature weights
// on the particles), and updates the counts and the NBMC_STAGE_POSTPROCESS
// time in st. A mesh left in device memory is copied to the host for it and
// back into its device arrays. particles: needed (non-null) for
// NBMC_SMOOTH_FEATURE with smoothing on, else unused. Each step is counted
// in tracker while it runs (its estimate from core/mesh_memory.hpp plus the
// mesh) and refused with NBMC_ERROR_MEMORY_BUDGET, before it changes the
// mesh, when that would pass tracker's budget.
mesh::PostprocessStats postprocess_mesh(const nbmc_params& params, HostMesh& mesh, RunStats& st, MemoryTracker& tracker,
                                        const FeatureParticles* particles = nullptr);

}  // namespace nbmc
