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
//
// Feature weights (nbmc_params.smooth_weighting = NBMC_SMOOTH_FEATURE; after
// Loeschner, Boettcher, Jeske, Bender, "Weighted Laplacian smoothing for
// surface reconstruction of particle-based fluids", VMV 2023): both steps of
// vertex i are scaled by a weight w_i in [0, 1] from the particles near it,
//   n_i = sum_j max(0, 1 - |x_i - x_j|^2 / R^2)   (R: the influence radius),
//   w_i = s(clamp((n_i / n_bulk - 0.15) / 0.2, 0, 1)),  s(x) = 3x^2 - 2x^3,
// with n_bulk = (8/15) pi (R / r)^3 the sum for a point inside a lattice of
// spacing r. On a flat surface of a lattice, n / n_bulk is 0.4 to 0.5 (w = 1:
// smoothed fully); beside a sheet one particle thick about 0.22 (w = 0.25),
// a filament of single particles 0.05 and a lone particle 0.01 (w = 0): thin
// features, which uniform smoothing erodes, stay. The weights are taken once,
// at the positions before smoothing.
#pragma once

#include "mesh_check.hpp"
#include "parallel.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <utility>
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

// Feature weight ramp: n / n_bulk from kFeatureLow (weight 0) to
// kFeatureLow + kFeatureWidth (weight 1).
constexpr double kFeatureLow = 0.15;
constexpr double kFeatureWidth = 0.2;

// The weighted particle count n / n_bulk at each vertex (see above): xyz, n
// particles (3 doubles each), radius R > 0, spacing r > 0. Each vertex's sum
// runs over the particles in a fixed order (cells, then particle index), on
// several host threads: the result depends only on the input.
template <class Real>
std::vector<double> particle_density_ratio(const Real* positions, std::size_t nv, const double* xyz, std::size_t n,
                                           double radius, double spacing) {
  std::vector<double> out(nv, 0.0);
  if (nv == 0 || n == 0) return out;
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) lo[a] = hi[a] = xyz[a];
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz[3 * i + a]);
      hi[a] = std::max(hi[a], xyz[3 * i + a]);
    }
  // Cells of edge >= R (21 bits per axis; larger cells for huge extents).
  double cell = radius;
  for (int a = 0; a < 3; ++a) cell = std::max(cell, (hi[a] - lo[a]) / double((1 << 20) - 4));
  auto index = [&](double x, int a) -> std::int64_t {
    const double c = std::floor((x - lo[a]) / cell);
    // Particles lie in [0, 2^20 - 4]; a vertex beyond (-1 or 2^20) has no
    // particle within R past that side.
    return std::int64_t(std::min(std::max(c, -1.0), double(1 << 20)));
  };
  auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) {
    return std::uint64_t(x + 1) | (std::uint64_t(y + 1) << 21) | (std::uint64_t(z + 1) << 42);
  };
  std::vector<std::pair<std::uint64_t, std::uint32_t>> items(n);
  for (std::size_t i = 0; i < n; ++i)
    items[i] = {key(index(xyz[3 * i], 0), index(xyz[3 * i + 1], 1), index(xyz[3 * i + 2], 2)), std::uint32_t(i)};
  std::sort(items.begin(), items.end());
  std::unordered_map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> cells;
  cells.reserve(n / 2 + 1);
  for (std::size_t b = 0; b < n;) {
    std::size_t e = b + 1;
    while (e < n && items[e].first == items[b].first) ++e;
    cells.emplace(items[b].first, std::make_pair(std::uint32_t(b), std::uint32_t(e)));
    b = e;
  }
  const double r2 = radius * radius;
  const double pi = 3.14159265358979323846;
  const double bulk = 8.0 / 15.0 * pi * std::pow(radius / spacing, 3);
  for_chunks(nv, chunk_count(nv, 4096), [&](std::size_t, std::size_t vb, std::size_t ve) {
    for (std::size_t v = vb; v < ve; ++v) {
      const double x[3] = {double(positions[3 * v]), double(positions[3 * v + 1]), double(positions[3 * v + 2])};
      const std::int64_t c[3] = {index(x[0], 0), index(x[1], 1), index(x[2], 2)};
      double sum = 0;
      for (std::int64_t dz = -1; dz <= 1; ++dz)
        for (std::int64_t dy = -1; dy <= 1; ++dy)
          for (std::int64_t dx = -1; dx <= 1; ++dx) {
            const std::int64_t X = c[0] + dx, Y = c[1] + dy, Z = c[2] + dz;
            if (X < -1 || Y < -1 || Z < -1) continue;
            const auto it = cells.find(key(X, Y, Z));
            if (it == cells.end()) continue;
            for (std::uint32_t q = it->second.first; q < it->second.second; ++q) {
              const double* p = xyz + 3 * std::size_t(items[q].second);
              const double d2 = ((x[0] - p[0]) * (x[0] - p[0]) + (x[1] - p[1]) * (x[1] - p[1]) +
                                 (x[2] - p[2]) * (x[2] - p[2])) / r2;
              if (d2 < 1) sum += 1 - d2;
            }
          }
      out[v] = sum / bulk;
    }
  });
  return out;
}

// The smoothing weight of a vertex from its particle_density_ratio.
inline double feature_weight(double ratio) {
  const double t = std::min(1.0, std::max(0.0, (ratio - kFeatureLow) / kFeatureWidth));
  return t * t * (3 - 2 * t);
}

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
// weights: one per vertex in [0, 1] scaling both steps (feature weights), or
// null for 1 everywhere.
template <class PosVec, class NormalVec, class IndexVec>
SmoothResult smooth_mesh(PosVec& positions, NormalVec& normals, const IndexVec& triangles, int iterations,
                         double lambda = kTaubinLambda, double mu = kTaubinMu,
                         const std::vector<double>* weights = nullptr) {
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
          const double fv = weights ? f * (*weights)[v] : f;
          y[3 * v + a] = e > b ? x[3 * v + a] + fv * (s / (e - b) - x[3 * v + a]) : x[3 * v + a];
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
