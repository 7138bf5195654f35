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

// Cleans (params.cleanup) and smooths (params.smooth_iterations) the mesh on
// the host, serially (the result depends only on the mesh), and updates the
// counts and the NBMC_STAGE_POSTPROCESS time in st. A mesh left in device
// memory is copied to the host for it and back into its device arrays.
mesh::PostprocessStats postprocess_mesh(const nbmc_params& params, HostMesh& mesh, RunStats& st);

}  // namespace nbmc
