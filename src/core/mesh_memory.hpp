// SPDX-License-Identifier: MIT
// What the mesh post-processing steps (clean-up, smoothing, decimation: all
// on the host, after the reconstruction) allocate at most, in bytes, from the
// vertex and triangle counts of the mesh they start from. The C API checks
// each step's estimate plus the mesh against the context's memory budget
// before the step runs, and counts it for the step's duration
// (src/capi_mesh.cpp); docs/api.md lists the formulas.
//
// Each estimate adds up every array the step holds at one time or another
// (so it bounds the peak whatever overlaps), with per-vertex and
// per-triangle sizes taken from the implementations:
//   mesh_cleanup.hpp (Cleaner, cleanup_mesh), mesh_smooth.hpp (smooth_mesh,
//   particle_density_ratio), mesh_decimate.hpp (Decimator, decimate_mesh),
//   mesh_check.hpp (check_mesh, compact_mesh).
// Lists whose length depends on the repairs (the clean-up's bad triangles,
// the decimation's heap) are sized for their worst case in triangles of
// the mesh (every triangle bad; every edge in the heap twice over), which
// also covers the small scratch lists of the repairs. Keep these in step
// with the implementations.
#pragma once

#include "params.hpp"

#include <cstdint>
#include <cstdio>
#include <tuple>

namespace nbmc {
namespace mesh {

// The mesh itself in host memory: positions (3 floats, or 3 doubles with
// double positions), normals (3 floats, when computed), triangles (3
// uint32 indices).
inline std::uint64_t mesh_bytes(std::uint64_t nv, std::uint64_t nt, bool double_positions, bool normals) {
  return nv * 3 * (double_positions ? 8 : 4) + (normals ? nv * 3 * 4 : 0) + nt * 3 * 4;
}

// The clean-up (cleanup_mesh) of a mesh of nv vertices and nt triangles.
//   per vertex (34 B): the triangle lists' offsets (start_) and fill
//     cursors while they are built, the renaming chains (next_, tail_) (4 B
//     each), the repair passes' slots (reservation, stamp, last write, last
//     change: 16 B; kept for the next clean-up afterwards, see
//     repair_scratch.hpp), the irregular flag and, for a device mesh, the
//     change flag (1 B each); the compaction's lists and the list heads
//     after flips (a few entries per repair) are not counted;
//   per triangle (67 B): the lists of triangles around each vertex
//     (incident_, 3 x 4 B), alive, walk state and the change flag (1 B
//     each), and the larger
//     of what is held only for a while: the (vertex, triangle) corners the
//     lists are built from (3 x 8 B, freed before the scan), or two lists of
//     bad triangles at once (the old and the new one of a pass; a (class,
//     sine, index) entry each) and the indices a pass looks at again (4 B).
// The fairing flips after it (mesh_flip.hpp) need less, once the clean-up's
// own arrays are freed: per vertex 17 B (the corner lists' heads, the
// regular flag, the conflict-free passes' claim and last flip), per
// triangle at most about 40 B (the opposite half-edges, 3 x 4 B; the unit
// normals in float, 3 x 4 B, or while the neighbours are found the corner
// lists' links instead; per half-edge the level it was looked at, 3 x 1 B;
// two flip stamps, 2 x 4 B; the edges that leave their chunk, about 5 %,
// with the passes' flips, about 2 %, 68 B each).
inline std::uint64_t cleanup_bytes(std::uint64_t nv, std::uint64_t nt) {
  constexpr std::uint64_t bad_entry = sizeof(std::tuple<int, double, std::uint32_t>);
  constexpr std::uint64_t corners = 3 * 8, passes = 2 * bad_entry + 4;
  return (nv + 1) * (4 * 4 + 16 + 2) + nt * (3 * 4 + 3 + (corners > passes ? corners : passes));
}
// Smoothing (smooth_mesh), and with feature weights the particle density
// around each vertex (particle_density_ratio, over `particles` particles;
// 0 without feature weights).
//   per vertex (136 B): neighbour lists' offsets and fill cursors (2 x 4 B),
//     two double copies of the positions (2 x 24 B), the small components'
//     restore (union-find and root 2 x 4 B, count and two volumes 3 x 8 B,
//     two centroids 2 x 24 B), the normals' accumulator is freed by then;
//     with feature weights one weight (8 B);
//   per triangle (24 B): the neighbour lists before deduplication (6 x 4 B);
//   per particle, with feature weights (72 B): the sorted (cell, index)
//     records (16 B), the cell map (a bucket per two particles and a node
//     per cell, at most one per particle: 4 + 52 B).
inline std::uint64_t smooth_bytes(std::uint64_t nv, std::uint64_t nt, std::uint64_t particles) {
  std::uint64_t b = (nv + 1) * (2 * 4 + 2 * 24 + 2 * 4 + 3 * 8 + 2 * 24) + nt * 6 * 4;
  if (particles) b += nv * 8 + particles * (16 + 4 + 52);
  return b;
}

// Decimation (decimate_mesh).
//   per vertex (163 B): the quadric (11 doubles), the stamp (4 B), two flags,
//     the triangle list's header (24 B) and allocation slack (32 B), the
//     check's used flag and list offsets (1 + 2 x 4 B), compaction's
//     renumbering (4 B); (the normals' accumulator comes after the rest is
//     freed);
//   per triangle (185 B): alive flag, the per-vertex triangle lists (3
//     entries of 4 B, capacity at most doubled), the check's half edges (3 x
//     16 B), union-find (4 B) and incidences (3 x 4 B), the heap of edge
//     collapses (at most 2 edges per triangle plus the re-pushed ones, 16 B
//     each, sized as 6 per triangle).
inline std::uint64_t decimate_bytes(std::uint64_t nv, std::uint64_t nt) {
  return (nv + 1) * (11 * 8 + 4 + 2 + 24 + 32 + 1 + 2 * 4 + 4) + nt * (1 + 2 * 3 * 4 + 3 * 16 + 4 + 3 * 4 + 6 * 16);
}

// The largest mesh each step can address, in triangles: the lists of
// triangles (or neighbours) around the vertices are offset with 32-bit
// integers, so their entries in all must stay below 2^32: 3 per triangle
// (the clean-up's incidence, the check's, which the decimation runs too),
// 6 per triangle (the smoothing's neighbour lists before their
// duplicates go). The reconstruction itself stops at 2^32 - 1 triangles
// (32-bit offsets); the C API refuses a larger mesh's step with
// NBMC_ERROR_DOMAIN_TOO_LARGE before it runs (src/capi_mesh.cpp).
constexpr std::uint64_t kMaxListEntries = 0xffffffffu;
constexpr std::uint64_t cleanup_max_triangles = kMaxListEntries / 3;   // 1,431,655,765
constexpr std::uint64_t check_max_triangles = kMaxListEntries / 3;     // (and the decimation's)
constexpr std::uint64_t smooth_max_triangles = kMaxListEntries / 6;    // 715,827,882

// Throws NBMC_ERROR_DOMAIN_TOO_LARGE when a step (its name; how to turn it
// off) cannot address a mesh of nt triangles (at most max_triangles).
inline void require_addressable(const char* step, const char* turn_off, std::uint64_t nv, std::uint64_t nt,
                                std::uint64_t max_triangles) {
  if (nt <= max_triangles) return;
  char msg[512];
  std::snprintf(msg, sizeof msg,
                "%s of %llu vertices and %llu triangles is not possible: its 32-bit list offsets address at most "
                "%llu triangles; turn it off (%s), or use a coarser cell or a subset of the particles",
                step, (unsigned long long)nv, (unsigned long long)nt, (unsigned long long)max_triangles, turn_off);
  throw Error(NBMC_ERROR_DOMAIN_TOO_LARGE, msg);
}

}  // namespace mesh
}  // namespace nbmc
