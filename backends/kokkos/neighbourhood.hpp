// SPDX-License-Identifier: MIT
// Neighbourhood: particle handlers sorted by the z-order (Morton) key of their
// neighbour-grid cell (cell size S = R/2), then by position, so that the order
// (and every sum over it) is independent of the input order. Occupied cells are
// kept as a sorted list with start indices and a hash map key -> cell, so memory
// follows the particles, never the bounding box (the paper's startIndices array
// is dense; ours is not).
#pragma once

#include "common.hpp"
#include "grid.hpp"

#include <algorithm>
#include <cstring>
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
  HashMapStorage<MemSpace> cells;              // Morton key -> cell index
};

// Read-only device view of a neighbourhood for kernels.
template <class MemSpace>
struct NeighbourView {
  Kokkos::View<const float*, MemSpace> pos;  // SoA: x(j) = pos(j), y(j) = pos(n + j), z(j) = pos(2n + j)
  std::size_t n;
  Kokkos::View<const std::uint32_t*, MemSpace> cell_start;
  HashMap<MemSpace> cells;
  std::int64_t nb_dims[3];
  float inv_nb_cell;

  // Range of particles of neighbour cell (x, y, z); empty if unoccupied.
  KOKKOS_INLINE_FUNCTION bool cell_range(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t& b,
                                         std::uint32_t& e) const {
    const std::uint32_t c = cells.find(morton3(std::uint32_t(x), std::uint32_t(y), std::uint32_t(z)));
    if (c == ~0u) return false;
    b = cell_start(c);
    e = cell_start(c + 1);
    return true;
  }
};

template <class MemSpace>
NeighbourView<MemSpace> view_of(const Neighbourhood<MemSpace>& nb, const Grid& g) {
  NeighbourView<MemSpace> v;
  v.pos = nb.pos.view();
  v.n = nb.n;
  v.cell_start = nb.cell_start.view();
  v.cells = nb.cells.map;
  for (int a = 0; a < 3; ++a) v.nb_dims[a] = g.nb_dims[a];
  v.inv_nb_cell = float(1.0 / g.nb_cell);
  return v;
}

struct SortRecord {
  std::uint64_t key;
  float x, y, z;
  std::uint32_t index;
};

inline bool operator<(const SortRecord& a, const SortRecord& b) {
  if (a.key != b.key) return a.key < b.key;
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

// Builds the neighbourhood from host positions (absolute, double, 3 per particle).
// `keep` (may be empty) selects the particles to use.
template <class ExecSpace>
void build_neighbourhood(const ExecSpace& space, MemoryTracker& tracker, const double* xyz, std::size_t count,
                         const std::vector<std::uint32_t>& keep, const Grid& g,
                         Neighbourhood<typename ExecSpace::memory_space>& out) {
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
        s.x = float(px);
        s.y = float(py);
        s.z = float(pz);
        // With a bounding box, kept particles may lie up to R outside the
        // grid: they go to the boundary cell. That is exact for the searches,
        // since a vertex whose cell range stops short of the boundary cell is
        // farther than R from anything beyond it.
        auto cell = [](double x, double inv, std::int64_t dim) {
          const double c = x * inv;
          return std::uint32_t(c <= 0 ? 0.0 : (c >= double(dim - 1) ? double(dim - 1) : c));
        };
        s.key = morton3(cell(px, inv_s, nd0), cell(py, inv_s, nd1), cell(pz, inv_s, nd2));
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

  // Cells: start indices of each run of equal keys.
  std::vector<std::uint32_t> starts;
  starts.reserve(n / 4 + 2);
  for (std::size_t i = 0; i < n; ++i)
    if (i == 0 || r[i].key != r[i - 1].key) starts.push_back(std::uint32_t(i));
  out.n_cells = starts.size();
  starts.push_back(std::uint32_t(n));

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
    host_space.fence();
    for (std::size_t c = 0; c < out.n_cells; ++c) hkeys(c) = r[starts[c]].key;
    std::memcpy(hstart.data(), starts.data(), starts.size() * sizeof(std::uint32_t));
    Kokkos::deep_copy(space, out.pos.view(), hpos);
    Kokkos::deep_copy(space, out.perm.view(), hperm);
    Kokkos::deep_copy(space, out.cell_keys.view(), hkeys);
    Kokkos::deep_copy(space, out.cell_start.view(), hstart);
    space.fence();
  }
  rec.release();

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

}  // namespace Details
}  // namespace nbmc
