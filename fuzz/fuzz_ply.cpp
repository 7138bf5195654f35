// SPDX-License-Identifier: MIT
// libFuzzer target: PLY particle reader (with attributes) and PLY mesh reader
// from memory.
#include "check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc::io::ReadOptions o;
  o.format = "ply";
  nbmc_fuzz::parse_twice(data, size, o, "fuzz.ply");
  o.attributes = false;
  nbmc::io::Particles p;
  if (nbmc_fuzz::parse_twice(data, size, o, "fuzz.ply", &p) && !p.attributes.empty())
    nbmc_fuzz::die("attributes read although not asked for");
  try {
    nbmc_fuzz::check_mesh(nbmc::io::parse_mesh_ply(data, size, "fuzz.ply"));
  } catch (const nbmc::io::Error&) {
  }
  return 0;
}
