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
#include "scalar_field.hpp"

namespace nbmc {
namespace Details {

// The host's pass over the particles of one neighbour cell, [b, e): L
// particles at a time as SIMD lanes (sum_cell_particles_host_lanes; each
// D_j bit for bit a device thread's), their weights 1 / D_j into w.
template <bool Radii, int L, class MemSpace>
KOKKOS_INLINE_FUNCTION void sph_cell_host_lanes(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                                std::uint32_t b, std::uint32_t e, float* w) {
  sum_cell_particles_host_lanes<SphDensityT<Radii>, L>(
      nb, S, fc, b, e, [&](std::uint32_t j, const float* a, std::uint32_t) { w[j] = 1.f / SphDensityT<Radii>::value(a, fc); });
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
                                                                  const FieldConstants& fc, std::uint32_t b,
                                                                  std::uint32_t e, float* w) {
  sph_cell_host_lanes<Radii, 8>(nb, S, fc, b, e, w);
}
#endif
#if defined(NBMC_HOST_AVX512)
template <bool Radii, class MemSpace>
__attribute__((target("avx512f"), flatten)) void sph_cell_host_avx512(const NeighbourView<MemSpace>& nb, float S,
                                                                    const FieldConstants& fc, std::uint32_t b,
                                                                    std::uint32_t e, float* w) {
  sph_cell_host_lanes<Radii, 16>(nb, S, fc, b, e, w);
}
#endif
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// The pass over one neighbour cell with `lanes` lanes (host_simd_lanes).
template <bool Radii, class MemSpace>
KOKKOS_INLINE_FUNCTION void sph_cell_host(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                          std::uint32_t b, std::uint32_t e, float* w, int lanes) {
#if defined(NBMC_HOST_AVX512)
  if (lanes == 16) return sph_cell_host_avx512<Radii>(nb, S, fc, b, e, w);
#endif
#if defined(NBMC_HOST_AVX2)
  if (lanes == 8) return sph_cell_host_avx2<Radii>(nb, S, fc, b, e, w);
#endif
  (void)lanes;
  sph_cell_host_lanes<Radii, 4>(nb, S, fc, b, e, w);
}

// The weights of the particles the band's field can reach, computed when
// the band first reaches them: before the gather, and after each round of
// band growth for the words it added. A particle's weight is read only by
// band vertices within R of it (the field sums nothing from farther ones:
// k = 0 there, and 0 * 0 adds an exact 0); on the 1.65 M frame at r/2 with
// R = 4r, 59 % of the particles have a band vertex within R.
// Reach is decided per occupied neighbour cell, conservatively: a cell is
// reached when a band tile (4x4x4 vertices, a band word) with band vertices
// meets the grid vertices within R of the cell's box (one vertex of margin,
// and unbounded on the sides of the grid's edge cells, into which particles
// outside it are clamped); on that frame 78 % of the particles are in
// reached cells. The weights of unreached particles stay 0. Each weight is
// computed once, by the same code as before: the same bits on every
// backend, whichever pass computes it. The tiles are held as a bitmap over
// the grid; where it would pass kMaxBits (very large sparse domains), every
// particle's weight is computed at once.
template <class MemSpace>
struct SphWeights {
  static constexpr std::uint64_t kMaxBits = std::uint64_t(1) << 27;  // 16 MiB
  Buffer<std::uint32_t, MemSpace> tiles;  // the band's tiles, a bit per 4x4x4 tile of the grid
  Buffer<std::uint8_t, MemSpace> state;    // per occupied neighbour cell: 0 unreached, 1 to compute, 2 done
  std::int64_t tdims[3] = {0, 0, 0};
  bool all = false;  // every particle (no bitmap)

  template <class ExecSpace>
  void start(const ExecSpace& space, MemoryTracker& tracker, Neighbourhood<MemSpace>& nbh, const Grid& g,
             bool whole_grid) {
    nbh.pdata = Buffer<float, MemSpace>(tracker, "scalar_field::sph_weights", nbh.n, true);
    for (int a = 0; a < 3; ++a) tdims[a] = 2 * g.block_dims(a);
    const std::uint64_t bits = std::uint64_t(tdims[0]) * std::uint64_t(tdims[1]) * std::uint64_t(tdims[2]);
    all = whole_grid || bits > kMaxBits;
    state = Buffer<std::uint8_t, MemSpace>(tracker, "scalar_field::sph_cells", nbh.n_cells, true);
    if (!all) tiles = Buffer<std::uint32_t, MemSpace>(tracker, "scalar_field::sph_tiles", (bits + 31) / 32, true);
    (void)space;
  }

  // Adds the band's words list(0..n_list) (a word index each; without a
  // list, words 0..n_list of the band that have vertices).
  template <class ExecSpace>
  void add_words(const ExecSpace& space, const BandView<MemSpace>& band, std::size_t n_list,
                 const Kokkos::View<const std::uint64_t*, MemSpace>& listed) {
    if (all) return;
    const auto bits = tiles.view();
    const auto keys = band.block_keys, words = band.words;
    const std::int64_t d0 = tdims[0], d1 = tdims[1];
    const bool by_list = listed.extent(0) != 0;
    Kokkos::parallel_for(
        "nbmc::scalar_field::sph_tiles", Kokkos::RangePolicy<ExecSpace>(space, 0, n_list),
        KOKKOS_LAMBDA(const std::size_t q) {
          const std::size_t w = by_list ? std::size_t(listed(q)) : q;
          if (!by_list && words(w) == 0) return;
          const std::uint64_t key = keys(w >> 3);
          const int sub = int(w & 7);
          const std::uint64_t t = std::uint64_t(2 * compact3(key) + (sub & 1)) +
                                  std::uint64_t(d0) * (std::uint64_t(2 * compact3(key >> 1) + ((sub >> 1) & 1)) +
                                                       std::uint64_t(d1) * std::uint64_t(2 * compact3(key >> 2) + (sub >> 2)));
          Kokkos::atomic_fetch_or(&bits(t >> 5), std::uint32_t(1) << (t & 31));
        });
  }

  // Computes the weights of the particles in the cells the blocks now reach
  // and no pass has computed yet.
  template <bool Radii, class ExecSpace>
  void update(const ExecSpace& space, Neighbourhood<MemSpace>& nbh, const Grid& g, const FieldConstants& fc) {
    ScopedRegion region("nbmc::scalar_field::sph_density");
    const NeighbourView<MemSpace> nb = view_of(nbh, g);
    const auto st = state.view();
    const auto keys = nbh.cell_keys.view();
    const auto bits = tiles.view();
    const bool every = all;
    const double S = g.nb_cell, c = g.cell, R = double(fc.R);
    const std::int64_t nd[3] = {g.nb_dims[0], g.nb_dims[1], g.nb_dims[2]};
    const std::int64_t vd[3] = {g.dims[0], g.dims[1], g.dims[2]};
    const std::int64_t td[3] = {tdims[0], tdims[1], tdims[2]};
    Kokkos::parallel_for(
        "nbmc::scalar_field::sph_reach", Kokkos::RangePolicy<ExecSpace>(space, 0, nbh.n_cells),
        KOKKOS_LAMBDA(const std::size_t q) {
          if (st(q) != 0) return;
          bool reached = every;
          if (!reached) {
            std::int64_t x[3], lo[3], hi[3];
            neighbour_cell_of_key(keys(q), nd, x[0], x[1], x[2]);
            for (int a = 0; a < 3; ++a) {
              lo[a] = x[a] == 0 ? 0 : std::int64_t(Kokkos::Experimental::floor((double(x[a]) * S - R) / c)) - 1;
              hi[a] = x[a] == nd[a] - 1 ? vd[a] - 1
                                        : std::int64_t(Kokkos::Experimental::ceil((double(x[a] + 1) * S + R) / c)) + 1;
              lo[a] = lo[a] < 0 ? 0 : lo[a];
              hi[a] = hi[a] > vd[a] - 1 ? vd[a] - 1 : hi[a];
              lo[a] >>= 2;
              hi[a] >>= 2;
            }
            for (std::int64_t k = lo[2]; k <= hi[2] && !reached; ++k)
              for (std::int64_t j = lo[1]; j <= hi[1] && !reached; ++j)
                for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
                  const std::uint64_t b =
                      std::uint64_t(i) + std::uint64_t(td[0]) * (std::uint64_t(j) + std::uint64_t(td[1]) * std::uint64_t(k));
                  if ((bits(b >> 5) >> (b & 31)) & 1u) {
                    reached = true;
                    break;
                  }
                }
          }
          if (reached) st(q) = 1;
        });
    const auto w = nbh.pdata.view();
    const auto starts = nbh.cell_start.view();
    const float Sf = float(g.nb_cell);
    // (D_j >= 1: the particle's own W~(0) = 1 is in the sum.)
    if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
      // One work item per cell, its particles as SIMD lanes (one particle at
      // a time, this pass took longer than the field itself).
      const int lanes = host_simd_lanes();
      float* const o = w.data();
      Kokkos::parallel_for(
          "nbmc::scalar_field::sph_density",
          Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, nbh.n_cells),
          KOKKOS_LAMBDA(const std::size_t q) {
            if (st(q) != 1) return;
            sph_cell_host<Radii>(nb, Sf, fc, starts(q), starts(q + 1), o, lanes);
            st(q) = 2;
          });
    } else {
      // One thread per particle of a cell to compute (its cell by bisection
      // of the cell starts), then the cells marked done.
      const std::size_t n = nbh.n, n_cells = nbh.n_cells;
      Kokkos::parallel_for(
          "nbmc::scalar_field::sph_density", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t j) {
            std::size_t a = 0, b = n_cells;  // the cell q with starts(q) <= j < starts(q + 1)
            while (b - a > 1) {
              const std::size_t m = (a + b) / 2;
              if (starts(m) <= j) a = m;
              else b = m;
            }
            if (st(a) != 1) return;
            const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
            std::uint64_t evals = 0;
            w(j) = 1.f / eval_vertex_direct<SphDensityT<Radii>>(nb, x, Sf, fc, evals);
          });
      Kokkos::parallel_for(
          "nbmc::scalar_field::sph_done", Kokkos::RangePolicy<ExecSpace>(space, 0, n_cells),
          KOKKOS_LAMBDA(const std::size_t q) {
            if (st(q) == 1) st(q) = 2;
          });
    }
    space.fence();
  }
};

// Every particle's weight (the dense and scatter fields, and tests).
template <bool Radii, class ExecSpace>
void compute_sph_weights(const ExecSpace& space, MemoryTracker& tracker,
                         Neighbourhood<typename ExecSpace::memory_space>& nbh, const Grid& g,
                         const FieldConstants& fc) {
  SphWeights<typename ExecSpace::memory_space> w;
  w.start(space, tracker, nbh, g, true);
  w.template update<Radii>(space, nbh, g, fc);
}

}  // namespace Details
}  // namespace nbmc
