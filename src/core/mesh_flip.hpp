// SPDX-License-Identifier: MIT
// Fairing edge flips, the last step of the mesh clean-up (nbmc_params.cleanup):
// an edge is flipped (its quad's other diagonal taken instead) where that
// lowers the bend of the five edges it changes, the edge and the quad's four
// sides. The bend of an edge is |n0 - n1| = 2 sin(angle / 2) for the unit
// normals of its two triangles (within 5 % of the dihedral angle itself up to
// 60 degrees, without an acos). After N. Dyn, K. Hormann, S.-J. Kim,
// D. Levin, "Optimizing 3D triangulations using discrete curvature analysis"
// (2001), who choose the diagonals of a triangulation of given points by
// edge swaps that lower a discrete curvature functional: marching cubes picks
// each cell's diagonals from the cell's corner signs, not from the surface,
// and where the surface bends across cells (droplets and splashes, the
// rounded beads the distance guard leaves, the fluid's own free surface) the
// diagonal it picks often folds the surface more than the other would. No
// vertex moves, so every vertex-to-particle distance and the normals stay as
// they are; the numbers of vertices, triangles and edges stay the same.
//
// A flip of edge (a, b) with triangles (a, b, c) and (b, a, d) gives
// (a, d, c) and (d, b, c) (the quad's boundary keeps its direction, so the
// orientation is kept). It is made only when
//  - both triangles are consistently oriented neighbours across (a, b) and
//    a, b, c, d are regular vertices (one closed fan of triangles each,
//    through manifold edges), and the edge (c, d) does not exist yet (so a
//    and b keep three or more triangles and the mesh stays manifold);
//  - neither old triangle is bad (an angle below 1 degree: what the clean-up
//    could not repair is left alone), and the smallest angle of the two new
//    triangles is at least kFlipMinAngleDegrees or, when the old pair had a
//    smaller one, at least that: a flip never makes the triangles worse
//    than kFlipMinAngleDegrees, so the clean-up's guarantee (no angle below
//    1 degree) holds;
//  - the two new triangles meet at no more than kFlipMaxDihedralDegrees
//    (no folds);
//  - the bend of the five edges falls by at least kFlipMinGain.
// Open, non-manifold or misoriented parts of a mesh are left alone. At most
// kFlipRounds rounds (below); the result depends only on the mesh, the same
// on every backend and thread count.
#pragma once

#include "mesh_check.hpp"
#include "parallel.hpp"
#include "trace.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__SSE__) || defined(_M_X64)
#include <xmmintrin.h>
#endif

namespace nbmc {
namespace mesh {

constexpr int kFlipRounds = 3;
constexpr double kFlipMinAngleDegrees = 5.0;
// The least gain (fall of the bend of the five edges, about radians) a flip
// must bring: smaller ones change nothing visible and only cost rounds.
constexpr double kFlipMinGain = 1e-3;
constexpr double kFlipMaxDihedralDegrees = 60.0;
// Triangles per chunk of the parallel rounds: large enough that few edges
// read across a chunk's border (those go to the serial pass), small enough
// for many chunks per thread.
constexpr std::size_t kFlipChunkTriangles = 16384;

struct FlipResult {
  std::uint64_t flips = 0;
  int rounds = 0;
};

namespace detail {

constexpr std::uint32_t kNoTriangle = 0xffffffffu;

// Sine of the smallest angle of triangle (p, q, r): twice its area over the
// product of its two longest sides (the smallest angle, opposite the
// shortest side, is at most 60 degrees, where the sine grows with the
// angle); 0 for a zero-length side or a zero area.
inline double sin_smallest_angle(double twice_area, double a, double b, double c) {
  const double lo = std::min(a, std::min(b, c));
  if (!(lo > 0)) return 0;
  return twice_area * lo / (a * b * c);
}
// The same of (p, q, r): sides a = |q - p|, b = |r - q|, c = |p - r|, twice
// the area |(q - p) x (r - p)|.
inline double sin_smallest_angle(const Vec3& p, const Vec3& q, const Vec3& r) {
  return sin_smallest_angle(norm(cross(q - p, r - p)), norm(q - p), norm(r - q), norm(p - r));
}

// Unit normal of (p, q, r); zero for a zero area.
inline Vec3 unit_normal(const Vec3& p, const Vec3& q, const Vec3& r) {
  const Vec3 n = cross(q - p, r - p);
  const double l = norm(n);
  return l > 0 ? (1.0 / l) * n : Vec3{};
}

// Unit normal of (p, q, r) in float (the differences in the positions' own
// precision, the rest in float: a flip's bends compare these); false and
// zero for a zero area.
#if defined(__GNUC__)
#define NBMC_FLIP_INLINE inline __attribute__((always_inline))
#else
#define NBMC_FLIP_INLINE inline
#endif
template <class Real>
NBMC_FLIP_INLINE bool unit_normal_f(const Real* P, std::uint32_t p, std::uint32_t q, std::uint32_t r, float* u) {
  const Real* a = P + 3 * std::size_t(p);
  const Real* b = P + 3 * std::size_t(q);
  const Real* c = P + 3 * std::size_t(r);
  const float e0 = float(b[0] - a[0]), e1 = float(b[1] - a[1]), e2 = float(b[2] - a[2]);
  const float f0 = float(c[0] - a[0]), f1 = float(c[1] - a[1]), f2 = float(c[2] - a[2]);
  const float x = e1 * f2 - e2 * f1, y = e2 * f0 - e0 * f2, z = e0 * f1 - e1 * f0;
  const float l = std::sqrt(x * x + y * y + z * z);
  if (!(l > 0)) {
    u[0] = u[1] = u[2] = 0;
    return false;
  }
  u[0] = x / l, u[1] = y / l, u[2] = z / l;
  return true;
}
// The half-edges after h = 3 t + k in its triangle: 3 t + (k + 1) % 3 and
// 3 t + (k + 2) % 3.
inline std::uint32_t next1(std::uint32_t h) { return h % 3 == 2 ? h - 2 : h + 1; }
inline std::uint32_t next2(std::uint32_t h) { return h % 3 == 0 ? h + 2 : h - 1; }
inline void prefetch(const void* p) {
#if defined(__GNUC__)
  __builtin_prefetch(p);
#else
  (void)p;
#endif
}
inline float dot3(const float* a, const float* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline bool zero3(const float* a) { return a[0] == 0 && a[1] == 0 && a[2] == 0; }
// |a - b|^2.
inline float diff2(const float* a, const float* b) {
  const float x = a[0] - b[0], y = a[1] - b[1], z = a[2] - b[2];
  return x * x + y * y + z * z;
}
// The square roots of four floats into out: one packed square root where
// SSE exists, else one by one (both correctly rounded: the same bits). The
// operands go in through registers: a packed load of four separate scalar
// stores would stall on the store forwarding (about a fifth of the
// evaluation's time when they went through memory).
inline void sqrt4(float a, float b, float c, float d, float* out) {
#if defined(__SSE__) || defined(_M_X64)
  _mm_storeu_ps(out, _mm_sqrt_ps(_mm_setr_ps(a, b, c, d)));
#else
  out[0] = std::sqrt(a), out[1] = std::sqrt(b), out[2] = std::sqrt(c), out[3] = std::sqrt(d);
#endif
}

// A fixed permutation of the 32-bit integers that scatters neighbours
// (xor-shifts and odd multipliers, each invertible): the conflict-free
// passes' priorities. By the half-edge itself (neighbours have close
// numbers), a run of neighbouring edges that all pass would be flipped one
// by one, a pass each (about 30 passes on the 1.65 M frame); scattered, most
// runs are broken at once.
inline std::uint32_t scramble(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

}  // namespace detail

// Flips edges of the triangle mesh (positions: float or double, 3 per
// vertex; triangles: 3 indices each, counter-clockwise) as described above.
// chunk: the triangles per chunk of the parallel rounds (below; a fixed
// size, so that the result does not depend on the thread count; the tests
// pass small ones).
template <class Real, class IndexVec>
FlipResult flip_edges_fairing(const Real* positions, std::size_t nv, IndexVec& triangles,
                              int max_rounds = kFlipRounds, std::size_t chunk = kFlipChunkTriangles) {
  using detail::kNoTriangle;
  FlipResult res;
  const std::size_t nt = triangles.size() / 3;
  if (nt == 0 || nv == 0 || max_rounds <= 0 || 3 * nt >= kNoTriangle) return res;
  if (chunk == 0) chunk = 1;
  std::uint32_t* T = triangles.data();
  // (The twenty to forty parallel steps below wake the persistent host
  // threads of parallel.hpp; none starts threads of its own.)
  {
    // Not a mesh of these vertices: leave it alone. (On the host threads:
    // serial, this alone took a few ms, as much as the rest at 16 threads.)
    std::atomic<bool> foreign{false};
    for_chunks(nt, chunk_count(nt, 65536), [&](std::size_t, std::size_t lo, std::size_t hi) {
      bool out = false;
      for (std::size_t i = 3 * lo; i < 3 * hi; ++i) out |= T[i] >= nv;
      if (out) foreign.store(true, std::memory_order_relaxed);
    });
    if (foreign.load()) return res;
  }
  // The opposite half-edge of every half-edge h = 3 t + k (T[h] ->
  // T[3t+(k+1)%3]): the one half-edge of the reverse direction, where the
  // edge is used by exactly these two, in two different triangles; else
  // kNoTriangle. Found at each vertex among its own triangles: the corners
  // of a vertex are chained (head, next) by one atomic exchange each, in an
  // order that depends on the threads, but what the vertex makes of them
  // (below) does not depend on their order.
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> opp(3 * nt);
  std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>> regular(nv);
  // Per vertex, of the conflict-free passes (below): the highest claim,
  // (pass << 32) | scramble(half-edge), and the last pass that flipped an
  // edge of its (pass counts on through the rounds: neither is ever
  // cleared). Set here with the corner lists' heads.
  std::unique_ptr<std::atomic<std::uint64_t>[]> claim(new std::atomic<std::uint64_t>[nv]);
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> moved(nv);
  {
    std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> next(3 * nt);  // (freed after this block)
    std::unique_ptr<std::atomic<std::uint32_t>[]> head(new std::atomic<std::uint32_t>[nv]);
    for_chunks(nv, chunk_count(nv, 65536), [&](std::size_t, std::size_t lo, std::size_t hi) {
      for (std::size_t v = lo; v < hi; ++v) {
        head[v].store(kNoTriangle, std::memory_order_relaxed);
        claim[v].store(0, std::memory_order_relaxed);
        moved[v] = 0;
      }
    });
    for_chunks(nt, chunk_count(nt, 65536), [&](std::size_t, std::size_t lo, std::size_t hi) {
      for (std::size_t i = 3 * lo; i < 3 * hi; ++i)
        next[i] = head[T[i]].exchange(std::uint32_t(i), std::memory_order_relaxed);
    });
    host_trace("clean-up: fairing corner lists", nt);
    // Per vertex v, for each of its corners i (triangle i / 3): the
    // half-edge out of v (i: v -> o) and the one into v (3t+(k+2)%3: n ->
    // v). The out-edge v -> o gets as opposite the in-edge o -> v when each
    // is the only one of its direction; v is regular when its triangles
    // form one closed fan through such edges: from each triangle, across its
    // in-edge n -> v, to the triangle of the out-edge v -> n, one cycle
    // through all of them.
    for_chunks(nv, chunk_count(nv, 16384), [&](std::size_t, std::size_t lo, std::size_t hi) {
      std::vector<std::uint32_t> cv, ov, nv_, rv;  // (vertices of more than 32 triangles)
      std::uint32_t ca[32], oa[32], na[32], ra[32];
      for (std::size_t v = lo; v < hi; ++v) {
        // (One walk of the chain: into the arrays above, or, from the
        // 33rd corner on, into the vectors.)
        std::uint32_t *c = ca, *o = oa, *n = na, *r = ra;
        std::uint32_t m = 0;
        for (std::uint32_t i = head[v].load(std::memory_order_relaxed); i != kNoTriangle; i = next[i]) {
          if (m == 32 && c == ca) {
            cv.assign(ca, ca + 32), ov.assign(oa, oa + 32), nv_.assign(na, na + 32);
          }
          if (m >= 32) {
            cv.resize(m + 1), ov.resize(m + 1), nv_.resize(m + 1);
            c = cv.data(), o = ov.data(), n = nv_.data();
          }
          c[m] = i;
          o[m] = T[detail::next1(i)];
          n[m] = T[detail::next2(i)];
          ++m;
        }
        if (m > 32) {
          rv.resize(m);
          r = rv.data();
        }
        // Out-edge j (v -> o[j]): its opposite o[j] -> v is the in-edge of
        // corner r[j].
        bool fan = m >= 3;
        for (std::uint32_t j = 0; j < m; ++j) {
          std::uint32_t same = 0, rev = 0, at = 0;
          for (std::uint32_t q = 0; q < m; ++q) {
            same += o[q] == o[j];
            const bool x = n[q] == o[j];
            rev += x;
            at = x ? q : at;
          }
          const bool ok = o[j] != v && same == 1 && rev == 1 && c[at] / 3 != c[j] / 3;
          opp[c[j]] = ok ? detail::next2(c[at]) : kNoTriangle;
          fan = fan && ok;
          r[j] = at;
        }
        // Every out-edge so matched: j -> r[j] is a permutation (the o[j]
        // differ, so do the r[j]); v is regular when it is one cycle.
        if (fan) {
          std::uint32_t steps = 0, j = 0;
          do j = r[j], ++steps;
          while (j != 0 && steps < m);
          fan = j == 0 && steps == m;
        }
        regular[v] = fan;
      }
    });
  }
  host_trace("clean-up: fairing neighbours", nt);
  auto pos = [&](std::uint32_t v) { return load(positions, v); };
  // Unit normals of the triangles, kept up to date through the flips, in
  // float: every bend below is taken from these in float arithmetic, the
  // same on every run (no contraction into FMA: src/CMakeLists.txt).
  std::vector<float, NoInitAllocator<float>> tn(3 * nt);
  for_chunks(nt, chunk_count(nt, 65536), [&](std::size_t, std::size_t lo, std::size_t hi) {
    for (std::size_t t = lo; t < hi; ++t) detail::unit_normal_f(positions, T[3 * t], T[3 * t + 1], T[3 * t + 2], &tn[3 * t]);
  });
  host_trace("clean-up: fairing normals", nt);
  const double sin_min_angle = std::sin(kFlipMinAngleDegrees * 3.14159265358979323846 / 180.0);
  const float cos_max_dihedral = float(std::cos(kFlipMaxDihedralDegrees * 3.14159265358979323846 / 180.0));
  const float min_gain = float(kFlipMinGain);

  // The rounds' bookkeeping (below): per half-edge the level it was last
  // evaluated at (0: not this round), per triangle the time of the last
  // flip that rewrote it and the latest such time over it and its three
  // neighbours. (All set by the rounds' chunks, each its own, in parallel.)
  std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>> seen(3 * nt);
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> last(nt);
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> near(nt);
  constexpr int kMaxLevel = 255;  // (seen's range)
  const std::uint64_t span = 6 * std::uint64_t(nt) + 4;
  const bool timed = 2 * span + 2 * kMaxLevel < std::uint64_t(kNoTriangle);  // (else: every change counts)
  auto time_of = [&](int level, std::uint32_t h) {
    return level <= 2 ? std::uint32_t((level - 1) * span) + 2 * (h + 1)
                      : std::uint32_t(2 * span) + 2 * std::uint32_t(level - 3);
  };
  // A flip found by evaluate: what apply needs.
  struct Candidate {
    float u0[3], u1[3];
    std::uint32_t t0, t1, a, b, c, d, o_bc, o_ca, o_ad, o_db;  // o_*: the outer half-edges' opposites
  };
  enum Outcome { Reject, Pass, Outside };
  // Evaluates the edge of half-edge h = 3 t0 + k on the current mesh (reads
  // only). Every triangle it reads lies in [lo, hi) (a chunk's), or it
  // returns Outside before reading it: so that chunks are evaluated and
  // flipped at once, each alone with its own triangles. whole: true when
  // [lo, hi) is the whole mesh (a type: one copy of this for the chunks,
  // inlined there, one for the conflict-free passes).
  using detail::next1;
  using detail::next2;
  auto evaluate = [&](std::uint32_t h, std::uint32_t lo, std::uint32_t hi, Candidate& f, auto whole) -> Outcome {
    auto inside = [&](std::uint32_t t) { return whole || (t >= lo && t < hi); };
    const std::uint32_t t0 = h / 3;
    const std::uint32_t g = opp[h];
    if (g == kNoTriangle) return Reject;
    const std::uint32_t t1 = g / 3;
    if (t1 < t0) return Reject;  // the edge is its lower triangle's
    if (!inside(t1)) return Outside;
    const std::uint32_t h1 = next1(h), h2 = next2(h), g1 = next1(g), g2 = next2(g);
    const std::uint32_t a = T[h], b = T[h1], c = T[h2], d = T[g2];
    if (c == d) return Reject;
    const std::uint32_t o_bc = opp[h1], o_ca = opp[h2], o_ad = opp[g1], o_db = opp[g2];
    if (o_bc == kNoTriangle || o_ca == kNoTriangle || o_ad == kNoTriangle || o_db == kNoTriangle) return Reject;
    if (!inside(o_bc / 3) || !inside(o_ca / 3) || !inside(o_ad / 3) || !inside(o_db / 3)) return Outside;
    // The bend test first, in float on the stored normals (most edges end
    // here): the five edges' bends before and after.
    const float* m0 = &tn[3 * std::size_t(t0)];
    const float* m1 = &tn[3 * std::size_t(t1)];
    const float* s_bc = &tn[3 * std::size_t(o_bc / 3)];
    const float* s_ca = &tn[3 * std::size_t(o_ca / 3)];
    const float* s_ad = &tn[3 * std::size_t(o_ad / 3)];
    const float* s_db = &tn[3 * std::size_t(o_db / 3)];
    if (!detail::unit_normal_f(positions, a, d, c, f.u0) || !detail::unit_normal_f(positions, d, b, c, f.u1))
      return Reject;
    if (detail::dot3(f.u0, f.u1) < cos_max_dihedral) return Reject;
    float sq[12];
    using detail::diff2;
    detail::sqrt4(diff2(m0, m1), diff2(m0, s_bc), diff2(m0, s_ca), diff2(m1, s_ad), sq);
    detail::sqrt4(diff2(m1, s_db), diff2(f.u0, f.u1), diff2(f.u1, s_bc), diff2(f.u0, s_ca), sq + 4);
    detail::sqrt4(diff2(f.u0, s_ad), diff2(f.u1, s_db), 0.0f, 0.0f, sq + 8);
    const float before = sq[0] + sq[1] + sq[2] + sq[3] + sq[4];
    const float after = sq[5] + sq[6] + sq[7] + sq[8] + sq[9];
    if (!(after < before - min_gain)) return Reject;
    // (A zero normal: a degenerate triangle, old or new, never flipped.)
    if (detail::zero3(m0) || detail::zero3(m1) || detail::zero3(s_bc) || detail::zero3(s_ca) || detail::zero3(s_ad) ||
        detail::zero3(s_db))
      return Reject;
    if (!regular[a] || !regular[b] || !regular[c] || !regular[d]) return Reject;
    const Vec3 pa = pos(a), pb = pos(b), pc = pos(c), pd = pos(d);
    // (sin_smallest_angle of the four triangles, each side's length taken
    // once: the same values.)
    const double ab = norm(pb - pa), bc = norm(pc - pb), ca = norm(pa - pc), ad = norm(pd - pa), db = norm(pb - pd);
    const double old_min = std::min(detail::sin_smallest_angle(norm(cross(pb - pa, pc - pa)), ab, bc, ca),
                                    detail::sin_smallest_angle(norm(cross(pa - pb, pd - pb)), ab, ad, db));
    if (!(old_min >= kSinOneDegree)) return Reject;  // a bad triangle: the clean-up's, left alone
    const double cd = norm(pc - pd);
    const double new_min = std::min(detail::sin_smallest_angle(norm(cross(pd - pa, pc - pa)), ad, cd, ca),
                                    detail::sin_smallest_angle(norm(cross(pb - pd, pc - pd)), db, bc, cd));
    if (!(new_min >= std::min(sin_min_angle, old_min))) return Reject;
    // The edge (c, d) must not exist: walk c's fan (regular: closed), from
    // t0 across its in-edge of c, (b -> c), to the triangle of c -> b, ...
    std::uint32_t cur = t0, steps = 0;
    do {
      const std::uint32_t* x = T + 3 * std::size_t(cur);
      if (x[0] == d || x[1] == d || x[2] == d) return Reject;
      const std::uint32_t in = x[0] == c ? 2 : x[1] == c ? 0 : 1;  // the slot of c's in-edge
      cur = opp[3 * cur + in] / 3;  // (regular: never kNoTriangle)
      if (!inside(cur)) return Outside;
      if (++steps > nt) return Reject;
    } while (cur != t0);
    f.t0 = t0, f.t1 = t1, f.a = a, f.b = b, f.c = c, f.d = d;
    f.o_bc = o_bc, f.o_ca = o_ca, f.o_ad = o_ad, f.o_db = o_db;
    return Pass;
  };
  // t0 = (a, d, c), t1 = (d, b, c): half-edges 3t0: a->d (opposite o_ad),
  // 3t0+1: d->c (3t1+2), 3t0+2: c->a (o_ca); 3t1: d->b (o_db), 3t1+1: b->c
  // (o_bc), 3t1+2: c->d (3t0+1). The quad's boundary keeps its direction.
  // Writes t0, t1 and the four outer triangles (their opposites).
  auto apply = [&](const Candidate& f) {
    std::uint32_t* A = T + 3 * std::size_t(f.t0);
    std::uint32_t* B = T + 3 * std::size_t(f.t1);
    A[0] = f.a, A[1] = f.d, A[2] = f.c;
    B[0] = f.d, B[1] = f.b, B[2] = f.c;
    const std::uint32_t h0 = 3 * f.t0, h1 = 3 * f.t1;
    opp[h0] = f.o_ad, opp[h0 + 1] = h1 + 2, opp[h0 + 2] = f.o_ca;
    opp[h1] = f.o_db, opp[h1 + 1] = f.o_bc, opp[h1 + 2] = h0 + 1;
    opp[f.o_ad] = h0, opp[f.o_ca] = h0 + 2, opp[f.o_db] = h1, opp[f.o_bc] = h1 + 1;
    for (int i = 0; i < 3; ++i) tn[std::size_t(h0) + i] = f.u0[i], tn[std::size_t(h1) + i] = f.u1[i];
  };

  // Rounds. The triangles are cut into chunks of `chunk` (a fixed size:
  // the same chunks on every thread count); the chunks are taken by the host
  // threads, each walks the round's edges of its triangles (the edge's
  // lower triangle there) in order and flips each that passes, at once,
  // greedily: what it reads and writes lies in its chunk (evaluate), so the
  // chunks do not meet and each comes out as one thread alone would make
  // it. Each chunk picks its own edges of the round as it walks them (no
  // list; below). The edges that read outside their chunk (about 6 % in the
  // first round) go, in order, through chunks 16 times as large in the same
  // way (level 2), and what is left of them (about 2 %: neighbours far away
  // in the triangles' order) through conflict-free passes (levels 3, 4, ...;
  // before, a serial greedy pass, which dominated at many threads): all of
  // them are evaluated on the same mesh (read only, in parallel), each that
  // passes claims the quad's four corners with its priority (a fixed
  // scramble of its half-edge: atomic maxima, so the claims do not depend on
  // the threads), and those that hold all four are flipped at once, in
  // parallel. That is safe: an edge's test reads its two triangles, the four
  // beyond (their normals) and the fan of c, all at one of its corners (and
  // the opposites of half-edges out of or into a corner), and a flip writes
  // only triangles and half-edges whose corners are all its own; so flips of
  // disjoint corners read nothing another writes and do not meet. The
  // others are looked at again in the next pass, evaluated again only when
  // a flip of that pass took one of their corners. The highest priority
  // that passes always holds its claims, so every pass flips.
  //
  // The next round's edges: those whose quad (their two triangles and the
  // four beyond) holds a triangle that a flip rewrote after the edge was
  // evaluated (a flip rewrites its two triangles: their corners and
  // normals; of the four beyond only which of the two faces them, seen from
  // the quad's side): an edge evaluated after the change saw it, and would
  // only be rejected again. The times: level 1 and 2 evaluate half-edge h
  // at base(l) + 2 (h + 1), a pass at level l >= 3 all its edges at one
  // time, after those; a flip stamps its two triangles with its
  // evaluation's time + 1 (so the slot h itself, rewritten by the flip,
  // counts as changed). The rounds but the first take an edge when the
  // latest stamp over its quad (near, computed before) is later than its
  // evaluation in the round before.
  const std::size_t chunks = (nt + chunk - 1) / chunk;
  std::uint64_t pass = 0;  // the conflict-free passes so far, all rounds: claim's and moved's clock
  struct Found {
    Candidate f;
    std::uint32_t h;
    bool valid;  // f is h's flip on the current mesh
  };
  for (int round = 0; round < max_rounds; ++round) {
    const std::uint64_t flips0 = res.flips;
    if (round > 0) {
      for_chunks(nt, chunk_count(nt, 65536), [&](std::size_t, std::size_t lo, std::size_t hi) {
        for (std::size_t t = lo; t < hi; ++t) {
          std::uint32_t x = last[t];
          for (std::size_t h = 3 * t; h < 3 * t + 3; ++h)
            if (opp[h] != kNoTriangle) x = std::max(x, last[opp[h] / 3]);
          near[t] = x;
        }
      });
      host_trace("clean-up: fairing near stamps", nt);
    }
    std::vector<std::vector<std::uint32_t>> out(chunks);
    std::vector<std::uint64_t> flipped(chunks, 0);
    std::atomic<std::size_t> next_chunk{0};
    on_threads(chunk_count(chunks, 1), [&](std::size_t) {
      Candidate f;
      for (std::size_t q; (q = next_chunk.fetch_add(1, std::memory_order_relaxed)) < chunks;) {
        const std::uint32_t lo = std::uint32_t(q * chunk), hi = std::uint32_t(std::min(nt, (q + 1) * chunk));
        // (The stamps of the round before are all in near: cleared here,
        // by the chunk that alone writes them in this level.)
        std::fill(last.begin() + lo, last.begin() + hi, 0u);
        // (Counted and listed here, stored once: neighbouring chunks run at
        // once, and their slots of flipped and out share cache lines.)
        std::uint64_t made = 0;
        std::vector<std::uint32_t> leave;
        for (std::uint32_t h = 3 * lo; h < 3 * hi; ++h) {
          // (The opposite a few half-edges ahead, and its triangle's: the
          // evaluation's chain of loads starts there.)
          if (h + 24 < 3 * hi) {
            const std::uint32_t g = opp[h + 24];
            if (g != kNoTriangle) {
              detail::prefetch(&opp[g]);
              detail::prefetch(&T[g]);
              detail::prefetch(&tn[g]);
            }
          }
          const std::uint32_t g = opp[h];
          bool take = g != kNoTriangle && g / 3 > h / 3;
          if (take && round > 0) {
            const std::uint32_t at = seen[h] ? time_of(seen[h], h) : 0;
            take = std::max(near[h / 3], near[g / 3]) > at;
          }
          seen[h] = 0;
          if (!take) continue;
          const Outcome o = evaluate(h, lo, hi, f, std::false_type());
          if (o == Outside) {
            leave.push_back(h);
            continue;
          }
          if (timed) seen[h] = 1;
          if (o != Pass) continue;
          apply(f);
          ++made;
          last[f.t0] = last[f.t1] = timed ? time_of(1, h) + 1 : 1;
        }
        flipped[q] = made;
        out[q] = std::move(leave);
      }
    });
    std::vector<std::uint32_t> pending;
    for (std::size_t q = 0; q < chunks; ++q) {
      res.flips += flipped[q];
      pending.insert(pending.end(), out[q].begin(), out[q].end());
    }
    host_trace("clean-up: fairing chunks", pending.size());
    // Level 2: the same in chunks 16 times as large, from the list.
    if (!pending.empty()) {
      const std::size_t size = 16 * chunk, large = (nt + size - 1) / size;
      std::vector<std::size_t> from(large + 1);
      for (std::size_t q = 0; q <= large; ++q)
        from[q] = std::size_t(
            std::lower_bound(pending.begin(), pending.end(), std::uint32_t(3 * std::min(nt, q * size))) -
            pending.begin());
      std::vector<std::vector<std::uint32_t>> rest(large);
      std::vector<std::uint64_t> made(large, 0);
      next_chunk = 0;
      on_threads(chunk_count(large, 1), [&](std::size_t) {
        Candidate f;
        for (std::size_t q; (q = next_chunk.fetch_add(1, std::memory_order_relaxed)) < large;) {
          const std::uint32_t lo = std::uint32_t(q * size), hi = std::uint32_t(std::min(nt, (q + 1) * size));
          std::uint64_t n = 0;
          std::vector<std::uint32_t> leave;
          for (std::size_t i = from[q]; i < from[q + 1]; ++i) {
            const std::uint32_t h = pending[i];
            const Outcome o = evaluate(h, lo, hi, f, std::false_type());
            if (o == Outside) {
              leave.push_back(h);
              continue;
            }
            if (timed) seen[h] = 2;
            if (o != Pass) continue;
            apply(f);
            ++n;
            last[f.t0] = last[f.t1] = timed ? time_of(2, h) + 1 : 1;
          }
          made[q] = n;
          rest[q] = std::move(leave);
        }
      });
      pending.clear();
      for (std::size_t q = 0; q < large; ++q) {
        res.flips += made[q];
        pending.insert(pending.end(), rest[q].begin(), rest[q].end());
      }
      host_trace("clean-up: fairing large chunks", pending.size());
    }
    // The conflict-free passes. (A pathological mesh that needs more than
    // kMaxLevel - 2 of them keeps the rest of its edges for the round.)
    std::vector<Found> items(pending.size());
    for (std::size_t i = 0; i < pending.size(); ++i) items[i].h = pending[i], items[i].valid = false;
    for (int level = 3; !items.empty() && level <= kMaxLevel; ++level) {
      const std::uint64_t key_hi = ++pass << 32;
      const std::size_t parts = chunk_count(items.size(), 1024);
      std::vector<std::vector<Found>> again(parts);
      std::vector<std::uint64_t> made(parts, 0);
      auto take = [&](std::uint32_t v, std::uint64_t key) {
        std::uint64_t c = claim[v].load(std::memory_order_relaxed);
        while (c < key && !claim[v].compare_exchange_weak(c, key, std::memory_order_relaxed)) {
        }
      };
      for_chunks(items.size(), parts, [&](std::size_t, std::size_t lo, std::size_t hi) {
        for (std::size_t i = lo; i < hi; ++i) {
          Found& x = items[i];
          const Candidate& f = x.f;
          // (Kept from the pass before when no flip there touched its
          // quad's corners: what it read is unchanged.)
          if (x.valid && (moved[f.a] == pass - 1 || moved[f.b] == pass - 1 || moved[f.c] == pass - 1 ||
                          moved[f.d] == pass - 1))
            x.valid = false;
          if (!x.valid) x.valid = evaluate(x.h, 0, std::uint32_t(nt), x.f, std::true_type()) == Pass;
          if (timed) seen[x.h] = std::uint8_t(level);
          if (!x.valid) continue;
          const std::uint64_t key = key_hi | detail::scramble(x.h);
          take(f.a, key), take(f.b, key), take(f.c, key), take(f.d, key);
        }
      });
      for_chunks(items.size(), parts, [&](std::size_t q, std::size_t lo, std::size_t hi) {
        std::uint64_t n = 0;
        std::vector<Found> lost;
        for (std::size_t i = lo; i < hi; ++i) {
          const Found& x = items[i];
          if (!x.valid) continue;
          const Candidate& f = x.f;
          const std::uint64_t key = key_hi | detail::scramble(x.h);
          auto held = [&](std::uint32_t v) { return claim[v].load(std::memory_order_relaxed) == key; };
          if (!(held(f.a) && held(f.b) && held(f.c) && held(f.d))) {
            lost.push_back(x);
            continue;
          }
          apply(f);
          ++n;
          last[f.t0] = last[f.t1] = timed ? time_of(level, x.h) + 1 : 1;
          moved[f.a] = moved[f.b] = moved[f.c] = moved[f.d] = std::uint32_t(pass);
        }
        made[q] = n;
        again[q] = std::move(lost);
      });
      items.clear();
      for (std::size_t q = 0; q < parts; ++q) {
        res.flips += made[q];
        items.insert(items.end(), again[q].begin(), again[q].end());
      }
    }
    host_trace("clean-up: fairing conflict-free passes", res.flips - flips0);
    res.rounds = round + 1;
    if (res.flips == flips0) break;
  }
  return res;
}

}  // namespace mesh
}  // namespace nbmc
