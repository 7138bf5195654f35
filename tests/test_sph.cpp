// SPDX-License-Identifier: MIT
// NBMC_METHOD_SPH, the normalised SPH density of splashsurf (docs/methods.md):
//   rho(x) = sum_j W(x - x_j) / D_j,  D_j = sum_k W(x_j - x_k),
// W the cubic spline of compact support h = influence_radius (its constant
// factor cancels), surface at rho = iso_threshold. The reference here is a
// separate, plain double-precision evaluation of that formula over all
// particles (no cells, no float), against which the meshes are measured.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <limits>
#include <set>
#include <string>

using namespace nbmc_test;

namespace {

// The cubic spline over sigma, q = |d| / h.
double spline(double q) {
  if (q <= 0.5) return 1 - 6 * q * q + 6 * q * q * q;
  if (q < 1) return 2 * (1 - q) * (1 - q) * (1 - q);
  return 0;
}

struct Reference {
  const Points& p;
  double h;
  std::vector<double> inv_density;
  Reference(const Points& pts, double support) : p(pts), h(support) {
    const std::size_t n = p.size() / 3;
    inv_density.resize(n);
    for (std::size_t j = 0; j < n; ++j) inv_density[j] = 1 / raw(p[3 * j], p[3 * j + 1], p[3 * j + 2], false);
  }
  double raw(double x, double y, double z, bool weighted) const {
    double s = 0;
    for (std::size_t k = 0; k < p.size() / 3; ++k) {
      const double dx = p[3 * k] - x, dy = p[3 * k + 1] - y, dz = p[3 * k + 2] - z;
      const double w = spline(std::sqrt(dx * dx + dy * dy + dz * dz) / h);
      s += weighted ? w * inv_density[k] : w;
    }
    return s;
  }
  double rho(double x, double y, double z) const { return raw(x, y, z, true); }
};

nbmc_params sph_params(double r, double R, double threshold) {
  nbmc_params prm = params(r);
  prm.method = NBMC_METHOD_SPH;
  prm.influence_radius = R;
  prm.iso_threshold = threshold;
  return prm;
}

// Largest |rho(v) - threshold| over the mesh vertices.
double worst_level(const Mesh& m, const Reference& ref, double threshold) {
  double worst = 0;
  for (std::size_t v = 0; v < m.vertex_count(); ++v)
    worst = std::max(worst, std::fabs(ref.rho(m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]) -
                                      threshold));
  return worst;
}

Points blob(double r) {
  const double lo[3] = {-0.5, -0.35, -0.3}, hi[3] = {0.5, 0.35, 0.0};
  Points p = box(lo, hi, r);
  p = concat(p, sphere(0.1, 0.0, 0.3, 0.2, r));
  const double drops[][3] = {{0.7, 0.45, 0.5}, {-0.6, 0.3, 0.45}, {0.72, 0.45, 0.52}};
  for (const auto& d : drops) p.insert(p.end(), {d[0], d[1], d[2]});
  return p;
}

void expect_identical(const Result& a, const Result& b, const std::string& what) {
  ASSERT_EQ(a.status, NBMC_OK) << a.message;
  ASSERT_EQ(b.status, NBMC_OK) << b.message;
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles) << what;
  EXPECT_EQ(a.mesh.positions, b.mesh.positions) << what;  // bitwise
  EXPECT_EQ(a.mesh.normals, b.mesh.normals) << what;
}

}  // namespace

// One particle: D = W(0)/sigma = 1, so the surface is the sphere where the
// spline equals the threshold, q* h with 1 - 6 q*^2 + 6 q*^3 = t (q* < 1/2
// for t > 1/4).
TEST(Sph, SingleParticleIsTheSplineLevelSphere) {
  const double r = 0.1;
  for (const double t : {0.3, 0.6, 0.9}) {
    double a = 0, b = 0.5;  // spline(a) > t > spline(b)
    for (int i = 0; i < 100; ++i) (spline(0.5 * (a + b)) > t ? a : b) = 0.5 * (a + b);
    for (const double R : {2.0, 4.0}) {
      nbmc_params prm = sph_params(r, R, t);
      prm.cell_size = 0.05;
      prm.cleanup = 0;
      prm.max_distance = 0;  // the level sphere lies up to 2.4 r out: no distance guard
      const Points p = {0.3, -0.2, 0.1};
      const Result res = reconstruct(p, prm);
      ASSERT_EQ(res.status, NBMC_OK) << res.message;
      ASSERT_GT(res.mesh.triangle_count(), 0u);
      EXPECT_TRUE(check_mesh(res.mesh).closed);
      const double expect = a * R * r;
      double worst = 0;
      for (std::size_t v = 0; v < res.mesh.vertex_count(); ++v) {
        const double dx = res.mesh.positions[3 * v] - p[0], dy = res.mesh.positions[3 * v + 1] - p[1],
                     dz = res.mesh.positions[3 * v + 2] - p[2];
        worst = std::max(worst, std::fabs(std::sqrt(dx * dx + dy * dy + dz * dz) - expect));
      }
      // Linear interpolation along the cell edges (0.05 r) is the only
      // error. Measured at cell 0.1 r: 0.05% (t 0.3, R 4r) to 1.5% (t 0.9,
      // R 2r: a sphere of 2.7 cells); stated bound 2% at 0.05 r.
      EXPECT_LT(worst, 0.02 * expect) << "t " << t << ", R " << R << "r, radius " << expect;
    }
  }
}

// A lattice box: closed, every vertex on the level set of the reference
// density, and the faces where a uniform lattice puts them. The expected
// offset of a face beyond its last particle layer is where the normalised
// density of a half lattice falls to t: found here by bisection of the
// reference along the normal through the middle of the face.
TEST(Sph, LatticeBoxOnTheReferenceLevelSet) {
  const double r = 0.05;
  const double lo[3] = {0, 0, 0}, hi[3] = {0.75, 0.6, 0.5};
  const Points p = box(lo, hi, r);
  for (const double R : {2.0, 3.0}) {
    const double t = 0.6;
    nbmc_params prm = sph_params(r, R, t);
    prm.cell_size = 0.25;
    prm.cleanup = 0;
    const Result res = reconstruct(p, prm);
    ASSERT_EQ(res.status, NBMC_OK) << res.message;
    const MeshReport rep = check_mesh(res.mesh);
    EXPECT_TRUE(rep.closed) << rep.summary();
    EXPECT_EQ(rep.components, 1u) << rep.summary();
    const Reference ref(p, R * r);
    // Measured: 0.0059 (R 2r), 0.0024 (R 3r); stated bound 0.01. The
    // reference with a kernel 10% wider is 0.035 to 0.040 off these meshes.
    EXPECT_LT(worst_level(res.mesh, ref, t), 0.01) << "R " << R << "r";
    // The +x face: bisection along (x, y_mid, z_mid) beyond the last layer.
    const double ym = 0.3, zm = 0.25;
    double a = hi[0], b = hi[0] + R * r;
    ASSERT_GT(ref.rho(a, ym, zm), t);
    for (int i = 0; i < 60; ++i) (ref.rho(0.5 * (a + b), ym, zm) > t ? a : b) = 0.5 * (a + b);
    double face = 0;
    std::size_t count = 0;
    for (std::size_t v = 0; v < res.mesh.vertex_count(); ++v) {
      const float* x = &res.mesh.positions[3 * v];
      if (std::fabs(x[1] - ym) < 0.5 * r && std::fabs(x[2] - zm) < 0.5 * r && x[0] > hi[0]) {
        face = std::max(face, std::fabs(x[0] - a));
        ++count;
      }
    }
    ASSERT_GT(count, 0u);
    // Measured: 0.0015 r (the offset itself: 0.48 r at R 2r, 0.58 r at
    // R 3r); stated: 0.01 r.
    EXPECT_LT(face, 0.01 * r) << "R " << R << "r: face offset " << (a - hi[0]) / r << " r expected";
    // The offset of the face is a fixed property of the lattice: positive
    // and within the kernel support.
    EXPECT_GT(a - hi[0], 0.0);
    EXPECT_LT(a - hi[0], R * r);
  }
}

TEST(Sph, LatticeSphereOnTheReferenceLevelSet) {
  const double r = 0.05;
  const Points p = sphere(0, 0, 0, 0.3, r);
  const double t = 0.6, R = 2;
  nbmc_params prm = sph_params(r, R, t);
  prm.cell_size = 0.25;
  prm.cleanup = 0;
  const Result res = reconstruct(p, prm);
  ASSERT_EQ(res.status, NBMC_OK) << res.message;
  const MeshReport rep = check_mesh(res.mesh);
  EXPECT_TRUE(rep.closed) << rep.summary();
  EXPECT_EQ(rep.components, 1u);
  const Reference ref(p, R * r);
  EXPECT_LT(worst_level(res.mesh, ref, t), 0.01);  // measured 0.0061
  // Radius: the lattice sphere's outermost particles lie within 0.3 of the
  // centre; the surface lies beyond them by about the flat-face offset
  // (0.48 r at R 2r). Measured mean vertex radius 0.3036.
  double mean = 0;
  for (std::size_t v = 0; v < res.mesh.vertex_count(); ++v) {
    const float* x = &res.mesh.positions[3 * v];
    mean += std::sqrt(double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
  }
  mean /= double(res.mesh.vertex_count());
  EXPECT_GT(mean, 0.3 - r);
  EXPECT_LT(mean, 0.3 + R * r);
}

TEST(Sph, SameMeshOnOneTwoFourThreadsAndSerial) {
  const double r = 0.05;
  const Points p = blob(r);
  for (const double R : {4.0, 2.0}) {
    const nbmc_params prm = sph_params(r, R, 0.6);
    const Result one = reconstruct(p, prm, NBMC_BACKEND_OPENMP, 1);
    ASSERT_EQ(one.status, NBMC_OK) << one.message;
    EXPECT_TRUE(check_mesh(one.mesh).closed);
    expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_OPENMP, 2), "2 threads");
    expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_OPENMP, 4), "4 threads");
    expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_SERIAL, 0), "serial backend");
  }
}

// The band (built around surface particles, grown where the surface leaves
// it) holds the whole SPH surface: the dense baseline gives the same
// triangles, and both meshes are closed.
TEST(Sph, NarrowBandEqualsDense) {
  const double r = 0.05;
  const Points p = blob(r);
  for (const double R : {4.0, 2.0, 1.5}) {
    for (const double t : {0.3, 0.6, 0.9}) {
      nbmc_params nb = sph_params(r, R, t), dense = nb;
      nb.cleanup = dense.cleanup = 0;
      dense.field = NBMC_FIELD_DENSE;
      const Result a = reconstruct(p, nb), b = reconstruct(p, dense);
      ASSERT_EQ(a.status, NBMC_OK) << a.message;
      ASSERT_EQ(b.status, NBMC_OK) << b.message;
      const std::string what = "R " + std::to_string(R) + "r, t " + std::to_string(t);
      EXPECT_TRUE(check_mesh(a.mesh).closed) << what;
      EXPECT_TRUE(check_mesh(b.mesh).closed) << what;
      EXPECT_EQ(a.mesh.triangle_count(), b.mesh.triangle_count()) << what;
      EXPECT_EQ(a.mesh.vertex_count(), b.mesh.vertex_count()) << what;
      EXPECT_TRUE(triangle_set(a.mesh) == triangle_set(b.mesh)) << what << ": other triangles";
    }
  }
}

TEST(Sph, ThresholdOutOfRangeIsAnInvalidParameter) {
  const double r = 0.05;
  const Points p = sphere(0, 0, 0, 0.2, r);
  const double bad[] = {0.0, 1.0, -0.5, 1.5, std::numeric_limits<double>::quiet_NaN(),
                        std::numeric_limits<double>::infinity()};
  for (const int method : {NBMC_METHOD_SPH, NBMC_METHOD_SSP07}) {
    for (const double t : bad) {
      nbmc_params prm = sph_params(r, 2, t);
      prm.method = method;
      const Result res = reconstruct(p, prm);
      EXPECT_EQ(res.status, NBMC_ERROR_INVALID_PARAMETER) << "iso_threshold " << t;
      EXPECT_NE(res.message.find("iso_threshold"), std::string::npos) << res.message;
    }
  }
  nbmc_params prm = sph_params(r, 2, 0.6);
  prm.method = 4;  // 3 is NBMC_METHOD_YT10
  EXPECT_EQ(reconstruct(p, prm).status, NBMC_ERROR_INVALID_PARAMETER);
}

// The SPH density does not use iso_radius: iso_radius >= R is accepted.
TEST(Sph, IsoRadiusIsNotChecked) {
  const double r = 0.05;
  nbmc_params prm = sph_params(r, 1.2, 0.6);
  prm.iso_radius = 2;
  const Result res = reconstruct(sphere(0, 0, 0, 0.2, r), prm);
  ASSERT_EQ(res.status, NBMC_OK) << res.message;
  prm.method = NBMC_METHOD_ZB05;
  EXPECT_EQ(reconstruct(sphere(0, 0, 0, 0.2, r), prm).status, NBMC_ERROR_INVALID_PARAMETER);
}

// A caller built before iso_threshold was appended passes the shorter
// struct: whatever lies beyond it, the default 0.6 is used.
TEST(Sph, OlderStructGetsTheDefaultThreshold) {
  const double r = 0.05;
  const Points p = sphere(0, 0, 0, 0.25, r);
  const nbmc_params full = sph_params(r, 2, 0.6);
  nbmc_params old = sph_params(r, 2, 0.123);
  old.struct_size = uint32_t(offsetof(nbmc_params, iso_threshold));
  expect_identical(reconstruct(p, full), reconstruct(p, old), "older struct");
  nbmc_params other = sph_params(r, 2, 0.3);
  const Result c = reconstruct(p, other);
  ASSERT_EQ(c.status, NBMC_OK);
  EXPECT_NE(c.mesh.positions, reconstruct(p, full).mesh.positions) << "the threshold must matter";
}
