// SPDX-License-Identifier: MIT
// nbmc::io — particle readers: positions plus per-particle attributes.
//
// Formats (docs/formats.md has the details):
//  - "xyz":    raw little-endian float32 x, y, z triples, no header;
//  - "ply":    PLY point sets (ascii / binary), vertex x, y, z float or
//              double; other scalar vertex properties become attributes;
//  - "vtk":    legacy VTK (ascii / binary), POLYDATA, UNSTRUCTURED_GRID,
//              STRUCTURED_GRID: POINTS plus POINT_DATA arrays;
//  - "vtu", "vtp": VTK XML UnstructuredGrid / PolyData (ascii, inline
//              base64, raw or base64 appended data, optional zlib);
//  - "bgeo":   Houdini classic binary geometry (partio), gzip or not;
//  - "h5part": HDF5, Step#<n> groups with 1-D x, y, z (H5Part, SPH-EXA);
//  - "pysph":  HDF5, /particles/<name>/arrays/{x,y,z,...};
//  - "gadget": HDF5, /PartType0/Coordinates N x 3 (GADGET, SWIFT);
//  - "hdf5":   HDF5 with the layout detected from the content, or the object
//              named after the file: "file.h5:/path" (an N x 3 dataset, or a
//              group with 1-D x, y, z).
//
// Every problem throws nbmc::io::Error with a message that names the file.
// Counts in headers are checked against the size of the data before anything
// is reserved, so lying or truncated files fail cleanly. Values are not
// validated (NaN passes through; nbmc_context_set_particles_* checks them).
#ifndef NBMC_IO_PARTICLES_HPP
#define NBMC_IO_PARTICLES_HPP

#include "io/attributes.hpp"
#include "io/error.hpp"

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace nbmc::io {

struct Particles {
  std::vector<double> xyz;           // x, y, z of particle i at 3*i .. 3*i+2
  std::vector<Attribute> attributes; // one item per particle each
  double time = std::numeric_limits<double>::quiet_NaN(); // simulation time when the file has one
  std::size_t count() const { return xyz.size() / 3; }
  const Attribute* attribute(const std::string& name) const { return find_attribute(attributes, name); }
};

struct ReadOptions {
  std::string format;             // a name listed above (case-insensitive), or "" for the extension
  bool attributes = true;         // read per-particle attributes where the format has them
  std::vector<std::string> only;  // when not empty, only these attributes (others are skipped)
  std::int64_t frame = -1;        // multi-step files (H5Part): the step number; -1 = the first
  // HDF5 layouts: read only share `part` of `parts` of the particles (rows
  // [n part / parts, n (part + 1) / parts) of the position datasets, by
  // hyperslab), as each MPI rank does; attributes are then not read.
  std::uint32_t part = 0, parts = 1;
};

// Reads a particle file. format: one of the names above, or "" to take it
// from the extension of path ("file.h5:/object" selects an HDF5 object).
Particles read_particles(const std::string& path, const std::string& format = "");
Particles read_particles(const std::string& path, const ReadOptions& options);

// Parses particles from a memory block (the format is required, or taken
// from name's extension); name is used in error messages. For fuzzing and
// tests.
Particles parse_particles(const void* data, std::size_t size, const std::string& format,
                          const std::string& name = "<memory>");
Particles parse_particles(const void* data, std::size_t size, const ReadOptions& options,
                          const std::string& name = "<memory>");

// The format read_particles would use for path and format (a canonical name
// from the list above); throws Error for an unknown extension or format name.
std::string particle_format(const std::string& path, const std::string& format = "");

// The frames one file holds: the step numbers of an H5Part file (ascending);
// empty for formats with one frame per file.
std::vector<std::int64_t> list_frames(const std::string& path, const std::string& format = "");

// All format names read_particles accepts.
const std::vector<std::string>& particle_format_names();

} // namespace nbmc::io

#endif
