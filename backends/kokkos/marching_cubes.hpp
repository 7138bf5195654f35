// SPDX-License-Identifier: MIT
// Parallel marching cubes on the band (paper Sec. 4.2, which was serial):
// a cell is triangulated only when its eight corners are band vertices. Each
// band vertex owns the three edges leaving it in +x, +y, +z; an intersection
// point is computed once per edge (shared-edge reuse) and numbered in band
// order, so the output order is deterministic and independent of the thread
// count. Passes:
//   A  cases: per cell, the case index; crossed edges are flagged at their
//      owner vertex (atomic OR: the result is a set, order-independent)
//   B  vertex numbering: prefix sum of the flagged edges
//   C  intersection points and normals (field gradient, central differences)
//   D  triangles: per-word counts, prefix sum, table lookup
#pragma once

#include "common.hpp"
#include "grid.hpp"
#include "mc_tables.hpp"
#include "narrow_band.hpp"

#include <algorithm>
#include <array>
#include <vector>

namespace nbmc {
namespace Details {

template <class MemSpace>
struct McTables {
  Kokkos::View<std::int8_t*, MemSpace> triangles;  // 256 * 3 * kMaxTriangles
  Kokkos::View<std::uint8_t*, MemSpace> count;     // 256
  Kokkos::View<std::uint16_t*, MemSpace> edges;    // 256
};

template <class ExecSpace>
McTables<typename ExecSpace::memory_space> make_mc_tables(const ExecSpace& space) {
  using MemSpace = typename ExecSpace::memory_space;
  McTables<MemSpace> t;
  constexpr int W = 3 * mc::kMaxTriangles;
  t.triangles = Kokkos::View<std::int8_t*, MemSpace>("nbmc::mc::triangles", 256 * W);
  t.count = Kokkos::View<std::uint8_t*, MemSpace>("nbmc::mc::count", 256);
  t.edges = Kokkos::View<std::uint16_t*, MemSpace>("nbmc::mc::edges", 256);
  auto ht = Kokkos::create_mirror_view(t.triangles);
  auto hc = Kokkos::create_mirror_view(t.count);
  auto he = Kokkos::create_mirror_view(t.edges);
  for (int c = 0; c < 256; ++c) {
    hc(c) = mc::kTriangleCount[c];
    he(c) = mc::kEdgeMask[c];
    for (int k = 0; k < W; ++k) ht(c * W + k) = mc::kTriangles[c][k];
  }
  Kokkos::deep_copy(space, t.triangles, ht);
  Kokkos::deep_copy(space, t.count, hc);
  Kokkos::deep_copy(space, t.edges, he);
  space.fence();
  return t;
}

// Corner at which edge e starts (same as mc::kEdgeStart, usable on devices).
KOKKOS_INLINE_FUNCTION int edge_start(int e) {
  const int axis = e >> 2, m = e & 3;
  return axis == 0 ? (m << 1) : (axis == 1 ? ((m & 1) | ((m >> 1) << 2)) : m);
}

// Band indices of the 8 corners of the cell whose minimum corner is (i,j,k)
// (band index self, in block `block` if the caller knows it: w >> 3 of its
// word w); false if one is not a band vertex.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION bool cell_corners(const BandView<MemSpace>& band, std::int64_t i, std::int64_t j,
                                         std::int64_t k, std::int64_t self, std::int64_t idx[8],
                                         std::uint32_t block = ~0u) {
  idx[0] = self;
  return band.cell_indices(i, j, k, 1, idx, block);
}

// band: anything with BandView's index(i, j, k) (a BandView, or the host's
// NearBlocks).
template <class Look, class MemSpace>
KOKKOS_INLINE_FUNCTION float gradient_component(Look& band, const Kokkos::View<const float*, MemSpace>& phi,
                                                std::int64_t i, std::int64_t j, std::int64_t k, std::int64_t self,
                                                int axis, float inv_c) {
  const std::int64_t di = axis == 0, dj = axis == 1, dk = axis == 2;
  const std::int64_t p = band.index(i + di, j + dj, k + dk);
  const std::int64_t m = band.index(i - di, j - dj, k - dk);
  if (p >= 0 && m >= 0) return 0.5f * (phi(p) - phi(m)) * inv_c;
  if (p >= 0) return (phi(p) - phi(self)) * inv_c;
  if (m >= 0) return (phi(self) - phi(m)) * inv_c;
  return 0.f;
}

// Runs f(w, bit, self) for every band vertex. On the host one work item per
// band word (its vertices in a loop, dynamic schedule); on a GPU one thread
// per vertex slot (64 per word): one thread per word gave 0.2 waves and
// 8-13% achieved occupancy on an H100 (ncu, bench/RESULTS.md).
template <class ExecSpace, class F>
void for_each_band_vertex(const ExecSpace& space, const char* label,
                          const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words, const F& f) {
  using MemSpace = typename ExecSpace::memory_space;
  if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
    Kokkos::parallel_for(
        label, Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n_words),
        KOKKOS_LAMBDA(const std::size_t w) {
          band.for_each_vertex(w, [&](const int bit, const std::int64_t self) { f(w, bit, self); });
        });
  } else {
    Kokkos::parallel_for(
        label, Kokkos::RangePolicy<ExecSpace>(space, 0, n_words * 64), KOKKOS_LAMBDA(const std::size_t v) {
          const std::size_t w = v >> 6;
          const int bit = int(v & 63);
          const std::uint64_t full = band.words(w);
          if (!((full >> bit) & 1)) return;
          f(w, bit, std::int64_t(band.word_offset(w) + popcount64(full & ((std::uint64_t(1) << bit) - 1))));
        });
  }
}

// Host passes block by block: the band index of a grid vertex near block b
// (in b or one of its 26 neighbouring blocks), each neighbouring block looked
// up in the hash map once, on first use, instead of once per vertex (pass C
// looked up to 13 blocks per mesh vertex: the other end of the edge and the
// central differences at both ends; pass D 7 per cell that crosses a block
// face). index() gives BandView::index's value for every vertex; farther
// vertices are looked up directly.
template <class MemSpace>
struct NearBlocks {
  static constexpr std::uint32_t kUnknown = ~0u - 1;  // not looked up yet (no band has 2^32 - 2 blocks)
  const BandView<MemSpace>* band;
  std::int64_t bx, by, bz;
  std::uint32_t nb[27];  // (dx + 1) + 3 (dy + 1) + 9 (dz + 1)
  KOKKOS_INLINE_FUNCTION NearBlocks(const BandView<MemSpace>& bv, std::size_t b) : band(&bv) {
    const std::uint64_t key = bv.block_keys(b);
    bx = std::int64_t(compact3(key));
    by = std::int64_t(compact3(key >> 1));
    bz = std::int64_t(compact3(key >> 2));
    for (int q = 0; q < 27; ++q) nb[q] = kUnknown;
    nb[13] = std::uint32_t(b);
  }
  // (Host backends only; KOKKOS_INLINE_FUNCTION for nvcc: the passes' functors
  // that call it are compiled for both.)
  KOKKOS_INLINE_FUNCTION std::int64_t index(std::int64_t i, std::int64_t j, std::int64_t k) {
    const BandView<MemSpace>& v = *band;
    if (i < 0 || j < 0 || k < 0 || i >= v.dims[0] || j >= v.dims[1] || k >= v.dims[2]) return -1;
    const std::int64_t ox = (i >> 3) - bx + 1, oy = (j >> 3) - by + 1, oz = (k >> 3) - bz + 1;
    std::uint32_t b;
    if (std::uint64_t(ox) < 3 && std::uint64_t(oy) < 3 && std::uint64_t(oz) < 3) {
      std::uint32_t& q = nb[ox + 3 * oy + 9 * oz];
      if (q == kUnknown) q = v.blocks.find(morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3)));
      b = q;
    } else {
      b = v.blocks.find(morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3)));
    }
    if (b == ~0u) return -1;
    return v.index_in_block(b, i, j, k);
  }
  // BandView::cell_indices(i, j, k, 1, idx) (idx[0] is the caller's).
  KOKKOS_INLINE_FUNCTION bool cell_indices(std::int64_t i, std::int64_t j, std::int64_t k, std::int64_t idx[8]) {
    for (int c = 1; c < 8; ++c) {
      idx[c] = index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
      if (idx[c] < 0) return false;
    }
    return true;
  }
};

// Host backends: f(near, w, bit, self) for every band vertex, one work item
// per block (dynamic schedule), near: the block's NearBlocks.
template <class ExecSpace, class F>
void for_each_band_vertex_by_block_host(const ExecSpace& space, const char* label,
                                        const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                                        const F& f) {
  using MemSpace = typename ExecSpace::memory_space;
  Kokkos::parallel_for(
      label, Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n_words / 8),
      [=](const std::size_t b) {
        NearBlocks<MemSpace> near(band, b);
        for (std::size_t w = 8 * b; w < 8 * b + 8; ++w)
          band.for_each_vertex(w, [&](const int bit, const std::int64_t self) { f(near, w, bit, self); });
      });
}

// Host backends: an exact filter for the whole-band cell passes (round-0 leak
// detection, pass A). Most band vertices are the minimum corner of no
// triangulated cell (a corner outside the band, or eight corners of one
// sign), yet each paid the corner lookups (up to 7 popcounts and phi reads).
// inside_masks: per band word, bit set where the vertex has phi < 0 (same
// test as the case index). for_each_mixed_cell_host then works per block:
// it looks up the 7 neighbouring blocks once and, per word, ANDs the eight
// corner-shifted copies of the band and sign masks (bit operations on the
// 4x4x4 sub-blocks and their neighbours), and calls f(w, bit, self, complete) only for
// the vertices whose cell has all corners in the band and mixed signs, in
// band order within each word. The mask can only say "in the band" for a
// corner that index() might still reject (grid box), never the reverse, so
// f (which does the full test) sees every cell that matters: same results.
// complete: the word's cells whose eight corners have their band bits set.
// cw: the words of the cell's corners (corners_from_words).
// GPU backends use the same filter with one thread per word (pass A here,
// the round-0 leak detection in band_growth.hpp).
template <class ExecSpace>
Buffer<std::uint64_t, typename ExecSpace::memory_space> inside_masks(
    const ExecSpace& space, MemoryTracker& tracker, const BandView<typename ExecSpace::memory_space>& band,
    std::size_t n_words, const Kokkos::View<const float*, typename ExecSpace::memory_space>& phi) {
  using MemSpace = typename ExecSpace::memory_space;
  Buffer<std::uint64_t, MemSpace> masks(tracker, "marching_cubes::inside", n_words);
  const Kokkos::View<std::uint64_t*, MemSpace> m = masks.view();
  Kokkos::parallel_for(
      "nbmc::marching_cubes::inside", Kokkos::RangePolicy<ExecSpace>(space, 0, n_words),
      KOKKOS_LAMBDA(const std::size_t w) {
        std::uint64_t s = 0;
        band.for_each_vertex(w, [&](const int bit, const std::int64_t idx) {
          if (phi(idx) < 0.f) s |= std::uint64_t(1) << bit;
        });
        m(w) = s;
      });
  return masks;
}

// Bit b = x + 4 y + 16 z of a 4x4x4 word: the vertex one step along +x/+y/+z
// (from the word n beyond the sub-block's face where x/y/z is 3).
KOKKOS_FORCEINLINE_FUNCTION std::uint64_t shift_px(std::uint64_t w, std::uint64_t n) {
  constexpr std::uint64_t kX3 = 0x8888888888888888ull;
  return ((w >> 1) & ~kX3) | ((n << 3) & kX3);
}
KOKKOS_FORCEINLINE_FUNCTION std::uint64_t shift_py(std::uint64_t w, std::uint64_t n) {
  constexpr std::uint64_t kY3 = 0xF000F000F000F000ull;
  return ((w >> 4) & ~kY3) | ((n << 12) & kY3);
}
KOKKOS_FORCEINLINE_FUNCTION std::uint64_t shift_pz(std::uint64_t w, std::uint64_t n) { return (w >> 16) | (n << 48); }
// Bit set where all 8 corners of the cell (minimum corner at that bit) are
// set, from the masks of the word (q[0]) and its neighbours q[d] (d = dx |
// dy << 1 | dz << 2, as the corner numbering).
KOKKOS_FORCEINLINE_FUNCTION std::uint64_t all_corners(const std::uint64_t q[8]) {
  std::uint64_t px[4];
  for (int yz = 0; yz < 4; ++yz) px[yz] = q[2 * yz] & shift_px(q[2 * yz], q[2 * yz + 1]);
  const std::uint64_t py0 = px[0] & shift_py(px[0], px[1]), py1 = px[2] & shift_py(px[2], px[3]);
  return py0 & shift_pz(py0, py1);
}

// Band indices of the 8 corners of a cell that for_each_mixed_cell_host
// passes (bit `bit` of its word, all corners' band bits set), from its
// words cw[d] (d = dx | dy << 1 | dz << 2: the word one step along the axes
// set in d): corner c's word is cw of the axes where it crosses the word's
// face. The values index_in_block gives (same word, same bit), without
// looking blocks up in the hash map, as cell_corners does for a cell that
// crosses a block face. The caller checks the grid box (cell_corners's
// i + 1 < dims[0], ...), which the band bits do not.
template <class MemSpace>
KOKKOS_FORCEINLINE_FUNCTION void corners_from_words(const BandView<MemSpace>& band, const std::size_t cw[8], int bit,
                                                    std::int64_t idx[8]) {
  const int x = bit & 3, y = (bit >> 2) & 3, z = bit >> 4;
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = c >> 2;
    const int d = (dx & int(x == 3)) | ((dy & int(y == 3)) << 1) | ((dz & int(z == 3)) << 2);
    const int nbit = ((x + dx) & 3) | (((y + dy) & 3) << 2) | (((z + dz) & 3) << 4);
    const std::size_t nw = cw[d];
    idx[c] = std::int64_t(band.word_offset(nw)) + popcount64(band.words(nw) & ((std::uint64_t(1) << nbit) - 1));
  }
}
// Whether cell (i, j, k)'s far corner lies in the grid (cell_corners's test).
template <class MemSpace>
KOKKOS_FORCEINLINE_FUNCTION bool cell_in_grid(const BandView<MemSpace>& band, std::int64_t i, std::int64_t j,
                                              std::int64_t k) {
  return i + 1 < band.dims[0] && j + 1 < band.dims[1] && k + 1 < band.dims[2];
}

// The blocks that the corner words of word s (0..7) of block b lie in:
// nb[o] for the block o = dx | dy << 1 | dz << 2 steps beyond b, looked up
// for the nonzero o within s (a step beyond the block only where the word
// lies at its upper face; s = 7: all seven), ~0u where that block is not in
// the band; nb[0] = b. The others are left as they are.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION void corner_blocks(const BandView<MemSpace>& band, std::size_t b, int s, std::uint32_t nb[8]) {
  nb[0] = std::uint32_t(b);
  if (!s) return;
  const std::uint64_t key = band.block_keys(b);
  const std::uint32_t bx = std::uint32_t(compact3(key)), by = std::uint32_t(compact3(key >> 1)),
                      bz = std::uint32_t(compact3(key >> 2));
  for (int o = 1; o < 8; ++o)
    if (!(o & ~s))
      nb[o] = band.blocks.find(
          morton3(bx + std::uint32_t(o & 1), by + std::uint32_t((o >> 1) & 1), bz + std::uint32_t(o >> 2)));
}

// The corner words of word s of a block with corner blocks nb
// (corner_blocks): cw[d] is the word one step along the axes set in d (d =
// dx | dy << 1 | dz << 2), ~0 where its block is not in the band.
KOKKOS_INLINE_FUNCTION void corner_words(const std::uint32_t nb[8], int s, std::size_t cw[8]) {
  for (int d = 0; d < 8; ++d) {
    const int o = s & d, t = s ^ d;  // block offset (carry), word in that block
    cw[d] = nb[o] == ~0u ? ~std::size_t(0) : std::size_t(nb[o]) * 8 + std::size_t(t);
  }
}

// The cells of word w = 8 b + s whose eight corners have their band bits
// set and mixed signs (bits of the word), from the band and sign masks of
// the word and its corner words (in the blocks nb of corner_blocks), ANDed
// in their eight corner-shifted copies. complete: the word's cells with all
// corners' band bits set; cw: the corner words (corners_from_words).
template <class MemSpace>
KOKKOS_INLINE_FUNCTION std::uint64_t mixed_cells(const BandView<MemSpace>& band,
                                                 const Kokkos::View<const std::uint64_t*, MemSpace>& inside,
                                                 const std::uint32_t nb[8], int s, std::uint64_t& complete,
                                                 std::size_t cw[8]) {
  std::uint64_t qb[8], qi[8], qo[8];
  corner_words(nb, s, cw);
  for (int d = 0; d < 8; ++d) {
    if (cw[d] == ~std::size_t(0)) {
      qb[d] = qi[d] = qo[d] = 0;
      continue;
    }
    qb[d] = band.words(cw[d]);
    qi[d] = inside(cw[d]);
    qo[d] = qb[d] & ~qi[d];
  }
  complete = all_corners(qb);
  if (!complete) return 0;
  return complete & ~all_corners(qi) & ~all_corners(qo);
}

template <class ExecSpace, class F>
void for_each_mixed_cell_host(const ExecSpace& space, const char* label,
                              const BandView<typename ExecSpace::memory_space>& band, std::size_t n_words,
                              const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space>& inside,
                              const F& f) {
  Kokkos::parallel_for(
      label, Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n_words / 8),
      // A host lambda (host backends only): f may be one too, and nvcc
      // refuses a host lambda's type inside a KOKKOS_LAMBDA.
      [=](const std::size_t b) {
        std::uint32_t nb[8];
        nb[0] = std::uint32_t(b);
        bool looked = false;
        for (int s = 0; s < 8; ++s) {
          const std::size_t w = b * 8 + std::size_t(s);
          const std::uint64_t word = band.words(w);
          if (!word) continue;
          if (!looked && s) {  // word 0 needs no neighbouring block
            corner_blocks(band, b, 7, nb);
            looked = true;
          }
          std::uint64_t complete;
          std::size_t cw[8];  // the words themselves (CellWords)
          std::uint64_t cand = mixed_cells(band, inside, nb, s, complete, cw);
          const std::int64_t base = std::int64_t(band.word_offset(w));
          while (cand) {
            const int bit = ctz64(cand);
            cand &= cand - 1;
            f(w, bit, base + std::int64_t(popcount64(word & ((std::uint64_t(1) << bit) - 1))), complete, cw);
          }
        }
      });
}

struct McResult {
  std::uint64_t vertices = 0, triangles = 0, cells = 0;
};

// Runs passes A and B; returns the counts. `info` (zeroed, one per band
// vertex): bits 0-7 the cell case (only for triangulated cells), bits 8-10 the
// crossed edges owned by the vertex. `vert_offset`: first mesh vertex of each
// band vertex. `tri_offset` (zeroed, one per band vertex): first triangle of
// the vertex's cell. The mesh order (vertices and triangles by band vertex) does
// not depend on the thread count or the backend.
template <class ExecSpace>
McResult classify_cells(const ExecSpace& space, MemoryTracker& tracker,
                        const BandView<typename ExecSpace::memory_space>& band,
                        std::size_t n_words, const Kokkos::View<const float*, typename ExecSpace::memory_space>& phi,
                        const McTables<typename ExecSpace::memory_space>& tables,
                        const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& info,
                        const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& vert_offset,
                        const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& tri_offset) {
  ScopedRegion region("nbmc::marching_cubes::classify");
  McResult r;
  const std::size_t nb = info.extent(0);
  // tri_offset (zeroed by the caller: a memset on the GPU, where Kokkos'
  // fill took 66 µs for the 1.65 M frame's band) first holds each vertex's
  // triangle count (0 where no cell).
  // The case of the cell with corners idx (idx[0] = self), its crossed edges.
  const auto classify = KOKKOS_LAMBDA(const std::int64_t self, const std::int64_t idx[8]) {
        int cs = 0;
        for (int c = 0; c < 8; ++c) cs |= (phi(idx[c]) < 0.f ? 1 : 0) << c;
        if (cs == 0 || cs == 255) return;
        Kokkos::atomic_fetch_or(&info(self), std::uint32_t(cs));
        const std::uint16_t em = tables.edges(cs);
        for (int e = 0; e < 12; ++e)
          if (em & (1u << e)) Kokkos::atomic_fetch_or(&info(idx[edge_start(e)]), std::uint32_t(1) << (8 + e / 4));
        tri_offset(self) = std::uint32_t(tables.count(cs));
      };
  if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, typename ExecSpace::memory_space>::accessible)
    for_each_mixed_cell_host(
        space, "nbmc::marching_cubes::cases", band, n_words, inside_masks(space, tracker, band, n_words, phi).view(),
        [=](const std::size_t w, const int bit, const std::int64_t self, std::uint64_t, const std::size_t cw[8]) {
          std::int64_t i, j, k, idx[8];
          band.vertex(w, bit, i, j, k);
          if (!band.owns_cell(i, j, k) || !cell_in_grid(band, i, j, k)) return;
          corners_from_words(band, cw, bit, idx);  // cell_corners's values, without block lookups
          classify(self, idx);
        });
  else {
    // The same filter, one thread per word (instead of one per vertex slot,
    // each looking up its cell's corners).
    const auto in_view = inside_masks(space, tracker, band, n_words, phi);
    const Kokkos::View<const std::uint64_t*, typename ExecSpace::memory_space> inside = in_view.view();
    Kokkos::parallel_for(
        "nbmc::marching_cubes::cases", Kokkos::RangePolicy<ExecSpace>(space, 0, n_words),
        KOKKOS_LAMBDA(const std::size_t w) {
          const std::uint64_t word = band.words(w);
          if (!word) return;
          std::uint32_t nb[8];
          corner_blocks(band, w >> 3, int(w & 7), nb);
          std::uint64_t complete;
          std::size_t cw[8];
          std::uint64_t cand = mixed_cells(band, inside, nb, int(w & 7), complete, cw);
          const std::int64_t base = std::int64_t(band.word_offset(w));
          while (cand) {
            const int bit = ctz64(cand);
            cand &= cand - 1;
            std::int64_t i, j, k, idx[8];
            band.vertex(w, bit, i, j, k);
            if (!band.owns_cell(i, j, k) || !cell_in_grid(band, i, j, k)) continue;
            corners_from_words(band, cw, bit, idx);
            classify(base + std::int64_t(popcount64(word & ((std::uint64_t(1) << bit) - 1))), idx);
          }
        });
  }
  space.fence();
  std::uint64_t cells = 0;
  Kokkos::parallel_reduce(
      "nbmc::marching_cubes::count_cells", Kokkos::RangePolicy<ExecSpace>(space, 0, nb),
      KOKKOS_LAMBDA(const std::size_t v, std::uint64_t& acc) { acc += tri_offset(v) ? 1 : 0; }, cells);
  r.cells = cells;
  const std::uint64_t nverts =
      prefix_counts(space, tracker, "nbmc::marching_cubes::number_vertices", nb, vert_offset,
                    KOKKOS_LAMBDA(const std::size_t v) { return std::uint32_t(popcount64((info(v) >> 8) & 7u)); });
  r.vertices = nverts;
  r.triangles = exclusive_scan(space, tracker, "nbmc::marching_cubes::number_triangles", tri_offset, tri_offset);
  return r;
}

// Leaks of the cell with minimum corner (i, j, k) (band index self): the
// minimum corners of the neighbour cells across its mixed faces that are not
// entirely in the band (at most 6 cells, written to out); 0 if the cell is
// not triangulated. Face f: axis a = f / 2, side = f % 2 (0: at the minimum).
// The host scan (for_each_mixed_cell_host) passes the cell's bit in its word,
// its corner words (cw: corners_from_words) and the word's `complete` mask: a face neighbour whose minimum corner lies
// in the same word is then known to be entirely in the band when its bit of
// `complete` is set (its corners' band bits are set, and the grid check
// below holds), without the 8 look-ups (bit < 0: always the look-ups).
// word_complete (the GPU's scan: the complete masks of all words, at
// word_complete[2 w]) extends that to a neighbour whose minimum corner lies
// in the next or the previous word along the face's axis.
template <class MemSpace>
KOKKOS_INLINE_FUNCTION int leaks_at(const BandView<MemSpace>& band, const Kokkos::View<const float*, MemSpace>& phi,
                                    std::int64_t i, std::int64_t j, std::int64_t k, std::int64_t self,
                                    std::int64_t out[18], std::uint32_t block = ~0u, int bit = -1,
                                    std::uint64_t complete = 0, const std::size_t* cw = nullptr,
                                    const std::uint64_t* word_complete = nullptr) {
  std::int64_t idx[8];
  if (!band.owns_cell(i, j, k)) return 0;
  if (cw) {  // the host scan's complete cell: its corners from its words
    if (!cell_in_grid(band, i, j, k)) return 0;
    corners_from_words(band, cw, bit, idx);
  } else if (!cell_corners(band, i, j, k, self, idx, block)) {
    return 0;
  }
  int cs = 0;
  for (int c = 0; c < 8; ++c) cs |= (phi(idx[c]) < 0.f ? 1 : 0) << c;
  if (cs == 0 || cs == 255) return 0;
  int n = 0;
  for (int f = 0; f < 6; ++f) {
    const int a = f >> 1, side = f & 1;
    int inside = 0;
    for (int c = 0; c < 8; ++c)
      if (((c >> a) & 1) == side) inside += (cs >> c) & 1;
    if (inside == 0 || inside == 4) continue;
    const std::int64_t ni = i + (a == 0 ? (side ? 1 : -1) : 0), nj = j + (a == 1 ? (side ? 1 : -1) : 0),
                       nk = k + (a == 2 ? (side ? 1 : -1) : 0);
    if (ni < 0 || nj < 0 || nk < 0 || ni + 1 >= band.dims[0] || nj + 1 >= band.dims[1] || nk + 1 >= band.dims[2])
      continue;  // the grid's own boundary (padded: only reached with a clipping box)
    if (bit >= 0) {
      const int nl = ((bit >> (2 * a)) & 3) + (side ? 1 : -1);
      if (nl >= 0 && nl < 4 && ((complete >> (bit + (side ? 1 : -1) * (1 << (2 * a)))) & 1)) continue;
      if ((nl < 0 || nl > 3) && word_complete) {
        // The neighbour's minimum corner in the next word along a (a
        // corner word), or in the previous one (in this block, or in the
        // block before it along a, looked up), at the other end of the axis.
        std::size_t nw = ~std::size_t(0);
        const std::size_t w = cw[0];
        const int s = int(w & 7);
        if (side) {
          nw = cw[1 << a];
        } else if ((s >> a) & 1) {
          nw = w - (std::size_t(1) << a);
        } else {
          const std::uint64_t key = band.block_keys(w >> 3);
          std::uint32_t bc[3] = {std::uint32_t(compact3(key)), std::uint32_t(compact3(key >> 1)),
                                 std::uint32_t(compact3(key >> 2))};
          if (bc[a] > 0) {
            bc[a] -= 1;
            const std::uint32_t nb = band.blocks.find(morton3(bc[0], bc[1], bc[2]));
            if (nb != ~0u) nw = std::size_t(nb) * 8 + std::size_t(s | (1 << a));
          }
        }
        const int nbit = (bit & ~(3 << (2 * a))) | ((nl & 3) << (2 * a));
        if (nw != ~std::size_t(0) && ((word_complete[2 * nw] >> nbit) & 1)) continue;
      }
    }
    std::int64_t nidx[8];
    if (band.cell_indices(ni, nj, nk, 0, nidx)) continue;  // entirely in the band
    out[3 * n] = ni;
    out[3 * n + 1] = nj;
    out[3 * n + 2] = nk;
    ++n;
  }
  return n;
}


// Band leaks: cells that are triangulated (all corners in the band, mixed
// signs) and have a face with mixed signs whose neighbour cell across it is
// not entirely in the band. The surface continues into that neighbour, so
// without it the mesh would have a hole there. Returns the minimum corners
// of those neighbour cells (x, y, z triples, host memory, sorted).
// Sorts cell triples (minimum corners, x y z) by z, then y, then x, so that
// lists filled in parallel come out in one order; with `unique`, drops repeats.
// Cell triples as packed keys z << 42 | y << 21 | x (coordinates in
// [0, 2^21), as kMaxAxisCells guarantees): ordered by z, then y, then x.
// (Device code too: the band growth's candidate set, band_growth.hpp.)
KOKKOS_INLINE_FUNCTION std::uint64_t pack_cell(std::int64_t i, std::int64_t j, std::int64_t k) {
  return std::uint64_t(k) << 42 | std::uint64_t(j) << 21 | std::uint64_t(i);
}
// Writes packed keys back as triples (cells resized to 3 per key).
inline void unpack_cells(const std::vector<std::uint64_t>& keys, std::vector<std::int64_t>& cells) {
  constexpr std::uint64_t kMask = (std::uint64_t(1) << 21) - 1;
  cells.resize(3 * keys.size());
  for (std::size_t q = 0; q < keys.size(); ++q) {
    cells[3 * q] = std::int64_t(keys[q] & kMask);
    cells[3 * q + 1] = std::int64_t((keys[q] >> 21) & kMask);
    cells[3 * q + 2] = std::int64_t(keys[q] >> 42);
  }
}

inline void sort_cells(std::vector<std::int64_t>& cells, bool unique) {
  // Grid coordinates fit 21 bits (kMaxAxisCells): sorted as packed keys
  // z << 42 | y << 21 | x, the same order, a few times faster.
  constexpr std::int64_t kLimit = std::int64_t(1) << 21;
  if (std::all_of(cells.begin(), cells.end(), [](std::int64_t v) { return v >= 0 && v < kLimit; })) {
    std::vector<std::uint64_t> keys(cells.size() / 3);
    for (std::size_t q = 0; q < keys.size(); ++q)
      keys[q] = pack_cell(cells[3 * q], cells[3 * q + 1], cells[3 * q + 2]);
    std::sort(keys.begin(), keys.end());
    if (unique) keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    unpack_cells(keys, cells);
    return;
  }
  std::vector<std::array<std::int64_t, 3>> t(cells.size() / 3);
  for (std::size_t q = 0; q < t.size(); ++q) t[q] = {cells[3 * q + 2], cells[3 * q + 1], cells[3 * q]};
  std::sort(t.begin(), t.end());
  if (unique) t.erase(std::unique(t.begin(), t.end()), t.end());
  cells.resize(3 * t.size());
  for (std::size_t q = 0; q < t.size(); ++q) {
    cells[3 * q] = t[q][2];
    cells[3 * q + 1] = t[q][1];
    cells[3 * q + 2] = t[q][0];
  }
}

// The first `count` triples of a device list, on the host, sorted.
template <class View>
std::vector<std::int64_t> cells_to_host(const View& list, std::size_t count) {
  auto h = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(),
                                               Kokkos::subview(list, std::make_pair(std::size_t(0), 3 * count)));
  std::vector<std::int64_t> cells(h.data(), h.data() + h.extent(0));
  sort_cells(cells, false);
  return cells;
}

template <class ExecSpace>
std::vector<std::int64_t> find_band_leaks(const ExecSpace& space, const BandView<typename ExecSpace::memory_space>& band,
                                          std::size_t n_words,
                                          const Kokkos::View<const float*, typename ExecSpace::memory_space>& phi) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::marching_cubes::band_leaks");
  // One pass that appends the leaks through a 32-bit cursor (a native
  // atomic; the 64-bit one is emulated with compare-and-swap in Kokkos 3.4
  // and was 10x slower under contention on an H100). If the guessed capacity
  // is too small, a second pass with the exact count follows. The list is
  // sorted on the host, so the order of the appends does not matter.
  std::size_t capacity = 1024 + n_words / 16;
  for (int attempt = 0; attempt < 2; ++attempt) {
    Kokkos::View<std::int64_t*, MemSpace> list(Kokkos::view_alloc(Kokkos::WithoutInitializing, "nbmc::marching_cubes::leaks"),
                                               3 * capacity);
    Kokkos::View<unsigned int, MemSpace> cursor("nbmc::marching_cubes::leak_cursor");
    const std::size_t cap = capacity;
    for_each_band_vertex(
        space, "nbmc::marching_cubes::collect_leaks", band, n_words,
        KOKKOS_LAMBDA(const std::size_t w, const int bit, const std::int64_t self) {
          std::int64_t i, j, k, out[18];
          band.vertex(w, bit, i, j, k);
          const int n = leaks_at(band, phi, i, j, k, self, out, std::uint32_t(w >> 3));
          if (!n) return;
          const std::size_t at = Kokkos::atomic_fetch_add(&cursor(), unsigned(n));
          for (int q = 0; q < n; ++q)
            if (at + q < cap)
              for (int a = 0; a < 3; ++a) list(3 * (at + q) + a) = out[3 * q + a];
        });
    space.fence();
    unsigned int count = 0;
    Kokkos::deep_copy(count, cursor);
    if (count <= capacity) return count ? cells_to_host(list, count) : std::vector<std::int64_t>();
    capacity = count;
  }
  throw Error(9, "band leaks: the leak count changed between two identical passes");
}

// Pass C: intersection points (absolute; Real: float, or double for
// nbmc_params.double_positions) and normals. The point is computed in double
// either way; only the store rounds it. One band vertex's edges; band
// indices from look (the BandView, or on the host its block's NearBlocks).
template <class MemSpace, class Real>
struct VertexPass {
  BandView<MemSpace> band;
  Kokkos::View<const float*, MemSpace> phi;
  Kokkos::View<const std::uint32_t*, MemSpace> info, vert_offset;
  Kokkos::View<Real*, MemSpace> positions;
  Kokkos::View<float*, MemSpace> normals;
  Kokkos::View<std::uint64_t*, MemSpace> keys;
  Kokkos::View<std::uint8_t*, MemSpace> axes;
  bool with_normals, with_keys;
  double o0, o1, o2, c;
  float inv_c;

  template <class Look>
  KOKKOS_INLINE_FUNCTION void operator()(Look& look, const std::size_t w, const int bit,
                                         const std::int64_t self) const {
    const std::uint32_t edges = (info(self) >> 8) & 7u;
    if (!edges) return;
    std::int64_t i, j, k;
    band.vertex(w, bit, i, j, k);
    std::uint32_t out = vert_offset(self);
    // The gradient at this vertex, the same for each of its edges: computed
    // for the first one only (the same values as computing it per edge).
    float g0[3];
    bool have_g0 = false;
    for (int a = 0; a < 3; ++a) {
      if (!(edges & (1u << a))) continue;
      const std::int64_t di = a == 0, dj = a == 1, dk = a == 2;
      const std::int64_t other = look.index(i + di, j + dj, k + dk);
      const float f0 = phi(self), f1 = phi(other);
      float t = f0 / (f0 - f1);
      t = t < 0.f ? 0.f : (t > 1.f ? 1.f : t);
      positions(3 * out) = Real(o0 + (double(i) + double(t) * double(di)) * c);
      positions(3 * out + 1) = Real(o1 + (double(j) + double(t) * double(dj)) * c);
      positions(3 * out + 2) = Real(o2 + (double(k) + double(t) * double(dk)) * c);
      if (with_keys) {
        keys(out) = band_order_key(i, j, k);
        axes(out) = std::uint8_t(a);
      }
      if (with_normals) {
        if (!have_g0) {
          for (int b = 0; b < 3; ++b) g0[b] = gradient_component(look, phi, i, j, k, self, b, inv_c);
          have_g0 = true;
        }
        float n[3];
        for (int b = 0; b < 3; ++b) {
          const float g1 = gradient_component(look, phi, i + di, j + dj, k + dk, other, b, inv_c);
          n[b] = (1.f - t) * g0[b] + t * g1;
        }
        float len2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
        if (!(len2 > 1e-30f)) {  // flat field: the edge direction, inside -> outside
          n[0] = n[1] = n[2] = 0.f;
          n[a] = f1 > f0 ? 1.f : -1.f;
          len2 = 1.f;
        }
        const float inv = 1.f / Kokkos::Experimental::sqrt(len2);
        normals(3 * out) = n[0] * inv;
        normals(3 * out + 1) = n[1] * inv;
        normals(3 * out + 2) = n[2] * inv;
      }
      ++out;
    }
  }
};

template <class ExecSpace, class Real>
void compute_vertices(const ExecSpace& space, const BandView<typename ExecSpace::memory_space>& band,
                      std::size_t n_words, const Grid& g,
                      const Kokkos::View<const float*, typename ExecSpace::memory_space>& phi,
                      const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& info,
                      const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& vert_offset,
                      const Kokkos::View<Real*, typename ExecSpace::memory_space>& positions,
                      const Kokkos::View<float*, typename ExecSpace::memory_space>& normals, bool with_normals,
                      const Kokkos::View<std::uint64_t*, typename ExecSpace::memory_space>& keys = {},
                      const Kokkos::View<std::uint8_t*, typename ExecSpace::memory_space>& axes = {}) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::marching_cubes::vertices");
  VertexPass<MemSpace, Real> pass;
  pass.band = band;
  pass.phi = phi;
  pass.info = info;
  pass.vert_offset = vert_offset;
  pass.positions = positions;
  pass.normals = normals;
  pass.keys = keys;
  pass.axes = axes;
  pass.with_normals = with_normals;
  pass.with_keys = keys.extent(0) > 0;  // a subdomain's piece: where each vertex goes in the frame
  pass.o0 = g.origin[0];
  pass.o1 = g.origin[1];
  pass.o2 = g.origin[2];
  pass.c = g.cell;
  pass.inv_c = float(1.0 / g.cell);
  if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible)
    for_each_band_vertex_by_block_host(
        space, "nbmc::marching_cubes::vertices", band, n_words,
        [=](NearBlocks<MemSpace>& near, const std::size_t w, const int bit, const std::int64_t self) {
          pass(near, w, bit, self);
        });
  else
    for_each_band_vertex(
        space, "nbmc::marching_cubes::vertices", band, n_words,
        KOKKOS_LAMBDA(const std::size_t w, const int bit, const std::int64_t self) {
          pass(pass.band, w, bit, self);
        });
  space.fence();
}

// Pass D: triangles (vertex indices), counter-clockwise seen from outside.
template <class ExecSpace>
void compute_triangles(const ExecSpace& space, const BandView<typename ExecSpace::memory_space>& band,
                       std::size_t n_words, const McTables<typename ExecSpace::memory_space>& tables,
                       const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& info,
                       const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& vert_offset,
                       const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& tri_offset,
                       const Kokkos::View<std::uint32_t*, typename ExecSpace::memory_space>& triangles,
                       const Kokkos::View<std::uint64_t*, typename ExecSpace::memory_space>& cell_keys = {}) {
  ScopedRegion region("nbmc::marching_cubes::triangles");
  const bool with_keys = cell_keys.extent(0) > 0;  // per triangle: its cell's place in the frame
  constexpr int W = 3 * mc::kMaxTriangles;
  // The cell's triangles, from its corners' band indices (idx).
  const auto emit = KOKKOS_LAMBDA(const std::int64_t i, const std::int64_t j, const std::int64_t k,
                                  const std::int64_t self, const int cs, const std::int64_t idx[8]) {
        const std::uint64_t out = tri_offset(self);
        const int nt = tables.count(cs);
        for (int t = 0; t < 3 * nt; ++t) {
          const int e = tables.triangles(cs * W + t);
          const int axis = e >> 2;
          const std::int64_t owner = idx[edge_start(e)];
          const std::uint32_t below = (info(owner) >> 8) & ((1u << axis) - 1u);
          triangles(3 * out + t) = vert_offset(owner) + std::uint32_t(popcount64(below));
        }
        if (with_keys)
          for (int t = 0; t < nt; ++t) cell_keys(out + std::uint64_t(t)) = band_order_key(i, j, k);
      };
  if constexpr (Kokkos::SpaceAccessibility<Kokkos::HostSpace, typename ExecSpace::memory_space>::accessible) {
    // Cells inside the block find their corners there; those crossing its
    // faces in the block's neighbours (NearBlocks), not in the hash map.
    for_each_band_vertex_by_block_host(
        space, "nbmc::marching_cubes::triangles", band, n_words,
        [=](NearBlocks<typename ExecSpace::memory_space>& near, const std::size_t w, const int bit,
            const std::int64_t self) {
          const int cs = int(info(self) & 0xffu);
          if (!cs) return;
          std::int64_t i, j, k, idx[8];
          band.vertex(w, bit, i, j, k);
          idx[0] = self;
          if ((i & 7) != 7 && (j & 7) != 7 && (k & 7) != 7)
            cell_corners(band, i, j, k, self, idx, std::uint32_t(w >> 3));
          else
            near.cell_indices(i, j, k, idx);
          emit(i, j, k, self, cs, idx);
        });
  } else {
    for_each_band_vertex(
        space, "nbmc::marching_cubes::triangles", band, n_words,
        KOKKOS_LAMBDA(const std::size_t w, const int bit, const std::int64_t self) {
          const int cs = int(info(self) & 0xffu);
          if (!cs) return;
          std::int64_t i, j, k, idx[8];
          band.vertex(w, bit, i, j, k);
          cell_corners(band, i, j, k, self, idx, std::uint32_t(w >> 3));
          emit(i, j, k, self, cs, idx);
        });
  }
  space.fence();
}

}  // namespace Details
}  // namespace nbmc
