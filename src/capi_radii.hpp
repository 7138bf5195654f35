// SPDX-License-Identifier: MIT
// Per-particle radii behind the C API (src/capi_radii.cpp).
#pragma once

#include "context.hpp"

namespace nbmc {

// The context's radii applied to the resolved parameters of a reconstruction
// (scale_for_radii, src/core/params.hpp); nothing without radii. Throws
// Error(NBMC_ERROR_INVALID_ARGUMENT) when the radii do not match the
// particles.
void apply_radii(const nbmc_context& ctx, Params& p);

}  // namespace nbmc
