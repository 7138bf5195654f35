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
// the host, and stores them in out.attributes; adds the time to
// st.stage[NBMC_STAGE_ATTRIBUTES]. Nothing when ctx has no attributes.
void interpolate_mesh_attributes(nbmc_context& ctx, const Params& p, nbmc_mesh& out, RunStats& st);

// The mesh's attributes as the writers take them (doubles of the floats).
std::vector<io::Attribute> mesh_attributes_for_writer(const nbmc_mesh& mesh);

// Sets the thread-local message of nbmc_last_error() (capi_io.cpp).
void set_thread_error(const std::string& msg);

}  // namespace nbmc
