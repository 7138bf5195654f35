// SPDX-License-Identifier: MIT
// The clean-up's move rounds (mesh_cleanup.hpp, cleanup_mesh): what one
// item of a round decides, the same on the host and on a GPU. Plain C++;
// every function here is NBMC_HD and reads only flat arrays.
//
// Almost every repair of a marching-cubes mesh is a move of one vertex (the
// 1.65 M frame at r/2: 6,608 of 6,750 repairs), and moves of vertices that
// are not neighbours do not see each other: a move of v reads the
// positions of v's fan only and changes only v's triangles, and it never
// changes the topology. So the clean-up first makes its moves in rounds
// that need no order, on the mesh as it came (every triangle alive, the
// incidence as built). In each round:
//  1. each waiting bad triangle t takes its three vertices with its index
//     (the smallest index holds a vertex);
//  2. each triangle holding all three decides (evaluate_move below, on the
//     mesh as it stands): it leaves the rounds (it is good now, has a
//     vertex that is irregular or has more than kMoveFanMax triangles, no
//     move works, or flipping its longest edge would score better: the
//     passes decide those), or it proposes its best move; the others wait;
//  3. each proposal's vertex takes the smallest proposing index; a proposal
//     is made when it holds its vertex and no neighbour of that vertex is
//     held by a smaller index. The moves made in a round are made together:
//     no two touch a common triangle, so each one's checks still hold;
//  4. the triangles that proposed and lost, and those that waited, wait for
//     the next round.
// The smallest waiting index always moves or leaves, so the rounds end; no
// order of threads enters, so the result is the same on every backend and
// thread count. Moves judge every triangle around the vertex they move and
// never make a good triangle bad, so the bad triangles after the rounds
// are among those before (a scan of the maybe-bad triangles finds them).
// The repair passes then take what is left.
//
// evaluate_move is repair()'s first step in mesh_cleanup.hpp (consider_move
// for each vertex, the best of the three, then consider_flip), on fans of
// at most kMoveFanMax triangles held on the stack, with the same arithmetic.
#pragma once

#include "hd.hpp"
#include "mesh_check.hpp"  // Vec3, triangle_shape, triangle_class, surely_good

#include <cstdint>

namespace nbmc {
namespace mesh {

// Largest turn of a triangle's normal that a repair may cause (the move
// rounds' limit, and the clean-up's first one: mesh_cleanup.hpp).
constexpr double kCosMaxNormalTurn = 0.5;  // 60 degrees

// The largest fan a move round looks at (a regular vertex of a
// marching-cubes mesh has at most 12 or so triangles).
constexpr std::uint32_t kMoveFanMax = 16;

// The mesh as the rounds see it: positions (Real: float or double), the
// triangles, and per vertex its triangles in ascending order
// (incident[start[v] .. start[v + 1])).
template <class Real>
struct MoveMesh {
  Real* P = nullptr;
  const std::uint32_t* T = nullptr;
  const std::uint32_t* start = nullptr;
  const std::uint32_t* incident = nullptr;
  double degenerate_double_area = 0;
  double cos_limit = 0;
};

// What evaluate_move decides.
enum class MoveVerdict : std::uint8_t { Leave = 1, Propose = 2 };

// A proposed move: vertex v to p (p in the positions' precision already).
struct MoveProposal {
  std::uint32_t v = 0;
  double p[3] = {0, 0, 0};
  double score = -1;
};

// Whether the n triangles incident[b .. b + n) around v form one closed fan:
// each holds v once, and walking from a triangle to the one whose previous
// vertex is this one's next goes once through all of them (mesh_cleanup's
// small_closed_fan, the same test).
NBMC_HD bool small_closed_fan(const std::uint32_t* T, const std::uint32_t* incident, std::uint32_t v, std::uint32_t b,
                              std::uint32_t n) {
  if (n < 3 || n > kMoveFanMax) return false;
  std::uint32_t in[kMoveFanMax], out[kMoveFanMax];  // previous and next vertex, by local index
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::uint32_t* w = T + 3 * std::size_t(incident[b + i]);
    const int k = w[0] == v ? 0 : w[1] == v ? 1 : 2;
    out[i] = w[(k + 1) % 3];
    in[i] = w[(k + 2) % 3];
    if (out[i] == v || in[i] == v) return false;
  }
  for (std::uint32_t i = 1; i < n; ++i)
    for (std::uint32_t j = 0; j < i; ++j)
      if (in[i] == in[j]) return false;
  std::uint32_t cur = 0, steps = 0;
  do {
    std::uint32_t j = 0;
    while (j < n && in[j] != out[cur]) ++j;
    if (j == n) return false;
    cur = j;
    ++steps;
  } while (cur != 0 && steps <= n);
  return cur == 0 && steps == n;
}

namespace moves_detail {

// A vertex's fan (its list as built: ascending, each triangle once when the
// vertex is regular) and its one-ring (sorted, unique).
struct Fan {
  std::uint32_t n = 0, ring_n = 0;
  std::uint32_t t[kMoveFanMax];
  std::uint32_t ring[2 * kMoveFanMax];
};

template <class Real>
NBMC_HD bool movable(const MoveMesh<Real>& m, std::uint32_t v) {
  const std::uint32_t b = m.start[v], n = m.start[v + 1] - b;
  return small_closed_fan(m.T, m.incident, v, b, n);
}

// v's fan and ring; v movable (at most kMoveFanMax triangles).
template <class Real>
NBMC_HD void fan_of(const MoveMesh<Real>& m, std::uint32_t v, Fan& f) {
  const std::uint32_t b = m.start[v];
  f.n = m.start[v + 1] - b;
  f.ring_n = 0;
  for (std::uint32_t i = 0; i < f.n; ++i) {
    const std::uint32_t t = m.incident[b + i];
    f.t[i] = t;
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t u = m.T[3 * std::size_t(t) + k];
      if (u == v) continue;
      // (insertion into the sorted ring, skipping repeats)
      std::uint32_t j = f.ring_n;
      bool seen = false;
      for (std::uint32_t q = 0; q < f.ring_n; ++q)
        if (f.ring[q] == u) seen = true;
      if (seen) continue;
      while (j > 0 && f.ring[j - 1] > u) {
        f.ring[j] = f.ring[j - 1];
        --j;
      }
      f.ring[j] = u;
      ++f.ring_n;
    }
  }
}

NBMC_HD bool holds(const std::uint32_t* w, std::uint32_t x) { return w[0] == x || w[1] == x || w[2] == x; }

// consider_move(t, v): the shortest of the trial moves of v (a quarter,
// half or all the way to its ring's centroid, in the tangent plane) that
// makes t good, turns no triangle good to bad or beyond the limit; its
// score is the smallest angle's sine around v afterwards. False: none.
template <class Real>
NBMC_HD bool consider_move(const MoveMesh<Real>& m, std::uint32_t t, std::uint32_t v, const Fan& f,
                           MoveProposal& out) {
  if (f.ring_n == 0) return false;
  const Vec3 pv = load(m.P, v);
  Vec3 centroid, n;
  for (std::uint32_t i = 0; i < f.ring_n; ++i) centroid = centroid + load(m.P, f.ring[i]);
  centroid = (1.0 / double(f.ring_n)) * centroid;
  for (std::uint32_t i = 0; i < f.n; ++i) {
    const std::uint32_t* w = m.T + 3 * std::size_t(f.t[i]);
    n = n + cross(load(m.P, w[1]) - load(m.P, w[0]), load(m.P, w[2]) - load(m.P, w[0]));
  }
  const double ln = norm(n);
  if (!(ln > 0)) return false;
  n = (1.0 / ln) * n;
  Vec3 d = centroid - pv;
  d = d - dot(d, n) * n;
  const std::uint32_t* w = m.T + 3 * std::size_t(t);
  // The fan's old normals and classes (prepare_positions), once.
  bool prepared = false;
  Vec3 old_normal[kMoveFanMax];
  double ref_norm[kMoveFanMax];
  int old_cls[kMoveFanMax];
  Vec3 mean;
  const double fs[3] = {0.25, 0.5, 1.0};
  for (int s = 0; s < 3; ++s) {
    const Vec3 p = pv + fs[s] * d;
    const Vec3 pr{double(Real(p.x)), double(Real(p.y)), double(Real(p.z))};
    Vec3 q[3];
    for (int k = 0; k < 3; ++k) q[k] = w[k] == v ? pr : load(m.P, w[k]);
    if (triangle_class(triangle_shape(q[0], q[1], q[2]), m.degenerate_double_area) != 0) continue;
    if (!prepared) {
      for (std::uint32_t i = 0; i < f.n; ++i) {
        const std::uint32_t* x = m.T + 3 * std::size_t(f.t[i]);
        const Vec3 o0 = load(m.P, x[0]), o1 = load(m.P, x[1]), o2 = load(m.P, x[2]);
        const Vec3 c = cross(o1 - o0, o2 - o0);
        mean = mean + c;
        old_normal[i] = c;
        old_cls[i] = triangle_class_of(o0, o1, o2, m.degenerate_double_area);
      }
      const double lm = norm(mean);
      for (std::uint32_t i = 0; i < f.n; ++i) ref_norm[i] = old_cls[i] == 0 ? norm(old_normal[i]) : lm;
      if (!(lm > 0)) return false;
      prepared = true;
    }
    // judge_positions: t first, then the others; the score a minimum.
    double score = 2;
    auto judge = [&](std::uint32_t i) {
      const std::uint32_t u = f.t[i];
      const std::uint32_t* x = m.T + 3 * std::size_t(u);
      Vec3 r[3];
      for (int k = 0; k < 3; ++k) r[k] = x[k] == v ? pr : load(m.P, x[k]);
      const TriangleShape s_new = triangle_shape(r[0], r[1], r[2]);
      const int c_old = old_cls[i];
      const int c_new = triangle_class(s_new, m.degenerate_double_area);
      if (c_new == 2 || (c_new != 0 && (c_old == 0 || u == t))) return false;
      const Vec3 n_new = cross(r[1] - r[0], r[2] - r[0]);
      const Vec3& n_ref = c_old == 0 ? old_normal[i] : mean;
      if (dot(n_new, n_ref) <= m.cos_limit * s_new.double_area * ref_norm[i]) return false;
      score = s_new.sin_min_angle < score ? s_new.sin_min_angle : score;
      return true;
    };
    std::uint32_t i_t = f.n;
    for (std::uint32_t i = 0; i < f.n; ++i)
      if (f.t[i] == t) i_t = i;
    bool ok = i_t == f.n || judge(i_t);
    for (std::uint32_t i = 0; ok && i < f.n; ++i)
      if (i != i_t && !judge(i)) ok = false;
    if (!ok) continue;
    if (score <= -1) continue;  // (as judge_positions against a fresh candidate)
    out.v = v;
    out.p[0] = pr.x;
    out.p[1] = pr.y;
    out.p[2] = pr.z;
    out.score = score;
    return true;
  }
  return false;
}

// 0: no flip of t's longest edge beats `score`; 1: one does (the passes
// decide); 2: one might, but its far vertex is not movable here (the
// passes decide too). consider_flip's checks, in its order.
template <class Real>
NBMC_HD int flip_beats(const MoveMesh<Real>& m, std::uint32_t t, double best_score) {
  const std::uint32_t* v = m.T + 3 * std::size_t(t);
  int k_long = 0;
  double l_long = -1;
  for (int k = 0; k < 3; ++k) {
    const double l = norm(load(m.P, v[(k + 1) % 3]) - load(m.P, v[k]));
    if (l > l_long) l_long = l, k_long = k;
  }
  const std::uint32_t a = v[k_long], b = v[(k_long + 1) % 3], c = v[(k_long + 2) % 3];
  const std::uint32_t ab = m.start[a], an = m.start[a + 1] - ab;
  std::uint32_t t2 = ~0u;
  for (std::uint32_t i = 0; i < an; ++i) {
    const std::uint32_t u = m.incident[ab + i];
    if (u == t) continue;
    if (holds(m.T + 3 * std::size_t(u), b)) {
      if (t2 != ~0u) return 0;
      t2 = u;
    }
  }
  if (t2 == ~0u) return 0;
  const std::uint32_t* w = m.T + 3 * std::size_t(t2);
  const std::uint32_t d = w[0] != a && w[0] != b ? w[0] : w[1] != a && w[1] != b ? w[1] : w[2];
  if (d == c) return 0;
  const Vec3 pa = load(m.P, a), pb = load(m.P, b), pc = load(m.P, c), pd = load(m.P, d);
  const Vec3 n_old = cross(pb - pa, pc - pa) + cross(pa - pb, pd - pb);
  const TriangleShape s1 = triangle_shape(pc, pa, pd), s2 = triangle_shape(pc, pd, pb);
  if (triangle_class(s1, m.degenerate_double_area) || triangle_class(s2, m.degenerate_double_area)) return 0;
  const Vec3 n1 = cross(pa - pc, pd - pc), n2 = cross(pd - pc, pb - pc);
  if (dot(n1, n_old) <= m.cos_limit * norm(n1) * norm(n_old)) return 0;
  if (dot(n2, n_old) <= m.cos_limit * norm(n2) * norm(n_old)) return 0;
  if (dot(n1, n2) <= m.cos_limit * norm(n1) * norm(n2)) return 0;
  const double score = s2.sin_min_angle < s1.sin_min_angle ? s2.sin_min_angle : s1.sin_min_angle;
  if (score <= best_score) return 0;
  if (m.start[d + 1] - m.start[d] > kMoveFanMax) return 2;
  if (!movable(m, d)) return 0;
  // An edge c-d already, or a or b left with fewer than four triangles.
  const std::uint32_t cb = m.start[c], cn = m.start[c + 1] - cb;
  for (std::uint32_t i = 0; i < cn; ++i)
    if (holds(m.T + 3 * std::size_t(m.incident[cb + i]), d)) return 0;
  if (an < 4 || m.start[b + 1] - m.start[b] < 4) return 0;
  return 1;
}

}  // namespace moves_detail

// Round step 2 for the bad triangle t (see the top of this file): Leave, or
// Propose with `out` the best move of one of t's vertices.
template <class Real>
NBMC_HD MoveVerdict evaluate_move(const MoveMesh<Real>& m, std::uint32_t t, MoveProposal& out) {
  using namespace moves_detail;
  const std::uint32_t* v = m.T + 3 * std::size_t(t);
  if (triangle_class_of(load(m.P, v[0]), load(m.P, v[1]), load(m.P, v[2]), m.degenerate_double_area) == 0)
    return MoveVerdict::Leave;
  for (int k = 0; k < 3; ++k)
    if (!movable(m, v[k])) return MoveVerdict::Leave;
  MoveProposal best;
  bool found = false;
  for (int k = 0; k < 3; ++k) {
    Fan f;
    fan_of(m, v[k], f);
    MoveProposal c;
    if (consider_move(m, t, v[k], f, c) && c.score > best.score) {
      best = c;
      found = true;
    }
  }
  if (!found || flip_beats(m, t, best.score) != 0) return MoveVerdict::Leave;
  out = best;
  return MoveVerdict::Propose;
}

// Round step 3's test for a proposal of index t moving v: whether a
// neighbour of v is held by a smaller index (held[stride * u]: the
// smallest index proposing to move u, or ~0u; read while nothing writes it).
template <class Real>
NBMC_HD bool neighbour_taken_before(const MoveMesh<Real>& m, std::uint32_t v, std::uint32_t t,
                                    const std::uint32_t* held, std::size_t stride) {
  for (std::uint32_t i = m.start[v], e = m.start[v + 1]; i < e; ++i) {
    const std::uint32_t* w = m.T + 3 * std::size_t(m.incident[i]);
    for (int k = 0; k < 3; ++k)
      if (w[k] != v && held[stride * w[k]] < t) return true;
  }
  return false;
}

}  // namespace mesh
}  // namespace nbmc
