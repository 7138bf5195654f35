// SPDX-License-Identifier: MIT
// Neighbourhood: particle handlers sorted by the key of their neighbour-grid
// cell (cell size S = max(R/2, surface radius), grid.hpp; the key is the
// cell's row-major index x + nx (y + ny z), so that the cells of one row in x
// are consecutive), then by position, so that the order (and every sum over
// it) is independent of the input order. Occupied cells are kept as a sorted
// list with start indices and a hash map key -> cell, so memory follows the
// particles, never the bounding box; where the grid is small enough, a dense
// table of start indices (the paper's startIndices array) serves the lookups.
#pragma once

#include "common.hpp"
#include "grid.hpp"

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
#if defined(_OPENMP)
#include <parallel/algorithm>
#endif

namespace nbmc {
namespace Details {

template <class MemSpace>
struct Neighbourhood {
  std::size_t n = 0, n_cells = 0;
  Buffer<float, MemSpace> pos;            // 3 * n: all x, then all y, then all z (relative to the grid origin)
  Buffer<std::uint32_t, MemSpace> perm;   // sorted index -> uploaded index
  Buffer<std::uint64_t, MemSpace> cell_keys;
  Buffer<std::uint32_t, MemSpace> cell_start;  // n_cells + 1
  HashMapStorage<MemSpace> cells;              // cell key -> cell index (without dense_start)
  // Where the neighbour grid is small enough (dense_cells_allowed), the
  // start of every grid cell's particles, by cell key, and n at the end
  // (empty cells start where the next occupied one does): one load per cell
  // lookup instead of a hash and a probe, and a whole row of cells in x is
  // one range. Empty otherwise, and then the hash map, which is built only
  // then, serves. Both give the same ranges.
  Buffer<std::uint32_t, MemSpace> dense_start;
  // With dense_start: where each cell's particles cross the quarter points
  // of the cell in x (sub_cell_edge: four sub-cells per cell): for q = 1, 2,
  // 3, byte q - 1 of dense_sub(d) is how many of cell d's particles have
  // x < sub_cell_edge(4 x_d + q); all bits set where the cell holds more than
  // 254 particles (unknown: use the whole cell). A gather then cuts a row to
  // the sub-cells that a vertex's ball can reach without walking particles.
  Buffer<std::uint32_t, MemSpace> dense_sub;
  // On a device: the positions once more, one float4 (x, y, z, 0) per
  // particle, for the gathers' 16-byte loads (Aos4Positions; 16 bytes per
  // particle). Empty on the host, and with NBMC_GPU_POS4=0.
  Buffer<float, MemSpace> pos4;
  // Per-particle data of a field method with a pass over the particles (P
  // floats per particle, sorted order: SPH's weight, YT10's kernel; with
  // per-particle radii, SSP07's and ZB05's radius r_j, radii.hpp); empty
  // for the others.
  Buffer<float, MemSpace> pdata;
  // Per-particle radii (radii.hpp), sorted order; empty without them.
  Buffer<float, MemSpace> scale;    // t_j = r_j / r_max, in (0, 1]
  Buffer<float, MemSpace> support;  // 1 / R_j^2, R_j = R t_j
};

// Where sub-cell m of a row starts in x, for sub-cells of width w
// (sub_cell_width): the one expression for the table's builder and the
// gathers' cuts (NeighbourView::sub_edge), which must agree bit for bit.
KOKKOS_INLINE_FUNCTION float sub_cell_edge(int m, float w) { return float(m) * w; }

// The key of neighbour cell (x, y, z): its row-major index in the grid.
KOKKOS_INLINE_FUNCTION std::uint64_t neighbour_cell_key(std::int64_t x, std::int64_t y, std::int64_t z,
                                                        const std::int64_t dims[3]) {
  return std::uint64_t(x) + std::uint64_t(dims[0]) * (std::uint64_t(y) + std::uint64_t(dims[1]) * std::uint64_t(z));
}
KOKKOS_INLINE_FUNCTION void neighbour_cell_of_key(std::uint64_t key, const std::int64_t dims[3], std::int64_t& x,
                                                  std::int64_t& y, std::int64_t& z) {
  const std::uint64_t row = key / std::uint64_t(dims[0]);
  x = std::int64_t(key - row * std::uint64_t(dims[0]));
  z = std::int64_t(row / std::uint64_t(dims[1]));
  y = std::int64_t(row - std::uint64_t(z) * std::uint64_t(dims[1]));
}

// Read-only device view of a neighbourhood for kernels.
template <class MemSpace>
struct NeighbourView {
  Kokkos::View<const float*, MemSpace> pos;  // SoA: x(j) = pos(j), y(j) = pos(n + j), z(j) = pos(2n + j)
  std::size_t n;
  Kokkos::View<const std::uint32_t*, MemSpace> cell_start;
  HashMap<MemSpace> cells;
  std::int64_t nb_dims[3];
  float inv_nb_cell;
  // Per-particle data of the field method (Neighbourhood::pdata): particle
  // j's P floats at pdata(P j), ..., pdata(P j + P - 1); empty if P = 0.
  Kokkos::View<const float*, MemSpace> pdata;
  // Per-particle radii (radii.hpp; sorted order, empty without them): the
  // radius relative to the largest, t_j, and the kernel's 1 / R_j^2.
  Kokkos::View<const float*, MemSpace> scale, support;
  // Neighbourhood::dense_start (empty: look cells up in the hash map).
  Kokkos::View<const std::uint32_t*, MemSpace> dense_start;
  // Neighbourhood::dense_sub (empty with the hash map) and the sub-cells'
  // width (sub_cell_width).
  Kokkos::View<const std::uint32_t*, MemSpace> dense_sub;
  float sub_width = 0;
  // Neighbourhood::pos4 (empty: read pos).
  Kokkos::View<const float*, MemSpace> pos4;

  KOKKOS_INLINE_FUNCTION std::uint64_t key(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return neighbour_cell_key(x, y, z, nb_dims);
  }
  // Range of particles of neighbour cell (x, y, z), which must lie in the
  // grid (0 <= x < nb_dims[0], ...); false if the cell is unoccupied.
  KOKKOS_INLINE_FUNCTION bool cell_range(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& b,
                                         std::uint32_t& e) const {
    if (dense_start.extent(0) != 0) {
      const std::size_t d = std::size_t(key(x, y, z));
      b = dense_start(d);
      e = dense_start(d + 1);
      return e != b;
    }
    const std::uint32_t c = cells.find(key(x, y, z));
    if (c == ~0u) return false;
    b = cell_start(c);
    e = cell_start(c + 1);
    return true;
  }
  // With the dense table only: the particles of cells x0..x1 of row (y, z),
  // one range (the row's cells are consecutive in the sorted order).
  KOKKOS_INLINE_FUNCTION void row_range(std::int64_t x0, std::int64_t x1, std::int64_t y, std::int64_t z,
                                        std::uint32_t& b, std::uint32_t& e) const {
    const std::size_t d = std::size_t(key(0, y, z));
    b = dense_start(d + std::size_t(x0));
    e = dense_start(d + std::size_t(x1) + 1);
  }
  // Whether rows can be cut to sub-cells: the dense table and its sub-cell
  // splits (sub_range) are there.
  KOKKOS_INLINE_FUNCTION bool has_sub_cells() const {
    return dense_start.extent(0) != 0 && dense_sub.extent(0) != 0;
  }
  // The x at which sub-cell m of a row starts (sub_cell_edge).
  KOKKOS_INLINE_FUNCTION float sub_edge(int m) const { return sub_cell_edge(m, sub_width); }
  // With dense_sub: one range of row (y, z)'s particles, in sorted order,
  // for sub-cells m0..m1 (0 <= m0 <= m1 < 4 nb_dims[0]): the particles of
  // cells m0 / 4 .. m1 / 4, less those of the first cell with
  // x < sub_edge(m0) and those of the last with x >= sub_edge(m1 + 1)
  // (none left out of a cell whose splits are unknown).
  KOKKOS_INLINE_FUNCTION void sub_range(int m0, int m1, int y, int z, std::uint32_t& b, std::uint32_t& e) const {
    const std::size_t d = std::size_t(key(0, y, z));
    const std::size_t c0 = d + std::size_t(m0 >> 2), c1 = d + std::size_t(m1 >> 2);
    const int q0 = m0 & 3, q1 = m1 & 3;
    b = dense_start(c0);
    if (q0 != 0) {
      const std::uint32_t k = (dense_sub(c0) >> (8 * (q0 - 1))) & 255u;
      if (k != 255u) b += k;
    }
    if (q1 == 3) {
      e = dense_start(c1 + 1);
    } else {
      const std::uint32_t k = (dense_sub(c1) >> (8 * q1)) & 255u;
      e = k != 255u ? dense_start(c1) + k : dense_start(c1 + 1);
    }
  }
};

// The width of the sub-cells of Neighbourhood::dense_sub: a quarter of the
// neighbour cell (the same float on every backend, for the builder and the
// gathers).
inline float sub_cell_width(const Grid& g) { return float(g.nb_cell) * 0.25f; }

template <class MemSpace>
NeighbourView<MemSpace> view_of(const Neighbourhood<MemSpace>& nb, const Grid& g) {
  NeighbourView<MemSpace> v;
  v.pos = nb.pos.view();
  v.n = nb.n;
  v.cell_start = nb.cell_start.view();
  v.cells = nb.cells.map;
  for (int a = 0; a < 3; ++a) v.nb_dims[a] = g.nb_dims[a];
  v.inv_nb_cell = float(1.0 / g.nb_cell);
  v.pdata = nb.pdata.view();
  v.scale = nb.scale.view();
  v.support = nb.support.view();
  v.dense_start = nb.dense_start.view();
  v.dense_sub = nb.dense_sub.view();
  v.sub_width = sub_cell_width(g);
  v.pos4 = nb.pos4.view();
  return v;
}

struct SortRecord {
  std::uint64_t key;
  float x, y, z;
  std::uint32_t index;
};

// The order of the handlers: cell key, then x, y, z, then the uploaded index
// (a strict total order, so the sorted sequence and every sum over it are the
// same for any input order and any sort algorithm; the device sort in
// build_neighbourhood_device gives exactly this order too). With per-particle
// radii, particles at the same position are ordered by their radius before
// their index (order_by_radius), so that their sums, which read the radii,
// do not depend on the input order either.
inline bool operator<(const SortRecord& a, const SortRecord& b) {
  if (a.key != b.key) return a.key < b.key;
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  if (a.z != b.z) return a.z < b.z;
  return a.index < b.index;
}

// Neighbour cells: neighbour_cell() in src/core/grid.hpp. With a bounding box,
// kept particles may lie up to R outside the grid: they go to the boundary
// cell. That is exact for the searches, since a vertex whose cell range stops
// short of the boundary cell is farther than R from anything beyond it.

// Relative position as stored: float, with -0 made +0 so that equal
// coordinates compare (and sort by their bits) as equal everywhere.
KOKKOS_INLINE_FUNCTION float relative_coordinate(double x) { return float(x) + 0.0f; }

// The hash map key -> cell index of the occupied cells.
template <class ExecSpace>
void insert_cells(const ExecSpace& space, MemoryTracker& tracker, Neighbourhood<typename ExecSpace::memory_space>& out) {
  out.cells.allocate(space, tracker, "neighbourhood::cell_map", out.n_cells);
  auto map = out.cells.map;
  auto keys = out.cell_keys.view();
  Kokkos::parallel_for(
      "nbmc::neighbourhood::map", Kokkos::RangePolicy<ExecSpace>(space, 0, out.n_cells),
      KOKKOS_LAMBDA(const std::size_t c) {
        map.insert(keys(c));
        map.values(map.find_slot(keys(c))) = std::uint32_t(c);
      });
  space.fence();
}

// Whether the dense cell table (Neighbourhood::dense_start) is built for a
// grid of `dense` cells and n particles: when it has at most 2 entries (8
// bytes) per particle, or 64 Ki entries, so that memory still follows the
// particles, not the bounding box (Memory.TwoClumpsFarApart...). A frame's
// particles fill much of their bounding box (the 1.65 M dam-break frame:
// 1.76 M cells of 2 r, 11% of them occupied); scattered particles in a huge
// box keep the hash map alone. NBMC_DENSE_CELLS=0 turns the table off (the
// results are the same; tests compare both).
inline bool dense_cells_allowed(std::uint64_t dense, std::size_t n) {
  const char* e = std::getenv("NBMC_DENSE_CELLS");
  if (e && std::string(e) == "0") return false;
  return dense <= std::max<std::uint64_t>(std::uint64_t(1) << 16, 2 * std::uint64_t(n));
}

// Builds Neighbourhood::dense_start from the occupied cells' keys and
// starts, if dense_cells_allowed: the count of every cell at its key, then an
// exclusive scan (the particles are sorted by key).
template <class ExecSpace>
void build_dense_cells(const ExecSpace& space, MemoryTracker& tracker, const Grid& g,
                       Neighbourhood<typename ExecSpace::memory_space>& out) {
  using MemSpace = typename ExecSpace::memory_space;
  const std::uint64_t n_dense =
      std::uint64_t(g.nb_dims[0]) * std::uint64_t(g.nb_dims[1]) * std::uint64_t(g.nb_dims[2]);
  if (!dense_cells_allowed(n_dense, out.n)) {
    out.dense_start = Buffer<std::uint32_t, MemSpace>();
    out.dense_sub = Buffer<std::uint32_t, MemSpace>();
    return;
  }
  out.dense_start = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::dense_cells", std::size_t(n_dense) + 1);
  const auto start = out.dense_start.view();
  Kokkos::deep_copy(space, start, std::uint32_t(0));
  const auto keys = out.cell_keys.view();
  const auto cs = out.cell_start.view();
  Kokkos::parallel_for(
      "nbmc::neighbourhood::dense_cells", Kokkos::RangePolicy<ExecSpace>(space, 0, out.n_cells),
      KOKKOS_LAMBDA(const std::size_t c) { start(std::size_t(keys(c))) = cs(c + 1) - cs(c); });
  exclusive_scan(space, tracker, "nbmc::neighbourhood::dense_starts", start, start);
  // The sub-cell splits of every occupied cell (empty cells keep 0).
  // NBMC_SUB_CELLS=0 leaves them out (the gathers then trim rows by walking
  // their particles; the same results).
  // Sub-cell and cell coordinates must fit 32 bits (NeighbourView::sub_range).
  const char* e = std::getenv("NBMC_SUB_CELLS");
  if ((e && std::string(e) == "0") || g.nb_dims[0] > (std::int64_t(1) << 28) ||
      g.nb_dims[1] > (std::int64_t(1) << 30) || g.nb_dims[2] > (std::int64_t(1) << 30)) {
    out.dense_sub = Buffer<std::uint32_t, MemSpace>();
    return;
  }
  out.dense_sub = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::dense_sub_cells", std::size_t(n_dense), true);
  const auto sub = out.dense_sub.view();
  const auto X = out.pos.view();
  const std::uint64_t nx = std::uint64_t(g.nb_dims[0]);
  const float w = sub_cell_width(g);
  Kokkos::parallel_for(
      "nbmc::neighbourhood::dense_sub_cells", Kokkos::RangePolicy<ExecSpace>(space, 0, out.n_cells),
      KOKKOS_LAMBDA(const std::size_t c) {
        const std::uint64_t key = keys(c);
        const std::uint32_t b = cs(c), e = cs(c + 1);
        if (e - b > 254u) {
          sub(std::size_t(key)) = ~std::uint32_t(0);
          return;
        }
        const int m = 4 * int(key % nx);
        std::uint32_t packed = 0, j = b;
        for (int q = 1; q <= 3; ++q) {
          const float edge = sub_cell_edge(m + q, w);
          while (j < e && X(j) < edge) ++j;
          packed |= (j - b) << (8 * (q - 1));
        }
        sub(std::size_t(key)) = packed;
      });
}

// Neighbourhood::pos4 from pos, on a device (the host's gathers read pos).
template <class ExecSpace>
void build_pos4(const ExecSpace& space, MemoryTracker& tracker, Neighbourhood<typename ExecSpace::memory_space>& out) {
  using MemSpace = typename ExecSpace::memory_space;
  out.pos4 = Buffer<float, MemSpace>();
  if constexpr (!Kokkos::SpaceAccessibility<Kokkos::HostSpace, MemSpace>::accessible) {
    const char* e = std::getenv("NBMC_GPU_POS4");
    if ((e && std::string(e) == "0") || out.n == 0) return;
    out.pos4 = Buffer<float, MemSpace>(tracker, "neighbourhood::positions4", 4 * out.n);
    const auto p4 = out.pos4.view();
    const auto pos = out.pos.view();
    const std::size_t n = out.n;
    Kokkos::parallel_for(
        "nbmc::neighbourhood::positions4", Kokkos::RangePolicy<ExecSpace>(space, 0, n),
        KOKKOS_LAMBDA(const std::size_t j) {
          p4(4 * j) = pos(j);
          p4(4 * j + 1) = pos(n + j);
          p4(4 * j + 2) = pos(2 * n + j);
          p4(4 * j + 3) = 0.f;
        });
  } else {
    (void)space;
    (void)tracker;
  }
}

// The cell lookups of a built neighbourhood: the dense table where it is
// allowed, else the hash map (one of the two, never both).
template <class ExecSpace>
void index_cells(const ExecSpace& space, MemoryTracker& tracker, const Grid& g,
                 Neighbourhood<typename ExecSpace::memory_space>& out) {
  build_dense_cells(space, tracker, g, out);
  if (out.dense_start.size() == 0) insert_cells(space, tracker, out);
  else out.cells = HashMapStorage<typename ExecSpace::memory_space>();
  build_pos4(space, tracker, out);
}

// Per-particle radii (host, uploaded order): the runs of handlers at one
// position (same cell, same x, y, z) sorted by radius, then index. Such runs
// are rare (duplicates), so this is one pass over the sorted handlers.
inline void order_by_radius(SortRecord* r, std::size_t n, const double* radii) {
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i + 1;
    while (j < n && r[j].key == r[i].key && r[j].x == r[i].x && r[j].y == r[i].y && r[j].z == r[i].z) ++j;
    if (j - i > 1)
      std::sort(r + i, r + j, [radii](const SortRecord& a, const SortRecord& b) {
        const double ra = radii[a.index], rb = radii[b.index];
        return ra != rb ? ra < rb : a.index < b.index;
      });
    i = j;
  }
}

// Builds the neighbourhood from host positions (absolute, double, 3 per particle).
// `keep` (may be empty) selects the particles to use; `radii` (null without
// per-particle radii) are the uploaded particles' radii.
template <class ExecSpace>
void build_neighbourhood(const ExecSpace& space, MemoryTracker& tracker, const double* xyz, std::size_t count,
                         const std::vector<std::uint32_t>& keep, const Grid& g,
                         Neighbourhood<typename ExecSpace::memory_space>& out, const double* radii = nullptr) {
  using MemSpace = typename ExecSpace::memory_space;
  ScopedRegion region("nbmc::neighbourhood");
  const std::size_t n = keep.empty() ? count : keep.size();
  out.n = n;

  // Handlers: (cell key, position) for every particle, computed on the host
  // (the positions are on the host), sorted with a parallel sort.
  Buffer<SortRecord, Kokkos::HostSpace> rec(tracker, "neighbourhood::handlers", n);
  SortRecord* r = rec.data();
  const double o0 = g.origin[0], o1 = g.origin[1], o2 = g.origin[2];
  const double inv_s = 1.0 / g.nb_cell;
  const std::int64_t nd0 = g.nb_dims[0], nd1 = g.nb_dims[1], nd2 = g.nb_dims[2];
  const std::int64_t dims[3] = {nd0, nd1, nd2};
  const std::uint32_t* kp = keep.empty() ? nullptr : keep.data();
  using HostExec = Kokkos::DefaultHostExecutionSpace;
  auto host_space = [&]() {
    if constexpr (std::is_same<typename ExecSpace::memory_space, Kokkos::HostSpace>::value &&
                  !std::is_same<ExecSpace, HostExec>::value)
      return ExecSpace(space);  // e.g. Serial when the default host space is OpenMP
    else
      return HostExec();
  }();
  using HostPolicyExec = decltype(host_space);
  Kokkos::parallel_for(
      "nbmc::neighbourhood::keys", Kokkos::RangePolicy<HostPolicyExec>(host_space, 0, n), [=](const std::size_t i) {
        const std::uint32_t src = kp ? kp[i] : std::uint32_t(i);
        const double px = xyz[3 * std::size_t(src)] - o0, py = xyz[3 * std::size_t(src) + 1] - o1,
                     pz = xyz[3 * std::size_t(src) + 2] - o2;
        SortRecord s;
        s.x = relative_coordinate(px);
        s.y = relative_coordinate(py);
        s.z = relative_coordinate(pz);
        s.key = neighbour_cell_key(neighbour_cell(px, inv_s, nd0), neighbour_cell(py, inv_s, nd1),
                                   neighbour_cell(pz, inv_s, nd2), dims);
        s.index = src;
        r[i] = s;
      });
  host_space.fence();
#if defined(_OPENMP)
  if (std::is_same<HostPolicyExec, Kokkos::Serial>::value)
    std::sort(r, r + n);
  else
    __gnu_parallel::sort(r, r + n);
#else
  std::sort(r, r + n);
#endif
  if (radii) order_by_radius(r, n, radii);

  // Cells: start indices of each run of equal keys, counted, then written
  // by a parallel scan (a serial pass over the handlers was a serial part of
  // this stage: about 10 ms for the 1.65 M frame).
  std::uint64_t n_cells = 0;
  Kokkos::parallel_reduce(
      "nbmc::neighbourhood::count_cells", Kokkos::RangePolicy<HostPolicyExec>(host_space, 0, n),
      [=](const std::size_t i, std::uint64_t& acc) { acc += (i == 0 || r[i].key != r[i - 1].key) ? 1 : 0; },
      n_cells);
  out.n_cells = std::size_t(n_cells);

  out.pos = Buffer<float, MemSpace>(tracker, "neighbourhood::positions", 3 * n);
  out.perm = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::permutation", n);
  out.cell_keys = Buffer<std::uint64_t, MemSpace>(tracker, "neighbourhood::cell_keys", out.n_cells);
  out.cell_start = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::cell_start", out.n_cells + 1);
  {
    auto hpos = Kokkos::create_mirror_view(out.pos.view());
    auto hperm = Kokkos::create_mirror_view(out.perm.view());
    auto hkeys = Kokkos::create_mirror_view(out.cell_keys.view());
    auto hstart = Kokkos::create_mirror_view(out.cell_start.view());
    Kokkos::parallel_for(
        "nbmc::neighbourhood::scatter", Kokkos::RangePolicy<HostPolicyExec>(host_space, 0, n),
        [=](const std::size_t i) {
          hpos(i) = r[i].x;
          hpos(n + i) = r[i].y;
          hpos(2 * n + i) = r[i].z;
          hperm(i) = r[i].index;
        });
    Kokkos::parallel_scan(
        "nbmc::neighbourhood::cells", Kokkos::RangePolicy<HostPolicyExec>(host_space, 0, n),
        [=](const std::size_t i, std::uint64_t& c, const bool final) {
          const bool first = i == 0 || r[i].key != r[i - 1].key;
          if (final && first) {
            hstart(c) = std::uint32_t(i);
            hkeys(c) = r[i].key;
          }
          c += first ? 1 : 0;
        });
    host_space.fence();
    hstart(out.n_cells) = std::uint32_t(n);
    Kokkos::deep_copy(space, out.pos.view(), hpos);
    Kokkos::deep_copy(space, out.perm.view(), hperm);
    Kokkos::deep_copy(space, out.cell_keys.view(), hkeys);
    Kokkos::deep_copy(space, out.cell_start.view(), hstart);
    space.fence();
  }
  rec.release();
  index_cells(space, tracker, g, out);
}

// Unsigned bits of a float that sort in the float's order (no NaN; -0 is
// made +0 by relative_coordinate).
KOKKOS_INLINE_FUNCTION std::uint64_t float_order_bits(float f) {
  union {
    float f;
    std::uint32_t u;
  } b;
  b.f = f;
  return (b.u & 0x80000000u) ? std::uint64_t(~b.u) : std::uint64_t(b.u | 0x80000000u);
}

// The bits of a positive double, which sort in its order.
KOKKOS_INLINE_FUNCTION std::uint64_t positive_double_bits(double d) {
  union {
    double d;
    std::uint64_t u;
  } b;
  b.d = d;
  return b.u;
}

// Longest run of equal (cell key, x) that the one-sort path orders by one
// thread; NBMC_SORT_PASSES=1 takes the four sort passes always (tests).
constexpr std::size_t kMaxTieRun = 64;
inline bool one_sort_allowed() {
  const char* e = std::getenv("NBMC_SORT_PASSES");
  return !(e && std::string(e) == "1");
}

// The same neighbourhood, built on the device from device positions (absolute,
// double, 3 per particle; `keep`, if not empty, selects the particles, in
// increasing order). The handlers get exactly the host's order: key, x, y,
// z, then index. Usually by one radix sort by (key, x) and the runs of equal
// (key, x) ordered by (y, z) (below); else by four stable radix sorts, least
// significant criterion first (z, y, x, then the cell key). With
// per-particle radii (`radii`, device memory, uploaded order; empty
// without), a first pass by radius gives the host's order_by_radius too.
template <class ExecSpace>
void build_neighbourhood_device(const ExecSpace& space, MemoryTracker& tracker,
                                const Kokkos::View<const double*, typename ExecSpace::memory_space>& xyz,
                                const Kokkos::View<const std::uint32_t*, typename ExecSpace::memory_space>& keep,
                                std::size_t n, const Grid& g, Neighbourhood<typename ExecSpace::memory_space>& out,
                                const Kokkos::View<const double*, typename ExecSpace::memory_space>& radii = {}) {
  using MemSpace = typename ExecSpace::memory_space;
  using Range = Kokkos::RangePolicy<ExecSpace>;
  ScopedRegion region("nbmc::neighbourhood");
  out.n = n;
  Buffer<float, MemSpace> rel(tracker, "neighbourhood::unsorted_positions", 3 * n);
  Buffer<std::uint64_t, MemSpace> cell(tracker, "neighbourhood::unsorted_keys", n);
  Buffer<std::uint64_t, MemSpace> ka(tracker, "neighbourhood::sort_keys", n), kb(tracker, "neighbourhood::sort_keys", n);
  Buffer<std::uint32_t, MemSpace> va(tracker, "neighbourhood::sort_order", n), vb(tracker, "neighbourhood::sort_order", n);
  const auto relv = rel.view();
  const auto cellv = cell.view();
  const bool has_keep = keep.extent(0) > 0;
  const double o0 = g.origin[0], o1 = g.origin[1], o2 = g.origin[2];
  const double inv_s = 1.0 / g.nb_cell;
  const std::int64_t nd0 = g.nb_dims[0], nd1 = g.nb_dims[1], nd2 = g.nb_dims[2];
  const std::int64_t dims[3] = {nd0, nd1, nd2};
  {
    const auto order = va.view();
    Kokkos::parallel_for(
        "nbmc::neighbourhood::keys", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t i) {
          const std::size_t src = has_keep ? std::size_t(keep(i)) : i;
          const double px = xyz(3 * src) - o0, py = xyz(3 * src + 1) - o1, pz = xyz(3 * src + 2) - o2;
          relv(i) = relative_coordinate(px);
          relv(n + i) = relative_coordinate(py);
          relv(2 * n + i) = relative_coordinate(pz);
          cellv(i) = neighbour_cell_key(neighbour_cell(px, inv_s, nd0), neighbour_cell(py, inv_s, nd1),
                                        neighbour_cell(pz, inv_s, nd2), dims);
          order(i) = std::uint32_t(i);
        });
  }
  int key_bits = 1;  // of the cell keys, < nx ny nz
  {
    const std::uint64_t m = std::uint64_t(nd0) * std::uint64_t(nd1) * std::uint64_t(nd2);
    while (key_bits < 64 && (std::uint64_t(1) << key_bits) < m) ++key_bits;
  }
  std::uint32_t* order = va.data();
  std::uint32_t* other = vb.data();
  std::uint64_t* keys_in = ka.data();
  std::uint64_t* keys_out = kb.data();
  const bool by_radius = radii.extent(0) > 0;
  // The sorted keys are the cell keys shifted left by key_shift bits.
  int key_shift = 0;
  if (!by_radius && key_bits <= 32 && one_sort_allowed()) {
    // One sort by (cell key, x), then the runs of equal (cell key, x) put in
    // (y, z) order by one thread each: the same order as the four passes
    // below, since the sort is stable (equal y and z stay in index order).
    // Such runs are rare (equal float x in one cell: duplicates, lattices);
    // one longer than kMaxTieRun sends the whole sort to the four passes.
    Kokkos::parallel_for(
        "nbmc::neighbourhood::cell_x_keys", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t i) {
          keys_in[i] = (cellv(i) << 32) | float_order_bits(relv(i));
        });
    device_sort_pairs(space, tracker, keys_in, keys_out, order, other, n, 32 + key_bits);
    const std::uint64_t* const sk = keys_out;
    std::uint32_t* const sorted = other;
    std::uint64_t too_long = 0;
    Kokkos::parallel_reduce(
        "nbmc::neighbourhood::tied_x", Range(space, 0, n),
        KOKKOS_LAMBDA(const std::size_t i, std::uint64_t& bad) {
          if (i + 1 >= n || sk[i + 1] != sk[i] || (i > 0 && sk[i - 1] == sk[i])) return;
          std::size_t e = i + 2;
          while (e < n && sk[e] == sk[i] && e - i <= kMaxTieRun) ++e;
          if (e - i > kMaxTieRun) {
            bad += 1;
            return;
          }
          auto yz = [&](const std::uint32_t j) {
            return (float_order_bits(relv(n + j)) << 32) | float_order_bits(relv(2 * n + j));
          };
          for (std::size_t a = i + 1; a < e; ++a) {  // insertion sort, stable
            const std::uint32_t v = sorted[a];
            const std::uint64_t kv = yz(v);
            std::size_t b = a;
            while (b > i && yz(sorted[b - 1]) > kv) {
              sorted[b] = sorted[b - 1];
              --b;
            }
            sorted[b] = v;
          }
        },
        too_long);
    if (too_long == 0) {
      std::swap(order, other);
      key_shift = 32;
    } else {
      trace("neighbourhood: long tied runs, four sort passes", too_long);
      const auto ord = va.view();
      Kokkos::parallel_for(
          "nbmc::neighbourhood::identity", Range(space, 0, n),
          KOKKOS_LAMBDA(const std::size_t i) { ord(i) = std::uint32_t(i); });
    }
  }
  for (int pass = by_radius ? -1 : 0; key_shift == 0 && pass < 4; ++pass) {  // (radius,) z, y, x, cell key
    const int axis = 2 - pass;                              // 3: the radius
    std::uint32_t* const cur = order;
    Kokkos::parallel_for(
        "nbmc::neighbourhood::sort_keys", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t i) {
          keys_in[i] = axis == 3   ? positive_double_bits(radii(has_keep ? std::size_t(keep(cur[i])) : cur[i]))
                       : axis >= 0 ? float_order_bits(relv(std::size_t(axis) * n + cur[i]))
                                   : cellv(cur[i]);
        });
    device_sort_pairs(space, tracker, keys_in, keys_out, order, other, n,
                      axis == 3 ? 63 : axis >= 0 ? 32 : key_bits);
    std::swap(order, other);
  }
  cell.release();

  out.pos = Buffer<float, MemSpace>(tracker, "neighbourhood::positions", 3 * n);
  out.perm = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::permutation", n);
  {
    const auto pos = out.pos.view();
    const auto perm = out.perm.view();
    const std::uint32_t* const sorted = order;
    Kokkos::parallel_for(
        "nbmc::neighbourhood::scatter", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t i) {
          const std::uint32_t j = sorted[i];
          pos(i) = relv(j);
          pos(n + i) = relv(n + j);
          pos(2 * n + i) = relv(2 * n + j);
          perm(i) = has_keep ? keep(j) : j;
        });
  }
  // Cells: the runs of equal keys in the sorted sequence, numbered in the
  // sort's spare order array (`other`, free after the scatter).
  const std::uint64_t* const sk = keys_out;
  const int shift = key_shift;
  const auto first = KOKKOS_LAMBDA(const std::size_t i) {
    return (i == 0 || (sk[i] >> shift) != (sk[i - 1] >> shift)) ? 1u : 0u;
  };
  const Kokkos::View<std::uint32_t*, MemSpace, Kokkos::MemoryTraits<Kokkos::Unmanaged>> cell_no(other, n);
  out.n_cells = std::size_t(prefix_counts(space, tracker, "nbmc::neighbourhood::count_cells", n, cell_no, first));
  out.cell_keys = Buffer<std::uint64_t, MemSpace>(tracker, "neighbourhood::cell_keys", out.n_cells);
  out.cell_start = Buffer<std::uint32_t, MemSpace>(tracker, "neighbourhood::cell_start", out.n_cells + 1);
  {
    const auto ck = out.cell_keys.view();
    const auto cs = out.cell_start.view();
    Kokkos::parallel_for(
        "nbmc::neighbourhood::cell_starts", Range(space, 0, n), KOKKOS_LAMBDA(const std::size_t i) {
          if (!first(i)) return;
          ck(cell_no(i)) = sk[i] >> shift;
          cs(cell_no(i)) = std::uint32_t(i);
        });
    Kokkos::deep_copy(space, Kokkos::subview(cs, out.n_cells), std::uint32_t(n));
  }
  space.fence();
  rel.release();
  index_cells(space, tracker, g, out);
}

}  // namespace Details
}  // namespace nbmc
