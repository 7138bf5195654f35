// SPDX-License-Identifier: MIT
// Mesh clean-up (nbmc_params.cleanup, on by default): removes degenerate and
// sliver triangles (see mesh_check.hpp) from a marching-cubes mesh while it
// stays closed, manifold and consistently oriented.
//
// Marching cubes makes slivers where the surface passes close to a grid
// vertex: the mesh vertices on the grid edges around that grid vertex nearly
// coincide (short edges, "needles"), or one lies almost on the segment of two
// others ("caps"). Each bad triangle is repaired by the first kind of these
// that works, the best of its kind ("best": the largest smallest angle among
// the triangles it changes):
//  1. without losing a triangle:
//     - moving one of its vertices toward the centroid of its neighbours,
//       within its tangent plane (a quarter, half or all the way: the
//       shortest move that works);
//     - flipping its longest edge (caps), when the new edge does not exist
//       yet and both new triangles are good;
//  2. widening a needle whose short edge cannot be collapsed (the surface is
//     a thin tube there): the cluster of nearly coincident vertices is scaled
//     about its centre until the needle's angle is 2 (or 4) degrees, a move
//     of about 1e-4 cell;
//  3. collapsing one of its edges (to the midpoint or to either end), when
//     the link condition holds (the two ends share no neighbour but the two
//     opposite vertices) and the opposite vertices keep three neighbours.
// First, the moves of 1. alone, in rounds that need no order (mesh_moves.hpp:
// each bad triangle takes its vertices by its index, and moves of vertices
// that are not neighbours are made together; on a GPU where the mesh is
// made, with the same decisions). Then, for what they left:
// rounds: passes of these until nothing more is repaired with the normal
// turn limit of 60 degrees, then with 90 degrees (a fold, beyond 90, never),
// then a last round that adds the last resorts (never pre-empting a repair
// that keeps more of the mesh):
//  - in 3., a triangle that was degenerate may stay degenerate, and one
//    that was bad may stay bad whatever its normal (several vertices at or
//    near one point, where the field is zero at a grid vertex, as SPH's
//    level set makes: one collapse after the other merges them);
//  - 4. cutting a pinched tube: when the needle's short edge (a, b) and a
//    third vertex c nearly coincide (edges below sin(1 degree) times the
//    needle's long edge) and form a 3-cycle that is no triangle (ZB05 makes
//    these where the zero set pinches off at a grid vertex, often with a cap
//    of three triangles around a fourth vertex on one side), no collapse
//    passes the link condition. The cycle is cut: the triangles on its left
//    take a, those on its right take b (c, and a cap's apex, go), both at the
//    cycle's centre; the six triangles with two vertices on the cycle go.
//    Every vertex around must keep one closed fan of at least three
//    triangles; a cap closes its side, otherwise the component splits in two
//    (or loses a handle) that touch at one point, as the zero set does. Six
//    triangles fewer; the Euler characteristic is kept for a cap and grows by
//    2 otherwise.
// After the noise removal below (so that a component that is noise still
// goes whole, and meshes the rounds above leave clean are not touched), the
// needles left in the larger components may merge their cluster:
//  - 5. a needle whose short edge (a, b) fails the link condition because a
//    and b share neighbours besides the two opposite vertices, a fraction of
//    a cell away (beyond the cut's reach: YT10's pinches at creases, where
//    the anisotropic kernels' sharp edges meet a grid vertex, often with a
//    cap of degree three). The cluster (a, b, the shared neighbours within
//    a quarter of the needle's long edge, and what is joined to them by
//    edges below sin(1 degree) times it) is merged: the triangles with two
//    or three vertices in it go; those with one form loops of their
//    opposite edges around it, and each loop keeps one of its vertices, all
//    at the cluster's centre or at one of its vertices (the best). When no
//    such common point works (YT10's needles beside triangles of just over
//    a degree, which every such point makes bad or turns over), each loop's
//    vertex gets a point of its own: the best for the loop's triangles among
//    the centre, the cluster's vertices, their pairwise midpoints and the
//    centre of the loop's own cluster vertices, else the first that works
//    found by a pattern search (axis steps, halved when none helps) that
//    maximizes the least margin of the loop's good triangles to the rules'
//    limits, within a quarter of the needle's long edge of the centre. One
//    loop: a collapse of several vertices (the topology is kept); more: a
//    cut, the parts touching at a point (or nearly, with points of their
//    own). When the shared neighbours lie near the needle's far vertex
//    instead (a strip of slivers between two pinches, YT10's sheets thinner
//    than a cell), both ends are merged at once, each at its centre (else
//    each loop vertex in turn at a point of its own, found as above); a
//    vertex between the pinches joined to both ends on both of its sides
//    has two triangles that fold onto one another: both go (the strip is
//    cut through). As in the last round, a triangle that was bad may stay
//    bad (its normal is noise) and one that was degenerate may stay
//    degenerate; every vertex around keeps one closed fan.
// Every repair must make the bad triangle good (or remove it), keep every
// good triangle good, create no degenerate triangle (but for the last
// resorts in 3. and 5.), and turn no triangle's normal beyond the round's limit.
// Vertices on a boundary, non-manifold or misoriented edge are left alone, so
// an open or broken input is never made worse. Orientation is kept by
// construction (collapses and cuts rename vertices, flips keep the quad's
// boundary direction).
//
// What no repair of the three rounds could fix and is only noise is
// removed, whole connected components at a time (the rest of the mesh is
// untouched), before 5.:
//  - components made of degenerate triangles only (a speck where the field
//    barely dips below zero at one grid vertex);
//  - given the cell size, components that still hold a bad triangle, have
//    at most kSmallComponentTriangles triangles and enclose less than
//    kSmallComponentCells cells (cell^3): droplets the grid cannot resolve
//    (such as a flat ZB05 droplet of 22 triangles and 0.3 cell^3).
//    CleanupResult counts their triangles.
// Cost: the adjacency and one scan of every triangle run on all host
// threads (or come prebuilt with the mesh from the GPU: mesh_incidence.hpp;
// whether a vertex is regular is found only for the vertices the
// repairs ask about); after that only the bad triangles and
// what the repairs changed are looked at again (each pass, on all host
// threads from 1024 items), and only the components of the bad
// triangles left are walked (serially). A bad triangle whose repair failed
// is not tried again in the round's later passes while no vertex of its
// region (below) changes: its repair would fail again (exactly: see
// start_times).
//
// The passes after the move rounds go in a fixed order (worst triangle
// first, then by index), so the result depends only on the input mesh: the
// same on every backend and thread count. That serial order defines the
// passes' result; a pass of the repairs runs
// on the host threads (from kParallelMinItems bad triangles per thread; the
// cluster merges of 5. always serially) by deterministic reservations and
// gives exactly the serial pass' mesh: in rounds, each of the next items of
// the list computes its region (the vertices whose positions or triangles
// its repair may read or write: its triangle's vertices and their
// one-rings, a needle's widening cluster and its one-ring, in the last
// round a pinched tube's third vertices' one-rings) and reserves it with
// its place in the list; an item holding its whole region commits, in
// parallel with the other such items, and the others wait for the next
// round, so each item runs after every earlier item whose region meets
// its own (a waiting item keeps its region unless an item that wrote
// something committed beside it). A stamp per vertex (the last item that committed with it in its
// region) catches a region that grew, after a later item committed beside
// it, into that item's; the pass is then undone (per-thread undo logs) and
// run serially. A vertex's list of triangles may still name one that a
// flip, cut or merge took from it and that another thread rewrites in the
// same round: the repairs write the triangles' vertices and alive flags,
// and fan() reads them, through relaxed atomics (see fan()), so that such a
// read, whose value does not matter, is no data race. Counts and changed
// lists are per thread and merged after each round; the next pass' list is
// sorted, so their order does not matter. In the output the places of the
// removed triangles and of the vertices no triangle uses (also the
// input's) are filled with the last surviving ones (compact()); every other
// entry stays where it was.
#pragma once

#include "mesh_check.hpp"
#include "mesh_incidence.hpp"
#include "mesh_moves.hpp"
#include "parallel.hpp"
#include "params.hpp"
#include "repair_scratch.hpp"
#include "trace.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iterator>
#include <memory>
#include <mutex>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

namespace nbmc {
namespace mesh {

// Largest turn of a triangle's normal that a repair may cause: 60 degrees
// (kCosMaxNormalTurn, in mesh_moves.hpp), then for the triangles still bad
// after that:
constexpr double kCosMaxNormalTurnLast = 0.0;  // 90 degrees
// Passes over the bad triangles (each pass repairs what the previous one
// could not, after its neighbours changed).
constexpr int kCleanupPasses = 8;
// Components that still hold a bad triangle after every repair are removed
// when they enclose less than this many marching-cubes cells (cell^3).
constexpr double kSmallComponentCells = 1.0;
// ... and hold at most this many triangles (a droplet of one cell^3 has a few
// dozen; a larger component, such as a thin sheet with little volume, stays).
constexpr std::size_t kSmallComponentTriangles = 4096;

struct CleanupResult {
  std::uint64_t collapses = 0, flips = 0, moves = 0;
  std::uint64_t cuts = 0;  // pinched tubes cut
  std::uint64_t small_component_triangles = 0;  // in droplets below kSmallComponentCells, removed
  std::uint64_t degenerate_component_triangles = 0;  // in specks of degenerate triangles alone, removed
  std::uint64_t removed_triangles = 0, removed_vertices = 0;
  std::uint64_t bad_before = 0;  // degenerate + sliver triangles of the input
  std::uint64_t bad_after = 0;   // of the output
};

namespace detail {

// For the tests: repair_pass runs on several threads from this many bad
// triangles per thread (the library: Cleaner::kParallelMinItems), as does
// bad_triangles_after from this many items looked at (Cleaner::kListMinItems),
// and, when undo_after_round > 0, undoes its pass after that round (as when a
// region grew) and runs it serially.
struct RepairPassHooks {
  std::size_t min_items = 0;  // 0: kParallelMinItems
  std::size_t undo_after_round = 0;
  std::size_t prefix_per_thread = 0;  // items per thread in a round (0: kPrefixPerThread)
  // Check that every write of a committed repair (positions, normals,
  // triangles' old and new vertices, removed triangles' vertices, merge
  // chains) lies in its region; writes outside are counted here.
  bool check_writes = false;
  std::uint64_t writes_outside = 0;
  // What the parallel passes did while min_items > 0 (added to): passes,
  // rounds, items that lost, lost items' regions kept for the next round,
  // passes undone and run serially (a stamp of a later item found).
  std::uint64_t parallel_passes = 0, rounds = 0, lost = 0, kept_regions = 0, undone = 0;
  // Items skipped because their earlier failure must repeat (added to,
  // always). With check_skips, such an item is repaired anyway and counted
  // in skip_mismatches if that succeeds (it must never).
  bool check_skips = false;
  std::uint64_t skipped = 0, skip_mismatches = 0;
  // Entries bad_triangles_after looked at while min_items > 0 (added to):
  // the list before, the changed vertices and triangles; the same at any
  // thread count.
  std::uint64_t looked_at = 0;
  // bad_triangles_after leaves out the fans of the vertices whose repair
  // judged every triangle around them (judged_vertices_). With check_lists
  // it also makes the list with them and counts each pass whose two lists
  // differ in list_mismatches (added to; it must stay 0).
  bool check_lists = false;
  std::uint64_t list_mismatches = 0;
  // The compaction as compact_mesh does it (everything kept in its order)
  // instead of filling the removed entries' places from the end.
  bool compact_in_order = false;
};
inline RepairPassHooks& repair_pass_hooks() {
  static RepairPassHooks hooks;
  return hooks;
}

// repair_pass' rounds: all of its threads wait here until each has come
// (spinning a little, then yielding: a round's steps are short).
class SpinBarrier {
 public:
  explicit SpinBarrier(std::size_t n) : n_(n) {}
  void wait() {
    const std::size_t gen = gen_.load(std::memory_order_acquire);
    if (count_.fetch_add(1, std::memory_order_acq_rel) + 1 == n_) {
      count_.store(0, std::memory_order_relaxed);
      gen_.fetch_add(1, std::memory_order_release);
      return;
    }
    for (int spin = 0; gen_.load(std::memory_order_acquire) == gen; ++spin)
      if (spin > 64) std::this_thread::yield();
  }

 private:
  std::size_t n_;
  std::atomic<std::size_t> count_{0}, gen_{0};
};

// The heads of the lists of triangles added to vertices (Cleaner::
// add_incidence: after flips, cuts and merges), by vertex. A few hundred
// vertices get one in a clean-up of a million, so a small open-addressed
// table, not an array per vertex: nothing to fill for each clean-up, and
// fan()'s look-up, for every vertex it walks, stays in the cache. Written
// only while nothing reads it (between a parallel pass' rounds, on the main
// thread, or in a serial pass).
class ExtraHeads {
 public:
  static constexpr std::uint32_t kNone = 0xffffffffu;
  // v's head (kNone: none).
  std::uint32_t get(std::uint32_t v) const {
    if (size_ == 0) return kNone;
    for (std::size_t h = slot(v);; h = (h + 1) & (table_.size() - 1)) {
      const std::pair<std::uint32_t, std::uint32_t>& e = table_[h];
      if (e.first == v) return e.second;
      if (e.first == kNone) return kNone;
    }
  }
  void set(std::uint32_t v, std::uint32_t head) {
    if (2 * (size_ + 1) > table_.size()) grow();
    for (std::size_t h = slot(v);; h = (h + 1) & (table_.size() - 1)) {
      std::pair<std::uint32_t, std::uint32_t>& e = table_[h];
      if (e.first == v) {
        e.second = head;
        return;
      }
      if (e.first == kNone) {
        e = {v, head};
        ++size_;
        return;
      }
    }
  }

 private:
  std::size_t slot(std::uint32_t v) const {
    return std::size_t((std::uint64_t(v) * 0x9e3779b97f4a7c15ull) >> (64 - bits_));
  }
  void grow() {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> old(std::max<std::size_t>(64, 2 * table_.size()),
                                                           {kNone, kNone});
    old.swap(table_);
    bits_ = 0;
    while ((std::size_t(1) << bits_) < table_.size()) ++bits_;
    size_ = 0;
    for (const auto& e : old)
      if (e.first != kNone) set(e.first, e.second);
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> table_;  // (vertex, head); kNone: empty
  std::size_t size_ = 0;
  int bits_ = 0;  // table_.size() is 2^bits_
};

// Real: the positions' scalar (float, or double with
// nbmc_params.double_positions); normals are float either way.
template <class Real>
class Cleaner {
 public:
  // prebuilt: the incidence and the maybe-bad bits of this mesh, built
  // where it was made (mesh_incidence.hpp; may be null). Taken (moved
  // from) when its sizes fit the mesh. track_changes: keep what the repairs
  // write (changed_entries).
  Cleaner(Real* positions, float* normals, std::size_t nv, std::uint32_t* tri, std::size_t nt,
          PrebuiltIncidence* prebuilt = nullptr, bool track_changes = false)
      : P_(positions), N_(normals), nv_(nv), T_(tri), nt_(nt), alive_own_(nt), irregular_own_(nv), next_own_(nv),
        tail_own_(nv), expanded_(nv) {
    if (track_changes) {  // (unwritten: cleared below with the other arrays)
      vchanged_own_.resize(nv);
      tchanged_own_.resize(nt);
      vchanged_ = vchanged_own_.data();
      tchanged_ = tchanged_own_.data();
    }
    // The per-triangle and per-vertex arrays are left unwritten by their
    // allocation and filled here on all host threads: the kernel maps (and
    // clears) a fresh array's pages when they are first written, a few
    // microseconds per 4 KiB page, which one thread writing them all (as a
    // value-initialized std::vector does) pays alone. Each vertex chunk also
    // finds its part of the bounding box.
    // (alive_ and state_ are filled by the triangle round of the incidence
    // build below.)
    const std::size_t vchunks = chunk_count(nv, 65536);
    std::vector<std::array<double, 6>> box(vchunks);  // lo, hi
    // A prebuilt incidence's lists bounds are looked at here: the vertices
    // without a triangle (bare_, for compact()).
    const bool take = prebuilt && prebuilt->fits(nv, nt);
    std::vector<std::vector<std::uint32_t>> bare(vchunks);
    for_chunks(nv, vchunks, [&](std::size_t k, std::size_t b, std::size_t e) {
      for (std::size_t v = b; v < e; ++v) {
        next_[v] = kNone;
        tail_[v] = std::uint32_t(v);
        irregular_[v] = kFanUnknown;  // (found when first asked: irregular())
        expanded_[v] = 0;
      }
      if (take)
        for (std::size_t v = b; v < e; ++v)
          if (prebuilt->start[v] == prebuilt->start[v + 1]) bare[k].push_back(std::uint32_t(v));
      if (vchanged_) std::fill(vchanged_ + b, vchanged_ + e, std::uint8_t(0));
      // As bounding_extent: every chunk starts from vertex 0 (so a NaN
      // coordinate is ignored, or not, exactly as in its serial loop).
      if (nv == 0) return;  // (one empty chunk; no vertex 0 to read)
      std::array<double, 6>& x = box[k];
      for (int a = 0; a < 3; ++a) x[a] = x[3 + a] = positions[a];
      for (std::size_t v = b; v < e; ++v)
        for (int a = 0; a < 3; ++a) {
          x[a] = std::min(x[a], double(positions[3 * v + a]));
          x[3 + a] = std::max(x[3 + a], double(positions[3 * v + a]));
        }
    });
    double extent = 0;
    if (nv > 0) {
      std::array<double, 6> x = box[0];
      for (std::size_t k = 1; k < vchunks; ++k)
        for (int a = 0; a < 3; ++a) {
          x[a] = std::min(x[a], box[k][a]);
          x[3 + a] = std::max(x[3 + a], box[k][3 + a]);
        }
      extent = std::max({x[3] - x[0], x[4] - x[1], x[5] - x[2]});
    }
    degenerate_double_area_ = 2 * kDegenerateAreaFraction * extent * extent;
    // (The moves made where the mesh was made judged with the extent before
    // them, as move_rounds here does: the same area from here on.)
    if (prebuilt && prebuilt->moves_made) degenerate_double_area_ = prebuilt->degenerate_double_area;
    for (const auto& x : bare) bare_.insert(bare_.end(), x.begin(), x.end());
    host_trace("clean-up: arrays, extent", nv);
    if (take) {
      // The lists as they are; the first scan classifies only the
      // triangles whose bit is set (add_if_bad: the same list).
      const std::uint32_t* bits = prebuilt->maybe_bad.data();
      const std::size_t tparts = chunk_count(nt, 16384);
      std::vector<BadList> bad(tparts);
      state_.resize(nt);  // (unwritten: cleared here by each thread for its triangles)
      for_chunks(nt, tparts, [&](std::size_t k, std::size_t b, std::size_t e) {
        std::fill(alive_.begin() + b, alive_.begin() + e, std::uint8_t(1));
        std::fill(state_.begin() + b, state_.begin() + e, kUnseen);
        if (tchanged_) std::fill(tchanged_ + b, tchanged_ + e, std::uint8_t(0));
        for (std::size_t t = b; t < e;) {  // (the set bits of [b, e), a word at a time)
          const std::uint32_t w = bits[t >> 5] >> (t & 31);
          if (w == 0) {
            t = (t | 31) + 1;
            continue;
          }
          t += std::size_t(__builtin_ctz(w));
          if (t >= e) break;
          add_if_bad(std::uint32_t(t), bad[k]);
          ++t;
        }
      });
      host_trace("clean-up: flags, maybe-bad triangles", nt);
      set_initial_bad(bad);
      start_ = std::move(prebuilt->start);
      incident_ = std::move(prebuilt->incident);
      prebuilt->clear();
      host_trace("clean-up: prebuilt incidence", nt);
      return;
    }
    // Triangles around each vertex (CSR, ascending triangle index), on all
    // host threads without atomics: each thread sorts the corners of its
    // range of triangles by vertex range (a count, then a copy into one array
    // ordered by vertex range, then triangle range), and each thread fills
    // the lists of its vertex range from its part of that array, in triangle
    // order by construction. With one vertex range (one thread), the corners
    // in that order are those of tri itself: no count and no copy. The copy
    // round also fills alive_ and scans its triangles for the first list of
    // bad ones (bad_triangles' scan, fused: tri is read once).
    {
      // Vertex ranges of 2^shift vertices (a shift, not a division, per
      // corner), about 8 per thread: the list round gives each thread a
      // run of them (one range per thread, a power of two, left them
      // uneven: 62/38 % of the vertices on 2 threads, 13 ranges on 16).
      const std::size_t want = std::max(chunk_count(nt, 16384), chunk_count(nv, 16384));
      const std::size_t per_thread = want > 1 ? 8 : 1;
      int shift = 0;
      while ((std::size_t(1) << shift) * want * per_thread < nv) ++shift;
      const std::size_t parts = std::max<std::size_t>(1, (nv + (std::size_t(1) << shift) - 1) >> shift);
      const std::size_t groups = std::min(want, parts);  // the list round's threads
      const std::size_t tparts = want;  // triangle ranges
      const bool sorted = parts > 1;    // false: corner i is i itself
      std::vector<std::size_t> at(parts * tparts + 1, 0);  // [vertex range][triangle range]
      if (sorted) {
        for_chunks(nt, tparts, [&](std::size_t k, std::size_t b, std::size_t e) {
          std::vector<std::size_t> n(parts, 0);
          for (std::size_t i = 3 * b; i < 3 * e; ++i)
            if (tri[i] < nv) ++n[tri[i] >> shift];
          for (std::size_t r = 0; r < parts; ++r) at[r * tparts + k + 1] = n[r];
        });
        for (std::size_t i = 0; i < parts * tparts; ++i) at[i + 1] += at[i];
      }
      // A corner is its index in tri (3 t + c, 32 bits as incident_'s
      // offsets): its vertex is read again from tri, its triangle is a
      // third of it. Half the bytes of storing both (fewer fresh pages to
      // map, less to write and read back), and tri's reads stay local.
      std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> corners(sorted ? at[parts * tparts] : 0);
      std::vector<BadList> bad(tparts);
      state_.resize(nt);  // (unwritten: cleared here by each thread for its triangles)
      for_chunks(nt, tparts, [&](std::size_t k, std::size_t b, std::size_t e) {
        std::fill(alive_.begin() + b, alive_.begin() + e, std::uint8_t(1));
        std::fill(state_.begin() + b, state_.begin() + e, kUnseen);
        if (tchanged_) std::fill(tchanged_ + b, tchanged_ + e, std::uint8_t(0));
        if (sorted) {
          std::vector<std::size_t> w(parts);
          for (std::size_t r = 0; r < parts; ++r) w[r] = at[r * tparts + k];
          for (std::size_t i = 3 * b; i < 3 * e; ++i) {
            const std::uint32_t v = tri[i];
            if (v < nv) corners[w[v >> shift]++] = std::uint32_t(i);
          }
        }
        // (As bad_triangles(), every triangle alive.)
        for (std::size_t t = b; t < e; ++t) {
          const std::uint32_t* v = tri + 3 * t;
          if (surely_good(load(P_, v[0]), load(P_, v[1]), load(P_, v[2]), degenerate_double_area_)) continue;
          add_if_bad(std::uint32_t(t), bad[k]);
        }
      });
      set_initial_bad(bad);
      host_trace("clean-up: incidence corners", nt);
      // (start_ unwritten: each thread clears its own range of it.)
      start_.resize(nv + 1);
      start_[0] = 0;
      if (sorted) incident_.resize(corners.size());
      bare.assign(groups, {});
      on_threads(groups, [&](std::size_t g) {
        // (Ranges [r0, r1): their corners lie together, by range, then
        // triangle range, so in triangle order for each vertex.)
        const std::size_t r0 = parts * g / groups, r1 = parts * (g + 1) / groups;
        const std::size_t vb = r0 << shift, ve = std::min(nv, r1 << shift);
        const std::size_t cb = sorted ? at[r0 * tparts] : 0, ce = sorted ? at[r1 * tparts] : 3 * nt;
        auto corner = [&](std::size_t i) { return sorted ? corners[i] : std::uint32_t(i); };
        std::fill(start_.begin() + vb + 1, start_.begin() + ve + 1, 0u);
        for (std::size_t i = cb; i < ce; ++i) {
          const std::uint32_t v = tri[corner(i)];
          if (sorted || v < nv) ++start_[v + 1];
        }
        // (start_[vb] belongs to the range before: its lists start at cb.)
        std::vector<std::uint32_t> fill(ve - vb);
        std::size_t pos = sorted ? cb : 0;
        for (std::size_t v = vb; v < ve; ++v) {
          fill[v - vb] = std::uint32_t(pos);
          if (start_[v + 1] == 0) bare[g].push_back(std::uint32_t(v));  // (no triangle: compact())
          pos += start_[v + 1];
          start_[v + 1] = std::uint32_t(pos);
        }
        if (!sorted) incident_.resize(pos);  // (one range, one thread: this one)
        for (std::size_t i = cb; i < ce; ++i) {
          const std::uint32_t c = corner(i), v = tri[c];
          if (sorted || v < nv) incident_[fill[v - vb]++] = c / 3;
        }
      });
      for (const auto& x : bare) bare_.insert(bare_.end(), x.begin(), x.end());
      host_trace("clean-up: incidence lists", nt);
    }
  }

  // A worker of repair_pass: the main Cleaner's mesh and arrays, its own
  // scratch, counts, changed lists and undo log.
  struct WorkerTag {};
  Cleaner(Cleaner& m, WorkerTag)
      : P_(m.P_), N_(m.N_), nv_(m.nv_), T_(m.T_), nt_(m.nt_), alive_(m.alive_own_), irregular_(m.irregular_own_),
        start_(m.start_own_), next_(m.next_own_), tail_(m.tail_own_), incident_(m.incident_own_),
        extra_head_(m.extra_head_own_), extra_(m.extra_own_), degenerate_double_area_(m.degenerate_double_area_),
        worker_(true), repair_scratch_(m.repair_scratch_own_), vchanged_(m.vchanged_), tchanged_(m.tchanged_) {}
  Cleaner(const Cleaner&) = delete;
  Cleaner& operator=(const Cleaner&) = delete;
  // The repair passes' scratch goes back to the pool for the next clean-up.
  ~Cleaner() {
    if (repair_scratch_own_) RepairScratchPool::instance().give(std::move(repair_scratch_own_));
  }

  std::uint64_t collapses = 0, flips = 0, moves = 0, cuts = 0;
  // Largest turn of a triangle's normal a repair may cause (cosine).
  double cos_limit = kCosMaxNormalTurn;
  // The last round: a collapse may leave degenerate triangles degenerate,
  // and pinched tubes may be cut.
  bool last_resort = false;
  // After the last round: needles whose short edge fails the link
  // condition may merge their cluster (consider_cluster).
  bool merge_clusters = false;

  using BadList = std::vector<std::tuple<int, double, std::uint32_t>>;
  // Adds triangle t to `out` as (-class, sin of its smallest angle, t) when
  // it is alive and bad.
  void add_if_bad(std::uint32_t t, BadList& out) const {
    if (!alive_[t]) return;
    const TriangleShape s = shape(t);
    const int c = triangle_class(s, degenerate_double_area_);
    if (c) out.emplace_back(-c, s.sin_min_angle, t);
  }

  // The parts' entries as one sorted list, on the host threads: each part
  // sorted, then merged pairwise in rounds. The same list as one std::sort
  // of them all (the order of distinct entries is total; equal ones are
  // equal). One serial sort of the 1.65 M frame's 9,772 first bad
  // triangles took 0.9 ms on an H200 machine's host (bench/RESULTS.md,
  // session 36).
  static BadList sorted_union(std::vector<BadList>& parts) {
    for_chunks(parts.size(), chunk_count(parts.size(), 1), [&](std::size_t, std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) std::sort(parts[i].begin(), parts[i].end());
    });
    while (parts.size() > 1) {
      std::vector<BadList> next((parts.size() + 1) / 2);
      for_chunks(next.size(), chunk_count(next.size(), 1), [&](std::size_t, std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) {
          if (2 * i + 1 == parts.size()) {
            next[i] = std::move(parts[2 * i]);
            continue;
          }
          const BadList &x = parts[2 * i], &y = parts[2 * i + 1];
          next[i].resize(x.size() + y.size());
          std::merge(x.begin(), x.end(), y.begin(), y.end(), next[i].begin());
        }
      });
      parts.swap(next);
    }
    return parts.empty() ? BadList() : std::move(parts[0]);
  }
  // The constructor's scan: its threads' lists, as one sorted list.
  void set_initial_bad(std::vector<BadList>& parts) {
    initial_bad_ = sorted_union(parts);
    has_initial_bad_ = true;
  }
  // The constructor's scan (the same list as bad_triangles() before any
  // repair), once; then bad_triangles().
  BadList initial_bad_triangles() {
    if (!has_initial_bad_) return bad_triangles();
    has_initial_bad_ = false;
    return std::move(initial_bad_);
  }
  // Bad triangles now: (class, sin of the smallest angle, index), worst first.
  // (A scan on all host threads; the sort makes the list independent of them.)
  BadList bad_triangles() const {
    const std::size_t chunks = chunk_count(nt_, 16384);
    std::vector<std::vector<std::tuple<int, double, std::uint32_t>>> part(chunks);
    for_chunks(nt_, chunks, [&](std::size_t k, std::size_t b, std::size_t e) {
      for (std::size_t t = b; t < e; ++t) {
        if (!alive_[t]) continue;
        const std::uint32_t* v = T_ + 3 * t;
        if (surely_good(load(P_, v[0]), load(P_, v[1]), load(P_, v[2]), degenerate_double_area_)) continue;
        add_if_bad(std::uint32_t(t), part[k]);
      }
    });
    return sorted_union(part);
  }

  // bad_triangles_after's chunks: at least this many items each (a changed
  // vertex's fan and classes cost about 0.3 us: a chunk of 1024 about
  // 0.3 ms; after the first pass of the 1.65 M frame at r/2, 20-25 k items,
  // 4096 left 10 of 16 threads idle).
  static constexpr std::size_t kListMinItems = 1024;
  // The same list as bad_triangles(), from the list before the repairs
  // since (`before`) and what they changed: a triangle that was good and
  // whose vertices neither moved nor were renamed is still good, so only the
  // triangles of `before` and those around the changed vertices (and the
  // flipped ones) are looked at again. A full scan costs about 40 ns per
  // triangle of the mesh; this, the same per triangle of the repairs'
  // neighbourhoods. The fans of the vertices that moves and collapses moved
  // (judged_vertices_, nearly all of the changed ones) are not looked at:
  // those repairs judged every triangle of the fan with the arithmetic of
  // add_if_bad (the positions rounded as stored, the corners in the
  // triangle's order) and leave none bad that was good, so a bad triangle
  // there was bad before the pass, and `before` (every bad triangle then)
  // holds it. (A cut or a cluster merge judges less: their vertices' fans
  // are looked at.)
  BadList bad_triangles_after(const BadList& before) {
    RepairPassHooks& hooks = repair_pass_hooks();
    if (hooks.check_lists) {  // (a test's: the list with the judged fans too)
      std::vector<std::uint32_t> kept = changed_vertices_;
      changed_vertices_.insert(changed_vertices_.end(), judged_vertices_.begin(), judged_vertices_.end());
      const std::vector<std::uint32_t> triangles = changed_triangles_;
      const std::uint64_t looked_at = hooks.looked_at;
      const BadList full = list_after(before);
      hooks.looked_at = looked_at;
      changed_vertices_ = std::move(kept);
      changed_triangles_ = triangles;
      judged_vertices_.clear();
      BadList bad = list_after(before);
      if (bad != full) ++hooks.list_mismatches;
      return bad;
    }
    judged_vertices_.clear();
    return list_after(before);
  }
  // bad_triangles_after's list from `before` and changed_vertices_' fans.
  BadList list_after(const BadList& before) {
    // On several host threads: each chunk of what is looked at (the
    // triangles of `before`, the fans of the changed vertices, the changed
    // triangles) lists its bad triangles, a triangle looked at twice twice;
    // sorted and made unique, the same list.
    const std::size_t nb = before.size(), ncv = changed_vertices_.size(), nct = changed_triangles_.size();
    const std::size_t total = nb + ncv + nct;
    const std::size_t min_items = repair_pass_hooks().min_items;
    if (min_items > 0) repair_pass_hooks().looked_at += total;  // (a test's, as in repair_pass)
    const std::size_t chunks = chunk_count(total, min_items > 0 ? min_items : kListMinItems);
    if (chunks > 1) {
      std::vector<BadList> part(chunks);
      // (Each chunk asks for the lines of its next items a few ahead:
      // prefetch_region's steps, which took the list after the 1.65 M
      // frame's first pass from 7.0-7.6 to 4.7-5.0 ms on the dev VM's two
      // threads.)
      for_chunks(total, chunks, [&](std::size_t k, std::size_t b, std::size_t e) {
        std::vector<std::uint32_t> f;
        BadList& out = part[k];
        for (std::size_t i = b; i < e; ++i) {
          if (i < nb) {
            if (i + 4 < nb) prefetch_region(std::get<2>(before[i + 4]), 0);
            if (i + 2 < nb) prefetch_corners(std::get<2>(before[i + 2]));
            add_if_bad(std::get<2>(before[i]), out);
          } else if (i < nb + ncv) {
            const std::size_t c = i - nb;
            if (c + 4 < ncv) prefetch_vertex(changed_vertices_[c + 4], 1);
            if (c + 2 < ncv) prefetch_vertex(changed_vertices_[c + 2], 2);
            fan(changed_vertices_[c], f);
            for (std::uint32_t t : f) add_if_bad(t, out);
          } else add_if_bad(changed_triangles_[i - nb - ncv], out);
        }
      });
      changed_vertices_.clear();
      changed_triangles_.clear();
      BadList bad = sorted_union(part);
      bad.erase(std::unique(bad.begin(), bad.end()), bad.end());
      return bad;
    }
    std::vector<std::uint32_t> look;
    look.reserve(before.size() + 8 * changed_vertices_.size() + changed_triangles_.size());
    for (const auto& b : before) look.push_back(std::get<2>(b));
    for (std::uint32_t v : changed_vertices_) {
      fan(v, scratch_);
      look.insert(look.end(), scratch_.begin(), scratch_.end());
    }
    look.insert(look.end(), changed_triangles_.begin(), changed_triangles_.end());
    changed_vertices_.clear();
    changed_triangles_.clear();
    std::sort(look.begin(), look.end());
    look.erase(std::unique(look.begin(), look.end()), look.end());
    BadList bad;
    for (std::uint32_t t : look) add_if_bad(t, bad);
    std::sort(bad.begin(), bad.end());
    return bad;
  }
  // The triangles of `before` still alive (after removals, which change no
  // shape).
  BadList alive_of(const BadList& before) const {
    BadList bad;
    for (const auto& b : before)
      if (alive_[std::get<2>(b)]) bad.push_back(b);
    return bad;
  }

  bool repair(std::uint32_t t) {
    if (!alive_[t] || tri_class(t) == 0) return false;
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    for (int k = 0; k < 3; ++k)
      if (irregular(v[k])) return false;
    // First what keeps every triangle: moving a vertex, flipping an edge.
    Candidate best;
    // The shortest move of each vertex that works (a quarter, half or all
    // the way), the best of the three vertices.
    for (int k = 0; k < 3; ++k) {
      Candidate c;
      consider_move(t, v[k], c);
      if (c.valid && c.score > best.score) best = std::move(c);
    }
    consider_flip(t, best);
    if (!best.valid) consider_push(t, best);
    if (best.valid) {
      if (best.kind == Candidate::Flip) apply_flip(best);
      else apply_move(best);
      return true;
    }
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = v[k], b = v[(k + 1) % 3];
      CollapseSite site;
      if (!collapse_site(a, b, site)) continue;
      const Vec3 pa = load(P_, a), pb = load(P_, b);
      const Vec3 targets[3] = {0.5 * (pa + pb), pa, pb};
      for (int w = 0; w < 3; ++w) consider_collapse(site, targets[w], w, best);
    }
    if (best.valid) {
      apply_collapse(best);
      return true;
    }
    // Last, a needle in a pinched tube: cut the tube (in the last round
    // only, when nothing else worked).
    if (!last_resort) return false;
    CutCandidate cut;
    consider_cut(t, cut);
    if (cut.valid) {
      apply_cut(cut);
      return true;
    }
    // After that round, a needle in a pinched cluster: merge the cluster,
    // one vertex per loop around it.
    if (!merge_clusters) return false;
    ClusterCandidate m;
    consider_cluster(t, m);
    if (!m.valid) return false;
    apply_cluster(m);
    return true;
  }

  // The move rounds (mesh_moves.hpp) over the bad triangles `bad` of the
  // mesh as it came (every triangle alive, the lists as built), on the host
  // threads; returns the bad triangles left (the list a scan would give).
  // The reservations are the repair scratch's (all free before and after).
  BadList move_rounds(const BadList& bad) {
    const std::size_t n = bad.size();
    if (n == 0) return bad;
    const bool trace = host_trace_on();
    using Clock = std::chrono::steady_clock;
    if (!repair_scratch_) repair_scratch_ = RepairScratchPool::instance().take(nv_);
    RepairScratch& scratch = *repair_scratch_;
    RepairSlot* const slots = scratch.slots.data();
    MoveMesh<Real> mm;
    mm.P = P_;
    mm.T = T_;
    mm.start = start_.data();
    mm.incident = incident_.data();
    mm.degenerate_double_area = degenerate_double_area_;
    mm.cos_limit = kCosMaxNormalTurn;
    std::vector<std::uint32_t> cur(n), next;  // the waiting triangles
    for (std::size_t i = 0; i < n; ++i) cur[i] = std::get<2>(bad[i]);
    std::vector<MoveProposal> prop;
    std::vector<std::uint8_t> state;  // 0 waits, 1 leaves, 2 proposes, 3 moves
    const std::size_t min_items = repair_pass_hooks().min_items;
    auto take = [&](std::uint32_t x, std::uint32_t t) {
      std::atomic<std::uint32_t>& r = slots[x].reserve;
      std::uint32_t old = r.load(std::memory_order_relaxed);
      while (t < old && !r.compare_exchange_weak(old, t, std::memory_order_relaxed)) {
      }
    };
    auto held = [&](std::uint32_t x) { return slots[x].reserve.load(std::memory_order_relaxed); };
    // (The reservations as plain words, for neighbour_taken_before, which
    // reads them in a step that writes none.)
    static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t) &&
                      sizeof(RepairSlot) % sizeof(std::uint32_t) == 0 && offsetof(RepairSlot, reserve) == 0,
                  "a reservation is a plain word at the start of its slot");
    const std::uint32_t* const reserved = reinterpret_cast<const std::uint32_t*>(slots);
    scratch.clean = false;  // (until the rounds end: see RepairScratchPool::give)
    std::uint64_t made = 0;
    while (!cur.empty()) {
      const Clock::time_point r0 = trace ? Clock::now() : Clock::time_point();
      const std::size_t m = cur.size();
      const std::size_t threads = chunk_count(m, min_items > 0 ? min_items : kParallelMinItems);
      prop.resize(m);
      state.assign(m, 0);
      // (Blocks of items handed out as they come: the items' costs differ.)
      constexpr std::size_t kBlock = 16;
      std::atomic<std::size_t> cursor{0};
      auto each = [&](const auto& f) {
        cursor.store(0, std::memory_order_relaxed);
        on_threads(threads, [&](std::size_t) {
          for (std::size_t b; (b = cursor.fetch_add(kBlock, std::memory_order_relaxed)) < m;)
            for (std::size_t i = b, e = std::min(m, b + kBlock); i < e; ++i) f(i);
        });
      };
      // 1. Each triangle's vertices take the smallest index.
      each([&](std::size_t i) {
        const std::uint32_t* v = T_ + 3 * std::size_t(cur[i]);
        for (int k = 0; k < 3; ++k) take(v[k], cur[i]);
      });
      // 2. Those holding all three decide; then the vertices are freed.
      each([&](std::size_t i) {
        const std::uint32_t t = cur[i];
        const std::uint32_t* v = T_ + 3 * std::size_t(t);
        for (int k = 0; k < 3; ++k)
          if (held(v[k]) != t) return;
        state[i] = std::uint8_t(evaluate_move(mm, t, prop[i]));
      });
      each([&](std::size_t i) {
        const std::uint32_t* v = T_ + 3 * std::size_t(cur[i]);
        for (int k = 0; k < 3; ++k) slots[v[k]].reserve.store(kNone, std::memory_order_relaxed);
      });
      // 3. Each proposal's vertex takes the smallest proposing index; a
      // proposal holding its vertex, with no neighbour of it held by a
      // smaller index, is made.
      each([&](std::size_t i) {
        if (state[i] == std::uint8_t(MoveVerdict::Propose)) take(prop[i].v, cur[i]);
      });
      each([&](std::size_t i) {
        if (state[i] != std::uint8_t(MoveVerdict::Propose)) return;
        const std::uint32_t t = cur[i], v = prop[i].v;
        if (held(v) == t && !neighbour_taken_before(mm, v, t, reserved, sizeof(RepairSlot) / sizeof(std::uint32_t)))
          state[i] = 3;
      });
      // Made (their vertices differ), the vertices freed; 4. the losers and
      // the waiting ones go on.
      next.clear();
      std::uint64_t won = 0, waited = 0;
      for (std::size_t i = 0; i < m; ++i) {
        if (state[i] >= std::uint8_t(MoveVerdict::Propose)) slots[prop[i].v].reserve.store(kNone, std::memory_order_relaxed);
        if (state[i] == 3) {
          const std::uint32_t v = prop[i].v;
          changed_vertex(v);
          for (int a = 0; a < 3; ++a) P_[3 * std::size_t(v) + a] = Real(prop[i].p[a]);
          ++won;
        } else if (state[i] != std::uint8_t(MoveVerdict::Leave)) {
          next.push_back(cur[i]);
          waited += state[i] == 0 ? 1 : 0;
        }
      }
      made += won;
      if (trace)
        std::fprintf(stderr, "[nbmc trace]   move round: items=%zu waited=%llu moved=%llu %.3f ms\n", m,
                     (unsigned long long)waited, (unsigned long long)won,
                     std::chrono::duration<double, std::milli>(Clock::now() - r0).count());
      cur.swap(next);
    }
    scratch.clean = true;
    moves += made;
    // The bad triangles left: among those before (a move never makes a
    // good triangle bad), judged again (list_after: nothing else changed
    // yet, the rounds run before any pass).
    BadList left = list_after(bad);
    RepairPassHooks& hooks = repair_pass_hooks();
    if (hooks.check_lists && left != bad_triangles()) ++hooks.list_mismatches;  // (a test's: against a scan)
    return left;
  }

  // One pass of repair() over `bad`, in its order; returns how many were
  // repaired. Serial below kParallelMinItems items per thread (and for the
  // cluster merges); otherwise on the host threads by deterministic
  // reservations, with exactly the serial pass' result: in rounds, the
  // next items of the list (the losers of the round before, then new ones,
  // up to kPrefixPerThread per thread) each find their region (region():
  // every vertex whose position or triangles repair() may read or write
  // now) and write their place in the list into each of its vertices,
  // keeping the smallest; an item that holds all of its region runs
  // repair() (on a worker: per-thread scratch, counts, changed lists,
  // deferred incidences), in parallel with the others that do, and the
  // rest wait for the next round. So an item runs after every earlier one
  // whose region meets its own. Each vertex is stamped with the last item
  // that committed with it in its region: an item that finds in its region
  // the stamp of a later one (a region that grew after a later item
  // committed next to it) would not see the serial pass' mesh; then the
  // pass is undone (the workers' undo logs) and run again serially.
  static constexpr std::size_t kParallelMinItems = 128;
  static constexpr std::size_t kPrefixPerThread = 64;

  std::uint64_t repair_pass(const BadList& bad) {
    // (NBMC_TRACE: the main thread's time before, in and after the rounds.)
    const bool trace = host_trace_on();
    using Clock = std::chrono::steady_clock;
    const Clock::time_point setup_start = trace ? Clock::now() : Clock::time_point();
    const std::size_t n = bad.size();
    const RepairPassHooks hooks = repair_pass_hooks();
    const std::size_t threads =
        merge_clusters ? 1 : chunk_count(n, hooks.min_items > 0 ? hooks.min_items : kParallelMinItems);
    // The items' times (time_base + place) and outcomes (for the next
    // pass' skips).
    const std::uint32_t time_base = start_times(n);
    outcome_.assign(n, 0);
    skipped_ = 0;
    std::uint64_t skip_mismatches = 0;
    // repair() of item `pos` at its time, unless its failure must repeat
    // (region: repair's region now, or null to find it here).
    auto attempt = [&](Cleaner& me, std::size_t pos, const std::vector<std::uint32_t>* region) {
      const std::uint32_t t = std::get<2>(bad[pos]);
      const std::uint32_t failed_at = failed_before(t);
      if (failed_at != 0) {
        if (!region) {
          me.region(t, me.region_);
          region = &me.region_;
        }
        if (unchanged_since(*region, failed_at)) {
          if (!hooks.check_skips) {
            outcome_[pos] = failed_at;
            ++me.skipped_;
            return false;
          }
          me.now_ = time_base + std::uint32_t(pos);
          const bool ok = me.repair(t);
          if (ok) ++me.skip_mismatches_;
          outcome_[pos] = ok ? 0 : failed_at;
          ++me.skipped_;
          return ok;
        }
      }
      me.now_ = time_base + std::uint32_t(pos);
      const bool ok = me.repair(t);
      outcome_[pos] = ok ? 0 : me.now_;
      return ok;
    };
    auto finish = [&](std::uint64_t repaired) {
      record_failures(bad);
      if (hooks.min_items > 0 || hooks.check_skips) {  // (a test's, as below)
        RepairPassHooks& h = repair_pass_hooks();
        h.skipped += skipped_;
        h.skip_mismatches += skip_mismatches;
      }
      return repaired;
    };
    if (!hooks.check_skips && every_item_skips(bad)) {
      skipped_ = n;
      return finish(0);
    }
    if (threads <= 1) {
      std::uint64_t repaired = 0;
      skip_mismatches_ = 0;
      for (std::size_t pos = 0; pos < n; ++pos) {
        for (int d = 4; d >= 1; --d)  // (the lines of the next items, as in the reserve step below)
          if (pos + std::size_t(d) < n) prefetch_region(std::get<2>(bad[pos + std::size_t(d)]), 4 - d);
        repaired += attempt(*this, pos, nullptr) ? 1 : 0;
      }
      skip_mismatches = skip_mismatches_;
      return finish(repaired);
    }
    const std::uint64_t saved[4] = {collapses, flips, moves, cuts};
    // The per-vertex reservations, stamps and rounds (start_times took
    // the scratch; kept from an earlier clean-up, its stamps and rounds are
    // all below the counters). (A pass has at most n rounds: each round's
    // first item wins.)
    static_assert(RepairScratch::kFree == kNone, "a free reservation is kNone, above every place in the list");
    RepairScratch& scratch = *repair_scratch_;
    if (std::uint64_t(scratch.stamp_base) + n + 2 >= kNone || std::uint64_t(scratch.round_base) + n + 2 >= kNone)
      scratch.reset_stamps();
    RepairSlot* const slots_ = scratch.slots.data();
    const std::uint32_t base = scratch.stamp_base + 1;  // item i's stamp: base + i
    scratch.stamp_base = base + std::uint32_t(n);
    std::uint32_t round_id = scratch.round_base + 1;  // the current round's (slots_' wrote)
    while (workers_.size() < threads) workers_.emplace_back(new Cleaner(*this, WorkerTag{}));
    for (std::size_t w = 0; w < threads; ++w) {
      Cleaner& k = *workers_[w];
      k.cos_limit = cos_limit;
      k.last_resort = last_resort;
      k.merge_clusters = merge_clusters;
      k.collapses = k.flips = k.moves = k.cuts = 0;
      k.repaired_ = 0;
      k.skipped_ = k.skip_mismatches_ = 0;
      k.log_.clear();
      k.round_ends_.clear();
    }
    const std::size_t prefix = (hooks.prefix_per_thread > 0 ? hooks.prefix_per_thread : kPrefixPerThread) * threads;
    std::vector<std::uint32_t> cur, next;  // places in `bad`, ascending
    std::vector<std::vector<std::uint32_t>> reg(prefix);
    // carried[i]: reg[i] is the region item cur[i] found in the round
    // before, when it lost. It is still its region unless an item that
    // wrote something committed in that round with a vertex of it in its
    // own region (slots_' wrote): region() reads only the positions, the
    // triangles and the lists of its vertices' fans, and a repair writes
    // only within its own region (every write touches a vertex of it).
    std::vector<std::uint8_t> win(prefix), carried(prefix, 0);
    std::atomic<std::uint64_t> reused{0};
    std::size_t fresh = 0;  // the first item not yet in a round
    auto refill = [&] {
      while (cur.size() < prefix && fresh < n) cur.push_back(std::uint32_t(fresh++));
    };
    refill();
    std::atomic<bool> violation{false}, failed{false};
    std::atomic<std::uint64_t> writes_outside{0};
    bool done = false;
    std::exception_ptr error;
    std::mutex error_mutex;
    std::uint64_t repaired = 0, rounds = 0, lost = 0;
    SpinBarrier barrier(threads);
    // (NBMC_TRACE: the main thread's time in each step of the rounds.)
    double step_ms[5] = {0, 0, 0, 0, 0};  // reserve, commit, release, merge, waits
    // The items of a round: each thread takes its own range first (in both
    // steps, so that an item commits where its region's lines are cached),
    // then what is left of the others'.
    struct alignas(64) Cursor {
      std::atomic<std::size_t> next{0};
    };
    std::unique_ptr<Cursor[]> cursor_a(new Cursor[threads]), cursor_b(new Cursor[threads]);
    auto reset_cursors = [&] {
      for (std::size_t v = 0; v < threads; ++v) {
        cursor_a[v].next.store(cur.size() * v / threads, std::memory_order_relaxed);
        cursor_b[v].next.store(cur.size() * v / threads, std::memory_order_relaxed);
      }
    };
    reset_cursors();
    const Clock::time_point rounds_start = trace ? Clock::now() : Clock::time_point();
    scratch.clean = false;  // (until the rounds end without an error: see RepairScratchPool::give)
    on_threads(threads, [&](std::size_t w) {
      auto each_item = [&](Cursor* cursor, const auto& f) {
        const std::size_t m = cur.size();
        for (std::size_t k = 0; k < threads; ++k) {
          const std::size_t v = (w + k) % threads, ve = m * (v + 1) / threads;
          for (std::size_t i; (i = cursor[v].next.fetch_add(1, std::memory_order_relaxed)) < ve;) f(i);
        }
      };
      Cleaner& me = *workers_[w];
      auto guarded = [&](const auto& f) {
        if (failed.load(std::memory_order_relaxed)) return;
        try {
          f();
        } catch (...) {
          std::lock_guard<std::mutex> lock(error_mutex);
          if (!error) error = std::current_exception();
          failed = true;
        }
      };
      Clock::time_point t0;
      auto step = [&](int k) {  // (the main thread's, when tracing)
        if (!trace || w != 0) return;
        const Clock::time_point t1 = Clock::now();
        if (k >= 0) step_ms[k] += std::chrono::duration<double, std::milli>(t1 - t0).count();
        t0 = t1;
      };
      step(-1);
      for (;;) {
        barrier.wait();
        step(4);
        if (done) return;
        // Reserve.
        guarded([&] {
          std::uint64_t kept = 0;
          each_item(cursor_a.get(), [&](std::size_t i) {
            const std::uint32_t pos = cur[i];
            for (int d = 4; d >= 1; --d)  // (the lines of the next items: prefetch_region)
              if (i + std::size_t(d) < cur.size()) me.prefetch_region(std::get<2>(bad[cur[i + std::size_t(d)]]), 4 - d);
            bool find = true;
            if (carried[i]) {
              find = false;
              for (std::uint32_t x : reg[i])
                if (slots_[x].wrote == round_id - 1) {
                  find = true;
                  break;
                }
              kept += find ? 0 : 1;
            }
            if (find) me.region(std::get<2>(bad[pos]), reg[i]);
            for (std::uint32_t x : reg[i]) {
              std::atomic<std::uint32_t>& r = slots_[x].reserve;
              std::uint32_t old = r.load(std::memory_order_relaxed);
              while (pos < old && !r.compare_exchange_weak(old, pos, std::memory_order_relaxed)) {
              }
            }
          });
          if (kept > 0) reused.fetch_add(kept, std::memory_order_relaxed);
        });
        step(0);
        barrier.wait();
        step(4);
        // Commit the items that hold their whole region.
        guarded([&] {
          each_item(cursor_b.get(), [&](std::size_t i) {
            const std::uint32_t pos = cur[i];
            bool won = true;
            for (std::uint32_t x : reg[i])
              if (slots_[x].reserve.load(std::memory_order_relaxed) != pos) {
                won = false;
                break;
              }
            win[i] = won ? 1 : 0;
            if (!won) return;
            const std::uint32_t stamp = base + pos;
            for (std::uint32_t x : reg[i])
              if (slots_[x].stamp > stamp) violation.store(true, std::memory_order_relaxed);
            if (violation.load(std::memory_order_relaxed)) return;  // (the pass is undone)
            const std::size_t logged = me.log_.size();
            me.repaired_ += attempt(me, pos, &reg[i]) ? 1 : 0;
            const bool wrote = me.log_.size() > logged;
            for (std::uint32_t x : reg[i]) {
              slots_[x].stamp = stamp;
              if (wrote) slots_[x].wrote = round_id;
            }
            if (hooks.check_writes) writes_outside += me.writes_outside(reg[i], logged);
          });
        });
        step(1);
        barrier.wait();
        step(4);
        // Release the reservations.
        guarded([&] {
          const std::size_t m = cur.size(), ib = m * w / threads, ie = m * (w + 1) / threads;
          for (std::size_t i = ib; i < ie; ++i)
            for (std::uint32_t x : reg[i]) slots_[x].reserve.store(kNone, std::memory_order_relaxed);
        });
        step(2);
        barrier.wait();
        step(4);
        if (w != 0) continue;
        // The main thread: take the workers' counts and new incidences, then
        // the next round (done after a failure too, so that no thread waits
        // for ever). Their changed lists wait for the end of the pass (the
        // next pass' list is sorted), their undo logs stay theirs (each
        // round's end marked: see below).
        guarded([&] {
          ++rounds;
          if (rounds == hooks.undo_after_round) violation = true;
          for (std::size_t k = 0; k < threads; ++k) {
            Cleaner& o = *workers_[k];
            collapses += o.collapses, flips += o.flips, moves += o.moves, cuts += o.cuts;
            o.collapses = o.flips = o.moves = o.cuts = 0;
            repaired += o.repaired_;
            o.repaired_ = 0;
            skipped_ += o.skipped_, skip_mismatches += o.skip_mismatches_;
            o.skipped_ = o.skip_mismatches_ = 0;
            for (const auto& e : o.pending_incidence_) add_incidence(e.first, e.second);
            o.pending_incidence_.clear();
            o.round_ends_.push_back(o.log_.size());
          }
          if (violation) return;
          next.clear();
          for (std::size_t i = 0; i < cur.size(); ++i)
            if (!win[i]) {  // (the losers first, in order, with their regions)
              std::swap(reg[next.size()], reg[i]);
              carried[next.size()] = 1;
              next.push_back(cur[i]);
            }
          lost += next.size();
          std::fill(carried.begin() + next.size(), carried.end(), std::uint8_t(0));
          cur.swap(next);
          refill();
          ++round_id;
          done = cur.empty();
          reset_cursors();
        });
        if (violation || failed) done = true;
        step(3);
      }
    });
    scratch.round_base = round_id;
    if (!error) scratch.clean = true;
    const Clock::time_point rounds_end = trace ? Clock::now() : Clock::time_point();
    auto clear_workers = [&] {
      for (std::size_t k = 0; k < threads; ++k) {
        Cleaner& o = *workers_[k];
        o.log_.clear();
        o.round_ends_.clear();
        o.changed_vertices_.clear();
        o.changed_triangles_.clear();
        o.judged_vertices_.clear();
      }
    };
    if (error) {
      clear_workers();
      std::rethrow_exception(error);
    }
    if (!violation)
      for (std::size_t k = 0; k < threads; ++k) {
        const Cleaner& o = *workers_[k];
        changed_vertices_.insert(changed_vertices_.end(), o.changed_vertices_.begin(), o.changed_vertices_.end());
        changed_triangles_.insert(changed_triangles_.end(), o.changed_triangles_.begin(), o.changed_triangles_.end());
        judged_vertices_.insert(judged_vertices_.end(), o.judged_vertices_.begin(), o.judged_vertices_.end());
      }
    else {
      // The rounds undone last first; within a round, each worker's entries
      // last first, the workers in any order: a round's committed repairs
      // wrote only within their own regions, which were disjoint.
      for (std::size_t r = workers_[0]->round_ends_.size(); r-- > 0;)
        for (std::size_t k = 0; k < threads; ++k) {
          const Cleaner& o = *workers_[k];
          undo(o.log_, r > 0 ? o.round_ends_[r - 1] : 0, o.round_ends_[r]);
        }
    }
    // (Taken or undone: a later pass' workers start empty.)
    clear_workers();
    if (violation) {
      collapses = saved[0], flips = saved[1], moves = saved[2], cuts = saved[3];
      repaired = 0;
      skipped_ = skip_mismatches_ = 0;
      // (The undone repairs' times stay on their vertices: later than any
      // failure before this pass, they can only prevent a skip.)
      for (std::size_t pos = 0; pos < n; ++pos) repaired += attempt(*this, pos, nullptr) ? 1 : 0;
      skip_mismatches = skip_mismatches_;
    }
    if (hooks.min_items > 0) {  // (a test's: the library's clean-ups may run on several threads at once)
      RepairPassHooks& h = repair_pass_hooks();
      ++h.parallel_passes;
      h.rounds += rounds;
      h.lost += lost;
      h.kept_regions += reused.load();
      h.undone += violation ? 1 : 0;
      h.writes_outside += writes_outside;
    }
    if (trace) {
      auto ms = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
      std::fprintf(stderr,
                   "[nbmc trace] clean-up rounds: items=%zu threads=%zu rounds=%llu lost=%llu (%.1f%%, regions kept "
                   "%llu)%s; main thread: setup %.3f, reserve %.3f, commit %.3f, release %.3f, merge %.3f, waiting "
                   "%.3f, threads' start and end %.3f, after %.3f ms\n",
                   n, threads, (unsigned long long)rounds, (unsigned long long)lost, 100.0 * double(lost) / double(n),
                   (unsigned long long)reused.load(), violation ? " (undone, run serially)" : "",
                   ms(setup_start, rounds_start), step_ms[0], step_ms[1], step_ms[2], step_ms[3], step_ms[4],
                   ms(rounds_start, rounds_end) - (step_ms[0] + step_ms[1] + step_ms[2] + step_ms[3] + step_ms[4]),
                   ms(rounds_end, Clock::now()));
    }
    return finish(repaired);
  }
  // Items of the last pass skipped (their failure had to repeat).
  std::size_t last_skipped() const { return skipped_; }

  // Whether every item of a pass about to start (`bad`) must skip: each
  // failed before (in failed_) and its region is unchanged since. Then the
  // pass repairs nothing and changes nothing (the items' outcomes: their
  // failures again, written here), and needs neither its items in order nor
  // reservations: the checks only read, on the host threads (such a pass of
  // retries, as at YT10's creases, took 13-15 rounds of conflicting items).
  // The passes after the first of a round hold such retries, and the last
  // pass of a round often nothing else. Stops at the first item that would
  // be tried.
  bool every_item_skips(const BadList& bad) {
    const std::size_t n = bad.size();
    if (n == 0 || failed_.empty() || merge_clusters) return false;
    for (const auto& b : bad)
      if (failed_before(std::get<2>(b)) == 0) return false;
    const std::size_t min_items = repair_pass_hooks().min_items;
    const std::size_t threads = chunk_count(n, min_items > 0 ? min_items : kSkipCheckMinItems);
    while (workers_.size() < threads) workers_.emplace_back(new Cleaner(*this, WorkerTag{}));
    std::atomic<bool> tried{false};
    for_chunks(n, threads, [&](std::size_t k, std::size_t b, std::size_t e) {
      Cleaner& me = threads > 1 ? *workers_[k] : *this;
      me.last_resort = last_resort;  // (region() depends on it; a worker's is set here)
      for (std::size_t pos = b; pos < e && !tried.load(std::memory_order_relaxed); ++pos) {
        for (int d = 4; d >= 1; --d)
          if (pos + std::size_t(d) < e) me.prefetch_region(std::get<2>(bad[pos + std::size_t(d)]), 4 - d);
        const std::uint32_t t = std::get<2>(bad[pos]), failed_at = failed_before(t);
        me.region(t, me.region_);
        if (unchanged_since(me.region_, failed_at)) outcome_[pos] = failed_at;
        else tried.store(true, std::memory_order_relaxed);
      }
    });
    return !tried.load();
  }
  // every_item_skips' chunks: at least this many items each (a check, the
  // region of a triangle, costs a few microseconds).
  static constexpr std::size_t kSkipCheckMinItems = 32;

  // Skipping hopeless retries. repair(t) reads only its region (region():
  // the positions and triangles of its vertices; the tests check its
  // writes), and what it finds there decides. A repair stamps each vertex
  // whose position or triangles it changes with its time (touch): its
  // place in the serial order of all passes (the scratch's time_next on:
  // times only grow, also from one clean-up to the next), so the same
  // at any thread count (a parallel pass commits the items whose regions
  // meet in that order). A triangle whose repair failed at time f, with
  // no vertex of its region (now) stamped f or later, has the same region
  // as then, unchanged: its repair fails again, under the same limits, and
  // is skipped (recorded again with f). Not in the cluster merges
  // (consider_cluster reads beyond region()); the records are dropped when
  // the limits change and when components are removed.
  std::uint32_t start_times(std::size_t n) {
    const int key = (cos_limit == kCosMaxNormalTurn ? 0 : cos_limit == kCosMaxNormalTurnLast ? 1 : 2) +
                    3 * (last_resort ? 1 : 0) + 6 * (merge_clusters ? 1 : 0);
    if (key != failed_key_) failed_.clear(), failed_key_ = key;
    // (The scratch of an earlier clean-up holds only times below its
    // counter, older than any of this one's.)
    if (!repair_scratch_) repair_scratch_ = RepairScratchPool::instance().take(nv_);
    RepairScratch& scratch = *repair_scratch_;
    if (std::uint64_t(scratch.time_next) + n + 1 >= kNone) {
      scratch.reset_times();
      failed_.clear();
    }
    const std::uint32_t base = scratch.time_next;
    scratch.time_next += std::uint32_t(n);
    now_ = 0;  // (the main Cleaner's, for add_incidence after a round)
    return base;
  }
  // When repair(t) last failed (in the pass before, or skipped since), or 0.
  std::uint32_t failed_before(std::uint32_t t) const {
    if (merge_clusters) return 0;
    const auto it = std::lower_bound(failed_.begin(), failed_.end(), std::make_pair(t, std::uint32_t(0)));
    return it != failed_.end() && it->first == t ? it->second : 0;
  }
  bool unchanged_since(const std::vector<std::uint32_t>& region, std::uint32_t time) const {
    const RepairSlot* slots = repair_scratch_->slots.data();
    for (std::uint32_t x : region)
      if (slots[x].mod >= time) return false;
    return true;
  }
  void record_failures(const BadList& bad) {
    failed_.clear();
    if (merge_clusters) return;
    for (std::size_t pos = 0; pos < bad.size(); ++pos)
      if (outcome_[pos] != 0) failed_.push_back({std::get<2>(bad[pos]), outcome_[pos]});
    std::sort(failed_.begin(), failed_.end());
  }
  void forget_failures() { failed_.clear(); }

  // Removes the connected components all of whose triangles are degenerate
  // (marching cubes leaves such specks where the field barely dips below
  // zero at one grid vertex: an octahedron a millionth of a cell wide, which
  // no collapse can repair without leaving a degenerate triangle). Whole
  // components go, so the rest of the mesh is untouched. `bad`: the bad
  // triangles now (every degenerate one is among them); each component is
  // walked from them, and a walk stops at the first triangle that is not
  // degenerate. Returns the triangles removed.
  std::uint64_t drop_degenerate_components(const BadList& bad) {
    forget_failures();
    std::uint64_t removed = 0;
    for (const auto& b : bad) {
      const std::uint32_t t0 = std::get<2>(b);
      if (std::get<0>(b) != -2 || !alive_[t0] || visited(t0)) continue;
      bool solid = false;
      walk_component(t0, 0, [&](std::uint32_t t) {
        if (state_[t] == kSolid || tri_class(t) != 2) solid = true;
        return !solid;
      });
      settle_component(solid ? kSolid : kRemoved);
      if (!solid) removed += component_.size();
    }
    return removed;
  }

  // Removes the connected components that still hold a bad triangle, have
  // at most kSmallComponentTriangles triangles and enclose less than
  // max_volume (a component's signed volume, summed in triangle order about
  // its lowest-numbered vertex): droplets smaller than a marching-cubes
  // cell, whose surface the grid cannot resolve (a flat lens, or a tube
  // pinched off at a grid vertex), noise like the degenerate specks. Each
  // component is walked from its bad triangles (`bad`: all of them), and a
  // walk stops when it passes the size limit. Returns the triangles removed.
  std::uint64_t drop_small_bad_components(const BadList& bad, double max_volume) {
    forget_failures();
    // (kSolid meant "not all degenerate" above.)
    for (std::uint32_t t : walked_) state_[t] = kUnseen;
    walked_.clear();
    std::uint64_t removed = 0;
    for (const auto& b : bad) {
      const std::uint32_t t0 = std::get<2>(b);
      if (!alive_[t0] || visited(t0)) continue;
      bool large = false;
      walk_component(t0, kSmallComponentTriangles, [&](std::uint32_t t) {
        if (state_[t] == kSolid) large = true;
        return !large;
      });
      large = large || component_.size() > kSmallComponentTriangles;
      bool drop = false;
      if (!large) {
        std::sort(component_.begin(), component_.end());
        std::uint32_t o = kNone;
        for (std::uint32_t t : component_)
          for (int k = 0; k < 3; ++k) o = std::min(o, T_[3 * std::size_t(t) + k]);
        // Relative to that vertex: no cancellation far from the origin.
        const Vec3 po = load(P_, o);
        double volume = 0;  // six times
        for (std::uint32_t t : component_) {
          const std::uint32_t* v = T_ + 3 * std::size_t(t);
          volume += dot(load(P_, v[0]) - po, cross(load(P_, v[1]) - po, load(P_, v[2]) - po));
        }
        drop = std::abs(volume) < 6 * max_volume;
      }
      settle_component(drop ? kRemoved : kSolid);
      if (drop) removed += component_.size();
    }
    return removed;
  }
  // Writes the surviving triangles and vertices back, compacted; returns the
  // new counts. The places of the removed triangles below the new triangle
  // count take the surviving triangles from it on (both ascending, one for
  // one), and the same for the vertices that no surviving triangle uses
  // (their corners renumbered); everything else stays where it was. The
  // clean-up removes a few hundred of millions of entries: the removed
  // triangles and the vertices that may have lost their last triangle are
  // those it recorded (killed_, lost_; bare_: those that never had one),
  // and a moved vertex's triangles are its fan, so that nothing is read
  // whole. (An order-keeping compaction moved every entry after the first
  // removed one and read every triangle twice: 3-4 ms of the 1.65 M frame on
  // 16 host threads, 18-26 ms of the 13.2 M frame: bench/RESULTS.md,
  // session 39.)
  // written_*: the places below the new counts that now hold another
  // vertex or triangle, or a triangle with a vertex renumbered (ascending,
  // each once; may be null). The result does not depend on the thread count.
  std::pair<std::size_t, std::size_t> compact(std::vector<std::uint32_t>* written_vertices = nullptr,
                                              std::vector<std::uint32_t>* written_triangles = nullptr) {
    if (written_vertices) written_vertices->clear();
    if (written_triangles) written_triangles->clear();
    // (The tests' reference, which they run without `changed`: no places listed.)
    if (repair_pass_hooks().compact_in_order) return compact_mesh(P_, N_, nv_, T_, nt_, alive_);
    // The removed triangles, and the vertices to look at: those that lost
    // a triangle, and those whose lists are empty (no triangle in the input).
    std::vector<std::uint32_t> dead, look;
    auto gather = [&](const Cleaner& c) {
      for (std::uint32_t t : c.killed_)
        if (!alive_[t]) dead.push_back(t);
      look.insert(look.end(), c.lost_.begin(), c.lost_.end());
    };
    gather(*this);
    for (const auto& w : workers_) gather(*w);
    look.insert(look.end(), bare_.begin(), bare_.end());
    std::sort(dead.begin(), dead.end());
    dead.erase(std::unique(dead.begin(), dead.end()), dead.end());
    std::sort(look.begin(), look.end());
    look.erase(std::unique(look.begin(), look.end()), look.end());
    look.erase(std::lower_bound(look.begin(), look.end(), std::uint32_t(std::min<std::size_t>(nv_, kNone))), look.end());  // (no such vertex)
    // Of those, the vertices that no surviving triangle uses (an empty fan:
    // fan() finds every surviving triangle that holds the vertex).
    std::vector<std::uint8_t> unused_flag(look.size(), 0);
    for_chunks(look.size(), chunk_count(look.size(), 1024), [&](std::size_t, std::size_t b, std::size_t e) {
      std::vector<std::uint32_t> f;
      for (std::size_t i = b; i < e; ++i) {
        fan(look[i], f);
        unused_flag[i] = f.empty() ? 1 : 0;
      }
    });
    std::vector<std::uint32_t> unused;
    for (std::size_t i = 0; i < look.size(); ++i)
      if (unused_flag[i]) unused.push_back(look[i]);
    if (dead.empty() && unused.empty()) return {nv_, nt_};
    const std::size_t kv = nv_ - unused.size(), kt = nt_ - dead.size();
    // Holes below the counts and the entries kept from them on, ascending:
    // as many of each.
    auto holes_and_movers = [](const std::vector<std::uint32_t>& gone, std::size_t n, std::size_t kept,
                               std::vector<std::uint32_t>& holes, std::vector<std::uint32_t>& movers) {
      auto it = std::lower_bound(gone.begin(), gone.end(), std::uint32_t(kept));
      holes.assign(gone.begin(), it);
      for (std::size_t x = kept; x < n; ++x) {
        if (it != gone.end() && *it == x) {
          ++it;
          continue;
        }
        movers.push_back(std::uint32_t(x));
      }
    };
    std::vector<std::uint32_t> vhole, vmove, thole, tmove, renamed, f;
    holes_and_movers(unused, nv_, kv, vhole, vmove);
    holes_and_movers(dead, nt_, kt, thole, tmove);
    // Each moved vertex' triangles (its fan, by the triangles' places
    // before they move) name its new place. A hole is a vertex no triangle
    // uses, and no moved vertex is one, so no fan sees another's renaming.
    for (std::size_t i = 0; i < vmove.size(); ++i) {
      const std::uint32_t from = vmove[i], to = vhole[i];
      for (int a = 0; a < 3; ++a) P_[3 * std::size_t(to) + a] = P_[3 * std::size_t(from) + a];
      if (N_)
        for (int a = 0; a < 3; ++a) N_[3 * std::size_t(to) + a] = N_[3 * std::size_t(from) + a];
      fan(from, f);
      for (std::uint32_t t : f) {
        for (int k = 0; k < 3; ++k)
          if (T_[3 * std::size_t(t) + k] == from) T_[3 * std::size_t(t) + k] = to;
        renamed.push_back(t);
      }
    }
    for (std::size_t i = 0; i < tmove.size(); ++i)
      for (int k = 0; k < 3; ++k) T_[3 * std::size_t(thole[i]) + k] = T_[3 * std::size_t(tmove[i]) + k];
    if (written_vertices) *written_vertices = std::move(vhole);
    if (written_triangles) {
      std::vector<std::uint32_t>& w = *written_triangles;
      w = std::move(thole);
      for (std::uint32_t t : renamed)
        if (t < kt) w.push_back(t);
      std::sort(w.begin(), w.end());
      w.erase(std::unique(w.begin(), w.end()), w.end());
    }
    return {kv, kt};
  }
  // After compact(): what the repairs wrote (with track_changes; else
  // nothing) below the new counts (kv, kt), and the places compact() wrote
  // (written_*) that the repairs did not; each once, in no particular order
  // (the change flags tell which the repairs listed).
  void changed_entries(ChangedEntries& out, const std::vector<std::uint32_t>& written_vertices,
                       const std::vector<std::uint32_t>& written_triangles, std::size_t kv, std::size_t kt) const {
    out.vertices.clear();
    out.triangles.clear();
    auto below = [](std::vector<std::uint32_t>& to, const std::vector<std::uint32_t>& from, std::size_t count) {
      for (std::uint32_t x : from)
        if (x < count) to.push_back(x);
    };
    below(out.vertices, vlist_, kv);
    below(out.triangles, tlist_, kt);
    for (const auto& w : workers_) {
      below(out.vertices, w->vlist_, kv);
      below(out.triangles, w->tlist_, kt);
    }
    for (std::uint32_t v : written_vertices)
      if (!vchanged_ || !vchanged_[v]) out.vertices.push_back(v);
    for (std::uint32_t t : written_triangles)
      if (!tchanged_ || !tchanged_[t]) out.triangles.push_back(t);
  }

 private:
  static constexpr std::uint32_t kNone = 0xffffffffu;

  struct Candidate {
    enum Kind { Collapse, Flip, Move };
    bool valid = false;
    Kind kind = Collapse;
    double score = -1;
    std::uint32_t a = 0, b = 0;  // collapse b into a / flip edge (a, b)
    std::uint32_t t1 = 0, t2 = 0;  // the two triangles removed (collapse) or rewritten (flip)
    std::uint32_t c = 0, d = 0;    // flip: the opposite vertices
    Vec3 p;
    int where = 0;  // 0 midpoint, 1 at a, 2 at b
    std::vector<std::pair<std::uint32_t, Vec3>> moved;  // move: vertices and new positions
  };

  // Component walks (drop_*_components): a triangle's state.
  static constexpr std::uint8_t kUnseen = 0, kInWalk = 1, kSolid = 2, kRemoved = 3;
  bool visited(std::uint32_t t) const { return state_[t] != kUnseen; }
  // Collects into component_ the alive triangles connected to t0 through
  // shared vertices, breadth first, until `keep_going(t)` says no for a
  // triangle reached (that one is still collected) or more than `limit`
  // triangles are collected (0: no limit).
  template <class F>
  void walk_component(std::uint32_t t0, std::size_t limit, const F& keep_going) {
    component_.clear();
    component_.push_back(t0);
    bool go = keep_going(t0);
    if (state_[t0] == kUnseen) state_[t0] = kInWalk;
    // Each vertex's fan once (a vertex is in about six of the triangles
    // collected): a second time it would give only triangles collected
    // already, in the walk (or it would have stopped), so the walk is the
    // same.
    for (std::size_t i = 0; i < component_.size() && go; ++i) {
      const std::uint32_t t = component_[i];
      for (int k = 0; k < 3 && go; ++k) {
        const std::uint32_t v = T_[3 * std::size_t(t) + k];
        if (expanded_[v]) continue;
        expanded_[v] = 1;
        expanded_list_.push_back(v);
        fan(v, scratch_);
        for (std::uint32_t u : scratch_) {
          if (state_[u] == kInWalk) continue;
          component_.push_back(u);
          go = keep_going(u);
          if (state_[u] == kUnseen) state_[u] = kInWalk;
          if (!go || (limit && component_.size() > limit)) {
            go = false;
            break;
          }
        }
      }
    }
    for (std::uint32_t v : expanded_list_) expanded_[v] = 0;
    expanded_list_.clear();
  }
  // Ends a walk: its triangles are marked (kSolid: part of a component that
  // stays; kRemoved: removed now).
  void settle_component(std::uint8_t to) {
    for (std::uint32_t t : component_) {
      if (state_[t] != kInWalk) continue;
      state_[t] = to;
      walked_.push_back(t);
      if (to != kRemoved) continue;
      for (int k = 0; k < 3; ++k) irregular(T_[3 * std::size_t(t) + k]);  // (fixed before the write: see irregular())
      killed(t);
      alive_[t] = 0;
    }
  }

  TriangleShape shape(std::uint32_t t) const {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    return triangle_shape(load(P_, v[0]), load(P_, v[1]), load(P_, v[2]));
  }
  int tri_class(std::uint32_t t) const {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    return class_of(load(P_, v[0]), load(P_, v[1]), load(P_, v[2]));
  }
  // The triangle's class, surely_good first (mesh_check.hpp).
  int class_of(const Vec3& a, const Vec3& b, const Vec3& c) const {
    return triangle_class_of(a, b, c, degenerate_double_area_);
  }

  // A vertex is regular when each of its edges is used once in each
  // direction (two triangles, opposite orientations) and its triangles form
  // one closed fan; the others, and the vertices of triangles that repeat a
  // vertex, are never touched. Judged on the input mesh, but only for the
  // vertices the repairs ask about (a few per cent of them; a pass over
  // every vertex cost 6.5 ms of the clean-up on 16 threads): a vertex's flag
  // is found when first asked, or before the first write to one of its
  // triangles (touch(), settle_component()), from its lists as built (every
  // triangle in them still holds it then, unchanged). So it is the input's,
  // whenever asked. Relaxed atomics: in a round of repair_pass, several
  // threads finding their regions may ask about the same vertex at once
  // (they compute the same flag; nothing writes its triangles then), and in
  // the commit step a repair asks only about vertices in its own region.
  static constexpr std::uint8_t kFanUnknown = 0, kFanRegular = 1, kFanIrregular = 2;
  bool irregular(std::uint32_t v) const {
    std::uint8_t s = load_relaxed(irregular_[v]);
    if (s == kFanUnknown) {
      s = one_closed_fan_as_built(v) ? kFanRegular : kFanIrregular;
      store_relaxed(irregular_[v], s);
    }
    return s == kFanIrregular;
  }
  bool one_closed_fan_as_built(std::uint32_t v) const {
    const std::uint32_t b = start_[v], e = start_[v + 1];
    // Almost every fan is small: one_closed_fan's small case on the stack,
    // without the vectors.
    if (e - b <= kSmallFan) return small_closed_fan(v, b, e);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> in;  // (previous vertex, local index)
    std::vector<std::uint32_t> out;                           // next vertex, by local index
    for (std::uint32_t i = b; i < e; ++i) {
      const std::uint32_t* w = T_ + 3 * std::size_t(incident_[i]);
      const int k = w[0] == v ? 0 : w[1] == v ? 1 : 2;
      const std::uint32_t nx = w[(k + 1) % 3], pv = w[(k + 2) % 3];
      if (nx == v || pv == v) return false;
      out.push_back(nx);
      in.push_back({pv, i - b});
    }
    return one_closed_fan(in, out);
  }

  // The test for v with a list [b, e) of at most kSmallFan triangles:
  // exactly the loop above and one_closed_fan's small case.
  static constexpr std::uint32_t kSmallFan = kMoveFanMax;
  bool small_closed_fan(std::uint32_t v, std::uint32_t b, std::uint32_t e) const {
    return mesh::small_closed_fan(T_, incident_.data(), v, b, e - b);  // (mesh_moves.hpp)
  }

  // Whether triangles with these (previous vertex, local index) and next
  // vertices form one closed fan: the previous vertices are distinct, and
  // walking from a triangle to the one whose previous vertex is this one's
  // next goes once through all of them. `in` may be reordered. (Small fans,
  // almost all of them, by linear search; large ones sorted.)
  static bool one_closed_fan(std::vector<std::pair<std::uint32_t, std::uint32_t>>& in,
                             const std::vector<std::uint32_t>& out) {
    const std::size_t n = in.size();
    if (n <= 16) {
      for (std::size_t i = 1; i < n; ++i)
        for (std::size_t j = 0; j < i; ++j)
          if (in[i].first == in[j].first) return false;
      std::uint32_t cur = 0, steps = 0;
      do {
        std::size_t j = 0;
        while (j < n && in[j].first != out[cur]) ++j;
        if (j == n) return false;
        cur = in[j].second;
        ++steps;
      } while (cur != 0 && steps <= n);
      return cur == 0 && steps == n;
    }
    std::sort(in.begin(), in.end());
    for (std::size_t k = 1; k < n; ++k)
      if (in[k].first == in[k - 1].first) return false;
    std::uint32_t cur = 0, steps = 0;
    do {
      auto it = std::lower_bound(in.begin(), in.end(), std::make_pair(out[cur], 0u));
      if (it == in.end() || it->first != out[cur]) return false;
      cur = it->second;
      ++steps;
    } while (cur != 0 && steps <= n);
    return cur == 0 && steps == n;
  }

  // Alive triangles around v: in its own lists and those of the vertices
  // merged into it, that still contain v (flips move triangles away).
  // Each listed triangle's alive flag and vertices are read through relaxed
  // atomics (as the repairs write them): in a round of repair_pass, a stale
  // entry (a triangle that no longer contains v, left by an earlier flip,
  // cut or merge) may be one that another thread is rewriting or removing
  // now (its vertices lie in that thread's region, v in this one's). Neither
  // its old nor its new contents hold v (the other thread's region does not
  // hold v), so whichever values are read, it is skipped: the result is the
  // same, and the reads are no data race. Every triangle taken contains v,
  // which no other thread's region holds, so no other thread writes it in
  // the round, and the plain reads of it elsewhere race with nothing. A
  // removed triangle's flag is never written again in a pass (but by an
  // undo, serially). The lists themselves (start_, incident_, extra_head_,
  // extra_) change only between rounds, on the main thread, and a chain of
  // merged vertices (next_, tail_) only by the thread whose region holds its
  // first vertex, the one whose fan() walks it.
  void fan(std::uint32_t v, std::vector<std::uint32_t>& out) const {
    fan_unsorted(v, out);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }
  // fan()'s triangles in list order, a triangle listed twice (after a flip
  // or a merge) twice: for region(), whose vertices need no order.
  void fan_unsorted(std::uint32_t v, std::vector<std::uint32_t>& out) const {
    out.clear();
    auto take = [&](std::uint32_t t) {
      const std::uint32_t* w = T_ + 3 * std::size_t(t);
      if (load_relaxed(alive_[t]) &&
          (load_relaxed(w[0]) == v || load_relaxed(w[1]) == v || load_relaxed(w[2]) == v))
        out.push_back(t);
    };
    for (std::uint32_t u = v; u != kNone; u = next_[u]) {
      for (std::uint32_t i = start_[u]; i < start_[u + 1]; ++i) take(incident_[i]);
      for (std::uint32_t x = extra_head_.get(u); x != kNone; x = extra_[x].second)
        take(extra_[x].first);
    }
  }
  // repair_pass' reserve step (and a serial pass) asks for the lines
  // region(t) and repair(t) read first, a few items ahead, in four steps
  // (each reads what the one before fetched): t's vertices; their
  // positions, flags and list bounds; their lists' triangles and alive
  // flags; those triangles' corners' positions. (Only hints: no value
  // depends on them.) (On the dev VM's two threads, the reserve step of the
  // 1.65 M frame's first pass: 16.8-18.7 ms on the main thread without,
  // 13.7-15.3 with the first three steps; with the alive flags and the
  // fourth step 8.0-9.3 -> 6.0-6.8 ms (another day's load), and the serial
  // pass 23-25 -> 17-18 ms.)
  void prefetch_region(std::uint32_t t, int step) const {
    const std::uint32_t* w = T_ + 3 * std::size_t(t);
    if (step == 0) {
      prefetch(w);
      prefetch(&alive_[t]);
      return;
    }
    for (int k = 0; k < 3; ++k) prefetch_vertex(load_relaxed(w[k]), step);
  }
  // Step 1: v's position, flags and list bounds; step 2: its list's
  // triangles and their alive flags (reads its bounds and list).
  void prefetch_vertex(std::uint32_t v, int step) const {
    if (v >= nv_) return;
    if (step == 1) {
      prefetch(&start_[v]);
      prefetch(P_ + 3 * std::size_t(v));
      prefetch(&irregular_[v]);
      prefetch(&next_[v]);
      if (repair_scratch_) prefetch(&repair_scratch_->slots[v]);
      return;
    }
    if (step == 2) {
      for (std::uint32_t i = start_[v], e = start_[v + 1]; i < e; ++i) {
        const std::uint32_t t = incident_[i];
        prefetch(T_ + 3 * std::size_t(t));
        prefetch(&alive_[t]);
      }
      return;
    }
    // Step 3: the positions (and repair_pass' slots) of its list's
    // triangles' corners (reads the triangles).
    for (std::uint32_t i = start_[v], e = start_[v + 1]; i < e; ++i) prefetch_corners(incident_[i], true);
  }
  // The positions of t's corners, with `slots` their repair passes' slots
  // too (reads t's vertices).
  void prefetch_corners(std::uint32_t t, bool slots = false) const {
    const std::uint32_t* w = T_ + 3 * std::size_t(t);
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = load_relaxed(w[k]);
      if (v >= nv_) continue;
      prefetch(P_ + 3 * std::size_t(v));
      if (slots && repair_scratch_) prefetch(&repair_scratch_->slots[v]);
    }
  }
  static void prefetch(const void* p) {
#if defined(__GNUC__) || defined(__clang__)
    __builtin_prefetch(p);
#else
    (void)p;
#endif
  }
  // Vertices of the triangles in f other than v, sorted, unique.
  void ring(std::uint32_t v, const std::vector<std::uint32_t>& f, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (std::uint32_t t : f)
      for (int k = 0; k < 3; ++k)
        if (T_[3 * std::size_t(t) + k] != v) out.push_back(T_[3 * std::size_t(t) + k]);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }
  std::size_t degree(std::uint32_t v) {
    fan(v, scratch_);
    return scratch_.size();
  }
  static bool contains(const std::uint32_t* v, std::uint32_t x) { return v[0] == x || v[1] == x || v[2] == x; }
  // The repairs' writes of T_ and alive_, and fan()'s reads of them, are
  // relaxed atomic accesses (see fan()): on the host, plain loads and stores
  // of the same width, in the same order.
  template <class U>
  static U load_relaxed(const U& x) {
#if defined(__GNUC__) || defined(__clang__)
    return __atomic_load_n(&x, __ATOMIC_RELAXED);
#else
    return x;
#endif
  }
  template <class U>
  static void store_relaxed(U& x, U value) {
#if defined(__GNUC__) || defined(__clang__)
    __atomic_store_n(&x, value, __ATOMIC_RELAXED);
#else
    x = value;
#endif
  }

  // An edge (a, b) that may be collapsed (the topology; consider_collapse
  // then judges each target position): fa_ and fb_ hold the fans of a and b.
  struct CollapseSite {
    std::uint32_t a = 0, b = 0;
    std::uint32_t shared[2] = {0, 0};  // the two triangles of the edge
    Vec3 ref;                          // reference normal for triangles that are bad now
  };
  bool collapse_site(std::uint32_t a, std::uint32_t b, CollapseSite& site) {
    fan(a, fa_);
    fan(b, fb_);
    std::uint32_t* shared = site.shared;
    std::uint32_t n_shared = 0;
    for (std::uint32_t t : fa_)
      if (contains(T_ + 3 * std::size_t(t), b)) {
        if (n_shared == 2) return false;
        shared[n_shared++] = t;
      }
    if (n_shared != 2) return false;
    std::uint32_t opposite[2];
    for (int s = 0; s < 2; ++s) {
      const std::uint32_t* v = T_ + 3 * std::size_t(shared[s]);
      opposite[s] = v[0] != a && v[0] != b ? v[0] : v[1] != a && v[1] != b ? v[1] : v[2];
    }
    if (opposite[0] == opposite[1]) return false;
    ring(a, fa_, ra_);
    ring(b, fb_, rb_);
    // Link condition: a and b share exactly the two opposite vertices.
    common_.clear();
    std::set_intersection(ra_.begin(), ra_.end(), rb_.begin(), rb_.end(), std::back_inserter(common_));
    if (common_.size() != 2) return false;
    if (ra_.size() + rb_.size() < 4 + 3) return false;  // the merged vertex keeps three neighbours
    for (std::uint32_t o : opposite)
      if (degree(o) < 4) return false;
    // A reference normal for triangles that are bad now (theirs is noise).
    site.ref = Vec3();
    for (const auto* f : {&fa_, &fb_})
      for (std::uint32_t t : *f) {
        const std::uint32_t* v = T_ + 3 * std::size_t(t);
        site.ref = site.ref + cross(load(P_, v[1]) - load(P_, v[0]), load(P_, v[2]) - load(P_, v[0]));
      }
    site.a = a;
    site.b = b;
    return true;
  }

  // Collapsing site's edge to p (where: 0 midpoint, 1 at a, 2 at b), with
  // fa_ and fb_ as collapse_site left them.
  void consider_collapse(const CollapseSite& site, const Vec3& p, int where, Candidate& best) {
    const std::uint32_t a = site.a, b = site.b;
    const std::uint32_t* shared = site.shared;
    const Vec3& ref = site.ref;
    double score = 2;
    for (const auto* f : {&fa_, &fb_})
      for (std::uint32_t t : *f) {
        if (t == shared[0] || t == shared[1]) continue;
        const std::uint32_t* v = T_ + 3 * std::size_t(t);
        Vec3 q[3], o[3];
        for (int k = 0; k < 3; ++k) {
          o[k] = load(P_, v[k]);
          q[k] = v[k] == a || v[k] == b ? p : o[k];
        }
        // Rounded as the output will be.
        for (int k = 0; k < 3; ++k) q[k] = Vec3{double(Real(q[k].x)), double(Real(q[k].y)), double(Real(q[k].z))};
        const TriangleShape s_new = triangle_shape(q[0], q[1], q[2]);
        const int c_old = class_of(o[0], o[1], o[2]);
        const int c_new = triangle_class(s_new, degenerate_double_area_);
        // A triangle that was degenerate may stay so: where several
        // vertices coincide (the field is zero at a grid vertex), one
        // collapse after the other removes their degenerate triangles.
        if (last_resort && c_old == 2 && c_new == 2) continue;
        if (c_new == 2 || (c_old == 0 && c_new != 0)) return;
        // (and one that was bad may stay bad, its normal noise as before)
        if (last_resort && c_old != 0 && c_new != 0) continue;
        const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]);
        const Vec3 n_ref = c_old == 0 ? cross(o[1] - o[0], o[2] - o[0]) : ref;
        if (dot(n_new, n_ref) <= cos_limit * norm(n_new) * norm(n_ref)) return;
        score = std::min(score, s_new.sin_min_angle);
      }
    if (score <= best.score) return;
    best.valid = true;
    best.kind = Candidate::Collapse;
    best.score = score;
    best.a = a;
    best.b = b;
    best.t1 = shared[0];
    best.t2 = shared[1];
    best.p = p;
    best.where = where;
  }

  // Moves v by f times the way to the centroid of its neighbours, within
  // its tangent plane (the normal of its fan): the fan keeps its triangles.
  // (The shortest of a quarter, half or all the way that works, in `out`.)
  void consider_move(std::uint32_t t, std::uint32_t v, Candidate& out) {
    if (irregular(v)) return;
    fan(v, fa_);
    ring(v, fa_, ra_);
    if (ra_.empty()) return;
    const Vec3 pv = load(P_, v);
    Vec3 centroid, n;
    for (std::uint32_t u : ra_) centroid = centroid + load(P_, u);
    centroid = (1.0 / double(ra_.size())) * centroid;
    for (std::uint32_t u : fa_) {
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      n = n + cross(load(P_, w[1]) - load(P_, w[0]), load(P_, w[2]) - load(P_, w[0]));
    }
    const double ln = norm(n);
    if (!(ln > 0)) return;
    n = (1.0 / ln) * n;
    Vec3 d = centroid - pv;
    d = d - dot(d, n) * n;
    // The three trial positions change the same triangles: their old shapes
    // are judged once (prepare_positions, with v's fan in fa_ already), each
    // trial only the new ones. A trial that leaves t bad fails first thing
    // in judge_positions; those are found before the fan's old shapes are
    // (most of the vertices tried cannot repair their triangle: a needle's
    // far vertex), with the same arithmetic, so the verdicts are the same.
    const std::uint32_t* w = T_ + 3 * std::size_t(t);
    bool prepared = false;
    for (double f : {0.25, 0.5, 1.0}) {
      const Vec3 p = pv + f * d;
      const Vec3 pr{double(Real(p.x)), double(Real(p.y)), double(Real(p.z))};
      Vec3 q[3];
      for (int k = 0; k < 3; ++k) q[k] = w[k] == v ? pr : load(P_, w[k]);
      if (triangle_class(triangle_shape(q[0], q[1], q[2]), degenerate_double_area_) != 0) continue;
      if (!prepared && !prepare_positions({v}, true)) return;
      prepared = true;
      judge_positions(t, {{v, p}}, out);
      if (out.valid) return;
    }
  }

  // Moving vertices (v, p): valid when the bad triangle t becomes good, no
  // good triangle turns bad, nothing becomes degenerate, and no triangle
  // turns by more than the limit (triangles that were bad are compared with
  // the mean normal around the moved vertices).
  void consider_positions(std::uint32_t t, std::vector<std::pair<std::uint32_t, Vec3>> moved, Candidate& best) {
    std::vector<std::uint32_t> vs;
    for (const auto& m : moved) vs.push_back(m.first);
    if (!prepare_positions(vs)) return;
    judge_positions(t, std::move(moved), best);
  }
  // consider_positions in two steps, so that several trial positions of the
  // same vertices share the first: the triangles around the vertices
  // (around_), their mean normal (around_normal_) and each one's old class
  // and normal (around_old_), which do not depend on the trial. False when
  // no trial can be valid (an irregular vertex, no mean normal).
  // fan_ready: vs is one vertex whose fan fa_ holds now.
  bool prepare_positions(const std::vector<std::uint32_t>& vs, bool fan_ready = false) {
    around_.clear();
    for (std::uint32_t x : vs) {
      if (irregular(x)) return false;
      if (!fan_ready) fan(x, fa_);
      around_.insert(around_.end(), fa_.begin(), fa_.end());
    }
    std::sort(around_.begin(), around_.end());
    around_.erase(std::unique(around_.begin(), around_.end()), around_.end());
    Vec3 n;
    around_old_.resize(around_.size());
    for (std::size_t i = 0; i < around_.size(); ++i) {
      const std::uint32_t* w = T_ + 3 * std::size_t(around_[i]);
      const Vec3 o0 = load(P_, w[0]), o1 = load(P_, w[1]), o2 = load(P_, w[2]);
      const Vec3 c = cross(o1 - o0, o2 - o0);
      n = n + c;
      around_old_[i].normal = c;
      around_old_[i].cls = class_of(o0, o1, o2);
    }
    around_normal_ = n;
    const double ln = norm(n);
    for (OldTriangle& o : around_old_) o.ref_norm = o.cls == 0 ? norm(o.normal) : ln;
    return ln > 0;
  }
  // The second step: one trial (v, p) (the vertices given to
  // prepare_positions, in any order). The bad triangle t is judged first:
  // a trial that leaves it bad (most) costs one shape, not the whole fan's.
  // The verdict and the score (a minimum) do not depend on that order.
  void judge_positions(std::uint32_t t, std::vector<std::pair<std::uint32_t, Vec3>> moved, Candidate& best) {
    for (auto& m : moved) m.second = Vec3{double(Real(m.second.x)), double(Real(m.second.y)), double(Real(m.second.z))};
    const Vec3& n = around_normal_;
    double score = 2;
    auto judge = [&](std::size_t i) {
      const std::uint32_t u = around_[i];
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      Vec3 q[3];
      for (int k = 0; k < 3; ++k) {
        q[k] = load(P_, w[k]);
        for (const auto& m : moved)
          if (m.first == w[k]) q[k] = m.second;
      }
      const TriangleShape s_new = triangle_shape(q[0], q[1], q[2]);
      const int c_old = around_old_[i].cls;
      const int c_new = triangle_class(s_new, degenerate_double_area_);
      if (c_new == 2 || (c_new != 0 && (c_old == 0 || u == t))) return false;
      // (norm(n_new) is s_new.double_area: the same cross product but for
      // its sign, so the same square root.)
      const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]);
      const Vec3& n_ref = c_old == 0 ? around_old_[i].normal : n;
      if (dot(n_new, n_ref) <= cos_limit * s_new.double_area * around_old_[i].ref_norm) return false;
      score = std::min(score, s_new.sin_min_angle);
      return true;
    };
    const auto it_t = std::lower_bound(around_.begin(), around_.end(), t);
    const std::size_t i_t = it_t != around_.end() && *it_t == t ? std::size_t(it_t - around_.begin()) : around_.size();
    if (i_t < around_.size() && !judge(i_t)) return;
    for (std::size_t i = 0; i < around_.size(); ++i)
      if (i != i_t && !judge(i)) return;
    if (score <= best.score) return;
    best.valid = true;
    best.kind = Candidate::Move;
    best.score = score;
    best.moved = std::move(moved);
  }

  void apply_move(const Candidate& c) {
    for (const auto& m : c.moved) {
      log_position(m.first);
      P_[3 * std::size_t(m.first)] = Real(m.second.x);
      P_[3 * std::size_t(m.first) + 1] = Real(m.second.y);
      P_[3 * std::size_t(m.first) + 2] = Real(m.second.z);
      judged_vertices_.push_back(m.first);
    }
    ++moves;
  }

  // A needle whose short edge cannot be collapsed (its ends share a third
  // neighbour: the surface is a thin tube there, marching cubes' pinch near
  // a grid vertex) is widened instead: the cluster of vertices joined to the
  // short edge's ends by edges shorter than sin(1 degree) times the needle's
  // long edge is scaled about its centre until its shortest edge is 2 (or 4)
  // degrees' worth of the long edge (a move of about 1e-4 cell).
  // A triangle's shortest edge (v[k_short], v[k_short + 1]) and the lengths
  // of its shortest and longest edges (the first shortest on ties).
  void needle_edges(const std::uint32_t* v, int& k_short, double& l_short, double& l_long) const {
    for (int k = 0; k < 3; ++k) {
      const double l = norm(load(P_, v[(k + 1) % 3]) - load(P_, v[k]));
      if (k == 0 || l < l_short) l_short = l, k_short = k;
      l_long = std::max(l_long, l);
    }
  }

  // repair_pass' region of t: the vertices (in no order, some more than
  // once: its uses need neither; sorting it took about a third of the
  // parallel passes' reserve step) whose position, or
  // whose triangles (their vertex lists, whether alive), repair(t) may
  // read or write now, so that an item whose region meets no other's
  // cannot see or change what another does. Reads of the triangles around
  // a vertex take in their vertex numbers only; positions are read only of
  // vertices in the region. Per kind (a, b, c: t's vertices, d across the
  // longest edge):
  //  - a dead triangle: nothing (it stays dead); one that is good or has an
  //    irregular vertex: its vertices (repair reads their positions only);
  //  - moves of one vertex: its fan and one-ring (positions); flips: the
  //    fans of a, b, c (d is in the one-ring) and a's and b's degrees;
  //    collapses: the fans of the edge's ends and the opposite vertices'
  //    degrees, and they rename within the ends' fans: all within t's
  //    vertices and their one-rings;
  //  - widening a needle (consider_push): its cluster, found here as it
  //    would be, and the cluster's one-ring;
  //  - in the last round, cutting a pinched tube: the one-ring of each
  //    third vertex c near both ends of the short edge (the cut rewrites
  //    the fans of a, b and c and checks the fans of their neighbours).
  // The cluster merges (merge_clusters) have no region: they run serially.
  void region(std::uint32_t t, std::vector<std::uint32_t>& out) {
    out.clear();
    if (!alive_[t]) return;
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    out.assign(v, v + 3);
    if (irregular(v[0]) || irregular(v[1]) || irregular(v[2]) || tri_class(t) == 0) return;
    auto add = [&](const std::vector<std::uint32_t>& f) {
      for (std::uint32_t u : f) out.insert(out.end(), T_ + 3 * std::size_t(u), T_ + 3 * std::size_t(u) + 3);
    };
    int k_short = 0;
    double l_short = 0, l_long = 0;
    needle_edges(v, k_short, l_short, l_long);
    const double near = kSinOneDegree * l_long;
    // The fans of the short edge's ends (a, b) in fa_ and fb_, their rings
    // in ra_ and rb_ (consider_push's first two steps, and the cut's).
    const std::uint32_t a = v[k_short], b = v[(k_short + 1) % 3], c = v[(k_short + 2) % 3];
    fan_unsorted(a, fa_);
    fan_unsorted(b, fb_);
    fan_unsorted(c, scratch_);
    add(fa_);
    add(fb_);
    add(scratch_);
    if (l_short > 0) {
      // consider_push's cluster (its loop, its order).
      ring(a, fa_, ra_);
      ring(b, fb_, rb_);
      cluster_.assign({a, b});
      for (std::size_t i = 0; i < cluster_.size() && cluster_.size() <= 8; ++i) {
        const std::uint32_t x = cluster_[i];
        const std::vector<std::uint32_t>* r = &ra_;
        if (i == 1) r = &rb_;
        if (i >= 2) {
          fan_unsorted(x, scratch_);
          add(scratch_);
          ring(x, scratch_, common_);
          r = &common_;
        }
        const Vec3 px = load(P_, x);
        for (std::uint32_t u : *r)
          if (norm(load(P_, u) - px) < near && std::find(cluster_.begin(), cluster_.end(), u) == cluster_.end())
            cluster_.push_back(u);
      }
      // (members found but not looked from: their one-rings too)
      for (std::size_t i = 2; i < cluster_.size(); ++i) {
        fan_unsorted(cluster_[i], scratch_);
        add(scratch_);
      }
    }
    if (last_resort && l_short < near) {
      if (!(l_short > 0)) {
        ring(a, fa_, ra_);
        ring(b, fb_, rb_);
      }
      common_.clear();
      std::set_intersection(ra_.begin(), ra_.end(), rb_.begin(), rb_.end(), std::back_inserter(common_));
      const Vec3 pa = load(P_, a), pb = load(P_, b);
      for (std::uint32_t x : common_) {
        const Vec3 px = load(P_, x);
        if (norm(px - pa) < near && norm(px - pb) < near) {
          fan_unsorted(x, scratch_);
          add(scratch_);
        }
      }
    }
  }

  void consider_push(std::uint32_t t, Candidate& best) {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    int k_short = 0;
    double l_short = 0, l_long = 0;
    needle_edges(v, k_short, l_short, l_long);
    if (!(l_short > 0)) return;
    const double near = kSinOneDegree * l_long;
    cluster_.assign({v[k_short], v[(k_short + 1) % 3]});
    for (std::size_t i = 0; i < cluster_.size() && cluster_.size() <= 8; ++i) {
      fan(cluster_[i], fb_);
      ring(cluster_[i], fb_, rb_);
      for (std::uint32_t u : rb_)
        if (norm(load(P_, u) - load(P_, cluster_[i])) < near &&
            std::find(cluster_.begin(), cluster_.end(), u) == cluster_.end())
          cluster_.push_back(u);
    }
    if (cluster_.size() > 8) return;
    Vec3 centre;
    for (std::uint32_t u : cluster_) centre = centre + load(P_, u);
    centre = (1.0 / double(cluster_.size())) * centre;
    // The shortest edge within the cluster.
    double shortest = l_short;
    for (std::uint32_t x : cluster_) {
      fan(x, fb_);
      ring(x, fb_, rb_);
      for (std::uint32_t y : cluster_)
        if (y != x && std::binary_search(rb_.begin(), rb_.end(), y))
          shortest = std::min(shortest, norm(load(P_, x) - load(P_, y)));
    }
    if (!(shortest > 0)) return;
    for (double factor : {2.0, 4.0}) {
      const double scale = factor * kSinOneDegree * l_long / shortest;
      if (scale <= 1) continue;
      std::vector<std::pair<std::uint32_t, Vec3>> moved;
      for (std::uint32_t u : cluster_) moved.push_back({u, centre + scale * (load(P_, u) - centre)});
      consider_positions(t, std::move(moved), best);
    }
  }

  // A pinched tube: the needle t's short edge (a, b) and a third vertex c
  // nearly coincide (edges shorter than sin(1 degree) times the needle's
  // long edge) and form a 3-cycle that is no triangle of the mesh: the
  // surface is a tube of radius ~1e-5 cell there, which marching cubes makes
  // where the field's zero set pinches off at a grid vertex. No collapse
  // can shorten that cycle (the link condition fails) and widening it
  // turns triangles too far. The tube is cut along the cycle instead: the
  // triangles on one side of it take a, those on the other side take b (c
  // goes), both at the cycle's centre; the six triangles with two vertices
  // on the cycle (the needles among them) vanish. Two closed surfaces (or
  // one of lower genus) meet at a point there, as the zero set does.
  struct CutCandidate {
    bool valid = false;
    double score = -1;
    std::uint32_t a = 0, b = 0, c = 0;
    Vec3 p;
    std::vector<std::pair<std::uint32_t, std::array<std::uint32_t, 3>>> rewritten;  // kept triangles, new vertices
    std::vector<std::uint32_t> removed;
  };

  // The triangles of v's fan from the one with edge v -> from (v's next
  // vertex is `from`) around to the one with edge to -> v, in fan order
  // (each next triangle shares the previous one's edge to its previous
  // vertex); false when the fan does not lead there.
  bool fan_arc(std::uint32_t v, std::uint32_t from, std::uint32_t to, std::vector<std::uint32_t>& arc) {
    fan(v, scratch_);
    arc.clear();
    auto next_of = [&](std::uint32_t t, int which) {
      const std::uint32_t* w = T_ + 3 * std::size_t(t);
      const int k = w[0] == v ? 0 : w[1] == v ? 1 : 2;
      return w[(k + which) % 3];
    };
    std::uint32_t cur = kNone;
    for (std::uint32_t t : scratch_)
      if (next_of(t, 1) == from) cur = t;
    while (cur != kNone && arc.size() < scratch_.size()) {
      arc.push_back(cur);
      const std::uint32_t pv = next_of(cur, 2);
      if (pv == to) return true;
      std::uint32_t nxt = kNone;
      for (std::uint32_t t : scratch_)
        if (next_of(t, 1) == pv) nxt = t;
      cur = nxt;
    }
    return false;
  }

  // True when the triangles around v (each holding v once) form one closed
  // fan of at least three triangles, each edge used once in each direction.
  static bool closed_fan(std::uint32_t v, const std::vector<std::array<std::uint32_t, 3>>& f) {
    if (f.size() < 3) return false;
    std::vector<std::pair<std::uint32_t, std::uint32_t>> in;
    std::vector<std::uint32_t> out;
    for (std::size_t i = 0; i < f.size(); ++i) {
      const auto& w = f[i];
      if ((w[0] == v) + (w[1] == v) + (w[2] == v) != 1) return false;
      if (w[0] == w[1] || w[1] == w[2] || w[2] == w[0]) return false;
      const int k = w[0] == v ? 0 : w[1] == v ? 1 : 2;
      out.push_back(w[(k + 1) % 3]);
      in.push_back({w[(k + 2) % 3], std::uint32_t(i)});
    }
    return one_closed_fan(in, out);
  }

  void consider_cut(std::uint32_t t, CutCandidate& best) {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    int k_short = 0;
    double l_short = 0, l_long = 0;
    needle_edges(v, k_short, l_short, l_long);
    const double near = kSinOneDegree * l_long;
    if (!(l_short < near)) return;
    // (a, b) in the triangle's direction.
    const std::uint32_t a = v[k_short], b = v[(k_short + 1) % 3];
    fan(a, fa_);
    ring(a, fa_, ra_);
    fan(b, fb_);
    ring(b, fb_, rb_);
    common_.clear();
    std::set_intersection(ra_.begin(), ra_.end(), rb_.begin(), rb_.end(), std::back_inserter(common_));
    const std::vector<std::uint32_t> candidates = common_;
    for (std::uint32_t c : candidates) {
      const Vec3 pa = load(P_, a), pb = load(P_, b), pc = load(P_, c);
      if (!(norm(pc - pa) < near && norm(pc - pb) < near)) continue;
      if (irregular(c)) continue;
      // (a, b, c) must be no triangle.
      bool face = false;
      for (std::uint32_t u : fa_)
        if (contains(T_ + 3 * std::size_t(u), b) && contains(T_ + 3 * std::size_t(u), c)) face = true;
      if (face) continue;
      // The two sides of the cycle a -> b -> c -> a: "left" holds the
      // triangles with edges a -> b, b -> c, c -> a.
      std::vector<std::uint32_t> left, right, arc;
      const std::uint32_t cyc[3] = {a, b, c};
      bool ok = true;
      std::size_t fans = 0;
      for (int k = 0; k < 3 && ok; ++k) {
        const std::uint32_t x = cyc[k], nx = cyc[(k + 1) % 3], pv = cyc[(k + 2) % 3];
        ok = fan_arc(x, nx, pv, arc);
        left.insert(left.end(), arc.begin(), arc.end());
        std::size_t n = arc.size();
        ok = ok && fan_arc(x, pv, nx, arc);
        right.insert(right.end(), arc.begin(), arc.end());
        n += arc.size();
        fan(x, scratch_);
        ok = ok && n == scratch_.size();
        fans += scratch_.size();
      }
      if (!ok) continue;
      std::sort(left.begin(), left.end());
      left.erase(std::unique(left.begin(), left.end()), left.end());
      std::sort(right.begin(), right.end());
      right.erase(std::unique(right.begin(), right.end()), right.end());
      common_.clear();
      std::set_intersection(left.begin(), left.end(), right.begin(), right.end(), std::back_inserter(common_));
      if (!common_.empty()) continue;  // a side that wraps around to the other
      CutCandidate cand;
      cand.a = a, cand.b = b, cand.c = c;
      const Vec3 centre = (1.0 / 3) * (pa + pb + pc);
      cand.p = Vec3{double(Real(centre.x)), double(Real(centre.y)), double(Real(centre.z))};
      for (int side = 0; side < 2; ++side)
        for (std::uint32_t u : side == 0 ? left : right) {
          std::array<std::uint32_t, 3> w;
          int on = 0;
          for (int k = 0; k < 3; ++k) {
            w[k] = T_[3 * std::size_t(u) + k];
            if (w[k] == a || w[k] == b || w[k] == c) {
              w[k] = side == 0 ? a : b;
              ++on;
            }
          }
          if (on >= 2) cand.removed.push_back(u);
          else cand.rewritten.push_back({u, w});
        }
      if (cand.removed.size() != 6 || cand.rewritten.empty()) continue;
      // Topology: every vertex of a changed triangle keeps one closed fan.
      std::vector<std::uint32_t> touched;
      for (std::uint32_t u : left) touched.insert(touched.end(), T_ + 3 * std::size_t(u), T_ + 3 * std::size_t(u) + 3);
      for (std::uint32_t u : right) touched.insert(touched.end(), T_ + 3 * std::size_t(u), T_ + 3 * std::size_t(u) + 3);
      std::sort(touched.begin(), touched.end());
      touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
      auto new_triangle = [&](std::uint32_t u, std::array<std::uint32_t, 3>& w) {
        if (std::binary_search(cand.removed.begin(), cand.removed.end(), u)) return false;
        for (const auto& r : cand.rewritten)
          if (r.first == u) {
            w = r.second;
            return true;
          }
        for (int k = 0; k < 3; ++k) w[k] = T_[3 * std::size_t(u) + k];
        return true;
      };
      std::sort(cand.removed.begin(), cand.removed.end());
      std::vector<std::array<std::uint32_t, 3>> f;
      for (std::uint32_t x : touched) {
        if (x == c) continue;
        f.clear();
        if (x == a || x == b) {
          for (const auto& r : cand.rewritten)
            if (contains(r.second.data(), x)) f.push_back(r.second);
        } else {
          fan(x, scratch_);
          std::array<std::uint32_t, 3> w;
          for (std::uint32_t u : scratch_)
            if (new_triangle(u, w)) f.push_back(w);
        }
        // A vertex all of whose triangles go (the apex of a cap of three
        // triangles closing one side) goes with them.
        if (!f.empty() && !closed_fan(x, f)) {
          ok = false;
          break;
        }
      }
      if (!ok) continue;
      // Geometry: as for the other repairs.
      Vec3 ref;
      for (const auto& r : cand.rewritten) {
        const std::uint32_t* w = T_ + 3 * std::size_t(r.first);
        ref = ref + cross(load(P_, w[1]) - load(P_, w[0]), load(P_, w[2]) - load(P_, w[0]));
      }
      double score = 2;
      for (const auto& r : cand.rewritten) {
        Vec3 q[3], o[3];
        for (int k = 0; k < 3; ++k) {
          o[k] = load(P_, T_[3 * std::size_t(r.first) + k]);
          q[k] = r.second[k] == a || r.second[k] == b ? cand.p : o[k];
        }
        const TriangleShape s_new = triangle_shape(q[0], q[1], q[2]);
        const int c_old = class_of(o[0], o[1], o[2]);
        const int c_new = triangle_class(s_new, degenerate_double_area_);
        if (c_new == 2 || (c_old == 0 && c_new != 0)) {
          ok = false;
          break;
        }
        const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]);
        const Vec3 n_ref = c_old == 0 ? cross(o[1] - o[0], o[2] - o[0]) : ref;
        if (dot(n_new, n_ref) <= cos_limit * norm(n_new) * norm(n_ref)) {
          ok = false;
          break;
        }
        score = std::min(score, s_new.sin_min_angle);
      }
      if (!ok || score <= best.score) continue;
      cand.valid = true;
      cand.score = score;
      best = std::move(cand);
    }
  }

  void apply_cut(const CutCandidate& c) {
    for (std::uint32_t u : c.removed) log_alive(u), store_relaxed(alive_[u], std::uint8_t(0));
    for (const auto& r : c.rewritten) {
      log_triangle(r.first);
      for (int k = 0; k < 3; ++k) store_relaxed(T_[3 * std::size_t(r.first) + k], r.second[k]);
      add_incidence(contains(r.second.data(), c.a) ? c.a : c.b, r.first);
    }
    const std::uint32_t ends[2] = {c.a, c.b};  // (nvcc's front end rejects {c.a, c.b} in a range-for)
    for (std::uint32_t x : ends) {
      log_position(x);
      P_[3 * std::size_t(x)] = Real(c.p.x);
      P_[3 * std::size_t(x) + 1] = Real(c.p.y);
      P_[3 * std::size_t(x) + 2] = Real(c.p.z);
      changed_vertices_.push_back(x);  // (its fan holds the rewritten triangles)
    }
    ++cuts;
  }

  // A needle t whose short edge (a, b) cannot be collapsed because a and b
  // share neighbours besides the two opposite vertices (the link condition
  // fails), and that no cut can repair: YT10's sharp creases make these
  // where the zero set pinches near a grid vertex, the shared neighbours a
  // fraction of a cell away (3-cycles through (a, b) that are no triangle,
  // or a vertex of degree three capping the edge). The cluster K = {a, b},
  // the shared neighbours closer than kClusterReach times the needle's long
  // edge, and what is joined to them by edges shorter than sin(1 degree)
  // times it, is merged: the triangles with two or three vertices in K go;
  // those with one form closed loops of their opposite edges around K, and
  // each loop gets one vertex of K (the lowest-numbered among its
  // triangles' not taken by an earlier loop), all at K's centre or all at
  // one of K's vertices (the best); when none of these works, each at a
  // point of its own (see the header: more candidates, a pattern search). One loop: a collapse of K (the surface
  // keeps its topology); two or more: a cut, the parts touching at a point.
  // Every vertex around keeps one closed fan of at least three triangles,
  // and the geometry is checked as for the other repairs.
  struct ClusterCandidate {
    bool valid = false;
    Vec3 p;
    std::vector<Vec3> positions;  // of loop_vertices, when they differ (else all at p)
    bool strip = false;           // a strip's two ends merged (consider_strip)
    std::vector<std::uint32_t> cluster, removed, loop_vertices;
    std::vector<std::pair<std::uint32_t, std::array<std::uint32_t, 3>>> rewritten;  // kept triangles, new vertices
  };
  static constexpr double kClusterReach = 0.25;
  static constexpr std::size_t kClusterMax = 8;

  // A triangle of a cluster or strip merge that goes from corners o to q:
  // -1 if it breaks a rule (it becomes degenerate, a good triangle becomes
  // bad, or its normal turns beyond cos_limit from its own, or from ref
  // for a bad one), 2 if it was bad and stays so (as for the last round's
  // collapses: a degenerate triangle may stay degenerate, a bad one bad),
  // else its new smallest angle's sine.
  double merged_triangle_score(const Vec3 o[3], const Vec3 q[3], const Vec3& ref) const {
    const TriangleShape s_new = triangle_shape(q[0], q[1], q[2]);
    const int c_old = class_of(o[0], o[1], o[2]);
    const int c_new = triangle_class(s_new, degenerate_double_area_);
    if (c_old != 0 && c_new != 0 && (c_new != 2 || c_old == 2)) return 2;
    const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]);
    const Vec3 n_ref = c_old == 0 ? cross(o[1] - o[0], o[2] - o[0]) : ref;
    if (c_new == 2 || (c_old == 0 && c_new != 0) || dot(n_new, n_ref) <= cos_limit * norm(n_new) * norm(n_ref))
      return -1;
    return s_new.sin_min_angle;
  }

  // How far a triangle that was good stays from the rules' limits when its
  // corners go from o to q: the least of its smallest angle's sine above
  // sin 1 degree and its normal's cosine to its old one above cos_limit
  // (negative: a rule broken); 1 (no bound) for a triangle that was bad.
  double good_triangle_margin(const Vec3 o[3], const Vec3 q[3]) const {
    if (class_of(o[0], o[1], o[2]) != 0) return 1;
    const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]), n_old = cross(o[1] - o[0], o[2] - o[0]);
    const double ln = norm(n_new) * norm(n_old);
    return std::min(triangle_shape(q[0], q[1], q[2]).sin_min_angle - kSinOneDegree,
                    ln > 0 ? dot(n_new, n_old) / ln - cos_limit : -1.0);
  }

  // The pattern search of the cluster and strip merges, for a point that
  // none of their listed points gives: from p (margin m), a step of h along
  // the axis direction of largest margin(q) among those that improve it and
  // stay within reach of centre, h halved when none does, for at most 200
  // steps and while h > 1e-3 reach; stops at the first p with m > 0 that
  // accept(p) takes (true), else false. p and m are the last step's.
  template <class Margin, class Accept>
  static bool pattern_search(Vec3& p, double& m, double h, const Vec3& centre, double reach, Margin&& margin,
                             Accept&& accept) {
    const Vec3 dirs[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    for (int step = 0; step < 200 && h > 1e-3 * reach; ++step) {
      int best_dir = -1;
      double best_m = m;
      for (int d = 0; d < 6; ++d) {
        const Vec3 q = p + h * dirs[d];
        if (norm(q - centre) > reach) continue;
        const double mq = margin(q);
        if (mq > best_m) best_m = mq, best_dir = d;
      }
      if (best_dir < 0) {
        h *= 0.5;
        continue;
      }
      p = p + h * dirs[best_dir], m = best_m;
      if (m > 0 && accept(p)) return true;
    }
    return false;
  }

  void consider_cluster(std::uint32_t t, ClusterCandidate& best) {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    int k_short = 0;
    double l_short = 0, l_long = 0;
    needle_edges(v, k_short, l_short, l_long);
    const double near = kSinOneDegree * l_long;
    const std::uint32_t a = v[k_short], b = v[(k_short + 1) % 3];
    const Vec3 pa = load(P_, a);
    fan(a, fa_);
    ring(a, fa_, ra_);
    fan(b, fb_);
    ring(b, fb_, rb_);
    common_.clear();
    std::set_intersection(ra_.begin(), ra_.end(), rb_.begin(), rb_.end(), std::back_inserter(common_));
    // The opposite vertices of (a, b).
    std::vector<std::uint32_t> opposite;
    for (std::uint32_t u : fa_) {
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      if (contains(w, b)) opposite.push_back(w[0] != a && w[0] != b ? w[0] : w[1] != a && w[1] != b ? w[1] : w[2]);
    }
    if (opposite.size() != 2 || common_.size() <= 2) return;
    std::vector<std::uint32_t> K = {a, b}, far;
    for (std::uint32_t x : common_)
      if (x != opposite[0] && x != opposite[1]) {
        if (norm(load(P_, x) - pa) < kClusterReach * l_long) K.push_back(x);
        else far.push_back(x);
      }
    if (!far.empty()) {
      consider_strip(K, far, opposite, l_long, best);
      return;
    }
    for (std::size_t i = 0; i < K.size() && K.size() <= kClusterMax; ++i) {
      fan(K[i], fb_);
      ring(K[i], fb_, rb_);
      for (std::uint32_t u : rb_)
        if (norm(load(P_, u) - load(P_, K[i])) < near && std::find(K.begin(), K.end(), u) == K.end()) K.push_back(u);
    }
    if (K.size() > kClusterMax) return;
    std::sort(K.begin(), K.end());
    auto in_k = [&](std::uint32_t x) { return std::binary_search(K.begin(), K.end(), x); };
    // The star of K: triangles with two or three vertices in K go; each of
    // the others, (k, x, y) with k in K, leaves the edge x -> y.
    std::vector<std::uint32_t> star;
    for (std::uint32_t x : K) {
      if (irregular(x)) return;
      fan(x, scratch_);
      star.insert(star.end(), scratch_.begin(), scratch_.end());
    }
    std::sort(star.begin(), star.end());
    star.erase(std::unique(star.begin(), star.end()), star.end());
    ClusterCandidate cand;
    std::vector<std::array<std::uint32_t, 3>> edges;  // (x, y, triangle) of the kept triangles
    for (std::uint32_t u : star) {
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      int on = 0, k_on = 0;
      for (int k = 0; k < 3; ++k) {
        if (irregular(w[k])) return;
        if (in_k(w[k])) ++on, k_on = k;
      }
      if (on >= 2) cand.removed.push_back(u);
      else edges.push_back({w[(k_on + 1) % 3], w[(k_on + 2) % 3], u});
    }
    if (edges.size() < 3) return;
    // The loops: from each edge to the one starting where it ends.
    std::sort(edges.begin(), edges.end());
    for (std::size_t i = 1; i < edges.size(); ++i)
      if (edges[i][0] == edges[i - 1][0]) return;
    std::vector<std::uint8_t> taken(edges.size(), 0);
    for (std::size_t i0 = 0; i0 < edges.size(); ++i0) {
      if (taken[i0]) continue;
      std::vector<std::uint32_t> loop;  // triangles
      std::uint32_t owner = kNone;
      for (std::size_t i = i0; !taken[i];) {
        taken[i] = 1;
        loop.push_back(edges[i][2]);
        // (the reverse edge around K too: two triangles would fold onto one)
        const std::array<std::uint32_t, 3> rev = {edges[i][1], edges[i][0], 0};
        const auto r = std::lower_bound(edges.begin(), edges.end(), rev);
        if (r != edges.end() && (*r)[0] == rev[0] && (*r)[1] == rev[1]) return;
        for (int k = 0; k < 3; ++k) {
          const std::uint32_t x = T_[3 * std::size_t(edges[i][2]) + k];
          if (in_k(x) && x < owner &&
              std::find(cand.loop_vertices.begin(), cand.loop_vertices.end(), x) == cand.loop_vertices.end())
            owner = x;
        }
        const std::array<std::uint32_t, 3> key = {edges[i][1], 0, 0};
        const auto it = std::lower_bound(edges.begin(), edges.end(), key);
        if (it == edges.end() || (*it)[0] != edges[i][1]) return;  // an open chain
        i = std::size_t(it - edges.begin());
        if (taken[i] && i != i0) return;
      }
      if (loop.size() < 3 || owner == kNone) return;
      cand.loop_vertices.push_back(owner);
      for (std::uint32_t u : loop) {
        std::array<std::uint32_t, 3> w;
        for (int k = 0; k < 3; ++k) {
          w[k] = T_[3 * std::size_t(u) + k];
          if (in_k(w[k])) w[k] = owner;
        }
        cand.rewritten.push_back({u, w});
      }
    }
    std::sort(cand.removed.begin(), cand.removed.end());
    std::sort(cand.rewritten.begin(), cand.rewritten.end());
    // Topology: every vertex outside K around the changed triangles keeps
    // one closed fan (or loses all of its triangles).
    std::vector<std::uint32_t> touched;
    for (std::uint32_t u : star) touched.insert(touched.end(), T_ + 3 * std::size_t(u), T_ + 3 * std::size_t(u) + 3);
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    std::vector<std::array<std::uint32_t, 3>> f;
    for (std::uint32_t x : touched) {
      if (in_k(x)) continue;
      f.clear();
      fan(x, scratch_);
      for (std::uint32_t u : scratch_) {
        if (std::binary_search(cand.removed.begin(), cand.removed.end(), u)) continue;
        const auto it = std::lower_bound(cand.rewritten.begin(), cand.rewritten.end(),
                                         std::make_pair(u, std::array<std::uint32_t, 3>{0, 0, 0}));
        if (it != cand.rewritten.end() && it->first == u) f.push_back(it->second);
        else f.push_back({T_[3 * std::size_t(u)], T_[3 * std::size_t(u) + 1], T_[3 * std::size_t(u) + 2]});
      }
      if (!f.empty() && !closed_fan(x, f)) return;
    }
    // Geometry: as for the other repairs, every vertex of K at one point:
    // K's centre or one of K's vertices, the best.
    Vec3 ref;
    for (const auto& r : cand.rewritten) {
      const std::uint32_t* w = T_ + 3 * std::size_t(r.first);
      ref = ref + cross(load(P_, w[1]) - load(P_, w[0]), load(P_, w[2]) - load(P_, w[0]));
    }
    // The smallest angle's sine over the rewritten triangles of the loop
    // kept by `owner` (kNone: all), with K's vertex at p; -1 when one of
    // them breaks a rule.
    auto score_at = [&](const Vec3& p, std::uint32_t owner) {
      double score = 2;
      for (const auto& r : cand.rewritten) {
        if (owner != kNone && !contains(r.second.data(), owner)) continue;
        Vec3 q[3], o[3];
        for (int k = 0; k < 3; ++k) {
          o[k] = load(P_, T_[3 * std::size_t(r.first) + k]);
          q[k] = in_k(r.second[k]) ? p : o[k];
        }
        const double s = merged_triangle_score(o, q, ref);
        if (s < 0) return -1.0;
        score = std::min(score, s);
      }
      return score;
    };
    auto rounded = [](const Vec3& c) { return Vec3{double(Real(c.x)), double(Real(c.y)), double(Real(c.z))}; };
    Vec3 centre;
    for (std::uint32_t x : K) centre = centre + load(P_, x);
    centre = (1.0 / double(K.size())) * centre;
    double best_score = -1;
    for (std::size_t i = 0; i <= K.size(); ++i) {
      const Vec3 p = rounded(i == 0 ? centre : load(P_, K[i - 1]));
      const double score = score_at(p, kNone);
      if (score > best_score) best_score = score, cand.p = p;
    }
    if (!(best_score > 0)) {
      // No common point works (YT10's needles beside triangles of just
      // over a degree, which every move of K's vertex makes bad or turns
      // over): each loop's vertex at the best point for its own
      // triangles (they touch only that loop's vertex), among K's centre,
      // K's vertices, the midpoints of two of them and the centre of the
      // loop's own vertices of K.
      std::vector<Vec3> points = {centre};
      for (std::uint32_t x : K) points.push_back(load(P_, x));
      for (std::size_t i = 0; i < K.size(); ++i)
        for (std::size_t j = i + 1; j < K.size(); ++j) points.push_back(0.5 * (load(P_, K[i]) + load(P_, K[j])));
      const std::size_t shared = points.size();
      for (std::uint32_t owner : cand.loop_vertices) {
        points.resize(shared);
        // (the loop's triangles' vertices in K, before the merge)
        std::vector<std::uint32_t> own;
        for (const auto& r : cand.rewritten)
          if (contains(r.second.data(), owner))
            for (int k = 0; k < 3; ++k) {
              const std::uint32_t x = T_[3 * std::size_t(r.first) + k];
              if (in_k(x) && std::find(own.begin(), own.end(), x) == own.end()) own.push_back(x);
            }
        std::sort(own.begin(), own.end());
        Vec3 c;
        for (std::uint32_t x : own) c = c + load(P_, x);
        points.push_back((1.0 / double(own.size())) * c);
        double loop_best = -1;
        Vec3 at;
        for (const Vec3& q : points) {
          const Vec3 p = rounded(q);
          const double score = score_at(p, owner);
          if (score > loop_best) loop_best = score, at = p;
        }
        if (!(loop_best > 0)) {
          // None of them: a pattern search (steps along the axes, halved
          // when none improves) for a point that keeps its good triangles
          // within the rules' limits (the smallest angle's sine above
          // sin(1 degree), the normal's turn below the limit: the least
          // margin, maximized), from the best of them, within
          // kClusterReach times the needle's long edge of K's centre; the
          // first that works.
          auto margin = [&](const Vec3& p) {
            double m = 1;
            for (const auto& r : cand.rewritten) {
              if (!contains(r.second.data(), owner)) continue;
              Vec3 q[3], o[3];
              for (int k = 0; k < 3; ++k) {
                o[k] = load(P_, T_[3 * std::size_t(r.first) + k]);
                q[k] = in_k(r.second[k]) ? p : o[k];
              }
              m = std::min(m, good_triangle_margin(o, q));
            }
            return m;
          };
          const double reach = kClusterReach * l_long;
          Vec3 p = points[0];
          double m = margin(p);
          for (std::size_t i = 1; i < points.size(); ++i) {
            const double mi = margin(points[i]);
            if (mi > m) m = mi, p = points[i];
          }
          double h = 0;
          for (std::uint32_t x : K) h = std::max(h, norm(load(P_, x) - centre));
          pattern_search(p, m, h, centre, reach, margin,
                         [&](const Vec3& q) { return score_at(rounded(q), owner) > 0; });
          if (m > 0) {
            const Vec3 q = rounded(p);
            const double score = score_at(q, owner);
            if (score > loop_best) loop_best = score, at = q;
          }
        }
        if (!(loop_best > 0)) return;
        cand.positions.push_back(at);
      }
    }
    cand.cluster = std::move(K);
    cand.valid = true;
    best = std::move(cand);
  }

  // The needle's short edge (a, b) and its far end: the shared neighbours
  // of a and b beyond kClusterReach lie next to one of the needle's
  // opposite vertices o (a strip of slivers between two pinches, as on
  // YT10's sheets thinner than a cell). Both ends are merged at once, all
  // of an end's vertices at its centre: `near_end` (a, b and the shared
  // neighbours close to them) and o with the far ones (each with what is
  // joined to it by edges shorter than sin(1 degree) times the long edge);
  // the triangles with two vertices in one end go, so do two that become
  // one another's reverse, and each end keeps one vertex per loop of the
  // triangles around it. Every vertex around, the kept ones included, must
  // keep one closed fan; the geometry is checked as above, with the ends'
  // centres first, else with points of the loop vertices' own.
  void consider_strip(std::vector<std::uint32_t> near_end, const std::vector<std::uint32_t>& far,
                      const std::vector<std::uint32_t>& opposite, double l_long, ClusterCandidate& best) {
    const double reach = kClusterReach * l_long, near = kSinOneDegree * l_long;
    std::uint32_t o = kNone;
    for (std::uint32_t x : far)
      for (std::uint32_t y : opposite)
        if (norm(load(P_, x) - load(P_, y)) < reach) {
          if (o != kNone && o != y) return;
          o = y;
        }
    if (o == kNone) return;
    std::vector<std::uint32_t> far_end = {o};
    for (std::uint32_t x : far) {
      if (!(norm(load(P_, x) - load(P_, o)) < reach)) return;
      far_end.push_back(x);
    }
    // Each end with what is joined to it by edges shorter than `near`.
    std::vector<std::uint32_t>* ends[2] = {&near_end, &far_end};
    for (auto* e : ends)
      for (std::size_t i = 0; i < e->size() && e->size() <= kClusterMax; ++i) {
        fan((*e)[i], fb_);
        ring((*e)[i], fb_, rb_);
        for (std::uint32_t u : rb_)
          if (norm(load(P_, u) - load(P_, (*e)[i])) < near && std::find(e->begin(), e->end(), u) == e->end())
            e->push_back(u);
      }
    if (near_end.size() + far_end.size() > kClusterMax) return;
    std::vector<std::pair<std::uint32_t, int>> group;  // (vertex, end)
    for (int g = 0; g < 2; ++g)
      for (std::uint32_t x : *ends[g]) group.push_back({x, g});
    std::sort(group.begin(), group.end());
    for (std::size_t i = 1; i < group.size(); ++i)
      if (group[i].first == group[i - 1].first) return;  // the ends touch
    auto end_of = [&](std::uint32_t x) {
      const auto it = std::lower_bound(group.begin(), group.end(), std::make_pair(x, -1));
      return it != group.end() && it->first == x ? it->second : -1;
    };
    std::uint32_t rep[2];
    for (int g = 0; g < 2; ++g) rep[g] = *std::min_element(ends[g]->begin(), ends[g]->end());
    std::vector<std::uint32_t> star;
    for (const auto& x : group) {
      if (irregular(x.first)) return;
      fan(x.first, scratch_);
      star.insert(star.end(), scratch_.begin(), scratch_.end());
    }
    std::sort(star.begin(), star.end());
    star.erase(std::unique(star.begin(), star.end()), star.end());
    ClusterCandidate cand;
    for (std::uint32_t u : star) {
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      int count[2] = {0, 0};
      std::array<std::uint32_t, 3> nw;
      for (int k = 0; k < 3; ++k) {
        if (irregular(w[k])) return;
        const int g = end_of(w[k]);
        nw[k] = g < 0 ? w[k] : rep[g];
        if (g >= 0) ++count[g];
      }
      if (count[0] >= 2 || count[1] >= 2) cand.removed.push_back(u);
      else cand.rewritten.push_back({u, nw});
    }
    {
      // Two kept triangles that become one another's reverse (a vertex
      // between the pinches, joined to both ends on both of its sides)
      // fold onto each other: both go. (Before, such a pair always failed
      // the loops below.) The same triangle twice: no merge.
      std::vector<std::pair<std::array<std::uint32_t, 3>, std::uint32_t>> keys;  // (sorted vertices, index)
      for (std::size_t i = 0; i < cand.rewritten.size(); ++i) {
        std::array<std::uint32_t, 3> k = cand.rewritten[i].second;
        std::sort(k.begin(), k.end());
        keys.push_back({k, std::uint32_t(i)});
      }
      std::sort(keys.begin(), keys.end());
      std::vector<std::uint8_t> folded(cand.rewritten.size(), 0);
      for (std::size_t i = 0; i + 1 < keys.size(); ++i) {
        if (keys[i].first != keys[i + 1].first) continue;
        if (i + 2 < keys.size() && keys[i + 2].first == keys[i].first) return;
        const auto& w = cand.rewritten[keys[i].second].second;
        const auto& x = cand.rewritten[keys[i + 1].second].second;
        // (the same cyclic order: the same triangle, not its reverse)
        if (x == w || x == std::array<std::uint32_t, 3>{w[1], w[2], w[0]} ||
            x == std::array<std::uint32_t, 3>{w[2], w[0], w[1]})
          return;
        folded[keys[i].second] = folded[keys[i + 1].second] = 1;
        ++i;
      }
      std::size_t kept = 0;
      for (std::size_t i = 0; i < cand.rewritten.size(); ++i) {
        if (folded[i]) cand.removed.push_back(cand.rewritten[i].first);
        else cand.rewritten[kept++] = cand.rewritten[i];
      }
      cand.rewritten.resize(kept);
    }
    std::sort(cand.removed.begin(), cand.removed.end());
    // Topology: the merged vertices and every vertex around keep one
    // closed fan (the others around may lose all of theirs).
    std::vector<std::uint32_t> touched;
    for (std::uint32_t u : star) touched.insert(touched.end(), T_ + 3 * std::size_t(u), T_ + 3 * std::size_t(u) + 3);
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    // Each end's triangles form one or more loops around it (the sheet's
    // two sides at a pinch): one vertex of the end for each, as in
    // consider_cluster.
    for (int g = 0; g < 2; ++g) {
      std::vector<std::array<std::uint32_t, 4>> edges;  // (x, y, index in rewritten, 0)
      for (std::size_t i = 0; i < cand.rewritten.size(); ++i) {
        const auto& w = cand.rewritten[i].second;
        for (int k = 0; k < 3; ++k)
          if (w[k] == rep[g]) edges.push_back({w[(k + 1) % 3], w[(k + 2) % 3], std::uint32_t(i), 0});
      }
      std::sort(edges.begin(), edges.end());
      for (std::size_t i = 1; i < edges.size(); ++i)
        if (edges[i][0] == edges[i - 1][0]) return;
      std::vector<std::uint32_t> members = *ends[g];
      std::sort(members.begin(), members.end());
      std::size_t loops = 0;
      for (std::size_t i0 = 0; i0 < edges.size(); ++i0) {
        if (edges[i0][3]) continue;
        if (loops == members.size()) return;
        const std::uint32_t owner = members[loops++];
        std::size_t len = 0;
        for (std::size_t i = i0; !edges[i][3];) {
          edges[i][3] = 1;
          ++len;
          auto& w = cand.rewritten[edges[i][2]].second;
          for (int k = 0; k < 3; ++k)
            if (w[k] == rep[g]) w[k] = owner;
          const std::array<std::uint32_t, 4> key = {edges[i][1], 0, 0, 0};
          const auto it = std::lower_bound(edges.begin(), edges.end(), key);
          if (it == edges.end() || (*it)[0] != edges[i][1]) return;
          i = std::size_t(it - edges.begin());
          if (edges[i][3] && i != i0) return;
        }
        if (len < 3) return;
        cand.loop_vertices.push_back(owner);
      }
      if (loops == 0) return;
    }
    std::vector<std::array<std::uint32_t, 3>> f;
    for (std::uint32_t x : cand.loop_vertices) {
      f.clear();
      for (const auto& r : cand.rewritten)
        if (contains(r.second.data(), x)) f.push_back(r.second);
      if (!closed_fan(x, f)) return;
    }
    for (std::uint32_t x : touched) {
      if (end_of(x) >= 0) continue;
      f.clear();
      fan(x, scratch_);
      for (std::uint32_t u : scratch_) {
        if (std::binary_search(cand.removed.begin(), cand.removed.end(), u)) continue;
        const auto it = std::lower_bound(cand.rewritten.begin(), cand.rewritten.end(),
                                         std::make_pair(u, std::array<std::uint32_t, 3>{0, 0, 0}));
        if (it != cand.rewritten.end() && it->first == u) f.push_back(it->second);
        else f.push_back({T_[3 * std::size_t(u)], T_[3 * std::size_t(u) + 1], T_[3 * std::size_t(u) + 2]});
      }
      if (!f.empty() && !closed_fan(x, f)) return;
    }
    // Geometry: each end at its centre.
    Vec3 at[2];
    for (int g = 0; g < 2; ++g) {
      Vec3 c;
      for (std::uint32_t x : *ends[g]) c = c + load(P_, x);
      c = (1.0 / double(ends[g]->size())) * c;
      at[g] = Vec3{double(Real(c.x)), double(Real(c.y)), double(Real(c.z))};
    }
    Vec3 ref;
    for (const auto& r : cand.rewritten) {
      const std::uint32_t* w = T_ + 3 * std::size_t(r.first);
      ref = ref + cross(load(P_, w[1]) - load(P_, w[0]), load(P_, w[2]) - load(P_, w[0]));
    }
    // The loop vertices' points (in loop_vertices' order); whether the
    // rewritten triangles keep the rules with them, and (margin) the least
    // margin of the good ones to the rules' limits.
    std::vector<Vec3> ps;
    for (std::uint32_t x : cand.loop_vertices) ps.push_back(at[end_of(x)]);
    auto point_of = [&](std::uint32_t x) {
      return ps[std::size_t(std::find(cand.loop_vertices.begin(), cand.loop_vertices.end(), x) -
                            cand.loop_vertices.begin())];
    };
    auto shapes = [&](const std::pair<std::uint32_t, std::array<std::uint32_t, 3>>& r, Vec3* q, Vec3* o3) {
      for (int k = 0; k < 3; ++k) {
        o3[k] = load(P_, T_[3 * std::size_t(r.first) + k]);
        q[k] = end_of(r.second[k]) < 0 ? o3[k] : point_of(r.second[k]);
      }
    };
    auto works = [&] {
      for (const auto& r : cand.rewritten) {
        Vec3 q[3], o3[3];
        shapes(r, q, o3);
        if (merged_triangle_score(o3, q, ref) < 0) return false;
      }
      return true;
    };
    if (!works()) {
      // Not at the centres (YT10's strips beside triangles of just over a
      // degree): each loop vertex in turn, the others kept, at the best of
      // its end's centre, the end's vertices and their midpoints, then
      // moved by a pattern search (as in consider_cluster) within
      // kClusterReach times the long edge of its end's centre, each
      // maximizing the least margin of all the good triangles to the
      // rules' limits, until the whole works.
      auto margin = [&] {
        double m = 1;
        for (const auto& r : cand.rewritten) {
          Vec3 q[3], o3[3];
          shapes(r, q, o3);
          m = std::min(m, good_triangle_margin(o3, q));
        }
        return m;
      };
      auto rounded = [](const Vec3& c) { return Vec3{double(Real(c.x)), double(Real(c.y)), double(Real(c.z))}; };
      bool ok = false;
      for (std::size_t i = 0; i < ps.size() && !ok; ++i) {
        const std::vector<std::uint32_t>& e = *ends[end_of(cand.loop_vertices[i])];
        const Vec3 centre = at[end_of(cand.loop_vertices[i])];
        std::vector<Vec3> points = {centre};
        for (std::uint32_t x : e) points.push_back(load(P_, x));
        for (std::size_t j = 0; j < e.size(); ++j)
          for (std::size_t k = j + 1; k < e.size(); ++k) points.push_back(0.5 * (load(P_, e[j]) + load(P_, e[k])));
        double m = -2;
        Vec3 p = centre;
        for (const Vec3& q : points) {
          ps[i] = rounded(q);
          const double mq = margin();
          if (mq > m) m = mq, p = ps[i];
        }
        ps[i] = p;
        if (m > 0 && works()) {
          ok = true;
          break;
        }
        double h = 0;
        for (std::uint32_t x : e) h = std::max(h, norm(load(P_, x) - centre));
        ok = pattern_search(
            p, m, h, centre, reach,
            [&](const Vec3& q) {
              ps[i] = q;
              return margin();
            },
            [&](const Vec3& q) {
              ps[i] = rounded(q);
              const bool w = works();
              ps[i] = q;
              return w;
            });
        ps[i] = rounded(p);
        if (!ok && m > 0 && works()) ok = true;
      }
      if (!ok) return;
    }
    cand.positions = ps;
    cand.cluster = near_end;
    cand.cluster.insert(cand.cluster.end(), far_end.begin(), far_end.end());
    cand.strip = true;
    cand.valid = true;
    best = std::move(cand);
  }

  void apply_cluster(const ClusterCandidate& c) {
    for (std::uint32_t u : c.removed) log_alive(u), store_relaxed(alive_[u], std::uint8_t(0));
    for (const auto& r : c.rewritten) {
      log_triangle(r.first);
      std::uint32_t owner = kNone;
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t old = T_[3 * std::size_t(r.first) + k];
        if (old != r.second[k]) owner = r.second[k];
        store_relaxed(T_[3 * std::size_t(r.first) + k], r.second[k]);
      }
      if (owner != kNone) add_incidence(owner, r.first);
      changed_triangles_.push_back(r.first);
    }
    for (std::size_t i = 0; i < c.loop_vertices.size(); ++i) {
      const std::uint32_t x = c.loop_vertices[i];
      const Vec3& p = c.positions.empty() ? c.p : c.positions[i];
      log_position(x);
      P_[3 * std::size_t(x)] = Real(p.x);
      P_[3 * std::size_t(x) + 1] = Real(p.y);
      P_[3 * std::size_t(x) + 2] = Real(p.z);
      changed_vertices_.push_back(x);
    }
    // Counted as the repairs that remove as many triangles, so that every
    // removed triangle is counted once (nbmc_stats: raw - kept = 2
    // collapses + 6 cuts + removed components): a merge into more than one
    // loop (not a strip) as a cut of six, the rest as collapses of two. (A
    // closed mesh keeps an even count: the triangles removed are even.)
    const std::size_t removed = c.removed.size();
    const bool cut = c.loop_vertices.size() > 1 && !c.strip && removed >= 6;
    if (cut) ++cuts;
    collapses += (removed - (cut ? 6 : 0)) / 2;
  }

  void consider_flip(std::uint32_t t, Candidate& best) {
    const std::uint32_t* v = T_ + 3 * std::size_t(t);
    // The longest edge (a, b), in the triangle's direction; c opposite.
    int k_long = 0;
    double l_long = -1;
    for (int k = 0; k < 3; ++k) {
      const double l = norm(load(P_, v[(k + 1) % 3]) - load(P_, v[k]));
      if (l > l_long) l_long = l, k_long = k;
    }
    const std::uint32_t a = v[k_long], b = v[(k_long + 1) % 3], c = v[(k_long + 2) % 3];
    fan(a, fa_);
    std::uint32_t t2 = kNone;
    for (std::uint32_t u : fa_) {
      if (u == t) continue;
      const std::uint32_t* w = T_ + 3 * std::size_t(u);
      if (contains(w, b)) {
        if (t2 != kNone) return;
        t2 = u;
      }
    }
    if (t2 == kNone) return;
    const std::uint32_t* w = T_ + 3 * std::size_t(t2);
    const std::uint32_t d = w[0] != a && w[0] != b ? w[0] : w[1] != a && w[1] != b ? w[1] : w[2];
    if (d == c) return;
    // The new triangles' shapes and turns first, then what the fans say
    // (d regular, no edge c-d yet, a and b keep three triangles): the same
    // verdict, and most flips fail on the shapes or the score alone.
    const Vec3 pa = load(P_, a), pb = load(P_, b), pc = load(P_, c), pd = load(P_, d);
    const Vec3 n_old = cross(pb - pa, pc - pa) + cross(pa - pb, pd - pb);
    // New triangles (c, a, d) and (c, d, b).
    const TriangleShape s1 = triangle_shape(pc, pa, pd), s2 = triangle_shape(pc, pd, pb);
    if (triangle_class(s1, degenerate_double_area_) || triangle_class(s2, degenerate_double_area_)) return;
    const Vec3 n1 = cross(pa - pc, pd - pc), n2 = cross(pd - pc, pb - pc);
    for (const Vec3& n : {n1, n2})
      if (dot(n, n_old) <= cos_limit * norm(n) * norm(n_old)) return;
    if (dot(n1, n2) <= cos_limit * norm(n1) * norm(n2)) return;
    const double score = std::min(s1.sin_min_angle, s2.sin_min_angle);
    if (score <= best.score) return;
    if (irregular(d)) return;
    fan(c, fb_);
    ring(c, fb_, rb_);
    if (std::binary_search(rb_.begin(), rb_.end(), d)) return;  // edge c-d exists
    if (degree(a) < 4 || degree(b) < 4) return;
    best.valid = true;
    best.kind = Candidate::Flip;
    best.score = score;
    best.a = a;
    best.b = b;
    best.c = c;
    best.d = d;
    best.t1 = t;
    best.t2 = t2;
  }

  void apply_collapse(const Candidate& c) {
    const std::uint32_t a = c.a, b = c.b;
    fan(b, fb_);
    log_alive(c.t1);
    log_alive(c.t2);
    store_relaxed(alive_[c.t1], std::uint8_t(0));
    store_relaxed(alive_[c.t2], std::uint8_t(0));
    for (std::uint32_t t : fb_) {
      log_triangle(t);
      for (int k = 0; k < 3; ++k)
        if (T_[3 * std::size_t(t) + k] == b) store_relaxed(T_[3 * std::size_t(t) + k], a);
    }
    if (N_) {
      log_normal(a);
      float n[3];
      for (int x = 0; x < 3; ++x)
        n[x] = c.where == 0 ? 0.5f * (N_[3 * std::size_t(a) + x] + N_[3 * std::size_t(b) + x])
               : c.where == 1 ? N_[3 * std::size_t(a) + x]
                              : N_[3 * std::size_t(b) + x];
      const double l = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
      for (int x = 0; x < 3; ++x) N_[3 * std::size_t(a) + x] = l > 0 ? float(n[x] / l) : N_[3 * std::size_t(a) + x];
    }
    log_position(a);
    P_[3 * std::size_t(a)] = Real(c.p.x);
    P_[3 * std::size_t(a) + 1] = Real(c.p.y);
    P_[3 * std::size_t(a) + 2] = Real(c.p.z);
    // b's triangles now belong to a.
    log_chain(a);
    next_[tail_[a]] = b;
    tail_[a] = tail_[b];
    judged_vertices_.push_back(a);
    ++collapses;
  }

  void apply_flip(const Candidate& c) {
    std::uint32_t* t1 = T_ + 3 * std::size_t(c.t1);
    std::uint32_t* t2 = T_ + 3 * std::size_t(c.t2);
    log_triangle(c.t1);
    log_triangle(c.t2);
    store_relaxed(t1[0], c.c), store_relaxed(t1[1], c.a), store_relaxed(t1[2], c.d);
    store_relaxed(t2[0], c.c), store_relaxed(t2[1], c.d), store_relaxed(t2[2], c.b);
    // t1 now touches d and t2 touches c: extra entries in their lists (a
    // and b keep stale entries, which fan() skips).
    add_incidence(c.d, c.t1);
    add_incidence(c.c, c.t2);
    changed_triangles_.push_back(c.t1);
    changed_triangles_.push_back(c.t2);
    ++flips;
  }

  // A worker's undo log (repair_pass): the old value of everything its
  // repairs wrote, so that a pass can be put back as it was.
  struct Undo {
    enum Kind : std::uint8_t { Position, Normal, Triangle, Alive, Chain };
    Kind kind;
    std::uint32_t i;
    double x[3];
  };
  // Every write of a repair goes through one of these (before it), which
  // also stamps the vertices whose position or triangles it changes with
  // the repair's time (touch): a triangle's old vertices here, its new ones
  // are vertices whose position the same repair writes (a collapse's or a
  // cut's kept ends, a merge's loop vertices) or were its old ones (flips).
  // (Before the first such write, v's flag of the input mesh is fixed:
  // irregular().)
  void touch(std::uint32_t v) {
    irregular(v);
    if (repair_scratch_) {
      std::uint32_t& mod = repair_scratch_->slots[v].mod;
      if (mod < now_) mod = now_;
    }
  }
  void touch_triangle(std::uint32_t t) {
    for (int k = 0; k < 3; ++k) touch(T_[3 * std::size_t(t) + k]);
  }
  // The first write of a vertex's position or normal, or of a triangle's
  // vertices (with track_changes): flagged and listed by the Cleaner that
  // writes it (a round's regions are disjoint: no other writes it then).
  void changed_vertex(std::uint32_t v) {
    if (vchanged_ && !vchanged_[v]) {
      vchanged_[v] = 1;
      vlist_.push_back(v);
    }
  }
  void changed_triangle(std::uint32_t t) {
    if (tchanged_ && !tchanged_[t]) {
      tchanged_[t] = 1;
      tlist_.push_back(t);
    }
  }
  void log_position(std::uint32_t v) {
    changed_vertex(v);
    touch(v);
    if (worker_) log_.push_back({Undo::Position, v, {double(P_[3 * std::size_t(v)]), double(P_[3 * std::size_t(v) + 1]), double(P_[3 * std::size_t(v) + 2])}});
  }
  void log_normal(std::uint32_t v) {
    changed_vertex(v);
    touch(v);
    if (worker_) log_.push_back({Undo::Normal, v, {double(N_[3 * std::size_t(v)]), double(N_[3 * std::size_t(v) + 1]), double(N_[3 * std::size_t(v) + 2])}});
  }
  void log_triangle(std::uint32_t t) {
    lost(t);
    changed_triangle(t);
    touch_triangle(t);
    if (worker_) log_.push_back({Undo::Triangle, t, {double(T_[3 * std::size_t(t)]), double(T_[3 * std::size_t(t) + 1]), double(T_[3 * std::size_t(t) + 2])}});
  }
  void log_alive(std::uint32_t t) {
    touch_triangle(t);
    if (worker_) log_.push_back({Undo::Alive, t, {double(alive_[t]), 0, 0}});
    killed(t);
  }
  // For the compaction (compact()): a triangle about to be removed, and its
  // vertices, which may lose their last triangle with it.
  void killed(std::uint32_t t) {
    killed_.push_back(t);
    lost(t);
  }
  // ... a triangle's vertices, before its vertices are rewritten or it is
  // removed (each may lose its last triangle).
  void lost(std::uint32_t t) { lost_.insert(lost_.end(), T_ + 3 * std::size_t(t), T_ + 3 * std::size_t(t) + 3); }
  // a's chain of merged vertices: next_ of its tail, and its tail.
  void log_chain(std::uint32_t a) {
    touch(a);
    if (worker_) log_.push_back({Undo::Chain, a, {double(tail_[a]), double(next_[tail_[a]]), 0}});
  }
  // For the tests (RepairPassHooks::check_writes): how many of the writes
  // logged from log_[from] touch a vertex outside `region`.
  std::uint64_t writes_outside(std::vector<std::uint32_t> region, std::size_t from) const {
    std::sort(region.begin(), region.end());
    std::uint64_t n = 0;
    auto out = [&](double x) { return !std::binary_search(region.begin(), region.end(), std::uint32_t(x)) ? 1 : 0; };
    for (std::size_t k = from; k < log_.size(); ++k) {
      const Undo& u = log_[k];
      const std::uint32_t* w = T_ + 3 * std::size_t(u.i);
      switch (u.kind) {
        case Undo::Position:
        case Undo::Normal:
        case Undo::Chain:
          n += out(u.i);
          break;
        case Undo::Triangle:
          for (int j = 0; j < 3; ++j) n += out(u.x[j]) + out(w[j]);
          break;
        case Undo::Alive:
          for (int j = 0; j < 3; ++j) n += out(w[j]);
          break;
      }
    }
    return n;
  }
  // Puts back what the entries of `log` (in the order written) changed.
  // (Entries a worker added to extra_ stay: fan() skips a triangle that no
  // longer holds the vertex, and one that does is in the vertex's lists.)
  // Undoes log[begin, end), last entry first.
  void undo(const std::vector<Undo>& log, std::size_t begin, std::size_t end) {
    for (std::size_t k = end; k-- > begin;) {
      const Undo& u = log[k];
      const std::size_t i = u.i;
      switch (u.kind) {
        case Undo::Position:
          for (int k = 0; k < 3; ++k) P_[3 * i + k] = Real(u.x[k]);
          break;
        case Undo::Normal:
          for (int k = 0; k < 3; ++k) N_[3 * i + k] = float(u.x[k]);
          break;
        case Undo::Triangle:
          for (int k = 0; k < 3; ++k) T_[3 * i + k] = std::uint32_t(u.x[k]);
          break;
        case Undo::Alive:
          alive_[i] = std::uint8_t(u.x[0]);
          break;
        case Undo::Chain:
          tail_[i] = std::uint32_t(u.x[0]);
          next_[tail_[i]] = std::uint32_t(u.x[1]);
          break;
      }
    }
  }

  void add_incidence(std::uint32_t v, std::uint32_t t) {
    if (worker_) {  // (the main Cleaner adds them after the round)
      pending_incidence_.push_back({v, t});
      return;
    }
    extra_.push_back({t, extra_head_.get(v)});
    extra_head_.set(v, std::uint32_t(extra_.size() - 1));
  }

  Real* P_;
  float* N_;
  std::size_t nv_;
  std::uint32_t* T_;
  std::size_t nt_;
  // (Allocated unwritten, filled on all host threads: see the constructor.)
  // (The main Cleaner owns them; its workers, repair_pass' per-thread
  // copies, refer to the main one's through the references below.)
  using Bytes = std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>>;
  using Indices = std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>>;
  using Extra = std::vector<std::pair<std::uint32_t, std::uint32_t>>;
  Bytes alive_own_, irregular_own_;
  Indices start_own_, next_own_, tail_own_, incident_own_;
  ExtraHeads extra_head_own_;
  Extra extra_own_;
  Bytes& alive_ = alive_own_;
  Bytes& irregular_ = irregular_own_;
  Indices& start_ = start_own_;
  Indices& next_ = next_own_;
  Indices& tail_ = tail_own_;
  Indices& incident_ = incident_own_;
  ExtraHeads& extra_head_ = extra_head_own_;  // by vertex, into extra_ (after flips)
  Extra& extra_ = extra_own_;                                 // (triangle, next entry)
  double degenerate_double_area_ = 0;
  // The constructor's scan (initial_bad_triangles).
  std::vector<std::tuple<int, double, std::uint32_t>> initial_bad_;
  bool has_initial_bad_ = false;
  std::vector<std::uint32_t> fa_, fb_, ra_, rb_, common_, scratch_, around_, cluster_;
  // prepare_positions: the old class and normal of each triangle of around_,
  // and their sum.
  struct OldTriangle {
    Vec3 normal;
    double ref_norm = 0;  // the length of the normal a trial's is compared with (its own, or the mean)
    int cls = 0;
  };
  std::vector<OldTriangle> around_old_;
  Vec3 around_normal_;
  // What the repairs changed since the last bad_triangles_after(): vertices
  // moved or renamed into, triangles rewritten in place; and the vertices
  // moved or renamed into by a move or a collapse, whose every triangle the
  // repair judged (judged_vertices_: see bad_triangles_after).
  std::vector<std::uint32_t> changed_vertices_, changed_triangles_, judged_vertices_;
  // The component walks (the main Cleaner's): per triangle, its state, and
  // per vertex, whether the current walk has taken its fan (both cleared in
  // the constructor, on all host threads: a fresh array cleared by one
  // thread pays the mapping of its pages alone); the triangles whose state
  // a walk set and the vertices it took, so that they alone are cleared
  // again; the triangles of the current walk.
  Bytes state_, expanded_;
  std::vector<std::uint32_t> walked_, expanded_list_, component_;

  // repair_pass: a worker (a per-thread Cleaner on the main one's arrays)
  // logs its writes, defers its new incidences and keeps its own counts
  // and changed lists, which the main Cleaner takes after each round.
  bool worker_ = false;
  std::vector<Undo> log_;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> pending_incidence_;
  // A worker's log_ sizes at the end of each round of a parallel pass.
  std::vector<std::size_t> round_ends_;
  std::uint64_t repaired_ = 0;
  // The main Cleaner's workers.
  std::vector<std::unique_ptr<Cleaner>> workers_;
  // What compact() looks at instead of the whole mesh: the triangles
  // removed (killed(); an undone pass may have revived some) and the
  // vertices of every triangle rewritten or removed (lost()), repeats and
  // all; each Cleaner its own.
  std::vector<std::uint32_t> killed_, lost_;
  std::vector<std::uint32_t> bare_;  // vertices without a triangle in the input (the main Cleaner's)
  // The repair passes' per-vertex scratch (repair_scratch.hpp; the main
  // Cleaner's, taken by the first pass, given back by the destructor; its
  // workers use it through repair_scratch_): per vertex, the reservation, the
  // stamp and round of repair_pass, and the time of the last repair that
  // changed its position or triangles (start_times). Also for skipping
  // hopeless retries: the current item's time (each Cleaner's own); per
  // item of the pass, 0 (repaired) or when it failed; the failures of the
  // last pass (triangle, time), sorted, and under which limits.
  std::unique_ptr<RepairScratch> repair_scratch_own_;
  std::unique_ptr<RepairScratch>& repair_scratch_ = repair_scratch_own_;
  std::uint32_t now_ = 0;
  // With track_changes: per vertex, its position or normal was written; per
  // triangle, its vertices were (the main Cleaner's flags, null: not kept);
  // and each Cleaner's list of what it flagged.
  std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>> vchanged_own_, tchanged_own_;
  std::uint8_t* vchanged_ = nullptr;
  std::uint8_t* tchanged_ = nullptr;
  std::vector<std::uint32_t> vlist_, tlist_;
  std::vector<std::uint32_t> outcome_, region_;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> failed_;
  int failed_key_ = -1;
  std::uint64_t skipped_ = 0, skip_mismatches_ = 0;
  // ... and the last round (the scratch's round_base + its number) in
  // which an item that wrote something committed with the vertex in its
  // region: all in the scratch's slots (RepairSlot, per vertex).
};

}  // namespace detail

// Cleans the mesh in place: positions (3 floats or doubles per vertex) and
// normals (3 floats per vertex; may be empty), triangles (3 indices each).
// Vectors of any allocator; they are shrunk to the new counts.
// cell: the marching-cubes cell edge; with cell > 0, the components that
// still hold a bad triangle at the end and enclose less than
// kSmallComponentCells cells are removed (0: never).
// prebuilt: this mesh's incidence, built where it was made (may be null;
// taken when its sizes fit: see mesh_incidence.hpp); the result is the same.
// The compaction fills the removed entries' places from the end (Cleaner::
// compact()): the kept entries below the new counts stay where they were,
// and unreferenced vertices (also the input's) are dropped.
// changed (may be null): the places of the result whose contents may
// differ from the input's at the same place (ChangedEntries), for a
// caller that holds the input elsewhere and copies back only those.
template <class PosVec, class NormalVec, class IndexVec>
CleanupResult cleanup_mesh(PosVec& positions, NormalVec& normals, IndexVec& triangles, double cell = 0,
                           PrebuiltIncidence* prebuilt = nullptr, ChangedEntries* changed = nullptr) {
  CleanupResult r;
  const std::size_t nv = positions.size() / 3, nt = triangles.size() / 3;
  if (nt == 0) return r;
  const bool has_normals = !normals.empty() && normals.size() == positions.size();
  host_trace("clean-up: start", nt);
  // (Read before the Cleaner takes the prebuilt incidence.)
  const bool moved_before = prebuilt && prebuilt->moves_made;
  const std::uint64_t moved_bad_before = moved_before ? prebuilt->bad_before_moves : 0;
  const std::uint64_t moves_made = moved_before ? prebuilt->moves : 0;
  detail::Cleaner<typename PosVec::value_type> c(positions.data(), has_normals ? normals.data() : nullptr, nv, triangles.data(), nt,
                                                 prebuilt, changed != nullptr);
  // Passes until nothing more can be repaired; then again with a looser
  // limit on the normals' turn for what is left (folds stay excluded);
  // then, for what is still left, with the last resorts (collapses that
  // leave degenerate triangles degenerate, cuts of pinched tubes), so that
  // they never pre-empt a repair that keeps more of the mesh.
  // One scan of the whole mesh; after it, each pass looks again only at what
  // was bad and what the repairs changed (bad_triangles_after).
  auto bad = c.initial_bad_triangles();
  r.bad_before = bad.size();
  host_trace("clean-up: scan", bad.size());
  // First the moves, in rounds that need no order (mesh_moves.hpp), unless
  // they were made where the mesh was made (the scan above then found what
  // they left).
  if (moved_before) {
    r.bad_before = moved_bad_before;
    c.moves = moves_made;
  } else {
    bad = c.move_rounds(bad);
    host_trace("clean-up: moves", c.moves);
  }
  auto passes = [&] {
    for (int pass = 0; pass < kCleanupPasses && !bad.empty(); ++pass) {
      // (NBMC_TRACE: each pass' items, repairs and times, on a line of its
      // own that leaves host_trace's clock alone.)
      const bool trace = host_trace_on();
      const auto t0 = trace ? std::chrono::steady_clock::now() : std::chrono::steady_clock::time_point();
      const std::uint64_t repaired = c.repair_pass(bad);
      const auto t1 = trace ? std::chrono::steady_clock::now() : t0;
      const std::size_t items = bad.size();
      bad = c.bad_triangles_after(bad);
      if (trace)
        std::fprintf(stderr, "[nbmc trace] clean-up pass: items=%zu skipped=%zu repaired=%llu %.3f ms, list %.3f ms\n",
                     items, c.last_skipped(), (unsigned long long)repaired,
                     std::chrono::duration<double, std::milli>(t1 - t0).count(),
                     std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t1).count());
      if (repaired == 0) break;
    }
  };
  for (int round = 0; round < 3 && !bad.empty(); ++round) {
    c.cos_limit = round == 0 ? kCosMaxNormalTurn : kCosMaxNormalTurnLast;
    c.last_resort = round == 2;
    passes();
  }
  host_trace("clean-up: repairs", c.collapses + c.flips + c.moves + c.cuts);
  // What no repair could fix and is only noise: specks made of degenerate
  // triangles alone.
  if (!bad.empty()) {
    r.degenerate_component_triangles = c.drop_degenerate_components(bad);
    if (r.degenerate_component_triangles > 0) bad = c.alive_of(bad);
  }
  // ... and droplets smaller than a cell that still hold a bad triangle.
  if (!bad.empty() && cell > 0) {
    r.small_component_triangles = c.drop_small_bad_components(bad, kSmallComponentCells * cell * cell * cell);
    if (r.small_component_triangles > 0) bad = c.alive_of(bad);
  }
  // Then, in the larger components, the needles whose short edge fails the
  // link condition: their clusters are merged (after the removals, so that
  // a component that is noise goes whole as before).
  if (!bad.empty()) {
    c.cos_limit = kCosMaxNormalTurnLast;
    c.last_resort = true;
    c.merge_clusters = true;
    passes();
  }
  r.bad_after = bad.size();
  r.collapses = c.collapses;
  r.cuts = c.cuts;
  r.flips = c.flips;
  r.moves = c.moves;
  host_trace("clean-up: noise components", bad.size());
  std::vector<std::uint32_t> filled_vertices, filled_triangles;
  const auto counts = changed ? c.compact(&filled_vertices, &filled_triangles) : c.compact();
  host_trace("clean-up: compaction", counts.second);
  if (changed) {
    // What the repairs wrote that stays below the new counts, and the
    // places the compaction wrote: each once.
    c.changed_entries(*changed, filled_vertices, filled_triangles, counts.first, counts.second);
    changed->valid = true;
    host_trace("clean-up: changed entries", changed->vertices.size() + changed->triangles.size());
  }
  positions.resize(3 * counts.first);
  if (has_normals) normals.resize(3 * counts.first);
  triangles.resize(3 * counts.second);
  r.removed_vertices = nv - counts.first;
  r.removed_triangles = nt - counts.second;
  return r;
}

}  // namespace mesh
}  // namespace nbmc
