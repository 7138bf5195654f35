// SPDX-License-Identifier: MIT
// Test helper for the readers and writers (src/io/).
#pragma once

#include "io/error.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <string>
#include <vector>

namespace nbmc_test {

// Runs f, expects nbmc::io::Error whose message contains every needle.
inline void expect_error(const std::function<void()>& f, const std::vector<std::string>& needles) {
  try {
    f();
    ADD_FAILURE() << "no nbmc::io::Error thrown (expected one mentioning '" << needles.front() << "')";
  } catch (const nbmc::io::Error& e) {
    const std::string msg = e.what();
    for (const std::string& n : needles)
      EXPECT_NE(msg.find(n), std::string::npos) << "message '" << msg << "' does not contain '" << n << "'";
  }
}

}  // namespace nbmc_test
