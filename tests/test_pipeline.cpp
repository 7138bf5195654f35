// SPDX-License-Identifier: MIT
// The narrow band against the paper's two baselines, determinism, memory
// that follows the particles, and the real frames of shared/data.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <random>
#include <set>

using namespace nbmc_test;

namespace {

// A blobby, splashy test body: a box of fluid, a sphere above it and a few
// isolated droplets (so surface particles of both kinds occur).
Points blob(double r) {
  const double lo[3] = {-0.6, -0.4, -0.3}, hi[3] = {0.6, 0.4, 0.0};
  Points p = box(lo, hi, r);
  p = concat(p, sphere(0.1, 0.0, 0.35, 0.25, r));
  const double drops[][3] = {{0.8, 0.5, 0.6}, {-0.7, 0.3, 0.5}, {0.83, 0.5, 0.62}};
  for (const auto& d : drops) p.insert(p.end(), {d[0], d[1], d[2]});
  return p;
}

void expect_identical(const Result& a, const Result& b, const char* what) {
  ASSERT_EQ(a.status, NBMC_OK) << a.message;
  ASSERT_EQ(b.status, NBMC_OK) << b.message;
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles) << what;
  EXPECT_EQ(a.mesh.positions, b.mesh.positions) << what;  // bitwise
  EXPECT_EQ(a.mesh.normals, b.mesh.normals) << what;
}

std::string frame(const char* name) { return std::string(NBMC_DATA_DIR) + "/xyz/" + name; }
bool have(const std::string& path) { return std::ifstream(path).good(); }

}  // namespace

TEST(Baselines, NarrowBandEqualsDenseWhereBothTriangulate) {
  const double r = 0.05;
  for (double cell : {0.5, 1.0}) {
    nbmc_params nb = params(r), dense = params(r);
    nb.cell_size = dense.cell_size = cell;
    dense.field = NBMC_FIELD_DENSE;
    const Points p = blob(r);
    const Result a = reconstruct(p, nb), b = reconstruct(p, dense);
    ASSERT_EQ(a.status, NBMC_OK) << a.message;
    ASSERT_EQ(b.status, NBMC_OK) << b.message;
    EXPECT_LT(a.stats.band_vertex_count, b.stats.band_vertex_count / 2) << "the band should be much smaller";
    const std::set<Tri> in_dense = triangle_set(b.mesh);
    std::size_t missing = 0;
    for (const Tri& t : triangle_set(a.mesh)) missing += in_dense.count(t) ? 0 : 1;
    EXPECT_EQ(missing, 0u) << "narrow-band triangles not produced identically by the dense baseline (cell " << cell << ")";
    // Both cover the same surface: the dense grid may add only closed inner pockets.
    EXPECT_GE(a.mesh.triangle_count(), b.mesh.triangle_count() * 99 / 100);
    EXPECT_TRUE(check_mesh(a.mesh).closed);
    EXPECT_TRUE(check_mesh(b.mesh).closed);
  }
}

TEST(Baselines, ScatterAndGatherFieldsAgree) {
  const double r = 0.05;
  for (int method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    nbmc_params gather = params(r), scatter = params(r);
    gather.field = NBMC_FIELD_DENSE;
    scatter.field = NBMC_FIELD_SCATTER;
    gather.method = scatter.method = method;
    // The raw meshes: the clean-up's choices (angles against 1 degree) can
    // flip on the last bit of a position.
    gather.cleanup = scatter.cleanup = 0;
    const Points p = blob(r);
    const Result a = reconstruct(p, gather), b = reconstruct(p, scatter);
    ASSERT_EQ(a.status, NBMC_OK) << a.message;
    ASSERT_EQ(b.status, NBMC_OK) << b.message;
    // Same grid, same vertex order: the sums differ only in order (float
    // rounding), so the meshes agree to well below a cell.
    ASSERT_EQ(a.mesh.triangles, b.mesh.triangles);
    ASSERT_EQ(a.mesh.positions.size(), b.mesh.positions.size());
    double worst = 0;
    for (std::size_t i = 0; i < a.mesh.positions.size(); ++i)
      worst = std::max(worst, double(std::fabs(a.mesh.positions[i] - b.mesh.positions[i])));
    EXPECT_LT(worst, 1e-3 * 0.5 * r);
  }
}

TEST(Determinism, SameMeshOnOneTwoFourThreadsAndSerial) {
  const double r = 0.05;
  const Points p = blob(r);
  const Result one = reconstruct(p, params(r), NBMC_BACKEND_OPENMP, 1);
  expect_identical(one, reconstruct(p, params(r), NBMC_BACKEND_OPENMP, 2), "2 threads");
  expect_identical(one, reconstruct(p, params(r), NBMC_BACKEND_OPENMP, 4), "4 threads");
  expect_identical(one, reconstruct(p, params(r), NBMC_BACKEND_SERIAL, 0), "serial backend");
}

TEST(Determinism, RealFrameOnOneTwoFourThreads) {
  const std::string f = frame("cbd46k_t050_46250.xyz");
  if (!have(f)) GTEST_SKIP() << f << " not present";
  const Points p = read_xyz(f);
  nbmc_params prm = params(0.0156);
  prm.cell_size = 1.0;
  const Result one = reconstruct(p, prm, NBMC_BACKEND_OPENMP, 1);
  expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_OPENMP, 2), "2 threads");
  expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_OPENMP, 4), "4 threads");
}

TEST(Determinism, ShuffledParticleOrderGivesTheSameMesh) {
  const double r = 0.05;
  const Points p = blob(r);
  std::vector<std::size_t> order(p.size() / 3);
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(42);
  std::shuffle(order.begin(), order.end(), rng);
  Points q;
  for (std::size_t i : order) q.insert(q.end(), {p[3 * i], p[3 * i + 1], p[3 * i + 2]});
  expect_identical(reconstruct(p, params(r)), reconstruct(q, params(r)), "shuffled");
}

TEST(Memory, TwoClumpsFarApartCostWhatTheirParticlesCost) {
  // Two spheres 10,000 cells apart: the bounding grid has ~29 million
  // vertices, but nothing is allocated per vertex or cell of the bounding
  // box. Stated bound: peak memory of nbmc's own allocations <= 1 KiB per
  // particle, and at most 3x that of one clump alone (measured: 333 B per
  // particle and 2.3x).
  const double r = 0.1;
  const nbmc_params prm = params(r);
  const Points a = sphere(0, 0, 0, 1.0, r);
  const Points far = concat(a, sphere(10000 * 0.5 * r, 0, 0, 1.0, r));
  const Result one = reconstruct(a, prm), two = reconstruct(far, prm);
  ASSERT_EQ(one.status, NBMC_OK) << one.message;
  ASSERT_EQ(two.status, NBMC_OK) << two.message;
  EXPECT_GT(two.stats.grid_vertex_count, 20'000'000u);
  EXPECT_EQ(two.mesh.triangle_count(), 2 * one.mesh.triangle_count());
  EXPECT_LE(two.stats.peak_memory_bytes, 1024u * (far.size() / 3));
  EXPECT_LE(two.stats.peak_memory_bytes, 3 * one.stats.peak_memory_bytes);
  EXPECT_GT(two.stats.peak_memory_bytes, 0u);
}

// Real SPH frames: closed, manifold, oriented meshes with triangle counts in
// a band of +-3% around the counts measured when this test was written.
struct FrameCase {
  const char* file;
  double spacing, cell;
  std::size_t triangles;
};

class RealFrames : public ::testing::TestWithParam<FrameCase> {};

TEST_P(RealFrames, ClosedManifoldWithExpectedTriangleCount) {
  const FrameCase& c = GetParam();
  const std::string f = frame(c.file);
  if (!have(f)) GTEST_SKIP() << f << " not present";
  nbmc_params prm = params(c.spacing);
  prm.cell_size = c.cell;
  const Result run = reconstruct(read_xyz(f), prm);
  ASSERT_EQ(run.status, NBMC_OK) << run.message;
  const MeshReport rep = check_mesh(run.mesh);
  EXPECT_TRUE(rep.closed) << rep.summary();
  EXPECT_TRUE(rep.vertex_manifold) << rep.summary();
  EXPECT_TRUE(rep.oriented) << rep.summary();
  EXPECT_EQ(rep.degenerate_triangles, 0u);
  EXPECT_GT(rep.volume, 0);
  EXPECT_GE(run.mesh.triangle_count(), c.triangles * 97 / 100);
  EXPECT_LE(run.mesh.triangle_count(), c.triangles * 103 / 100);
}

INSTANTIATE_TEST_SUITE_P(
    SharedData, RealFrames,
    ::testing::Values(FrameCase{"splashsurf_doubledambreak_f26_4732.xyz", 0.05, 0.5, 75572},
                      FrameCase{"splashsurf_bunny_f14_7706.xyz", 0.05, 0.5, 31112},
                      FrameCase{"splashsurf_dambreak_f23_24389.xyz", 0.05, 0.5, 93296},
                      FrameCase{"cbd46k_t050_46250.xyz", 0.0156, 0.5, 167712},
                      FrameCase{"cbd292k_t040_292008.xyz", 0.0086, 1.0, 106676},
                      FrameCase{"cbd950k_t040_950232.xyz", 0.0058, 1.0, 251732},
                      FrameCase{"cbd1654k_t040_1654104.xyz", 0.00484, 1.0, 411491}),
    [](const ::testing::TestParamInfo<FrameCase>& i) {
      std::string s = i.param.file;
      s = s.substr(0, s.find('.'));
      for (char& ch : s)
        if (!isalnum(static_cast<unsigned char>(ch))) ch = '_';
      return s;
    });

// The surface particles are defined by the surface radius and the thresholds,
// not by the influence radius R: the same count at R = 2r, 2.5r, 3r and 4r
// (the neighbour cells are then all as wide as the surface radius). At
// R = 2r nbmc used to judge empty neighbour cells on cells of R/2 = r, one
// particle wide, and marked most of a fluid's inside as surface.
namespace {
std::vector<std::uint64_t> surface_counts(const Points& p, double r, double cell) {
  std::vector<std::uint64_t> counts;
  for (double R : {2.0, 2.5, 3.0, 4.0}) {
    nbmc_params prm = params(r);
    prm.cell_size = cell;
    prm.influence_radius = R;
    const Result run = reconstruct(p, prm);
    EXPECT_EQ(run.status, NBMC_OK) << run.message;
    counts.push_back(run.stats.surface_particle_count);
  }
  return counts;
}
}  // namespace

TEST(SurfaceParticles, IndependentOfTheInfluenceRadiusOnALatticeBlock) {
  // A jittered 30^3 block: a free surface on all sides, 27,000 particles, of
  // which about the outer layer (5,048 particles) is surface.
  const double r = 0.05;
  const double lo[3] = {-0.7, -0.7, -0.7}, hi[3] = {-0.7 + 29.5 * r, -0.7 + 29.5 * r, -0.7 + 29.5 * r};
  Points p = box(lo, hi, r);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.15 * r, 0.15 * r);
  for (double& x : p) x += u(rng);
  ASSERT_EQ(p.size() / 3, 27000u);
  const std::vector<std::uint64_t> c = surface_counts(p, r, 1.0);
  for (std::size_t i = 1; i < c.size(); ++i) EXPECT_EQ(c[i], c[0]) << "influence radius #" << i;
  EXPECT_GT(c[0], 4000u);       // the outer layer
  EXPECT_LT(c[0], 27000u / 2);  // not the inside
}

TEST(SurfaceParticles, IndependentOfTheInfluenceRadiusOnARealFrame) {
  const std::string f = frame("cbd46k_t050_46250.xyz");
  if (!have(f)) GTEST_SKIP() << f << " not present";
  const std::vector<std::uint64_t> c = surface_counts(read_xyz(f), 0.0156, 1.0);
  for (std::size_t i = 1; i < c.size(); ++i) EXPECT_EQ(c[i], c[0]) << "influence radius #" << i;
  EXPECT_LT(c[0], 46250u / 2);
}

// The host field kernel runs 16 lanes (AVX-512F), 8 (AVX2), chosen at run
// time, or 4 (NBMC_HOST_SIMD=16|8|4 asks for one): every lane does the
// scalar operations, so the meshes are the same bit for bit.
namespace {
std::vector<std::pair<Points, nbmc_params>> lane_cases() {
  std::vector<std::pair<Points, nbmc_params>> cases;
  const double r = 0.05;
  for (double R : {4.0, 2.0}) {
    nbmc_params prm = params(r);
    prm.influence_radius = R;
    cases.emplace_back(blob(r), prm);
    prm.method = NBMC_METHOD_ZB05;
    cases.emplace_back(blob(r), prm);
  }
  const std::string f = frame("cbd46k_t050_46250.xyz");
  if (have(f)) {
    nbmc_params prm = params(0.0156);
    prm.cell_size = 0.5;
    cases.emplace_back(read_xyz(f), prm);
  }
  return cases;
}

// The meshes with NBMC_HOST_SIMD=a and =b.
void expect_same_mesh_with_lanes(const char* a, const char* b) {
  for (const auto& c : lane_cases()) {
    setenv("NBMC_HOST_SIMD", a, 1);
    const Result ra = reconstruct(c.first, c.second);
    setenv("NBMC_HOST_SIMD", b, 1);
    const Result rb = reconstruct(c.first, c.second);
    unsetenv("NBMC_HOST_SIMD");
    expect_identical(ra, rb, (std::string(a) + " vs " + b + " lanes").c_str());
    EXPECT_EQ(ra.stats.neighbour_evaluations, rb.stats.neighbour_evaluations);
  }
}
}  // namespace

TEST(HostSimd, FourAndEightLanesGiveTheSameMesh) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "no AVX2 on this CPU: 4 lanes only";
#else
  GTEST_SKIP() << "8 lanes are an x86-64 path";
#endif
  expect_same_mesh_with_lanes("4", "8");
}

TEST(HostSimd, EightAndSixteenLanesGiveTheSameMesh) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (!__builtin_cpu_supports("avx512f")) GTEST_SKIP() << "no AVX-512F on this CPU: at most 8 lanes";
#else
  GTEST_SKIP() << "16 lanes are an x86-64 path";
#endif
  expect_same_mesh_with_lanes("8", "16");
  expect_same_mesh_with_lanes("4", "16");
}
