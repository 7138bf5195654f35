// SPDX-License-Identifier: MIT
// nbmc::io — particle position readers.
//
// Formats
//  - raw ".xyz": little-endian float32 x, y, z triples, no header
//    (N = bytes / 12; any other size is an error);
//  - ".ply" point sets: ascii, binary_little_endian or binary_big_endian 1.0,
//    an element "vertex" with properties x, y, z of type float/float32 or
//    double/float64. Other scalar properties are skipped, a list property in
//    the vertex element is an error, other elements are skipped.
//
// Every problem throws nbmc::io::Error with a message that names the file.
// Counts in headers are checked against the size of the data before anything
// is reserved, so lying or truncated files fail cleanly. Values are not
// validated (NaN passes through; nbmc_context_set_particles_* checks them).
#ifndef NBMC_IO_PARTICLES_HPP
#define NBMC_IO_PARTICLES_HPP

#include "io/error.hpp"

#include <cstddef>
#include <string>
#include <vector>

namespace nbmc::io {

struct Particles {
  std::vector<double> xyz; // x, y, z of particle i at 3*i .. 3*i+2
  std::size_t count() const { return xyz.size() / 3; }
};

// Reads a particle file. format: "xyz" or "ply" (case-insensitive), or "" to
// take it from the extension of path.
Particles read_particles(const std::string& path, const std::string& format = "");

// Parses particles from a memory block (format "xyz" or "ply" required);
// name is used in error messages. For fuzzing and tests.
Particles parse_particles(const void* data, std::size_t size, const std::string& format,
                          const std::string& name = "<memory>");

// The format read_particles would use for path and format: "xyz" or "ply";
// throws Error for an unknown extension or format name.
std::string particle_format(const std::string& path, const std::string& format = "");

} // namespace nbmc::io

#endif
