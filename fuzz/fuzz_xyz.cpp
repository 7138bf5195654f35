// SPDX-License-Identifier: MIT
// libFuzzer target: raw .xyz reader from memory.
#include "check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc::io::ReadOptions o;
  o.format = "xyz";
  nbmc::io::Particles p;
  const bool ok = nbmc_fuzz::parse_twice(data, size, o, "fuzz.xyz", &p);
  if (ok != (size % 12 == 0)) nbmc_fuzz::die("xyz accepts exactly the multiples of 12 bytes");
  if (ok && p.count() != size / 12) nbmc_fuzz::die("xyz count");
  return 0;
}
