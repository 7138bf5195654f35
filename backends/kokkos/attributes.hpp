// SPDX-License-Identifier: MIT
// Particle attributes interpolated onto the vertices of a finished mesh, on
// the context's execution space (Serial, OpenMP or the GPU): for every vertex
// x, the weighted mean over the particles j closer than R of their values,
// weight w_j = (1 - |x - x_j|^2 / R^2)^3 (the kernel the CLI's --attributes
// always used, src/io/attributes.cpp). The particles are sorted into cells of
// size R with the pipeline's neighbourhood (neighbourhood.hpp: a strict total
// order independent of the input order, the same on the host and the
// device), and each vertex sums its 27 cells in a fixed order in double
// precision, so every backend gives the same values, bit for bit (FMA
// contraction is off on every backend, src/CMakeLists.txt).
//
// Vertices with no particle closer than R are only flagged here (`empty`);
// the caller gives them the value of the nearest particle on the host.
#pragma once

#include "../../src/backends.hpp"
#include "../../src/core/parallel.hpp"
#include "neighbourhood.hpp"

#include <limits>

namespace nbmc {
namespace Details {

// The cells of size R/2 over the particles' bounding box (a vertex's
// particles lie in the 5^3 cells around its own, of which those farther than
// R are skipped: about 2.5 times fewer candidates than 27 cells of size R);
// false when the box is too large for 21-bit cell indices (the caller then
// uses the host path).
inline bool attribute_grid(const double lo[3], const double hi[3], double radius, Grid& g) {
  g.nb_cell = 0.5 * radius;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = lo[a] - radius;
    const double cells = (hi[a] - g.origin[a]) / g.nb_cell + 3;
    if (!(cells < double(1u << 21))) return false;
    g.nb_dims[a] = std::int64_t(cells);
  }
  return true;
}

// Distance along one axis from x to the interval of cell k (0 inside).
KOKKOS_INLINE_FUNCTION double cell_gap(double x, std::int64_t k, double cell) {
  const double lo = double(k) * cell, hi = lo + cell;
  return x < lo ? lo - x : (x > hi ? x - hi : 0.0);
}

template <class ExecSpace>
bool interpolate_attributes(const ExecSpace& space, MemoryTracker& tracker, const AttributeJob& job) {
  using MemSpace = typename ExecSpace::memory_space;
  using Range = Kokkos::RangePolicy<ExecSpace>;
  using Unmanaged = Kokkos::MemoryTraits<Kokkos::Unmanaged>;
  constexpr bool host_memory = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  ScopedRegion region("nbmc::attributes");
  const std::size_t n = job.count, nv = job.vertex_count, width = job.width;
  if (n == 0 || nv == 0 || width == 0) return true;

  // Particle positions where the kernels can read them, and their bounds.
  Buffer<double, MemSpace> staged;
  Kokkos::View<const double*, MemSpace> dxyz;
  if (job.on_device) {
    if constexpr (host_memory) throw Error(7, "device particles need the CUDA backend");
    dxyz = Kokkos::View<const double*, MemSpace, Unmanaged>(job.xyz, 3 * n);
  } else if constexpr (host_memory) {
    dxyz = Kokkos::View<const double*, MemSpace, Unmanaged>(job.xyz, 3 * n);
  } else {
    staged = Buffer<double, MemSpace>(tracker, "attributes::particles", 3 * n);
    Kokkos::deep_copy(space, staged.view(),
                      Kokkos::View<const double*, Kokkos::HostSpace, Unmanaged>(job.xyz, 3 * n));
    dxyz = staged.view();
  }
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    using MinMax = Kokkos::MinMax<double>;
    typename MinMax::value_type m;
    Kokkos::parallel_reduce(
        "nbmc::attributes::bounds", Range(space, 0, n),
        KOKKOS_LAMBDA(const std::size_t i, typename MinMax::value_type& r) {
          const double v = dxyz(3 * i + std::size_t(a));
          if (v < r.min_val) r.min_val = v;
          if (v > r.max_val) r.max_val = v;
        },
        MinMax(m));
    lo[a] = m.min_val;
    hi[a] = m.max_val;
  }
  trace("attributes: particles staged, bounds", n);
  if (job.use_bounds)
    for (int a = 0; a < 3; ++a) {
      lo[a] = job.bounds[a];
      hi[a] = job.bounds[3 + a];
    }
  Grid g;
  if (!attribute_grid(lo, hi, job.radius, g)) return false;

  Neighbourhood<MemSpace> nb;
  if constexpr (host_memory)
    build_neighbourhood(space, tracker, job.xyz, n, {}, g, nb);
  else
    build_neighbourhood_device(space, tracker, dxyz, Kokkos::View<const std::uint32_t*, MemSpace>(), n, g, nb);
  staged.release();
  trace("attributes: neighbourhood", nb.n_cells);
  const NeighbourView<MemSpace> nbv = view_of(nb, g);

  // The values in the sorted order of the particles.
  Buffer<double, MemSpace> sorted(tracker, "attributes::values", n * width);
  {
    Buffer<double, MemSpace> raw;
    Kokkos::View<const double*, MemSpace> src;
    if constexpr (host_memory) {
      src = Kokkos::View<const double*, MemSpace, Unmanaged>(job.values, n * width);
    } else {
      raw = Buffer<double, MemSpace>(tracker, "attributes::upload", n * width);
      Kokkos::deep_copy(space, raw.view(),
                        Kokkos::View<const double*, Kokkos::HostSpace, Unmanaged>(job.values, n * width));
      src = raw.view();
    }
    const auto dst = sorted.view();
    const auto perm = nb.perm.view();
    Kokkos::parallel_for(
        "nbmc::attributes::sort_values", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t j) {
          const std::size_t from = std::size_t(perm(j)) * width;
          for (std::size_t k = 0; k < width; ++k) dst(j * width + k) = src(from + k);
        });
    space.fence();
  }

  trace("attributes: values sorted", n * width);
  // Per-particle supports (radii): 1 / (R scale_j)^2 in the sorted order.
  Buffer<double, MemSpace> inv_support2;
  if (job.scale) {
    inv_support2 = Buffer<double, MemSpace>(tracker, "attributes::inv_support2", n);
    Buffer<double, MemSpace> raw;
    Kokkos::View<const double*, MemSpace> src;
    if constexpr (host_memory) {
      src = Kokkos::View<const double*, MemSpace, Unmanaged>(job.scale, n);
    } else {
      raw = Buffer<double, MemSpace>(tracker, "attributes::scale_upload", n);
      Kokkos::deep_copy(space, raw.view(), Kokkos::View<const double*, Kokkos::HostSpace, Unmanaged>(job.scale, n));
      src = raw.view();
    }
    const auto dst = inv_support2.view();
    const auto perm = nb.perm.view();
    const double inv_r2 = 1.0 / (job.radius * job.radius);
    Kokkos::parallel_for(
        "nbmc::attributes::sort_supports", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t j) {
          const double sc = src(perm(j));
          dst(j) = inv_r2 / (sc * sc);
        });
    space.fence();
  }
  // The vertices, relative to the grid origin (double), then the sums.
  Buffer<double, MemSpace> verts(tracker, "attributes::vertices", 3 * nv);
  {
    auto h = Kokkos::create_mirror_view(verts.view());
    double* hp = h.data();
    const double o[3] = {g.origin[0], g.origin[1], g.origin[2]};
    for_chunks(nv, chunk_count(nv, 1 << 16), [&](std::size_t, std::size_t b, std::size_t e) {
      for (std::size_t v = b; v < e; ++v)
        for (std::size_t a = 0; a < 3; ++a)
          hp[3 * v + a] = (job.vertices64 ? job.vertices64[3 * v + a] : double(job.vertices[3 * v + a])) - o[a];
    });
    Kokkos::deep_copy(space, verts.view(), h);
  }
  trace("attributes: vertices", nv);
  Buffer<double, MemSpace> out(tracker, "attributes::result", nv * width);
  Buffer<std::uint8_t, MemSpace> empty(tracker, "attributes::empty", nv);
  {
    const auto vx = verts.view();
    const auto val = sorted.view();
    const auto res = out.view();
    const auto emp = empty.view();
    const auto inv_sup = inv_support2.view();
    const bool per_particle = job.scale != nullptr;
    const double inv_s = 1.0 / g.nb_cell, inv_r2 = 1.0 / (job.radius * job.radius);
    const std::int64_t nd0 = g.nb_dims[0], nd1 = g.nb_dims[1], nd2 = g.nb_dims[2];
    const std::size_t np = n;
    // Up to kChunk components are summed in registers per pass over the
    // particles; wider attribute sets take several passes (the weights are
    // recomputed: the same values, in the same order, every pass).
    constexpr std::size_t kChunk = 8;
    const double cell = g.nb_cell, reach2 = 1.0001 * job.radius * job.radius;
    Kokkos::parallel_for(
        "nbmc::attributes::interpolate", Range(space, 0, nv), KOKKOS_LAMBDA(const std::size_t v) {
          const double x = vx(3 * v), y = vx(3 * v + 1), z = vx(3 * v + 2);
          const std::int64_t c0 = std::int64_t(neighbour_cell(x, inv_s, nd0));
          const std::int64_t c1 = std::int64_t(neighbour_cell(y, inv_s, nd1));
          const std::int64_t c2 = std::int64_t(neighbour_cell(z, inv_s, nd2));
          for (std::size_t first = 0; first < width; first += kChunk) {
            const std::size_t m = width - first < kChunk ? width - first : kChunk;
            double acc[kChunk] = {0, 0, 0, 0, 0, 0, 0, 0};
            double wsum = 0;
            for (std::int64_t k2 = c2 - 2; k2 <= c2 + 2; ++k2)
              for (std::int64_t k1 = c1 - 2; k1 <= c1 + 2; ++k1)
                for (std::int64_t k0 = c0 - 2; k0 <= c0 + 2; ++k0) {
                  if (k0 < 0 || k1 < 0 || k2 < 0 || k0 >= nd0 || k1 >= nd1 || k2 >= nd2) continue;
                  // Skip a cell whose box is farther than R (with a margin
                  // for the float positions: nothing in it has weight).
                  const double g0 = cell_gap(x, k0, cell), g1 = cell_gap(y, k1, cell), g2 = cell_gap(z, k2, cell);
                  if (g0 * g0 + g1 * g1 + g2 * g2 > reach2) continue;
                  std::uint32_t b, e;
                  if (!nbv.cell_range(k0, k1, k2, b, e)) continue;
                  for (std::uint32_t j = b; j < e; ++j) {
                    const double d0 = x - double(nbv.pos(j)), d1 = y - double(nbv.pos(np + j)),
                                 d2 = z - double(nbv.pos(2 * np + j));
                    const double s2 = (d0 * d0 + d1 * d1 + d2 * d2) * (per_particle ? inv_sup(j) : inv_r2);
                    if (s2 >= 1.0) continue;
                    const double t = 1.0 - s2;
                    const double w = t * t * t;
                    wsum += w;
                    const std::size_t at = std::size_t(j) * width + first;
                    for (std::size_t k = 0; k < kChunk; ++k)
                      if (k < m) acc[k] += w * val(at + k);
                  }
                }
            if (first == 0) emp(v) = wsum > 0 ? 0 : 1;
            for (std::size_t k = 0; k < m; ++k) res(v * width + first + k) = wsum > 0 ? acc[k] / wsum : 0.0;
          }
        });
    space.fence();
  }
  trace("attributes: sums", nv);
  Kokkos::deep_copy(space, Kokkos::View<double*, Kokkos::HostSpace, Unmanaged>(job.out, nv * width), out.view());
  Kokkos::deep_copy(space, Kokkos::View<std::uint8_t*, Kokkos::HostSpace, Unmanaged>(job.empty, nv), empty.view());
  space.fence();
  return true;
}

}  // namespace Details
}  // namespace nbmc
