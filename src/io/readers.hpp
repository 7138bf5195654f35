// SPDX-License-Identifier: MIT
// nbmc::io internals: the per-format particle readers behind
// read_particles() and parse_particles(). Not part of any public interface.
#ifndef NBMC_IO_READERS_HPP
#define NBMC_IO_READERS_HPP

#include "io/detail.hpp"
#include "io/particles.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace nbmc::io::detail {

// Whether the attribute called name should be read under o.
bool want_attribute(const ReadOptions& o, const std::string& name);

// Merges scalar attributes named <p>x, <p>y, <p>z (or <p>_x, ...) that come
// in this order into one 3-vector attribute <p>, in place of the first.
void merge_vector_attributes(std::vector<Attribute>& list);

// Legacy VTK. When triangles is not null, polygons / cells (triangles only)
// are read into it as well.
Particles read_vtk_legacy(ByteReader& in, const ReadOptions& o, std::vector<std::uint32_t>* triangles = nullptr);

// VTK XML (UnstructuredGrid, PolyData) from a complete file in memory.
Particles read_vtk_xml(const unsigned char* data, std::size_t size, const std::string& name, const ReadOptions& o,
                       std::vector<std::uint32_t>* triangles = nullptr);

// Houdini classic BGEO (raw or gzip-compressed).
Particles read_bgeo(ByteReader& in, const ReadOptions& o);

// HDF5. layout: "h5part", "pysph", "gadget" or "hdf5" (detect); object: an
// HDF5 path ("" for none).
Particles read_hdf5_file(const std::string& file, const std::string& object, const std::string& layout,
                         const ReadOptions& o);
Particles read_hdf5_memory(const void* data, std::size_t size, const std::string& name, const std::string& object,
                           const std::string& layout, const ReadOptions& o);
std::vector<std::int64_t> hdf5_steps(const std::string& file, const std::string& object, const std::string& layout);

// Splits "file.h5:/object" into file and object when the part before ":/"
// has an HDF5 extension or (check_exists) is an existing file. Returns false
// (and leaves the outputs alone) otherwise.
bool split_hdf5_path(const std::string& path, bool check_exists, std::string& file, std::string& object);

} // namespace nbmc::io::detail

#endif
