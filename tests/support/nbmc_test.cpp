// SPDX-License-Identifier: MIT
#include "nbmc_test.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>
#include <unordered_map>

namespace nbmc_test {

Points lattice(const double lo[3], const double hi[3], double r,
               const std::function<bool(double, double, double)>& inside) {
  Points p;
  const long n[3] = {long(std::floor((hi[0] - lo[0]) / r)) + 1, long(std::floor((hi[1] - lo[1]) / r)) + 1,
                     long(std::floor((hi[2] - lo[2]) / r)) + 1};
  for (long k = 0; k < n[2]; ++k)
    for (long j = 0; j < n[1]; ++j)
      for (long i = 0; i < n[0]; ++i) {
        const double x = lo[0] + i * r, y = lo[1] + j * r, z = lo[2] + k * r;
        if (inside(x, y, z)) {
          p.push_back(x);
          p.push_back(y);
          p.push_back(z);
        }
      }
  return p;
}

Points sphere(double cx, double cy, double cz, double radius, double r) {
  const double lo[3] = {cx - radius - r, cy - radius - r, cz - radius - r};
  const double hi[3] = {cx + radius + r, cy + radius + r, cz + radius + r};
  // Lattice aligned with the centre so the shape is symmetric.
  const double lo2[3] = {cx - r * std::ceil((radius + r) / r), cy - r * std::ceil((radius + r) / r),
                         cz - r * std::ceil((radius + r) / r)};
  (void)lo;
  return lattice(lo2, hi, r, [&](double x, double y, double z) {
    return (x - cx) * (x - cx) + (y - cy) * (y - cy) + (z - cz) * (z - cz) <= radius * radius * (1 + 1e-9);
  });
}

Points box(const double lo[3], const double hi[3], double r) {
  const double h[3] = {hi[0] + 1e-9, hi[1] + 1e-9, hi[2] + 1e-9};
  return lattice(lo, h, r, [](double, double, double) { return true; });
}

Points torus(double R, double a, double r) {
  const double lo[3] = {-R - a - r, -R - a - r, -a - r};
  const double hi[3] = {R + a + r, R + a + r, a + r};
  const double lo2[3] = {-r * std::ceil((R + a + r) / r), -r * std::ceil((R + a + r) / r), -r * std::ceil((a + r) / r)};
  (void)lo;
  return lattice(lo2, hi, r, [&](double x, double y, double z) {
    const double q = std::sqrt(x * x + y * y) - R;
    return q * q + z * z <= a * a;
  });
}

Points concat(const Points& a, const Points& b) {
  Points c = a;
  c.insert(c.end(), b.begin(), b.end());
  return c;
}

Points read_xyz(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<float> v;
  if (!f) return {};
  f.seekg(0, std::ios::end);
  const std::size_t bytes = std::size_t(f.tellg());
  f.seekg(0);
  v.resize(bytes / sizeof(float));
  f.read(reinterpret_cast<char*>(v.data()), std::streamsize(v.size() * sizeof(float)));
  return Points(v.begin(), v.end());
}

nbmc_params params(double spacing) {
  nbmc_params p;
  nbmc_params_init(&p);
  p.spacing = spacing;
  return p;
}

Result reconstruct(const Points& pts, const nbmc_params& prm, int32_t backend, int threads) {
  Result run;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = backend;
  d.num_threads = threads;
  nbmc_context* ctx = nullptr;
  run.status = nbmc_context_create(&d, &ctx);
  if (run.status != NBMC_OK) {
    run.message = nbmc_context_last_error(nullptr);
    return run;
  }
  run.status = nbmc_context_set_particles_f64(ctx, pts.data(), pts.size() / 3, 0);
  nbmc_mesh* mesh = nullptr;
  if (run.status == NBMC_OK) run.status = nbmc_context_reconstruct(ctx, &prm, &mesh);
  run.message = nbmc_context_last_error(ctx);
  if (run.status == NBMC_OK) {
    const std::size_t nv = nbmc_mesh_vertex_count(mesh), nt = nbmc_mesh_triangle_count(mesh);
    const float* p = nbmc_mesh_positions(mesh);
    const float* n = nbmc_mesh_normals(mesh);
    const std::uint32_t* t = nbmc_mesh_triangles(mesh);
    if (p) run.mesh.positions.assign(p, p + 3 * nv);
    if (n) run.mesh.normals.assign(n, n + 3 * nv);
    if (t) run.mesh.triangles.assign(t, t + 3 * nt);
    nbmc_stats_init(&run.stats);
    nbmc_context_stats(ctx, &run.stats);
  }
  nbmc_mesh_destroy(mesh);
  nbmc_context_destroy(ctx);
  return run;
}

namespace {
struct DSU {
  std::vector<std::size_t> p;
  explicit DSU(std::size_t n) : p(n) { std::iota(p.begin(), p.end(), 0); }
  std::size_t find(std::size_t x) {
    while (p[x] != x) x = p[x] = p[p[x]];
    return x;
  }
  void unite(std::size_t a, std::size_t b) { p[find(a)] = find(b); }
};
}  // namespace

MeshReport check_mesh(const Mesh& m) {
  MeshReport r;
  const std::size_t nt = m.triangle_count(), nv = m.vertex_count();
  // directed edge counts
  std::unordered_map<std::uint64_t, std::vector<std::size_t>> edges;  // undirected key -> triangles
  std::unordered_map<std::uint64_t, int> directed;
  edges.reserve(nt * 2);
  directed.reserve(nt * 4);
  std::vector<char> used(nv, 0);
  auto key = [](std::uint64_t a, std::uint64_t b) { return (a << 32) | b; };
  for (std::size_t t = 0; t < nt; ++t) {
    const std::uint32_t v[3] = {m.triangles[3 * t], m.triangles[3 * t + 1], m.triangles[3 * t + 2]};
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) ++r.degenerate_triangles;
    for (int e = 0; e < 3; ++e) {
      const std::uint32_t a = v[e], b = v[(e + 1) % 3];
      if (a < nv) used[a] = 1;
      edges[key(std::min(a, b), std::max(a, b))].push_back(t);
      directed[key(a, b)]++;
    }
  }
  for (std::size_t i = 0; i < nv; ++i)
    if (!used[i]) ++r.unreferenced_vertices;
  for (const auto& [k, tris] : edges) {
    if (tris.size() == 1) ++r.boundary_edges;
    if (tris.size() > 2) ++r.nonmanifold_edges;
    if (tris.size() == 2) {
      const std::uint64_t a = k >> 32, b = k & 0xffffffffu;
      if (directed[key(a, b)] != 1 || directed[key(b, a)] != 1) ++r.misoriented_edges;
    }
  }
  // Vertex manifoldness: triangles around a vertex connected through shared edges form one fan.
  std::vector<std::vector<std::size_t>> vt(nv);
  for (std::size_t t = 0; t < nt; ++t)
    for (int e = 0; e < 3; ++e)
      if (m.triangles[3 * t + e] < nv) vt[m.triangles[3 * t + e]].push_back(t);
  for (std::size_t v = 0; v < nv; ++v) {
    const auto& ts = vt[v];
    if (ts.size() < 2) continue;
    DSU d(ts.size());
    for (std::size_t a = 0; a < ts.size(); ++a)
      for (std::size_t b = a + 1; b < ts.size(); ++b) {
        int shared = 0;
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            if (m.triangles[3 * ts[a] + i] == m.triangles[3 * ts[b] + j]) ++shared;
        if (shared >= 2) d.unite(a, b);
      }
    std::size_t roots = 0;
    for (std::size_t a = 0; a < ts.size(); ++a)
      if (d.find(a) == a) ++roots;
    if (roots != 1) ++r.nonmanifold_vertices;
  }
  DSU comp(nt ? nt : 1);
  for (const auto& [k, tris] : edges)
    for (std::size_t i = 1; i < tris.size(); ++i) comp.unite(tris[0], tris[i]);
  for (std::size_t t = 0; t < nt; ++t)
    if (comp.find(t) == t) ++r.components;
  for (std::size_t t = 0; t < nt; ++t) {
    const float* a = &m.positions[3 * std::size_t(m.triangles[3 * t])];
    const float* b = &m.positions[3 * std::size_t(m.triangles[3 * t + 1])];
    const float* c = &m.positions[3 * std::size_t(m.triangles[3 * t + 2])];
    const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
    const double w[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    r.area += 0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    r.volume += (double(a[0]) * n[0] + double(a[1]) * n[1] + double(a[2]) * n[2]) / 6.0;
  }
  r.closed = r.boundary_edges == 0 && r.nonmanifold_edges == 0;
  r.edge_manifold = r.nonmanifold_edges == 0;
  r.vertex_manifold = r.nonmanifold_vertices == 0;
  r.oriented = r.misoriented_edges == 0;
  return r;
}

std::string MeshReport::summary() const {
  std::ostringstream s;
  s << "boundary_edges=" << boundary_edges << " nonmanifold_edges=" << nonmanifold_edges
    << " misoriented_edges=" << misoriented_edges << " nonmanifold_vertices=" << nonmanifold_vertices
    << " degenerate=" << degenerate_triangles << " unreferenced=" << unreferenced_vertices
    << " components=" << components << " volume=" << volume << " area=" << area;
  return s.str();
}

std::set<Tri> triangle_set(const Mesh& m) {
  std::set<Tri> s;
  for (std::size_t t = 0; t < m.triangle_count(); ++t) {
    std::array<std::array<float, 3>, 3> v;
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) v[c][a] = m.positions[3 * m.triangles[3 * t + c] + a];
    const int first = int(std::min_element(v.begin(), v.end()) - v.begin());
    Tri key;
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) key[3 * c + a] = v[(first + c) % 3][a];
    s.insert(key);
  }
  return s;
}

}  // namespace nbmc_test
