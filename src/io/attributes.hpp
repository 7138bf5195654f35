// SPDX-License-Identifier: MIT
// nbmc::io — per-particle attributes and their interpolation onto mesh
// vertices.
//
// An attribute is a named scalar (1 component) or 3-vector (3 components)
// per particle or per vertex, stored as double.
//
// interpolate_attributes() carries particle attributes to the vertices of a
// reconstructed surface with the kernel of the scalar field,
//   k(s) = max(0, (1 - s^2)^3),  s = |x - x_j| / R,
// normalised by the sum of the weights: a(x) = sum_j k_j a_j / sum_j k_j.
// A vertex with no particle closer than R takes the value of its nearest
// particle. Particles are binned into a uniform hash grid of cell size R;
// vertices are processed in parallel (OpenMP) but every sum runs in a fixed
// order, so the result does not depend on the number of threads.
#ifndef NBMC_IO_ATTRIBUTES_HPP
#define NBMC_IO_ATTRIBUTES_HPP

#include "io/error.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nbmc::io {

struct Attribute {
  std::string name;
  int components = 1;         // 1 (scalar) or 3 (vector)
  std::vector<double> values; // components values per item, item-major
  std::size_t count() const { return components > 0 ? values.size() / static_cast<std::size_t>(components) : 0; }
};

// The attribute called name in list (exact match first, then
// case-insensitive), or null.
const Attribute* find_attribute(const std::vector<Attribute>& list, const std::string& name);

// Comma-separated list of the names in list ("vel (3), rho (1)") for
// messages.
std::string attribute_names(const std::vector<Attribute>& list);

// Interpolates the particle attributes named in names (all of them when
// names is empty) to vertex_count vertices (x, y, z floats at vertices).
// particles_xyz holds 3 doubles per particle; every attribute must have one
// item per particle. radius is R (absolute, > 0). Throws Error (kind
// argument) for an unknown name, a size mismatch or a bad radius.
std::vector<Attribute> interpolate_attributes(const std::vector<double>& particles_xyz,
                                              const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const float* vertices,
                                              std::uint64_t vertex_count, double radius);

// The same over particle_count particles at xyz (3 doubles each), on threads
// OpenMP threads (0: the OpenMP default); the result does not depend on it.
// scale (may be null; per-particle radii): particle p's kernel support is
// radius * scale[p], scale[p] in (0, 1].
std::vector<Attribute> interpolate_attributes(const double* xyz, std::size_t particle_count,
                                              const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const float* vertices,
                                              std::uint64_t vertex_count, double radius, int threads = 0,
                                              const double* scale = nullptr);
// The same at double-precision vertices (meshes made with double_positions).
std::vector<Attribute> interpolate_attributes(const double* xyz, std::size_t particle_count,
                                              const std::vector<Attribute>& attributes,
                                              const std::vector<std::string>& names, const double* vertices,
                                              std::uint64_t vertex_count, double radius, int threads = 0,
                                              const double* scale = nullptr);

} // namespace nbmc::io

#endif
