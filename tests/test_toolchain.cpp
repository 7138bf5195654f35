// SPDX-License-Identifier: MIT
// What nbmc needs of the compiler beyond the standard's letter, checked with
// the project's own compile flags.
#include <gtest/gtest.h>

#include <cstdint>
#include <utility>
#include <vector>

namespace {

struct V {
  double x = 0, y = 0, z = 0;
};

// The mesh clean-up's way of rounding a candidate position as the output
// will store it (src/core/mesh_cleanup.hpp: Vec3{double(Real(p.x)), ...}).
template <class R>
V rounded(const V& a) {
  return {double(R(a.x)), double(R(a.y)), double(R(a.z))};
}

// The shape in which GCC 12's SLP vectorizer pairs the x and y conversions
// and drops their rounding (z, left scalar, is rounded); CMakeLists.txt
// turns that vectorizer off for GCC < 13.
__attribute__((noinline)) void round_all(std::vector<std::pair<std::uint32_t, V>>& moved,
                                         std::vector<std::uint32_t>& seen) {
  for (auto& m : moved) {
    m.second = rounded<float>(m.second);
    seen.push_back(m.first);
  }
}

double as_float(double v) {
  volatile float f = float(v);  // rounded through memory, out of the optimiser's reach
  return double(f);
}

}  // namespace

TEST(Toolchain, FloatRoundingOfDoublesSurvivesVectorisation) {
  volatile double s = 1;  // no compile-time constants
  const double in[2][3] = {{0.1 * s, 0.2 * s, 0.3 * s}, {-0.056808110056777661 * s, 1.0192402501505431 * s, 0.7 * s}};
  std::vector<std::pair<std::uint32_t, V>> moved;
  for (std::uint32_t i = 0; i < 2; ++i) moved.push_back({i, V{in[i][0], in[i][1], in[i][2]}});
  std::vector<std::uint32_t> seen;
  round_all(moved, seen);
  ASSERT_EQ(seen.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(moved[i].second.x, as_float(in[i][0])) << i;
    EXPECT_EQ(moved[i].second.y, as_float(in[i][1])) << i;
    EXPECT_EQ(moved[i].second.z, as_float(in[i][2])) << i;
    EXPECT_NE(moved[i].second.x, in[i][0]) << i;  // (these inputs are no floats)
  }
}
