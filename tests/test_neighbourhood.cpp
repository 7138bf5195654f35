// SPDX-License-Identifier: MIT
// The neighbourhood's two cell lookups (backends/kokkos/neighbourhood.hpp):
// the dense table of cell starts, built where the neighbour grid is small
// enough, and the hash map of occupied cells, which always exists. They must
// give the same range for every cell of the grid, so that the field, the
// surface particles and the band never depend on which one served; and a
// row of cells must be one range, sorted by x (the device field's rows).
#include <gtest/gtest.h>

#include "common.hpp"
#include "grid.hpp"
#include "neighbourhood.hpp"
#include "stage_tests.hpp"

#include <cstdlib>
#include <random>
#include <vector>


namespace {

using namespace nbmc;
using namespace nbmc::Details;
using Host = Kokkos::HostSpace;
using Points = std::vector<double>;

const ::testing::Environment* const kokkos_env =
    ::testing::AddGlobalTestEnvironment(new nbmc_test::KokkosThreads(2));

Params params(double r) {
  Params p;  // the C API's defaults, absolute units
  p.spacing = r;
  p.cell_size = 0.5 * r;
  p.influence_radius = 4 * r;
  p.band_width = 2 * r;
  p.surface_radius = 2 * r;
  p.iso_radius = r;
  return p;
}

struct Built {
  Grid g;
  Neighbourhood<Host> nbh;
};

void build(const Points& xyz, const Params& p, Built& b) {
  static MemoryTracker tracker;
  const std::size_t n = xyz.size() / 3;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], xyz[3 * i + a]);
      hi[a] = std::max(hi[a], xyz[3 * i + a]);
    }
  b.g = make_grid(lo, hi, p);
  build_neighbourhood(Kokkos::DefaultHostExecutionSpace(), tracker, xyz.data(), n, {}, b.g, b.nbh);
}

// A jittered ball of particles: it fills most of its bounding box's cells.
Points ball(double r, int half, unsigned seed) {
  Points p;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.3 * r, 0.3 * r);
  for (int k = -half; k <= half; ++k)
    for (int j = -half; j <= half; ++j)
      for (int i = -half; i <= half; ++i)
        if (i * i + j * j + k * k <= half * half) {
          p.push_back(i * r + u(rng));
          p.push_back(j * r + u(rng));
          p.push_back(k * r + u(rng));
        }
  return p;
}

// Every cell of the grid: the dense table of b and the hash map of h (the
// same particles, built with NBMC_DENSE_CELLS=0) agree, and every particle
// lies in the range of its own cell.
void expect_same_ranges(const Built& b, const Built& h) {
  const NeighbourView<Host> dense = view_of(b.nbh, b.g), hashed = view_of(h.nbh, h.g);
  ASSERT_EQ(h.nbh.dense_start.size(), 0u);
  ASSERT_EQ(b.nbh.cells.keys.size(), 0u) << "the hash map is built only without the dense table";
  std::size_t occupied = 0, particles = 0;
  for (std::int64_t z = 0; z < b.g.nb_dims[2]; ++z)
    for (std::int64_t y = 0; y < b.g.nb_dims[1]; ++y)
      for (std::int64_t x = 0; x < b.g.nb_dims[0]; ++x) {
        std::uint32_t b0 = 7, e0 = 7, b1 = 9, e1 = 9;
        const bool in_dense = dense.cell_range(x, y, z, b0, e0);
        const bool in_hash = hashed.cell_range(x, y, z, b1, e1);
        ASSERT_EQ(in_dense, in_hash) << "cell " << x << " " << y << " " << z;
        if (!in_hash) continue;
        EXPECT_EQ(b0, b1);
        EXPECT_EQ(e0, e1);
        EXPECT_LT(b1, e1);
        ++occupied;
        particles += e1 - b1;
      }
  EXPECT_EQ(occupied, b.nbh.n_cells);
  EXPECT_EQ(particles, b.nbh.n);
  // A row's cells x0..x1 are one range, the concatenation of their own, and
  // its particles are sorted by x (the field trims a row's ends by x).
  const float* X = b.nbh.pos.data();
  for (std::int64_t z = 0; z < b.g.nb_dims[2]; ++z)
    for (std::int64_t y = 0; y < b.g.nb_dims[1]; ++y)
      for (std::int64_t x0 = 0; x0 < b.g.nb_dims[0]; ++x0)
        for (std::int64_t x1 = x0; x1 < b.g.nb_dims[0]; ++x1) {
          std::uint32_t rb, re;
          dense.row_range(x0, x1, y, z, rb, re);
          std::uint32_t next = rb;
          for (std::int64_t x = x0; x <= x1; ++x) {
            std::uint32_t cb, ce;
            if (!hashed.cell_range(x, y, z, cb, ce)) continue;
            ASSERT_EQ(cb, next) << "row " << y << " " << z << ", cell " << x;
            next = ce;
          }
          ASSERT_EQ(re, next) << "row " << y << " " << z << ", cells " << x0 << ".." << x1;
          for (std::uint32_t j = rb + 1; j < re; ++j) ASSERT_LE(X[j - 1], X[j]);
        }
}

TEST(Neighbourhood, DenseTableAndHashMapGiveTheSameRanges) {
  const double r = 0.05;
  const Points p = ball(r, 9, 3);
  Built b, h;
  build(p, params(r), b);
  ASSERT_GT(b.nbh.dense_start.size(), 0u) << "a compact ball must get the dense table";
  setenv("NBMC_DENSE_CELLS", "0", 1);
  build(p, params(r), h);
  unsetenv("NBMC_DENSE_CELLS");
  expect_same_ranges(b, h);
}

TEST(Neighbourhood, ScatteredParticlesKeepTheHashMapAlone) {
  // Two small balls, 2,000 r apart in x and 300 r in y and z: neighbour
  // cells are R/2 = 2 r wide, so the grid has about 1,000 x 150 x 150 cells,
  // of which a few hundred are occupied.
  const double r = 0.05;
  Points p = ball(r, 3, 4), q = ball(r, 3, 5);
  for (std::size_t i = 0; i < q.size(); i += 3) q[i] += 2000 * r, q[i + 1] += 300 * r, q[i + 2] += 300 * r;
  p.insert(p.end(), q.begin(), q.end());
  Built b;
  build(p, params(r), b);
  EXPECT_EQ(b.nbh.dense_start.size(), 0u);
  // The lookups still find every particle (hash map); only the occupied
  // cells are visited, the grid is too large to walk.
  const NeighbourView<Host> v = view_of(b.nbh, b.g);
  std::size_t found = 0;
  for (std::size_t c = 0; c < b.nbh.n_cells; ++c) {
    std::int64_t x, y, z;
    neighbour_cell_of_key(b.nbh.cell_keys.view()(c), b.g.nb_dims, x, y, z);
    std::uint32_t b0, e0;
    ASSERT_TRUE(v.cell_range(x, y, z, b0, e0));
    found += e0 - b0;
  }
  EXPECT_EQ(found, b.nbh.n);
}

TEST(Neighbourhood, DenseTableCanBeTurnedOff) {
  const double r = 0.05;
  setenv("NBMC_DENSE_CELLS", "0", 1);
  Built b;
  build(ball(r, 5, 6), params(r), b);
  unsetenv("NBMC_DENSE_CELLS");
  EXPECT_EQ(b.nbh.dense_start.size(), 0u);
}

}  // namespace
