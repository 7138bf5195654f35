// SPDX-License-Identifier: MIT
// Hostile inputs, the memory budget and concurrent contexts.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

using namespace nbmc_test;

namespace {

struct Ctx {
  nbmc_context* c = nullptr;
  explicit Ctx(int threads = 0) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = NBMC_BACKEND_OPENMP;
    d.num_threads = threads;
    EXPECT_EQ(nbmc_context_create(&d, &c), NBMC_OK);
  }
  ~Ctx() { nbmc_context_destroy(c); }
  std::string error() const { return nbmc_context_last_error(c); }
};

}  // namespace

TEST(MemoryBudget, OverBudgetIsAStatusWithTheEstimateAndTheContextStaysUsable) {
  const Points p = sphere(0, 0, 0, 1.0, 0.1);
  Ctx ctx;
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx.c, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_params prm = params(0.1);
  nbmc_mesh* m = nullptr;
  // Unlimited: measure the peak.
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  nbmc_stats s;
  nbmc_stats_init(&s);
  ASSERT_EQ(nbmc_context_stats(ctx.c, &s), NBMC_OK);
  const std::uint64_t peak = s.peak_memory_bytes;
  const std::uint64_t tris = nbmc_mesh_triangle_count(m);
  nbmc_mesh_destroy(m);
  // Far too small: refused by the up-front estimate, before the big allocations.
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx.c, 1024), NBMC_OK);
  m = reinterpret_cast<nbmc_mesh*>(0x1);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_ERROR_MEMORY_BUDGET);
  EXPECT_EQ(m, nullptr);
  EXPECT_NE(ctx.error().find("memory budget"), std::string::npos) << ctx.error();
  EXPECT_NE(ctx.error().find("MiB"), std::string::npos) << ctx.error();
  // Just below the peak: fails somewhere during the run, cleanly.
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx.c, peak - 1), NBMC_OK);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_ERROR_MEMORY_BUDGET) << ctx.error();
  // The dense baseline needs far more than the band: refused up front.
  nbmc_params dense = prm;
  dense.field = NBMC_FIELD_SCATTER;
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx.c, 4 * peak), NBMC_OK);
  EXPECT_EQ(nbmc_context_reconstruct(ctx.c, &dense, &m), NBMC_ERROR_MEMORY_BUDGET) << ctx.error();
  EXPECT_NE(ctx.error().find("dense baseline"), std::string::npos) << ctx.error();
  // Enough budget (the peak itself), then no cap: same mesh again.
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx.c, peak), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  EXPECT_EQ(nbmc_mesh_triangle_count(m), tris);
  nbmc_mesh_destroy(m);
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx.c, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_reconstruct(ctx.c, &prm, &m), NBMC_OK) << ctx.error();
  EXPECT_EQ(nbmc_mesh_triangle_count(m), tris);
  nbmc_mesh_destroy(m);
  EXPECT_EQ(nbmc_context_set_memory_budget(nullptr, 1), NBMC_ERROR_INVALID_ARGUMENT);
}

TEST(Hostile, HundredThousandParticlesInOnePointFinishAndCloseTheMesh) {
  // Policy: a neighbour cell with more than 2048 particles is all surface
  // (no pairwise test, which would cost 10^10 distance checks here).
  Points p = sphere(0, 0, 0, 0.5, 0.1);
  for (int i = 0; i < 100000; ++i) p.insert(p.end(), {3.0, 3.0, 3.0});
  const Result run = reconstruct(p, params(0.1));
  ASSERT_EQ(run.status, NBMC_OK) << run.message;
  const MeshReport rep = check_mesh(run.mesh);
  EXPECT_TRUE(rep.closed && rep.oriented && rep.vertex_manifold) << rep.summary();
  EXPECT_EQ(rep.components, 2u) << rep.summary();
}

TEST(Hostile, IsolatedParticlesFarFromTheBulkAreSmallSpheres) {
  Points p = sphere(0, 0, 0, 0.5, 0.1);
  p.insert(p.end(), {40.0, 0.0, 0.0});
  p.insert(p.end(), {0.0, -35.0, 20.0});
  const Result run = reconstruct(p, params(0.1));
  ASSERT_EQ(run.status, NBMC_OK) << run.message;
  const MeshReport rep = check_mesh(run.mesh);
  EXPECT_TRUE(rep.closed) << rep.summary();
  EXPECT_EQ(rep.components, 3u) << rep.summary();
}

TEST(Concurrency, FourThreadsWithTheirOwnContextsGiveTheMeshesTheyGiveAlone) {
  // Different bodies and parameters per thread; each context used by one
  // thread at a time, several threads at once.
  const std::vector<Points> bodies = {sphere(0, 0, 0, 0.6, 0.1), torus(0.8, 0.3, 0.1),
                                      concat(sphere(-0.5, 0, 0, 0.4, 0.1), sphere(0.5, 0, 0, 0.4, 0.1)),
                                      sphere(1, 2, 3, 0.7, 0.1), torus(0.6, 0.25, 0.1), sphere(0, 0, 0, 0.3, 0.05)};
  std::vector<nbmc_params> prm;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    prm.push_back(params(i == 5 ? 0.05 : 0.1));
    prm.back().cell_size = i % 2 ? 1.0 : 0.5;
    prm.back().method = i == 3 ? NBMC_METHOD_ZB05 : NBMC_METHOD_SSP07;
  }
  std::vector<Result> alone;
  for (std::size_t i = 0; i < bodies.size(); ++i) alone.push_back(reconstruct(bodies[i], prm[i]));
  for (int round = 0; round < 2; ++round) {
    std::vector<Result> together(bodies.size());
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
      threads.emplace_back([&, t] {
        for (std::size_t i = std::size_t(t); i < bodies.size(); i += 4)
          together[i] = reconstruct(bodies[i], prm[i], NBMC_BACKEND_OPENMP, 1 + int(i % 2));
      });
    for (auto& th : threads) th.join();
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      ASSERT_EQ(together[i].status, NBMC_OK) << together[i].message;
      EXPECT_EQ(together[i].mesh.triangles, alone[i].mesh.triangles) << "body " << i;
      EXPECT_EQ(together[i].mesh.positions, alone[i].mesh.positions) << "body " << i;
    }
  }
}

// Band growth: after the first round only the cells around what the previous
// round added are scanned for leaks. With NBMC_CHECK_BAND=1 the pipeline runs
// a full scan after the last round and fails (INTERNAL) if it finds a leak the
// near scans missed. Parameters that leave the surface outside the band
// (iso radius + cell > band width) take many rounds (fuzz/README_api.md,
// finding 4).
TEST(BandGrowth, ScansNearTheAddedCellsFindEveryLeak) {
  ::setenv("NBMC_CHECK_BAND", "1", 1);
  struct Case {
    int method;
    double R, iso, band, cell;
  } cases[] = {{NBMC_METHOD_ZB05, 1.5, 1.44, 1.0, 0.5}, {NBMC_METHOD_SSP07, 4.0, 0.91, 0.54, 0.3},
               {NBMC_METHOD_ZB05, 3.0, 1.0, 0.5, 0.3}};
  const double lo[3] = {-0.3, -0.2, -0.25}, hi[3] = {0.3, 0.2, 0.25};
  for (const Points& pts : {sphere(0, 0, 0, 0.35, 0.1), box(lo, hi, 0.1)})
    for (const Case& c : cases) {
      nbmc_params p = params(0.1);
      p.method = c.method;
      p.influence_radius = c.R;
      p.iso_radius = c.iso;
      p.band_width = c.band;
      p.cell_size = c.cell;
      const Result r = reconstruct(pts, p, NBMC_BACKEND_OPENMP, 2);
      ASSERT_EQ(r.status, NBMC_OK) << r.message;
      const MeshReport rep = check_mesh(r.mesh);
      EXPECT_TRUE(rep.closed && rep.oriented && rep.vertex_manifold) << rep.summary();
      EXPECT_GT(r.mesh.triangle_count(), 0u) << "R " << c.R << " iso " << c.iso << " band " << c.band;
    }
  ::unsetenv("NBMC_CHECK_BAND");
}

// Band growth's capacity guesses (band_growth.hpp): when a round's leaks or
// new words exceed them, the detection runs again with exact bounds. With
// guesses of 1 every round takes that path; the mesh must not change.
TEST(BandGrowth, DetectionOverflowGivesTheSameMesh) {
  ::setenv("NBMC_CHECK_BAND", "1", 1);
  nbmc_params p = params(0.1);
  p.method = NBMC_METHOD_ZB05;
  p.influence_radius = 1.5;
  p.iso_radius = 1.44;
  p.band_width = 1.0;
  p.cell_size = 0.5;
  const Points pts = sphere(0, 0, 0, 0.35, 0.1);
  const Result guessed = reconstruct(pts, p, NBMC_BACKEND_OPENMP, 2);
  ::setenv("NBMC_GROWTH_TINY_GUESSES", "1", 1);
  const Result exact = reconstruct(pts, p, NBMC_BACKEND_OPENMP, 2);
  ::unsetenv("NBMC_GROWTH_TINY_GUESSES");
  ::unsetenv("NBMC_CHECK_BAND");
  ASSERT_EQ(guessed.status, NBMC_OK) << guessed.message;
  ASSERT_EQ(exact.status, NBMC_OK) << exact.message;
  EXPECT_GT(guessed.mesh.triangle_count(), 0u);
  EXPECT_EQ(exact.mesh.triangles, guessed.mesh.triangles);
  EXPECT_EQ(exact.mesh.positions, guessed.mesh.positions);
}
