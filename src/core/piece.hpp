// SPDX-License-Identifier: MIT
// A piece: the part of a frame's mesh that one subdomain (or rank)
// triangulated, with the keys that place its vertices and triangles in the
// order of the whole frame's mesh. Plain C++.
#pragma once

#include "params.hpp"

#include <cstdint>
#include <vector>

namespace nbmc {

struct Piece {
  std::vector<float, NoInitAllocator<float>> positions, normals;  // 3 per vertex (normals may be empty)
  // Instead of positions, with nbmc_params.double_positions (positions empty).
  std::vector<double, NoInitAllocator<double>> positions64;
  std::vector<std::uint32_t, NoInitAllocator<std::uint32_t>> triangles;  // 3 per triangle, indices into this piece
  // Per vertex: band_order_key() of the grid vertex owning its edge, and the
  // edge's axis (0, 1, 2). Ascending in (key, axis): the order in which the
  // whole frame numbers its mesh vertices.
  std::vector<std::uint64_t, NoInitAllocator<std::uint64_t>> vertex_keys;
  std::vector<std::uint8_t, NoInitAllocator<std::uint8_t>> vertex_axes;
  // Per triangle: band_order_key() of its cell. Ascending (the triangles of a
  // cell are consecutive, in the order of the case table).
  std::vector<std::uint64_t, NoInitAllocator<std::uint64_t>> triangle_cells;
  std::uint64_t vertex_count() const { return vertex_keys.size(); }
  std::uint64_t triangle_count() const { return triangle_cells.size(); }
};

}  // namespace nbmc
