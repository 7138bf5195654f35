// SPDX-License-Identifier: MIT
// Mesh check (nbmc_mesh_check, `nbmc reconstruct --check`): topology and
// quality figures of a triangle mesh given as flat host arrays. Plain C++,
// serial, so the figures are the same on every backend and thread count
// (compact_mesh, for the decimation, runs on host threads and its result
// does not depend on them either).
//
// Definitions (also in include/nbmc.h):
//  - an edge is an unordered pair of vertices used by at least one triangle;
//    boundary: used by one triangle; non-manifold: by three or more;
//    misoriented: by two triangles in the same direction;
//  - a vertex is non-manifold when its triangles, joined through the edges at
//    that vertex, form more than one fan (two cones touching at a tip);
//  - degenerate: area below 1e-12 of the squared largest side of the bounding
//    box, or two equal vertex indices; sliver: not degenerate, smallest angle
//    below 1 degree;
//  - components: sets of triangles connected through shared edges;
//  - Euler characteristic: V - E + F with V the vertices used by triangles;
//  - volume: the divergence theorem, sum of det(p0 - c, p1 - c, p2 - c) / 6
//    with c the centre of the bounding box (for a closed mesh independent of
//    c; positive when the triangles are counter-clockwise seen from outside).
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <utility>
#include <vector>

#include "hd.hpp"
#include "parallel.hpp"
#include "params.hpp"

namespace nbmc {
namespace mesh {

// sin(1 degree): a triangle's smallest angle is below 1 degree when
// 2 * area / (product of its two longest edges) is below this.
constexpr double kSinOneDegree = 0.017452406437283512;
// Degenerate: area below this fraction of the squared bounding-box extent.
constexpr double kDegenerateAreaFraction = 1e-12;

struct Vec3 {
  double x = 0, y = 0, z = 0;
};
// (These, triangle_shape, triangle_class and surely_good also run on GPUs:
// NBMC_HD, with the same roundings there, as contraction into fused
// multiply-adds is off on every backend: src/CMakeLists.txt.)
NBMC_HD Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
NBMC_HD Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
NBMC_HD Vec3 operator*(double s, const Vec3& a) { return {s * a.x, s * a.y, s * a.z}; }
NBMC_HD double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
NBMC_HD Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
NBMC_HD double norm(const Vec3& a) { return sqrt(dot(a, a)); }
// Vertex v of positions in float, or in double (nbmc_params.double_positions).
NBMC_HD Vec3 load(const float* p, std::uint32_t v) { return {p[3 * std::size_t(v)], p[3 * std::size_t(v) + 1], p[3 * std::size_t(v) + 2]}; }
NBMC_HD Vec3 load(const double* p, std::uint32_t v) { return {p[3 * std::size_t(v)], p[3 * std::size_t(v) + 1], p[3 * std::size_t(v) + 2]}; }

namespace detail {

// Moves the items i < n (`width` elements each) of array a with keep(i) to
// the front, in their order and in place, on host threads: item i goes to
// the number of kept items before it, written as f(element). Chunk k's items
// lie in [S_k, S_k+1) and go to [D_k, D_k+1) with D_k <= S_k; the chunks
// after k write from D_k+1 on, so chunk k first puts aside its kept items
// from D_k+1 on (few: as many as the items dropped before chunk k+1), then
// all chunks move their items at once. In steps, so that compact_mesh runs
// the same step of its three arrays in one round of threads: count(k) for
// every chunk, then starts(), put_aside(k) for every chunk, move(k, f).
template <class T>
struct ArrayCompaction {
  T* a;
  std::size_t width, n, chunks;
  std::vector<std::size_t> dst;          // D_k; dst[chunks]: the items kept
  std::vector<std::vector<T>> aside;
  ArrayCompaction(T* a_, std::size_t width_, std::size_t n_)
      : a(a_), width(width_), n(n_), chunks(chunk_count(n_, 65536)), dst(chunks + 1, 0), aside(chunks) {}
  std::size_t begin(std::size_t k) const { return n * k / chunks; }  // (as for_chunks)
  template <class Keep>
  void count(std::size_t k, const Keep& keep) {
    std::size_t m = 0;
    for (std::size_t i = begin(k), e = begin(k + 1); i < e; ++i) m += keep(i) ? 1 : 0;
    dst[k + 1] = m;
  }
  void starts() {
    for (std::size_t k = 0; k < chunks; ++k) dst[k + 1] += dst[k];
  }
  template <class Keep>
  void put_aside(std::size_t k, const Keep& keep) {
    for (std::size_t i = std::max(begin(k), dst[k + 1]), e = begin(k + 1); i < e; ++i)
      if (keep(i)) aside[k].insert(aside[k].end(), a + width * i, a + width * (i + 1));
  }
  template <class Keep, class F>
  void move(std::size_t k, const Keep& keep, const F& f) {
    std::size_t to = dst[k];
    const T* from_aside = aside[k].data();
    for (std::size_t i = begin(k), e = begin(k + 1); i < e; ++i) {
      if (!keep(i)) continue;
      const T* src = i >= dst[k + 1] ? (from_aside += width) - width : a + width * i;
      for (std::size_t c = 0; c < width; ++c) a[width * to + c] = f(src[c]);
      ++to;
    }
  }
};

}  // namespace detail

// Keeps the triangles t with alive[t] and the vertices they use, both in
// their order (positions, and normals when not NULL, move with their
// vertex; indices are renumbered), in place; returns the new vertex and
// triangle counts. The clean-up's and the decimation's last step; on all
// host threads (the result does not depend on them).
template <class Real, class AliveVec>
std::pair<std::size_t, std::size_t> compact_mesh(Real* positions, float* normals, std::size_t nv, std::uint32_t* tri,
                                                 std::size_t nt, const AliveVec& alive) {
  // The vertices the kept triangles use: a flag each, set by relaxed atomic
  // stores (plain stores on x86; threads may set the same flag). Allocated
  // unwritten and cleared on all host threads (a fresh array's pages are
  // mapped when first written: slow for one thread alone); so is remap.
  // Five rounds of host threads in all (each round starts its threads
  // afresh): the arrays' steps share them.
  std::vector<std::atomic<std::uint8_t>, NoInitAllocator<std::atomic<std::uint8_t>>> used(nv);
  for_chunks(nv, chunk_count(nv, 65536), [&](std::size_t, std::size_t b, std::size_t e) {
    for (std::size_t v = b; v < e; ++v) used[v].store(0, std::memory_order_relaxed);
  });
  auto is_used = [&](std::size_t v) { return used[v].load(std::memory_order_relaxed) != 0; };
  auto is_alive = [&](std::size_t t) { return alive[t] != 0; };
  detail::ArrayCompaction<Real> pc(positions, 3, nv);
  detail::ArrayCompaction<float> nc(normals, 3, nv);  // (not touched without normals)
  detail::ArrayCompaction<std::uint32_t> tc(tri, 3, nt);
  on_threads(tc.chunks, [&](std::size_t k) {
    for (std::size_t t = tc.begin(k), e = tc.begin(k + 1); t < e; ++t)
      if (alive[t])
        for (int c = 0; c < 3; ++c) used[tri[3 * t + c]].store(1, std::memory_order_relaxed);
    tc.count(k, is_alive);
  });
  on_threads(pc.chunks, [&](std::size_t k) { pc.count(k, is_used); });
  pc.starts();
  nc.dst = pc.dst;  // (the same chunks and vertices)
  tc.starts();
  // Nothing removed: every item stays where it is (no remap, no copy).
  if (pc.dst[pc.chunks] == nv && tc.dst[tc.chunks] == nt) return {nv, nt};
  // New vertex numbers: the used vertices before each one (pc's D_k).
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> remap(nv);  // (every entry written below)
  const std::size_t rounds = std::max(pc.chunks, tc.chunks);
  on_threads(rounds, [&](std::size_t k) {
    if (k < pc.chunks) {
      std::size_t m = pc.dst[k];
      for (std::size_t v = pc.begin(k), e = pc.begin(k + 1); v < e; ++v)
        remap[v] = std::uint32_t(is_used(v) ? m++ : 0);
      pc.put_aside(k, is_used);
      if (normals) nc.put_aside(k, is_used);
    }
    if (k < tc.chunks) tc.put_aside(k, is_alive);
  });
  auto same = [](auto x) { return x; };
  on_threads(rounds, [&](std::size_t k) {
    if (k < pc.chunks) {
      pc.move(k, is_used, same);
      if (normals) nc.move(k, is_used, same);
    }
    if (k < tc.chunks) tc.move(k, is_alive, [&](std::uint32_t v) { return remap[v]; });
  });
  const std::size_t kept_v = pc.dst[pc.chunks], kept_t = tc.dst[tc.chunks];
  return {kept_v, kept_t};
}

// Shape of one triangle: twice its area and the sine of its smallest angle
// (0 when two vertices coincide).
struct TriangleShape {
  double double_area = 0;
  double sin_min_angle = 0;
  double min_edge = 0;
};
NBMC_HD TriangleShape triangle_shape(const Vec3& a, const Vec3& b, const Vec3& c) {
  TriangleShape s;
  const Vec3 ab = b - a, bc = c - b, ca = a - c;
  s.double_area = norm(cross(ab, ca));
  double l[3] = {norm(ab), norm(bc), norm(ca)};
  // (Sorted by three exchanges: the values std::sort gives.)
  auto order = [](double& x, double& y) {
    if (y < x) {
      const double t = x;
      x = y;
      y = t;
    }
  };
  order(l[0], l[1]);
  order(l[1], l[2]);
  order(l[0], l[1]);
  s.min_edge = l[0];
  // The smallest angle lies opposite the shortest edge, between the two
  // longer ones: sin = 2A / (l1 * l2). (As std::min(1.0, q).)
  const double q = l[1] > 0 ? s.double_area / (l[1] * l[2]) : 0;
  s.sin_min_angle = l[1] > 0 ? (q < 1.0 ? q : 1.0) : 0;
  return s;
}

// Largest side of the bounding box of the vertices (0 for none).
template <class Real>
inline double bounding_extent(const Real* positions, std::size_t vertex_count, Vec3* centre = nullptr) {
  if (vertex_count == 0) {
    if (centre) *centre = Vec3{};
    return 0;
  }
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = positions[a];
  for (std::size_t v = 1; v < vertex_count; ++v)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], double(positions[3 * v + a]));
      hi[a] = std::max(hi[a], double(positions[3 * v + a]));
    }
  if (centre) *centre = Vec3{0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])};
  return std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
}

// Classifies a triangle: 0 good, 1 sliver, 2 degenerate.
NBMC_HD int triangle_class(const TriangleShape& s, double degenerate_double_area) {
  if (s.double_area < degenerate_double_area || s.sin_min_angle <= 0) return 2;
  return s.sin_min_angle < kSinOneDegree ? 1 : 0;
}

// True only for triangles that triangle_class certainly calls good (0),
// from squared lengths alone: no square root, division or sort, a third of
// triangle_shape's cost. The comparisons keep a relative margin of 1e-6,
// far above the few roundings either way, so a triangle near a threshold
// (and a NaN) gets false and is judged by triangle_shape itself; a scan
// that asks this first finds the same triangles.
NBMC_HD bool surely_good(const Vec3& a, const Vec3& b, const Vec3& c, double degenerate_double_area) {
  const Vec3 ab = b - a, bc = c - b, ca = a - c;
  const Vec3 n = cross(ab, ca);
  const double area2 = dot(n, n);  // (2 * area)^2
  const double x = dot(ab, ab), y = dot(bc, bc), z = dot(ca, ca);
  // The product of the two largest squared edges (as std::max of the three:
  // the first of the largest).
  double l12 = x * y;
  if (l12 < y * z) l12 = y * z;
  if (l12 < z * x) l12 = z * x;
  constexpr double kMargin = 1 + 1e-6;
  return area2 > 0 && area2 >= degenerate_double_area * degenerate_double_area * kMargin &&
         area2 >= kSinOneDegree * kSinOneDegree * l12 * kMargin;
}

// triangle_class of the triangle (a, b, c), asking surely_good first (no
// square root or division; most triangles a repair looks at are good): the
// same class.
NBMC_HD int triangle_class_of(const Vec3& a, const Vec3& b, const Vec3& c, double degenerate_double_area) {
  if (surely_good(a, b, c, degenerate_double_area)) return 0;
  return triangle_class(triangle_shape(a, b, c), degenerate_double_area);
}

struct CheckResult {
  bool closed = false, manifold = false, oriented = false;
  std::uint64_t vertices = 0, triangles = 0, edges = 0;
  std::uint64_t boundary_edges = 0, nonmanifold_edges = 0, misoriented_edges = 0;
  std::uint64_t nonmanifold_vertices = 0, unreferenced_vertices = 0;
  std::uint64_t degenerate_triangles = 0, sliver_triangles = 0;
  std::uint64_t components = 0;
  std::int64_t euler_characteristic = 0;
  double volume = 0, area = 0;
  double min_angle_degrees = 0;  // smallest angle of the non-degenerate triangles (0 if none)
};

namespace detail {

struct UnionFind {
  std::vector<std::uint32_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  std::uint32_t find(std::uint32_t x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  }
  // Deterministic: the smaller root survives.
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) parent[b] = a;
    else parent[a] = b;
  }
};

// One directed edge of a triangle, keyed by its unordered vertex pair.
struct HalfEdge {
  std::uint64_t key;     // (min << 32) | max
  std::uint32_t tri;
  std::uint32_t forward; // 1 when the triangle runs min -> max
  bool operator<(const HalfEdge& o) const { return key != o.key ? key < o.key : tri < o.tri; }
};

inline std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  return a < b ? (std::uint64_t(a) << 32) | b : (std::uint64_t(b) << 32) | a;
}

}  // namespace detail

// Checks the mesh. Throws std::invalid_argument when a triangle refers to a
// vertex index >= vertex_count.
// When irregular is given, it gets one flag per vertex: 1 where the vertex
// touches a boundary, non-manifold or misoriented edge, a triangle that
// repeats a vertex, or has more than one fan (mesh clean-up leaves these
// alone).
template <class Real>  // float or double positions
inline CheckResult check_mesh(const Real* positions, std::size_t vertex_count, const std::uint32_t* triangles,
                              std::size_t triangle_count, std::vector<std::uint8_t>* irregular = nullptr) {
  using detail::HalfEdge;
  CheckResult r;
  r.vertices = vertex_count;
  r.triangles = triangle_count;
  for (std::size_t i = 0; i < 3 * triangle_count; ++i)
    if (triangles[i] >= vertex_count) throw std::invalid_argument("a triangle refers to a vertex that does not exist");

  if (irregular) irregular->assign(vertex_count, 0);
  auto irregular_mark = [&](std::uint32_t v) { (*irregular)[v] = 1; };
  Vec3 centre;
  const double extent = bounding_extent(positions, vertex_count, &centre);
  const double degenerate_double_area = 2 * kDegenerateAreaFraction * extent * extent;

  // Quality, area, volume (serial sums in triangle order: reproducible).
  double min_sin = 2;
  std::vector<std::uint8_t> used(vertex_count, 0);
  for (std::size_t t = 0; t < triangle_count; ++t) {
    const std::uint32_t* v = triangles + 3 * t;
    for (int k = 0; k < 3; ++k) used[v[k]] = 1;
    const Vec3 a = load(positions, v[0]), b = load(positions, v[1]), c = load(positions, v[2]);
    const bool repeated = v[0] == v[1] || v[1] == v[2] || v[2] == v[0];
    if (repeated && irregular) irregular_mark(v[0]), irregular_mark(v[1]), irregular_mark(v[2]);
    const TriangleShape s = triangle_shape(a, b, c);
    const int cls = repeated ? 2 : triangle_class(s, degenerate_double_area);
    if (cls == 2) ++r.degenerate_triangles;
    else {
      if (cls == 1) ++r.sliver_triangles;
      min_sin = std::min(min_sin, s.sin_min_angle);
    }
    r.area += 0.5 * s.double_area;
    r.volume += dot(a - centre, cross(b - centre, c - centre)) / 6;
  }
  r.min_angle_degrees = min_sin <= 1 ? std::asin(min_sin) * 180.0 / 3.14159265358979323846 : 0;
  std::uint64_t used_count = 0;
  for (std::uint8_t u : used) used_count += u;
  r.unreferenced_vertices = vertex_count - used_count;

  // Edges: the directed edges sorted by their unordered pair.
  std::vector<HalfEdge> he;
  he.reserve(3 * triangle_count);
  for (std::size_t t = 0; t < triangle_count; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = triangles[3 * t + k], b = triangles[3 * t + (k + 1) % 3];
      if (a == b) continue;
      he.push_back({detail::edge_key(a, b), std::uint32_t(t), a < b ? 1u : 0u});
    }
  std::sort(he.begin(), he.end());
  detail::UnionFind tri_sets(triangle_count);
  for (std::size_t i = 0; i < he.size();) {
    std::size_t j = i + 1;
    while (j < he.size() && he[j].key == he[i].key) ++j;
    const std::size_t n = j - i;
    ++r.edges;
    const bool bad = n != 2 || he[i].forward == he[i + 1].forward;
    if (n == 1) ++r.boundary_edges;
    else if (n > 2) ++r.nonmanifold_edges;
    else if (he[i].forward == he[i + 1].forward) ++r.misoriented_edges;
    if (bad && irregular) irregular_mark(std::uint32_t(he[i].key >> 32)), irregular_mark(std::uint32_t(he[i].key));
    for (std::size_t k = i + 1; k < j; ++k) tri_sets.unite(he[i].tri, he[k].tri);
    i = j;
  }
  for (std::size_t t = 0; t < triangle_count; ++t)
    if (tri_sets.find(std::uint32_t(t)) == t) ++r.components;
  r.euler_characteristic = std::int64_t(used_count) - std::int64_t(r.edges) + std::int64_t(triangle_count);

  // Vertex fans: around each vertex, join the triangles that share an edge
  // at it (the same other vertex); more than one group is two fans.
  std::vector<std::uint32_t> start(vertex_count + 1, 0);
  for (std::size_t i = 0; i < 3 * triangle_count; ++i) ++start[triangles[i] + 1];
  for (std::size_t v = 0; v < vertex_count; ++v) start[v + 1] += start[v];
  std::vector<std::uint32_t> incident(start[vertex_count]);
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t t = 0; t < triangle_count; ++t)
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t v = triangles[3 * t + k];
        // A triangle that repeats v is listed once.
        if (k > 0 && triangles[3 * t + k - 1] == v) continue;
        if (k == 2 && triangles[3 * t] == v) continue;
        incident[fill[v]++] = std::uint32_t(t);
      }
    const std::vector<std::uint32_t>& end = fill;  // lists may be shorter than reserved
    std::vector<std::pair<std::uint32_t, std::uint32_t>> spokes;  // (other vertex, local triangle)
    std::vector<std::uint32_t> local_parent;
    for (std::size_t v = 0; v < vertex_count; ++v) {
      const std::uint32_t b = start[v], e = end[v];
      if (e - b < 2) continue;
      spokes.clear();
      for (std::uint32_t i = b; i < e; ++i) {
        const std::uint32_t* tv = triangles + 3 * std::size_t(incident[i]);
        for (int k = 0; k < 3; ++k)
          if (tv[k] != v) spokes.push_back({tv[k], i - b});
      }
      std::sort(spokes.begin(), spokes.end());
      local_parent.resize(e - b);
      std::iota(local_parent.begin(), local_parent.end(), 0u);
      auto find = [&](std::uint32_t x) {
        while (local_parent[x] != x) x = local_parent[x] = local_parent[local_parent[x]];
        return x;
      };
      std::uint32_t groups = e - b;
      for (std::size_t k = 1; k < spokes.size(); ++k)
        if (spokes[k].first == spokes[k - 1].first) {
          const std::uint32_t x = find(spokes[k].second), y = find(spokes[k - 1].second);
          if (x != y) {
            local_parent[std::max(x, y)] = std::min(x, y);
            --groups;
          }
        }
      if (groups > 1) {
        ++r.nonmanifold_vertices;
        if (irregular) irregular_mark(std::uint32_t(v));
      }
    }
  }
  r.closed = r.boundary_edges == 0 && r.nonmanifold_edges == 0;
  r.manifold = r.nonmanifold_edges == 0 && r.nonmanifold_vertices == 0;
  r.oriented = r.misoriented_edges == 0;
  return r;
}

}  // namespace mesh
}  // namespace nbmc
