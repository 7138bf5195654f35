// SPDX-License-Identifier: MIT
// nbmc_params.isolated = NBMC_ISOLATED_DROP: clusters (particles linked when
// closer than surface_radius) of fewer than min_cluster particles make no
// surface, and nbmc_stats counts them.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <string>

using namespace nbmc_test;

namespace {

const double kR = 0.05;

Points body() {
  const double lo[3] = {-0.4, -0.3, -0.2}, hi[3] = {0.4, 0.3, 0.1};
  return box(lo, hi, kR);
}

// The body plus a lone particle, a pair 0.6 r apart and a lattice ball of
// a few dozen particles, all far (> surface radius 2r) from each other.
Points with_drops() {
  Points p = body();
  p.insert(p.end(), {0.8, 0.5, 0.5});                    // 1 particle
  p.insert(p.end(), {-0.8, 0.5, 0.5, -0.77, 0.5, 0.5});  // 2 particles
  return concat(p, sphere(0.0, 0.0, 0.6, 0.12, kR));     // a small ball
}

void expect_identical(const Result& a, const Result& b, const std::string& what) {
  ASSERT_EQ(a.status, NBMC_OK) << a.message;
  ASSERT_EQ(b.status, NBMC_OK) << b.message;
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles) << what;
  EXPECT_EQ(a.mesh.positions, b.mesh.positions) << what;
}

}  // namespace

TEST(Isolated, KeepIsTheDefault) {
  nbmc_params prm = params(kR);
  EXPECT_EQ(prm.isolated, NBMC_ISOLATED_KEEP);
  EXPECT_EQ(prm.min_cluster, 10);
  const Result r = reconstruct(with_drops(), prm);
  ASSERT_EQ(r.status, NBMC_OK) << r.message;
  EXPECT_EQ(r.stats.dropped_particle_count, 0u);
  EXPECT_EQ(r.stats.dropped_cluster_count, 0u);
  EXPECT_EQ(check_mesh(r.mesh).components, 4u);  // body, lone particle, pair, ball
}

TEST(Isolated, DropCountsAndEqualsTheFilteredInput) {
  const Points all = with_drops(), ball = sphere(0.0, 0.0, 0.6, 0.12, kR);
  const std::size_t ball_n = ball.size() / 3;
  ASSERT_GT(ball_n, 3u);
  for (const int method : {NBMC_METHOD_SSP07, NBMC_METHOD_SPH}) {
    nbmc_params prm = params(kR);
    prm.method = method;
    prm.isolated = NBMC_ISOLATED_DROP;
    // 3: the lone particle and the pair go; the ball stays.
    prm.min_cluster = 3;
    Result r = reconstruct(all, prm);
    ASSERT_EQ(r.status, NBMC_OK) << r.message;
    EXPECT_EQ(r.stats.dropped_particle_count, 3u);
    EXPECT_EQ(r.stats.dropped_cluster_count, 2u);
    EXPECT_EQ(r.stats.particle_count, all.size() / 3 - 3);
    EXPECT_EQ(check_mesh(r.mesh).components, 2u);
    // The same mesh as the input without them (bit for bit).
    nbmc_params keep = prm;
    keep.isolated = NBMC_ISOLATED_KEEP;
    expect_identical(r, reconstruct(concat(body(), ball), keep), "min_cluster 3");
    // Larger than the ball: only the body stays.
    prm.min_cluster = int32_t(ball_n + 1);
    r = reconstruct(all, prm);
    ASSERT_EQ(r.status, NBMC_OK) << r.message;
    EXPECT_EQ(r.stats.dropped_particle_count, 3u + ball_n);
    EXPECT_EQ(r.stats.dropped_cluster_count, 3u);
    expect_identical(r, reconstruct(body(), keep), "min_cluster above the ball");
    // 1 drops nothing.
    prm.min_cluster = 1;
    r = reconstruct(all, prm);
    ASSERT_EQ(r.status, NBMC_OK) << r.message;
    EXPECT_EQ(r.stats.dropped_particle_count, 0u);
    expect_identical(r, reconstruct(all, keep), "min_cluster 1");
  }
}

TEST(Isolated, SameOnThreadsAndSerial) {
  nbmc_params prm = params(kR);
  prm.isolated = NBMC_ISOLATED_DROP;
  prm.min_cluster = 3;
  const Points p = with_drops();
  const Result one = reconstruct(p, prm, NBMC_BACKEND_OPENMP, 1);
  expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_OPENMP, 4), "4 threads");
  expect_identical(one, reconstruct(p, prm, NBMC_BACKEND_SERIAL, 0), "serial");
}

TEST(Isolated, EverythingDroppedIsNoParticles) {
  nbmc_params prm = params(kR);
  prm.isolated = NBMC_ISOLATED_DROP;
  prm.min_cluster = 1000000;
  const Result r = reconstruct(with_drops(), prm);
  EXPECT_EQ(r.status, NBMC_ERROR_NO_PARTICLES);
  EXPECT_NE(r.message.find("min_cluster"), std::string::npos) << r.message;
}

TEST(Isolated, BadValuesAreInvalidParameters) {
  const Points p = body();
  for (const int32_t mode : {3, -1}) {  // (2 is NBMC_ISOLATED_SPHERE)
    nbmc_params prm = params(kR);
    prm.isolated = mode;
    const Result r = reconstruct(p, prm);
    EXPECT_EQ(r.status, NBMC_ERROR_INVALID_PARAMETER) << mode;
    EXPECT_NE(r.message.find("isolated"), std::string::npos) << r.message;
  }
  for (const int32_t m : {0, -5}) {
    nbmc_params prm = params(kR);
    prm.isolated = NBMC_ISOLATED_DROP;
    prm.min_cluster = m;
    const Result r = reconstruct(p, prm);
    EXPECT_EQ(r.status, NBMC_ERROR_INVALID_PARAMETER) << m;
    EXPECT_NE(r.message.find("min_cluster"), std::string::npos) << r.message;
  }
}
