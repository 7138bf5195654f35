// SPDX-License-Identifier: MIT
// libFuzzer target: VTK XML reader (.vtu / .vtp; ascii, base64, appended,
// zlib) for particles and meshes, from memory.
#include "check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc::io::ReadOptions o;
  o.format = "vtu";
  nbmc_fuzz::parse_twice(data, size, o, "fuzz.vtu");
  o.only = {"vel"};
  nbmc::io::Particles p;
  if (nbmc_fuzz::parse_twice(data, size, o, "fuzz.vtu", &p))
    for (const auto& a : p.attributes)
      if (nbmc::io::find_attribute(p.attributes, "vel") != &a) nbmc_fuzz::die("an attribute not asked for");
  try {
    nbmc_fuzz::check_mesh(nbmc::io::parse_mesh(data, size, "vtu", "fuzz.vtu"));
  } catch (const nbmc::io::Error&) {
  }
  return 0;
}
