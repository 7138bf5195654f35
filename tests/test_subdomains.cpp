// SPDX-License-Identifier: MIT
// Subdomains (one frame in pieces, stitched): the mesh must be the one the
// whole frame gives, bit for bit (positions, normals, triangles in order),
// for any split, cell size, method and band width; the band growth that
// crosses subdomain faces must be exchanged (cases built so that it does);
// `auto` splits only over the budget; bad settings fail cleanly.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <array>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace {

using nbmc_test::Points;

struct Outcome {
  nbmc_test::Mesh mesh;
  nbmc_subdomain_stats sub{};
  std::vector<nbmc_subdomain_entry> entries;
  int32_t status = NBMC_OK;
  std::string error;
};

Outcome run(const Points& pts, const nbmc_params& prm, int nx, int ny, int nz, std::uint64_t budget = 0,
        int32_t backend = NBMC_BACKEND_OPENMP) {
  Outcome r;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = backend;
  d.num_threads = 2;
  nbmc_context* ctx = nullptr;
  EXPECT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_subdomains(ctx, nx, ny, nz), NBMC_OK);
  if (budget) nbmc_context_set_memory_budget(ctx, budget);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx, pts.data(), pts.size() / 3, 0), NBMC_OK);
  nbmc_mesh* m = nullptr;
  r.status = nbmc_context_reconstruct(ctx, &prm, &m);
  if (r.status != NBMC_OK) {
    r.error = nbmc_context_last_error(ctx);
    nbmc_context_destroy(ctx);
    return r;
  }
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  r.mesh.positions.assign(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nv);
  if (nbmc_mesh_normals(m)) r.mesh.normals.assign(nbmc_mesh_normals(m), nbmc_mesh_normals(m) + 3 * nv);
  r.mesh.triangles.assign(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nt);
  nbmc_mesh_destroy(m);
  nbmc_subdomain_stats_init(&r.sub);
  EXPECT_EQ(nbmc_context_subdomain_stats(ctx, &r.sub), NBMC_OK);
  for (std::uint64_t i = 0; i < r.sub.count; ++i) {
    nbmc_subdomain_entry e;
    nbmc_subdomain_entry_init(&e);
    EXPECT_EQ(nbmc_context_subdomain_entry(ctx, i, &e), NBMC_OK);
    r.entries.push_back(e);
  }
  nbmc_context_destroy(ctx);
  return r;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

// The whole frame and a split must give the same mesh, bit for bit.
void expect_identical(const Points& pts, const nbmc_params& prm, int nx, int ny, int nz, Outcome* out = nullptr) {
  const Outcome whole = run(pts, prm, 1, 1, 1);
  ASSERT_EQ(whole.status, NBMC_OK) << whole.error;
  EXPECT_EQ(whole.sub.count, 0u);
  const Outcome split = run(pts, prm, nx, ny, nz);
  ASSERT_EQ(split.status, NBMC_OK) << split.error;
  EXPECT_EQ(split.sub.count, std::uint64_t(split.sub.parts[0]) * split.sub.parts[1] * split.sub.parts[2]);
  ASSERT_GT(whole.mesh.triangles.size(), 0u);
  EXPECT_TRUE(same_bits(whole.mesh.positions, split.mesh.positions))
      << nx << "x" << ny << "x" << nz << ": positions differ (" << whole.mesh.positions.size() << " vs "
      << split.mesh.positions.size() << " floats)";
  EXPECT_TRUE(same_bits(whole.mesh.normals, split.mesh.normals)) << "normals differ";
  EXPECT_TRUE(same_bits(whole.mesh.triangles, split.mesh.triangles)) << "triangles differ";
  const nbmc_test::MeshReport rep = nbmc_test::check_mesh(split.mesh);
  EXPECT_TRUE(rep.closed && rep.edge_manifold && rep.vertex_manifold && rep.oriented);
  if (out) *out = split;
}

Points jittered_blob(unsigned seed, double r) {
  // A lumpy blob: a sphere and a box, particles jittered by 0.2 r.
  const double lo[3] = {-0.4, -0.3, -0.35}, hi[3] = {0.3, 0.25, 0.3};
  Points p = nbmc_test::concat(nbmc_test::sphere(0.35, 0.1, 0.0, 0.35, r), nbmc_test::box(lo, hi, r));
  std::mt19937 g(seed);
  std::uniform_real_distribution<double> u(-0.2 * r, 0.2 * r);
  for (double& x : p) x += u(g);
  return p;
}

TEST(Subdomains, ShapesAreIdenticalForEverySplit) {
  const double r = 0.05;
  const Points p = jittered_blob(1, r);
  for (double cell : {1.0, 0.5}) {
    nbmc_params prm = nbmc_test::params(r);
    prm.cell_size = cell;
    for (const auto& s : std::vector<std::array<int, 3>>{{2, 1, 1}, {1, 2, 1}, {1, 1, 3}, {2, 2, 2}, {3, 3, 3}}) {
      SCOPED_TRACE("cell " + std::to_string(cell) + ", " + std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" +
                   std::to_string(s[2]));
      expect_identical(p, prm, s[0], s[1], s[2]);
    }
  }
}

// Influence radii below twice the surface radius: neighbour cells as wide as
// the surface radius, not R/2 (src/core/grid.hpp), and the ghosts they imply.
TEST(Subdomains, SmallInfluenceRadii) {
  const double r = 0.05;
  const Points p = jittered_blob(3, r);
  for (double R : {2.0, 3.0}) {
    nbmc_params prm = nbmc_test::params(r);
    prm.influence_radius = R;
    for (const auto& s : std::vector<std::array<int, 3>>{{2, 1, 1}, {2, 2, 2}, {3, 3, 3}}) {
      SCOPED_TRACE("R " + std::to_string(R) + ", " + std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" +
                   std::to_string(s[2]));
      expect_identical(p, prm, s[0], s[1], s[2]);
    }
  }
}

// The stitching merges key ranges in parallel on large meshes; force many
// ranges on these small ones (ranges end inside pieces and at shared keys).
TEST(Subdomains, ParallelStitchingRanges) {
  const double r = 0.05;
  const Points p = jittered_blob(6, r);
  nbmc_params prm = nbmc_test::params(r);
  for (const char* ranges : {"2", "7", "64"}) {
    SCOPED_TRACE(std::string("NBMC_STITCH_RANGES=") + ranges);
    setenv("NBMC_STITCH_RANGES", ranges, 1);
    expect_identical(p, prm, 3, 2, 2);
    unsetenv("NBMC_STITCH_RANGES");
  }
}

TEST(Subdomains, Zb05AndNoNormalsAndNoCleanup) {
  const double r = 0.05;
  const Points p = jittered_blob(2, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.method = NBMC_METHOD_ZB05;
  expect_identical(p, prm, 2, 3, 1);
  prm = nbmc_test::params(r);
  prm.compute_normals = 0;
  prm.cleanup = 0;
  expect_identical(p, prm, 3, 1, 2);
}

// The SPH density needs each particle's own density, a sum over R around
// it: the ghost layer is 2R wide, and a split gives the same mesh. Also with
// a small kernel (splashsurf's usual -l 2, R = 2r) and on a lattice.
TEST(Subdomains, SphDensity) {
  const double r = 0.05;
  const Points p = jittered_blob(4, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.method = NBMC_METHOD_SPH;
  for (const auto& s : std::vector<std::array<int, 3>>{{2, 1, 1}, {1, 3, 1}, {2, 2, 2}}) {
    SCOPED_TRACE(std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" + std::to_string(s[2]));
    expect_identical(p, prm, s[0], s[1], s[2]);
  }
  prm.influence_radius = 2;
  prm.iso_threshold = 0.5;
  expect_identical(p, prm, 3, 2, 2);
  const double lo[3] = {0, 0, 0}, hi[3] = {0.8, 0.6, 0.7};
  prm.cell_size = 1;
  expect_identical(nbmc_test::box(lo, hi, r), prm, 4, 3, 2);
}

// YT10's kernels need each particle's neighbours within R (its covariance,
// density and smoothed centre): the ghost layer is 2R wide, and a split
// gives the same mesh, though each subdomain narrows the field's radius to
// its own largest kernel (field_yt10.hpp). Also with a small kernel, with
// strong smoothing, and on a lattice (neighbours at exactly R).
TEST(Subdomains, Yt10AnisotropicKernels) {
  const double r = 0.05;
  const Points p = jittered_blob(4, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.method = NBMC_METHOD_YT10;
  for (const auto& s : std::vector<std::array<int, 3>>{{2, 1, 1}, {1, 3, 1}, {2, 2, 2}}) {
    SCOPED_TRACE(std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" + std::to_string(s[2]));
    expect_identical(p, prm, s[0], s[1], s[2]);
  }
  prm.influence_radius = 3;
  prm.aniso_lambda = 1;
  prm.aniso_neighbours = 10;
  expect_identical(p, prm, 3, 2, 2);
  const double lo[3] = {0, 0, 0}, hi[3] = {0.8, 0.6, 0.7};
  prm.cell_size = 1;
  expect_identical(nbmc_test::box(lo, hi, r), prm, 4, 3, 2);
}

// Isolated particles dropped before the split: the same mesh for any split.
TEST(Subdomains, IsolatedDropped) {
  const double r = 0.05;
  Points p = jittered_blob(5, r);
  p.insert(p.end(), {0.9, 0.6, 0.6, 0.92, 0.6, 0.6, -0.9, -0.6, 0.5});  // a pair and a lone particle
  nbmc_params prm = nbmc_test::params(r);
  prm.isolated = NBMC_ISOLATED_DROP;
  prm.min_cluster = 3;
  expect_identical(p, prm, 2, 2, 1);
}

// A regular lattice puts particles and surface crossings exactly on the
// grid vertices and cell faces where subdomains meet.
TEST(Subdomains, FacesThroughParticlesAndGridVertices) {
  const double r = 0.05;
  const double lo[3] = {0, 0, 0}, hi[3] = {0.8, 0.6, 0.7};
  const Points p = nbmc_test::box(lo, hi, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.cell_size = 1;
  expect_identical(p, prm, 4, 3, 2);
  prm.cell_size = 0.5;
  expect_identical(p, prm, 2, 2, 2);
}

// A thin band makes the surface leave it often: the band grows, and the
// growth crosses subdomain faces. The split must exchange those cells, run
// the neighbours again, and still give the same mesh.
TEST(Subdomains, BandGrowthAcrossFacesIsExchanged) {
  const double r = 0.05;
  const Points p = jittered_blob(3, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.band_width = 0.6;
  prm.cleanup = 0;
  Outcome split;
  expect_identical(p, prm, 3, 3, 3, &split);
  EXPECT_GT(split.sub.exchanged_cells, 0u);
  EXPECT_GT(split.sub.reruns, 0u);
  EXPECT_GT(split.sub.shared_vertices, 0u);
  std::uint64_t particles = 0, runs = 0;
  for (const auto& e : split.entries) {
    particles += e.particles;
    runs += e.runs;
  }
  EXPECT_EQ(particles, p.size() / 3);  // every particle owned by exactly one subdomain
  EXPECT_EQ(runs, split.sub.count + split.sub.reruns);
}

TEST(Subdomains, EmptySubdomainsAndMoreSubdomainsThanCells) {
  const double r = 0.05;
  // Two far-apart spheres: most subdomains of a 5x1x1 split are empty.
  const Points p = nbmc_test::concat(nbmc_test::sphere(0, 0, 0, 0.2, r), nbmc_test::sphere(3, 0, 0, 0.2, r));
  nbmc_params prm = nbmc_test::params(r);
  Outcome split;
  expect_identical(p, prm, 5, 1, 1, &split);
  int empty = 0;
  for (const auto& e : split.entries) empty += e.particles == 0 && e.triangle_count == 0;
  EXPECT_GE(empty, 2);
  // More subdomains than cells along an axis: reduced to one cell each.
  const Points tiny = nbmc_test::sphere(0, 0, 0, 0.1, r);
  prm.cell_size = 1;
  Outcome t;
  expect_identical(tiny, prm, 4000, 1, 1, &t);
  EXPECT_LT(t.sub.parts[0], 4000);
}

TEST(Subdomains, ClippingBox) {
  const double r = 0.05;
  const Points p = jittered_blob(4, r);
  nbmc_params prm = nbmc_test::params(r);
  prm.use_bbox = 1;
  const double lo[3] = {-0.2, -0.2, -0.5}, hi[3] = {0.5, 0.3, 0.1};
  for (int a = 0; a < 3; ++a) {
    prm.bbox_min[a] = lo[a];
    prm.bbox_max[a] = hi[a];
  }
  const Outcome whole = run(p, prm, 1, 1, 1), split = run(p, prm, 2, 2, 2);
  ASSERT_EQ(split.status, NBMC_OK) << split.error;
  EXPECT_TRUE(same_bits(whole.mesh.positions, split.mesh.positions));
  EXPECT_TRUE(same_bits(whole.mesh.triangles, split.mesh.triangles));
  // A box with no particle: the same error as without subdomains.
  for (int a = 0; a < 3; ++a) {
    prm.bbox_min[a] = 10;
    prm.bbox_max[a] = 11;
  }
  EXPECT_EQ(run(p, prm, 2, 2, 2).status, NBMC_ERROR_NO_PARTICLES);
}

TEST(Subdomains, AutoSplitsOnlyOverTheBudget) {
  const double r = 0.05;
  const Points p = jittered_blob(5, r);
  nbmc_params prm = nbmc_test::params(r);
  const Outcome whole = run(p, prm, 1, 1, 1);
  // No budget on a CPU context: nothing to size for, the frame stays whole.
  const Outcome unlimited = run(p, prm, NBMC_SUBDOMAINS_AUTO, 0, 0);
  ASSERT_EQ(unlimited.status, NBMC_OK);
  EXPECT_EQ(unlimited.sub.count, 0u);
  // A small budget: split, the same mesh, and the budget reported.
  const std::uint64_t budget = 48u << 20;
  const Outcome small = run(p, prm, NBMC_SUBDOMAINS_AUTO, 0, 0, budget);
  ASSERT_EQ(small.status, NBMC_OK) << small.error;
  EXPECT_GT(small.sub.count, 1u);
  EXPECT_EQ(small.sub.automatic, 1u);
  EXPECT_EQ(small.sub.budget_bytes, budget);
  EXPECT_TRUE(same_bits(whole.mesh.positions, small.mesh.positions));
  EXPECT_TRUE(same_bits(whole.mesh.triangles, small.mesh.triangles));
}

// A per-run size limit (on a GPU: 2^31 band vertex slots; here lowered with
// the test hook NBMC_MAX_BAND_BLOCKS) stops a whole run with
// NBMC_ERROR_DOMAIN_TOO_LARGE and the figures, before the field is
// evaluated; the context stays usable, and `auto` splits the frame instead,
// with the whole frame's mesh.
TEST(Subdomains, BandSizeLimitFailsCleanlyAndAutoSplits) {
  const double r = 0.05;
  const Points p = jittered_blob(9, r);
  nbmc_params prm = nbmc_test::params(r);
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_OPENMP;
  d.num_threads = 2;
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK);
  nbmc_test::Mesh whole;
  whole.positions.assign(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nbmc_mesh_vertex_count(m));
  whole.triangles.assign(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nbmc_mesh_triangle_count(m));
  nbmc_mesh_destroy(m);
  nbmc_stats st;
  nbmc_stats_init(&st);
  ASSERT_EQ(nbmc_context_stats(ctx, &st), NBMC_OK);
  ASSERT_GT(st.band_block_count, 4u);
  const std::string limit = std::to_string(st.band_block_count * 7 / 10);
  setenv("NBMC_MAX_BAND_BLOCKS", limit.c_str(), 1);
  m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_ERROR_DOMAIN_TOO_LARGE);
  EXPECT_EQ(m, nullptr);
  const std::string msg = nbmc_context_last_error(ctx);
  EXPECT_NE(msg.find(std::to_string(st.band_block_count) + " blocks"), std::string::npos) << msg;
  EXPECT_NE(msg.find("at most " + limit), std::string::npos) << msg;
  EXPECT_NE(msg.find("--subdomains auto"), std::string::npos) << msg;
  // The same context, `auto`: no budget on this CPU context, but the limit
  // makes it split.
  ASSERT_EQ(nbmc_context_set_subdomains(ctx, NBMC_SUBDOMAINS_AUTO, 0, 0), NBMC_OK);
  const int32_t status = nbmc_context_reconstruct(ctx, &prm, &m);
  unsetenv("NBMC_MAX_BAND_BLOCKS");
  ASSERT_EQ(status, NBMC_OK) << nbmc_context_last_error(ctx);
  nbmc_subdomain_stats sub;
  nbmc_subdomain_stats_init(&sub);
  ASSERT_EQ(nbmc_context_subdomain_stats(ctx, &sub), NBMC_OK);
  EXPECT_GE(sub.count, 2u);
  EXPECT_EQ(sub.automatic, 1u);
  std::vector<float> pos(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nbmc_mesh_vertex_count(m));
  std::vector<std::uint32_t> tri(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nbmc_mesh_triangle_count(m));
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
  EXPECT_TRUE(same_bits(whole.positions, pos));
  EXPECT_TRUE(same_bits(whole.triangles, tri));
}

TEST(Subdomains, BadSettings) {
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_SERIAL;
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_subdomains(ctx, 0, 1, 1), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_NE(std::string(nbmc_context_last_error(ctx)).find("subdomains"), std::string::npos);
  EXPECT_EQ(nbmc_context_set_subdomains(ctx, 2, -3, 1), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_subdomains(ctx, 1000, 1000, 1000), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_set_subdomains(nullptr, 2, 2, 2), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_subdomain_stats s;
  nbmc_subdomain_stats_init(&s);
  EXPECT_EQ(nbmc_context_subdomain_stats(ctx, &s), NBMC_ERROR_NO_PARTICLES);
  s.struct_size = 4;
  EXPECT_EQ(nbmc_context_subdomain_stats(ctx, &s), NBMC_ERROR_INVALID_ARGUMENT);
  // The baselines cannot be split.
  ASSERT_EQ(nbmc_context_set_subdomains(ctx, 2, 1, 1), NBMC_OK);
  const Points p = nbmc_test::sphere(0, 0, 0, 0.2, 0.05);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_params prm = nbmc_test::params(0.05);
  prm.field = NBMC_FIELD_DENSE;
  nbmc_mesh* m = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_ERROR_INVALID_PARAMETER);
  EXPECT_EQ(m, nullptr);
  // The context stays usable.
  prm.field = NBMC_FIELD_NARROW_BAND;
  EXPECT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK);
  nbmc_subdomain_entry e;
  nbmc_subdomain_entry_init(&e);
  EXPECT_EQ(nbmc_context_subdomain_entry(ctx, 2, &e), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_context_subdomain_entry(ctx, 1, &e), NBMC_OK);
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
}

// Real frames of ../shared/data (skipped where absent).
struct Frame {
  const char* file;
  double spacing;
};
class RealFrames : public ::testing::TestWithParam<Frame> {};

TEST_P(RealFrames, IdenticalAtCellsROverOneAndTwo) {
  const std::string f = std::string(NBMC_DATA_DIR) + "/xyz/" + GetParam().file;
  if (!std::ifstream(f)) GTEST_SKIP() << f << " not present";
  const Points p = nbmc_test::read_xyz(f);
  for (double cell : {1.0, 0.5}) {
    nbmc_params prm = nbmc_test::params(GetParam().spacing);
    prm.cell_size = cell;
    for (const auto& s : std::vector<std::array<int, 3>>{{2, 1, 1}, {3, 3, 3}}) {
      SCOPED_TRACE(std::string(GetParam().file) + " cell " + std::to_string(cell) + " split " +
                   std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" + std::to_string(s[2]));
      expect_identical(p, prm, s[0], s[1], s[2]);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(SharedData, RealFrames,
                         ::testing::Values(Frame{"splashsurf_dambreak_f23_24389.xyz", 0.05},
                                           Frame{"cbd46k_t050_46250.xyz", 0.0156}),
                         [](const auto& info) {
                           std::string n = info.param.file;
                           return n.substr(0, n.find('.'));
                         });

}  // namespace
