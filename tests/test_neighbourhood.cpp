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

// The sub-cell table (dense_sub): for every occupied cell, byte q - 1 is the
// number of the cell's particles with x below the cell's q-th quarter point,
// or the whole word is all ones (a cell of more than 254 particles); and a
// sub_range is the cells' particles cut at those points.
TEST(Neighbourhood, SubCellsSplitEveryCellAtItsQuarterPoints) {
  const double r = 0.05;
  Points p = ball(r, 7, 8);
  // A crowded cell: 400 particles within 0.2 r (one cell is 2 r wide); and
  // a clump of 254 within 0.1 r (one cell of 254 or more particles, or two).
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> u(-0.1 * r, 0.1 * r);
  for (int i = 0; i < 400; ++i) p.insert(p.end(), {u(rng), u(rng), u(rng)});
  for (int i = 0; i < 254; ++i) p.insert(p.end(), {5 * r + 0.5 * u(rng), 5 * r + 0.5 * u(rng), 0.5 * u(rng)});
  Built b;
  build(p, params(r), b);
  ASSERT_GT(b.nbh.dense_sub.size(), 0u);
  const NeighbourView<Host> v = view_of(b.nbh, b.g);
  const float* X = b.nbh.pos.data();
  std::size_t crowded = 0, checked = 0;
  for (std::size_t c = 0; c < b.nbh.n_cells; ++c) {
    const std::uint64_t key = b.nbh.cell_keys.view()(c);
    std::int64_t x, y, z;
    neighbour_cell_of_key(key, b.g.nb_dims, x, y, z);
    std::uint32_t cb, ce;
    ASSERT_TRUE(v.cell_range(x, y, z, cb, ce));
    const std::uint32_t word = v.dense_sub(std::size_t(key));
    if (ce - cb > 254) {
      EXPECT_EQ(word, ~std::uint32_t(0));
      ++crowded;
    } else {
      for (int q = 1; q <= 3; ++q) {
        std::uint32_t below = 0;
        for (std::uint32_t j = cb; j < ce; ++j) below += X[j] < v.sub_edge(4 * x + q) ? 1u : 0u;
        EXPECT_EQ((word >> (8 * (q - 1))) & 255u, below) << "cell " << x << " " << y << " " << z << ", q " << q;
      }
    }
    // sub_range over this cell's sub-cells m0..m1: its particles with
    // sub_edge(m0) <= x < sub_edge(m1 + 1) (all of them where unknown).
    for (int q0 = 0; q0 < 4; ++q0)
      for (int q1 = q0; q1 < 4; ++q1) {
        std::uint32_t sb, se;
        v.sub_range(4 * x + q0, 4 * x + q1, y, z, sb, se);
        ASSERT_LE(cb, sb);
        ASSERT_LE(se, ce);
        ASSERT_LE(sb, se);
        for (std::uint32_t j = cb; j < ce; ++j) {
          const bool inside = !(X[j] < v.sub_edge(4 * x + q0)) && X[j] < v.sub_edge(4 * x + q1 + 1);
          if (inside) EXPECT_TRUE(j >= sb && j < se) << "particle " << j << " left out";
          else if (ce - cb <= 254) EXPECT_FALSE(j >= sb && j < se) << "particle " << j << " kept";
        }
        ++checked;
      }
  }
  EXPECT_GE(crowded, 1u) << "the cell of 400 particles";
  EXPECT_GT(checked, 0u);
  setenv("NBMC_SUB_CELLS", "0", 1);
  Built off;
  build(p, params(r), off);
  unsetenv("NBMC_SUB_CELLS");
  EXPECT_EQ(off.nbh.dense_sub.size(), 0u);
  EXPECT_GT(off.nbh.dense_start.size(), 0u);
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
