// SPDX-License-Identifier: MIT
// Stitching pieces into the frame's mesh: a k-way merge by the keys of the
// pieces. A vertex on a face shared by subdomains is in every piece that
// triangulated a cell at it; it is kept once. Its position and normal must
// be bitwise the same in every such piece (they are computed from the same
// field values): stitch() verifies that and fails loudly otherwise.
#pragma once

#include "piece.hpp"

#include <cstdint>
#include <functional>
#include <vector>

namespace nbmc {

struct StitchResult {
  std::uint64_t vertices = 0, triangles = 0;
  std::uint64_t shared_vertices = 0;  // vertices found in more than one piece (kept once)
};

// Writes the merged mesh through `out`, which is called once with the final
// counts and returns the arrays to fill (normals may be null when the pieces
// have none; pieces carry either float or double positions, all the same
// kind). Throws Error(NBMC_ERROR_INTERNAL) if a shared vertex differs.
struct StitchTarget {
  float* positions = nullptr;     // the pieces' float positions go here,
  double* positions64 = nullptr;  // their double positions (Piece::positions64) here
  float* normals = nullptr;
  std::uint32_t* triangles = nullptr;
  // Optional: the keys of the merged mesh, which is then a piece itself
  // (an MPI rank's subdomains merged before the pieces of all ranks are).
  std::uint64_t* vertex_keys = nullptr;
  std::uint8_t* vertex_axes = nullptr;
  std::uint64_t* triangle_cells = nullptr;
};
StitchResult stitch(const std::vector<const Piece*>& pieces,
                    const std::function<StitchTarget(std::uint64_t vertices, std::uint64_t triangles)>& out);

}  // namespace nbmc
