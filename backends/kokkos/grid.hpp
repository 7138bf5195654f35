// SPDX-License-Identifier: MIT
// The virtual marching-cubes grid and the neighbour grid. Neither is ever
// allocated densely: they only turn positions into integer coordinates.
#pragma once

#include "common.hpp"

#include <cmath>
#include <sstream>

namespace nbmc {
namespace Details {

struct Grid {
  double origin[3] = {0, 0, 0};  // position of vertex (0,0,0), absolute
  double cell = 0;               // marching-cubes cell size c
  std::int64_t dims[3] = {0, 0, 0};  // vertices per axis
  double nb_cell = 0;            // neighbour-grid cell size S (= R/2)
  std::int64_t nb_dims[3] = {0, 0, 0};
  std::uint64_t vertex_count() const { return std::uint64_t(dims[0]) * dims[1] * dims[2]; }
  std::int64_t block_dims(int a) const { return (dims[a] + 7) / 8; }
};

// Chooses a grid that contains [lo, hi] padded by `pad` on every side.
inline Grid make_grid(const double lo[3], const double hi[3], const Params& p) {
  Grid g;
  g.cell = p.cell_size;
  g.nb_cell = 0.5 * p.influence_radius;
  const double pad = std::max(p.band_width, p.iso_radius + p.cell_size) + 2 * p.cell_size;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = lo[a] - pad;
    const double extent = (hi[a] + pad) - g.origin[a];
    const double n = std::floor(extent / g.cell) + 2;
    const double nn = std::floor(extent / g.nb_cell) + 2;
    if (!(n < double(kMaxAxisCells)) || !(nn < double(kMaxAxisCells))) {
      std::ostringstream s;
      s << "the domain needs " << n << " grid vertices along axis " << "xyz"[a] << " (extent " << extent
        << ", cell size " << g.cell << "); at most " << kMaxAxisCells
        << " are supported: use a larger cell size, a bounding box, or remove far-away particles";
      throw Error(5 /*NBMC_ERROR_DOMAIN_TOO_LARGE*/, s.str());
    }
    g.dims[a] = std::int64_t(n);
    g.nb_dims[a] = std::int64_t(nn);
  }
  return g;
}

}  // namespace Details
}  // namespace nbmc
