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
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace nbmc {
namespace mesh {

constexpr int kFlipRounds = 3;
constexpr double kFlipMinAngleDegrees = 5.0;
// The least gain (fall of the bend of the five edges, about radians) a flip
// must bring: smaller ones change nothing visible and only cost rounds.
constexpr double kFlipMinGain = 1e-3;
constexpr double kFlipMaxDihedralDegrees = 60.0;

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
inline double sin_smallest_angle(const Vec3& p, const Vec3& q, const Vec3& r) {
  const double a = norm(q - p), b = norm(r - q), c = norm(p - r);
  const double lo = std::min(a, std::min(b, c));
  if (!(lo > 0)) return 0;
  const double twice_area = norm(cross(q - p, r - p));
  return twice_area * lo / (a * b * c);
}

// Unit normal of (p, q, r); zero for a zero area.
inline Vec3 unit_normal(const Vec3& p, const Vec3& q, const Vec3& r) {
  const Vec3 n = cross(q - p, r - p);
  const double l = norm(n);
  return l > 0 ? (1.0 / l) * n : Vec3{};
}

}  // namespace detail

// Flips edges of the triangle mesh (positions: float or double, 3 per
// vertex; triangles: 3 indices each, counter-clockwise) as described above.
template <class Real, class IndexVec>
FlipResult flip_edges_fairing(const Real* positions, std::size_t nv, IndexVec& triangles,
                              int max_rounds = kFlipRounds) {
  using detail::kNoTriangle;
  FlipResult res;
  const std::size_t nt = triangles.size() / 3;
  if (nt == 0 || nv == 0 || max_rounds <= 0) return res;
  std::uint32_t* T = triangles.data();
  // Neighbour across edge k (T[3t+k] -> T[3t+(k+1)%3]) of every triangle:
  // the one triangle with the opposite half-edge, where the edge is used by
  // exactly these two triangles in opposite directions; else kNoTriangle.
  for (std::size_t i = 0; i < 3 * nt; ++i)
    if (T[i] >= nv) return res;  // not a mesh of these vertices: leave it alone
  std::vector<std::uint32_t> nb(3 * nt, kNoTriangle);
  // count[v]: the half-edges that start at v (the triangles that hold v).
  std::vector<std::uint32_t> count(nv, 0), some(nv, kNoTriangle);
  {
    // The half-edges grouped by their first vertex (CSR, in index order),
    // each with its second vertex.
    std::vector<std::uint32_t> start(nv + 1, 0);
    std::vector<std::pair<std::uint32_t, std::uint32_t>> list(3 * nt);  // (head, half-edge)
    for (std::size_t i = 0; i < 3 * nt; ++i) ++start[T[i] + 1];
    for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
    {
      std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
      for (std::size_t t = 0; t < nt; ++t)
        for (int k = 0; k < 3; ++k)
          list[fill[T[3 * t + k]]++] = {T[3 * t + (k + 1) % 3], std::uint32_t(3 * t + k)};
    }
    for (std::size_t v = 0; v < nv; ++v) {
      count[v] = start[v + 1] - start[v];
      if (count[v]) some[v] = list[start[v]].second / 3;
    }
    // (Each vertex writes only the neighbours of its own half-edges: on the
    // host threads.)
    for_chunks(nv, chunk_count(nv, 4096), [&](std::size_t, std::size_t lo, std::size_t hi) {
      for (std::size_t a = lo; a < hi; ++a)
        for (std::uint32_t i = start[a]; i < start[a + 1]; ++i) {
          const std::uint32_t b = list[i].first, h = list[i].second;
          if (b == a) continue;
          std::uint32_t same = 0, opposite = 0, other = 0;
          for (std::uint32_t j = start[a]; j < start[a + 1]; ++j) same += list[j].first == b;
          for (std::uint32_t j = start[b]; j < start[b + 1]; ++j)
            if (list[j].first == a) ++opposite, other = list[j].second;
          if (same == 1 && opposite == 1 && other / 3 != h / 3) nb[h] = other / 3;
        }
    });
  }
  host_trace("clean-up: fairing neighbours", nt);
  // Regular vertices: the fan walked around v through the neighbours closes
  // after exactly as many triangles as hold v.
  auto slot = [&](std::uint32_t t, std::uint32_t v) -> int {
    for (int k = 0; k < 3; ++k)
      if (T[3 * t + k] == v) return k;
    return -1;
  };
  // Walks the fan of v from triangle t (which holds v); calls f(triangle)
  // for each; returns the number of triangles, or 0 when the walk meets an
  // edge without a neighbour or does not close within limit steps.
  auto walk = [&](std::uint32_t v, std::uint32_t t, std::uint32_t limit, auto&& f) -> std::uint32_t {
    std::uint32_t cur = t, n = 0;
    do {
      const int k = slot(cur, v);
      if (k < 0) return 0;
      f(cur);
      ++n;
      cur = nb[3 * std::size_t(cur) + std::size_t((k + 2) % 3)];  // across (prev, v)
      if (cur == kNoTriangle || n > limit) return 0;
    } while (cur != t);
    return n;
  };
  std::vector<std::uint8_t> regular(nv, 0);
  for_chunks(nv, chunk_count(nv, 4096), [&](std::size_t, std::size_t lo, std::size_t hi) {
    for (std::size_t v = lo; v < hi; ++v)
      if (some[v] != kNoTriangle && count[v] >= 3)
        regular[v] = walk(std::uint32_t(v), some[v], count[v], [](std::uint32_t) {}) == count[v];
  });

  host_trace("clean-up: fairing regular vertices", nv);
  auto pos = [&](std::uint32_t v) { return load(positions, v); };
  // Unit normals of the triangles, kept up to date through the flips.
  // (In float: half the memory traffic of the evaluations; a flip compares
  // bends of these rounded normals, the same on every run.)
  std::vector<float> tnf(3 * nt);
  auto set_normal = [&](std::size_t t, const Vec3& n) {
    tnf[3 * t] = float(n.x), tnf[3 * t + 1] = float(n.y), tnf[3 * t + 2] = float(n.z);
  };
  auto normal_of = [&](std::size_t t) { return Vec3{tnf[3 * t], tnf[3 * t + 1], tnf[3 * t + 2]}; };
  for (std::size_t t = 0; t < nt; ++t)
    set_normal(t, detail::unit_normal(pos(T[3 * t]), pos(T[3 * t + 1]), pos(T[3 * t + 2])));
  // Index of edge (x -> y) in triangle t, or -1.
  auto edge_slot = [&](std::uint32_t t, std::uint32_t x, std::uint32_t y) -> int {
    for (int k = 0; k < 3; ++k)
      if (T[3 * std::size_t(t) + k] == x && T[3 * std::size_t(t) + (k + 1) % 3] == y) return k;
    return -1;
  };
  const double sin_min_angle = std::sin(kFlipMinAngleDegrees * 3.14159265358979323846 / 180.0);
  const double cos_max_dihedral = std::cos(kFlipMaxDihedralDegrees * 3.14159265358979323846 / 180.0);
  // The bend of an edge: |n0 - n1| = 2 sin(angle / 2), within 5 % of the
  // angle itself up to 60 degrees, without an acos.
  auto bend = [](const Vec3& n0, const Vec3& n1) { return norm(n0 - n1); };
  auto zero = [](const Vec3& n) { return n.x == 0 && n.y == 0 && n.z == 0; };

  // A candidate flip: edge k of triangle t0 (the lower of its two), with
  // what applying it needs.
  struct Candidate {
    double gain = 0;
    Vec3 u0, u1;
    std::uint32_t t0 = 0, t1 = 0, a = 0, b = 0, c = 0, d = 0, n_bc = 0, n_ca = 0, n_ad = 0, n_db = 0;
  };
  // Evaluates edge k of t0 on the current mesh (reads only); true when its
  // flip is allowed and lowers the bend.
  auto evaluate = [&](std::uint32_t t0, int k, Candidate& f) -> bool {
    const std::uint32_t t1 = nb[3 * std::size_t(t0) + k];
    if (t1 == kNoTriangle) return false;
    const std::uint32_t a = T[3 * std::size_t(t0) + k], b = T[3 * std::size_t(t0) + (k + 1) % 3],
                        c = T[3 * std::size_t(t0) + (k + 2) % 3];
    const int k1 = edge_slot(t1, b, a);
    if (k1 < 0) return false;
    const std::uint32_t d = T[3 * std::size_t(t1) + (k1 + 2) % 3];
    if (c == d || !regular[a] || !regular[b] || !regular[c] || !regular[d]) return false;
    const Vec3 m0 = normal_of(t0), m1 = normal_of(t1);
    const std::uint32_t n_bc = nb[3 * std::size_t(t0) + (k + 1) % 3], n_ca = nb[3 * std::size_t(t0) + (k + 2) % 3];
    const std::uint32_t n_ad = nb[3 * std::size_t(t1) + (k1 + 1) % 3], n_db = nb[3 * std::size_t(t1) + (k1 + 2) % 3];
    if (n_bc == kNoTriangle || n_ca == kNoTriangle || n_ad == kNoTriangle || n_db == kNoTriangle) return false;
    const Vec3 s_bc = normal_of(n_bc), s_ca = normal_of(n_ca), s_ad = normal_of(n_ad), s_db = normal_of(n_db);
    if (zero(m0) || zero(m1) || zero(s_bc) || zero(s_ca) || zero(s_ad) || zero(s_db)) return false;
    const Vec3 pa = pos(a), pb = pos(b), pc = pos(c), pd = pos(d);
    // The new triangles' normals, rounded as they will be kept.
    Vec3 u0 = detail::unit_normal(pa, pd, pc), u1 = detail::unit_normal(pd, pb, pc);
    u0 = Vec3{float(u0.x), float(u0.y), float(u0.z)};
    u1 = Vec3{float(u1.x), float(u1.y), float(u1.z)};
    if (zero(u0) || zero(u1) || dot(u0, u1) < cos_max_dihedral) return false;
    const double before = bend(m0, m1) + bend(m0, s_bc) + bend(m0, s_ca) + bend(m1, s_ad) + bend(m1, s_db);
    const double after = bend(u0, u1) + bend(u1, s_bc) + bend(u0, s_ca) + bend(u0, s_ad) + bend(u1, s_db);
    if (!(after < before - kFlipMinGain)) return false;
    const double old_min = std::min(detail::sin_smallest_angle(pa, pb, pc), detail::sin_smallest_angle(pb, pa, pd));
    if (!(old_min >= kSinOneDegree)) return false;  // a bad triangle: the clean-up's, left alone
    const double new_min = std::min(detail::sin_smallest_angle(pa, pd, pc), detail::sin_smallest_angle(pd, pb, pc));
    if (!(new_min >= std::min(sin_min_angle, old_min))) return false;
    // The edge (c, d) must not exist: walk c's fan.
    bool exists = false;
    const std::uint32_t nc = walk(c, t0, std::uint32_t(nt), [&](std::uint32_t t) {
      if (slot(t, d) >= 0) exists = true;
    });
    if (exists || nc == 0) return false;
    f.gain = before - after;
    f.u0 = u0, f.u1 = u1;
    f.t0 = t0, f.t1 = t1, f.a = a, f.b = b, f.c = c, f.d = d;
    f.n_bc = n_bc, f.n_ca = n_ca, f.n_ad = n_ad, f.n_db = n_db;
    return true;
  };
  auto apply = [&](const Candidate& f) {
    // t0 = (a, d, c), t1 = (d, b, c): edges t0: a->d (n_ad), d->c (t1), c->a (n_ca);
    // t1: d->b (n_db), b->c (n_bc), c->d (t0).
    std::uint32_t* A = T + 3 * std::size_t(f.t0);
    std::uint32_t* B = T + 3 * std::size_t(f.t1);
    A[0] = f.a, A[1] = f.d, A[2] = f.c;
    B[0] = f.d, B[1] = f.b, B[2] = f.c;
    std::uint32_t* NA = nb.data() + 3 * std::size_t(f.t0);
    std::uint32_t* NB = nb.data() + 3 * std::size_t(f.t1);
    NA[0] = f.n_ad, NA[1] = f.t1, NA[2] = f.n_ca;
    NB[0] = f.n_db, NB[1] = f.n_bc, NB[2] = f.t0;
    // The outer neighbours: n_ad's edge (d -> a) now faces t0, n_bc's (c -> b) t1.
    const int ka = edge_slot(f.n_ad, f.d, f.a), kb = edge_slot(f.n_bc, f.c, f.b);
    if (ka >= 0) nb[3 * std::size_t(f.n_ad) + ka] = f.t0;
    if (kb >= 0) nb[3 * std::size_t(f.n_bc) + kb] = f.t1;
    set_normal(f.t0, f.u0);
    set_normal(f.t1, f.u1);
  };
  // The canonical id of the edge k of t: 3 t' + k' of its lower triangle t'.
  auto edge_id = [&](std::uint32_t t, int k) -> std::uint32_t {
    const std::uint32_t o = nb[3 * std::size_t(t) + k];
    if (o == kNoTriangle) return kNoTriangle;
    if (o > t) return 3 * t + std::uint32_t(k);
    const int ko = edge_slot(o, T[3 * std::size_t(t) + (k + 1) % 3], T[3 * std::size_t(t) + k]);
    return ko < 0 ? kNoTriangle : 3 * o + std::uint32_t(ko);
  };

  // Rounds. First every edge of the work list is evaluated on the mesh as
  // it is, on the host threads (each evaluation only reads: which edges
  // pass depends only on the mesh); then, serially in the list's order,
  // each edge that passed is evaluated again (an earlier flip of the round
  // may have changed its quad or its neighbours) and flipped if it still
  // passes: one pass of greedy flips over the edges that can gain. The next
  // round's work list: the edges of the triangles the flips changed or
  // bordered.
  std::vector<std::uint32_t> work;
  work.reserve(3 * nt / 2);
  for (std::uint32_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t o = nb[3 * std::size_t(t) + k];
      if (o != kNoTriangle && o > t) work.push_back(3 * t + std::uint32_t(k));
    }
  std::vector<std::uint8_t> ok, mark(nt, 0);
  for (int round = 0; round < max_rounds && !work.empty(); ++round) {
    ok.assign(work.size(), 0);
    for_chunks(work.size(), chunk_count(work.size(), 4096), [&](std::size_t, std::size_t lo, std::size_t hi) {
      Candidate f;
      for (std::size_t i = lo; i < hi; ++i) ok[i] = evaluate(work[i] / 3, int(work[i] % 3), f);
    });
    host_trace("clean-up: fairing evaluation", work.size());
    std::uint64_t flips = 0;
    Candidate f;
    for (std::size_t i = 0; i < work.size(); ++i) {
      if (!ok[i]) continue;
      const std::uint32_t t0 = work[i] / 3;
      const int k = int(work[i] % 3);
      // The edge may have moved (an earlier flip rewrote t0): only an edge
      // that is still the lower triangle's edge k is looked at.
      const std::uint32_t o = nb[3 * std::size_t(t0) + k];
      if (o == kNoTriangle || o < t0 || !evaluate(t0, k, f)) continue;
      apply(f);
      ++flips;
      for (std::uint32_t t : {f.t0, f.t1, f.n_bc, f.n_ca, f.n_ad, f.n_db}) mark[t] = 1;
    }
    host_trace("clean-up: fairing round", flips);
    res.rounds = round + 1;
    res.flips += flips;
    if (flips == 0) break;
    // The next work list: the edges of the marked triangles, in triangle
    // order, each once (an edge between two marked triangles from the lower).
    work.clear();
    for (std::uint32_t t = 0; t < nt; ++t) {
      if (!mark[t]) continue;
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t o = nb[3 * std::size_t(t) + k];
        if (o == kNoTriangle || (o < t && mark[o])) continue;
        const std::uint32_t id = edge_id(t, k);
        if (id != kNoTriangle) work.push_back(id);
      }
    }
    std::fill(mark.begin(), mark.end(), std::uint8_t(0));
  }
  return res;
}

}  // namespace mesh
}  // namespace nbmc
