// SPDX-License-Identifier: MIT
// The grid of a frame lives in src/core/grid.hpp (plain C++, shared with the
// subdomain runner and the MPI layer); the pipeline uses it from here.
#pragma once

#include "common.hpp"

namespace nbmc {
namespace Details {
using nbmc::Grid;
using nbmc::make_grid;
}  // namespace Details
}  // namespace nbmc
