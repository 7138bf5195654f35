// SPDX-License-Identifier: MIT
// Analytic shapes sampled as particle lattices (spacing r): the mesh must be
// closed, 2-manifold, consistently oriented outward, have one component per
// body and the right genus, and every vertex must lie within a stated band
// of the analytic surface through the outermost particle centres.
//
// Tolerances (measured, then stated): SSP07/ZB05 with R = 4r put the iso
// surface slightly inside the outer particle layer on convex parts (x-bar is
// pulled inward) and up to one spacing outside on flat and concave parts, so
// vertices must lie within [-0.75 r, +1.1 r] of the analytic surface; where
// two bodies touch, the field blends them (a fillet up to 1.25 r).
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>

using namespace nbmc_test;

namespace {

constexpr double r = 0.1;
using Sdf = std::function<double(double, double, double)>;

double box_sdf(double x, double y, double z, const double c[3], const double h[3]) {
  const double q[3] = {std::fabs(x - c[0]) - h[0], std::fabs(y - c[1]) - h[1], std::fabs(z - c[2]) - h[2]};
  double out = 0, in = -1e300;
  for (int a = 0; a < 3; ++a) {
    out += std::pow(std::max(q[a], 0.0), 2);
    in = std::max(in, q[a]);
  }
  return std::sqrt(out) + std::min(in, 0.0);
}

struct Expect {
  std::size_t components;
  int euler;  // V - E + F summed over components (2 per sphere-like body)
  double lo = -0.75, hi = 1.1;  // allowed signed distance of vertices, in r
};

void check_shape(const Points& pts, const Sdf& sdf, const Expect& e, double cell, int method = NBMC_METHOD_SSP07) {
  nbmc_params prm = params(r);
  prm.cell_size = cell;
  prm.method = method;
  const Result run = reconstruct(pts, prm);
  ASSERT_EQ(run.status, NBMC_OK) << run.message;
  ASSERT_GT(run.mesh.triangle_count(), 0u);
  const MeshReport rep = check_mesh(run.mesh);
  EXPECT_TRUE(rep.closed) << rep.summary();
  EXPECT_TRUE(rep.vertex_manifold) << rep.summary();
  EXPECT_TRUE(rep.oriented) << rep.summary();
  EXPECT_EQ(rep.degenerate_triangles, 0u) << rep.summary();
  EXPECT_EQ(rep.unreferenced_vertices, 0u) << rep.summary();
  EXPECT_EQ(rep.components, e.components) << rep.summary();
  EXPECT_GT(rep.volume, 0) << "inward-facing mesh: " << rep.summary();
  const long V = long(run.mesh.vertex_count()), F = long(run.mesh.triangle_count());
  EXPECT_EQ(V - 3 * F / 2 + F, e.euler);
  double mn = 1e300, mx = -1e300;
  for (std::size_t i = 0; i < run.mesh.vertex_count(); ++i) {
    const double d = sdf(run.mesh.positions[3 * i], run.mesh.positions[3 * i + 1], run.mesh.positions[3 * i + 2]);
    mn = std::min(mn, d);
    mx = std::max(mx, d);
  }
  EXPECT_GE(mn / r, e.lo);
  EXPECT_LE(mx / r, e.hi);
  // Normals: unit length and pointing the way the triangles face.
  ASSERT_EQ(run.mesh.normals.size(), run.mesh.positions.size());
  std::size_t agree = 0;
  for (std::size_t t = 0; t < run.mesh.triangle_count(); ++t) {
    const std::uint32_t* v = &run.mesh.triangles[3 * t];
    const float* a = &run.mesh.positions[3 * v[0]];
    const float* b = &run.mesh.positions[3 * v[1]];
    const float* c = &run.mesh.positions[3 * v[2]];
    const double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const float* vn = &run.mesh.normals[3 * v[0]];
    if (n[0] * vn[0] + n[1] * vn[1] + n[2] * vn[2] > 0) ++agree;
  }
  EXPECT_GT(double(agree), 0.99 * double(run.mesh.triangle_count()));
  for (std::size_t i = 0; i < run.mesh.vertex_count(); ++i) {
    const float* n = &run.mesh.normals[3 * i];
    ASSERT_NEAR(std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), 1.0, 1e-4);
  }
}

class Shapes : public ::testing::TestWithParam<double> {};

}  // namespace

TEST_P(Shapes, Sphere) {
  check_shape(sphere(0, 0, 0, 1.0, r), [](double x, double y, double z) { return std::sqrt(x * x + y * y + z * z) - 1.0; },
              {1, 2}, GetParam());
}

TEST_P(Shapes, Box) {
  const double lo[3] = {-0.8, -0.5, -0.4}, hi[3] = {0.8, 0.5, 0.4}, c[3] = {0, 0, 0}, h[3] = {0.8, 0.5, 0.4};
  check_shape(box(lo, hi, r), [&](double x, double y, double z) { return box_sdf(x, y, z, c, h); }, {1, 2},
              GetParam());
}

TEST_P(Shapes, Torus) {
  check_shape(torus(1.0, 0.4, r),
              [](double x, double y, double z) {
                const double q = std::sqrt(x * x + y * y) - 1.0;
                return std::sqrt(q * q + z * z) - 0.4;
              },
              {1, 0}, GetParam());
}

TEST_P(Shapes, TwoTouchingSpheres) {
  Expect e{1, 2};
  e.hi = 1.25;  // the fillet where they touch
  check_shape(concat(sphere(-0.6, 0, 0, 0.6, r), sphere(0.6, 0, 0, 0.6, r)),
              [](double x, double y, double z) {
                return std::min(std::sqrt((x + 0.6) * (x + 0.6) + y * y + z * z),
                                std::sqrt((x - 0.6) * (x - 0.6) + y * y + z * z)) -
                       0.6;
              },
              e, GetParam());
}

TEST_P(Shapes, TwoSeparateSpheres) {
  check_shape(concat(sphere(-1.0, 0, 0, 0.6, r), sphere(1.0, 0, 0, 0.6, r)),
              [](double x, double y, double z) {
                return std::min(std::sqrt((x + 1) * (x + 1) + y * y + z * z),
                                std::sqrt((x - 1) * (x - 1) + y * y + z * z)) -
                       0.6;
              },
              {2, 4}, GetParam());
}

TEST_P(Shapes, ThinSheet) {  // two particle layers
  const double lo[3] = {-1, -1, 0}, hi[3] = {1, 1, 0.1}, c[3] = {0, 0, 0.05}, h[3] = {1, 1, 0.05};
  check_shape(box(lo, hi, r), [&](double x, double y, double z) { return box_sdf(x, y, z, c, h); }, {1, 2},
              GetParam());
}

TEST_P(Shapes, SingleLayerSheet) {
  const double lo[3] = {-1, -1, 0}, hi[3] = {1, 1, 0};
  check_shape(box(lo, hi, r),
              [&](double x, double y, double z) {
                const double c[3] = {0, 0, 0}, h[3] = {1, 1, 0};
                return box_sdf(x, y, z, c, h);
              },
              {1, 2}, GetParam());
}

TEST_P(Shapes, SphereZB05) {
  check_shape(sphere(0, 0, 0, 1.0, r), [](double x, double y, double z) { return std::sqrt(x * x + y * y + z * z) - 1.0; },
              {1, 2}, GetParam(), NBMC_METHOD_ZB05);
}

INSTANTIATE_TEST_SUITE_P(CellSizes, Shapes, ::testing::Values(0.5, 1.0),
                         [](const ::testing::TestParamInfo<double>& i) {
                           return i.param == 0.5 ? std::string("HalfSpacing") : std::string("Spacing");
                         });

TEST(Shapes, OneParticleIsASphereOfRadiusIsoRadius) {
  const Points one = {0.3, -0.2, 0.1};
  nbmc_params prm = params(r);
  const Result run = reconstruct(one, prm);
  ASSERT_EQ(run.status, NBMC_OK) << run.message;
  const MeshReport rep = check_mesh(run.mesh);
  EXPECT_TRUE(rep.closed && rep.oriented && rep.vertex_manifold) << rep.summary();
  EXPECT_EQ(rep.components, 1u);
  for (std::size_t i = 0; i < run.mesh.vertex_count(); ++i) {
    const double dx = run.mesh.positions[3 * i] - 0.3, dy = run.mesh.positions[3 * i + 1] + 0.2,
                 dz = run.mesh.positions[3 * i + 2] - 0.1;
    // phi = |x - x_j| - r exactly; linear interpolation on cells of r/2 is within 0.1 r.
    EXPECT_NEAR(std::sqrt(dx * dx + dy * dy + dz * dz), r, 0.1 * r);
  }
}

TEST(Shapes, CoincidentParticlesActLikeOne) {
  // 49 neighbours and no colour gradient: only the empty-neighbour-cell
  // safety net makes these surface particles; at R = 2r as at 4r.
  Points many;
  for (int i = 0; i < 50; ++i) many.insert(many.end(), {0.3, -0.2, 0.1});
  for (double R : {4.0, 2.0}) {
    nbmc_params prm = params(r);
    prm.influence_radius = R;
    const Result a = reconstruct(many, prm);
    const Result b = reconstruct({0.3, -0.2, 0.1}, prm);
    ASSERT_EQ(a.status, NBMC_OK) << a.message;
    ASSERT_EQ(b.status, NBMC_OK) << b.message;
    EXPECT_EQ(a.stats.surface_particle_count, 50u) << "R = " << R;
    // (At R = 2r SSP07's field of 50 coincident particles is not that of one
    // particle, whatever the surface particles: only the count is compared.)
    if (R != 4.0) continue;
    EXPECT_EQ(a.mesh.triangles, b.mesh.triangles) << "R = " << R;
    ASSERT_EQ(a.mesh.positions.size(), b.mesh.positions.size()) << "R = " << R;
    for (std::size_t i = 0; i < a.mesh.positions.size(); ++i)
      EXPECT_NEAR(a.mesh.positions[i], b.mesh.positions[i], 1e-5);
  }
}
