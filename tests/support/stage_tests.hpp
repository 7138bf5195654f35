// SPDX-License-Identifier: MIT
// For the test programs that build the pipeline's stages themselves from the
// Kokkos backend headers (test_yt10_kernels, test_neighbourhood): the
// progress callback's definition, which the library does not export (the
// stages only report progress), and a gtest environment that runs Kokkos on
// a given number of host threads. Include in one source file per program.
#pragma once

#include <gtest/gtest.h>

#include "common.hpp"

void nbmc::Progress::operator()(int, double) const {}

namespace nbmc_test {

class KokkosThreads : public ::testing::Environment {
 public:
  explicit KokkosThreads(int threads) : threads_(threads) {}
  void SetUp() override {
    Kokkos::InitArguments args;
    args.num_threads = threads_;
    Kokkos::initialize(args);
  }
  void TearDown() override { Kokkos::finalize(); }

 private:
  int threads_;
};

}  // namespace nbmc_test
