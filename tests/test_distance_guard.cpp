// SPDX-License-Identifier: MIT
// The distance guard (nbmc_params.max_distance, backends/kokkos/field_common.hpp):
// where no particle lies within rho the field is raised, so that the surface
// stays within about rho of the particles. Through the C API: the bound on
// scenes that break it without the guard (bridges between filaments and
// sheets, a sparse splash), per-particle radii, what turns it off, YT10
// ignoring it, thread counts, and the parameter's checks.
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

using namespace nbmc_test;

namespace {

const double kR = 0.05;  // spacing r

// Over the mesh's vertices, the largest min_j (|v - x_j| - rho_j): how far a
// vertex lies beyond the guard's balls (rho_j = rho, or rho r_j / r_max with
// radii); and the largest distance to the nearest particle.
struct Reach {
  double beyond_balls = -std::numeric_limits<double>::max();
  double nearest = 0;
};
Reach reach(const Mesh& m, const Points& p, double rho, const std::vector<double>& radii = {}) {
  Reach out;
  const std::size_t n = p.size() / 3;
  const double r_max = radii.empty() ? 1 : *std::max_element(radii.begin(), radii.end());
  for (std::size_t v = 0; v < m.vertex_count(); ++v) {
    double best = std::numeric_limits<double>::max(), nearest = best;
    for (std::size_t j = 0; j < n; ++j) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(double(m.positions[3 * v + a]) - p[3 * j + a], 2);
      const double d = std::sqrt(d2);
      best = std::min(best, d - (radii.empty() ? rho : rho * radii[j] / r_max));
      nearest = std::min(nearest, d);
    }
    out.beyond_balls = std::max(out.beyond_balls, best);
    out.nearest = std::max(out.nearest, nearest);
  }
  return out;
}

// Two one-particle filaments (rows of particles r apart along x), `gap`
// apart in y: at 4 r, SSP07's and ZB05's averaged centre bridges them with a
// surface up to 2.2 r from every particle.
Points filaments(double gap) {
  Points p;
  for (int i = -8; i <= 8; ++i)
    for (double y : {-gap / 2, gap / 2}) p.insert(p.end(), {i * kR, y, 0.0});
  return p;
}

// Two one-particle-thick sheets (z = +-gap/2), as above.
Points sheets(double gap) {
  Points p;
  for (int i = -6; i <= 6; ++i)
    for (int j = -6; j <= 6; ++j)
      for (double z : {-gap / 2, gap / 2}) p.insert(p.end(), {i * kR, j * kR, z});
  return p;
}

// A sparse splash: n particles uniform in a cube of side 8 r (splitmix64).
Points splash(int n, std::uint64_t seed) {
  Points p;
  for (int i = 0; i < 3 * n; ++i) {
    std::uint64_t z = (seed += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    z ^= z >> 31;
    p.push_back((double(z >> 11) / 9007199254740992.0 - 0.5) * 8 * kR);
  }
  return p;
}

nbmc_params guard_params(int32_t method, double rho) {
  nbmc_params prm = params(kR);
  prm.method = method;
  prm.max_distance = rho;
  return prm;
}

}  // namespace

TEST(DistanceGuard, DefaultIsOnePointFiveSpacings) {
  nbmc_params prm;
  nbmc_params_init(&prm);
  EXPECT_EQ(prm.max_distance, 1.5);
}

// The bound: with the guard every vertex lies within rho + half a cell of a
// particle here (in general, within rho + one cell: a vertex is interpolated
// on an edge whose inside end is within rho of one).
TEST(DistanceGuard, KeepsTheSurfaceNearTheParticles) {
  struct Scene {
    const char* name;
    Points p;
  } scenes[] = {{"filaments 4r apart", filaments(4 * kR)}, {"sheets 4r apart", sheets(4 * kR)},
                {"sparse splash", splash(100, 3)}};
  for (const Scene& s : scenes)
    for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH})
      for (double cell : {1.0, 0.5}) {
        const std::string what = std::string(s.name) + ", method " + std::to_string(method) + ", cell " +
                                 std::to_string(cell) + "r";
        nbmc_params prm = guard_params(method, 1.5);
        prm.cell_size = cell;
        const Result on = reconstruct(s.p, prm);
        ASSERT_EQ(on.status, NBMC_OK) << what << ": " << on.message;
        const MeshReport rep = check_mesh(on.mesh);
        EXPECT_TRUE(rep.closed && rep.edge_manifold && rep.vertex_manifold && rep.oriented)
            << what << ": " << rep.summary();
        const Reach got = reach(on.mesh, s.p, 1.5 * kR);
        EXPECT_LE(got.beyond_balls, 0.5 * cell * kR) << what;
        std::printf("%-20s method %d cell %.1f: guard on: %.3f r beyond rho at most (%zu triangles)\n", s.name,
                    method, cell, got.beyond_balls / kR, on.mesh.triangle_count());
      }
}

// Without the guard, each scene (at cell r/2) has vertices more than half a
// cell r beyond rho: it breaks the bounds of the test above (so that it can
// fail).
TEST(DistanceGuard, TheScenesNeedIt) {
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05})
    for (const Points& p : {filaments(4 * kR), sheets(4 * kR), splash(100, 3)}) {
      const Result off = reconstruct(p, guard_params(method, 0));
      ASSERT_EQ(off.status, NBMC_OK) << off.message;
      const double beyond = reach(off.mesh, p, 1.5 * kR).beyond_balls;
      std::printf("method %d: guard off: %.3f r beyond rho at most\n", method, beyond / kR);
      EXPECT_GT(beyond, 0.5 * kR) << "method " << method;
    }
}

// Cut bridges: two filaments 4 r apart are one tube around both without the
// guard, and two with it.
TEST(DistanceGuard, SeparatesFilaments) {
  const Points p = filaments(4 * kR);
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05}) {
    const Result off = reconstruct(p, guard_params(method, 0));
    const Result on = reconstruct(p, guard_params(method, 1.5));
    ASSERT_EQ(off.status, NBMC_OK) << off.message;
    ASSERT_EQ(on.status, NBMC_OK) << on.message;
    EXPECT_EQ(check_mesh(off.mesh).components, 1u) << "method " << method;
    EXPECT_EQ(check_mesh(on.mesh).components, 2u) << "method " << method;
  }
}

// rho >= R, or 0, is no guard: the same mesh bit for bit; YT10 has none.
TEST(DistanceGuard, OffSettingsAndYt10) {
  const Points p = filaments(4 * kR);
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH, NBMC_METHOD_YT10}) {
    const Result off = reconstruct(p, guard_params(method, 0));
    const Result big = reconstruct(p, guard_params(method, 4));  // = influence_radius
    const Result on = reconstruct(p, guard_params(method, 1.5));
    ASSERT_EQ(off.status, NBMC_OK) << off.message;
    ASSERT_EQ(big.status, NBMC_OK) << big.message;
    ASSERT_EQ(on.status, NBMC_OK) << on.message;
    EXPECT_EQ(off.mesh.positions, big.mesh.positions) << "method " << method;
    EXPECT_EQ(off.mesh.triangles, big.mesh.triangles) << "method " << method;
    if (method == NBMC_METHOD_YT10)
      EXPECT_EQ(off.mesh.positions, on.mesh.positions);
    else
      EXPECT_NE(off.mesh.positions, on.mesh.positions) << "method " << method;
  }
}

// Same mesh on 1, 2 and 3 threads and on the serial backend (the guard is a
// maximum: exact whatever the order).
TEST(DistanceGuard, SameMeshOnAnyThreadCount) {
  const Points p = concat(filaments(4 * kR), splash(300, 7));
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    const nbmc_params prm = guard_params(method, 1.5);
    const Result ref = reconstruct(p, prm, NBMC_BACKEND_SERIAL);
    ASSERT_EQ(ref.status, NBMC_OK) << ref.message;
    for (int threads : {1, 2, 3}) {
      const Result r = reconstruct(p, prm, NBMC_BACKEND_OPENMP, threads);
      ASSERT_EQ(r.status, NBMC_OK) << r.message;
      EXPECT_EQ(r.mesh.positions, ref.mesh.positions) << "method " << method << ", " << threads << " threads";
      EXPECT_EQ(r.mesh.triangles, ref.mesh.triangles) << "method " << method << ", " << threads << " threads";
    }
  }
}

// Lengths in absolute units: rho = 1.5 r absolute is the same guard.
TEST(DistanceGuard, AbsoluteUnits) {
  const Points p = filaments(4 * kR);
  nbmc_params rel = guard_params(NBMC_METHOD_ZB05, 1.5);
  nbmc_params abs = rel;
  abs.length_unit = NBMC_UNIT_ABSOLUTE;
  abs.cell_size = rel.cell_size * kR;
  abs.influence_radius = rel.influence_radius * kR;
  abs.band_width = rel.band_width * kR;
  abs.surface_radius = rel.surface_radius * kR;
  abs.iso_radius = rel.iso_radius * kR;
  abs.max_distance = 1.5 * kR;
  const Result a = reconstruct(p, rel), b = reconstruct(p, abs);
  ASSERT_EQ(a.status, NBMC_OK) << a.message;
  ASSERT_EQ(b.status, NBMC_OK) << b.message;
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
}

// Per-particle radii: each particle's rho scales with its radius (rho_j =
// rho r_j / r_max); the bound holds per particle.
TEST(DistanceGuard, PerParticleRadii) {
  const Points p = concat(filaments(4 * kR), splash(150, 5));
  std::vector<double> radii;
  for (std::size_t j = 0; j < p.size() / 3; ++j) radii.push_back(j < 34 ? kR : (j % 2 ? 0.7 : 0.5) * kR);
  for (int32_t method : {NBMC_METHOD_SSP07, NBMC_METHOD_ZB05, NBMC_METHOD_SPH}) {
    nbmc_context_desc desc;
    nbmc_context_desc_init(&desc);
    desc.backend = NBMC_BACKEND_OPENMP;
    nbmc_context* ctx = nullptr;
    ASSERT_EQ(nbmc_context_create(&desc, &ctx), NBMC_OK);
    ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
    ASSERT_EQ(nbmc_context_set_radii_f64(ctx, radii.data(), radii.size(), 0), NBMC_OK);
    const nbmc_params prm = guard_params(method, 1.5);
    nbmc_mesh* mesh = nullptr;
    ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &mesh), NBMC_OK) << nbmc_context_last_error(ctx);
    Mesh m;
    const float* x = nbmc_mesh_positions(mesh);
    m.positions.assign(x, x + 3 * nbmc_mesh_vertex_count(mesh));
    nbmc_mesh_destroy(mesh);
    nbmc_context_destroy(ctx);
    // the radii are the spacings here (r_max = kR): rho_j = 1.5 r_j
    EXPECT_LE(reach(m, p, 1.5 * kR, radii).beyond_balls, prm.cell_size * kR) << "method " << method;
  }
}

TEST(DistanceGuard, RejectsBadValues) {
  const Points p = sphere(0, 0, 0, 0.1, kR);
  for (double bad : {-0.1, std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    const Result r = reconstruct(p, guard_params(NBMC_METHOD_SSP07, bad));
    EXPECT_EQ(r.status, NBMC_ERROR_INVALID_PARAMETER) << bad;
    EXPECT_NE(r.message.find("max_distance"), std::string::npos) << r.message;
  }
}
