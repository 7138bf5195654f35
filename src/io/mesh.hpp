// SPDX-License-Identifier: MIT
// nbmc::io — triangle mesh writers (binary PLY, Wavefront OBJ, legacy VTK,
// VTK XML .vtu and .vtp, glTF 2.0 binary .glb, HDF5 + XDMF) and readers for
// the PLY, VTK, VTU and VTP meshes written here.
//
// Writers create a temporary file next to the destination and rename it into
// place once complete, so an interrupted or failed run never leaves a
// half-written mesh under the destination name (a killed process may leave a
// hidden ".<name>.nbmc-tmp.*" file behind). Errors throw nbmc::io::Error
// naming the file.
#ifndef NBMC_IO_MESH_HPP
#define NBMC_IO_MESH_HPP

#include "io/attributes.hpp"
#include "io/error.hpp"

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace nbmc::io {

// A mesh in flat arrays, as nbmc_mesh_* returns it. Pointers may be null when
// the matching count is 0; normals may be null (then none are written).
struct MeshView {
  const float* positions = nullptr;      // 3 * vertex_count
  // Double-precision positions (nbmc_params.double_positions), 3 *
  // vertex_count: when set, PLY (double x y z), OBJ (shortest exact
  // decimals), VTK (POINTS double), VTU/VTP (Float64) and HDF5 (float64) write
  // these instead of positions; glTF (float only) rounds them.
  const double* positions64 = nullptr;
  const float* normals = nullptr;        // 3 * vertex_count, or null
  const std::uint32_t* triangles = nullptr; // 3 * triangle_count, 0-based
  std::uint64_t vertex_count = 0;
  std::uint64_t triangle_count = 0;
  // Per-vertex attributes (each with vertex_count items), written where the
  // format allows: PLY (extra vertex properties; vectors as <name>_x, _y, _z),
  // VTK, VTU and VTP (point data), glTF (custom attributes "_<NAME>"), HDF5
  // (float64 datasets under attributes/). OBJ has no place for them.
  const Attribute* attributes = nullptr;
  std::size_t attribute_count = 0;
};

// An owning mesh (what read_mesh_ply returns).
struct Mesh {
  std::vector<float> positions;
  // The positions as the file holds them, in double (exact for float and
  // double files): PLY, VTK, VTU and VTP readers.
  std::vector<double> positions64;
  std::vector<float> normals; // empty when the file has none
  std::vector<std::uint32_t> triangles;
  std::vector<Attribute> attributes; // per vertex (VTK and VTU readers)
  std::uint64_t vertex_count() const { return positions.size() / 3; }
  std::uint64_t triangle_count() const { return triangles.size() / 3; }
  MeshView view() const;
};

// Writes m to path. format, case-insensitive, or "" to take it from the
// extension of path:
//  - "ply": binary little-endian, vertex x y z [nx ny nz] [attributes] float
//    (x y z double with positions64),
//    face "list uchar uint vertex_indices";
//  - "obj": v, vn, f a//a b//b c//c (1-based); no attributes;
//  - "vtk": legacy VTK 4.2 BINARY POLYDATA (big-endian): POINTS float,
//    POLYGONS, POINT_DATA with NORMALS "Normals" and SCALARS / VECTORS;
//  - "vtu": VTK XML UnstructuredGrid, raw appended data (UInt64 headers,
//    uncompressed), Float32 points and point data, Int64 cells;
//  - "vtp": VTK XML PolyData, the same with the triangles as <Polys>;
//  - "h5" (also ".hdf5"): HDF5 datasets positions, triangles, normals and
//    attributes/<name> (layout in mesh_xdmf.hpp) plus an XDMF descriptor
//    next to the file (same name, ".xdmf"). "file.h5:/group" writes the mesh
//    into that group of the file (created, or opened and the group replaced)
//    and the descriptor becomes a temporal collection of the file's mesh
//    groups (time: the number at the end of the group name) — how sequences
//    are written. A whole file is written atomically; a group is not;
//  - "glb": glTF 2.0 binary: POSITION (with min/max), NORMAL (unit length),
//    UNSIGNED_INT indices, attributes as "_<NAME>" accessors.
// Triangle indices are checked against vertex_count.
// cancelled, when set, is polled while writing; if it returns true the
// temporary file is removed and Cancelled is thrown.
void write_mesh(const std::string& path, const MeshView& m, const std::string& format = "",
                const std::function<bool()>& cancelled = {});

// The format write_mesh would use: "ply", "obj", "vtk", "vtu", "vtp", "glb"
// or "h5"; throws Error otherwise.
std::string mesh_format(const std::string& path, const std::string& format = "");

// The file write_mesh(path) writes: path, or "file.h5" for "file.h5:/group".
std::string mesh_output_file(const std::string& path);

// Whether the mesh write_mesh(path) would write exists: a regular file, or
// for "file.h5:/group" a mesh in that group of the file.
bool mesh_output_exists(const std::string& path);

// Reads a triangle mesh from a PLY file (any of the three encodings): vertex
// x, y, z and optionally nx, ny, nz; face list "vertex_indices" (or
// "vertex_index") of triangles only.
Mesh read_mesh_ply(const std::string& path);
Mesh parse_mesh_ply(const void* data, std::size_t size, const std::string& name = "<memory>");

// Reads a triangle mesh with its point data from PLY, legacy VTK or VTK XML
// (.vtu / .vtp); format as for write_mesh ("" = by extension). An array
// "Normals" (3 components) becomes the normals; the other point data become
// attributes (PLY: positions and normals only).
Mesh read_mesh(const std::string& path, const std::string& format = "");
Mesh parse_mesh(const void* data, std::size_t size, const std::string& format, const std::string& name = "<memory>");

} // namespace nbmc::io

#endif
