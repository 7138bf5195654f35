// SPDX-License-Identifier: MIT
// Interpolation of particle attributes onto mesh vertices
// (src/io/attributes.cpp): kernel weights, normalisation, nearest-particle
// fallback, determinism across thread counts, errors.
#include "io/attributes.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include <omp.h>

using nbmc::io::Attribute;
using nbmc::io::interpolate_attributes;

namespace {

double kernel(double s) {
  const double t = 1 - s * s;
  return s < 1 ? t * t * t : 0;
}

struct Cloud {
  std::vector<double> xyz;
  std::vector<Attribute> attrs;
};

// A jittered lattice with rho = 2x + 1 and vel = (y, z, x).
Cloud lattice(int n, double h, unsigned seed) {
  Cloud c;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.2 * h, 0.2 * h);
  Attribute rho{"rho", 1, {}}, vel{"vel", 3, {}};
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) {
        const double x = i * h + jitter(rng), y = j * h + jitter(rng), z = k * h + jitter(rng);
        c.xyz.insert(c.xyz.end(), {x, y, z});
        rho.values.push_back(2 * x + 1);
        vel.values.insert(vel.values.end(), {y, z, x});
      }
  c.attrs = {rho, vel};
  return c;
}

} // namespace

TEST(IoAttributes, MatchesABruteForceSum) {
  const Cloud c = lattice(8, 0.1, 1);
  const double R = 0.25;
  std::vector<float> verts = {0.35f, 0.35f, 0.35f, 0.1f, 0.62f, 0.3f, 0.0f, 0.0f, 0.0f, 0.7f, 0.7f, 0.05f};
  const auto out = interpolate_attributes(c.xyz, c.attrs, {"rho", "vel"}, verts.data(), 4, R);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].name, "rho");
  EXPECT_EQ(out[1].components, 3);
  for (int v = 0; v < 4; ++v) {
    double w = 0, rho = 0, vel[3] = {0, 0, 0};
    for (std::size_t p = 0; p < c.xyz.size() / 3; ++p) {
      const double d = std::sqrt(std::pow(verts[3 * v] - c.xyz[3 * p], 2) + std::pow(verts[3 * v + 1] - c.xyz[3 * p + 1], 2) +
                                 std::pow(verts[3 * v + 2] - c.xyz[3 * p + 2], 2));
      const double k = kernel(d / R);
      w += k;
      rho += k * c.attrs[0].values[p];
      for (int a = 0; a < 3; ++a) vel[a] += k * c.attrs[1].values[3 * p + a];
    }
    ASSERT_GT(w, 0);
    EXPECT_NEAR(out[0].values[v], rho / w, 1e-12) << v;
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(out[1].values[3 * v + a], vel[a] / w, 1e-12) << v;
  }
}

TEST(IoAttributes, ConstantsAreReproduced) {
  Cloud c = lattice(6, 0.1, 2);
  for (double& r : c.attrs[0].values) r = 998.25;
  std::vector<float> verts;
  for (int i = 0; i < 50; ++i) verts.insert(verts.end(), {0.01f * i, 0.25f, 0.3f});
  const auto out = interpolate_attributes(c.xyz, c.attrs, {"rho"}, verts.data(), 50, 0.2);
  for (double v : out[0].values) EXPECT_NEAR(v, 998.25, 1e-9);
}

TEST(IoAttributes, FarVerticesTakeTheNearestParticle) {
  Cloud c;
  c.xyz = {0, 0, 0, 10, 0, 0, 0, 7, 0};
  c.attrs = {Attribute{"id", 1, {1, 2, 3}}};
  // R = 1: vertices far from every particle; the last one is beyond the
  // shell search (a full scan then).
  std::vector<float> verts = {9, 1, 0, 0.5f, 5, 0, -2, -2, 0, 1000, 1000, 1000, 0.2f, 0, 0};
  const auto out = interpolate_attributes(c.xyz, c.attrs, {}, verts.data(), 5, 1.0);
  EXPECT_EQ(out[0].values, (std::vector<double>{2, 3, 1, 2, 1}));
}

TEST(IoAttributes, SameResultForAnyThreadCount) {
  const Cloud c = lattice(12, 0.05, 3);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.1f, 0.7f);
  std::vector<float> verts(3 * 20000);
  for (float& v : verts) v = u(rng);
  const int before = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = interpolate_attributes(c.xyz, c.attrs, {}, verts.data(), 20000, 0.12);
  omp_set_num_threads(4);
  const auto four = interpolate_attributes(c.xyz, c.attrs, {}, verts.data(), 20000, 0.12);
  omp_set_num_threads(before);
  ASSERT_EQ(one.size(), four.size());
  for (std::size_t a = 0; a < one.size(); ++a) EXPECT_EQ(one[a].values, four[a].values); // bitwise
}

TEST(IoAttributes, NamesAreCaseInsensitiveAndErrorsAreClear) {
  const Cloud c = lattice(3, 0.1, 4);
  float v[3] = {0.1f, 0.1f, 0.1f};
  EXPECT_EQ(interpolate_attributes(c.xyz, c.attrs, {"RHO"}, v, 1, 0.2)[0].name, "rho");
  try {
    interpolate_attributes(c.xyz, c.attrs, {"pressure"}, v, 1, 0.2);
    ADD_FAILURE();
  } catch (const nbmc::io::Error& e) {
    EXPECT_NE(std::string(e.what()).find("'pressure'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("rho (scalar), vel (vector)"), std::string::npos) << e.what();
    EXPECT_EQ(e.kind(), nbmc::io::Error::Kind::argument);
  }
  EXPECT_THROW(interpolate_attributes(c.xyz, c.attrs, {"rho"}, v, 1, 0.0), nbmc::io::Error);
  EXPECT_THROW(interpolate_attributes({}, {}, {}, v, 1, 1.0), nbmc::io::Error);
  std::vector<Attribute> bad = c.attrs;
  bad[0].values.pop_back();
  EXPECT_THROW(interpolate_attributes(c.xyz, bad, {"rho"}, v, 1, 0.2), nbmc::io::Error);
  // No vertices: empty arrays of the right names.
  const auto none = interpolate_attributes(c.xyz, c.attrs, {}, nullptr, 0, 0.2);
  ASSERT_EQ(none.size(), 2u);
  EXPECT_TRUE(none[1].values.empty());
}
