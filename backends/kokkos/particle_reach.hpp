// SPDX-License-Identifier: MIT
// Which particles the band's field can reach, for the passes over the
// particles before the field (SPH's weights, sph_density.hpp; YT10's
// kernels, yt10_kernels.hpp): a particle's weight or kernel is read only by
// band vertices within R of it, and in a frame's interior most particles
// have none (on the 1.65 M frame at r/2 with R = 4r, 41 % of them).
//
// Reach is decided per occupied neighbour cell, conservatively: a cell is
// reached when the box of a band tile's vertices (4x4x4 vertices, a band
// word, with band vertices) lies within R of the cell's box (a small
// margin; the cell's box unbounded on the sides of the grid's edge cells,
// into which particles outside it are clamped); on that frame 71 % of the
// particles lie in reached cells (59 % within R of a band vertex). Every
// cell a gather visits (box distance below R from one of its vertices) is
// reached (test: ParticleReach.SelectReachesEveryCellWithinROfABandTile),
// so the data of the others is never read. A
// pass computes the cells reached since its last run: before the field, and
// after each round of band growth for the words it added. The tiles are a
// bitmap over the grid; where it would pass kMaxBits (very large sparse
// domains), or without a narrow band, every cell counts as reached. On the
// host only: a GPU's pass (one thread per particle, which would first have
// to find its cell) took as long or longer with the reach as without
// (H100, 1.65 M frame: YT10's field 13.3-14.0 ms without, 14.5-14.7 with),
// so there every particle is computed, once.
#pragma once

#include "common.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"

#include <cstdint>

namespace nbmc {
namespace Details {

// Cells of a row in one work item of the host passes (ParticleReach::host_ranges).
constexpr int kRunCells = 8;

// The particles of one such work item: ranges [b[i], e[i]) of the sorted
// order, i < n, ascending.
struct ParticleRanges {
  std::uint32_t b[kRunCells], e[kRunCells];
  int n = 0;
};

template <class MemSpace>
struct ParticleReach {
  static constexpr std::uint64_t kMaxBits = std::uint64_t(1) << 27;  // 16 MiB
  Buffer<std::uint32_t, MemSpace> tiles;  // the band's tiles, a bit per 4x4x4 tile of the grid
  Buffer<std::uint8_t, MemSpace> state;   // per occupied neighbour cell: 0 unreached, 1 to compute, 2 done
  std::int64_t tdims[3] = {0, 0, 0};
  bool all = false;       // every cell (no bitmap, no states)
  bool complete = false;  // with all: the one pass has run

  static constexpr bool kHost = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;

  void start(MemoryTracker& tracker, std::size_t n_cells, const Grid& g, bool whole_grid) {
    for (int a = 0; a < 3; ++a) tdims[a] = 2 * g.block_dims(a);
    const std::uint64_t bits = std::uint64_t(tdims[0]) * std::uint64_t(tdims[1]) * std::uint64_t(tdims[2]);
    all = whole_grid || !kHost || bits > kMaxBits;
    complete = false;
    if (all) return;
    state = Buffer<std::uint8_t, MemSpace>(tracker, "scalar_field::reached_cells", n_cells, true);
    tiles = Buffer<std::uint32_t, MemSpace>(tracker, "scalar_field::band_tiles", (bits + 31) / 32, true);
  }
  // Whether a pass may have cells to compute.
  bool pending() const { return !(all && complete); }

  // Adds the band's words listed(0..n_list) (a word index each; without a
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
        "nbmc::scalar_field::band_tiles", Kokkos::RangePolicy<ExecSpace>(space, 0, n_list),
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

  // Marks 1 the cells not marked yet that the tiles now reach (radius R):
  // a tile with band vertices whose vertex box lies within R of the cell's
  // box (Euclidean; per axis, the gap between the cell's interval and the
  // tile's first and last vertex coordinates), the cell's box unbounded on
  // the grid's edge sides. The margin (1e-3 of a cell, plus a few float
  // roundings of the largest coordinate) covers the gathers' float tests
  // and a particle sorted into a cell next to its own by rounding.
  template <class ExecSpace>
  void select(const ExecSpace& space, const Neighbourhood<MemSpace>& nbh, const Grid& g, double R) {
    if (all) return;
    const auto st = state.view();
    const auto keys = nbh.cell_keys.view();
    const auto bits = tiles.view();
    const double S = g.nb_cell, c = g.cell;
    const std::int64_t nd[3] = {g.nb_dims[0], g.nb_dims[1], g.nb_dims[2]};
    const std::int64_t vd[3] = {g.dims[0], g.dims[1], g.dims[2]};
    const std::int64_t td[3] = {tdims[0], tdims[1], tdims[2]};
    double largest = 0;
    for (int a = 0; a < 3; ++a) {
      largest = largest > double(vd[a]) * c ? largest : double(vd[a]) * c;
      largest = largest > double(nd[a]) * S ? largest : double(nd[a]) * S;
    }
    const double reach = R + 1e-3 * c + 1e-6 * largest, reach2 = reach * reach;
    Kokkos::parallel_for(
        "nbmc::scalar_field::reached_cells", Kokkos::RangePolicy<ExecSpace>(space, 0, nbh.n_cells),
        KOKKOS_LAMBDA(const std::size_t q) {
          if (st(q) != 0) return;
          std::int64_t x[3], lo[3], hi[3];
          double clo[3], chi[3];
          neighbour_cell_of_key(keys(q), nd, x[0], x[1], x[2]);
          for (int a = 0; a < 3; ++a) {
            // (The tiles' vertex range, with one vertex of margin; then the
            // exact gap per tile below.)
            lo[a] = x[a] == 0 ? 0 : std::int64_t(Kokkos::Experimental::floor((double(x[a]) * S - reach) / c)) - 1;
            hi[a] = x[a] == nd[a] - 1 ? vd[a] - 1
                                      : std::int64_t(Kokkos::Experimental::ceil((double(x[a] + 1) * S + reach) / c)) + 1;
            lo[a] = lo[a] < 0 ? 0 : lo[a];
            hi[a] = hi[a] > vd[a] - 1 ? vd[a] - 1 : hi[a];
            lo[a] >>= 2;  // tiles
            hi[a] >>= 2;
            clo[a] = x[a] == 0 ? -1e300 : double(x[a]) * S;
            chi[a] = x[a] == nd[a] - 1 ? 1e300 : double(x[a] + 1) * S;
          }
          // Per axis, a tile's squared gap to the cell.
          auto gap2 = [&](int a, std::int64_t t) {
            const double first = double(4 * t) * c;
            const std::int64_t last_v = 4 * t + 3 < vd[a] - 1 ? 4 * t + 3 : vd[a] - 1;
            const double last = double(last_v) * c;
            const double gap = last < clo[a] ? clo[a] - last : first > chi[a] ? first - chi[a] : 0.0;
            return gap * gap;
          };
          for (std::int64_t k = lo[2]; k <= hi[2]; ++k) {
            const double gz = gap2(2, k);
            if (gz >= reach2) continue;
            for (std::int64_t j = lo[1]; j <= hi[1]; ++j) {
              const double gyz = gz + gap2(1, j);
              if (gyz >= reach2) continue;
              for (std::int64_t i = lo[0]; i <= hi[0]; ++i) {
                const std::uint64_t b =
                    std::uint64_t(i) + std::uint64_t(td[0]) * (std::uint64_t(j) + std::uint64_t(td[1]) * std::uint64_t(k));
                if (((bits(b >> 5) >> (b & 31)) & 1u) && gyz + gap2(0, i) < reach2) {
                  st(q) = 1;
                  return;
                }
              }
            }
          }
        });
  }

  // Whether a pass computes cell q now (host code, after select).
  KOKKOS_INLINE_FUNCTION static bool now(const Kokkos::View<std::uint8_t*, MemSpace>& st, bool every, std::size_t q) {
    return every || st(q) == 1;
  }

  // The host passes' work item q (an occupied neighbour cell): the particles
  // it computes now, as ranges in the sorted order (out.n = 0: none). The
  // cells of a row are taken in runs of kRunCells (aligned in x): the run's
  // first cell computed now takes every cell of its run computed now (their
  // particles follow one another: cell keys are row-major, a cell's
  // particles are sorted by x), the run's other items nothing. So the SIMD
  // lanes are filled with neighbouring particles of several cells (a cell of
  // R/2 holds about 9 particles of a fluid at rest with R = 4r: 16 lanes
  // over one cell ran about half empty). Which particles are computed, and
  // how each is summed, stay the same.
  KOKKOS_INLINE_FUNCTION static void host_ranges(const Kokkos::View<std::uint8_t*, MemSpace>& st, bool every,
                                                 const Kokkos::View<const std::uint64_t*, MemSpace>& keys,
                                                 const Kokkos::View<const std::uint32_t*, MemSpace>& starts,
                                                 std::uint64_t row, std::size_t q, ParticleRanges& out) {
    out.n = 0;
    if (!now(st, every, q)) return;
    const std::uint64_t k = keys(q), run = k / row * row + (k % row) / kRunCells * kRunCells;
    if (k > run && q > 0)
      for (std::size_t p = q - 1;; --p) {
        if (keys(p) < run) break;
        if (now(st, every, p)) return;  // (taken by an earlier item of the run)
        if (p == 0) break;
      }
    const std::size_t n_cells = keys.extent(0);
    const std::uint64_t end = run + kRunCells < k / row * row + row ? run + kRunCells : k / row * row + row;
    for (std::size_t p = q; p < n_cells && keys(p) < end; ++p) {
      if (!now(st, every, p)) continue;
      const std::uint32_t b = starts(p), e = starts(p + 1);
      if (out.n > 0 && out.e[out.n - 1] == b) {
        out.e[out.n - 1] = e;
      } else {
        out.b[out.n] = b;
        out.e[out.n] = e;
        ++out.n;
      }
    }
  }

  // How many particles the pass computes now (every one without the
  // bitmap); for the trace.
  template <class ExecSpace>
  std::uint64_t count_now(const ExecSpace& space, const Neighbourhood<MemSpace>& nbh) const {
    if (all) return nbh.n;
    const auto st = state.view();
    const auto starts = nbh.cell_start.view();
    std::uint64_t n = 0;
    Kokkos::parallel_reduce(
        "nbmc::scalar_field::reached_count", Kokkos::RangePolicy<ExecSpace>(space, 0, st.extent(0)),
        KOKKOS_LAMBDA(const std::size_t q, std::uint64_t& sum) {
          if (st(q) == 1) sum += starts(q + 1) - starts(q);
        },
        n);
    return n;
  }

  // Marks the cells of state 1 done (2).
  template <class ExecSpace>
  void finish(const ExecSpace& space) {
    if (all) {
      complete = true;
      return;
    }
    const auto st = state.view();
    Kokkos::parallel_for(
        "nbmc::scalar_field::reached_done", Kokkos::RangePolicy<ExecSpace>(space, 0, st.extent(0)),
        KOKKOS_LAMBDA(const std::size_t q) {
          if (st(q) == 1) st(q) = 2;
        });
  }
};

}  // namespace Details
}  // namespace nbmc
