// SPDX-License-Identifier: MIT
// libFuzzer target: legacy VTK reader (particles and meshes) from memory.
#include "check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc::io::ReadOptions o;
  o.format = "vtk";
  nbmc::io::Particles p;
  nbmc_fuzz::parse_twice(data, size, o, "fuzz.vtk", &p);
  try {
    nbmc_fuzz::check_mesh(nbmc::io::parse_mesh(data, size, "vtk", "fuzz.vtk"));
  } catch (const nbmc::io::Error&) {
  }
  return 0;
}
