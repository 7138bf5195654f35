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

// Where a clean-up's result differs from its input (mesh_cleanup.hpp,
// cleanup_mesh's `changed`), each place once, in no particular order,
// below the result's counts: the vertices whose position or normal may differ from
// the input's at the same place, and the triangles whose vertices may.
// Everything else below the counts is as it was (every write of a repair
// goes through the Cleaner's log_ functions, which list it; the compaction
// lists the places it fills and renumbers); a write that was undone stays
// listed. valid: filled by a clean-up (empty lists then mean: nothing
// differs).
struct ChangedEntries {
  std::vector<std::uint32_t> vertices, triangles;
  bool valid = false;
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
  // moves_made: the clean-up's move rounds (mesh_moves.hpp) were made on
  // this mesh where it was made; then the moves made, the bad triangles
  // before them and the degenerate area they judged with (the clean-up goes on from its scan, which finds what they
  // left: the bits above are set for every triangle bad before them).
  bool moves_made = false;
  std::uint64_t moves = 0, bad_before_moves = 0;
  double degenerate_double_area = 0;  // (the clean-up's, from the extent before them)
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
