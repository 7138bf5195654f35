// SPDX-License-Identifier: MIT
// Mesh decimation (nbmc_params.decimate_fraction): quadric-error edge
// collapses (M. Garland, P. Heckbert, "Surface simplification using quadric
// error metrics", SIGGRAPH 1997) down to a fraction of the triangles, keeping
// the mesh closed, manifold and consistently oriented. Plain C++, serial.
//
// Each vertex carries the quadric of the planes of its triangles, weighted
// by their areas: Q(x) is the sum of area * (distance of x to the plane)^2.
// Collapsing the edge (a, b) puts the merged vertex where Qa + Qb is
// smallest; along directions where that minimum is flat (a flat or
// cylindrical patch), toward the edge's midpoint (the minimum of
// Qa + Qb + eps * trace * |x - midpoint|^2, eps = 1e-3). Its cost is that
// minimum. Edges are collapsed cheapest first (a 4-ary heap with lazy
// deletion; ties by the vertex indices, so the order is a total order and the
// result depends only on the input mesh: the same on every backend, thread
// count and subdomain split, whose meshes are the same). O(n log n). A collapse is made only when
//  - the edge has two triangles and the link condition holds (the two ends
//    share exactly the two opposite vertices), the merged vertex keeps three
//    neighbours and each opposite vertex keeps three: closed and manifold
//    stay so, and orientation is kept by construction (a collapse renames a
//    vertex);
//  - no triangle's normal turns by 60 degrees or more (no fold), no
//    triangle becomes degenerate and no good triangle becomes a sliver
//    (smallest angle below 1 degree; see mesh_check.hpp).
// Vertices on a boundary, non-manifold or misoriented edge are left alone.
// A collapse refused now may become possible after its neighbours changed:
// when the heap runs dry above the target, it is filled again with every
// edge (at most kDecimatePasses times, or until a pass collapses nothing).
// The surviving triangles keep their order, the surviving vertices theirs.
// Normals, when present, are recomputed from the faces (area-weighted).
#pragma once

#include "mesh_check.hpp"
#include "mesh_smooth.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

namespace nbmc {
namespace mesh {

constexpr int kDecimatePasses = 4;
// Largest turn of a triangle's normal a collapse may cause (cosine).
constexpr double kDecimateCosMaxTurn = 0.5;  // 60 degrees
// Weight of the pull toward the edge's midpoint (relative to the quadric's trace).
constexpr double kDecimateMidpointPull = 1e-3;

struct DecimateResult {
  std::uint64_t triangles_before = 0, triangles_after = 0;
  std::uint64_t collapses = 0;
  std::uint64_t refused = 0;  // candidate collapses refused by the checks
  double max_error = 0;       // largest sqrt(cost / area) of a collapse made (a distance)
};

namespace detail {

// A 4-ary min-heap (half the depth of a binary one: the sifting, which
// dominates the decimation's run time, touches half the cache lines).
// before(x, y): x comes out first.
template <class T, class Before>
class QuadHeap {
 public:
  bool empty() const { return h_.empty(); }
  const T& top() const { return h_.front(); }
  void clear() { std::vector<T>().swap(h_); }
  void assign(std::vector<T> items) {
    h_ = std::move(items);
    if (h_.size() > 1)
      for (std::size_t i = (h_.size() - 2) / 4 + 1; i-- > 0;) down(i);
  }
  void push(const T& x) {
    h_.push_back(x);
    std::size_t i = h_.size() - 1;
    while (i > 0) {
      const std::size_t parent = (i - 1) / 4;
      if (!before_(h_[i], h_[parent])) break;
      std::swap(h_[i], h_[parent]);
      i = parent;
    }
  }
  void pop() {
    h_.front() = h_.back();
    h_.pop_back();
    if (!h_.empty()) down(0);
  }

 private:
  void down(std::size_t i) {
    const std::size_t n = h_.size();
    const T x = h_[i];
    for (;;) {
      const std::size_t c = 4 * i + 1;
      if (c >= n) break;
#if defined(__GNUC__)
      // The grandchildren are 16 consecutive entries (4 cache lines): fetch
      // them while this level is compared (the sifting waits on memory).
      const std::size_t g = 4 * c + 1;
      if (g < n)
        for (std::size_t k = 0; k < 16 && g + k < n; k += 4) __builtin_prefetch(&h_[g + k]);
#endif
      std::size_t best = c;
      const std::size_t end = std::min(n, c + 4);
      for (std::size_t k = c + 1; k < end; ++k)
        if (before_(h_[k], h_[best])) best = k;
      if (!before_(h_[best], x)) break;
      h_[i] = h_[best];
      i = best;
    }
    h_[i] = x;
  }
  std::vector<T> h_;
  Before before_;
};

// Symmetric 4x4 quadric, upper triangle: xx xy xz xw yy yz yw zz zw ww.
struct Quadric {
  double q[10] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  double area = 0;
  void add_plane(const Vec3& n, double d, double w) {  // unit n, n.x + d = 0
    const double p[4] = {n.x, n.y, n.z, d};
    int k = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i; j < 4; ++j) q[k++] += w * p[i] * p[j];
    area += w;
  }
  Quadric& operator+=(const Quadric& o) {
    for (int i = 0; i < 10; ++i) q[i] += o.q[i];
    area += o.area;
    return *this;
  }
  double eval(const Vec3& x) const {
    return q[0] * x.x * x.x + 2 * q[1] * x.x * x.y + 2 * q[2] * x.x * x.z + 2 * q[3] * x.x + q[4] * x.y * x.y +
           2 * q[5] * x.y * x.z + 2 * q[6] * x.y + q[7] * x.z * x.z + 2 * q[8] * x.z + q[9];
  }
};

template <class Real>
class Decimator {
 public:
  // positions are shifted by -origin for the quadrics (coordinates far from
  // the origin keep their precision); P_ itself stays in place.
  Decimator(Real* positions, std::size_t nv, std::uint32_t* tri, std::size_t nt)
      : P_(positions), nv_(nv), T_(tri), nt_(nt), alive_(nt, 1), vertex_alive_(nv, 1), stamp_(nv, 0), quadric_(nv),
        tris_(nv) {
    const double extent = bounding_extent(positions, nv, &origin_);
    degenerate_double_area_ = 2 * kDegenerateAreaFraction * extent * extent;
    check_mesh(positions, nv, tri, nt, &irregular_);
    for (std::size_t t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k) tris_[tri[3 * t + k]].push_back(std::uint32_t(t));
    for (std::size_t t = 0; t < nt; ++t) {
      const std::uint32_t* v = tri + 3 * t;
      const Vec3 a = pos(v[0]), b = pos(v[1]), c = pos(v[2]);
      const Vec3 n = cross(b - a, c - a);
      const double l = norm(n);
      if (!(l > 0)) continue;
      const Vec3 u = (1.0 / l) * n;
      for (int k = 0; k < 3; ++k) quadric_[v[k]].add_plane(u, -dot(u, a), 0.5 * l);
    }
    alive_count_ = nt;
  }

  DecimateResult run(std::size_t target) {
    DecimateResult r;
    r.triangles_before = nt_;
    for (int pass = 0; pass < kDecimatePasses && alive_count_ > target; ++pass) {
      seed();
      const std::uint64_t before = r.collapses;
      while (alive_count_ > target && !heap_.empty()) {
        const Entry e = heap_.top();
        heap_.pop();
        if (!vertex_alive_[e.a] || !vertex_alive_[e.b] || stamp_[e.a] + stamp_[e.b] != e.stamp) continue;
        if (!try_collapse(e.a, e.b, place(e.a, e.b))) {
          ++r.refused;
          continue;
        }
        ++r.collapses;
        const double area = quadric_[e.a].area;
        if (area > 0) r.max_error = std::max(r.max_error, std::sqrt(std::max(0.0, double(e.cost)) / area));
      }
      if (r.collapses == before) break;
    }
    heap_.clear();
    r.triangles_after = alive_count_;
    return r;
  }

  // Writes the surviving triangles and vertices back, compacted (normals,
  // when given, follow their vertices); returns the new counts.
  std::pair<std::size_t, std::size_t> compact(float* normals) {
    return compact_mesh(P_, normals, nv_, T_, nt_, alive_);
  }

 private:
  // 16 bytes, four to a cache line: the heap's sifting dominates the run
  // time. The merged vertex's position is computed again when the entry is
  // taken; the cost is kept in float (ties: by the vertex indices).
  struct Entry {
    float cost;
    std::uint32_t a, b;  // a < b; b merges into a
    std::uint32_t stamp; // stamps of a and b added up when it was computed (they only grow)
  };
  // Total order: cost, then the vertex indices.
  struct Before {
    bool operator()(const Entry& x, const Entry& y) const {
      if (x.cost != y.cost) return x.cost < y.cost;
      if (x.a != y.a) return x.a < y.a;
      return x.b < y.b;
    }
  };
  using Heap = QuadHeap<Entry, Before>;

  Vec3 pos(std::uint32_t v) const { return load(P_, v) - origin_; }
  // The position as the output will hold it (rounded to Real), shifted.
  Vec3 rounded(const Vec3& p) const {
    const Vec3 x = p + origin_;
    return Vec3{double(Real(x.x)), double(Real(x.y)), double(Real(x.z))} - origin_;
  }
  static bool contains(const std::uint32_t* v, std::uint32_t x) { return v[0] == x || v[1] == x || v[2] == x; }

  // Every edge of the alive triangles between two regular vertices, once.
  void seed() {
    std::vector<Entry> all;
    for (std::size_t t = 0; t < nt_; ++t) {
      if (!alive_[t]) continue;
      const std::uint32_t* v = T_ + 3 * t;
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t a = v[k], b = v[(k + 1) % 3];
        // Each edge of a closed, oriented mesh runs once each way: take it
        // from the triangle where it runs upward.
        if (a < b && !irregular_[a] && !irregular_[b]) all.push_back(entry(a, b));
      }
    }
    heap_.assign(std::move(all));
  }

  Entry entry(std::uint32_t a, std::uint32_t b) const {
    if (a > b) std::swap(a, b);
    Quadric q = quadric_[a];
    q += quadric_[b];
    return Entry{float(std::max(0.0, q.eval(place(a, b)))), a, b, stamp_[a] + stamp_[b]};
  }

  // Where the edge (a, b), a < b, puts the merged vertex (shifted, rounded
  // as the output will hold it).
  Vec3 place(std::uint32_t a, std::uint32_t b) const {
    Quadric q = quadric_[a];
    q += quadric_[b];
    const Vec3 pa = pos(a), pb = pos(b), m = 0.5 * (pa + pb);
    // Minimise Q(x) + lambda |x - m|^2: (A + lambda I) x = lambda m - bvec.
    const double lambda = kDecimateMidpointPull * (q.q[0] + q.q[4] + q.q[7]);
    const double a00 = q.q[0] + lambda, a01 = q.q[1], a02 = q.q[2], a11 = q.q[4] + lambda, a12 = q.q[5],
                 a22 = q.q[7] + lambda;
    const double r0 = lambda * m.x - q.q[3], r1 = lambda * m.y - q.q[6], r2 = lambda * m.z - q.q[8];
    const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
    const double det = a00 * c00 + a01 * c01 + a02 * c02;
    Vec3 best = m;
    const double edge = norm(pb - pa);
    if (lambda > 0 && std::fabs(det) > 0) {
      const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
      const Vec3 x{(c00 * r0 + c01 * r1 + c02 * r2) / det, (c01 * r0 + c11 * r1 + c12 * r2) / det,
                   (c02 * r0 + c12 * r1 + c22 * r2) / det};
      // A minimum far from the edge means an ill-posed system: keep the
      // best of the ends and the midpoint instead.
      if (std::isfinite(x.x) && std::isfinite(x.y) && std::isfinite(x.z) && norm(x - m) <= edge) best = x;
    }
    if (best.x == m.x && best.y == m.y && best.z == m.z) {
      double e = q.eval(m);
      for (const Vec3& c : {pa, pb})
        if (q.eval(c) < e) e = q.eval(c), best = c;
    }
    return rounded(best);
  }

  // Alive triangles around v (its list is kept to those).
  const std::vector<std::uint32_t>& fan(std::uint32_t v) {
    std::vector<std::uint32_t>& f = tris_[v];
    f.erase(std::remove_if(f.begin(), f.end(),
                           [&](std::uint32_t t) { return !alive_[t] || !contains(T_ + 3 * std::size_t(t), v); }),
            f.end());
    return f;
  }
  void ring(std::uint32_t v, const std::vector<std::uint32_t>& f, std::vector<std::uint32_t>& out) const {
    out.clear();
    for (std::uint32_t t : f)
      for (int k = 0; k < 3; ++k)
        if (T_[3 * std::size_t(t) + k] != v) out.push_back(T_[3 * std::size_t(t) + k]);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
  }

  bool try_collapse(std::uint32_t a, std::uint32_t b, const Vec3& p) {
    const std::vector<std::uint32_t>& fa = fan(a);
    const std::vector<std::uint32_t>& fb = fan(b);
    std::uint32_t shared[2], n_shared = 0;
    for (std::uint32_t t : fa)
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
    ring(a, fa, ra_);
    ring(b, fb, rb_);
    common_.clear();
    std::set_intersection(ra_.begin(), ra_.end(), rb_.begin(), rb_.end(), std::back_inserter(common_));
    if (common_.size() != 2) return false;  // link condition
    if (ra_.size() + rb_.size() < 4 + 3) return false;
    for (std::uint32_t o : opposite)
      if (fan(o).size() < 4) return false;
    for (const std::vector<std::uint32_t>* f : {&fa, &fb})
      for (std::uint32_t t : *f) {
        if (t == shared[0] || t == shared[1]) continue;
        const std::uint32_t* v = T_ + 3 * std::size_t(t);
        Vec3 q[3], o[3];
        for (int k = 0; k < 3; ++k) {
          o[k] = pos(v[k]);
          q[k] = v[k] == a || v[k] == b ? p : o[k];
        }
        const TriangleShape s_old = triangle_shape(o[0], o[1], o[2]);
        const TriangleShape s_new = triangle_shape(q[0], q[1], q[2]);
        const int c_old = triangle_class(s_old, degenerate_double_area_);
        const int c_new = triangle_class(s_new, degenerate_double_area_);
        if (c_new == 2 || (c_old == 0 && c_new != 0)) return false;
        if (c_old == 2) continue;  // its normal is noise
        const Vec3 n_new = cross(q[1] - q[0], q[2] - q[0]), n_old = cross(o[1] - o[0], o[2] - o[0]);
        if (dot(n_new, n_old) <= kDecimateCosMaxTurn * norm(n_new) * norm(n_old)) return false;
      }
    // Collapse b into a.
    alive_[shared[0]] = alive_[shared[1]] = 0;
    alive_count_ -= 2;
    std::vector<std::uint32_t>& ta = tris_[a];
    for (std::uint32_t t : tris_[b]) {
      if (!alive_[t]) continue;
      std::uint32_t* v = T_ + 3 * std::size_t(t);
      for (int k = 0; k < 3; ++k)
        if (v[k] == b) v[k] = a;
      ta.push_back(t);
    }
    std::vector<std::uint32_t>().swap(tris_[b]);
    std::sort(ta.begin(), ta.end());
    ta.erase(std::unique(ta.begin(), ta.end()), ta.end());
    const Vec3 x = p + origin_;
    P_[3 * std::size_t(a)] = Real(x.x);
    P_[3 * std::size_t(a) + 1] = Real(x.y);
    P_[3 * std::size_t(a) + 2] = Real(x.z);
    quadric_[a] += quadric_[b];
    vertex_alive_[b] = 0;
    ++stamp_[a];
    ++stamp_[b];
    ring(a, fan(a), ra_);
    for (std::uint32_t u : ra_)
      if (!irregular_[u]) heap_.push(entry(a, u));
    return true;
  }

  Real* P_;
  std::size_t nv_;
  std::uint32_t* T_;
  std::size_t nt_;
  std::size_t alive_count_ = 0;
  Vec3 origin_;
  double degenerate_double_area_ = 0;
  std::vector<std::uint8_t> alive_, vertex_alive_, irregular_;
  std::vector<std::uint32_t> stamp_;
  std::vector<Quadric> quadric_;
  std::vector<std::vector<std::uint32_t>> tris_;
  Heap heap_;
  std::vector<std::uint32_t> ra_, rb_, common_;
};

}  // namespace detail

// Decimates the mesh in place to about fraction (0 < fraction <= 1) of its
// triangles (fewer collapses when the checks refuse more): positions (3
// floats or doubles per vertex), normals (3 floats per vertex, may be empty;
// recomputed from the faces) and triangles (3 indices each). Vectors of any
// allocator; shrunk to the new counts. fraction >= 1 leaves the mesh as is.
template <class PosVec, class NormalVec, class IndexVec>
DecimateResult decimate_mesh(PosVec& positions, NormalVec& normals, IndexVec& triangles, double fraction) {
  DecimateResult r;
  const std::size_t nv = positions.size() / 3, nt = triangles.size() / 3;
  r.triangles_before = r.triangles_after = nt;
  if (nt == 0 || !(fraction < 1)) return r;
  const std::size_t target = std::size_t(std::ceil(std::max(0.0, fraction) * double(nt)));
  const bool has_normals = !normals.empty() && normals.size() == positions.size();
  using Real = typename PosVec::value_type;
  std::pair<std::size_t, std::size_t> counts;
  {
    detail::Decimator<Real> d(positions.data(), nv, triangles.data(), nt);
    r = d.run(target);
    counts = d.compact(has_normals ? normals.data() : nullptr);
  }
  positions.resize(3 * counts.first);
  triangles.resize(3 * counts.second);
  if (has_normals) {
    normals.resize(3 * counts.first);
    face_normals_to_vertices(positions.data(), counts.first, triangles.data(), counts.second, normals.data());
  }
  return r;
}

}  // namespace mesh
}  // namespace nbmc
