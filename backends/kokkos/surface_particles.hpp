// SPDX-License-Identifier: MIT
// Surface particles (paper Sec. 4): the smoothed colour field of [MCG03]
// c(x) = sum_j V_j W(x - x_j, h) with V_j = r^3 and the poly6 kernel of support
// h = surface_radius; a particle is on the surface when |grad c| * h exceeds
// color_threshold, or when it has fewer than neighbour_threshold neighbours
// within h (this catches splashes, which the colour field misses). A third,
// nbmc's own: every particle of a neighbour cell that borders an empty cell
// but holds no surface particle (see surface_particles_of_cell).
//
// The neighbour cells are never smaller than h (src/core/grid.hpp,
// neighbour_cell_size: S = max(R/2, h)), so the test reads exactly the 27
// cells around a particle's own. For every R <= 2h the cells are h wide and
// lie on the same grid whatever R is: the sums, their order and the
// empty-cell rule, hence the surface particles, do not depend on R. (Cells of
// R/2 < h, as nbmc had before, were one particle wide at R = 2r: the
// empty-cell rule then marked most of the fluid as surface.)
//
// With per-particle radii (radii.hpp) particle i uses its own h_i = h t_i
// (h the largest particle's, so the 27 cells still cover it) and every
// neighbour its own volume V_j = r_j^3:
//   |grad c(x_i)| h_i = 945 / (32 pi) * |sum_j (r_j / h_i)^3 q_j^2 e_j|,
//   e_j = (x_i - x_j) / h_i, q_j = 1 - |e_j|^2 (> 0),
// which for equal radii is the test above; the neighbours counted are those
// within h_i. One scalar loop on every backend.
#pragma once

#include "common.hpp"
#include "field_common.hpp"
#include "grid.hpp"
#include "neighbourhood.hpp"
#include "scalar_field.hpp"  // host_simd_lanes, NBMC_HOST_AVX2 / NBMC_HOST_AVX512

#include <cmath>
#include <cstdlib>

namespace nbmc {
namespace Details {

// Particles in one neighbour cell (edge 2r by default) beyond which it is
// "crowded": the rest density puts about 8 there.
constexpr std::uint32_t kCrowdedCell = 2048;

#if !defined(__CUDA_ARCH__)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"  // 32- and 64-byte vectors never cross a call that is not inlined
#endif
// The colour-gradient sums of particles i0, i0 + 1, ... (L of them, one per
// lane; lanes past last - 1 repeat it and are not used) over the n_cells
// ranges [begin, end), in the order of the scalar loop in
// surface_particles_of_cell: each lane does the scalar operations, so the
// sums are the same bit for bit for any L. Results in gx..count[0, L).
template <int L>
inline void surface_sums_lanes(const float* X, const float* Y, const float* Z, const std::uint32_t* begin,
                               const std::uint32_t* end, int n_cells, std::uint32_t i0, std::uint32_t last, float h2,
                               float* gx_out, float* gy_out, float* gz_out, int* count_out) {
  using F = typename HostSimd<L>::F;
  using I = typename HostSimd<L>::I;
  const F vh2 = lanes_of<F>(h2), zero = lanes_of<F>(0.f);
  F xi, yi, zi;
  for (int l = 0; l < L; ++l) {
    const std::uint32_t i = i0 + std::uint32_t(l) < last ? i0 + std::uint32_t(l) : last - 1;
    xi[l] = X[i];
    yi[l] = Y[i];
    zi[l] = Z[i];
  }
  F gx = zero, gy = zero, gz = zero;
  I count = I{};
  for (int c = 0; c < n_cells; ++c)
    for (std::uint32_t j = begin[c]; j < end[c]; ++j) {
      const F dx = xi - lanes_of<F>(X[j]), dy = yi - lanes_of<F>(Y[j]), dz = zi - lanes_of<F>(Z[j]);
      const F d2 = dx * dx + dy * dy + dz * dz;
      const I in = d2 < vh2;
      const F q = (F)((I)(vh2 - d2) & in);
      const F w = q * q;
      gx += w * dx;
      gy += w * dy;
      gz += w * dz;
      count -= in;
    }
  for (int l = 0; l < L; ++l) {
    gx_out[l] = gx[l];
    gy_out[l] = gy[l];
    gz_out[l] = gz[l];
    count_out[l] = count[l];
  }
}
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

// The sums of the next group of particles from i0 on: as few lanes of 4, 8
// or 16 as cover the particles left (a cell holds about 8 at rest density,
// so 16 lanes would mostly idle), at most `lanes` (host_simd_lanes).
// Returns the group's lane count.
inline int surface_sums_host(const float* X, const float* Y, const float* Z, const std::uint32_t* begin,
                             const std::uint32_t* end, int n_cells, std::uint32_t i0, std::uint32_t last, float h2,
                             int lanes, float* gx, float* gy, float* gz, int* count) {
  const std::uint32_t left = last - i0;
  const int L = lanes >= 16 && left > 8 ? 16 : lanes >= 8 && left > 4 ? 8 : 4;
  return with_host_lanes(L, [=](auto W) {
    surface_sums_lanes<decltype(W)::value>(X, Y, Z, begin, end, n_cells, i0, last, h2, gx, gy, gz, count);
    return int(decltype(W)::value);
  });
}
#endif

// Adds the colour-gradient terms of particles [b, e) at particle i (xi, yi,
// zi) to gx, gy, gz and counts those within h (h2 = h^2), one after the
// other: the GPU's order (the host's lanes use the same operations).
KOKKOS_INLINE_FUNCTION void add_surface_pairs(const float* X, const float* Y, const float* Z, std::uint32_t b,
                                              std::uint32_t e, float xi, float yi, float zi, float h2, float& gx,
                                              float& gy, float& gz, int& count) {
  for (std::uint32_t j = b; j < e; ++j) {
    const float dx = xi - X[j], dy = yi - Y[j], dz = zi - Z[j];
    const float d2 = dx * dx + dy * dy + dz * dz;
    const float q = d2 < h2 ? h2 - d2 : 0.f;
    const float w = q * q;  // grad W ~ (h^2 - d^2)^2 (x_i - x_j); 0 for i itself
    gx += w * dx;
    gy += w * dy;
    gz += w * dz;
    count += d2 < h2 ? 1 : 0;
  }
}

// Whether a particle with these sums (count includes itself) is a surface
// particle: fewer neighbours than min_neighbours, or |grad c| h above the
// threshold (scale: the kernel's constant for this particle).
KOKKOS_INLINE_FUNCTION bool surface_test(float gx, float gy, float gz, int count, float scale, float threshold,
                                         int min_neighbours) {
  const int neighbours = count - 1;  // the particle itself is counted
  const float grad_h = Kokkos::Experimental::sqrt(gx * gx + gy * gy + gz * gz) * scale;
  return neighbours < min_neighbours || grad_h > threshold;
}

// Marks the particles of occupied neighbour cell `cell`: the 27 neighbour
// cells around it (range 1) are looked up once for all particles of the cell. Each
// particle's colour gradient is summed in one order on every backend: the
// cells in z, y, x order, their particles in sorted order (the host computes
// 4, 8 or 16 particles i at a time, one lane each, with the same operations;
// `lanes`: the most it may use, host_simd_lanes).
// Radii: scale is (r_max / h)^3 * 945 / (32 pi) and h_abs = h in double.
template <bool Radii, class MemSpace>
KOKKOS_INLINE_FUNCTION std::size_t surface_particles_of_cell(const NeighbourView<MemSpace>& nb,
                                                             const Kokkos::View<const std::uint64_t*, MemSpace>& keys,
                                                             std::size_t cell, int range, float h, float scale,
                                                             float threshold, int min_neighbours,
                                                             const Kokkos::View<std::uint8_t*, MemSpace>& flags,
                                                             double h_abs = 0, int lanes = 4) {
  constexpr int kMaxCells = 27;  // range 1: cells at least h wide
  (void)lanes;                   // the host's groups below only
  // A cell crowded far beyond any fluid density (256x the rest density: a
  // solver blow-up, or many particles at one point) is all surface, without
  // the pairwise test that would cost its count squared.
  const std::uint32_t first = nb.cell_start(cell), last = nb.cell_start(cell + 1);
  if (last - first > kCrowdedCell) {
    for (std::uint32_t i = first; i < last; ++i) flags(i) = 1;
    return last - first;
  }
  std::uint32_t begin[kMaxCells], end[kMaxCells];
  int n_cells = 0;
  bool face_empty = false;
  const std::uint64_t key = keys(cell);
  std::int64_t cx, cy, cz;
  neighbour_cell_of_key(key, nb.nb_dims, cx, cy, cz);
  for (std::int64_t z = cz - range; z <= cz + range; ++z)
    for (std::int64_t y = cy - range; y <= cy + range; ++y)
      for (std::int64_t x = cx - range; x <= cx + range; ++x) {
        if (x < 0 || y < 0 || z < 0 || x >= nb.nb_dims[0] || y >= nb.nb_dims[1] || z >= nb.nb_dims[2]) continue;
        std::uint32_t b, e;
        if (nb.cell_range(x, y, z, b, e)) {
          begin[n_cells] = b;
          end[n_cells] = e;
          ++n_cells;
        } else if ((x != cx) + (y != cy) + (z != cz) == 1 && (x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) == 1) {
          face_empty = true;
        }
      }
  // Face neighbours outside the neighbour grid are empty too.
  if (cx == 0 || cy == 0 || cz == 0 || cx + 1 >= nb.nb_dims[0] || cy + 1 >= nb.nb_dims[1] || cz + 1 >= nb.nb_dims[2])
    face_empty = true;
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  const float h2 = h * h;
  std::size_t surface = 0;
  auto mark = [&](std::uint32_t i, float gx, float gy, float gz, int count, float scale_i) {
    const bool is_surface = surface_test(gx, gy, gz, count, scale_i, threshold, min_neighbours);
    flags(i) = is_surface ? 1 : 0;
    surface += is_surface ? 1 : 0;
  };
  if constexpr (Radii) {
    const float* T = nb.scale.data();
    for (std::uint32_t i = first; i < last; ++i) {
      const float xi = X[i], yi = Y[i], zi = Z[i];
      const float ti = T[i];
      const float inv_hi = float(1.0 / (h_abs * double(ti)));
      float gx = 0, gy = 0, gz = 0;
      int count = 0;
      for (int c = 0; c < n_cells; ++c)
        for (std::uint32_t j = begin[c]; j < end[c]; ++j) {
          const float ex = (xi - X[j]) * inv_hi, ey = (yi - Y[j]) * inv_hi, ez = (zi - Z[j]) * inv_hi;
          const float e2 = ex * ex + ey * ey + ez * ez;
          const float q = e2 < 1.f ? 1.f - e2 : 0.f;
          const float tj = T[j];
          const float w = (q * q) * (tj * tj * tj);  // 0 for i itself (e = 0)
          gx += w * ex;
          gy += w * ey;
          gz += w * ez;
          count += e2 < 1.f ? 1 : 0;
        }
      mark(i, gx, gy, gz, count, scale / (ti * ti * ti));
    }
  } else {
    (void)h_abs;
#if defined(__CUDA_ARCH__)
  for (std::uint32_t i = first; i < last; ++i) {
    const float xi = X[i], yi = Y[i], zi = Z[i];
    float gx = 0, gy = 0, gz = 0;
    int count = 0;
    for (int c = 0; c < n_cells; ++c) add_surface_pairs(X, Y, Z, begin[c], end[c], xi, yi, zi, h2, gx, gy, gz, count);
    mark(i, gx, gy, gz, count, scale);
  }
#else
  // The loop above, for groups of 4, 8 or 16 particles i at once
  // (surface_sums_host: one lane each, the same operations).
  float gx[16], gy[16], gz[16];
  int count[16];
  for (std::uint32_t i0 = first; i0 < last;) {
    const int L = surface_sums_host(X, Y, Z, begin, end, n_cells, i0, last, h2, lanes, gx, gy, gz, count);
    for (int l = 0; l < L && i0 + std::uint32_t(l) < last; ++l)
      mark(i0 + std::uint32_t(l), gx[l], gy[l], gz[l], count[l], scale);
    i0 += std::uint32_t(L);
  }
#endif
  }
  // Safety net for clumps the two criteria miss (coincident or compressed
  // particles: many neighbours, no colour gradient): a cell next to an empty
  // cell that holds no surface particle is all surface. Cells on a normal
  // free surface already hold surface particles, so the band is unchanged there.
  // The cells are at least h wide (about 8 particles at rest density for the
  // default h = 2r), so inside the fluid they are not empty.
  if (surface == 0 && face_empty) {
    for (std::uint32_t i = first; i < last; ++i) flags(i) = 1;
    surface = last - first;
  }
  return surface;
}

// GPU, without radii: the flags of surface_particles_of_cell, one thread per
// particle instead of one per cell (a cell's particles are neighbouring
// threads with the same 27 cells to walk, where the per-cell threads were
// few, about a wave of the GPU, each looping over its particles). Each
// particle's sums are those of surface_particles_of_cell, in its order;
// then, per cell, the safety net (no surface particle and an empty face
// neighbour: all surface). Crowded cells are all surface, as there.
template <class ExecSpace>
std::size_t mark_surface_particles_device(const ExecSpace& space, MemoryTracker& tracker,
                                          const NeighbourView<typename ExecSpace::memory_space>& nb,
                                          const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space>& keys,
                                          std::size_t n_cells, float h, float scale, float threshold,
                                          int min_neighbours,
                                          const Kokkos::View<std::uint8_t*, typename ExecSpace::memory_space>& flags) {
  using MemSpace = typename ExecSpace::memory_space;
  using Range = Kokkos::RangePolicy<ExecSpace>;
  const std::size_t n = nb.n;
  if (n == 0 || n_cells == 0) return 0;
  Buffer<std::uint32_t, MemSpace> cell_of_buf(tracker, "surface_particles::cell_of", n);
  const Kokkos::View<std::uint32_t*, MemSpace> cell_of = cell_of_buf.view();
  const auto start = nb.cell_start;
  Kokkos::parallel_for(
      "nbmc::surface_particles::cell_of", Range(space, 0, n_cells), KOKKOS_LAMBDA(const std::size_t c) {
        for (std::uint32_t i = start(c); i < start(c + 1); ++i) cell_of(i) = std::uint32_t(c);
      });
  const float h2 = h * h;
  Kokkos::parallel_for(
      "nbmc::surface_particles::particles", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t pi) {
        const std::uint32_t i = std::uint32_t(pi);
        const std::uint32_t c = cell_of(i);
        if (start(c + 1) - start(c) > kCrowdedCell) {
          flags(i) = 1;
          return;
        }
        std::int64_t cx, cy, cz;
        neighbour_cell_of_key(keys(c), nb.nb_dims, cx, cy, cz);
        const float* X = nb.pos.data();
        const float* Y = X + nb.n;
        const float* Z = Y + nb.n;
        const float xi = X[i], yi = Y[i], zi = Z[i];
        float gx = 0, gy = 0, gz = 0;
        int count = 0;
        // With the dense cell table, a row's three cells are one range of
        // the sorted particles: one look-up instead of three, the same
        // particles in the same order.
        const bool rows = nb.dense_start.extent(0) != 0;
        const std::int64_t x0 = cx > 0 ? cx - 1 : 0, x1 = cx + 1 < nb.nb_dims[0] ? cx + 1 : cx;
        for (std::int64_t z = cz - 1; z <= cz + 1; ++z)
          for (std::int64_t y = cy - 1; y <= cy + 1; ++y) {
            if (y < 0 || z < 0 || y >= nb.nb_dims[1] || z >= nb.nb_dims[2]) continue;
            std::uint32_t b, e;
            if (rows) {
              nb.row_range(x0, x1, y, z, b, e);
              add_surface_pairs(X, Y, Z, b, e, xi, yi, zi, h2, gx, gy, gz, count);
              continue;
            }
            for (std::int64_t x = x0; x <= x1; ++x)
              if (nb.cell_range(x, y, z, b, e)) add_surface_pairs(X, Y, Z, b, e, xi, yi, zi, h2, gx, gy, gz, count);
          }
        flags(i) = surface_test(gx, gy, gz, count, scale, threshold, min_neighbours) ? 1 : 0;
      });
  // The safety net, per cell (surface_particles_of_cell's).
  Kokkos::parallel_for(
      "nbmc::surface_particles::safety_net", Range(space, 0, n_cells), KOKKOS_LAMBDA(const std::size_t c) {
        const std::uint32_t first = start(c), last = start(c + 1);
        if (last - first > kCrowdedCell) return;
        for (std::uint32_t i = first; i < last; ++i)
          if (flags(i)) return;
        std::int64_t cx, cy, cz;
        neighbour_cell_of_key(keys(c), nb.nb_dims, cx, cy, cz);
        bool face_empty =
            cx == 0 || cy == 0 || cz == 0 || cx + 1 >= nb.nb_dims[0] || cy + 1 >= nb.nb_dims[1] || cz + 1 >= nb.nb_dims[2];
        for (int f = 0; f < 6 && !face_empty; ++f) {
          const std::int64_t d = (f & 1) ? 1 : -1;
          const std::int64_t x = cx + (f / 2 == 0 ? d : 0), y = cy + (f / 2 == 1 ? d : 0), z = cz + (f / 2 == 2 ? d : 0);
          std::uint32_t b, e;
          if (!nb.cell_range(x, y, z, b, e)) face_empty = true;
        }
        if (!face_empty) return;
        for (std::uint32_t i = first; i < last; ++i) flags(i) = 1;
      });
  std::size_t count = 0;
  Kokkos::parallel_reduce(
      "nbmc::surface_particles::count", Range(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t i, std::size_t& acc) { acc += flags(i) ? 1 : 0; }, count);
  space.fence();
  return count;
}

// flags(i) = 1 for surface particles (sorted order); returns their count.
// tracker: for the GPU's per-particle pass (without it, per cell there too).
template <class ExecSpace>
std::size_t mark_surface_particles(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                                   const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space>& keys,
                                   std::size_t n_cells, const Params& p, const Grid& g,
                                   const Kokkos::View<std::uint8_t*, typename ExecSpace::memory_space>& flags,
                                   MemoryTracker* tracker = nullptr) {
  ScopedRegion region("nbmc::surface_particles");
  const float h = float(p.surface_radius);
  const int range = int(std::ceil(p.surface_radius / g.nb_cell));
  if (range != 1) throw Error(9, "the neighbour cells are smaller than the surface radius");
  // |grad c| * h with c = sum_j V W_poly6(x - x_j, h), V = r^3.
  const double h9 = std::pow(p.surface_radius, 9);
  const float scale = float(p.spacing * p.spacing * p.spacing * 945.0 / (32.0 * 3.14159265358979 * h9) * p.surface_radius);
  const float threshold = float(p.color_threshold);
  const int min_neighbours = p.neighbour_threshold;
  const int lanes = host_simd_lanes();  // host groups of particles (4 on a GPU: unused there)
  std::size_t count = 0;
  if (p.radius_ref > 0) {  // per-particle radii (radii.hpp): p.spacing is r_max
    const double rh = p.spacing / p.surface_radius;
    const float scale_r = float(rh * rh * rh * 945.0 / (32.0 * 3.14159265358979));
    const double h_abs = p.surface_radius;
    Kokkos::parallel_reduce(
        "nbmc::surface_particles",
        Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n_cells),
        KOKKOS_LAMBDA(const std::size_t c, std::size_t& acc) {
          acc += surface_particles_of_cell<true>(nb, keys, c, range, h, scale_r, threshold, min_neighbours, flags,
                                                 h_abs);
        },
        count);
    space.fence();
    return count;
  }
  if constexpr (!Kokkos::SpaceAccessibility<Kokkos::HostSpace, typename ExecSpace::memory_space>::accessible) {
    if (tracker && !std::getenv("NBMC_SURFACE_PER_CELL"))
      return mark_surface_particles_device(space, *tracker, nb, keys, n_cells, h, scale, threshold, min_neighbours,
                                           flags);
  }
  Kokkos::parallel_reduce(
      "nbmc::surface_particles",
      Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n_cells),
      KOKKOS_LAMBDA(const std::size_t c, std::size_t& acc) {
        acc += surface_particles_of_cell<false>(nb, keys, c, range, h, scale, threshold, min_neighbours, flags, 0,
                                                lanes);
      },
      count);
  space.fence();
  return count;
}

}  // namespace Details
}  // namespace nbmc
