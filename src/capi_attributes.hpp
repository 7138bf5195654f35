// SPDX-License-Identifier: MIT
// Particle attributes behind the C API (src/capi_attributes.cpp): their
// interpolation onto the finished mesh, and what the writers get.
#pragma once

#include "nbmc.h"

#include "context.hpp"
#include "io/attributes.hpp"

#include <string>
#include <vector>

namespace nbmc {

// Interpolates ctx.attributes onto the vertices of out (after the
// post-processing) with the field's kernel of radius p.influence_radius, on
// the context's backend, and stores them in out.attributes; adds the time to
// st.stage[NBMC_STAGE_ATTRIBUTES]. Nothing when ctx has no attributes.
void interpolate_mesh_attributes(nbmc_context& ctx, const Params& p, nbmc_mesh& out, RunStats& st);

// The kernel-weighted means of the attributes of n particles (xyz: host, or
// CUDA memory with on_device) at nv vertices (vertices, or vertices64 when
// not NULL), side by side per vertex (the attributes' components in order);
// a vertex with no particle within radius takes its nearest particle's
// values. bounds (lo[3], hi[3]; may be NULL: the particles' own) fix the
// cell grid, so that ranks holding parts of a frame sum in the whole
// frame's order.
std::vector<double, NoInitAllocator<double>> interpolate_at_vertices(nbmc_context& ctx, const double* xyz,
                                                                      bool on_device, std::size_t n,
                                                                      const std::vector<io::Attribute>& attributes,
                                                                      const float* vertices, const double* vertices64,
                                                                      std::size_t nv, double radius,
                                                                      const double* bounds,
                                                                      const double* scale = nullptr);
// Stores result (as interpolate_at_vertices gives it, for out's vertices) as
// out.attributes, named and shaped as layout.
void store_mesh_attributes(const std::vector<io::Attribute>& layout, const double* result, nbmc_mesh& out);

// The mesh's attributes as the writers take them (doubles of the floats).
std::vector<io::Attribute> mesh_attributes_for_writer(const nbmc_mesh& mesh);

// Sets the thread-local message of nbmc_last_error() (capi_io.cpp).
void set_thread_error(const std::string& msg);

}  // namespace nbmc
