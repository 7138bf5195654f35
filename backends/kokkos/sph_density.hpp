// SPDX-License-Identifier: MIT
// The pass before the SPH density field (field_sph.hpp): a particle's
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
#include "particle_reach.hpp"
#include "scalar_field.hpp"

namespace nbmc {
namespace Details {

// The host's pass over the particles of one work item (ParticleRanges): L
// particles at a time as SIMD lanes (sum_particles_host_lanes; each D_j bit
// for bit a device thread's), their weights 1 / D_j into w.
template <bool Radii, int L, class MemSpace>
KOKKOS_INLINE_FUNCTION void sph_cell_host_lanes(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                                const ParticleRanges& r, float* w) {
  sum_particles_host_lanes<SphDensityT<Radii>, L>(
      nb, S, fc, r, [&](std::uint32_t j, const float* a, std::uint32_t) { w[j] = 1.f / SphDensityT<Radii>::value(a, fc); });
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 32- and 64-byte vectors never cross a call that is not inlined
#endif
// 8 lanes where the CPU has AVX2, 16 where it has AVX-512F
// (host_simd_lanes), as for the band tiles. Their own wrappers rather than
// with_host_lanes (scalar_field.hpp): through it this pass took 2 % longer
// (SPH field t4 on the 1.65 M frame at r/2, dev VM, 1.396-1.404 against
// 1.438-1.449 s, alternated), with or without the closure's captures by value.
#if defined(NBMC_HOST_AVX2)
template <bool Radii, class MemSpace>
__attribute__((target("avx2,fma"), flatten)) void sph_cell_host_avx2(const NeighbourView<MemSpace>& nb, float S,
                                                                  const FieldConstants& fc, const ParticleRanges& r,
                                                                  float* w) {
  sph_cell_host_lanes<Radii, 8>(nb, S, fc, r, w);
}
#endif
#if defined(NBMC_HOST_AVX512)
template <bool Radii, class MemSpace>
__attribute__((target("avx512f"), flatten)) void sph_cell_host_avx512(const NeighbourView<MemSpace>& nb, float S,
                                                                    const FieldConstants& fc, const ParticleRanges& r,
                                                                    float* w) {
  sph_cell_host_lanes<Radii, 16>(nb, S, fc, r, w);
}
#endif
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// The pass over one work item with `lanes` lanes (host_simd_lanes).
template <bool Radii, class MemSpace>
KOKKOS_INLINE_FUNCTION void sph_cell_host(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                          const ParticleRanges& r, float* w, int lanes) {
#if defined(NBMC_HOST_AVX512)
  if (lanes == 16) return sph_cell_host_avx512<Radii>(nb, S, fc, r, w);
#endif
#if defined(NBMC_HOST_AVX2)
  if (lanes == 8) return sph_cell_host_avx2<Radii>(nb, S, fc, r, w);
#endif
  (void)lanes;
  sph_cell_host_lanes<Radii, 4>(nb, S, fc, r, w);
}

// The weights of the particles the band's field can reach (ParticleReach,
// particle_reach.hpp): computed when the band first reaches them, before the
// gather and after each round of band growth; the others stay 0 (never
// read). Each weight is computed once, by the same code: the same bits on
// every backend, whichever pass computes it.
template <class MemSpace>
struct SphWeights {
  ParticleReach<MemSpace> reach;

  void start(MemoryTracker& tracker, Neighbourhood<MemSpace>& nbh, const Grid& g, bool whole_grid) {
    nbh.pdata = Buffer<float, MemSpace>(tracker, "scalar_field::sph_weights", nbh.n, true);
    reach.start(tracker, nbh.n_cells, g, whole_grid);
  }
  template <class ExecSpace>
  void add_words(const ExecSpace& space, const BandView<MemSpace>& band, std::size_t n_list,
                 const Kokkos::View<const std::uint64_t*, MemSpace>& listed) {
    reach.add_words(space, band, n_list, listed);
  }

  // Computes the weights of the cells reached since the last update.
  template <bool Radii, class ExecSpace>
  void update(const ExecSpace& space, Neighbourhood<MemSpace>& nbh, const Grid& g, const FieldConstants& fc) {
    if (!reach.pending()) return;
    ScopedRegion region("nbmc::scalar_field::sph_density");
    reach.select(space, nbh, g, double(fc.R));
    const NeighbourView<MemSpace> nb = view_of(nbh, g);
    const auto st = reach.state.view();
    const bool every = reach.all;
    const auto w = nbh.pdata.view();
    const auto starts = nbh.cell_start.view();
    const float S = float(g.nb_cell);
    // (D_j >= 1: the particle's own W~(0) = 1 is in the sum.)
    if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
      // The particles of a run of cells per work item (host_ranges), as SIMD
      // lanes (one particle at a time, this pass took longer than the field
      // itself).
      const int lanes = host_simd_lanes();
      const Kokkos::View<const std::uint64_t*, MemSpace> keys = nbh.cell_keys.view();
      const std::uint64_t row = std::uint64_t(g.nb_dims[0]);
      float* const o = w.data();
      Kokkos::parallel_for(
          "nbmc::scalar_field::sph_density",
          Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, nbh.n_cells),
          KOKKOS_LAMBDA(const std::size_t q) {
            ParticleRanges r;
            ParticleReach<MemSpace>::host_ranges(st, every, keys, starts, row, q, r);
            if (r.n > 0) sph_cell_host<Radii>(nb, S, fc, r, o, lanes);
          });
    } else {
      // One thread per particle, every particle (ParticleReach: all).
      const std::size_t n = nbh.n;
      Kokkos::parallel_for(
          "nbmc::scalar_field::sph_density", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t j) {
            const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
            std::uint64_t evals = 0;
            w(j) = 1.f / eval_vertex_direct<SphDensityT<Radii>>(nb, x, S, fc, evals);
          });
    }
    const std::uint64_t computed = host_trace_on() ? reach.count_now(space, nbh) : 0;
    reach.finish(space);
    space.fence();
    trace("sph weights", computed);
  }
};

// Every particle's weight at once (tests; the pipeline runs SphWeights, which
// does the same without a narrow band).
template <bool Radii, class ExecSpace>
void compute_sph_weights(const ExecSpace& space, MemoryTracker& tracker,
                         Neighbourhood<typename ExecSpace::memory_space>& nbh, const Grid& g,
                         const FieldConstants& fc) {
  SphWeights<typename ExecSpace::memory_space> w;
  w.start(tracker, nbh, g, true);
  w.template update<Radii>(space, nbh, g, fc);
}

}  // namespace Details
}  // namespace nbmc
