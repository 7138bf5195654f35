// SPDX-License-Identifier: MIT
// Splitting one frame into subdomains (blocks of marching-cubes cells) and
// the ghost layer each needs. Plain C++: used by the in-process subdomain
// runner and by the MPI layer alike.
//
// A subdomain *owns* a box of cells: it triangulates those cells and no
// other. To do so exactly as the whole frame would, it works on a slightly
// larger *vertex box* (its cells' corners and one more vertex on every side:
// the leak scan looks at the cells around an owned cell, and the normals take
// central differences), and it must see every particle that can influence a
// vertex of that box. ghost_box() is the one place where that width is
// decided (docs/scale-out.md derives it):
//   * the field at a vertex sums the particles within the influence radius R;
//   * the band at a vertex depends on the surface particles within the band
//     width (their boxes), and whether a particle is a surface particle
//     depends on the particles in the neighbour cells within the surface
//     radius of its own cell (whole cells, as the surface test reads them).
// Particles are selected by whole neighbour cells (cells of S of the frame's
// neighbour grid), so a subdomain holds the same particles in the same cells,
// in the same sorted order, as the whole frame there.
#pragma once

#include "grid.hpp"
#include "params.hpp"

#include <cstdint>
#include <vector>

namespace nbmc {

struct Subdomain {
  int index = 0;
  int coord[3] = {0, 0, 0};            // position in the subdomain grid
  std::int64_t cell_lo[3] = {0, 0, 0};  // owned cells [cell_lo, cell_hi) (minimum corners)
  std::int64_t cell_hi[3] = {0, 0, 0};
  std::int64_t vert_lo[3] = {0, 0, 0};  // vertex box, inclusive: owned corners and one more vertex
  std::int64_t vert_hi[3] = {0, 0, 0};
  std::int64_t nb_lo[3] = {0, 0, 0};    // neighbour cells whose particles it needs, inclusive
  std::int64_t nb_hi[3] = {0, 0, 0};
  bool owns_cell(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return i >= cell_lo[0] && i < cell_hi[0] && j >= cell_lo[1] && j < cell_hi[1] && k >= cell_lo[2] &&
           k < cell_hi[2];
  }
};

struct Decomposition {
  Grid grid;
  int parts[3] = {1, 1, 1};
  std::vector<Subdomain> subdomains;
  // Ghost width in neighbour cells on each side of the owned cells (largest
  // over the axes), for the report.
  std::int64_t ghost_nb_cells = 0;
  std::size_t count() const { return subdomains.size(); }
};

// The frame grid: from the bounds of the particles, or from the clipping box.
// lo/hi are the particle bounds (ignored with p.use_bbox).
Grid frame_grid(const double lo[3], const double hi[3], const Params& p);
// Bounds of count particles (x, y, z doubles), for frame_grid.
void particle_bounds(const double* xyz, std::size_t count, double lo[3], double hi[3]);

// Splits the cells of g into parts[0] x parts[1] x parts[2] boxes of nearly
// equal size (parts are reduced where an axis has fewer cells).
Decomposition decompose(const Grid& g, const Params& p, const int parts[3]);

// The neighbour-cell box a subdomain with this vertex box needs (see above).
void ghost_box(const Grid& g, const Params& p, const std::int64_t vert_lo[3], const std::int64_t vert_hi[3],
               std::int64_t nb_lo[3], std::int64_t nb_hi[3]);

// n items into k nearly equal consecutive ranges: start of range i (i <= k).
std::int64_t split_point(std::int64_t n, int k, int i);

// For every subdomain, the indices of the particles it needs (owned and
// ghosts), in input order. Particles outside the clipping box extended by R
// are dropped when p.use_bbox. One pass over the particles.
std::vector<std::vector<std::uint32_t>> select_particles(const Decomposition& d, const Params& p, const double* xyz,
                                                         std::size_t count);

// The subdomains whose owned cells, grown by `margin` cells, contain cell
// (i, j, k) (appended to out).
void subdomains_near_cell(const Decomposition& d, std::int64_t i, std::int64_t j, std::int64_t k, int margin,
                          std::vector<int>& out);

// Estimated peak bytes of reconstructing `particles` particles (ghosts
// included) at these parameters: what `auto` sizes subdomains with.
std::uint64_t estimate_bytes(const Params& p, std::uint64_t particles);

// Parts per axis for `pieces` subdomains of the grid's cells, as close to
// cubes as the grid allows.
void choose_parts(const Grid& g, std::uint64_t pieces, int parts[3]);

// What the caller asked for (nbmc_context_set_subdomains).
struct SubdomainSetting {
  bool automatic = false;  // NBMC_SUBDOMAINS_AUTO: split only when over the memory budget
  int parts[3] = {1, 1, 1};
  bool split() const { return automatic || parts[0] * parts[1] * parts[2] > 1; }
};

struct SubdomainEntry {
  int index = 0;
  int coord[3] = {0, 0, 0};
  std::int64_t cell_lo[3] = {0, 0, 0}, cell_hi[3] = {0, 0, 0};
  std::uint64_t particles = 0, ghost_particles = 0, vertices = 0, triangles = 0;
  int runs = 0;  // 1, or more when neighbours' band growth made it run again
  double seconds = 0;
  int rank = 0;
};

// What happened (nbmc_context_subdomain_stats, the CLI report).
struct SubdomainReport {
  bool used = false;
  bool automatic = false;
  int parts[3] = {1, 1, 1};
  std::uint64_t count = 0;
  double ghost_width = 0;  // absolute: ghost layer beyond the owned cells (largest axis)
  std::uint64_t ghost_particles = 0, reruns = 0, exchanged_cells = 0, shared_vertices = 0;
  std::uint64_t budget_bytes = 0;  // what `auto` sized the subdomains for (0: none)
  double stitch_seconds = 0;
  std::vector<SubdomainEntry> entries;
};

}  // namespace nbmc
