// SPDX-License-Identifier: MIT
// Band growth (pipeline.hpp, after the field): close the band where the
// surface leaves it. A leak is a cell that is not entirely in the band next
// to a triangulated cell across a face with mixed signs (leaks_at in
// marching_cubes.hpp); each round adds the corners of every leak cell to the
// band, evaluates the new vertices only, and looks for leaks again, until
// there are none.
//
// Everything a round touches stays on the execution space; the host sees one
// small array of counters per round (GrowthCounter: leaks, words and blocks
// that gain vertices, new vertices), which is the loop's exit test and sizes
// every allocation of the round exactly. One round, in launches:
//   1  clear: one kernel empties the round's hash sets and zeroes the
//      counters (no fence: kernels on one execution space instance run in
//      order);
//   2  detection, one kernel (round 0 scans the whole band, later rounds
//      only the 27 cells around every cell the previous round added, made
//      unique through a hash set on the device): appends the leak cells to
//      a device list and at once records their corners that are not band
//      vertices yet, in a hash set of band words (word -> new bits) and a
//      hash set of the blocks that do not exist yet;
//   3  the round's only sync: one device-to-host copy of the counters
//      (32 bytes). No leaks: done;
//   4  the new block keys sorted (host memory: std::sort on the same
//      memory; device: one rank kernel, or CUB (which syncs) past 8,192 new
//      blocks in one round);
//   5  merge, one kernel: the old and new keys merged by binary search, the
//      old words copied to their new places, the block map renumbered (the
//      old map is reused while it has room; else a new one, one fill more);
//   6  set_bits, one kernel: the new bits set, the list of words to
//      evaluate written (WordList);
//   7  prefix: the word offsets (a scan whose total is not read back: it
//      is the old count plus the new vertices counted in step 2);
//   8  carry_values, one kernel (old vertices keep their values), and the
//      gather of the new vertices only, one kernel, its evaluation count
//      added to device counters read once after the loop.
// Allocations: the band a round replaces keeps its buffers for the next
// rounds (allocated with 1/32 headroom), the block map is reused while it has
// room, scratch buffers only grow: after the first two rounds, a round
// usually allocates and frees nothing (cudaFree synchronises; fresh host
// pages fault). In all, a round is about nine launches (a Kokkos scan is
// two on CUDA), one sync with one 32-byte device-to-host copy, no
// host-to-device copy; only the gather's functor is large enough for Kokkos'
// constant-memory launch, which waits for the previous such launch (the
// previous round's gather, long done). Before, a round made about ten
// blocking transfers (the band's keys and words to the host and back, the
// leak candidates built on the host and uploaded, the leak count and list
// read back, three growth lists uploaded) and about eight fences or totals
// read back (map, numbering, prefix, carry, gather count, counter inits).
//
// The list capacities are guesses (from the band or the previous round);
// when one is exceeded, the overflow flag in the counters makes the round's
// detection run again with exact bounds (a second sync, rarely).
#pragma once

#include "common.hpp"
#include "grid.hpp"
#include "marching_cubes.hpp"
#include "narrow_band.hpp"
#include "scalar_field.hpp"

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <string>
#include <type_traits>
#include <vector>

namespace nbmc {
namespace Details {

// Inserts key into an open-addressing set (linear probing, mask + 1 slots
// at keys, empty slots ~0); returns its slot, or -1 when every slot is taken
// (the probe is bounded: a full table flags an overflow instead of
// spinning). `inserted`: whether this call added the key.
KOKKOS_INLINE_FUNCTION std::int64_t set_insert(std::uint64_t* keys, std::uint64_t mask, std::uint64_t key,
                                               bool& inserted) {
  std::uint64_t slot = hash64(key) & mask;
  for (std::uint64_t probe = 0; probe <= mask; ++probe) {
    const std::uint64_t empty = ~std::uint64_t(0);
    const std::uint64_t prev = Kokkos::atomic_compare_exchange(&keys[slot], empty, key);
    if (prev == empty || prev == key) {
      inserted = prev == empty;
      return std::int64_t(slot);
    }
    slot = (slot + 1) & mask;
  }
  inserted = false;
  return -1;
}

// First index of a sorted array's first n entries whose value is >= key.
template <class View>
KOKKOS_INLINE_FUNCTION std::size_t lower_bound_in(const View& v, std::size_t n, std::uint64_t key) {
  std::size_t lo = 0, hi = n;
  while (lo < hi) {
    const std::size_t mid = lo + (hi - lo) / 2;
    if (v(mid) < key) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

// The counters of one detection pass (32-bit: native atomics on every device).
enum GrowthCounter { kLeakCount, kWordCount, kNewBlockCount, kFreshCount, kOverflow, kGrowthCounters = 8 };

// What a detection pass records, on the device: the leak cells (3 per
// cell, in the order the threads append them; with repeats, as the scans
// find them), and the corners of those cells that are not band vertices
// yet: per band word (key: block key * 8 + word), the bits of its new
// vertices; the blocks that do not exist yet, each once.
// Raw pointers, not views, and the band passed by the caller: kernels whose
// functor is 512 bytes or more go through CUDA constant memory in Kokkos 3.4,
// and each such launch waits for the previous one (a host sync); the
// detection kernels stay below that (about 420 bytes with the band view).
template <class MemSpace>
struct GrowthRecorder {
  unsigned int* counters = nullptr;
  std::int64_t* leaks = nullptr;
  std::uint64_t *word_keys = nullptr, *word_bits = nullptr, *block_set = nullptr;  // mask + 1 slots each
  std::uint32_t* word_slots = nullptr;  // entry -> slot of word_keys
  std::uint64_t* new_blocks = nullptr;  // entry -> block key
  std::uint64_t leak_cap = 0, mask = 0, entry_cap = 0;
  std::int32_t lim_lo[3] = {0, 0, 0}, lim_hi[3] = {0, 0, 0};  // corners allowed (grid, vertex box), inclusive

  KOKKOS_INLINE_FUNCTION void overflow() const { counters[kOverflow] = 1u; }

  // Records corner (i, j, k) of a leak cell unless it is a vertex of `band`
  // (the band before this round) or outside the box (extend_band's rule).
  KOKKOS_INLINE_FUNCTION void add_corner(const BandView<MemSpace>& band, std::int64_t i, std::int64_t j,
                                         std::int64_t k) const {
    if (i < lim_lo[0] || j < lim_lo[1] || k < lim_lo[2] || i > lim_hi[0] || j > lim_hi[1] || k > lim_hi[2]) return;
    const std::uint64_t key = morton3(std::uint32_t(i >> 3), std::uint32_t(j >> 3), std::uint32_t(k >> 3));
    const int sub = BandView<MemSpace>::word_of(i & 7, j & 7, k & 7);
    const std::uint64_t bit = std::uint64_t(1) << BandView<MemSpace>::bit_of(i & 7, j & 7, k & 7);
    const std::uint32_t b = band.blocks.find(key);
    if (b != ~0u && (band.words(std::size_t(b) * 8 + std::size_t(sub)) & bit)) return;
    bool inserted = false;
    const std::int64_t slot = set_insert(word_keys, mask, key * 8 + std::uint64_t(sub), inserted);
    if (slot < 0) {
      overflow();
      return;
    }
    if (inserted) {
      const unsigned int q = Kokkos::atomic_fetch_add(&counters[kWordCount], 1u);
      if (q < entry_cap) word_slots[q] = std::uint32_t(slot);
      else overflow();
      if (b == ~0u) {
        bool new_block = false;
        if (set_insert(block_set, mask, key, new_block) < 0) {
          overflow();
        } else if (new_block) {
          const unsigned int nb = Kokkos::atomic_fetch_add(&counters[kNewBlockCount], 1u);
          if (nb < entry_cap) new_blocks[nb] = key;
          else overflow();
        }
      }
    }
    const std::uint64_t prev = Kokkos::atomic_fetch_or(&word_bits[slot], bit);
    if (!(prev & bit)) Kokkos::atomic_fetch_add(&counters[kFreshCount], 1u);
  }

  // Appends the n leak cells found at one cell (out: x y z triples) and
  // records their corners; leaks past the capacity are counted only.
  KOKKOS_INLINE_FUNCTION void add_leaks(const BandView<MemSpace>& band, const std::int64_t* out, int n) const {
    const std::uint64_t at = Kokkos::atomic_fetch_add(&counters[kLeakCount], unsigned(n));
    for (int q = 0; q < n; ++q) {
      if (at + std::uint64_t(q) >= leak_cap) return;
      const std::int64_t i = out[3 * q], j = out[3 * q + 1], k = out[3 * q + 2];
      for (int a = 0; a < 3; ++a) leaks[3 * (at + std::uint64_t(q)) + std::uint64_t(a)] = out[3 * q + a];
      for (int c = 0; c < 8; ++c) add_corner(band, i + (c & 1), j + ((c >> 1) & 1), k + (c >> 2));
    }
  }
};

// A tracked scratch buffer that only grows (by half again), so that most
// rounds allocate nothing. Its contents are not kept.
template <class T, class MemSpace>
void ensure_capacity(MemoryTracker& tracker, Buffer<T, MemSpace>& b, std::size_t n, const char* label) {
  if (b.size() >= n) return;
  b.release();
  b = Buffer<T, MemSpace>(tracker, label, n + n / 2);
}

// `from` if it holds n elements (its contents are not kept), else a new
// buffer of n and 1/32 more: the band and its values grow by much less than
// that per round, so buffers handed back by one round serve the next ones.
template <class T, class MemSpace>
Buffer<T, MemSpace> reuse_or_allocate(MemoryTracker& tracker, Buffer<T, MemSpace>& from, std::size_t n,
                                      const char* label) {
  if (from.size() >= n) return std::move(from);
  from.release();
  return Buffer<T, MemSpace>(tracker, label, n + n / 32);
}

// Totals of the growth (RunStats fields) and, for a subdomain, the cells it added.
struct GrowthTotals {
  std::uint64_t rounds = 0, cells = 0, evaluations = 0;
  std::vector<std::int64_t>* grown_cells = nullptr;  // appended: each round's leaks, sorted (host)
};

// `evaluate(band_view, n_list, list, phi, sink)` runs the field method's
// gather on the listed words (gather_field) and returns the evaluations it
// counted on the host (0 where it added them to `sink`, 256 device
// counters). A std::function, not a template parameter: nvcc rejects
// extended lambdas in a function template instantiated with a local type
// (the caller's lambda).
template <class MemSpace>
using GrowthEvaluate = std::function<std::uint64_t(const BandView<MemSpace>&, std::size_t, const WordList<MemSpace>&,
                                                   const Kokkos::View<float*, MemSpace>&,
                                                   const Kokkos::View<unsigned long long*, MemSpace>&)>;

// The growth loop; band and phi are replaced by the grown band and values.
template <class ExecSpace>
void grow_band(const ExecSpace& space, MemoryTracker& tracker, const Grid& g,
               Band<typename ExecSpace::memory_space>& band, Buffer<float, typename ExecSpace::memory_space>& phi,
               const GrowthEvaluate<typename ExecSpace::memory_space>& evaluate, GrowthTotals& totals) {
  using MemSpace = typename ExecSpace::memory_space;
  using Range = Kokkos::RangePolicy<ExecSpace>;
  using Unmanaged = Kokkos::MemoryTraits<Kokkos::Unmanaged>;
  using U64 = Kokkos::View<std::uint64_t*, MemSpace, Unmanaged>;
  constexpr bool host_memory = Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible;
  ScopedRegion region("nbmc::band_growth");
  const bool check = std::getenv("NBMC_CHECK_BAND") != nullptr;
  // NBMC_GROWTH_TINY_GUESSES=1 (tests): capacity guesses of 1, so that the
  // detection's overflow path runs in every round.
  const bool tiny_guesses = std::getenv("NBMC_GROWTH_TINY_GUESSES") != nullptr;

  Buffer<unsigned int, MemSpace> counters(tracker, "band_growth::counters", kGrowthCounters);
  unsigned int hc[kGrowthCounters];
  const Kokkos::View<unsigned int*, Kokkos::HostSpace, Unmanaged> hcounters(hc, kGrowthCounters);
  Buffer<unsigned long long, MemSpace> sink(tracker, "band_growth::evaluations", 256, true);
  Buffer<std::int64_t, MemSpace> leak_lists[2];  // this round's leaks, the previous round's
  Buffer<std::uint64_t, MemSpace> word_keys, word_bits, block_set, new_blocks, candidates, sorted_new, old_to_new,
      list_words, list_bits;
  Buffer<std::uint32_t, MemSpace> word_slots, sort_values[2];
  // The band and values a round replaced: their buffers serve the next
  // rounds (reuse_or_allocate), so that most rounds neither allocate nor
  // free (on a GPU, cudaFree synchronises; on the host, fresh pages fault).
  Band<MemSpace> spare;
  Buffer<float, MemSpace> spare_phi;
  std::size_t n_prev = 0;  // leaks of the previous round (in leak_lists[1])

  for (int round = 0;; ++round) {
    const BandView<MemSpace> bv = view_of(band, g);
    const Kokkos::View<const float*, MemSpace> cur_phi = phi.view();
    const std::size_t n_words = band.n_blocks * 8;
    // Guessed capacities: leak cells (as many as 1/16 of the band's words,
    // or twice the previous round's), distinct words gaining vertices. (A
    // floor of 64: with 1024 the sets took about 350 KB whatever the frame,
    // twice a small frame's whole reconstruction; a guess too small costs
    // one detection more, not a different band.)
    std::size_t leak_cap = round == 0 ? 64 + n_words / 16 : 64 + 2 * n_prev;
    std::size_t entry_cap = 2 * leak_cap;
    if (tiny_guesses) leak_cap = entry_cap = 1;  // tests: every round overflows and runs again
    GrowthRecorder<MemSpace> rec;
    Buffer<std::uint64_t, MemSpace> inside;  // round 0: phi < 0 per band word (bits)
    // Round 0 on a GPU: the corner blocks of each block (8 per block), and
    // per word its mixed cells and its complete cells (mixed_cells).
    Buffer<std::uint32_t, MemSpace> corner_nb;
    Buffer<std::uint64_t, MemSpace> mixed;
    for (int attempt = 0;; ++attempt) {
      const std::size_t slots = next_pow2(2 * entry_cap + 16);
      ensure_capacity(tracker, leak_lists[0], 3 * leak_cap, "band_growth::leaks");
      ensure_capacity(tracker, word_keys, slots, "band_growth::word_set");
      ensure_capacity(tracker, word_bits, slots, "band_growth::word_bits");
      ensure_capacity(tracker, block_set, slots, "band_growth::block_set");
      ensure_capacity(tracker, word_slots, entry_cap, "band_growth::word_entries");
      ensure_capacity(tracker, new_blocks, entry_cap, "band_growth::new_blocks");
      rec.counters = counters.data();
      rec.leaks = leak_lists[0].data();
      rec.leak_cap = leak_cap;
      rec.word_keys = word_keys.data();
      rec.word_bits = word_bits.data();
      rec.block_set = block_set.data();
      rec.mask = slots - 1;
      rec.word_slots = word_slots.data();
      rec.new_blocks = new_blocks.data();
      rec.entry_cap = entry_cap;
      for (int a = 0; a < 3; ++a) {
        rec.lim_lo[a] = std::int32_t(band.clip_lo[a]);
        rec.lim_hi[a] = std::int32_t(std::min<std::int64_t>(g.dims[a] - 1, band.clip_hi[a]));
      }
      // The candidate set of the scans near the added cells (27 per added
      // cell at most: it cannot fill).
      const std::size_t n_cand = round == 0 ? 0 : 27 * n_prev;
      const std::size_t cslots = round == 0 ? 0 : next_pow2(n_cand + n_cand / 2 + 16);
      if (cslots) ensure_capacity(tracker, candidates, cslots, "band_growth::candidates");
      std::uint64_t* const cand = candidates.data();
      // One kernel empties the sets and zeroes the counters; no fence: the
      // detection kernel runs after it on the same execution space instance.
      {
        const GrowthRecorder<MemSpace> r = rec;
        Kokkos::parallel_for(
            "nbmc::band_growth::clear", Range(space, 0, std::max(slots, cslots)), KOKKOS_LAMBDA(const std::size_t s) {
              if (s < slots) {
                r.word_keys[s] = ~std::uint64_t(0);
                r.word_bits[s] = 0;
                r.block_set[s] = ~std::uint64_t(0);
              }
              if (s < cslots) cand[s] = ~std::uint64_t(0);
              if (s < std::size_t(kGrowthCounters)) r.counters[s] = 0u;
            });
      }
      if (round == 0) {
        // The whole band: on the host one work item per word, on a GPU one
        // thread per vertex slot (as for_each_band_vertex, written out so
        // that the functor holds one band view, not two: see GrowthRecorder).
        if constexpr (host_memory) {
          // Only the cells with all corners in the band and mixed signs
          // (exact bit-mask filter, for_each_mixed_cell_host).
          if (attempt == 0) inside = inside_masks(space, tracker, bv, n_words, cur_phi);
          for_each_mixed_cell_host(
              space, "nbmc::band_growth::leaks", bv, n_words, Kokkos::View<const std::uint64_t*, MemSpace>(inside.view()),
              KOKKOS_LAMBDA(const std::size_t w, const int bit, const std::int64_t self, const std::uint64_t complete,
                            const std::size_t cw[8]) {
                std::int64_t i, j, k, out[18];
                bv.vertex(w, bit, i, j, k);
                const int n = leaks_at(bv, cur_phi, i, j, k, self, out, std::uint32_t(w >> 3), bit, complete, cw);
                if (n) rec.add_leaks(bv, out, n);
              });
        } else {
          // The host's exact bit-mask filter: per block its neighbouring
          // blocks (one look-up each), per word the cells with all corners
          // in the band and mixed signs (the eight corner-shifted copies of
          // the band and sign masks ANDed), and leaks_at (with the corner
          // words) only at those, one thread per vertex slot. The same leaks
          // as every slot looking its cell's corners up, which the whole
          // band paid before (H100, 1.65 M frame at r/2: 2.1 ms, a fifth of
          // the field stage).
          if (attempt == 0) {
            inside = inside_masks(space, tracker, bv, n_words, cur_phi);
            corner_nb = Buffer<std::uint32_t, MemSpace>(tracker, "band_growth::corner_blocks", n_words);
            mixed = Buffer<std::uint64_t, MemSpace>(tracker, "band_growth::mixed_cells", 2 * n_words);
            const Kokkos::View<std::uint32_t*, MemSpace> cnb = corner_nb.view();
            const Kokkos::View<std::uint64_t*, MemSpace> mx = mixed.view();
            const Kokkos::View<const std::uint64_t*, MemSpace> in = inside.view();
            Kokkos::parallel_for(
                "nbmc::band_growth::corner_blocks", Range(space, 0, band.n_blocks),
                KOKKOS_LAMBDA(const std::size_t b) {
                  std::uint32_t nb[8];
                  corner_blocks(bv, b, 7, nb);
                  for (int o = 0; o < 8; ++o) cnb(8 * b + std::size_t(o)) = nb[o];
                });
            Kokkos::parallel_for(
                "nbmc::band_growth::mixed_cells", Range(space, 0, n_words), KOKKOS_LAMBDA(const std::size_t w) {
                  std::uint64_t complete = 0, cand = 0;
                  if (bv.words(w)) {
                    std::uint32_t nb[8];
                    for (int o = 0; o < 8; ++o) nb[o] = cnb(8 * (w >> 3) + std::size_t(o));
                    std::size_t cw[8];
                    cand = mixed_cells(bv, in, nb, int(w & 7), complete, cw);
                  }
                  mx(2 * w) = cand;
                  mx(2 * w + 1) = complete;
                });
          }
          const Kokkos::View<const std::uint32_t*, MemSpace> cnb = corner_nb.view();
          const Kokkos::View<const std::uint64_t*, MemSpace> mx = mixed.view();
          Kokkos::parallel_for(
              "nbmc::band_growth::leaks", Range(space, 0, n_words * 64), KOKKOS_LAMBDA(const std::size_t v) {
                const std::size_t w = v >> 6;
                const int bit = int(v & 63);
                if (!((mx(2 * w) >> bit) & 1)) return;
                std::uint32_t nb[8];
                for (int o = 0; o < 8; ++o) nb[o] = cnb(8 * (w >> 3) + std::size_t(o));
                std::size_t cw[8];
                corner_words(nb, int(w & 7), cw);
                const std::uint64_t word = bv.words(w);
                const std::int64_t self =
                    std::int64_t(bv.word_offset(w) + popcount64(word & ((std::uint64_t(1) << bit) - 1)));
                std::int64_t i, j, k, out[18];
                bv.vertex(w, bit, i, j, k);
                const int n =
                    leaks_at(bv, cur_phi, i, j, k, self, out, std::uint32_t(w >> 3), bit, mx(2 * w + 1), cw, mx.data() + 1);
                if (n) rec.add_leaks(bv, out, n);
              });
        }
      } else {
        // Only the cells that can have become leaky: a cell's leaks appear
        // when it becomes complete, i.e. when it gains a corner, so the 27
        // cells around every added cell (old cells only lose leaks). Same
        // result as a full scan (NBMC_CHECK_BAND=1 verifies it). Each
        // candidate is examined once: the thread that puts it into the set.
        const std::uint64_t cmask = cslots - 1;
        const Kokkos::View<const std::int64_t*, MemSpace> added = leak_lists[1].view();
        const std::size_t np = n_prev;
        Kokkos::parallel_for(
            "nbmc::band_growth::leaks_near", Range(space, 0, n_cand), KOKKOS_LAMBDA(const std::size_t t) {
              const std::size_t o = t / np, c = t - o * np;  // neighbouring threads: neighbouring cells
              const std::int64_t i = added(3 * c) + std::int64_t(o % 3) - 1,
                                 j = added(3 * c + 1) + std::int64_t((o / 3) % 3) - 1,
                                 k = added(3 * c + 2) + std::int64_t(o / 9) - 1;
              if (i < 0 || j < 0 || k < 0) return;
              bool first = false;
              if (set_insert(cand, cmask, pack_cell(i, j, k), first) < 0) rec.overflow();  // cannot happen: sized
              if (!first) return;
              if (i + 1 >= bv.dims[0] || j + 1 >= bv.dims[1] || k + 1 >= bv.dims[2]) return;
              const std::int64_t self = bv.index(i, j, k);
              if (self < 0) return;
              std::int64_t out[18];
              const int m = leaks_at(bv, cur_phi, i, j, k, self, out);
              if (m) rec.add_leaks(bv, out, m);
            });
      }
      // The round's one device-to-host copy (and sync).
      Kokkos::deep_copy(space, hcounters, counters.view());
      space.fence();
      const std::size_t n_leaks = hc[kLeakCount];
      if (!hc[kOverflow] && n_leaks <= leak_cap) break;
      if (attempt > 0) throw Error(9, "band growth: the detection overflowed its exact bounds");
      // Exact bounds: every leak stored, at most 8 new words per leak.
      leak_cap = n_leaks;
      entry_cap = 8 * n_leaks + 1;
      trace("growth: detection again", n_leaks);
    }
    const std::size_t n_leaks = hc[kLeakCount];
    trace("band leaks", n_leaks);
    if (n_leaks == 0) {
      // NBMC_CHECK_BAND=1 (tests): the scans near the added cells must have
      // found everything a full scan finds.
      if (round > 0 && check && !find_band_leaks(space, bv, n_words, cur_phi).empty())
        throw Error(9, "band growth: a full scan found leaks that the scans near the added cells missed");
      break;
    }
    if (round >= 1000) throw Error(9, "the narrow band did not close after 1000 growth rounds");
    totals.rounds = std::uint64_t(round + 1);
    totals.cells += n_leaks;
    std::vector<std::int64_t> host_leaks;  // subdomains and checks only
    if (totals.grown_cells || check) host_leaks = cells_to_host(leak_lists[0].view(), n_leaks);
    if (totals.grown_cells) totals.grown_cells->insert(totals.grown_cells->end(), host_leaks.begin(), host_leaks.end());
    const std::size_t n_list = hc[kWordCount], n_newb = hc[kNewBlockCount];
    if (n_list > 0) {
      // ---- the new block keys, sorted
      const std::size_t n_old = band.n_blocks, n_new = n_old + n_newb;
      check_band_blocks<MemSpace>(n_new);
      Kokkos::View<const std::uint64_t*, MemSpace> sorted;
      if constexpr (host_memory) {
        std::sort(new_blocks.data(), new_blocks.data() + n_newb);  // host memory, the device idle since the sync
        sorted = U64(new_blocks.data(), n_newb);
      } else {
        ensure_capacity(tracker, sorted_new, n_newb, "band_growth::sorted_blocks");
        const U64 out(sorted_new.data(), n_newb), in(new_blocks.data(), n_newb);
        bool done = false;
#if defined(KOKKOS_ENABLE_CUDA)
        if constexpr (std::is_same<ExecSpace, Kokkos::Cuda>::value) {
          if (n_newb > 8192) {  // CUB (it syncs); few rounds add that many blocks
            ensure_capacity(tracker, sort_values[0], n_newb, "band_growth::sort_values");
            ensure_capacity(tracker, sort_values[1], n_newb, "band_growth::sort_values");
            device_sort_pairs(space, tracker, new_blocks.data(), sorted_new.data(), sort_values[0].data(),
                              sort_values[1].data(), n_newb, 63);
            done = true;
          }
        }
#endif
        if (!done && n_newb) {
          // Rank of each key among the (distinct) new keys: one thread per key.
          Kokkos::parallel_for(
              "nbmc::band_growth::rank_blocks", Range(space, 0, n_newb), KOKKOS_LAMBDA(const std::size_t q) {
                const std::uint64_t key = in(q);
                std::size_t r = 0;
                for (std::size_t p = 0; p < in.extent(0); ++p) r += in(p) < key ? 1 : 0;
                out(r) = key;
              });
        }
        sorted = out;
      }
      // ---- the grown band: keys merged, old words moved, block map numbered
      Band<MemSpace> grown;
      for (int a = 0; a < 3; ++a) {
        grown.clip_lo[a] = band.clip_lo[a];
        grown.clip_hi[a] = band.clip_hi[a];
        grown.own_lo[a] = band.own_lo[a];
        grown.own_hi[a] = band.own_hi[a];
      }
      grown.n_blocks = n_new;
      grown.block_keys = reuse_or_allocate(tracker, spare.block_keys, n_new, "band::block_keys");
      grown.words = reuse_or_allocate(tracker, spare.words, n_new * 8, "band::words");
      // The old map is kept (its keys are a subset) while it has room for the
      // new keys at the load HashMapStorage::allocate gives; its values are
      // renumbered below.
      const bool reuse_map = band.blocks.map.mask + 1 >= next_pow2(std::max<std::size_t>(16, n_new + n_new / 2 + 1));
      if (reuse_map) grown.blocks = std::move(band.blocks);
      else grown.blocks.allocate(space, tracker, "band::block_map", n_new);
      ensure_capacity(tracker, old_to_new, n_old, "band_growth::old_to_new");
      {
        const auto okeys = Kokkos::View<const std::uint64_t*, MemSpace>(band.block_keys.view());
        const auto owords = Kokkos::View<const std::uint64_t*, MemSpace>(band.words.view());
        const auto nkeys = grown.block_keys.view();
        const auto nwords = grown.words.view();
        const auto map = grown.blocks.map;
        const U64 o2n(old_to_new.data(), n_old);
        Kokkos::parallel_for(
            "nbmc::band_growth::merge_blocks", Range(space, 0, n_new), KOKKOS_LAMBDA(const std::size_t t) {
              const bool old = t < n_old;
              const std::uint64_t key = old ? okeys(t) : sorted(t - n_old);
              // Both lists are sorted and disjoint: a key's place is its
              // index in its list plus the number of smaller keys in the other.
              const std::size_t pos = old ? t + lower_bound_in(sorted, n_newb, key)
                                          : (t - n_old) + lower_bound_in(okeys, n_old, key);
              nkeys(pos) = key;
              for (int w = 0; w < 8; ++w) nwords(pos * 8 + std::size_t(w)) = old ? owords(t * 8 + std::size_t(w)) : 0;
              if (old) o2n(t) = pos;
              if (!reuse_map || !old) map.insert(key);
              map.values(map.find_slot(key)) = std::uint32_t(pos);
            });
      }
      // ---- the new vertices' bits, and the words to evaluate
      ensure_capacity(tracker, list_words, n_list, "band_growth::list_words");
      ensure_capacity(tracker, list_bits, n_list, "band_growth::list_bits");
      {
        const U64 lw(list_words.data(), n_list), lb(list_bits.data(), n_list);
        const auto slots = Kokkos::View<const std::uint32_t*, MemSpace>(word_slots.view());
        const std::uint64_t* const wk = rec.word_keys;
        const std::uint64_t* const wb = rec.word_bits;
        const auto map = grown.blocks.map;
        const auto nwords = grown.words.view();
        Kokkos::parallel_for(
            "nbmc::band_growth::set_bits", Range(space, 0, n_list), KOKKOS_LAMBDA(const std::size_t q) {
              const std::uint32_t s = slots(q);
              const std::uint64_t key = wk[s];
              const std::size_t w = std::size_t(map.find(key >> 3)) * 8 + std::size_t(key & 7);
              const std::uint64_t bits = wb[s];
              nwords(w) |= bits;  // each word is listed once: no other thread writes it
              lw(q) = w;
              lb(q) = bits;
            });
      }
      // Prefix counts without reading the total back: it is known.
      grown.word_offset = reuse_or_allocate(tracker, spare.word_offset, n_new * 8, "band::word_offset");
      {
        const auto words = Kokkos::View<const std::uint64_t*, MemSpace>(grown.words.view());
        prefix_counts(space, tracker, "nbmc::band_growth::prefix", n_new * 8, grown.word_offset.view(),
                      KOKKOS_LAMBDA(const std::size_t w) { return std::uint64_t(popcount64(words(w))); }, false);
      }
      grown.n_vertices = band.n_vertices + hc[kFreshCount];
      trace("growth: extend (device)", n_new);
      if (check) {
        // NBMC_CHECK_BAND=1: the band extend_band builds on the host from the
        // same leaks must be this one.
        Band<MemSpace> ref;
        extend_band(space, tracker, g, band, host_leaks, ref);
        auto a = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), grown.block_keys.view());
        auto b = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), ref.block_keys.view());
        auto aw = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), grown.words.view());
        auto bw = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), ref.words.view());
        auto ao = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), grown.word_offset.view());
        auto bo = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), ref.word_offset.view());
        bool same = ref.n_blocks == grown.n_blocks && ref.n_vertices == grown.n_vertices;
        for (std::size_t q = 0; same && q < grown.n_blocks; ++q) same = a(q) == b(q);
        for (std::size_t q = 0; same && q < 8 * grown.n_blocks; ++q) same = aw(q) == bw(q) && ao(q) == bo(q);
        if (!same) throw Error(9, "band growth: the device extension differs from the host's");
        BandView<MemSpace> gv = view_of(grown, g);
        const std::size_t nb = grown.n_blocks;
        std::uint64_t bad = 0;
        Kokkos::parallel_reduce(
            "nbmc::band_growth::check_map", Range(space, 0, nb),
            KOKKOS_LAMBDA(const std::size_t q, std::uint64_t& acc) { acc += gv.blocks.find(gv.block_keys(q)) != q; },
            bad);
        if (bad) throw Error(9, "band growth: the block map is not numbered in key order");
      }
      // ---- the values: old vertices carried, new ones evaluated
      Buffer<float, MemSpace> grown_phi = reuse_or_allocate(tracker, spare_phi, grown.n_vertices, "scalar_field::values");
      const BandView<MemSpace> gv = view_of(grown, g);
      carry_values(space, bv, n_words, cur_phi, gv, grown_phi.view(),
                   Kokkos::View<const std::uint64_t*, MemSpace>(U64(old_to_new.data(), n_old)));
      trace("growth: carry values", n_words);
      const WordList<MemSpace> list{U64(list_words.data(), n_list), U64(list_bits.data(), n_list)};
      totals.evaluations += evaluate(gv, n_list, list, grown_phi.view(), sink.view());
      spare = std::move(band);
      spare_phi = std::move(phi);
      band = std::move(grown);
      phi = std::move(grown_phi);
    }
    trace("band growth round", band.n_vertices);
    std::swap(leak_lists[0], leak_lists[1]);
    n_prev = n_leaks;
  }
  // The evaluations the device counted (one copy for the whole growth).
  auto hs = Kokkos::create_mirror_view_and_copy(Kokkos::HostSpace(), sink.view());
  for (std::size_t q = 0; q < hs.extent(0); ++q) totals.evaluations += hs(q);
}

}  // namespace Details
}  // namespace nbmc
