// SPDX-License-Identifier: MIT
// libFuzzer target: Houdini classic BGEO reader (raw and gzip) from memory.
#include "check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc::io::ReadOptions o;
  o.format = "bgeo";
  nbmc_fuzz::parse_twice(data, size, o, "fuzz.bgeo");
  return 0;
}
