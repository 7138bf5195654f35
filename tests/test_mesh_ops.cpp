// SPDX-License-Identifier: MIT
// Mesh operations of nbmc_context_reconstruct through the C API (issue #11):
// decimation (nbmc_params.decimate_fraction) keeps reconstructed meshes
// closed, manifold and oriented, near the surface, the same on every thread
// count and subdomain split, with attributes on the final vertices;
// feature-weighted smoothing (NBMC_SMOOTH_FEATURE) keeps a lattice sphere's
// radius and erodes a thin filament less than uniform smoothing;
// NBMC_ISOLATED_SPHERE returns the dropped particles as spheres.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

using namespace nbmc_test;

namespace {

struct Outcome {
  int32_t status = -1;
  std::string message;
  Mesh mesh;
  nbmc_stats stats{};
  std::vector<float> spheres;
  std::vector<std::string> attribute_names;
  std::vector<std::vector<float>> attributes;
};

// A fresh OpenMP context (threads), optional subdomains and attribute "x"
// (each particle's x coordinate).
Outcome run(const Points& p, const nbmc_params& prm, int threads = 2, int split = 1, bool attribute = false) {
  Outcome r;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_OPENMP;
  d.num_threads = threads;
  nbmc_context* ctx = nullptr;
  if (nbmc_context_create(&d, &ctx) != NBMC_OK) return r;
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  if (split > 1) EXPECT_EQ(nbmc_context_set_subdomains(ctx, split, 1, 1), NBMC_OK);
  if (attribute) EXPECT_EQ(nbmc_context_set_attribute_f64(ctx, "x", p.data(), 1, 3 * sizeof(double)), NBMC_OK);
  nbmc_mesh* m = nullptr;
  r.status = nbmc_context_reconstruct(ctx, &prm, &m);
  r.message = nbmc_context_last_error(ctx);
  if (r.status == NBMC_OK) {
    nbmc_stats_init(&r.stats);
    EXPECT_EQ(nbmc_context_stats(ctx, &r.stats), NBMC_OK);
    const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
    r.mesh.positions.resize(3 * nv);
    r.mesh.normals.resize(nbmc_mesh_normals(m) ? 3 * nv : 0);
    r.mesh.triangles.resize(3 * nt);
    nbmc_mesh_copy_to_host(m, r.mesh.positions.data(), r.mesh.normals.empty() ? nullptr : r.mesh.normals.data(),
                           r.mesh.triangles.data());
    const float* s = nbmc_mesh_spheres(m);
    if (s) r.spheres.assign(s, s + 4 * nbmc_mesh_sphere_count(m));
    for (uint32_t i = 0; i < nbmc_mesh_attribute_count(m); ++i) {
      r.attribute_names.push_back(nbmc_mesh_attribute_name(m, i));
      uint32_t comps = 0;
      const float* a = nbmc_mesh_attribute(m, r.attribute_names.back().c_str(), &comps);
      r.attributes.emplace_back(a, a + comps * nv);
    }
  }
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
  return r;
}

nbmc_mesh_check_result check(const Mesh& m) {
  // The tests' own checker (independent of the library's), its figures in
  // nbmc_mesh_check_result's fields.
  nbmc_mesh_check_result r;
  nbmc_mesh_check_result_init(&r);
  const MeshReport c = check_mesh(m);
  r.closed = c.closed;
  r.manifold = c.edge_manifold && c.vertex_manifold;
  r.oriented = c.oriented;
  r.triangle_count = m.triangle_count();
  r.degenerate_triangle_count = c.degenerate_triangles;
  r.component_count = c.components;
  r.volume = c.volume;
  return r;
}

double distance(const float* p, const double c[3]) {
  return std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) + (p[2] - c[2]) * (p[2] - c[2]));
}

// A frame-like input: a pool (box), a drop falling into it, a jittered blob
// touching the pool, and a few splashes.
Points frame_like(double r) {
  const double lo[3] = {0, 0, 0}, hi[3] = {30 * r, 20 * r, 6 * r};
  Points p = box(lo, hi, r);
  p = concat(p, sphere(15 * r, 10 * r, 16 * r, 4 * r, r));
  Points blob = sphere(6 * r, 6 * r, 9 * r, 4.5 * r, r);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-0.2 * r, 0.2 * r);
  for (double& x : blob) x += u(rng);
  p = concat(p, blob);
  p.insert(p.end(), {25 * r, 15 * r, 14 * r, 25.6 * r, 15 * r, 14 * r, 5 * r, 15 * r, 20 * r});
  return p;
}

}  // namespace

TEST(MeshDecimateCapi, DefaultsAndErrors) {
  nbmc_params prm = params(1);
  EXPECT_EQ(prm.decimate_fraction, 1.0);
  EXPECT_EQ(prm.smooth_weighting, NBMC_SMOOTH_UNIFORM);
  const Points p = sphere(0, 0, 0, 4, 1);
  for (double f : {0.0, -0.5, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    prm.decimate_fraction = f;
    const Outcome r = run(p, prm);
    EXPECT_EQ(r.status, NBMC_ERROR_INVALID_PARAMETER) << f;
    EXPECT_NE(r.message.find("decimate_fraction"), std::string::npos) << r.message;
  }
  prm = params(1);
  prm.smooth_weighting = 2;
  EXPECT_EQ(run(p, prm).status, NBMC_ERROR_INVALID_PARAMETER);
  prm = params(1);
  prm.isolated = 3;
  EXPECT_EQ(run(p, prm).status, NBMC_ERROR_INVALID_PARAMETER);
  // An older caller's struct (up to double_positions) keeps the defaults.
  prm = params(1);
  prm.decimate_fraction = 0.25;
  prm.smooth_weighting = 9;  // beyond the caller's struct: ignored
  prm.struct_size = uint32_t(offsetof(nbmc_params, decimate_fraction));
  const Outcome old = run(p, prm);
  ASSERT_EQ(old.status, NBMC_OK) << old.message;
  EXPECT_EQ(old.stats.pre_decimation_triangle_count, old.stats.triangle_count);
}

// A lattice sphere and a frame-like scene decimated to a quarter and a tenth:
// closed, manifold, oriented, the counts met, the sphere's vertices near
// its surface, and the same mesh on 1, 2 and 4 threads and split in two.
TEST(MeshDecimateCapi, ClosedNearAndDeterministic) {
  const double radius = 8;
  const Points ball = sphere(0, 0, 0, radius, 1);
  nbmc_params prm = params(1);
  const Outcome raw = run(ball, prm);
  ASSERT_EQ(raw.status, NBMC_OK) << raw.message;
  const double centre[3] = {0, 0, 0};
  double lo = 1e30, hi = 0;
  for (std::size_t v = 0; v < raw.mesh.vertex_count(); ++v) {
    const double d = distance(&raw.mesh.positions[3 * v], centre);
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  for (double f : {0.25, 0.1}) {
    prm.decimate_fraction = f;
    const Outcome r = run(ball, prm);
    ASSERT_EQ(r.status, NBMC_OK) << r.message;
    const nbmc_mesh_check_result c = check(r.mesh);
    EXPECT_TRUE(c.closed && c.manifold && c.oriented) << f;
    EXPECT_EQ(c.component_count, 1u);
    EXPECT_EQ(r.stats.pre_decimation_triangle_count, raw.stats.triangle_count);
    EXPECT_EQ(r.stats.triangle_count, r.mesh.triangle_count());
    EXPECT_LE(double(r.stats.triangle_count), std::ceil(f * double(raw.stats.triangle_count)));
    EXPECT_GE(double(r.stats.triangle_count), 0.9 * f * double(raw.stats.triangle_count));
    // Every vertex within 0.1 r of the raw mesh's radial range.
    for (std::size_t v = 0; v < r.mesh.vertex_count(); ++v) {
      const double d = distance(&r.mesh.positions[3 * v], centre);
      ASSERT_GT(d, lo - 0.1) << f;
      ASSERT_LT(d, hi + 0.1) << f;
    }
    EXPECT_NEAR(c.volume, check(raw.mesh).volume, 0.01 * check(raw.mesh).volume) << f;
    ASSERT_EQ(r.mesh.normals.size(), r.mesh.positions.size());
    for (std::size_t v = 0; v < r.mesh.vertex_count(); ++v) {
      const float* n = &r.mesh.normals[3 * v];
      const float* x = &r.mesh.positions[3 * v];
      ASSERT_GT((n[0] * x[0] + n[1] * x[1] + n[2] * x[2]) / distance(x, centre), 0.9);
    }
  }
  const Points scene = frame_like(1);
  prm = params(1);
  prm.smooth_iterations = 5;
  for (double f : {0.25, 0.1}) {
    prm.decimate_fraction = f;
    const Outcome ref = run(scene, prm, 1);
    ASSERT_EQ(ref.status, NBMC_OK) << ref.message;
    const nbmc_mesh_check_result c = check(ref.mesh);
    EXPECT_TRUE(c.closed && c.manifold && c.oriented) << f;
    EXPECT_EQ(c.degenerate_triangle_count, 0u);
    EXPECT_LE(double(ref.stats.triangle_count), std::ceil(f * double(ref.stats.pre_decimation_triangle_count)));
    for (int threads : {2, 4}) {
      const Outcome r = run(scene, prm, threads);
      EXPECT_EQ(r.mesh.positions, ref.mesh.positions) << threads;
      EXPECT_EQ(r.mesh.triangles, ref.mesh.triangles) << threads;
      EXPECT_EQ(r.mesh.normals, ref.mesh.normals) << threads;
    }
    const Outcome s = run(scene, prm, 2, 2);
    EXPECT_EQ(s.mesh.positions, ref.mesh.positions) << "subdomains";
    EXPECT_EQ(s.mesh.triangles, ref.mesh.triangles) << "subdomains";
  }
}

// Attributes are interpolated onto the decimated mesh's vertices.
TEST(MeshDecimateCapi, AttributesOnTheFinalVertices) {
  const Points ball = sphere(0, 0, 0, 6, 1);
  nbmc_params prm = params(1);
  prm.decimate_fraction = 0.2;
  const Outcome r = run(ball, prm, 2, 1, true);
  ASSERT_EQ(r.status, NBMC_OK) << r.message;
  ASSERT_EQ(r.attribute_names.size(), 1u);
  ASSERT_EQ(r.attributes[0].size(), r.mesh.vertex_count());
  // x interpolated from the particles within R = 4 of each vertex: within R.
  for (std::size_t v = 0; v < r.mesh.vertex_count(); ++v)
    ASSERT_NEAR(r.attributes[0][v], r.mesh.positions[3 * v], 4.0);
}

// Feature-weighted smoothing keeps a lattice sphere's radius within 0.1 r
// (its vertices all have the bulk's weight), and a filament of single
// particles sticking out of a ball keeps its thickness better than with
// uniform weights, which erode it.
TEST(MeshSmoothCapi, FeatureWeights) {
  const double radius = 8;
  const Points ball = sphere(0, 0, 0, radius, 1);
  nbmc_params prm = params(1);
  const Outcome raw = run(ball, prm);
  prm.smooth_iterations = 10;
  prm.smooth_weighting = NBMC_SMOOTH_FEATURE;
  const Outcome f = run(ball, prm);
  ASSERT_EQ(f.status, NBMC_OK) << f.message;
  const double centre[3] = {0, 0, 0};
  auto mean_radius = [&](const Mesh& m) {
    double s = 0;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) s += distance(&m.positions[3 * v], centre);
    return s / double(m.vertex_count());
  };
  EXPECT_NEAR(mean_radius(f.mesh), mean_radius(raw.mesh), 0.1);
  // ... and is smoothed as with uniform weights (its vertices have the
  // bulk's weight).
  prm.smooth_weighting = NBMC_SMOOTH_UNIFORM;
  const Outcome u = run(ball, prm);
  auto spread = [&](const Mesh& m) {
    const double mean = mean_radius(m);
    double s = 0;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
      const double d = distance(&m.positions[3 * v], centre) - mean;
      s += d * d;
    }
    return std::sqrt(s / double(m.vertex_count()));
  };
  std::printf("sphere radius spread: raw %.4f, uniform %.4f, feature %.4f\n", spread(raw.mesh), spread(u.mesh),
              spread(f.mesh));
  EXPECT_LT(spread(f.mesh), 1.05 * spread(u.mesh));
  EXPECT_NEAR(mean_radius(f.mesh), mean_radius(u.mesh), 0.02);
  EXPECT_NE(f.mesh.positions, raw.mesh.positions);
  EXPECT_TRUE(check(f.mesh).closed && check(f.mesh).oriented);
  EXPECT_LT(std::fabs(f.stats.smoothing_volume_change), 0.01);

  // The filament: particles 1 r apart on the x axis from the ball's surface
  // to 10 r beyond it.
  Points p = sphere(0, 0, 0, 5, 1);
  for (int i = 6; i <= 16; ++i) p.insert(p.end(), {double(i), 0.0, 0.0});
  prm = params(1);
  const Outcome base = run(p, prm);
  prm.smooth_iterations = 40;
  prm.smooth_weighting = NBMC_SMOOTH_UNIFORM;
  const Outcome uni = run(p, prm);
  prm.smooth_weighting = NBMC_SMOOTH_FEATURE;
  const Outcome feat = run(p, prm);
  ASSERT_EQ(uni.status, NBMC_OK);
  ASSERT_EQ(feat.status, NBMC_OK);
  // Mean distance from the x axis of the vertices along the filament's middle.
  auto thickness = [](const Mesh& m) {
    double s = 0;
    int n = 0;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) {
      const float* x = &m.positions[3 * v];
      if (x[0] < 8 || x[0] > 14) continue;
      s += std::sqrt(double(x[1]) * x[1] + double(x[2]) * x[2]);
      ++n;
    }
    return n ? s / n : 0.0;
  };
  auto tip = [](const Mesh& m) {
    double t = 0;
    for (std::size_t v = 0; v < m.vertex_count(); ++v) t = std::max(t, double(m.positions[3 * v]));
    return t;
  };
  const double t0 = thickness(base.mesh), tu = thickness(uni.mesh), tf = thickness(feat.mesh);
  const double x0 = tip(base.mesh), xu = tip(uni.mesh), xf = tip(feat.mesh);
  std::printf("filament: tip raw %.3f, uniform %.3f, feature %.3f; thickness raw %.3f, uniform %.3f, feature %.3f\n",
              x0, xu, xf, t0, tu, tf);
  ASSERT_GT(t0, 0.3);
  EXPECT_GT(x0 - xu, 0.1);                    // uniform smoothing pulls the tip back
  EXPECT_LT(std::fabs(x0 - xf), 0.25 * (x0 - xu));  // feature weights keep it
  EXPECT_LT(std::fabs(tf - t0), std::fabs(tu - t0) + 1e-3);
  EXPECT_TRUE(check(feat.mesh).closed && check(feat.mesh).oriented);
}

// NBMC_ISOLATED_SPHERE: the mesh is the one NBMC_ISOLATED_DROP makes, and
// the dropped particles come back as spheres of radius iso_radius (absolute),
// in the particles' order.
TEST(IsolatedSpheres, DroppedParticlesBecomeSpheres) {
  const double r = 0.05;
  const double lo[3] = {-0.4, -0.3, -0.2}, hi[3] = {0.4, 0.3, 0.1};
  Points p = box(lo, hi, r);
  const std::size_t body = p.size() / 3;
  p.insert(p.end(), {0.8, 0.5, 0.5, -0.8, 0.5, 0.5, -0.77, 0.5, 0.5});
  nbmc_params prm = params(r);
  prm.isolated = NBMC_ISOLATED_DROP;
  const Outcome drop = run(p, prm);
  ASSERT_EQ(drop.status, NBMC_OK) << drop.message;
  EXPECT_TRUE(drop.spheres.empty());
  prm.isolated = NBMC_ISOLATED_SPHERE;
  const Outcome s = run(p, prm);
  ASSERT_EQ(s.status, NBMC_OK) << s.message;
  EXPECT_EQ(s.mesh.triangles, drop.mesh.triangles);
  EXPECT_EQ(s.mesh.positions, drop.mesh.positions);
  EXPECT_EQ(s.stats.dropped_particle_count, 3u);
  EXPECT_EQ(s.stats.dropped_cluster_count, 2u);
  ASSERT_EQ(s.spheres.size(), 4u * 3);
  for (int i = 0; i < 3; ++i) {
    for (int a = 0; a < 3; ++a) EXPECT_EQ(s.spheres[4 * i + a], float(p[3 * (body + i) + a]));
    EXPECT_FLOAT_EQ(s.spheres[4 * i + 3], float(prm.iso_radius * r));
  }
  // SPH and YT10 (no iso_radius): half the spacing.
  for (const int method : {NBMC_METHOD_SPH, NBMC_METHOD_YT10}) {
    prm.method = method;
    const Outcome sph = run(p, prm);
    ASSERT_EQ(sph.status, NBMC_OK) << sph.message;
    ASSERT_EQ(sph.spheres.size(), 12u);
    EXPECT_FLOAT_EQ(sph.spheres[3], float(0.5 * r));
  }
  // Keep: none.
  prm = params(r);
  const Outcome keep = run(p, prm);
  EXPECT_TRUE(keep.spheres.empty());
  EXPECT_EQ(nbmc_mesh_sphere_count(nullptr), 0u);
  EXPECT_EQ(nbmc_mesh_spheres(nullptr), nullptr);
}

// Decimation of a mesh with double positions far from the origin: closed,
// manifold and oriented, the count met, the shape of the same frame at the
// origin (its bounding box within 0.05 r).
TEST(MeshDecimateCapi, DoublePositionsFarAway) {
  Points near = frame_like(1);
  Points far = near;
  for (std::size_t i = 0; i < far.size(); i += 3) far[i] += 5e6;
  nbmc_params prm = params(1);
  prm.decimate_fraction = 0.2;
  prm.double_positions = 1;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_OPENMP;
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  double lo[2][3], hi[2][3];
  int k = 0;
  for (const Points* p : {&near, &far}) {
    ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p->data(), p->size() / 3, 0), NBMC_OK);
    nbmc_mesh* m = nullptr;
    ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(ctx);
    nbmc_stats st;
    nbmc_stats_init(&st);
    ASSERT_EQ(nbmc_context_stats(ctx, &st), NBMC_OK);
    EXPECT_LE(double(st.triangle_count), std::ceil(0.2 * double(st.pre_decimation_triangle_count)));
    nbmc_mesh_check_result c;
    nbmc_mesh_check_result_init(&c);
    ASSERT_EQ(nbmc_mesh_check(m, &c), NBMC_OK);
    EXPECT_TRUE(c.closed && c.manifold && c.oriented) << k;
    EXPECT_EQ(c.degenerate_triangle_count, 0u) << k;
    const double* x = nbmc_mesh_positions_f64(m);
    ASSERT_NE(x, nullptr);
    for (int a = 0; a < 3; ++a) lo[k][a] = 1e300, hi[k][a] = -1e300;
    for (std::size_t v = 0; v < nbmc_mesh_vertex_count(m); ++v)
      for (int a = 0; a < 3; ++a) {
        const double y = x[3 * v + a] - (k == 1 && a == 0 ? 5e6 : 0.0);
        lo[k][a] = std::min(lo[k][a], y);
        hi[k][a] = std::max(hi[k][a], y);
      }
    nbmc_mesh_destroy(m);
    ++k;
  }
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(lo[1][a], lo[0][a], 0.05) << a;
    EXPECT_NEAR(hi[1][a], hi[0][a], 0.05) << a;
  }
  nbmc_context_destroy(ctx);
}
