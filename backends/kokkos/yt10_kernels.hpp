// SPDX-License-Identifier: MIT
// The pass before the YT10 field (field_yt10.hpp): a particle's
// anisotropic kernel (smoothed centre, G, det(h G) / D) from the moments of
// its neighbours within R, in the sorted order of the neighbourhood. Each
// particle's moments are summed like a band vertex's field
// (sum_vertex_direct: cells in z, y, x order, particles in sorted order, the
// same float operations), and the 3x3 decomposition is a fixed Jacobi
// iteration, so the kernels, and the field after them, are bit-identical on
// every backend. A particle's kernel needs the particles within R of it: a
// subdomain's ghost layer is 2R wide for this method (particle_reach in
// src/core/params.hpp).
#pragma once

#include "common.hpp"
#include "field_yt10.hpp"
#include "neighbourhood.hpp"
#include "particle_reach.hpp"
#include "scalar_field.hpp"

#include <algorithm>
#include <cstring>

namespace nbmc {
namespace Details {

inline Yt10Constants yt10_constants(const Params& p) {
  const double R = p.influence_radius;
  Yt10Constants k;
  k.h = float(0.5 * R);
  k.ks = float(p.aniso_ks * 20.0 / (3.0 * R * R));  // k_s / sigma_0, sigma_0 = 3 R^2 / 20
  k.kr_inv = float(1.0 / p.aniso_kr);
  k.kn = float(p.aniso_kn);
  k.max_axis = float(kYt10MaxAxis);
  k.lambda = float(p.aniso_lambda);
  k.max_shift = float(kYt10MaxShift * R);
  k.neighbours = std::uint32_t(p.aniso_neighbours);
  return k;
}

// The host's pass over the particles of one work item (ParticleRanges):
// groups of L particles as the lanes of eval_points_host_lanes (each
// particle's moments in the order of sum_vertex_direct, bit for bit), chunks
// of 64 particles sharing one cell span. Writes their kernels and returns
// the largest reach. The kernels themselves (the Jacobi decomposition: a
// third of the pass when computed one particle at a time) are computed
// eight particles at a time on 8-lane vectors where the host has them
// (yt10_kernel_t: every lane the float's bits).
template <int L, class MemSpace>
KOKKOS_INLINE_FUNCTION float yt10_cell_host_lanes(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                                  const Yt10Constants& k, const ParticleRanges& r, float* out) {
  float reach = 0;
#if defined(NBMC_HOST_SIMD8) && defined(__GNUC__) && !defined(__clang__) && !defined(__CUDA_ARCH__)
  if constexpr (L == 8 || L == 16) {
    using V = typename HostSimd<8>::F;
    using I = typename HostSimd<8>::I;
    float a8[Yt10Moments::N][8];
    std::int32_t crowd8[8];
    std::uint32_t j8[8];
    int m = 0;
    auto flush = [&] {
      for (int l = m; l < 8; ++l) {  // (unused lanes: a copy of lane 0, not written)
        for (int q = 0; q < Yt10Moments::N; ++q) a8[q][l] = a8[q][0];
        crowd8[l] = crowd8[0];
      }
      V a[Yt10Moments::N], o[kYt10Floats], rv;
      I crowd;
      for (int q = 0; q < Yt10Moments::N; ++q) std::memcpy(&a[q], a8[q], 32);
      std::memcpy(&crowd, crowd8, 32);
      rv = yt10_kernel_t<V>(a, crowd, k, o);
      float ov[kYt10Floats][8], rl[8];
      for (int q = 0; q < kYt10Floats; ++q) std::memcpy(ov[q], &o[q], 32);
      std::memcpy(rl, &rv, 32);
      for (int l = 0; l < m; ++l) {
        float* dst = out + std::size_t(kYt10Floats) * j8[l];
        for (int q = 0; q < kYt10Floats; ++q) dst[q] = ov[q][l];
        reach = rl[l] > reach ? rl[l] : reach;
      }
      m = 0;
    };
    sum_particles_host_lanes<Yt10Moments, L>(nb, S, fc, r, [&](std::uint32_t j, const float* a, std::uint32_t count) {
      for (int q = 0; q < Yt10Moments::N; ++q) a8[q][m] = a[q];
      crowd8[m] = count - 1 > k.neighbours ? -1 : 0;
      j8[m] = j;
      if (++m == 8) flush();
    });
    if (m > 0) flush();
    return reach;
  }
#endif
  sum_particles_host_lanes<Yt10Moments, L>(nb, S, fc, r, [&](std::uint32_t j, const float* a, std::uint32_t count) {
    const float r = yt10_kernel(a, count, k, out + std::size_t(kYt10Floats) * j);
    reach = r > reach ? r : reach;
  });
  return reach;
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 32- and 64-byte vectors never cross a call that is not inlined
#endif
// The pass over one work item with `lanes` lanes (host_simd_lanes).
template <class MemSpace>
KOKKOS_INLINE_FUNCTION float yt10_cell_host(const NeighbourView<MemSpace>& nb, float S, const FieldConstants& fc,
                                             const Yt10Constants& k, const ParticleRanges& r, float* out, int lanes) {
  return with_host_lanes(lanes, [&nb, S, &fc, &k, &r, out](auto L) { return yt10_cell_host_lanes<decltype(L)::value>(nb, S, fc, k, r, out); });
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// The kernels of the particles the band's field can reach (ParticleReach,
// particle_reach.hpp), into nbh.pdata: computed when the band first reaches
// them, before the gather and after each round of band growth; the others
// stay 0 (never read). Each kernel is computed once, by the same code: the
// same bits on every backend, whichever pass computes it. update() returns
// the field's constants: fc with the visited radius narrowed to R_f = 1.02
// times the largest reach of a kernel computed so far (at most R;
// field_yt10.hpp says why that changes no value: a particle reached later
// lies farther than R from every vertex evaluated before).
template <class MemSpace>
struct Yt10Kernels {
  ParticleReach<MemSpace> reach;
  float largest = 0;  // the largest reach of a kernel computed so far

  void start(MemoryTracker& tracker, Neighbourhood<MemSpace>& nbh, const Grid& g, bool whole_grid) {
    nbh.pdata = Buffer<float, MemSpace>(tracker, "scalar_field::yt10_kernels", std::size_t(kYt10Floats) * nbh.n, true);
    reach.start(tracker, nbh.n_cells, g, whole_grid);
  }
  template <class ExecSpace>
  void add_words(const ExecSpace& space, const BandView<MemSpace>& band, std::size_t n_list,
                 const Kokkos::View<const std::uint64_t*, MemSpace>& listed) {
    reach.add_words(space, band, n_list, listed);
  }

  // Computes the kernels of the cells reached since the last update (fc:
  // the constants of influence radius R).
  template <class ExecSpace>
  FieldConstants update(const ExecSpace& space, Neighbourhood<MemSpace>& nbh, const Grid& g, const Params& p,
                        const FieldConstants& fc) {
    if (!reach.pending()) return constants(p, fc);
    ScopedRegion region("nbmc::scalar_field::yt10_kernels");
    reach.select(space, nbh, g, p.influence_radius);
    const NeighbourView<MemSpace> nb = view_of(nbh, g);
    const auto st = reach.state.view();
    const bool every = reach.all;
    const auto out = nbh.pdata.view();
    const auto starts = nbh.cell_start.view();
    const Yt10Constants k = yt10_constants(p);
    const float S = float(g.nb_cell);
    const std::size_t n = nbh.n;
    float r_new = 0;
    if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
      // The particles of a run of cells per work item (host_ranges), as SIMD lanes.
      const int lanes = host_simd_lanes();
      const Kokkos::View<const std::uint64_t*, MemSpace> keys = nbh.cell_keys.view();
      const std::uint64_t row = std::uint64_t(g.nb_dims[0]);
      float* const o = out.data();
      Kokkos::parallel_reduce(
          "nbmc::scalar_field::yt10_kernels",
          Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, nbh.n_cells),
          KOKKOS_LAMBDA(const std::size_t c, float& r) {
            ParticleRanges rs;
            ParticleReach<MemSpace>::host_ranges(st, every, keys, starts, row, c, rs);
            if (rs.n == 0) return;
            const float rc = yt10_cell_host(nb, S, fc, k, rs, o, lanes);
            if (rc > r) r = rc;
          },
          Kokkos::Max<float>(r_new));
    } else {
      // One thread per particle, every particle (ParticleReach: all).
      Kokkos::parallel_reduce(
          "nbmc::scalar_field::yt10_kernels", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t j, float& r) {
            const float x[3] = {nb.pos(j), nb.pos(n + j), nb.pos(2 * n + j)};
            float a[Yt10Moments::N];
            const std::uint32_t count = sum_vertex_direct<Yt10Moments>(nb, x, S, fc, a);
            float kern[kYt10Floats];
            const float rj = yt10_kernel(a, count, k, kern);
            for (int q = 0; q < kYt10Floats; ++q) out(std::size_t(kYt10Floats) * j + q) = kern[q];
            if (rj > r) r = rj;
          },
          Kokkos::Max<float>(r_new));
    }
    const std::uint64_t computed = host_trace_on() ? reach.count_now(space, nbh) : 0;
    reach.finish(space);
    space.fence();
    trace("yt10 kernels", computed);
    largest = r_new > largest ? r_new : largest;
    const FieldConstants f = constants(p, fc);
    trace("yt10 R_f / R (per mille)", std::uint64_t(1000.0 * double(f.R) / p.influence_radius + 0.5));
    return f;
  }
  // fc with R_f from the kernels computed so far.
  FieldConstants constants(const Params& p, const FieldConstants& fc) const {
    FieldConstants f = fc;
    const double Rf = largest > 0 ? std::min(p.influence_radius, 1.02 * double(largest)) : p.influence_radius;
    f.R = float(Rf);
    f.inv_R2 = float(1.0 / (Rf * Rf));
    return f;
  }
};

// Every particle's kernel at once (tests; the pipeline runs Yt10Kernels, which
// does the same without a narrow band); returns
// the field's constants as Yt10Kernels::update.
template <class ExecSpace>
FieldConstants compute_yt10_kernels(const ExecSpace& space, MemoryTracker& tracker,
                                    Neighbourhood<typename ExecSpace::memory_space>& nbh, const Grid& g,
                                    const Params& p, const FieldConstants& fc) {
  Yt10Kernels<typename ExecSpace::memory_space> kernels;
  kernels.start(tracker, nbh, g, true);
  return kernels.update(space, nbh, g, p, fc);
}

}  // namespace Details
}  // namespace nbmc
