// SPDX-License-Identifier: MIT
// Invariants shared by the fuzz targets: a reader either throws
// nbmc::io::Error or returns consistent particles, and does so the same way
// twice.
#ifndef NBMC_FUZZ_CHECK_HPP
#define NBMC_FUZZ_CHECK_HPP

#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/particles.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace nbmc_fuzz {

[[noreturn]] inline void die(const char* what) {
  std::fprintf(stderr, "fuzz invariant violated: %s\n", what);
  std::abort();
}

inline void check(const nbmc::io::Particles& p) {
  if (p.xyz.size() % 3 != 0) die("xyz size not a multiple of 3");
  for (const nbmc::io::Attribute& a : p.attributes) {
    if (a.components != 1 && a.components != 3) die("attribute components not 1 or 3");
    if (a.values.size() != p.count() * static_cast<std::size_t>(a.components)) die("attribute size mismatch");
    if (a.name.empty()) die("attribute without a name");
  }
}

inline bool same(double a, double b) { return (std::isnan(a) && std::isnan(b)) || a == b; }

inline void check_equal(const nbmc::io::Particles& a, const nbmc::io::Particles& b) {
  if (a.xyz.size() != b.xyz.size() || a.attributes.size() != b.attributes.size()) die("second parse differs");
  for (std::size_t i = 0; i < a.xyz.size(); ++i)
    if (!same(a.xyz[i], b.xyz[i])) die("second parse differs in positions");
  for (std::size_t k = 0; k < a.attributes.size(); ++k) {
    if (a.attributes[k].name != b.attributes[k].name || a.attributes[k].values.size() != b.attributes[k].values.size())
      die("second parse differs in attributes");
    for (std::size_t i = 0; i < a.attributes[k].values.size(); ++i)
      if (!same(a.attributes[k].values[i], b.attributes[k].values[i])) die("second parse differs in attribute values");
  }
}

// Parses twice; checks the invariants; returns whether it succeeded.
inline bool parse_twice(const std::uint8_t* data, std::size_t size, const nbmc::io::ReadOptions& o,
                        const std::string& name, nbmc::io::Particles* out = nullptr) {
  nbmc::io::Particles first;
  std::string error;
  bool ok = true;
  try {
    first = nbmc::io::parse_particles(data, size, o, name);
  } catch (const nbmc::io::Error& e) {
    ok = false;
    error = e.what();
    if (error.find(name) == std::string::npos) die("message does not name the file");
  }
  try {
    nbmc::io::Particles second = nbmc::io::parse_particles(data, size, o, name);
    if (!ok) die("second parse succeeded where the first failed");
    check(first);
    check_equal(first, second);
  } catch (const nbmc::io::Error& e) {
    if (ok) die("second parse failed where the first succeeded");
    if (error != e.what()) die("second parse failed differently");
  }
  if (ok && out) *out = std::move(first);
  return ok;
}

inline void check_mesh(const nbmc::io::Mesh& m) {
  if (m.positions.size() % 3 || m.triangles.size() % 3) die("mesh arrays not multiples of 3");
  if (!m.normals.empty() && m.normals.size() != m.positions.size()) die("normals size mismatch");
  for (std::uint32_t t : m.triangles)
    if (t >= m.vertex_count()) die("triangle index out of range");
  for (const nbmc::io::Attribute& a : m.attributes)
    if (a.values.size() != m.vertex_count() * static_cast<std::size_t>(a.components)) die("mesh attribute size");
}

} // namespace nbmc_fuzz

#endif
