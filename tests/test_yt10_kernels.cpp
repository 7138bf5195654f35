// SPDX-License-Identifier: MIT
// YT10's per-particle kernels (backends/kokkos/field_yt10.hpp,
// yt10_kernels.hpp), built from the pipeline's stages on the host: the
// Jacobi decomposition, the kernels of the cases with a known answer (a
// particle deep in a uniform lattice, on its face, in a one-particle-thick
// sheet, alone), and the bound that makes the band, the neighbour search and
// the ghost layers right: every kernel lies within 0.95 R of its particle,
// whatever the particles.
#include <gtest/gtest.h>

#include "common.hpp"
#include "field_yt10.hpp"
#include "grid.hpp"
#include "narrow_band.hpp"
#include "neighbourhood.hpp"
#include "stage_tests.hpp"
#include "scalar_field.hpp"
#include "yt10_kernels.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>


namespace {

using namespace nbmc;
using namespace nbmc::Details;
using Host = Kokkos::HostSpace;
using Points = std::vector<double>;

const ::testing::Environment* const kokkos_env =
    ::testing::AddGlobalTestEnvironment(new nbmc_test::KokkosThreads(2));

Params yt10(double r, double R = 4) {
  Params p;  // the C API's defaults, absolute units
  p.spacing = r;
  p.cell_size = 0.5 * r;
  p.influence_radius = R * r;
  p.band_width = 2 * r;
  p.surface_radius = 2 * r;
  p.iso_radius = r;
  p.method = nbmc::Method::YT10;
  return p;
}

// One particle's kernel, in the uploaded order.
struct Kernel {
  double o[3];
  double G[3][3];  // times h
  double c;        // det(h G) / D
  std::array<double, 3> axes() const;  // the kernel's axes in units of h (the s_k), descending
};

std::array<double, 3> eigenvalues(const double M[3][3]) {
  float A[3][3], V[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) A[i][j] = float(M[i][j]);
  jacobi_eigen_sym3(A, V);
  std::array<double, 3> e = {A[0][0], A[1][1], A[2][2]};
  std::sort(e.begin(), e.end());
  return e;
}

std::array<double, 3> Kernel::axes() const {
  std::array<double, 3> e = eigenvalues(G);  // 1 / s_k, ascending
  return {1 / e[0], 1 / e[1], 1 / e[2]};
}

struct Pass {
  std::vector<Kernel> kernels;  // uploaded order
  FieldConstants fc;
};

Pass run_pass(const Points& xyz, const Params& p) {
  MemoryTracker tracker;
  const std::size_t n = xyz.size() / 3;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz[3 * i + a]);
      hi[a] = std::max(hi[a], xyz[3 * i + a]);
    }
  const Grid g = make_grid(lo, hi, p);
  Neighbourhood<Host> nbh;
  build_neighbourhood(Kokkos::DefaultHostExecutionSpace(), tracker, xyz.data(), n, {}, g, nbh);
  const FieldConstants fc0 = field_constants(p.influence_radius, p.iso_radius, p.t_low, p.t_high, p.iso_threshold);
  Pass out;
  out.fc = compute_yt10_kernels(Kokkos::DefaultHostExecutionSpace(), tracker, nbh, g, p, fc0);
  out.kernels.resize(n);
  const double h = 0.5 * p.influence_radius;
  for (std::size_t j = 0; j < n; ++j) {
    const float* pd = nbh.pdata.data() + std::size_t(kYt10Floats) * j;
    Kernel& k = out.kernels[nbh.perm.view()(j)];
    for (int a = 0; a < 3; ++a) k.o[a] = pd[a];
    const int idx[3][3] = {{3, 4, 5}, {4, 6, 7}, {5, 7, 8}};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) k.G[a][b] = h * pd[idx[a][b]];
    k.c = pd[9];
  }
  return out;
}

Points lattice_box(int nx, int ny, int nz, double r) {
  Points p;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) p.insert(p.end(), {i * r, j * r, k * r});
  return p;
}

}  // namespace

TEST(Yt10Kernels, JacobiDecomposes) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  float worst = 0, worst_ortho = 0;
  for (int t = 0; t < 20000; ++t) {
    float A0[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = i; j < 3; ++j) A0[i][j] = A0[j][i] = u(rng);
    if (t % 4 == 1) A0[0][1] = A0[1][0] = 1e-7f * u(rng);            // nearly diagonal
    if (t % 4 == 2) A0[0][0] = A0[1][1] = A0[2][2];                  // equal diagonal
    if (t % 4 == 3) A0[0][2] = A0[2][0] = A0[1][2] = A0[2][1] = 0;  // block diagonal
    float A[3][3], V[3][3];
    std::copy(&A0[0][0], &A0[0][0] + 9, &A[0][0]);
    jacobi_eigen_sym3(A, V);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        float s = 0, o = 0;
        for (int k = 0; k < 3; ++k) {
          s += V[i][k] * V[j][k] * A[k][k];
          o += V[k][i] * V[k][j];
        }
        worst = std::max(worst, std::fabs(s - A0[i][j]));
        worst_ortho = std::max(worst_ortho, std::fabs(o - (i == j ? 1.f : 0.f)));
      }
  }
  EXPECT_LT(worst, 1e-5f);  // measured 1.1e-6
  EXPECT_LT(worst_ortho, 1e-5f);
  // The zero matrix and a diagonal one stay as they are.
  float Z[3][3] = {}, V[3][3];
  jacobi_eigen_sym3(Z, V);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(V[i][j], i == j ? 1.f : 0.f);
}

// Deep inside a uniform lattice the covariance is sigma_0 I (the continuum
// value 3 R^2 / 20, to a few per cent on a lattice), so k_s = 1 gives the
// isotropic kernel G = I / h, no displacement, and det(h G) / D = 1 / D.
TEST(Yt10Kernels, UniformInteriorIsIsotropic) {
  const double r = 0.1;
  for (const double R : {3.0, 4.0, 5.0}) {
    const int m = 2 * int(std::ceil(R)) + 5;
    const Points p = lattice_box(m, m, m, r);
    const Pass pass = run_pass(p, yt10(r, R));
    const int mid = m / 2;
    const Kernel& k = pass.kernels[std::size_t(mid + m * (mid + m * mid))];
    const auto s = k.axes();
    for (const double v : s) {
      EXPECT_GT(v, 0.95) << "R " << R;  // the lattice's sigma / sigma_0: 0.963 (3 r), 1.004 (4 r), 0.995 (5 r)
      EXPECT_LT(v, 1.05) << "R " << R;
    }
    EXPECT_LT(std::fabs(s[0] - s[2]), 1e-3) << "R " << R << ": a cubic lattice is isotropic";
    for (const double o : k.o) EXPECT_LT(std::fabs(o), 1e-5 * r);
  }
}

// A particle in the middle of a lattice's face: the kernel is flattened
// along the face's normal (the shortest axis), keeps about the interior's
// width along the face, and its centre moves inwards.
TEST(Yt10Kernels, FaceParticleIsFlattenedAlongTheNormal) {
  const double r = 0.1;
  const int m = 15;
  const Points p = lattice_box(m, m, 8, r);  // faces z = 0 and z = 7 r
  const Pass pass = run_pass(p, yt10(r));
  const int mid = m / 2;
  const Kernel& k = pass.kernels[std::size_t(mid + m * (mid + m * 7))];  // on the top face
  // The normal (z) is an eigenvector with the smallest axis.
  EXPECT_LT(std::fabs(k.G[0][2]), 1e-4);
  EXPECT_LT(std::fabs(k.G[1][2]), 1e-4);
  const double s_normal = 1 / k.G[2][2], s_x = 1 / k.G[0][0], s_y = 1 / k.G[1][1];
  EXPECT_LT(s_normal, 0.5 * s_x);
  EXPECT_NEAR(s_x, s_y, 1e-3);
  EXPECT_GT(s_x, 0.9);
  EXPECT_LT(s_x, 1.2);
  // The weighted mean of a half ball lies 9/28 R below its centre (in the
  // continuum); lambda = 0.3 moves the centre that far times 0.3.
  EXPECT_LT(k.o[2], -0.5 * 0.3 * 9.0 / 28.0 * 4 * r);
  EXPECT_GT(k.o[2], -1.5 * 0.3 * 9.0 / 28.0 * 4 * r);
}

// A one-particle-thick sheet: the normal axis is the longest divided by k_r
// (the clamp), the others those of a disc (about 1.19 times the interior's).
TEST(Yt10Kernels, SheetParticleIsClampedToKr) {
  const double r = 0.1;
  const int m = 15;
  const Points p = lattice_box(m, m, 1, r);
  for (const double kr : {4.0, 2.0}) {
    Params prm = yt10(r);
    prm.aniso_kr = kr;
    const Pass pass = run_pass(p, prm);
    const Kernel& k = pass.kernels[std::size_t(m / 2 + m * (m / 2))];
    const auto s = k.axes();
    EXPECT_NEAR(s[2], s[0] / kr, 1e-4 * s[0]) << "k_r " << kr;
    EXPECT_GT(s[0], 1.05);
    EXPECT_LT(s[0], 1.35);
    for (const double o : k.o) EXPECT_LT(std::fabs(o), 1e-5 * r);
  }
}

// A particle with N_eps neighbours or fewer gets the sphere of support k_n h;
// alone, D = 1 and det(h G) / D = 1 / k_n^3.
TEST(Yt10Kernels, FewNeighboursGiveASphere) {
  const double r = 0.1;
  Points p = {0, 0, 0};
  for (int i = 1; i <= 5; ++i) p.insert(p.end(), {10 * r + i * r, 0, 0});  // a short row far away
  for (const double kn : {0.5, 1.2}) {
    Params prm = yt10(r);
    prm.aniso_kn = kn;
    const Pass pass = run_pass(p, prm);
    for (const Kernel& k : pass.kernels) {
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) EXPECT_NEAR(k.G[a][b], a == b ? 1 / kn : 0.0, 1e-6);
    }
    EXPECT_NEAR(pass.kernels[0].c, 1 / (kn * kn * kn), 1e-5);
  }
}

// Whatever the particles (lines, clusters, coincident points, a particle
// beside a dense clump: its weighted mean lies almost R away), every kernel
// lies within 0.95 R of its particle: h s_1 <= 0.75 R and |xbar - x| <= 0.2 R.
// The field visits R_f = 1.02 times the largest such reach, at most R.
TEST(Yt10Kernels, EveryKernelLiesWithinTheInfluenceRadius) {
  const double r = 0.1;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0, 1);
  for (int trial = 0; trial < 6; ++trial) {
    Points p;
    for (int c = 0; c < 5; ++c) {  // clumps of various spreads
      const double cx = 20 * r * u(rng), cy = 20 * r * u(rng), cz = 20 * r * u(rng), spread = (0.01 + 3 * u(rng)) * r;
      for (int i = 0; i < 60; ++i) p.insert(p.end(), {cx + spread * u(rng), cy + spread * u(rng), cz + spread * u(rng)});
      // one particle just inside R of the clump
      p.insert(p.end(), {cx + spread / 2 + 3.9 * r, cy + spread / 2, cz + spread / 2});
    }
    for (int i = 0; i < 40; ++i) p.insert(p.end(), {30 * r + 0.3 * i * r, 5 * r, 5 * r});  // a dense line
    for (int i = 0; i < 30; ++i) p.insert(p.end(), {-5 * r, -5 * r, -5 * r});          // coincident points
    for (const double lambda : {0.3, 1.0}) {
      Params prm = yt10(r);
      prm.aniso_lambda = lambda;
      prm.aniso_ks = trial % 2 ? 50.0 : 1.0;  // k_s large: every axis clamped to 1.5 h
      const Pass pass = run_pass(p, prm);
      const double R = prm.influence_radius, h = R / 2;
      double largest = 0;
      for (const Kernel& k : pass.kernels) {
        const auto s = k.axes();
        for (const double v : s) {
          EXPECT_TRUE(std::isfinite(v));
          EXPECT_LE(v, 1.5 * (1 + 1e-5));
          EXPECT_GE(v, s[0] / prm.aniso_kr * (1 - 1e-5));
        }
        const double shift = std::sqrt(k.o[0] * k.o[0] + k.o[1] * k.o[1] + k.o[2] * k.o[2]);
        EXPECT_LE(shift, 0.2 * R * (1 + 1e-5));
        EXPECT_TRUE(std::isfinite(k.c) && k.c > 0);
        largest = std::max(largest, h * s[0] + shift);
      }
      EXPECT_LE(largest, 0.95 * R * (1 + 1e-5));
      EXPECT_LE(pass.fc.R, float(R));
      EXPECT_GE(pass.fc.R, float(std::min(R, 1.02 * largest) * (1 - 1e-5)));
    }
  }
}

// The field skips a particle where |x - x_j| is beyond its kernel's reach
// bound (field_yt10.hpp): that must change no value. The field on a dense
// grid with the bounds as computed and with every bound +inf (no skip) is
// the same bit for bit, and the bounds hold the reach.
TEST(Yt10Kernels, SkippingBeyondTheReachChangesNoValue) {
  const double r = 0.1;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-0.15 * r, 0.15 * r);
  Points p = lattice_box(10, 8, 6, r);
  for (int i = 0; i < 12; ++i) p.insert(p.end(), {i * 0.5 * r, 3 * r, 9 * r});  // a row above
  p.insert(p.end(), {4 * r, 4 * r, 12 * r});                                    // a lone particle
  for (double& v : p) v += u(rng);
  const Params prm = yt10(r);
  MemoryTracker tracker;
  const std::size_t n = p.size() / 3;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p[3 * i + a]);
      hi[a] = std::max(hi[a], p[3 * i + a]);
    }
  const Grid g = make_grid(lo, hi, prm);
  const auto space = Kokkos::DefaultHostExecutionSpace();
  Neighbourhood<Host> nbh;
  build_neighbourhood(space, tracker, p.data(), n, {}, g, nbh);
  const FieldConstants fc = compute_yt10_kernels(
      space, tracker, nbh, g, prm, field_constants(prm.influence_radius, prm.iso_radius, prm.t_low, prm.t_high));
  const double h = 0.5 * prm.influence_radius;
  for (std::size_t j = 0; j < n; ++j) {
    const float* pd = nbh.pdata.data() + std::size_t(kYt10Floats) * j;
    Kernel k;
    const int idx[3][3] = {{3, 4, 5}, {4, 6, 7}, {5, 7, 8}};
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) k.G[a][b] = h * pd[idx[a][b]];
    const double reach = h * k.axes()[0] + std::sqrt(double(pd[0]) * pd[0] + double(pd[1]) * pd[1] + double(pd[2]) * pd[2]);
    EXPECT_GE(double(pd[10]), reach * reach * (1 + 1e-3));
    EXPECT_LE(std::sqrt(double(pd[10])), double(fc.R));
  }
  Band<Host> band;
  build_dense_band(space, tracker, g, band);
  const BandView<Host> bv = view_of(band, g);
  Kokkos::View<float*, Host> with_skip("with_skip", band.n_vertices), without("without", band.n_vertices);
  gather_field<FieldYT10>(space, view_of(nbh, g), bv, band.n_blocks * 8, g, fc, with_skip, Progress{});
  for (std::size_t j = 0; j < n; ++j)
    nbh.pdata.data()[std::size_t(kYt10Floats) * j + 10] = std::numeric_limits<float>::infinity();
  gather_field<FieldYT10>(space, view_of(nbh, g), bv, band.n_blocks * 8, g, fc, without, Progress{});
  std::size_t differ = 0, inside = 0;
  for (std::size_t v = 0; v < band.n_vertices; ++v) {
    differ += std::memcmp(&with_skip(v), &without(v), sizeof(float)) != 0;
    inside += with_skip(v) < 0;
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(inside, 1000u);
}
