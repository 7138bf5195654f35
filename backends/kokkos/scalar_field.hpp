// SPDX-License-Identifier: MIT
// Scalar field drivers, written once for every method (field_*.hpp):
//  - gather_field: each band vertex gathers the particles within R (paper
//    Sec. 4.1, "parallelization"). Work is tiled by 4x4x4 sub-block (one band
//    word): the occupied neighbour cells around the sub-block are looked up
//    once and shared by its up to 64 vertices; each vertex skips cells whose
//    box is farther than R. Used for the narrow band and the dense baseline.
//  - scatter_field: the paper's serial scatter baseline over a dense grid.
// Inner particles contribute like all others (no double layers, Fig. 2).
#pragma once

#include "common.hpp"
#include "field_common.hpp"
#include "grid.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"

#include <cmath>

namespace nbmc {
namespace Details {

constexpr int kMaxTileCells = 1024;

struct CellRange {
  std::uint32_t begin, end;
  float lo[3];  // lower corner of the cell (relative coordinates)
};

// Occupied neighbour cells whose coordinates lie in [lo, hi]; false if more
// than kMaxTileCells cells would have to be examined.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION bool collect_cells(const NeighbourView<MemSpace>& nb, const std::int64_t lo[3],
                                          const std::int64_t hi[3], float S, CellRange* cells, int& n) {
  n = 0;
  if ((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1) > kMaxTileCells) return false;
  for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
    for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x) {
        std::uint32_t b, e;
        if (!nb.cell_range(x, y, z, b, e)) continue;
        CellRange& c = cells[n++];
        c.begin = b;
        c.end = e;
        c.lo[0] = float(x) * S;
        c.lo[1] = float(y) * S;
        c.lo[2] = float(z) * S;
      }
  return true;
}

// Neighbour-cell range covering [xmin - R, xmax + R] on every axis.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION void cell_span(const NeighbourView<MemSpace>& nb, const float xmin[3], const float xmax[3],
                                      float R, std::int64_t lo[3], std::int64_t hi[3]) {
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::int64_t(Kokkos::Experimental::floor((xmin[a] - R) * nb.inv_nb_cell));
    hi[a] = std::int64_t(Kokkos::Experimental::floor((xmax[a] + R) * nb.inv_nb_cell));
    if (lo[a] < 0) lo[a] = 0;
    if (hi[a] > nb.nb_dims[a] - 1) hi[a] = nb.nb_dims[a] - 1;
  }
}

// Squared distance from point x to the box [lo, lo + S]^3.
KOKKOS_INLINE_FUNCTION float box_distance2(const float lo[3], float S, const float x[3]) {
  float dist2 = 0;
  for (int a = 0; a < 3; ++a) {
    const float below = lo[a] - x[a], above = x[a] - (lo[a] + S);
    const float d = below > 0 ? below : (above > 0 ? above : 0.f);
    dist2 += d * d;
  }
  return dist2;
}

// Field value at x from the particles of `cells`; adds the number of
// contributing particles to `evals`.
template <class Method, class MemSpace>
KOKKOS_INLINE_FUNCTION float eval_vertex(const NeighbourView<MemSpace>& nb, const CellRange* cells, int n_cells,
                                         const float x[3], float S, const FieldConstants& fc, std::uint64_t& evals) {
  float acc[Method::N];
  for (int q = 0; q < Method::N; ++q) acc[q] = 0.f;
  const float R2 = fc.R * fc.R, inv_R2 = fc.inv_R2;
  const float x0 = x[0], x1 = x[1], x2 = x[2];
  const float* X = nb.pos.data();
  const float* Y = X + nb.n;
  const float* Z = Y + nb.n;
  std::uint32_t count = 0;
  for (int c = 0; c < n_cells; ++c) {
    const CellRange& cr = cells[c];
    if (box_distance2(cr.lo, S, x) >= R2) continue;
    count += Method::accumulate(acc, X, Y, Z, cr.begin, cr.end, x0, x1, x2, inv_R2);
  }
  evals += count;
  return Method::value(acc, fc);
}

// Host tile evaluation: the particles of all cells within R of the tile are
// copied once into a contiguous buffer, then every vertex of the tile runs one
// long vectorised loop over it (the CPU form of the GPU's shared-memory tile).
constexpr std::uint32_t kTileParticles = 6144;
struct TileScratch {
  float x[kTileParticles], y[kTileParticles], z[kTileParticles];
};

template <class Method, class MemSpace>
inline bool eval_tile_host(const NeighbourView<MemSpace>& nb, const CellRange* cells, int n_cells, const float tmin[3],
                           const float tmax[3], float S, const FieldConstants& fc, std::uint64_t word,
                           std::uint64_t full, std::size_t w, const BandView<MemSpace>& band, float c,
                           const Kokkos::View<float*, MemSpace>& phi, std::uint64_t& evals) {
  static thread_local TileScratch scratch;
  const float R2 = fc.R * fc.R;
  std::uint32_t n = 0;
  for (int q = 0; q < n_cells; ++q) {
    const CellRange& cr = cells[q];
    // distance between the cell box and the tile box
    float d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const float gap = cr.lo[a] > tmax[a] ? cr.lo[a] - tmax[a] : (tmin[a] > cr.lo[a] + S ? tmin[a] - cr.lo[a] - S : 0.f);
      d2 += gap * gap;
    }
    if (d2 >= R2) continue;
    if (n + (cr.end - cr.begin) > kTileParticles) return false;
    const float* X = nb.pos.data();
    for (std::uint32_t j = cr.begin; j < cr.end; ++j, ++n) {
      scratch.x[n] = X[j];
      scratch.y[n] = X[nb.n + j];
      scratch.z[n] = X[2 * nb.n + j];
    }
  }
  while (word) {
    const int bit = ctz64(word);
    word &= word - 1;
    std::int64_t i, j, k;
    band.vertex(w, bit, i, j, k);
    float acc[Method::N];
    for (int q = 0; q < Method::N; ++q) acc[q] = 0.f;
    evals += Method::accumulate(acc, scratch.x, scratch.y, scratch.z, 0, n, float(i) * c, float(j) * c,
                                float(k) * c, fc.inv_R2);
    phi(band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1))) = Method::value(acc, fc);
  }
  return true;
}

// Evaluates the field on the band. With `old` (a band contained in `band`
// whose values are `old_phi`), values of vertices already in `old` are copied
// and only the new vertices are evaluated (used when the band grows).
template <class Method, class ExecSpace>
std::uint64_t gather_field(const ExecSpace& space, const NeighbourView<typename ExecSpace::memory_space>& nb,
                           const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                           const Grid& g, const FieldConstants& fc,
                           const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                           const Progress& progress,
                           const BandView<typename ExecSpace::memory_space>* old = nullptr,
                           const Kokkos::View<const float*, typename ExecSpace::memory_space>& old_phi = {}) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::scalar_field::gather");
  constexpr bool host = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  const float c = float(g.cell), S = float(g.nb_cell);
  const bool has_old = old != nullptr;
  const BandView<MemSpace> ob = has_old ? *old : BandView<MemSpace>();
  std::uint64_t total_evals = 0;
  const std::size_t chunk = std::max<std::size_t>(4096, n_words / 64);
  for (std::size_t w0 = 0; w0 < n_words; w0 += chunk) {
    const std::size_t w1 = std::min(n_words, w0 + chunk);
    std::uint64_t evals = 0;
    Kokkos::parallel_reduce(
        "nbmc::scalar_field::gather",
        Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, w0, w1),
        KOKKOS_LAMBDA(const std::size_t w, std::uint64_t& acc_evals) {
          const std::uint64_t full = band.words(w);
          std::uint64_t word = full;
          if (!word) return;
          std::int64_t i0, j0, k0;
          band.vertex(w, 0, i0, j0, k0);
          if (has_old) {  // carry over the values the smaller band already has
            const std::uint32_t b = ob.blocks.find(
                morton3(std::uint32_t(i0 >> 3), std::uint32_t(j0 >> 3), std::uint32_t(k0 >> 3)));
            if (b != ~0u) {
              const std::size_t ow = std::size_t(b) * 8 + (w & 7);
              std::uint64_t both = ob.words(ow) & full;
              word = full & ~ob.words(ow);
              while (both) {
                const int bit = ctz64(both);
                both &= both - 1;
                const std::uint64_t below = (std::uint64_t(1) << bit) - 1;
                phi(band.word_offset(w) + popcount64(full & below)) =
                    old_phi(ob.word_offset(ow) + popcount64(ob.words(ow) & below));
              }
            }
            if (!word) return;
          }
          CellRange cells[kMaxTileCells];
          int n_cells = 0;
          const float tmin[3] = {float(i0) * c, float(j0) * c, float(k0) * c};
          const float tmax[3] = {float(i0 + 3) * c, float(j0 + 3) * c, float(k0 + 3) * c};
          std::int64_t lo[3], hi[3];
          cell_span(nb, tmin, tmax, fc.R, lo, hi);
          const bool tiled = collect_cells(nb, lo, hi, S, cells, n_cells);
          if constexpr (host) {
            if (tiled && eval_tile_host<Method>(nb, cells, n_cells, tmin, tmax, S, fc, word, full, w, band, c, phi,
                                                acc_evals))
              return;
          }
          while (word) {
            const int bit = ctz64(word);
            word &= word - 1;
            std::int64_t i, j, k;
            band.vertex(w, bit, i, j, k);
            const float x[3] = {float(i) * c, float(j) * c, float(k) * c};
            if (!tiled) {  // very coarse cells: look the cells up per vertex
              cell_span(nb, x, x, fc.R, lo, hi);
              collect_cells(nb, lo, hi, S, cells, n_cells);
            }
            phi(band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1))) =
                eval_vertex<Method>(nb, cells, n_cells, x, S, fc, acc_evals);
          }
        },
        evals);
    space.fence();
    total_evals += evals;
    if (!has_old) progress(4 /*NBMC_STAGE_FIELD*/, double(w1) / double(n_words));
  }
  return total_evals;
}

// Serial scatter over a dense grid of accumulators (the paper's baseline).
// Host memory only. Writes phi for every vertex of a dense band.
template <class Method, class ExecSpace>
std::uint64_t scatter_field(const ExecSpace& space, MemoryTracker& tracker,
                            const Kokkos::View<const float*, Kokkos::HostSpace>& pos, std::size_t n,
                            const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                            const Grid& g, const FieldConstants& fc,
                            const Kokkos::View<float*, typename ExecSpace::memory_space>& phi,
                            const Progress& progress) {
  ScopedRegion region("nbmc::scalar_field::scatter");
  constexpr int N = Method::N;
  const std::uint64_t nv = g.vertex_count();
  Buffer<float, Kokkos::HostSpace> acc(tracker, "scalar_field::scatter_accumulators", nv * N, true);
  float* a = acc.data();
  const double c = g.cell;
  const std::int64_t d0 = g.dims[0], d1 = g.dims[1], d2 = g.dims[2];
  std::uint64_t evals = 0;
  for (std::size_t p = 0; p < n; ++p) {
    const float px = pos(p), py = pos(n + p), pz = pos(2 * n + p);
    const std::int64_t lo[3] = {std::max<std::int64_t>(0, std::int64_t(std::ceil((px - fc.R) / c))),
                                std::max<std::int64_t>(0, std::int64_t(std::ceil((py - fc.R) / c))),
                                std::max<std::int64_t>(0, std::int64_t(std::ceil((pz - fc.R) / c)))};
    const std::int64_t hi[3] = {std::min<std::int64_t>(d0 - 1, std::int64_t(std::floor((px + fc.R) / c))),
                                std::min<std::int64_t>(d1 - 1, std::int64_t(std::floor((py + fc.R) / c))),
                                std::min<std::int64_t>(d2 - 1, std::int64_t(std::floor((pz + fc.R) / c)))};
    for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
      const float dz = pz - float(k) * float(c);
      for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
        const float dy = py - float(j) * float(c);
        float* row = a + N * std::size_t(d0) * (std::size_t(j) + std::size_t(d1) * std::size_t(k));
        for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
          const float dx = px - float(i) * float(c);
          const float s2 = (dx * dx + dy * dy + dz * dz) * fc.inv_R2;
          if (s2 >= 1.f) continue;
          Method::add(row + N * i, dx, dy, dz, 1.f - s2);
          ++evals;
        }
      }
    }
    if ((p & 0xffff) == 0xffff) progress(4, 0.95 * double(p) / double(n));
  }
  Kokkos::parallel_for(
      "nbmc::scalar_field::scatter_finalize", Kokkos::RangePolicy<ExecSpace>(space, 0, n_words),
      KOKKOS_LAMBDA(const std::size_t w) {
        std::uint64_t word = band.words(w);
        std::uint64_t out = band.word_offset(w);
        while (word) {
          const int bit = ctz64(word);
          word &= word - 1;
          std::int64_t i, j, k;
          band.vertex(w, bit, i, j, k);
          phi(out++) = Method::value(a + N * (std::size_t(i) + std::size_t(d0) * (std::size_t(j) + std::size_t(d1) * std::size_t(k))), fc);
        }
      });
  space.fence();
  progress(4, 1.0);
  return evals;
}

}  // namespace Details
}  // namespace nbmc
