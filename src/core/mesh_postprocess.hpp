// SPDX-License-Identifier: MIT
// Figures of the mesh post-processing of one reconstruction (clean-up,
// smoothing and decimation, src/capi_mesh.cpp), kept on the context for
// nbmc_context_stats.
#pragma once

#include <cstdint>

namespace nbmc {
namespace mesh {

struct PostprocessStats {
  std::uint64_t raw_triangles = 0;     // before the clean-up
  // The clean-up's figures, summed over its runs (after marching cubes, and
  // again after smoothing), except: bad_before of the first run (the
  // marching-cubes mesh), bad_after of the last.
  std::uint64_t collapses = 0, flips = 0, moves = 0, cuts = 0;
  std::uint64_t fairing_flips = 0;     // the fairing flips after each clean-up (mesh_flip.hpp)
  std::uint64_t removed_component_triangles = 0;  // small bad components + degenerate specks
  std::uint64_t bad_before = 0, bad_after = 0;  // degenerate + sliver triangles
  double volume_before_smoothing = 0, volume_after_smoothing = 0;
  double volume_change = 0;            // after / before - 1 (0 without smoothing)
  std::uint64_t pre_decimation_triangles = 0;  // triangles before the decimation
  std::uint64_t decimate_collapses = 0;
};

}  // namespace mesh
}  // namespace nbmc
