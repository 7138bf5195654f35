// SPDX-License-Identifier: MIT
// nbmc::io internals: triangle meshes as HDF5 datasets with an XDMF
// descriptor (ParaView, VisIt), and the XML escaping shared with the VTK XML
// writers. Used by write_mesh (src/io/mesh.cpp); not a public interface.
//
// Layout of one mesh in a group G ("/" for a single mesh, "/frame_<n>" for
// the frames of a sequence):
//   G/positions           float32 [V][3]      (float64 with MeshView::positions64)
//   G/triangles           uint32  [T][3], 0-based
//   G/normals             float32 [V][3]      (when the mesh has normals)
//   G/attributes/<name>   float64 [V] or [V][3]
#ifndef NBMC_IO_MESH_XDMF_HPP
#define NBMC_IO_MESH_XDMF_HPP

#include "io/mesh.hpp"

#include <functional>
#include <string>

namespace nbmc::io::detail {

// s with <, >, &, " as entities and control characters as '_'.
std::string xml_escape(const std::string& s);

// Writes m into the HDF5 file at path `file` under `group` ("/" or a
// top-level group name such as "/frame_0003"). create: make a new file
// (truncating one that exists); otherwise open the file for writing (it is
// created when missing) and replace a group of that name. name is the file
// name for messages. cancelled is polled between datasets; on a cancel the
// group is removed and Cancelled thrown.
void write_hdf5_mesh(const std::string& file, const std::string& name, const std::string& group, bool create,
                     const MeshView& m, const std::function<bool()>& cancelled);

// The XDMF 3 descriptor of the meshes in the HDF5 file `file`: the mesh at
// its root, or a temporal collection of its top-level groups that hold one
// (in the order of the number in their names, which is also their time).
// h5_ref is the file name the descriptor refers to (relative to it).
std::string xdmf_for_hdf5(const std::string& file, const std::string& name, const std::string& h5_ref);

// Whether the HDF5 file holds a mesh under group (for --resume).
bool hdf5_mesh_exists(const std::string& file, const std::string& group);

} // namespace nbmc::io::detail

#endif
