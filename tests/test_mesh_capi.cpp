// SPDX-License-Identifier: MIT
// Mesh post-processing through the C API: nbmc_mesh_check on reconstructed
// shapes (agrees with the tests' own checker), the clean-up (on by default,
// off with cleanup = 0) on random-jittered lattices, smoothing and the
// fairing flips after it, and the ABI's handling of structs from callers built before the
// fields were appended.
#include "nbmc_test.hpp"
#include "../src/core/mesh_memory.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace {

using nbmc_test::Points;

// One context for many reconstructions (OpenMP, 2 threads).
struct Context {
  nbmc_context* ctx = nullptr;
  explicit Context(int32_t backend = NBMC_BACKEND_OPENMP, int threads = 2) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = backend;
    d.num_threads = threads;
    EXPECT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  }
  ~Context() { nbmc_context_destroy(ctx); }
  nbmc_mesh* run(const Points& p, const nbmc_params& prm) {
    EXPECT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
    nbmc_mesh* m = nullptr;
    EXPECT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(ctx);
    return m;
  }
};

nbmc_mesh_check_result check(const nbmc_mesh* m) {
  nbmc_mesh_check_result r;
  nbmc_mesh_check_result_init(&r);
  EXPECT_EQ(nbmc_mesh_check(m, &r), NBMC_OK);
  return r;
}

nbmc_test::Mesh copy(const nbmc_mesh* m) {
  nbmc_test::Mesh out;
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  out.positions.resize(3 * nv);
  out.normals.resize(nbmc_mesh_normals(m) ? 3 * nv : 0);
  out.triangles.resize(3 * nt);
  nbmc_mesh_copy_to_host(m, out.positions.data(), out.normals.empty() ? nullptr : out.normals.data(),
                         out.triangles.data());
  return out;
}

bool good(const nbmc_mesh_check_result& c) { return c.closed && c.manifold && c.oriented; }


// A lattice sphere of radius `radius` (spacing 1) with every coordinate moved
// by up to +-`jitter`, from seed `seed`: marching cubes leaves slivers on it.
Points jittered_sphere(int radius, double jitter, unsigned seed) {
  Points p = nbmc_test::sphere(0, 0, 0, radius, 1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  for (double& x : p) x += u(rng);
  return p;
}

TEST(MeshCheckCapi, Errors) {
  nbmc_mesh_check_result r;
  nbmc_mesh_check_result_init(&r);
  EXPECT_EQ(r.struct_size, sizeof r);
  EXPECT_EQ(nbmc_mesh_check(nullptr, &r), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_mesh_check_result_init(nullptr);
  Context c;
  nbmc_mesh* m = c.run(nbmc_test::sphere(0, 0, 0, 3, 1), nbmc_test::params(1));
  EXPECT_EQ(nbmc_mesh_check(m, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  r.struct_size = 8;
  EXPECT_EQ(nbmc_mesh_check(m, &r), NBMC_ERROR_INVALID_ARGUMENT);
  nbmc_mesh_destroy(m);
  EXPECT_STREQ(nbmc_stage_name(NBMC_STAGE_POSTPROCESS), "postprocess");
}

// The library's check and the tests' own agree on reconstructed shapes.
TEST(MeshCheckCapi, Shapes) {
  Context c;
  const double lo[3] = {0, 0, 0}, hi[3] = {6, 4, 3};
  const struct {
    Points p;
    int64_t euler;
  } shapes[] = {{nbmc_test::sphere(0, 0, 0, 5, 1), 2},
                {nbmc_test::box(lo, hi, 1), 2},
                {nbmc_test::torus(8, 3, 1), 0},
                {nbmc_test::concat(nbmc_test::sphere(0, 0, 0, 3, 1), nbmc_test::sphere(20, 0, 0, 3, 1)), 4}};
  for (double cell : {0.5, 1.0})
    for (const auto& s : shapes) {
      nbmc_params prm = nbmc_test::params(1);
      prm.cell_size = cell;
      nbmc_mesh* m = c.run(s.p, prm);
      const nbmc_mesh_check_result r = check(m);
      const nbmc_test::MeshReport t = nbmc_test::check_mesh(copy(m));
      EXPECT_TRUE(good(r)) << t.summary();
      EXPECT_EQ(r.euler_characteristic, s.euler);
      EXPECT_EQ(r.component_count, t.components);
      EXPECT_EQ(r.vertex_count, nbmc_mesh_vertex_count(m));
      EXPECT_EQ(r.triangle_count, nbmc_mesh_triangle_count(m));
      EXPECT_EQ(r.degenerate_triangle_count, 0u);
      EXPECT_EQ(r.sliver_triangle_count, 0u);
      EXPECT_GE(r.min_angle_degrees, 1.0);
      EXPECT_NEAR(r.volume, t.volume, 1e-6 * std::fabs(t.volume));
      EXPECT_NEAR(r.area, t.area, 1e-6 * t.area);
      EXPECT_GT(r.volume, 0);
      nbmc_mesh_destroy(m);
    }
}

// Random-jittered lattices (small shapes, 60 seeds, cells r and r/2; the
// 1000-seed version on pinched spheres is in test_mesh_postprocess.cpp):
// the clean-up never opens or breaks the mesh, removes every bad triangle
// the raw mesh has, and at most 1% of the triangles.
TEST(MeshCleanupCapi, JitteredLatticesStayClosed) {
  Context c;
  std::uint64_t raw_bad = 0, clean_bad = 0, raw_tris = 0, clean_tris = 0, repairs = 0;
  double max_volume_change = 0;
  for (unsigned seed = 1; seed <= 60; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1, 1);
    const double radius = 2.5 + 2 * (u(rng) + 1);
    Points p = nbmc_test::sphere(0, 0, 0, radius, 1);
    if (seed % 3 == 0) p = nbmc_test::concat(p, nbmc_test::sphere(radius + 2.2, 0.3, 0, 2.5, 1));  // a bridge
    const double jitter = 0.05 + 0.3 * (u(rng) + 1) / 2;
    for (double& x : p) x += jitter * u(rng);
    for (double cell : {0.5, 1.0}) {
      nbmc_params prm = nbmc_test::params(1);
      prm.cell_size = cell;
      prm.cleanup = 0;
      nbmc_mesh* raw = c.run(p, prm);
      nbmc_stats off;
      nbmc_stats_init(&off);
      ASSERT_EQ(nbmc_context_stats(c.ctx, &off), NBMC_OK);
      EXPECT_EQ(off.cleanup_bad_triangles_before + off.cleanup_bad_triangles_after + off.cleanup_moves +
                    off.cleanup_flips + off.cleanup_collapses + off.cleanup_cuts +
                    off.cleanup_removed_component_triangles,
                0u);
      prm.cleanup = 1;
      nbmc_mesh* clean = c.run(p, prm);
      const nbmc_mesh_check_result a = check(raw), b = check(clean);
      ASSERT_TRUE(good(a)) << "seed " << seed;
      ASSERT_TRUE(good(b)) << "seed " << seed << " cell " << cell;
      ASSERT_EQ(a.euler_characteristic, b.euler_characteristic) << "seed " << seed;
      ASSERT_EQ(a.component_count, b.component_count) << "seed " << seed;
      ASSERT_EQ(b.unreferenced_vertex_count, 0u);
      EXPECT_EQ(b.degenerate_triangle_count + b.sliver_triangle_count, 0u) << "seed " << seed << " cell " << cell;
      EXPECT_LE(a.triangle_count - b.triangle_count, a.triangle_count / 100) << "seed " << seed;
      // Real frames change by about 1e-6; these small rough shapes at cell r
      // by up to 0.3% (a vertex moved within a bumpy fan's plane).
      EXPECT_NEAR(b.volume, a.volume, 0.005 * a.volume) << "seed " << seed;
      max_volume_change = std::max(max_volume_change, std::fabs(b.volume / a.volume - 1));
      nbmc_stats st;
      nbmc_stats_init(&st);
      ASSERT_EQ(nbmc_context_stats(c.ctx, &st), NBMC_OK);
      EXPECT_EQ(st.raw_triangle_count, a.triangle_count);
      EXPECT_EQ(st.triangle_count, b.triangle_count);
      EXPECT_EQ(st.vertex_count, b.vertex_count);
      // The clean-up's counts: the bad triangles it found and left are those
      // the check counts; every triangle it removed is accounted for.
      EXPECT_EQ(st.cleanup_bad_triangles_before, a.degenerate_triangle_count + a.sliver_triangle_count)
          << "seed " << seed << " cell " << cell;
      EXPECT_EQ(st.cleanup_bad_triangles_after, b.degenerate_triangle_count + b.sliver_triangle_count);
      EXPECT_EQ(a.triangle_count - b.triangle_count,
                2 * st.cleanup_collapses + 6 * st.cleanup_cuts + st.cleanup_removed_component_triangles)
          << "seed " << seed << " cell " << cell;
      EXPECT_EQ(st.pre_decimation_triangle_count, st.triangle_count);
      if (st.cleanup_bad_triangles_before > st.cleanup_bad_triangles_after)
        EXPECT_GT(st.cleanup_moves + st.cleanup_flips + st.cleanup_collapses + st.cleanup_cuts +
                      st.cleanup_removed_component_triangles,
                  0u)
            << "seed " << seed << " cell " << cell;
      repairs += st.cleanup_moves + st.cleanup_flips + st.cleanup_collapses;
      raw_bad += a.degenerate_triangle_count + a.sliver_triangle_count;
      clean_bad += b.degenerate_triangle_count + b.sliver_triangle_count;
      raw_tris += a.triangle_count;
      clean_tris += b.triangle_count;
      nbmc_mesh_destroy(raw);
      nbmc_mesh_destroy(clean);
    }
  }
  std::printf("jittered lattices: %llu bad triangles raw, %llu cleaned; %llu -> %llu triangles; volume change "
              "up to %.3f %%\n",
              (unsigned long long)raw_bad, (unsigned long long)clean_bad, (unsigned long long)raw_tris,
              (unsigned long long)clean_tris, 100 * max_volume_change);
  EXPECT_GT(raw_bad, 0u);  // the test exercises the clean-up
  EXPECT_GT(repairs, 0u);
}

// Mean dihedral angle (degrees) over the edges with exactly two triangles of
// non-zero area, as bench/nbmc_quality measures it.
double dihedral_mean(const nbmc_test::Mesh& m) {
  std::vector<std::pair<std::uint64_t, std::uint32_t>> e;
  for (std::size_t t = 0; t < m.triangle_count(); ++t)
    for (int k = 0; k < 3; ++k) {
      std::uint64_t a = m.triangles[3 * t + k], b = m.triangles[3 * t + (k + 1) % 3];
      if (a > b) std::swap(a, b);
      e.push_back({(a << 32) | b, std::uint32_t(t)});
    }
  std::sort(e.begin(), e.end());
  auto normal = [&](std::uint32_t t, double n[3]) {
    const float* P = m.positions.data();
    const std::uint32_t* v = &m.triangles[3 * std::size_t(t)];
    double u[3], w[3];
    for (int a = 0; a < 3; ++a) {
      u[a] = double(P[3 * v[1] + a]) - P[3 * v[0] + a];
      w[a] = double(P[3 * v[2] + a]) - P[3 * v[0] + a];
    }
    n[0] = u[1] * w[2] - u[2] * w[1], n[1] = u[2] * w[0] - u[0] * w[2], n[2] = u[0] * w[1] - u[1] * w[0];
    return std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  };
  double sum = 0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < e.size();) {
    std::size_t j = i;
    while (j < e.size() && e[j].first == e[i].first) ++j;
    if (j - i == 2) {
      double n0[3], n1[3];
      const double l = normal(e[i].second, n0) * normal(e[i + 1].second, n1);
      if (l > 0) {
        const double c = (n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]) / l;
        sum += std::acos(std::min(1.0, std::max(-1.0, c))) * 180 / M_PI;
        ++count;
      }
    }
    i = j;
  }
  return count ? sum / double(count) : 0;
}

// The fairing flips (src/core/mesh_flip.hpp), which end the clean-up that
// runs again after smoothing: on a jittered lattice ball with a spray of
// single particles beside it (the distance guard's beads), the smoothed and
// cleaned mesh's mean dihedral angle lies well below that of the same
// smoothing without the clean-up, and stays closed, manifold and oriented
// without a bad triangle. (The clean-up's sliver repairs alone change the
// mean by under 0.5 %.)
TEST(MeshCleanupCapi, FairingFlipsAfterSmoothingLowerTheDihedralAngle) {
  Context c;
  Points p = jittered_sphere(5, 0.15, 11);
  for (int i = 0; i < 12; ++i) {  // a sparse trail of droplets
    const double a = 0.5 * i;
    p.insert(p.end(), {7.0 + 1.6 * i, 2.0 * std::sin(a), 1.5 * std::cos(a)});
  }
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05}) {
    for (double cell : {0.5, 1.0}) {
      nbmc_params prm = nbmc_test::params(1);
      prm.method = method;
      prm.cell_size = cell;
      prm.smooth_iterations = 2;
      prm.cleanup = 0;
      nbmc_mesh* plain = c.run(p, prm);
      prm.cleanup = 1;
      nbmc_mesh* flipped = c.run(p, prm);
      const nbmc_mesh_check_result b = check(flipped);
      EXPECT_TRUE(good(b)) << method << " " << cell;
      EXPECT_EQ(b.degenerate_triangle_count + b.sliver_triangle_count, 0u);
      const nbmc_test::Mesh mp = copy(plain), mf = copy(flipped);
      const double d_plain = dihedral_mean(mp), d_flipped = dihedral_mean(mf);
      std::printf("method %d cell %g: dihedral mean smoothed %.3f, smoothed and cleaned %.3f\n", method, cell,
                  d_plain, d_flipped);
      EXPECT_LT(d_flipped, 0.95 * d_plain) << method << " " << cell;
      nbmc_mesh_destroy(plain);
      nbmc_mesh_destroy(flipped);
    }
  }
}

// Cleaned meshes are the same on every backend and thread count.
TEST(MeshCleanupCapi, Deterministic) {
  const Points p = jittered_sphere(6, 0.2, 7);
  nbmc_params prm = nbmc_test::params(1);
  const nbmc_test::Result ref = nbmc_test::reconstruct(p, prm, NBMC_BACKEND_SERIAL, 1);
  ASSERT_EQ(ref.status, NBMC_OK);
  for (int threads : {1, 2, 4}) {
    const nbmc_test::Result r = nbmc_test::reconstruct(p, prm, NBMC_BACKEND_OPENMP, threads);
    ASSERT_EQ(r.status, NBMC_OK);
    EXPECT_EQ(r.mesh.positions, ref.mesh.positions) << threads;
    EXPECT_EQ(r.mesh.normals, ref.mesh.normals) << threads;
    EXPECT_EQ(r.mesh.triangles, ref.mesh.triangles) << threads;
  }
}

// A caller built before the post-processing fields were appended passes the
// shorter nbmc_params and nbmc_stats: accepted, with the clean-up on (the
// default) and only its fields written.
TEST(MeshCleanupCapi, OldStructSizes) {
  Context c;
  nbmc_params prm = nbmc_test::params(1);
  prm.struct_size = uint32_t(offsetof(nbmc_params, cleanup));
  prm.cleanup = 0;  // beyond the caller's struct: ignored
  Points p = nbmc_test::sphere(0, 0, 0, 4, 1);
  nbmc_mesh* m = c.run(p, prm);
  nbmc_stats st;
  nbmc_stats_init(&st);
  std::memset(&st.raw_triangle_count, 0xab, sizeof st.raw_triangle_count);
  st.struct_size = uint32_t(offsetof(nbmc_stats, raw_triangle_count));
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st), NBMC_OK);
  EXPECT_EQ(st.struct_size, offsetof(nbmc_stats, raw_triangle_count));
  EXPECT_EQ(st.triangle_count, nbmc_mesh_triangle_count(m));
  std::uint64_t untouched;
  std::memset(&untouched, 0xab, sizeof untouched);
  EXPECT_EQ(st.raw_triangle_count, untouched);
  nbmc_stats full;
  nbmc_stats_init(&full);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &full), NBMC_OK);
  EXPECT_GE(full.raw_triangle_count, full.triangle_count);
  // A caller built before the clean-up's counts were appended: it gets the
  // fields up to pre_decimation_triangle_count, and not a byte more.
  struct {
    nbmc_stats s;
    unsigned char guard[8];
  } older;
  std::memset(&older, 0xcd, sizeof older);
  older.s.struct_size = uint32_t(offsetof(nbmc_stats, cleanup_bad_triangles_before));
  ASSERT_EQ(nbmc_context_stats(c.ctx, &older.s), NBMC_OK);
  EXPECT_EQ(older.s.struct_size, offsetof(nbmc_stats, cleanup_bad_triangles_before));
  EXPECT_EQ(older.s.triangle_count, full.triangle_count);
  EXPECT_EQ(older.s.raw_triangle_count, full.raw_triangle_count);
  EXPECT_EQ(older.s.pre_decimation_triangle_count, full.pre_decimation_triangle_count);
  const auto* bytes = reinterpret_cast<const unsigned char*>(&older);
  for (std::size_t i = offsetof(nbmc_stats, cleanup_bad_triangles_before); i < sizeof older; ++i)
    ASSERT_EQ(bytes[i], 0xcd) << "byte " << i << " written";
  nbmc_mesh_destroy(m);
  prm.struct_size = uint32_t(offsetof(nbmc_params, cleanup)) - 8;
  nbmc_mesh* bad = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &bad), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(bad, nullptr);
}

// Taubin smoothing keeps a lattice sphere's radius (within 0.1 r) and volume,
// keeps the mesh closed, and gives unit normals.
TEST(MeshSmoothCapi, SphereKeepsItsRadius) {
  Context c;
  const double radius = 8;
  Points p = nbmc_test::sphere(0, 0, 0, radius, 1);
  nbmc_params prm = nbmc_test::params(1);
  nbmc_mesh* raw = c.run(p, prm);
  prm.smooth_iterations = 10;
  nbmc_mesh* m = c.run(p, prm);
  nbmc_stats st;
  nbmc_stats_init(&st);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st), NBMC_OK);
  const nbmc_mesh_check_result a = check(raw), b = check(m);
  EXPECT_TRUE(good(b));
  EXPECT_EQ(a.triangle_count, b.triangle_count);
  // smoothing_volume_change is measured right after smoothing; the clean-up
  // that runs again on the smoothed mesh flips edges once more (its fairing
  // flips), which moves the final volume by about 1.5e-4 of it here.
  EXPECT_NEAR(st.smoothing_volume_change, b.volume / a.volume - 1, 3e-4);
  EXPECT_LT(std::fabs(st.smoothing_volume_change), 0.01);
  EXPECT_GT(st.stage_seconds[NBMC_STAGE_POSTPROCESS], 0);
  const nbmc_test::Mesh s = copy(m), r0 = copy(raw);
  auto mean_radius = [](const nbmc_test::Mesh& x) {
    double sum = 0;
    for (std::size_t v = 0; v < x.vertex_count(); ++v)
      sum += std::sqrt(double(x.positions[3 * v]) * x.positions[3 * v] +
                       double(x.positions[3 * v + 1]) * x.positions[3 * v + 1] +
                       double(x.positions[3 * v + 2]) * x.positions[3 * v + 2]);
    return sum / double(x.vertex_count());
  };
  EXPECT_NEAR(mean_radius(s), mean_radius(r0), 0.1);
  for (std::size_t v = 0; v < s.vertex_count(); ++v) {
    const double l = std::sqrt(double(s.normals[3 * v]) * s.normals[3 * v] +
                               double(s.normals[3 * v + 1]) * s.normals[3 * v + 1] +
                               double(s.normals[3 * v + 2]) * s.normals[3 * v + 2]);
    ASSERT_NEAR(l, 1.0, 1e-5);
    // Outward: along the position on a sphere.
    const double d = s.normals[3 * v] * s.positions[3 * v] + s.normals[3 * v + 1] * s.positions[3 * v + 1] +
                     s.normals[3 * v + 2] * s.positions[3 * v + 2];
    ASSERT_GT(d, 0);
  }
  nbmc_mesh_destroy(raw);
  nbmc_mesh_destroy(m);
  prm.smooth_iterations = -1;
  nbmc_mesh* bad = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &bad), NBMC_ERROR_INVALID_PARAMETER);
}

// With smoothing the clean-up runs twice (after marching cubes, and after
// smoothing): its repairs are summed, "before" is the marching-cubes mesh's
// bad triangles, "after" those the last run left, and every triangle removed
// is still accounted for.
TEST(MeshCleanupCapi, CountsSummedOverBothRuns) {
  Context c;
  const Points p = jittered_sphere(6, 0.3, 11);
  nbmc_params prm = nbmc_test::params(1);
  prm.cleanup = 0;
  nbmc_mesh* raw = c.run(p, prm);
  const nbmc_mesh_check_result a = check(raw);
  nbmc_mesh_destroy(raw);
  prm.cleanup = 1;
  nbmc_mesh* once = c.run(p, prm);
  nbmc_stats st1;
  nbmc_stats_init(&st1);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st1), NBMC_OK);
  nbmc_mesh_destroy(once);
  prm.smooth_iterations = 20;
  nbmc_mesh* twice = c.run(p, prm);
  nbmc_stats st2;
  nbmc_stats_init(&st2);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st2), NBMC_OK);
  const nbmc_mesh_check_result b = check(twice);
  nbmc_mesh_destroy(twice);
  ASSERT_GT(a.degenerate_triangle_count + a.sliver_triangle_count, 0u);
  EXPECT_EQ(st2.cleanup_bad_triangles_before, a.degenerate_triangle_count + a.sliver_triangle_count);
  EXPECT_EQ(st2.cleanup_bad_triangles_before, st1.cleanup_bad_triangles_before);
  EXPECT_EQ(st2.cleanup_bad_triangles_after, b.degenerate_triangle_count + b.sliver_triangle_count);
  EXPECT_LE(st2.cleanup_bad_triangles_after, st2.cleanup_bad_triangles_before);
  // The first run is the same with or without smoothing after it: the sums
  // hold at least its repairs.
  EXPECT_GE(st2.cleanup_moves, st1.cleanup_moves);
  EXPECT_GE(st2.cleanup_flips, st1.cleanup_flips);
  EXPECT_GE(st2.cleanup_collapses, st1.cleanup_collapses);
  EXPECT_GT(st1.cleanup_moves + st1.cleanup_flips + st1.cleanup_collapses, 0u);
  EXPECT_EQ(st2.raw_triangle_count, a.triangle_count);
  EXPECT_EQ(st2.raw_triangle_count - st2.triangle_count,
            2 * st2.cleanup_collapses + 6 * st2.cleanup_cuts + st2.cleanup_removed_component_triangles);
  std::printf("clean-up once: %llu moves, %llu flips, %llu collapses; with smoothing: %llu, %llu, %llu\n",
              (unsigned long long)st1.cleanup_moves, (unsigned long long)st1.cleanup_flips,
              (unsigned long long)st1.cleanup_collapses, (unsigned long long)st2.cleanup_moves,
              (unsigned long long)st2.cleanup_flips, (unsigned long long)st2.cleanup_collapses);
}

// Each post-processing step's largest mesh is the largest triangle count
// whose list entries (3 per triangle for the clean-up's and the check's
// incidence, 6 for the smoothing's neighbour lists) fit in 32-bit offsets;
// at it the step runs, one triangle more gives DOMAIN_TOO_LARGE with a
// message naming the step, the counts, the limit and how to turn it off
// (src/capi_mesh.cpp asks before each step: such meshes, of billions of
// triangles, cannot be made in a test).
TEST(MeshPostprocessLimits, StepsRefuseMeshesTheirOffsetsCannotAddress) {
  namespace mesh = nbmc::mesh;
  const std::uint64_t u32 = 0xffffffffu;
  const std::pair<std::uint64_t, std::uint64_t> limits[] = {
      {mesh::cleanup_max_triangles, 3}, {mesh::check_max_triangles, 3}, {mesh::smooth_max_triangles, 6}};
  for (const auto& l : limits) {
    EXPECT_LE(l.second * l.first, u32);
    EXPECT_GT(l.second * (l.first + 1), u32);
  }
  EXPECT_EQ(mesh::cleanup_max_triangles, 1431655765u);
  EXPECT_EQ(mesh::smooth_max_triangles, 715827882u);
  EXPECT_NO_THROW(mesh::require_addressable("the mesh clean-up", "CLI --no-cleanup", 7, mesh::cleanup_max_triangles,
                                            mesh::cleanup_max_triangles));
  try {
    mesh::require_addressable("the mesh smoothing", "CLI --smooth 0", 7, mesh::smooth_max_triangles + 1,
                              mesh::smooth_max_triangles);
    ADD_FAILURE() << "a mesh beyond the smoothing's limit was accepted";
  } catch (const nbmc::Error& e) {
    EXPECT_EQ(e.status, NBMC_ERROR_DOMAIN_TOO_LARGE);
    const std::string m = e.what();
    for (const char* part : {"the mesh smoothing", "7 vertices", "715827883 triangles", "at most 715827882", "--smooth 0"})
      EXPECT_NE(m.find(part), std::string::npos) << "\"" << part << "\" not in: " << m;
  }
}

// The post-processing counts against the memory budget: a budget that admits
// the reconstruction (its measured peak without post-processing) but not
// the clean-up's estimate plus the mesh fails with MEMORY_BUDGET naming the
// clean-up, and no mesh; the same budget without the clean-up succeeds, and
// so does the context afterwards. The peak reported with the clean-up
// includes its estimate; the decimation is refused the same way.
TEST(MeshPostprocessBudget, CleanupAndDecimationCountedAgainstTheBudget) {
  Context c;
  const Points p = jittered_sphere(8, 0.2, 5);
  nbmc_params prm = nbmc_test::params(1);
  prm.cell_size = 1;  // a coarse grid: the mesh is large next to the band
  prm.cleanup = 0;
  nbmc_mesh* raw = c.run(p, prm);
  ASSERT_NE(raw, nullptr);
  nbmc_stats st0;
  nbmc_stats_init(&st0);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st0), NBMC_OK);
  const std::uint64_t nv = nbmc_mesh_vertex_count(raw), nt = nbmc_mesh_triangle_count(raw);
  const nbmc_test::Mesh raw_mesh = copy(raw);
  nbmc_mesh_destroy(raw);
  const std::uint64_t reconstruction = st0.peak_memory_bytes;
  const std::uint64_t cleanup = nbmc::mesh::cleanup_bytes(nv, nt) + nbmc::mesh::mesh_bytes(nv, nt, false, true);
  ASSERT_GT(cleanup, reconstruction) << "the frame does not exercise the clean-up's budget check";

  // No budget: the peak includes the clean-up's estimate.
  prm.cleanup = 1;
  nbmc_mesh* m = c.run(p, prm);
  ASSERT_NE(m, nullptr);
  const std::uint64_t tris = nbmc_mesh_triangle_count(m);
  nbmc_mesh_destroy(m);
  nbmc_stats st1;
  nbmc_stats_init(&st1);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st1), NBMC_OK);
  EXPECT_GE(st1.peak_memory_bytes, cleanup);
  EXPECT_GT(st1.peak_memory_bytes, reconstruction);

  // The reconstruction's peak as the budget: the clean-up is refused.
  ASSERT_EQ(nbmc_context_set_memory_budget(c.ctx, reconstruction), NBMC_OK);
  m = reinterpret_cast<nbmc_mesh*>(0x1);
  EXPECT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &m), NBMC_ERROR_MEMORY_BUDGET);
  EXPECT_EQ(m, nullptr);
  const std::string msg = nbmc_context_last_error(c.ctx);
  for (const char* s : {"clean-up", "memory budget", "MiB", "--no-cleanup", "cleanup = 0"})
    EXPECT_NE(msg.find(s), std::string::npos) << s << ": " << msg;
  // Without the clean-up the same budget admits the run: the raw mesh again.
  prm.cleanup = 0;
  m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(c.ctx);
  const nbmc_test::Mesh again = copy(m);
  EXPECT_EQ(again.positions, raw_mesh.positions);
  EXPECT_EQ(again.triangles, raw_mesh.triangles);
  nbmc_mesh_destroy(m);
  // Decimation alone: refused the same way, naming it.
  prm.decimate_fraction = 0.5;
  m = reinterpret_cast<nbmc_mesh*>(0x1);
  EXPECT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &m), NBMC_ERROR_MEMORY_BUDGET);
  EXPECT_EQ(m, nullptr);
  EXPECT_NE(std::string(nbmc_context_last_error(c.ctx)).find("decimation"), std::string::npos)
      << nbmc_context_last_error(c.ctx);
  prm.decimate_fraction = 1;
  // The peak with the clean-up as the budget: it fits, the same mesh.
  prm.cleanup = 1;
  ASSERT_EQ(nbmc_context_set_memory_budget(c.ctx, st1.peak_memory_bytes), NBMC_OK);
  m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(c.ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(c.ctx);
  EXPECT_EQ(nbmc_mesh_triangle_count(m), tris);
  nbmc_mesh_destroy(m);
}

}  // namespace
