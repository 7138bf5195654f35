// SPDX-License-Identifier: MIT
// Per-particle radii (nbmc_context_set_radii_*, issue #13):
//  - a coarse box next to a sphere sampled four times finer reconstructs both
//    closed, and the fine sphere lies within 0.25 of its own spacing of its
//    analytic radius (SSP07, ZB05 and the SPH density), as a uniform run of
//    the fine sphere alone does; without radii it is more than one fine
//    spacing off;
//  - equal radii are a uniform frame: equal to nbmc_params.spacing, the mesh
//    without radii bit for bit; equal to another r, the mesh of spacing r;
//  - a particle path with radii barely different from the spacing gives the
//    uniform mesh up to rounding;
//  - the same mesh for every subdomain split, backend and thread count;
//  - radii follow the particles: cleared by an upload and by NULL; the
//    isolated-particle filter and attribute interpolation keep them aligned;
//  - bad input gets exact statuses;
//  - the CLI's --radius-attribute/--radius-scale give the C API's mesh.
#include "cli_fixture.hpp"
#include "nbmc_test.hpp"
#include "io/particles.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

using namespace nbmc_test;

namespace {

constexpr double kCoarse = 0.1, kFine = 0.025;  // spacings: the fine sphere is sampled 4x finer
constexpr double kSphereRadius = 0.4, kSphereX = 0.6;

struct Frame {
  Points xyz;
  std::vector<double> radii;
  std::size_t coarse = 0;  // the box's particles come first
};

// A 0.6 x 0.8 x 0.8 box of spacing kCoarse and, 0.8 to its right (twice the
// box's influence radius), a sphere of radius 0.4 and spacing kFine.
Frame two_resolutions() {
  Frame f;
  const double lo[3] = {-1.2, -0.4, -0.4}, hi[3] = {-0.6, 0.4, 0.4};
  f.xyz = box(lo, hi, kCoarse);
  f.coarse = f.xyz.size() / 3;
  f.xyz = concat(f.xyz, sphere(kSphereX, 0, 0, kSphereRadius, kFine));
  f.radii.assign(f.xyz.size() / 3, kFine);
  std::fill(f.radii.begin(), f.radii.begin() + std::ptrdiff_t(f.coarse), kCoarse);
  return f;
}

struct Ctx {
  nbmc_context* c = nullptr;
  explicit Ctx(int32_t backend = NBMC_BACKEND_OPENMP, int threads = 0) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = backend;
    d.num_threads = threads;
    EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_OK);
  }
  ~Ctx() { nbmc_context_destroy(c); }
  Ctx(const Ctx&) = delete;
  Ctx& operator=(const Ctx&) = delete;
  std::string error() const { return nbmc_context_last_error(c); }
};

struct Outcome {
  int32_t status = -1;
  std::string error;
  Mesh mesh;
  std::vector<float> attribute;
};

// Uploads the particles (and radii when given), reconstructs, copies the mesh.
Outcome run(const Points& xyz, const std::vector<double>* radii, const nbmc_params& prm, int32_t backend = NBMC_BACKEND_OPENMP,
        int threads = 0, const int split[3] = nullptr, const std::vector<double>* attribute = nullptr) {
  Outcome r;
  Ctx ctx(backend, threads);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, xyz.data(), xyz.size() / 3, 0), NBMC_OK);
  if (radii) EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, radii->data(), radii->size(), 0), NBMC_OK) << ctx.error();
  if (attribute) EXPECT_EQ(nbmc_context_set_attribute_f64(ctx.c, "a", attribute->data(), 1, 0), NBMC_OK);
  if (split) EXPECT_EQ(nbmc_context_set_subdomains(ctx.c, split[0], split[1], split[2]), NBMC_OK);
  nbmc_mesh* m = nullptr;
  r.status = nbmc_context_reconstruct(ctx.c, &prm, &m);
  r.error = ctx.error();
  if (r.status != NBMC_OK) return r;
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  const float* p = nbmc_mesh_positions(m);
  const float* n = nbmc_mesh_normals(m);
  const std::uint32_t* t = nbmc_mesh_triangles(m);
  if (p) r.mesh.positions.assign(p, p + 3 * nv);
  if (n) r.mesh.normals.assign(n, n + 3 * nv);
  if (t) r.mesh.triangles.assign(t, t + 3 * nt);
  if (attribute) {
    uint32_t comps = 0;
    const float* a = nbmc_mesh_attribute(m, "a", &comps);
    if (a) r.attribute.assign(a, a + nv);
  }
  nbmc_mesh_destroy(m);
  return r;
}

bool same_mesh(const Mesh& a, const Mesh& b) {
  auto same = [](const auto& x, const auto& y) {
    return x.size() == y.size() && (x.empty() || std::memcmp(x.data(), y.data(), x.size() * sizeof(x[0])) == 0);
  };
  return same(a.positions, b.positions) && same(a.normals, b.normals) && same(a.triangles, b.triangles);
}

void expect_closed(const Mesh& m, std::size_t components, const std::string& what) {
  const MeshReport rep = check_mesh(m);
  EXPECT_TRUE(rep.closed) << what << ": " << rep.summary();
  EXPECT_TRUE(rep.vertex_manifold) << what << ": " << rep.summary();
  EXPECT_TRUE(rep.oriented) << what << ": " << rep.summary();
  EXPECT_EQ(rep.components, components) << what << ": " << rep.summary();
  EXPECT_GT(rep.volume, 0) << what << ": " << rep.summary();
}

// Signed distances (in fine spacings) of the vertices right of x = 0 (the
// sphere's) from the analytic sphere: their mean, smallest and largest.
struct SphereFit {
  std::size_t vertices = 0;
  double mean = 0, lo = 1e300, hi = -1e300;
};
SphereFit fit_sphere(const Mesh& m) {
  SphereFit f;
  for (std::size_t i = 0; i < m.vertex_count(); ++i) {
    const double x = m.positions[3 * i] - kSphereX, y = m.positions[3 * i + 1], z = m.positions[3 * i + 2];
    if (m.positions[3 * i] < 0) continue;
    const double d = (std::sqrt(x * x + y * y + z * z) - kSphereRadius) / kFine;
    f.mean += d;
    f.lo = std::min(f.lo, d);
    f.hi = std::max(f.hi, d);
    ++f.vertices;
  }
  if (f.vertices) f.mean /= double(f.vertices);
  return f;
}

// The parameters of the two-resolution frame: spacing is the coarse radius
// (the lengths of a coarse particle); cells of the fine spacing (or `cells`
// fine spacings).
nbmc_params two_resolution_params(int32_t method, double cells = 1) {
  nbmc_params prm = params(kCoarse);
  prm.cell_size = cells * kFine / kCoarse;
  prm.method = method;
  return prm;
}

class TwoResolutions : public ::testing::TestWithParam<int32_t> {};

}  // namespace

// The test: a coarse box next to a sphere sampled four times finer.
TEST_P(TwoResolutions, BothClosedAndTheFineSphereWithinAQuarterOfItsSpacing) {
  const Frame f = two_resolutions();
  const nbmc_params prm = two_resolution_params(GetParam());
  const Outcome r = run(f.xyz, &f.radii, prm);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  expect_closed(r.mesh, 2, "two resolutions");
  const SphereFit s = fit_sphere(r.mesh);
  ASSERT_GT(s.vertices, 1000u);
  EXPECT_LE(std::fabs(s.mean), 0.25) << "mean distance of the fine sphere's vertices from r = 0.4, in fine spacings";
  EXPECT_GE(s.lo, -0.5);
  EXPECT_LE(s.hi, 0.5);

  // As good as the fine sphere alone, reconstructed uniformly at its own
  // spacing on the same cells.
  nbmc_params fine = params(kFine);
  fine.cell_size = 1.0;
  fine.method = GetParam();
  const Points alone(f.xyz.begin() + std::ptrdiff_t(3 * f.coarse), f.xyz.end());
  const Outcome u = run(alone, nullptr, fine);
  ASSERT_EQ(u.status, NBMC_OK) << u.error;
  const SphereFit su = fit_sphere(u.mesh);
  EXPECT_NEAR(s.mean, su.mean, 0.05);

  // Without radii every particle has the coarse lengths: the sphere is far off.
  const Outcome plain = run(f.xyz, nullptr, prm);
  ASSERT_EQ(plain.status, NBMC_OK) << plain.error;
  EXPECT_GT(std::fabs(fit_sphere(plain.mesh).mean), 0.5);
}

// Every subdomain split gives the frame's mesh, bit for bit.
TEST_P(TwoResolutions, SameMeshForEverySplit) {
  const Frame f = two_resolutions();
  const nbmc_params prm = two_resolution_params(GetParam());
  const Outcome whole = run(f.xyz, &f.radii, prm);
  ASSERT_EQ(whole.status, NBMC_OK) << whole.error;
  for (const auto& s : {std::array<int, 3>{2, 1, 1}, std::array<int, 3>{3, 2, 1}}) {
    const Outcome split = run(f.xyz, &f.radii, prm, NBMC_BACKEND_OPENMP, 0, s.data());
    ASSERT_EQ(split.status, NBMC_OK) << split.error;
    EXPECT_TRUE(same_mesh(whole.mesh, split.mesh)) << s[0] << "x" << s[1] << "x" << s[2];
  }
}

// Serial, and OpenMP on 1, 2 and 4 threads: the same mesh.
TEST_P(TwoResolutions, SameMeshOnEveryBackendAndThreadCount) {
  const Frame f = two_resolutions();
  const nbmc_params prm = two_resolution_params(GetParam());
  const Outcome ref = run(f.xyz, &f.radii, prm, NBMC_BACKEND_SERIAL);
  ASSERT_EQ(ref.status, NBMC_OK) << ref.error;
  for (int threads : {1, 2, 4}) {
    const Outcome r = run(f.xyz, &f.radii, prm, NBMC_BACKEND_OPENMP, threads);
    ASSERT_EQ(r.status, NBMC_OK) << r.error;
    EXPECT_TRUE(same_mesh(ref.mesh, r.mesh)) << threads << " threads";
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, TwoResolutions,
                         ::testing::Values(NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH),
                         [](const ::testing::TestParamInfo<int32_t>& i) {
                           return std::string(i.param == NBMC_METHOD_SSP07  ? "ssp07"
                                              : i.param == NBMC_METHOD_ZB05 ? "zb05"
                                                                            : "sph");
                         });

// The dense and scatter baselines evaluate the same field.
TEST(Radii, BaselinesAgreeWithTheBand) {
  const Frame f = two_resolutions();
  const nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);  // the dense grids stay small
  const Outcome band = run(f.xyz, &f.radii, prm);
  ASSERT_EQ(band.status, NBMC_OK) << band.error;
  for (int32_t field : {NBMC_FIELD_DENSE, NBMC_FIELD_SCATTER}) {
    nbmc_params q = prm;
    q.field = field;
    const Outcome r = run(f.xyz, &f.radii, q);
    ASSERT_EQ(r.status, NBMC_OK) << r.error;
    expect_closed(r.mesh, 2, field == NBMC_FIELD_DENSE ? "dense" : "scatter");
    EXPECT_NEAR(fit_sphere(r.mesh).mean, fit_sphere(band.mesh).mean, 0.01);
  }
}

// Radii all equal to the spacing: the mesh without radii, bit for bit (f32
// and f64, packed and strided).
TEST(Radii, EqualToTheSpacingIsTheMeshWithoutRadii) {
  const Points p = concat(sphere(0, 0, 0, 0.5, kCoarse), sphere(1.3, 0, 0, 0.3, kCoarse));
  const std::size_t n = p.size() / 3;
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    nbmc_params prm = params(kCoarse);
    prm.method = method;
    const Outcome plain = run(p, nullptr, prm);
    ASSERT_EQ(plain.status, NBMC_OK) << plain.error;
    const std::vector<double> equal(n, kCoarse);
    const Outcome r64 = run(p, &equal, prm);
    ASSERT_EQ(r64.status, NBMC_OK) << r64.error;
    EXPECT_TRUE(same_mesh(plain.mesh, r64.mesh)) << "method " << method;

    // float radii, every other float of an array (byte_stride 8)
    Ctx ctx;
    ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, p.data(), n, 0), NBMC_OK);
    std::vector<float> strided(2 * n, -1.f);
    for (std::size_t i = 0; i < n; ++i) strided[2 * i] = float(kCoarse);
    nbmc_params q = prm;
    q.spacing = double(float(kCoarse));  // equal to the float radii
    ASSERT_EQ(nbmc_context_set_radii_f32(ctx.c, strided.data(), n, 2 * sizeof(float)), NBMC_OK) << ctx.error();
    nbmc_mesh* m = nullptr;
    ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &q, &m), NBMC_OK) << ctx.error();
    const Outcome plain_f = run(p, nullptr, q);
    ASSERT_EQ(nbmc_mesh_vertex_count(m), plain_f.mesh.vertex_count());
    EXPECT_EQ(std::memcmp(nbmc_mesh_positions(m), plain_f.mesh.positions.data(),
                          plain_f.mesh.positions.size() * sizeof(float)),
              0);
    nbmc_mesh_destroy(m);
  }
}

// Equal radii r != spacing: a uniform frame of spacing r (on the same cells).
TEST(Radii, EqualRadiiAreAUniformFrameOfThatSpacing) {
  const Points p = sphere(0, 0, 0, 0.5, 0.05);
  const std::vector<double> equal(p.size() / 3, 0.05);
  nbmc_params prm = params(0.1);  // the lengths of a particle of radius 0.1, halved for 0.05
  prm.cell_size = 0.25;           // 0.025: the frame's cell
  const Outcome r = run(p, &equal, prm);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  nbmc_params uniform = params(0.05);
  uniform.cell_size = 0.5;  // 0.025 too
  const Outcome u = run(p, nullptr, uniform);
  ASSERT_EQ(u.status, NBMC_OK) << u.error;
  EXPECT_TRUE(same_mesh(r.mesh, u.mesh));
}

// The per-particle path with radii all but equal to the spacing: the uniform
// mesh up to rounding (rbar is then a weighted mean of equal radii).
TEST(Radii, NearlyEqualRadiiGiveTheUniformSurface) {
  const Points p = sphere(0, 0, 0, 0.5, kCoarse);
  std::vector<double> radii(p.size() / 3, kCoarse);
  radii[radii.size() / 2] = kCoarse * (1 - 1e-9);  // an inner particle: the per-particle path runs
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    nbmc_params prm = params(kCoarse);
    prm.method = method;
    const Outcome plain = run(p, nullptr, prm);
    const Outcome r = run(p, &radii, prm);
    ASSERT_EQ(r.status, NBMC_OK) << r.error;
    ASSERT_EQ(r.mesh.triangles, plain.mesh.triangles) << "method " << method;
    float worst = 0;
    for (std::size_t i = 0; i < r.mesh.positions.size(); ++i)
      worst = std::max(worst, std::fabs(r.mesh.positions[i] - plain.mesh.positions[i]));
    EXPECT_LT(worst, 1e-4 * kCoarse) << "method " << method;
  }
}

// The radii belong to the particles uploaded last.
TEST(Radii, FollowTheParticles) {
  const Frame f = two_resolutions();
  const nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);
  const Outcome with = run(f.xyz, &f.radii, prm);
  const Outcome without = run(f.xyz, nullptr, prm);
  ASSERT_EQ(with.status, NBMC_OK);
  ASSERT_EQ(without.status, NBMC_OK);
  const std::size_t n = f.xyz.size() / 3;
  auto reconstruct = [&](Ctx& ctx) {
    Outcome r;
    nbmc_mesh* m = nullptr;
    r.status = nbmc_context_reconstruct(ctx.c, &prm, &m);
    if (m) {
      const float* p = nbmc_mesh_positions(m);
      r.mesh.positions.assign(p, p + 3 * nbmc_mesh_vertex_count(m));
      const std::uint32_t* t = nbmc_mesh_triangles(m);
      r.mesh.triangles.assign(t, t + 3 * nbmc_mesh_triangle_count(m));
      const float* nn = nbmc_mesh_normals(m);
      r.mesh.normals.assign(nn, nn + 3 * nbmc_mesh_vertex_count(m));
    }
    nbmc_mesh_destroy(m);
    return r;
  };
  Ctx ctx;
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, f.xyz.data(), n, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, f.radii.data(), n, 0), NBMC_OK);
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, with.mesh));
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, with.mesh)) << "the radii stay for the next reconstruction";
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, nullptr, 0, 0), NBMC_OK);  // removed
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, without.mesh));
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, nullptr, 0, 0), NBMC_OK);  // none: still OK
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, f.radii.data(), n, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, f.xyz.data(), n, 0), NBMC_OK);  // an upload removes them
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, without.mesh));
  // A failed upload removes them too.
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, f.radii.data(), n, 0), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx.c, f.xyz.data(), 0, 0), NBMC_ERROR_NO_PARTICLES);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, f.xyz.data(), n, 0), NBMC_OK);
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, without.mesh));
  // A failed set leaves none.
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, f.radii.data(), n, 0), NBMC_OK);
  std::vector<double> bad = f.radii;
  bad[7] = -1;
  EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, bad.data(), n, 0), NBMC_ERROR_INVALID_PARAMETER);
  EXPECT_TRUE(same_mesh(reconstruct(ctx).mesh, without.mesh));
}

// The input order does not matter, also for particles at one position with
// different radii (they are summed in the order of their radii).
TEST(Radii, SameMeshForAnyInputOrder) {
  Frame f = two_resolutions();
  const std::size_t n = f.radii.size();
  for (std::size_t i = f.coarse; i < n; i += 7) {  // a larger twin of every 7th fine particle
    f.xyz.insert(f.xyz.end(), {f.xyz[3 * i], f.xyz[3 * i + 1], f.xyz[3 * i + 2]});
    f.radii.push_back(1.5 * kFine);
  }
  const std::size_t m = f.radii.size();
  std::vector<std::size_t> order(m);
  for (std::size_t i = 0; i < m; ++i) order[i] = (i * 7919) % m;  // a permutation (7919 is prime, m is not a multiple)
  ASSERT_NE(m % 7919, 0u);
  Frame g;
  for (std::size_t i : order) {
    g.xyz.insert(g.xyz.end(), {f.xyz[3 * i], f.xyz[3 * i + 1], f.xyz[3 * i + 2]});
    g.radii.push_back(f.radii[i]);
  }
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_SPH}) {
    const nbmc_params prm = two_resolution_params(method, 2);
    const Outcome a = run(f.xyz, &f.radii, prm), b = run(g.xyz, &g.radii, prm);
    ASSERT_EQ(a.status, NBMC_OK) << a.error;
    ASSERT_EQ(b.status, NBMC_OK) << b.error;
    EXPECT_TRUE(same_mesh(a.mesh, b.mesh)) << "method " << method;
  }
}

// Isolated particles dropped before the reconstruction take their radii
// with them: the mesh is the one of the particles kept.
TEST(Radii, IsolatedParticlesTakeTheirRadiiAlong) {
  Frame f = two_resolutions();
  Frame extra = f;
  for (const double x : {3.0, 3.5}) {  // two lone particles, of a radius between the others
    extra.xyz.insert(extra.xyz.begin(), {x, 2.0, 0.0});
    extra.radii.insert(extra.radii.begin(), 0.05);
  }
  nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);
  prm.isolated = NBMC_ISOLATED_DROP;
  prm.min_cluster = 3;
  const Outcome a = run(f.xyz, &f.radii, prm);
  const Outcome b = run(extra.xyz, &extra.radii, prm);
  ASSERT_EQ(a.status, NBMC_OK) << a.error;
  ASSERT_EQ(b.status, NBMC_OK) << b.error;
  EXPECT_TRUE(same_mesh(a.mesh, b.mesh));
}

// A clipping box around the sphere keeps the particles within R of it with
// their radii (the selection re-indexes them): the sphere alone, as well fit.
TEST(Radii, ClippingBoxKeepsTheRadiiOfItsParticles) {
  const Frame f = two_resolutions();
  nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);
  prm.use_bbox = 1;
  for (int a = 0; a < 3; ++a) {
    prm.bbox_min[a] = (a == 0 ? kSphereX : 0.0) - 0.5;
    prm.bbox_max[a] = (a == 0 ? kSphereX : 0.0) + 0.5;
  }
  const Outcome r = run(f.xyz, &f.radii, prm);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  expect_closed(r.mesh, 1, "clipped to the sphere");
  const SphereFit s = fit_sphere(r.mesh);
  EXPECT_EQ(s.vertices, r.mesh.vertex_count());
  EXPECT_LE(std::fabs(s.mean), 0.25);
}

// Attributes are interpolated with each particle's own support: the box's
// vertices get the box's value, the sphere's the sphere's.
TEST(Radii, AttributesFollowThePerParticleKernel) {
  const Frame f = two_resolutions();
  std::vector<double> value(f.radii.size(), 2.0);
  std::fill(value.begin(), value.begin() + std::ptrdiff_t(f.coarse), 1.0);
  const nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);
  const Outcome r = run(f.xyz, &f.radii, prm, NBMC_BACKEND_OPENMP, 0, nullptr, &value);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  ASSERT_EQ(r.attribute.size(), r.mesh.vertex_count());
  for (std::size_t i = 0; i < r.mesh.vertex_count(); ++i)
    ASSERT_EQ(r.attribute[i], r.mesh.positions[3 * i] < 0 ? 1.f : 2.f) << "vertex " << i;
}

// Exact statuses for bad input; the context keeps no radii after a failure.
// YT10 has no per-particle radii: differing radii are refused with
// INVALID_PARAMETER; equal radii are a uniform frame (equal to the spacing:
// the mesh without radii); without the radii the same context reconstructs.
TEST(Radii, Yt10IsRefused) {
  const Frame f = two_resolutions();
  const std::size_t n = f.radii.size();
  nbmc_params prm = params(kCoarse);
  prm.method = NBMC_METHOD_YT10;
  const Outcome differing = run(f.xyz, &f.radii, prm);
  EXPECT_EQ(differing.status, NBMC_ERROR_INVALID_PARAMETER);
  EXPECT_NE(differing.error.find("not supported with method yt10"), std::string::npos) << differing.error;
  const std::vector<double> equal(n, kCoarse);
  const Outcome same = run(f.xyz, &equal, prm);
  ASSERT_EQ(same.status, NBMC_OK) << same.error;
  const Outcome plain = run(f.xyz, nullptr, prm);
  ASSERT_EQ(plain.status, NBMC_OK) << plain.error;
  EXPECT_TRUE(same_mesh(plain.mesh, same.mesh));
  Ctx ctx;
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, f.xyz.data(), n, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, f.radii.data(), n, 0), NBMC_OK);
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_ERROR_INVALID_PARAMETER);
  EXPECT_EQ(m, nullptr);
  ASSERT_EQ(nbmc_context_set_radii_f64(ctx.c, nullptr, 0, 0), NBMC_OK);  // removed
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  EXPECT_GT(nbmc_mesh_triangle_count(m), 0u);
  nbmc_mesh_destroy(m);
  prm.method = NBMC_METHOD_SPH;  // the other methods take them
  const Outcome sph = run(f.xyz, &f.radii, prm);
  EXPECT_EQ(sph.status, NBMC_OK) << sph.error;
}

TEST(Radii, Errors) {
  EXPECT_EQ(nbmc_context_set_radii_f64(nullptr, nullptr, 0, 0), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_radii_f32(nullptr, nullptr, 0, 0), NBMC_ERROR_INVALID_ARGUMENT);
  Ctx ctx;
  const double one = 0.1;
  EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, &one, 1, 0), NBMC_ERROR_NO_PARTICLES);
  EXPECT_NE(ctx.error().find("no particles uploaded"), std::string::npos) << ctx.error();
  const Points p = sphere(0, 0, 0, 0.3, kCoarse);
  const std::size_t n = p.size() / 3;
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, p.data(), n, 0), NBMC_OK);
  std::vector<double> r(n, kCoarse);
  EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, r.data(), n - 1, 0), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_NE(ctx.error().find("count is"), std::string::npos) << ctx.error();
  EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, r.data(), n + 1, 0), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, r.data(), n, 4), NBMC_ERROR_INVALID_ARGUMENT);  // stride < 8
  std::vector<float> rf(n, float(kCoarse));
  EXPECT_EQ(nbmc_context_set_radii_f32(ctx.c, rf.data(), n, 2), NBMC_ERROR_INVALID_ARGUMENT);
  for (const double v : {std::nan(""), std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                         0.0, -0.1, 2e15}) {
    std::vector<double> bad = r;
    bad[5] = v;
    bad[9] = v;
    EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, bad.data(), n, 0), NBMC_ERROR_INVALID_PARAMETER) << v;
    EXPECT_NE(ctx.error().find("first at particle 5"), std::string::npos) << ctx.error();
    std::vector<float> badf = rf;
    badf[5] = float(v);
    EXPECT_EQ(nbmc_context_set_radii_f32(ctx.c, badf.data(), n, 0), NBMC_ERROR_INVALID_PARAMETER) << v;
  }
  {
    std::vector<double> wide = r;
    wide[3] = kCoarse * 0.5e-6;  // a factor 2e6
    EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, wide.data(), n, 0), NBMC_ERROR_INVALID_PARAMETER);
    EXPECT_NE(ctx.error().find("factor 1e6"), std::string::npos) << ctx.error();
    wide[3] = kCoarse * 2e-6;  // 5e5: accepted
    EXPECT_EQ(nbmc_context_set_radii_f64(ctx.c, wide.data(), n, 0), NBMC_OK) << ctx.error();
  }
  // Device pointers need the CUDA backend.
  EXPECT_EQ(nbmc_context_set_radii_device_f32(ctx.c, rf.data(), n, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  EXPECT_EQ(nbmc_context_set_radii_device_f64(ctx.c, r.data(), n, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  // After the failures the context has no radii: the uniform mesh.
  const nbmc_params prm = params(kCoarse);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  const Outcome plain = run(p, nullptr, prm);
  ASSERT_EQ(nbmc_mesh_vertex_count(m), plain.mesh.vertex_count());
  EXPECT_EQ(std::memcmp(nbmc_mesh_positions(m), plain.mesh.positions.data(), plain.mesh.positions.size() * 4), 0);
  nbmc_mesh_destroy(m);
}

namespace {

class RadiiCli : public nbmc_test::CliFixture {
 protected:
  RadiiCli() : CliFixture("nbmc_radii_cli_") {}
  // The two-resolution frame as an ASCII PLY point cloud with a property h,
  // half the radius (as a smoothing length to scale), and a vector v.
  void write_frame(const Frame& f, const std::string& name, double h_of_radius = 0.5) const {
    std::ofstream out(path(name));
    const std::size_t n = f.radii.size();
    out << "ply\nformat ascii 1.0\nelement vertex " << n
        << "\nproperty double x\nproperty double y\nproperty double z\nproperty double h\n"
           "property float vx\nproperty float vy\nproperty float vz\nend_header\n";
    out.precision(17);
    for (std::size_t i = 0; i < n; ++i)
      out << f.xyz[3 * i] << ' ' << f.xyz[3 * i + 1] << ' ' << f.xyz[3 * i + 2] << ' ' << f.radii[i] * h_of_radius
          << " 0 0 0\n";
  }
  // The vertices of a PLY mesh the CLI wrote (read back as a point cloud).
  std::vector<double> vertices(const std::string& name) const {
    return nbmc::io::read_particles(path(name), "ply").xyz;
  }
};

}  // namespace

TEST_F(RadiiCli, RadiusAttributeGivesTheApiMesh) {
  const Frame f = two_resolutions();
  write_frame(f, "frame.ply");
  const nbmc_params prm = two_resolution_params(NBMC_METHOD_SSP07, 2);
  const Outcome api = ::run(f.xyz, &f.radii, prm);
  ASSERT_EQ(api.status, NBMC_OK) << api.error;
  const std::vector<double> expect(api.mesh.positions.begin(), api.mesh.positions.end());
  // --spacing given: the lengths of a particle of radius 0.1; and without it,
  // the largest radius (0.1 too). --cell-size is relative to the spacing.
  for (const std::string spacing : {"--spacing 0.1 ", ""}) {
    const auto r = run("reconstruct frame.ply -o mesh.ply " + spacing +
                       "--cell-size 0.5 --radius-attribute h --radius-scale 2 -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(vertices("mesh.ply"), expect) << spacing;
  }
}

TEST_F(RadiiCli, BadRadiusAttributes) {
  const Frame f = two_resolutions();
  write_frame(f, "frame.ply");
  auto r = run("reconstruct frame.ply -o m.ply --radius-attribute nope -q");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(nbmc_test::contains(r.err, "no particle attribute 'nope'")) << r.err;
  r = run("reconstruct frame.ply -o m.ply --radius-attribute h --radius-scale 0 -q");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  r = run("reconstruct frame.ply -o m.ply --radius-attribute v -q");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(nbmc_test::contains(r.err, "radii need a scalar attribute")) << r.err;
  r = run("reconstruct frame.ply -o m.ply -q");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(nbmc_test::contains(r.err, "--radius-attribute")) << r.err;
  Frame bad = f;
  bad.radii[3] = -1;
  write_frame(bad, "bad.ply");
  r = run("reconstruct bad.ply -o m.ply --radius-attribute h -q");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(nbmc_test::contains(r.err, "invalid parameter")) << r.err;
  EXPECT_TRUE(nbmc_test::contains(r.err, "first at particle 3")) << r.err;
}
