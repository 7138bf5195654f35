// SPDX-License-Identifier: MIT
// Taubin lambda|mu smoothing (G. Taubin, "A signal processing approach to fair
// surface design", SIGGRAPH 1995) of a triangle mesh, and vertex normals from
// the faces. Plain C++; every vertex is updated from the previous positions
// (Jacobi), sums run in a fixed order: the result depends only on the mesh.
//
// One iteration is a shrinking step x += lambda * L(x) followed by an
// inflating step x += mu * L(x), with L(x)_i the mean of (x_j - x_i) over the
// vertices j joined to i by an edge (uniform weights). lambda = 0.5 and
// mu = -0.53 give the pass-band frequency k_pb = 1/lambda + 1/mu = 0.113
// (Taubin suggests 0.01 to 0.1): low frequencies (the shape) pass, the
// marching-cubes staircase is damped, and the volume barely shrinks.
// Droplets of a few vertices would shrink: see restore_small_components.
#pragma once

#include "mesh_check.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace nbmc {
namespace mesh {

constexpr double kTaubinLambda = 0.5;
constexpr double kTaubinMu = -0.53;

namespace detail {

// Sorted unique neighbours of every vertex (CSR).
inline void vertex_neighbours(const std::uint32_t* tri, std::size_t nt, std::size_t nv,
                              std::vector<std::uint32_t>& start, std::vector<std::uint32_t>& adj) {
  start.assign(nv + 1, 0);
  for (std::size_t i = 0; i < 3 * nt; ++i) start[tri[i] + 1] += 2;
  for (std::size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
  adj.resize(start[nv]);
  std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
  for (std::size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = tri[3 * t + k];
      adj[fill[v]++] = tri[3 * t + (k + 1) % 3];
      adj[fill[v]++] = tri[3 * t + (k + 2) % 3];
    }
  // Sort and deduplicate each list, then compact.
  std::size_t out = 0;
  std::uint32_t begin = 0;
  for (std::size_t v = 0; v < nv; ++v) {
    const std::uint32_t end = start[v + 1];
    std::sort(adj.begin() + begin, adj.begin() + end);
    const std::size_t first = out;
    for (std::uint32_t i = begin; i < end; ++i)
      if (adj[i] != v && (out == first || adj[out - 1] != adj[i])) adj[out++] = adj[i];
    start[v] = std::uint32_t(first);
    begin = end;
  }
  start[nv] = std::uint32_t(out);
  adj.resize(out);
}

}  // namespace detail

// Area-weighted vertex normals from the faces (counter-clockwise triangles
// give outward normals); a vertex without area keeps (0, 0, 0).
template <class Real>  // float or double positions
inline void face_normals_to_vertices(const Real* positions, std::size_t nv, const std::uint32_t* tri,
                                     std::size_t nt, float* normals) {
  std::vector<double> acc(3 * nv, 0.0);
  for (std::size_t t = 0; t < nt; ++t) {
    const std::uint32_t* v = tri + 3 * t;
    const Vec3 a = load(positions, v[0]), b = load(positions, v[1]), c = load(positions, v[2]);
    const Vec3 n = cross(b - a, c - a);  // length: twice the area
    for (int k = 0; k < 3; ++k) {
      acc[3 * std::size_t(v[k])] += n.x;
      acc[3 * std::size_t(v[k]) + 1] += n.y;
      acc[3 * std::size_t(v[k]) + 2] += n.z;
    }
  }
  for (std::size_t v = 0; v < nv; ++v) {
    const double l = std::sqrt(acc[3 * v] * acc[3 * v] + acc[3 * v + 1] * acc[3 * v + 1] + acc[3 * v + 2] * acc[3 * v + 2]);
    for (int a = 0; a < 3; ++a) normals[3 * v + a] = l > 0 ? float(acc[3 * v + a] / l) : 0.0f;
  }
}

// Taubin's analysis holds for shapes much larger than an edge; a droplet of
// a few vertices is all "high frequency" and shrinks by about half per
// iteration (a tetrahedron by 0.57). Components whose enclosed volume
// changed by more than this fraction are scaled about their centroid back to
// their volume (a component turned inside out gets its old positions back);
// the others, the bulk of a fluid, are left as smoothed.
constexpr double kSmoothRestoreVolume = 0.01;

// x: smoothed positions (double), before: the positions before smoothing.
template <class Real>
inline void restore_small_components(const Real* before, std::vector<double>& x, const std::uint32_t* tri,
                                     std::size_t nt, std::size_t nv) {
  detail::UnionFind uf(nv);
  for (std::size_t t = 0; t < nt; ++t) {
    uf.unite(tri[3 * t], tri[3 * t + 1]);
    uf.unite(tri[3 * t], tri[3 * t + 2]);
  }
  std::vector<std::uint32_t> root(nv);
  std::vector<double> count(nv, 0), c_old(3 * nv, 0), c_new(3 * nv, 0), v_old(nv, 0), v_new(nv, 0);
  for (std::size_t v = 0; v < nv; ++v) {
    const std::uint32_t r = root[v] = uf.find(std::uint32_t(v));
    count[r] += 1;
    for (int a = 0; a < 3; ++a) {
      c_old[3 * r + a] += before[3 * v + a];
      c_new[3 * r + a] += x[3 * v + a];
    }
  }
  for (std::size_t v = 0; v < nv; ++v)
    if (count[v] > 0)
      for (int a = 0; a < 3; ++a) {
        c_old[3 * v + a] /= count[v];
        c_new[3 * v + a] /= count[v];
      }
  auto at = [](const std::vector<double>& c, std::uint32_t r) { return Vec3{c[3 * r], c[3 * r + 1], c[3 * r + 2]}; };
  auto xs = [&](std::uint32_t v) { return Vec3{x[3 * v], x[3 * v + 1], x[3 * v + 2]}; };
  for (std::size_t t = 0; t < nt; ++t) {
    const std::uint32_t* i = tri + 3 * t;
    const std::uint32_t r = root[i[0]];
    const Vec3 co = at(c_old, r), cn = at(c_new, r);
    v_old[r] += dot(load(before, i[0]) - co, cross(load(before, i[1]) - co, load(before, i[2]) - co)) / 6;
    v_new[r] += dot(xs(i[0]) - cn, cross(xs(i[1]) - cn, xs(i[2]) - cn)) / 6;
  }
  for (std::size_t v = 0; v < nv; ++v) {
    const std::uint32_t r = root[v];
    if (!(v_old[r] > 0) || std::fabs(v_new[r] / v_old[r] - 1) <= kSmoothRestoreVolume) continue;
    if (!(v_new[r] > 0)) {
      for (int a = 0; a < 3; ++a) x[3 * v + a] = before[3 * v + a];
      continue;
    }
    const double s = std::cbrt(v_old[r] / v_new[r]);
    for (int a = 0; a < 3; ++a) x[3 * v + a] = c_new[3 * r + a] + s * (x[3 * v + a] - c_new[3 * r + a]);
  }
}

struct SmoothResult {
  double volume_before = 0, volume_after = 0;  // enclosed volumes (see check_mesh)
};

// Smooths positions in place (iterations of lambda|mu, in double, rounded to
// the positions' scalar: float, or double with nbmc_params.double_positions);
// recomputes normals (float) from the faces when normals is not empty.
template <class PosVec, class NormalVec, class IndexVec>
SmoothResult smooth_mesh(PosVec& positions, NormalVec& normals, const IndexVec& triangles, int iterations,
                         double lambda = kTaubinLambda, double mu = kTaubinMu) {
  SmoothResult r;
  const std::size_t nv = positions.size() / 3, nt = triangles.size() / 3;
  auto volume = [&]() {
    Vec3 c;
    bounding_extent(positions.data(), nv, &c);
    double v = 0;
    for (std::size_t t = 0; t < nt; ++t) {
      const std::uint32_t* i = triangles.data() + 3 * t;
      v += dot(load(positions.data(), i[0]) - c, cross(load(positions.data(), i[1]) - c, load(positions.data(), i[2]) - c)) / 6;
    }
    return v;
  };
  r.volume_before = volume();
  if (iterations > 0 && nt > 0) {
    std::vector<std::uint32_t> start, adj;
    detail::vertex_neighbours(triangles.data(), nt, nv, start, adj);
    std::vector<double> x(positions.begin(), positions.end()), y(x.size());
    auto step = [&](double f) {
      for (std::size_t v = 0; v < nv; ++v) {
        const std::uint32_t b = start[v], e = start[v + 1];
        for (int a = 0; a < 3; ++a) {
          double s = 0;
          for (std::uint32_t i = b; i < e; ++i) s += x[3 * std::size_t(adj[i]) + a];
          y[3 * v + a] = e > b ? x[3 * v + a] + f * (s / (e - b) - x[3 * v + a]) : x[3 * v + a];
        }
      }
      x.swap(y);
    };
    for (int it = 0; it < iterations; ++it) {
      step(lambda);
      step(mu);
    }
    restore_small_components(positions.data(), x, triangles.data(), nt, nv);
    using Real = typename PosVec::value_type;
    for (std::size_t i = 0; i < x.size(); ++i) positions[i] = Real(x[i]);
  }
  r.volume_after = volume();
  if (!normals.empty() && normals.size() == positions.size())
    face_normals_to_vertices(positions.data(), nv, triangles.data(), nt, normals.data());
  return r;
}

}  // namespace mesh
}  // namespace nbmc
