// SPDX-License-Identifier: MIT
// Surface particles (paper Sec. 4): the smoothed colour field of [MCG03]
// c(x) = sum_j V_j W(x - x_j, h) with V_j = r^3 and the poly6 kernel of support
// h = surface_radius; a particle is on the surface when |grad c| * h exceeds
// color_threshold, or when it has fewer than neighbour_threshold neighbours
// within h (this catches splashes, which the colour field misses).
#pragma once

#include "common.hpp"
#include "grid.hpp"
#include "neighbourhood.hpp"

#include <cmath>

namespace nbmc {
namespace Details {

// Dimensionless colour-field gradient |grad c| * h of one particle and its
// neighbour count within h. Device function so tests and kernels share it.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION void colour_field(const NeighbourView<MemSpace>& nb, std::size_t i, float h, float volume,
                                         int range, float& grad_h, int& neighbours) {
  const float xi = nb.pos(4 * i), yi = nb.pos(4 * i + 1), zi = nb.pos(4 * i + 2);
  const std::int64_t cx = std::int64_t(xi * nb.inv_nb_cell), cy = std::int64_t(yi * nb.inv_nb_cell),
                     cz = std::int64_t(zi * nb.inv_nb_cell);
  const float h2 = h * h;
  float gx = 0, gy = 0, gz = 0;
  int count = 0;
  for (std::int64_t z = cz - range; z <= cz + range; ++z) {
    if (z < 0 || z >= nb.nb_dims[2]) continue;
    for (std::int64_t y = cy - range; y <= cy + range; ++y) {
      if (y < 0 || y >= nb.nb_dims[1]) continue;
      for (std::int64_t x = cx - range; x <= cx + range; ++x) {
        if (x < 0 || x >= nb.nb_dims[0]) continue;
        std::uint32_t b, e;
        if (!nb.cell_range(x, y, z, b, e)) continue;
        for (std::uint32_t j = b; j < e; ++j) {
          if (j == i) continue;
          const float dx = xi - nb.pos(4 * j), dy = yi - nb.pos(4 * j + 1), dz = zi - nb.pos(4 * j + 2);
          const float d2 = dx * dx + dy * dy + dz * dz;
          if (d2 >= h2) continue;
          ++count;
          const float q = h2 - d2;
          const float w = q * q;  // grad W = -945/(32 pi h^9) (h^2-d^2)^2 (x_i - x_j)
          gx += w * dx;
          gy += w * dy;
          gz += w * dz;
        }
      }
    }
  }
  const float h4 = h2 * h2, h9 = h4 * h4 * h;
  const float scale = volume * 945.f / (32.f * 3.14159265358979f * h9);
  grad_h = std::sqrt(gx * gx + gy * gy + gz * gz) * scale * h;
  neighbours = count;
}

// flags(i) = 1 for surface particles (sorted order); returns their count.
template <class ExecSpace>
std::size_t mark_surface_particles(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                   std::size_t n, const Params& p, const Grid& g,
                                   const Kokkos::View<std::uint8_t*, typename ExecSpace::memory_space>& flags) {
  ScopedRegion region("nbmc::surface_particles");
  const float h = float(p.surface_radius);
  const float volume = float(p.spacing * p.spacing * p.spacing);
  const int range = int(std::ceil(p.surface_radius / g.nb_cell));
  const float threshold = float(p.color_threshold);
  const int min_neighbours = p.neighbour_threshold;
  std::size_t count = 0;
  Kokkos::parallel_reduce(
      "nbmc::surface_particles", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t i, std::size_t& acc) {
        float grad_h;
        int neighbours;
        colour_field(nb, i, h, volume, range, grad_h, neighbours);
        const bool surface = neighbours < min_neighbours || grad_h > threshold;
        flags(i) = surface ? 1 : 0;
        acc += surface ? 1 : 0;
      },
      count);
  space.fence();
  return count;
}

}  // namespace Details
}  // namespace nbmc
