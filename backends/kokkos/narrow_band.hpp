// SPDX-License-Identifier: MIT
// Narrow band (paper Sec. 4.1, "extracting surface vertices"): every grid vertex
// inside the +-band_width box of a surface particle. Stored block-sparse: blocks
// of 8x8x8 vertices exist only where the band is (hash map from the block's
// Morton key), each a 512-bit mask in eight 64-bit words (one word = a 4x4x4
// sub-block). A band vertex's index is the prefix count of set bits, so field
// values and everything after are stored compactly, one entry per band vertex,
// in a deterministic order (block key, word, bit). No per-vertex or per-cell
// array of the bounding box exists anywhere.
#pragma once

#include "common.hpp"
#include "grid.hpp"

#include <algorithm>
#include <iterator>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <type_traits>
#include <vector>
#if defined(_OPENMP)
#include <parallel/algorithm>
#endif

namespace nbmc {
namespace Details {

template <class MemSpace>
struct Band {
  std::size_t n_blocks = 0;
  std::uint64_t n_vertices = 0;
  // A subdomain's limits (whole grid otherwise): the band stays inside the
  // vertex box [clip_lo, clip_hi]; only cells in [own_lo, own_hi) (minimum
  // corners) are triangulated or scanned for leaks.
  std::int64_t clip_lo[3] = {0, 0, 0}, clip_hi[3] = {kNoLimit, kNoLimit, kNoLimit};
  std::int64_t own_lo[3] = {0, 0, 0}, own_hi[3] = {kNoLimit, kNoLimit, kNoLimit};
  static constexpr std::int64_t kNoLimit = std::int64_t(1) << 40;
  Buffer<std::uint64_t, MemSpace> block_keys;   // sorted Morton keys of the blocks
  HashMapStorage<MemSpace> blocks;              // key -> block index
  Buffer<std::uint64_t, MemSpace> words;        // 8 per block
  Buffer<std::uint64_t, MemSpace> word_offset;  // band index of each word's first vertex
};

template <class MemSpace>
struct BandView {
  Kokkos::View<const std::uint64_t*, MemSpace> block_keys, words, word_offset;
  HashMap<MemSpace> blocks;
  std::int64_t dims[3];
  std::int64_t own_lo[3], own_hi[3];

  // Whether this band's subdomain triangulates the cell with minimum corner (i, j, k).
  KOKKOS_INLINE_FUNCTION bool owns_cell(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i >= own_lo[0] && i < own_hi[0] && j >= own_lo[1] && j < own_hi[1] && k >= own_lo[2] && k < own_hi[2];
  }

  KOKKOS_INLINE_FUNCTION static int word_of(std::int64_t lx, std::int64_t ly, std::int64_t lz) {
    return int((lx >> 2) | ((ly >> 2) << 1) | ((lz >> 2) << 2));
  }
  KOKKOS_INLINE_FUNCTION static int bit_of(std::int64_t lx, std::int64_t ly, std::int64_t lz) {
    return int((lx & 3) | ((ly & 3) << 2) | ((lz & 3) << 4));
  }
  // Grid coordinates of bit `bit` of word `w` (global word index).
  KOKKOS_INLINE_FUNCTION void vertex(std::size_t w, int bit, std::int64_t& i, std::int64_t& j,
                                     std::int64_t& k) const {
    const std::uint64_t key = block_keys(w >> 3);
    const int sub = int(w & 7);
    i = std::int64_t(compact3(key)) * 8 + (sub & 1) * 4 + (bit & 3);
    j = std::int64_t(compact3(key >> 1)) * 8 + ((sub >> 1) & 1) * 4 + ((bit >> 2) & 3);
    k = std::int64_t(compact3(key >> 2)) * 8 + ((sub >> 2) & 1) * 4 + (bit >> 4);
  }
  // Calls f(bit, band_index) for every vertex of word w, in band order.
  template <class F>
  KOKKOS_INLINE_FUNCTION void for_each_vertex(std::size_t w, F&& f) const {
    std::uint64_t word = words(w);
    std::int64_t index = std::int64_t(word_offset(w));
    while (word) {
      const int bit = ctz64(word);
      word &= word - 1;
      f(bit, index);
      ++index;
    }
  }
  // Band index of grid vertex (i, j, k), or -1 when it is not in the band.
  KOKKOS_INLINE_FUNCTION std::int64_t index(std::int64_t i, std::int64_t j, std::int64_t k) const {
    if (i < 0 || j < 0 || k < 0 || i >= dims[0] || j >= dims[1] || k >= dims[2]) return -1;
    const std::uint32_t b =
        blocks.find(morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3)));
    if (b == ~0u) return -1;
    return index_in_block(b, i, j, k);
  }
  // The same for a vertex of block b (its index, already looked up).
  KOKKOS_FORCEINLINE_FUNCTION std::int64_t index_in_block(std::uint32_t b, std::int64_t i, std::int64_t j,
                                                     std::int64_t k) const {
    const std::size_t w = std::size_t(b) * 8 + word_of(i & 7, j & 7, k & 7);
    const int bit = bit_of(i & 7, j & 7, k & 7);
    const std::uint64_t word = words(w);
    if (!((word >> bit) & 1)) return -1;
    return std::int64_t(word_offset(w)) + popcount64(word & ((std::uint64_t(1) << bit) - 1));
  }
  // Band indices of the corners c = first..7 of the cell with minimum corner
  // (i, j, k) (corner c at i + (c & 1), j + (c >> 1 & 1), k + (c >> 2)); false
  // if one is not a band vertex. A cell inside one 8^3 block (7 of 8 per
  // axis) looks its block up once instead of once per corner, or not at all
  // when the caller knows it (`block`: the index of the block of (i, j, k)).
  KOKKOS_FORCEINLINE_FUNCTION bool cell_indices(std::int64_t i, std::int64_t j, std::int64_t k, int first,
                                                std::int64_t idx[8], std::uint32_t block = ~0u) const {
    if (i >= 0 && j >= 0 && k >= 0 && (i & 7) != 7 && (j & 7) != 7 && (k & 7) != 7 && i + 1 < dims[0] &&
        j + 1 < dims[1] && k + 1 < dims[2]) {
      const std::uint32_t b =
          block != ~0u ? block
                       : blocks.find(morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3)));
      if (b == ~0u) return false;
      for (int c = first; c < 8; ++c) {
        idx[c] = index_in_block(b, i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
        if (idx[c] < 0) return false;
      }
      return true;
    }
    for (int c = first; c < 8; ++c) {
      idx[c] = index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
      if (idx[c] < 0) return false;
    }
    return true;
  }
};

template <class MemSpace>
BandView<MemSpace> view_of(const Band<MemSpace>& b, const Grid& g) {
  BandView<MemSpace> v;
  v.block_keys = b.block_keys.view();
  v.words = b.words.view();
  v.word_offset = b.word_offset.view();
  v.blocks = b.blocks.map;
  for (int a = 0; a < 3; ++a) {
    v.dims[a] = g.dims[a];
    v.own_lo[a] = b.own_lo[a];
    v.own_hi[a] = b.own_hi[a];
  }
  return v;
}

// The largest band one run may hold. Kernels over band vertex slots (64 per
// word, 512 per 8x8x8 block) index with Kokkos's CUDA range type, 32-bit
// unsigned in Kokkos 3.4, and some of its scans count in int: a GPU run is
// limited to 2^31 slots, 4,194,304 blocks (about 1.5 G band vertices at real
// fill). Past it the kernels would wrap silently, so the run stops with
// NBMC_ERROR_DOMAIN_TOO_LARGE (split_helps: NBMC_SUBDOMAINS_AUTO splits).
// The host has no such limit. NBMC_MAX_BAND_BLOCKS (tests) sets a limit on
// every backend.
template <class MemSpace>
void check_band_blocks(std::size_t n_blocks) {
  constexpr bool host = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  std::uint64_t limit = host ? 0 : (std::uint64_t(1) << 31) / 512;
  if (const char* e = std::getenv("NBMC_MAX_BAND_BLOCKS")) limit = std::strtoull(e, nullptr, 10);
  if (!limit || n_blocks <= limit) return;
  char msg[512];
  std::snprintf(msg, sizeof msg,
                "the narrow band needs %llu blocks of 8x8x8 vertices (%.2f G vertex slots); one run on this backend "
                "handles at most %llu blocks: split the frame (--subdomains auto or NxMxK, "
                "nbmc_context_set_subdomains) or use a larger cell size",
                (unsigned long long)n_blocks, double(n_blocks) * 512 / 1e9, (unsigned long long)limit);
  throw Error(5 /*NBMC_ERROR_DOMAIN_TOO_LARGE*/, msg, true);
}

// Gives every block its index in the sorted key order.
template <class ExecSpace>
void number_blocks(const ExecSpace& space, Band<typename ExecSpace::memory_space>& band) {
  auto map = band.blocks.map;
  auto keys = band.block_keys.view();
  Kokkos::parallel_for(
      "nbmc::band::number_blocks", Kokkos::RangePolicy<ExecSpace>(space, 0, band.n_blocks),
      KOKKOS_LAMBDA(const std::size_t b) { map.values(map.find_slot(keys(b))) = std::uint32_t(b); });
  space.fence();
}

// Prefix counts of the words: the band index of every word's first vertex.
template <class ExecSpace>
void finish_band(const ExecSpace& space, MemoryTracker& tracker, Band<typename ExecSpace::memory_space>& band) {
  using MemSpace = typename ExecSpace::memory_space;
  band.word_offset = Buffer<std::uint64_t, MemSpace>(tracker, "band::word_offset", band.n_blocks * 8);
  auto words = band.words.view();
  band.n_vertices = prefix_counts(space, tracker, "nbmc::band::prefix", band.n_blocks * 8, band.word_offset.view(),
                                  KOKKOS_LAMBDA(const std::size_t w) { return popcount64(words(w)); });
}

// Sorted unique keys from a hash map's key array: the occupied slots
// numbered by prefix_counts and compacted, then sorted (GPU: a radix sort;
// host: a parallel sort on the host threads, where a serial pass and
// std::sort took 3-4 ms of the 1.65 M frame at r/2 on 16 threads:
// bench/RESULTS.md, sessions 25 and 26).
template <class ExecSpace>
void collect_sorted_keys(const ExecSpace& space, MemoryTracker& tracker,
                         Band<typename ExecSpace::memory_space>& band) {
  using MemSpace = typename ExecSpace::memory_space;
  using Range = Kokkos::RangePolicy<ExecSpace>;
  const auto slots = band.blocks.keys.view();
  const auto used = KOKKOS_LAMBDA(const std::size_t s) { return slots(s) != ~std::uint64_t(0) ? 1u : 0u; };
  Buffer<std::uint32_t, MemSpace> numbers(tracker, "band::slot_numbers", slots.extent(0));
  const auto no = numbers.view();
  const std::uint64_t n = prefix_counts(space, tracker, "nbmc::band::count_blocks", slots.extent(0), no, used);
  band.n_blocks = std::size_t(n);
  band.block_keys = Buffer<std::uint64_t, MemSpace>(tracker, "band::block_keys", band.n_blocks);
#if defined(KOKKOS_ENABLE_CUDA)
  if constexpr (std::is_same<ExecSpace, Kokkos::Cuda>::value) {
    Buffer<std::uint64_t, MemSpace> unsorted(tracker, "band::unsorted_block_keys", n);
    Buffer<std::uint32_t, MemSpace> va(tracker, "band::sort_values", n), vb(tracker, "band::sort_values", n);
    const auto uk = unsorted.view();
    const auto v = va.view();
    Kokkos::parallel_for(
        "nbmc::band::compact_blocks", Range(space, 0, slots.extent(0)), KOKKOS_LAMBDA(const std::size_t s) {
          if (!used(s)) return;
          uk(no(s)) = slots(s);
          v(no(s)) = no(s);
        });
    numbers.release();
    if (n) device_sort_pairs(space, tracker, unsorted.data(), band.block_keys.data(), va.data(), vb.data(), n, 63);
    space.fence();
    return;
  }
#endif
  const auto bk = band.block_keys.view();
  Kokkos::parallel_for(
      "nbmc::band::compact_blocks", Range(space, 0, slots.extent(0)), KOKKOS_LAMBDA(const std::size_t s) {
        if (used(s)) bk(no(s)) = slots(s);
      });
  space.fence();
  std::uint64_t* const k = band.block_keys.data();
#if defined(_OPENMP)
  if (std::is_same<ExecSpace, Kokkos::Serial>::value)
    std::sort(k, k + n);
  else
    __gnu_parallel::sort(k, k + n);
#else
  std::sort(k, k + n);
#endif
}

// Narrow band around the surface particles (flags(i) != 0, sorted order).
// With per-particle radii (scale: t_i, sorted order; empty without), particle
// i's box is band_width * t_i wide.
template <class ExecSpace>
void build_narrow_band(const ExecSpace& space, MemoryTracker& tracker, const Grid& g, const Params& p,
                       const Kokkos::View<const float*, typename ExecSpace::memory_space>& pos,
                       const Kokkos::View<const std::uint8_t*, typename ExecSpace::memory_space>& flags,
                       std::size_t n, Band<typename ExecSpace::memory_space>& band,
                       const Kokkos::View<const float*, typename ExecSpace::memory_space>& scale = {}) {
  using MemSpace = typename ExecSpace::memory_space;
  // Host-only steps below (a type, not a constexpr local, inside the kernels' lambdas for nvcc).
  using HostMemory = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>;
  ScopedRegion region("nbmc::narrow_band");
  const float inv_c = float(1.0 / g.cell);
  const float bw = float(p.band_width);
  const double bw_abs = p.band_width;
  const bool scaled = scale.extent(0) > 0;
  // The grid, or a subdomain's vertex box (band.clip_*, set by the caller).
  const std::int64_t d0 = std::min(g.dims[0] - 1, band.clip_hi[0]), d1 = std::min(g.dims[1] - 1, band.clip_hi[1]),
                     d2 = std::min(g.dims[2] - 1, band.clip_hi[2]);
  const std::int64_t m0 = band.clip_lo[0], m1 = band.clip_lo[1], m2 = band.clip_lo[2];

  // Vertex box of particle i, clamped to the grid; false if empty.
  auto box = KOKKOS_LAMBDA(std::size_t i, std::int64_t lo[3], std::int64_t hi[3])->bool {
    const std::int64_t dmax[3] = {d0, d1, d2}, dmin[3] = {m0, m1, m2};
    const float bwi = scaled ? float(bw_abs * double(scale(i))) : bw;
    for (int a = 0; a < 3; ++a) {
      const float x = pos(std::size_t(a) * n + i);
      lo[a] = std::int64_t(Kokkos::Experimental::ceil((x - bwi) * inv_c));
      hi[a] = std::int64_t(Kokkos::Experimental::floor((x + bwi) * inv_c));
      if (lo[a] < dmin[a]) lo[a] = dmin[a];
      if (hi[a] > dmax[a]) hi[a] = dmax[a];
      if (lo[a] > hi[a]) return false;
    }
    return true;
  };

  // 1. Upper bound of the number of blocks, to size the hash map.
  std::uint64_t bound = 0;
  Kokkos::parallel_reduce(
      "nbmc::band::count_blocks", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& acc) {
        std::int64_t lo[3], hi[3];
        if (!flags(i) || !box(i, lo, hi)) return;
        acc += std::uint64_t((hi[0] >> 3) - (lo[0] >> 3) + 1) * std::uint64_t((hi[1] >> 3) - (lo[1] >> 3) + 1) *
               std::uint64_t((hi[2] >> 3) - (lo[2] >> 3) + 1);
      },
      bound);
  const std::uint64_t grid_blocks = std::uint64_t(g.block_dims(0)) * g.block_dims(1) * g.block_dims(2);
  band.blocks.allocate(space, tracker, "band::block_map", std::size_t(std::min(bound, grid_blocks)));
  trace("band: bound, map", bound);

  // 2. Insert the blocks.
  auto map = band.blocks.map;
  std::size_t inserted = 0;
  Kokkos::parallel_reduce(
      "nbmc::band::insert_blocks", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t i, std::size_t& acc) {
        std::int64_t lo[3], hi[3];
        if (!flags(i) || !box(i, lo, hi)) return;
        for (std::int64_t bz = lo[2] >> 3; bz <= (hi[2] >> 3); ++bz)
          for (std::int64_t by = lo[1] >> 3; by <= (hi[1] >> 3); ++by)
            for (std::int64_t bx = lo[0] >> 3; bx <= (hi[0] >> 3); ++bx) {
              const std::uint64_t key = morton3(std::uint32_t(bx), std::uint32_t(by), std::uint32_t(bz));
              // Most keys are in already (HashMap::seen): neighbouring
              // surface particles' boxes overlap. A read skips the
              // compare-and-swap, which takes the slot exclusively (host:
              // the cache line; GPU: same-address atomics serialise; ncu,
              // H100, 1.65 M frame at r/2: this kernel and the count before
              // it 683 -> 447 µs).
              if (map.seen(key)) continue;
              if (map.insert(key)) ++acc;
            }
      },
      inserted);
  space.fence();
  band.n_blocks = inserted;
  trace("band: insert blocks", inserted);
  check_band_blocks<MemSpace>(band.n_blocks);
  collect_sorted_keys(space, tracker, band);
  trace("band: sorted block keys", band.n_blocks);
  number_blocks(space, band);  // before marking: the marking looks blocks up

  // 3. Set the bits: one atomic OR per (particle, 4x4x4 sub-block).
  band.words = Buffer<std::uint64_t, MemSpace>(tracker, "band::words", band.n_blocks * 8, true);
  auto words = band.words.view();
  Kokkos::parallel_for(
      "nbmc::band::mark", Kokkos::RangePolicy<ExecSpace, Kokkos::Schedule<Kokkos::Dynamic>>(space, 0, n),
      KOKKOS_LAMBDA(const std::size_t i) {
        std::int64_t lo[3], hi[3];
        if (!flags(i) || !box(i, lo, hi)) return;
        for (std::int64_t sz = lo[2] >> 2; sz <= (hi[2] >> 2); ++sz)
          for (std::int64_t sy = lo[1] >> 2; sy <= (hi[1] >> 2); ++sy)
            for (std::int64_t sx = lo[0] >> 2; sx <= (hi[0] >> 2); ++sx) {
              // The bits of the box inside this sub-block.
              const std::int64_t x0 = (sx << 2) > lo[0] ? (sx << 2) : lo[0];
              const std::int64_t x1 = (sx << 2) + 3 < hi[0] ? (sx << 2) + 3 : hi[0];
              const std::int64_t y0 = (sy << 2) > lo[1] ? (sy << 2) : lo[1];
              const std::int64_t y1 = (sy << 2) + 3 < hi[1] ? (sy << 2) + 3 : hi[1];
              const std::int64_t z0 = (sz << 2) > lo[2] ? (sz << 2) : lo[2];
              const std::int64_t z1 = (sz << 2) + 3 < hi[2] ? (sz << 2) + 3 : hi[2];
              // The x row (4 bits), copied to the rows y0..y1 (nibbles) and
              // then to the layers z0..z1 (16-bit groups) by multiplying with
              // a one in each: the copies do not overlap, so the product is
              // their OR (the loop over y and z this replaces).
              const std::uint64_t row = ((std::uint64_t(2) << (x1 & 3)) - 1) & ~((std::uint64_t(1) << (x0 & 3)) - 1);
              const std::uint64_t ys = (0x1111ull >> (4 * (3 - ((y1 - y0) & 3)))) << (4 * (y0 & 3));
              const std::uint64_t zs = (0x0001000100010001ull >> (16 * (3 - ((z1 - z0) & 3)))) << (16 * (z0 & 3));
              const std::uint64_t mask = (row * ys) * zs;
              const std::uint32_t b = map.find(
                  morton3(std::uint32_t(sx >> 1), std::uint32_t(sy >> 1), std::uint32_t(sz >> 1)));
              const std::size_t w = std::size_t(b) * 8 + ((sx & 1) | ((sy & 1) << 1) | ((sz & 1) << 2));
              // Host: neighbouring surface particles' boxes overlap, so most
              // of these bits are set already; a read (bits once set stay
              // set) skips the atomic, which takes the line exclusively and
              // contends between threads. The same words either way. Not on
              // the GPU: the read made the kernel slower (ncu, H100: 245 ->
              // 359 µs on the 1.65 M frame at r/2; bench/RESULTS.md, session
              // 26). A plain if (constant, folded): nvcc rejects a lambda
              // whose first use of a captured variable is in an if constexpr.
              if (HostMemory::accessible && (Kokkos::volatile_load(&words(w)) & mask) == mask) continue;
              Kokkos::atomic_fetch_or(&words(w), mask);
            }
      });
  space.fence();
  trace("band: mark", band.n_blocks);
  finish_band(space, tracker, band);
}

// Grows the band by the eight corners of every cell in `cells` (grid
// coordinates of the cells' minimum corners, host memory), on the host.
// Returns the new band; `old` is left intact. Used for a subdomain's seeds
// (once per run) and, with NBMC_CHECK_BAND=1, as the reference of the band
// growth's device extension (band_growth.hpp).
template <class ExecSpace>
void extend_band(const ExecSpace& space, MemoryTracker& tracker, const Grid& g,
                 const Band<typename ExecSpace::memory_space>& old, const std::vector<std::int64_t>& cells,
                 Band<typename ExecSpace::memory_space>& band) {
  using MemSpace = typename ExecSpace::memory_space;
  auto okeys = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), old.block_keys.view());
  auto owords = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), old.words.view());
  trace("extend: band to host", old.n_blocks);
  auto block_key = [](std::int64_t i, std::int64_t j, std::int64_t k) {
    return morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3));
  };
  // Corners inside the grid and the band's vertex box.
  auto inside = [&](std::int64_t i, std::int64_t j, std::int64_t k) {
    return i < g.dims[0] && j < g.dims[1] && k < g.dims[2] && i >= old.clip_lo[0] && j >= old.clip_lo[1] &&
           k >= old.clip_lo[2] && i <= old.clip_hi[0] && j <= old.clip_hi[1] && k <= old.clip_hi[2];
  };
  for (int a = 0; a < 3; ++a) {
    band.clip_lo[a] = old.clip_lo[a];
    band.clip_hi[a] = old.clip_hi[a];
    band.own_lo[a] = old.own_lo[a];
    band.own_hi[a] = old.own_hi[a];
  }
  // The corners to add, as (block key, word, bit); work in proportion to the
  // cells added, plus one linear pass over the old blocks.
  struct Corner {
    std::uint64_t key;
    int word;
    std::uint64_t bit;
  };
  std::vector<Corner> corners;
  corners.reserve(8 * (cells.size() / 3));
  for (std::size_t c = 0; c + 2 < cells.size(); c += 3)
    for (int q = 0; q < 8; ++q) {
      const std::int64_t i = cells[c] + (q & 1), j = cells[c + 1] + ((q >> 1) & 1), k = cells[c + 2] + (q >> 2);
      if (!inside(i, j, k)) continue;
      const std::int64_t lx = i & 7, ly = j & 7, lz = k & 7;
      corners.push_back({block_key(i, j, k), BandView<MemSpace>::word_of(lx, ly, lz),
                         std::uint64_t(1) << BandView<MemSpace>::bit_of(lx, ly, lz)});
    }
  std::vector<std::uint64_t> added_keys(corners.size());
  for (std::size_t q = 0; q < corners.size(); ++q) added_keys[q] = corners[q].key;
  std::sort(added_keys.begin(), added_keys.end());
  added_keys.erase(std::unique(added_keys.begin(), added_keys.end()), added_keys.end());
  std::vector<std::uint64_t> keys;
  keys.reserve(old.n_blocks + added_keys.size());
  std::set_union(okeys.data(), okeys.data() + old.n_blocks, added_keys.begin(), added_keys.end(),
                 std::back_inserter(keys));
  check_band_blocks<MemSpace>(keys.size());
  std::vector<std::uint64_t> words(keys.size() * 8, 0);
  for (std::size_t b = 0, nbk = 0; b < old.n_blocks; ++b) {
    while (keys[nbk] < okeys(b)) ++nbk;  // okeys is a subsequence of keys
    for (int w = 0; w < 8; ++w) words[nbk * 8 + w] = owords(b * 8 + w);
  }
  // Set the corners' bits.
  for (const Corner& c : corners) {
    const std::size_t b = std::size_t(std::lower_bound(keys.begin(), keys.end(), c.key) - keys.begin());
    words[b * 8 + std::size_t(c.word)] |= c.bit;
  }
  trace("extend: new words (host)", keys.size());
  band.n_blocks = keys.size();
  band.block_keys = Buffer<std::uint64_t, MemSpace>(tracker, "band::block_keys", keys.size());
  band.words = Buffer<std::uint64_t, MemSpace>(tracker, "band::words", words.size());
  using Unmanaged = Kokkos::MemoryTraits<Kokkos::Unmanaged>;
  Kokkos::deep_copy(space, band.block_keys.view(),
                    Kokkos::View<const std::uint64_t*, Kokkos::HostSpace, Unmanaged>(keys.data(), keys.size()));
  Kokkos::deep_copy(space, band.words.view(),
                    Kokkos::View<const std::uint64_t*, Kokkos::HostSpace, Unmanaged>(words.data(), words.size()));
  band.blocks.allocate(space, tracker, "band::block_map", keys.size());
  auto map = band.blocks.map;
  auto bk = band.block_keys.view();
  Kokkos::parallel_for(
      "nbmc::band::extend_insert", Kokkos::RangePolicy<ExecSpace>(space, 0, band.n_blocks),
      KOKKOS_LAMBDA(const std::size_t b) { map.insert(bk(b)); });
  space.fence();
  trace("extend: upload, block map", keys.size());
  number_blocks(space, band);
  finish_band(space, tracker, band);
  trace("extend: numbering", keys.size());
}

// The dense baseline: every vertex of the bounding grid is a "band" vertex.
template <class ExecSpace>
void build_dense_band(const ExecSpace& space, MemoryTracker& tracker, const Grid& g,
                      Band<typename ExecSpace::memory_space>& band) {
  using MemSpace = typename ExecSpace::memory_space;
  const std::int64_t bd[3] = {g.block_dims(0), g.block_dims(1), g.block_dims(2)};
  check_band_blocks<MemSpace>(std::size_t(bd[0] * bd[1] * bd[2]));
  std::vector<std::uint64_t> keys;
  keys.reserve(std::size_t(bd[0] * bd[1] * bd[2]));
  for (std::int64_t z = 0; z < bd[2]; ++z)
    for (std::int64_t y = 0; y < bd[1]; ++y)
      for (std::int64_t x = 0; x < bd[0]; ++x)
        keys.push_back(morton3(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)));
  std::sort(keys.begin(), keys.end());
  band.n_blocks = keys.size();
  band.block_keys = Buffer<std::uint64_t, MemSpace>(tracker, "band::block_keys", keys.size());
  Kokkos::View<const std::uint64_t*, Kokkos::HostSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>> hk(keys.data(),
                                                                                                   keys.size());
  Kokkos::deep_copy(space, band.block_keys.view(), hk);
  band.blocks.allocate(space, tracker, "band::block_map", keys.size());
  band.words = Buffer<std::uint64_t, MemSpace>(tracker, "band::words", band.n_blocks * 8);
  auto map = band.blocks.map;
  auto bkeys = band.block_keys.view();
  auto words = band.words.view();
  const std::int64_t d0 = g.dims[0], d1 = g.dims[1], d2 = g.dims[2];
  Kokkos::parallel_for(
      "nbmc::band::dense", Kokkos::RangePolicy<ExecSpace>(space, 0, band.n_blocks), KOKKOS_LAMBDA(const std::size_t b) {
        map.insert(bkeys(b));
        const std::uint64_t key = bkeys(b);
        const std::int64_t bx = std::int64_t(compact3(key)) * 8, by = std::int64_t(compact3(key >> 1)) * 8,
                           bz = std::int64_t(compact3(key >> 2)) * 8;
        for (int w = 0; w < 8; ++w) {
          std::uint64_t mask = 0;
          for (int bit = 0; bit < 64; ++bit) {
            const std::int64_t i = bx + (w & 1) * 4 + (bit & 3), j = by + ((w >> 1) & 1) * 4 + ((bit >> 2) & 3),
                               k = bz + ((w >> 2) & 1) * 4 + (bit >> 4);
            if (i < d0 && j < d1 && k < d2) mask |= std::uint64_t(1) << bit;
          }
          words(b * 8 + w) = mask;
        }
      });
  space.fence();
  number_blocks(space, band);
  finish_band(space, tracker, band);
}

}  // namespace Details
}  // namespace nbmc
