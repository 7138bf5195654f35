// SPDX-License-Identifier: MIT
// The pass before the SPH density field (field_sph.hpp): every particle's
// D_j = sum_k W~(x_j - x_k) over the particles within R, and its weight
// 1 / D_j, in the sorted order of the neighbourhood. Each particle is
// evaluated like a band vertex (eval_vertex_direct: cells in z, y, x order,
// particles in sorted order, the same float operations), so the weights, and
// the field after them, are bit-identical on every backend. A particle's
// D_j needs the particles within R of it: a subdomain's ghost layer is 2R
// wide for this method (particle_reach in src/core/params.hpp). With
// per-particle radii, D_j sums each particle k's kernel of support R_k
// (field_sph.hpp); R_k <= R, so the ghost layer stays 2R.
#pragma once

#include "common.hpp"
#include "field_sph.hpp"
#include "neighbourhood.hpp"
#include "scalar_field.hpp"

namespace nbmc {
namespace Details {

template <bool Radii, class ExecSpace>
void compute_sph_weights(const ExecSpace& space, MemoryTracker& tracker,
                         Neighbourhood<typename ExecSpace::memory_space>& nbh, const Grid& g,
                         const FieldConstants& fc) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::scalar_field::sph_density");
  nbh.pdata = Buffer<float, MemSpace>(tracker, "scalar_field::sph_weights", nbh.n);
  const NeighbourView<MemSpace> nb = view_of(nbh, g);
  const auto w = nbh.pdata.view();
  const float S = float(g.nb_cell);
  const std::size_t n = nbh.n;
  Kokkos::parallel_for(
      "nbmc::scalar_field::sph_density", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t j) {
        const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
        std::uint64_t evals = 0;
        // >= 1: the particle's own W~(0) = 1 is in the sum
        const float d = eval_vertex_direct<SphDensityT<Radii>>(nb, x, S, fc, evals);
        w(j) = 1.f / d;
      });
  space.fence();
}

}  // namespace Details
}  // namespace nbmc
