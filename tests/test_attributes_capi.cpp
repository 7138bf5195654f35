// SPDX-License-Identifier: MIT
// Particle attributes through the C API (nbmc_context_set_attribute_*,
// nbmc_mesh_attribute*): values against a brute-force kernel mean computed
// here, constants, f32/f64/strided uploads, the same values on every thread
// count and subdomain split, after smoothing, the rules of their lifetime
// (an upload clears them, NULL removes one), errors, and the writers.
#include "nbmc_test.hpp"

#include "io/mesh.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace {

using nbmc_test::Points;

struct Context {
  nbmc_context* ctx = nullptr;
  explicit Context(int32_t backend = NBMC_BACKEND_OPENMP, int threads = 2) {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = backend;
    d.num_threads = threads;
    EXPECT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  }
  ~Context() { nbmc_context_destroy(ctx); }
  void particles(const Points& p) {
    ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK) << nbmc_context_last_error(ctx);
  }
  nbmc_mesh* reconstruct(const nbmc_params& prm) {
    nbmc_mesh* m = nullptr;
    EXPECT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(ctx);
    return m;
  }
};

struct MeshPtr {
  nbmc_mesh* m;
  ~MeshPtr() { nbmc_mesh_destroy(m); }
};

// The field's kernel mean of values (comps per particle) at x, or the nearest
// particle's value: what the library documents, computed the slow way.
std::vector<double> brute(const Points& p, const std::vector<double>& values, int comps, const float* x, double R) {
  std::vector<double> acc(std::size_t(comps), 0.0);
  double wsum = 0, best = std::numeric_limits<double>::infinity();
  std::size_t best_j = 0;
  for (std::size_t j = 0; j < p.size() / 3; ++j) {
    const double d0 = x[0] - p[3 * j], d1 = x[1] - p[3 * j + 1], d2 = x[2] - p[3 * j + 2];
    const double d2sum = d0 * d0 + d1 * d1 + d2 * d2;
    if (d2sum < best) {
      best = d2sum;
      best_j = j;
    }
    const double s2 = d2sum / (R * R);
    if (s2 >= 1) continue;
    const double w = (1 - s2) * (1 - s2) * (1 - s2);
    wsum += w;
    for (int c = 0; c < comps; ++c) acc[std::size_t(c)] += w * values[j * std::size_t(comps) + std::size_t(c)];
  }
  for (int c = 0; c < comps; ++c)
    acc[std::size_t(c)] = wsum > 0 ? acc[std::size_t(c)] / wsum : values[best_j * std::size_t(comps) + std::size_t(c)];
  return acc;
}

std::vector<float> attribute(const nbmc_mesh* m, const char* name, uint32_t expect_components) {
  uint32_t comps = 99;
  const float* a = nbmc_mesh_attribute(m, name, &comps);
  EXPECT_EQ(comps, expect_components) << name << ": " << nbmc_last_error();
  EXPECT_NE(a, nullptr) << name << ": " << nbmc_last_error();
  if (!a) return {};
  return std::vector<float>(a, a + nbmc_mesh_vertex_count(m) * comps);
}

std::vector<float> positions(const nbmc_mesh* m) {
  const float* p = nbmc_mesh_positions(m);
  return std::vector<float>(p, p + 3 * nbmc_mesh_vertex_count(m));
}

// A sphere of particles with a scalar a = x and a vector (x, 2y, 5 - z).
struct Scene {
  Points p = nbmc_test::sphere(0.3, -0.2, 0.1, 3, 1);
  std::vector<double> scalar, vector;
  Scene() {
    const std::size_t n = p.size() / 3;
    for (std::size_t j = 0; j < n; ++j) {
      scalar.push_back(p[3 * j]);
      vector.push_back(p[3 * j]);
      vector.push_back(2 * p[3 * j + 1]);
      vector.push_back(5 - p[3 * j + 2]);
    }
  }
  std::size_t count() const { return p.size() / 3; }
};

TEST(AttributesCapi, MatchBruteForceKernelMean) {
  Scene s;
  Context c;
  c.particles(s.p);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", s.scalar.data(), 1, 0), NBMC_OK) << nbmc_context_last_error(c.ctx);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "vel", s.vector.data(), 3, 0), NBMC_OK);
  const nbmc_params prm = nbmc_test::params(1);
  MeshPtr m{c.reconstruct(prm)};
  ASSERT_NE(m.m, nullptr);
  const std::uint64_t nv = nbmc_mesh_vertex_count(m.m);
  ASSERT_GT(nv, 100u);
  ASSERT_EQ(nbmc_mesh_attribute_count(m.m), 2u);
  EXPECT_STREQ(nbmc_mesh_attribute_name(m.m, 0), "a");
  EXPECT_STREQ(nbmc_mesh_attribute_name(m.m, 1), "vel");
  EXPECT_EQ(nbmc_mesh_attribute_name(m.m, 2), nullptr);
  const std::vector<float> a = attribute(m.m, "a", 1), v = attribute(m.m, "vel", 3);
  const std::vector<float> x = positions(m.m);
  const double R = 4;  // influence_radius 4 spacings of 1
  for (std::uint64_t i = 0; i < nv; ++i) {
    const std::vector<double> e1 = brute(s.p, s.scalar, 1, &x[3 * i], R);
    const std::vector<double> e3 = brute(s.p, s.vector, 3, &x[3 * i], R);
    ASSERT_NEAR(a[i], e1[0], 1e-5 * (1 + std::fabs(e1[0]))) << "vertex " << i;
    for (int k = 0; k < 3; ++k) ASSERT_NEAR(v[3 * i + k], e3[std::size_t(k)], 1e-5 * (1 + std::fabs(e3[std::size_t(k)])));
    // A linear field: the kernel mean lies within R of the vertex's own value
    // and on the same side of the sphere's centre where the vertex is clearly
    // off it.
    EXPECT_LT(std::fabs(a[i] - x[3 * i]), R);
    if (std::fabs(x[3 * i] - 0.3) > 1.5) EXPECT_EQ(a[i] > 0.3, x[3 * i] > 0.3) << "vertex " << i;
  }
}

TEST(AttributesCapi, ConstantStaysConstant) {
  Scene s;
  Context c;
  c.particles(s.p);
  const std::vector<float> k(s.count(), 7.25f);
  ASSERT_EQ(nbmc_context_set_attribute_f32(c.ctx, "temperature", k.data(), 1, 0), NBMC_OK);
  MeshPtr m{c.reconstruct(nbmc_test::params(1))};
  for (float t : attribute(m.m, "temperature", 1)) ASSERT_NEAR(t, 7.25f, 1e-5f);
}

// f32, f64 and strided uploads of the same (float-exact) values give the same
// bits; so do all thread counts, the serial backend and a subdomain split.
TEST(AttributesCapi, SameValuesEverywhere) {
  Scene s;
  const std::size_t n = s.count();
  std::vector<float> f(3 * n);
  std::vector<double> d(3 * n);
  struct Item {
    double junk;
    float v[3];
    float pad;
  };
  std::vector<Item> items(n);
  for (std::size_t i = 0; i < 3 * n; ++i) {
    f[i] = float(s.vector[i]);
    d[i] = double(f[i]);
    items[i / 3].v[i % 3] = f[i];
  }
  const nbmc_params prm = nbmc_test::params(1);
  std::vector<float> ref, ref_pos;
  struct Variant {
    int32_t backend;
    int threads;
    int upload;  // 0 f32, 1 f64, 2 strided f32
    int split;
  };
  const Variant variants[] = {{NBMC_BACKEND_SERIAL, 1, 0, 1}, {NBMC_BACKEND_OPENMP, 1, 1, 1},
                              {NBMC_BACKEND_OPENMP, 2, 2, 1}, {NBMC_BACKEND_OPENMP, 4, 0, 1},
                              {NBMC_BACKEND_OPENMP, 3, 1, 2}, {NBMC_BACKEND_SERIAL, 1, 2, 3}};
  for (const Variant& var : variants) {
    Context c(var.backend, var.threads);
    c.particles(s.p);
    if (var.split > 1) ASSERT_EQ(nbmc_context_set_subdomains(c.ctx, var.split, 2, 1), NBMC_OK);
    int32_t st = NBMC_OK;
    if (var.upload == 0) st = nbmc_context_set_attribute_f32(c.ctx, "vel", f.data(), 3, 0);
    if (var.upload == 1) st = nbmc_context_set_attribute_f64(c.ctx, "vel", d.data(), 3, 3 * sizeof(double));
    if (var.upload == 2) st = nbmc_context_set_attribute_f32(c.ctx, "vel", items[0].v, 3, sizeof(Item));
    ASSERT_EQ(st, NBMC_OK) << nbmc_context_last_error(c.ctx);
    MeshPtr m{c.reconstruct(prm)};
    ASSERT_NE(m.m, nullptr);
    if (var.split > 1) {
      nbmc_subdomain_stats ss;
      nbmc_subdomain_stats_init(&ss);
      ASSERT_EQ(nbmc_context_subdomain_stats(c.ctx, &ss), NBMC_OK);
      EXPECT_EQ(ss.count, std::uint64_t(var.split) * 2);
    }
    const std::vector<float> v = attribute(m.m, "vel", 3), x = positions(m.m);
    if (ref.empty()) {
      ref = v;
      ref_pos = x;
      continue;
    }
    ASSERT_EQ(x.size(), ref_pos.size());
    EXPECT_EQ(0, std::memcmp(x.data(), ref_pos.data(), x.size() * sizeof(float)));
    ASSERT_EQ(v.size(), ref.size());
    EXPECT_EQ(0, std::memcmp(v.data(), ref.data(), v.size() * sizeof(float)))
        << "backend " << var.backend << ", " << var.threads << " threads, upload " << var.upload << ", split "
        << var.split;
  }
}

// Interpolated at the final vertices: after clean-up and smoothing.
TEST(AttributesCapi, AfterSmoothing) {
  Scene s;
  Context c;
  c.particles(s.p);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", s.scalar.data(), 1, 0), NBMC_OK);
  nbmc_params prm = nbmc_test::params(1);
  prm.smooth_iterations = 5;
  MeshPtr m{c.reconstruct(prm)};
  const std::vector<float> a = attribute(m.m, "a", 1), x = positions(m.m);
  ASSERT_EQ(a.size(), nbmc_mesh_vertex_count(m.m));
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::vector<double> e = brute(s.p, s.scalar, 1, &x[3 * i], 4);
    ASSERT_NEAR(a[i], e[0], 1e-5 * (1 + std::fabs(e[0])));
  }
  nbmc_stats st;
  nbmc_stats_init(&st);
  ASSERT_EQ(nbmc_context_stats(c.ctx, &st), NBMC_OK);
  EXPECT_GE(st.stage_seconds[NBMC_STAGE_ATTRIBUTES], 0.0);
  EXPECT_STREQ(nbmc_stage_name(NBMC_STAGE_ATTRIBUTES), "attributes");
}

// Attributes belong to the particles uploaded last.
TEST(AttributesCapi, Lifetime) {
  Scene s;
  Context c;
  const nbmc_params prm = nbmc_test::params(1);
  // Before any particles.
  EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", s.scalar.data(), 1, 0), NBMC_ERROR_NO_PARTICLES);
  EXPECT_NE(std::string(nbmc_context_last_error(c.ctx)).find("upload the particles first"), std::string::npos);
  c.particles(s.p);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", s.scalar.data(), 1, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "b", s.scalar.data(), 1, 0), NBMC_OK);
  // Replacing keeps the place; NULL removes (also an absent name).
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", s.vector.data(), 3, 0), NBMC_OK);
  {
    MeshPtr m{c.reconstruct(prm)};
    ASSERT_EQ(nbmc_mesh_attribute_count(m.m), 2u);
    EXPECT_STREQ(nbmc_mesh_attribute_name(m.m, 0), "a");
    attribute(m.m, "a", 3);
  }
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", nullptr, 0, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "never", nullptr, 0, 0), NBMC_OK);
  {
    MeshPtr m{c.reconstruct(prm)};
    ASSERT_EQ(nbmc_mesh_attribute_count(m.m), 1u);
    EXPECT_STREQ(nbmc_mesh_attribute_name(m.m, 0), "b");
  }
  // A new upload (here of another count) removes them all.
  const Points fewer = nbmc_test::sphere(0, 0, 0, 2.5, 1);
  ASSERT_NE(fewer.size(), s.p.size());
  c.particles(fewer);
  {
    MeshPtr m{c.reconstruct(prm)};
    EXPECT_EQ(nbmc_mesh_attribute_count(m.m), 0u);
    uint32_t comps = 7;
    EXPECT_EQ(nbmc_mesh_attribute(m.m, "b", &comps), nullptr);
    EXPECT_EQ(comps, 0u);
    EXPECT_NE(std::string(nbmc_last_error()).find("no attribute 'b'"), std::string::npos) << nbmc_last_error();
  }
}

TEST(AttributesCapi, Errors) {
  Scene s;
  Context c;
  c.particles(s.p);
  const double* d = s.scalar.data();
  EXPECT_EQ(nbmc_context_set_attribute_f64(nullptr, "a", d, 1, 0), NBMC_ERROR_INVALID_ARGUMENT);
  const std::string long_name(256, 'a');
  for (const char* name : {static_cast<const char*>(nullptr), "", "a\tb", "line\n", long_name.c_str()})
    EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, name, d, 1, 0), NBMC_ERROR_INVALID_ARGUMENT)
        << (name ? name : "NULL");
  EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, long_name.substr(1).c_str(), d, 1, 0), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, long_name.substr(1).c_str(), nullptr, 1, 0), NBMC_OK);
  for (uint32_t comps : {0u, 2u, 4u}) {
    EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", d, comps, 0), NBMC_ERROR_INVALID_ARGUMENT);
    EXPECT_NE(std::string(nbmc_context_last_error(c.ctx)).find("1 (scalar) or 3 (vector)"), std::string::npos);
  }
  EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", d, 3, 16), NBMC_ERROR_INVALID_ARGUMENT);
  // Non-finite values: named particle, and no attribute of that name kept.
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", d, 1, 0), NBMC_OK);
  std::vector<double> v = s.vector;
  v[3 * 5 + 2] = std::numeric_limits<double>::infinity();
  v[3 * 9] = std::nan("");
  EXPECT_EQ(nbmc_context_set_attribute_f64(c.ctx, "a", v.data(), 3, 0), NBMC_ERROR_INVALID_PARTICLES);
  const std::string msg = nbmc_context_last_error(c.ctx);
  EXPECT_NE(msg.find("2 value(s) of attribute 'a'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("first at particle 5, component 2"), std::string::npos) << msg;
  std::vector<float> big(s.count(), 3e38f);
  EXPECT_EQ(nbmc_context_set_attribute_f32(c.ctx, "big", big.data(), 1, 0), NBMC_ERROR_INVALID_PARTICLES);
  // Device pointers need the CUDA backend.
  EXPECT_EQ(nbmc_context_set_attribute_device_f32(c.ctx, "a", big.data(), 1, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  EXPECT_EQ(nbmc_context_set_attribute_device_f64(c.ctx, "a", d, 1, 0), NBMC_ERROR_BACKEND_UNAVAILABLE);
  MeshPtr m{c.reconstruct(nbmc_test::params(1))};
  EXPECT_EQ(nbmc_mesh_attribute_count(m.m), 0u);  // "a" went with its failed replacement
  uint32_t comps = 5;
  EXPECT_EQ(nbmc_mesh_attribute(m.m, nullptr, &comps), nullptr);
  EXPECT_EQ(comps, 0u);
  EXPECT_EQ(nbmc_mesh_attribute(nullptr, "a", nullptr), nullptr);
  EXPECT_NE(std::string(nbmc_last_error()).find("mesh is NULL"), std::string::npos);
  EXPECT_EQ(nbmc_mesh_attribute_count(nullptr), 0u);
  EXPECT_EQ(nbmc_mesh_attribute_name(nullptr, 0), nullptr);
}

// nbmc_mesh_write carries the attributes into the formats that hold them.
TEST(AttributesCapi, Writers) {
  Scene s;
  Context c;
  c.particles(s.p);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "rho", s.scalar.data(), 1, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_attribute_f64(c.ctx, "vel", s.vector.data(), 3, 0), NBMC_OK);
  MeshPtr m{c.reconstruct(nbmc_test::params(1))};
  const std::vector<float> rho = attribute(m.m, "rho", 1), vel = attribute(m.m, "vel", 3);
  for (const char* ext : {"vtk", "vtu", "vtp"}) {
    const std::string path = std::string(NBMC_BINARY_DIR) + "/attributes_capi." + ext;
    ASSERT_EQ(nbmc_mesh_write(m.m, path.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    const nbmc::io::Mesh back = nbmc::io::read_mesh(path);
    std::remove(path.c_str());
    ASSERT_EQ(back.attributes.size(), 2u) << ext;
    for (const nbmc::io::Attribute& a : back.attributes) {
      const std::vector<float>& want = a.name == "rho" ? rho : vel;
      ASSERT_EQ(a.components, a.name == "rho" ? 1 : 3) << ext << " " << a.name;
      ASSERT_EQ(a.values.size(), want.size());
      for (std::size_t i = 0; i < want.size(); ++i) ASSERT_EQ(float(a.values[i]), want[i]) << ext << " " << a.name;
    }
  }
}

}  // namespace
