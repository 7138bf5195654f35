// SPDX-License-Identifier: MIT
// The virtual marching-cubes grid and the neighbour grid of a frame. Neither
// is ever allocated densely: they only turn positions into integer
// coordinates. Plain C++; the functions marked NBMC_HD also run on GPUs.
//
// A frame has exactly one grid (origin, cell size, dimensions), chosen from
// the bounds of all its particles (or the clipping box). Subdomains and MPI
// ranks use that same grid, so every one of them computes the same relative
// float coordinates and the same neighbour cells for a particle: this is
// what makes a split reconstruction bit-identical to the whole one.
#pragma once

#include "hd.hpp"
#include "params.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>

namespace nbmc {

constexpr std::uint32_t kMaxAxisCells = (1u << 21) - 2;  // Morton limit per axis

struct Grid {
  double origin[3] = {0, 0, 0};  // position of vertex (0,0,0), absolute
  double cell = 0;               // marching-cubes cell size c
  std::int64_t dims[3] = {0, 0, 0};  // vertices per axis
  double nb_cell = 0;            // neighbour-grid cell size S = max(R/2, surface radius)
  std::int64_t nb_dims[3] = {0, 0, 0};
  std::uint64_t vertex_count() const { return std::uint64_t(dims[0]) * dims[1] * dims[2]; }
  std::int64_t block_dims(int a) const { return (dims[a] + 7) / 8; }
};

// The neighbour-grid cell size S: R/2 (a vertex's particles lie in the 5^3
// cells around its own), but never below the surface radius h. The surface
// test (backends/kokkos/surface_particles.hpp) sums over the 27 cells around
// a particle's own and judges emptiness on these cells, so with S = h for
// every R <= 2h the surface particles are the same for all such R (the grid's
// origin does not depend on R either); with S = R/2 < h, cells of one
// particle would make the surface test slow and its empty-cell rule wrong.
inline double neighbour_cell_size(const Params& p) {
  return std::max(0.5 * p.influence_radius, p.surface_radius);
}

// Chooses a grid that contains [lo, hi] padded on every side by what the band
// and the field reach beyond the particles.
inline Grid make_grid(const double lo[3], const double hi[3], const Params& p) {
  Grid g;
  g.cell = p.cell_size;
  g.nb_cell = neighbour_cell_size(p);
  const double pad = std::max(p.band_width, surface_reach(p) + p.cell_size) + 2 * p.cell_size;
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
      throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, s.str());
    }
    g.dims[a] = std::int64_t(n);
    g.nb_dims[a] = std::int64_t(nn);
  }
  return g;
}

// Neighbour-grid cell of a coordinate relative to the origin, clamped to the
// grid (particles outside a clipping box land in its boundary cells).
NBMC_HD std::uint32_t neighbour_cell(double x, double inv, std::int64_t dim) {
  const double c = x * inv;
  return std::uint32_t(c <= 0 ? 0.0 : (c >= double(dim - 1) ? double(dim - 1) : c));
}

// Morton (Z-order) keys of 21-bit coordinates.
NBMC_HD std::uint64_t spread3(std::uint32_t v) {
  std::uint64_t x = v & 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}
NBMC_HD std::uint32_t compact3(std::uint64_t x) {
  x &= 0x1249249249249249ULL;
  x = (x ^ (x >> 2)) & 0x10c30c30c30c30c3ULL;
  x = (x ^ (x >> 4)) & 0x100f00f00f00f00fULL;
  x = (x ^ (x >> 8)) & 0x1f0000ff0000ffULL;
  x = (x ^ (x >> 16)) & 0x1f00000000ffffULL;
  x = (x ^ (x >> 32)) & 0x1fffffULL;
  return std::uint32_t(x);
}
NBMC_HD std::uint64_t morton3(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return spread3(x) | (spread3(y) << 1) | (spread3(z) << 2);
}

// The position of grid vertex (i, j, k) in the band order of the pipeline
// (block Morton key, then the 4x4x4 word in the block, then the bit in the
// word): band vertices, mesh vertices and triangles are numbered in this
// order, in a whole frame as in any subdomain. 63 bits at most.
NBMC_HD std::uint64_t band_order_key(std::int64_t i, std::int64_t j, std::int64_t k) {
  const std::uint64_t block = morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3));
  const std::uint64_t word = std::uint64_t(((i & 7) >> 2) | (((j & 7) >> 2) << 1) | (((k & 7) >> 2) << 2));
  const std::uint64_t bit = std::uint64_t((i & 3) | ((j & 3) << 2) | ((k & 3) << 4));
  return (block << 9) | (word << 6) | bit;
}

}  // namespace nbmc
