// SPDX-License-Identifier: MIT
// A mesh's incidence built where the mesh was made, for the clean-up's first
// run on that mesh (mesh_cleanup.hpp: cleanup_mesh's `prebuilt`). The CUDA
// pipeline builds it on the GPU right after marching cubes and downloads it
// with the mesh (backends/kokkos/mesh_incidence.hpp); the clean-up then
// skips its own build and its scan of every triangle. Plain C++.
#pragma once

#include "params.hpp"  // NoInitAllocator

#include <cstddef>
#include <cstdint>
#include <vector>

namespace nbmc {
namespace mesh {

// One flag per triangle (1: kept): cleanup_mesh's output (mesh_cleanup.hpp)
// when its caller compacts the mesh itself (a device mesh: on the GPU).
using AliveFlags = std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>>;
// What a clean-up that leaves the compaction to its caller wrote
// (mesh_cleanup.hpp, cleanup_mesh's `changed`), each entry once, in no
// particular order: the vertices whose position or normal it wrote and the
// triangles whose vertices it wrote.
// Everything else is as it was (every write of a repair goes through the
// Cleaner's log_ functions, which set the flags these lists are made of); a
// write that was undone stays listed.
struct ChangedEntries {
  std::vector<std::uint32_t> vertices, triangles;
};

struct PrebuiltIncidence {
  using Indices = std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>>;
  // Per vertex v, its triangles in ascending order: incident[start[v] ..
  // start[v + 1]); start has nv + 1 entries, start[nv] = 3 nt.
  Indices start, incident;
  // A bit per triangle t (bit t % 32 of word t / 32): set for every triangle
  // that surely_good (mesh_check.hpp) may reject, with the clean-up's
  // degenerate area (relative to the positions' bounding box); the
  // clean-up classifies exactly these.
  Indices maybe_bad;
  // maybe_bad's words for nt triangles; the words of all three arrays.
  static std::uint64_t bit_words(std::uint64_t nt) { return (nt + 31) / 32; }
  static std::uint64_t words(std::uint64_t nv, std::uint64_t nt) { return (nv + 1) + 3 * nt + bit_words(nt); }
  bool empty() const { return start.empty(); }
  // Whether it can be the incidence of a mesh of nv vertices and nt
  // triangles (the sizes; the content is the builder's contract).
  bool fits(std::size_t nv, std::size_t nt) const {
    return start.size() == nv + 1 && start[nv] == 3 * nt && incident.size() == 3 * nt &&
           maybe_bad.size() == bit_words(nt);
  }
  void clear() { *this = PrebuiltIncidence(); }
};

}  // namespace mesh
}  // namespace nbmc
