// SPDX-License-Identifier: MIT
// nbmc_params.double_positions: a sphere far from the origin (1e7 in each
// coordinate, spacing 0.01, where a float resolves 1.0) keeps its shape in
// double; without the flag nothing changes; subdomains stitch doubles bit for
// bit; clean-up and smoothing keep the mesh closed; the writers store doubles
// that read back exactly; misuse gets exact statuses.
#include "io/mesh.hpp"
#include "nbmc.h"
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

namespace {

using nbmc_test::Points;
namespace fs = std::filesystem;

constexpr double kOffset = 1e7;  // float spacing there: 1.0
constexpr double kSpacing = 0.01;
constexpr double kRadius = 0.1;  // ten particles

// The sphere's particles about (offset, offset, offset): the same particles
// at every offset (shifted after the lattice is made).
Points offset_sphere(double offset) {
  Points p = nbmc_test::sphere(0, 0, 0, kRadius, kSpacing);
  for (double& x : p) x += offset;
  return p;
}

// A mesh copied out of the C API: positions in double (from the doubles when
// the mesh has them, else widened floats).
struct Copy {
  std::vector<double> positions;
  std::vector<float> positions_f32, normals;
  std::vector<std::uint32_t> triangles;
  bool f64 = false;
  std::size_t vertex_count() const { return positions.size() / 3; }
};

Copy copy_out(const nbmc_mesh* m) {
  Copy c;
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  const double* d = nbmc_mesh_positions_f64(m);
  const float* f = nbmc_mesh_positions(m);
  c.f64 = d != nullptr;
  if (nv) {
    EXPECT_NE(f, nullptr);
    c.positions_f32.assign(f, f + 3 * nv);
    if (d) c.positions.assign(d, d + 3 * nv);
    else c.positions.assign(f, f + 3 * nv);
  }
  if (nbmc_mesh_normals(m)) c.normals.assign(nbmc_mesh_normals(m), nbmc_mesh_normals(m) + 3 * nv);
  if (nt) c.triangles.assign(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nt);
  return c;
}

struct Outcome {
  int32_t status = -1;
  std::string error;
  Copy mesh;
  nbmc_mesh_check_result check{};
};

Outcome run(const Points& p, const nbmc_params& prm, int nx = 1, int ny = 1, int nz = 1, std::uint64_t budget = 0,
        int32_t backend = NBMC_BACKEND_OPENMP, nbmc_mesh** keep = nullptr) {
  Outcome r;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = backend;
  d.num_threads = 2;
  nbmc_context* ctx = nullptr;
  EXPECT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  if (nx != 1 || ny != 1 || nz != 1) EXPECT_EQ(nbmc_context_set_subdomains(ctx, nx, ny, nz), NBMC_OK);
  if (budget) EXPECT_EQ(nbmc_context_set_memory_budget(ctx, budget), NBMC_OK);
  EXPECT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_mesh* m = nullptr;
  r.status = nbmc_context_reconstruct(ctx, &prm, &m);
  if (r.status != NBMC_OK) r.error = nbmc_context_last_error(ctx);
  if (m) {
    r.mesh = copy_out(m);
    nbmc_mesh_check_result_init(&r.check);
    EXPECT_EQ(nbmc_mesh_check(m, &r.check), NBMC_OK);
    if (keep) *keep = m;
    else nbmc_mesh_destroy(m);
  }
  nbmc_context_destroy(ctx);
  return r;
}

nbmc_params params(bool f64) {
  nbmc_params p = nbmc_test::params(kSpacing);
  p.double_positions = f64 ? 1 : 0;
  return p;
}

// Largest distance of a vertex from the sphere of radius `radius` about
// (c, c, c), computed in double.
double max_deviation(const Copy& m, double c, double radius) {
  double worst = 0;
  for (std::size_t v = 0; v < m.vertex_count(); ++v) {
    const double x = m.positions[3 * v] - c, y = m.positions[3 * v + 1] - c, z = m.positions[3 * v + 2] - c;
    worst = std::max(worst, std::fabs(std::sqrt(x * x + y * y + z * z) - radius));
  }
  return worst;
}

double mean_radius(const Copy& m, double c) {
  double s = 0;
  for (std::size_t v = 0; v < m.vertex_count(); ++v) {
    const double x = m.positions[3 * v] - c, y = m.positions[3 * v + 1] - c, z = m.positions[3 * v + 2] - c;
    s += std::sqrt(x * x + y * y + z * z);
  }
  return m.vertex_count() ? s / double(m.vertex_count()) : 0;
}

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

bool good(const nbmc_mesh_check_result& c) { return c.closed && c.manifold && c.oriented; }

}  // namespace

// The same particles at the origin (float is plenty there) and shifted by
// 1e7 in each coordinate (a float resolves 1.0 there; the shift itself
// rounds by 1e-9): the field is relative to the grid origin, so the meshes
// have the same triangles, and the double vertices, shifted back, agree with
// the origin mesh's to a micrometre, while float vertices are off by up to
// the sphere's radius (they all round to 1e7). Raw meshes: the clean-up would
// repair the float mesh's collapsed triangles away.
TEST(DoublePositions, FarFromTheOriginKeepsTheShape) {
  const Points near = offset_sphere(0), far = offset_sphere(kOffset);
  nbmc_params raw32 = params(false), raw64 = params(true);
  raw32.cleanup = raw64.cleanup = 0;
  const Outcome origin = run(near, raw32);
  ASSERT_EQ(origin.status, NBMC_OK) << origin.error;
  ASSERT_GT(origin.mesh.vertex_count(), 100u);
  const double radius = mean_radius(origin.mesh, 0);
  EXPECT_GT(radius, 0.9 * kRadius);
  EXPECT_LT(max_deviation(origin.mesh, 0, radius), 0.5 * kSpacing);

  // Largest distance of a vertex (shifted back) from the origin mesh's.
  auto offset_error = [&](const Copy& m) {
    double worst = 0;
    for (std::size_t i = 0; i < m.positions.size(); ++i)
      worst = std::max(worst, std::fabs((m.positions[i] - kOffset) - origin.mesh.positions[i]));
    return worst;
  };
  const Outcome f64 = run(far, raw64);
  ASSERT_EQ(f64.status, NBMC_OK) << f64.error;
  EXPECT_TRUE(f64.mesh.f64);
  ASSERT_EQ(f64.mesh.triangles, origin.mesh.triangles);
  EXPECT_LT(offset_error(f64.mesh), 1e-6) << "double positions lost precision";
  EXPECT_LT(max_deviation(f64.mesh, kOffset, radius), 0.5 * kSpacing);

  // Without the flag: float positions, useless there.
  const Outcome f32 = run(far, raw32);
  ASSERT_EQ(f32.status, NBMC_OK) << f32.error;
  EXPECT_FALSE(f32.mesh.f64);
  ASSERT_EQ(f32.mesh.triangles, origin.mesh.triangles);
  EXPECT_GT(offset_error(f32.mesh), 5 * kSpacing) << "the test cannot tell float from double";

  // The float view of the double mesh is its positions rounded.
  ASSERT_EQ(f64.mesh.positions_f32.size(), f64.mesh.positions.size());
  for (std::size_t i = 0; i < f64.mesh.positions.size(); ++i)
    ASSERT_EQ(f64.mesh.positions_f32[i], float(f64.mesh.positions[i])) << i;

  // Cleaned up (the default), the double mesh is closed and still a sphere.
  const Outcome clean = run(far, params(true));
  ASSERT_EQ(clean.status, NBMC_OK) << clean.error;
  EXPECT_TRUE(good(clean.check));
  EXPECT_GT(clean.mesh.vertex_count(), 100u);
  EXPECT_LT(max_deviation(clean.mesh, kOffset, radius), 0.5 * kSpacing);
}

// The raw marching-cubes mesh computes each point in double either way: the
// flag changes only the rounding of the store. Rounded to float, the double
// mesh is the float mesh bit for bit (topology, normals, positions).
TEST(DoublePositions, RawMeshRoundsToTheFloatMesh) {
  for (const double offset : {0.0, 123.456}) {
    SCOPED_TRACE(offset);
    nbmc_params a = params(false), b = params(true);
    a.cleanup = b.cleanup = 0;
    const Outcome f32 = run(offset_sphere(offset), a), f64 = run(offset_sphere(offset), b);
    ASSERT_EQ(f32.status, NBMC_OK) << f32.error;
    ASSERT_EQ(f64.status, NBMC_OK) << f64.error;
    EXPECT_FALSE(f32.mesh.f64);
    EXPECT_TRUE(f64.mesh.f64);
    EXPECT_TRUE(same_bits(f32.mesh.triangles, f64.mesh.triangles));
    EXPECT_TRUE(same_bits(f32.mesh.normals, f64.mesh.normals));
    EXPECT_TRUE(same_bits(f32.mesh.positions_f32, f64.mesh.positions_f32));
    // And the doubles carry more than the floats (not widened floats).
    std::size_t differ = 0;
    for (std::size_t i = 0; i < f64.mesh.positions.size(); ++i)
      differ += double(float(f64.mesh.positions[i])) != f64.mesh.positions[i] ? 1 : 0;
    EXPECT_GT(differ, f64.mesh.positions.size() / 2);
  }
}

// Serial and OpenMP at different thread counts: the same doubles.
TEST(DoublePositions, SameOnEveryBackendAndThreadCount) {
  const Points p = offset_sphere(kOffset);
  const Outcome serial = run(p, params(true), 1, 1, 1, 0, NBMC_BACKEND_SERIAL);
  const Outcome omp = run(p, params(true), 1, 1, 1, 0, NBMC_BACKEND_OPENMP);
  ASSERT_EQ(serial.status, NBMC_OK) << serial.error;
  ASSERT_EQ(omp.status, NBMC_OK) << omp.error;
  EXPECT_TRUE(same_bits(serial.mesh.positions, omp.mesh.positions));
  EXPECT_TRUE(same_bits(serial.mesh.triangles, omp.mesh.triangles));
}

// Subdomains stitch the doubles: a 2x1x1 split, a 1x2x2 split and `auto`
// under a budget give the whole frame's mesh bit for bit (cleaned up, as by
// default).
TEST(DoublePositions, SubdomainsGiveTheWholeFramesMesh) {
  const Points p = offset_sphere(kOffset);
  const Outcome whole = run(p, params(true));
  ASSERT_EQ(whole.status, NBMC_OK) << whole.error;
  ASSERT_TRUE(whole.mesh.f64);
  for (const auto& split : {std::array<int, 3>{2, 1, 1}, std::array<int, 3>{1, 2, 2}}) {
    const Outcome s = run(p, params(true), split[0], split[1], split[2]);
    ASSERT_EQ(s.status, NBMC_OK) << s.error;
    EXPECT_TRUE(s.mesh.f64);
    EXPECT_TRUE(same_bits(whole.mesh.positions, s.mesh.positions)) << split[0] << split[1] << split[2];
    EXPECT_TRUE(same_bits(whole.mesh.normals, s.mesh.normals));
    EXPECT_TRUE(same_bits(whole.mesh.triangles, s.mesh.triangles));
  }
  // `auto` with a budget below the frame's estimate splits it.
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_subdomains(ctx, NBMC_SUBDOMAINS_AUTO, 0, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_memory_budget(ctx, 3u << 20), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  const nbmc_params prm = params(true);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(ctx);
  nbmc_subdomain_stats st;
  nbmc_subdomain_stats_init(&st);
  ASSERT_EQ(nbmc_context_subdomain_stats(ctx, &st), NBMC_OK);
  EXPECT_GT(st.count, 1u);
  const Copy a = copy_out(m);
  EXPECT_TRUE(a.f64);
  EXPECT_TRUE(same_bits(whole.mesh.positions, a.positions));
  EXPECT_TRUE(same_bits(whole.mesh.triangles, a.triangles));
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
}

// Clean-up and smoothing run on the doubles: the mesh stays closed and
// manifold, and smoothing moves it (in double: far from the origin a float
// step would be lost in the rounding).
TEST(DoublePositions, CleanedAndSmoothedMeshIsClosed) {
  nbmc_params prm = params(true);
  prm.smooth_iterations = 10;
  const Outcome s = run(offset_sphere(kOffset), prm);
  ASSERT_EQ(s.status, NBMC_OK) << s.error;
  EXPECT_TRUE(good(s.check)) << s.check.boundary_edge_count << " " << s.check.nonmanifold_edge_count;
  EXPECT_EQ(s.check.degenerate_triangle_count, 0u);
  EXPECT_GT(s.check.volume, 0.0);
  const Outcome raw = run(offset_sphere(kOffset), params(true));
  ASSERT_EQ(raw.status, NBMC_OK);
  // Smoothing shrinks the sphere a little (Taubin keeps most of the volume).
  const double r_raw = mean_radius(raw.mesh, kOffset), r_smooth = mean_radius(s.mesh, kOffset);
  EXPECT_NE(r_raw, r_smooth);
  EXPECT_NEAR(r_smooth, r_raw, 0.1 * kSpacing);
  // The enclosed volume matches the sphere's (a float mesh there has none).
  EXPECT_NEAR(s.check.volume, 4.0 / 3.0 * M_PI * r_smooth * r_smooth * r_smooth, 0.05 * s.check.volume);
}

// Particle attributes are interpolated at the double positions.
TEST(DoublePositions, AttributesAtTheDoublePositions) {
  const Points p = offset_sphere(kOffset);
  std::vector<double> one(p.size() / 3, 1.0);
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  ASSERT_EQ(nbmc_context_set_attribute_f64(ctx, "one", one.data(), 1, 0), NBMC_OK);
  const nbmc_params prm = params(true);
  nbmc_mesh* m = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK) << nbmc_context_last_error(ctx);
  uint32_t comps = 0;
  const float* v = nbmc_mesh_attribute(m, "one", &comps);
  ASSERT_NE(v, nullptr);
  ASSERT_EQ(comps, 1u);
  // (Float vertices 1e7 away lie up to half a metre off: no particle within
  // the influence radius, no value.)
  for (std::uint64_t i = 0; i < nbmc_mesh_vertex_count(m); ++i) ASSERT_NEAR(v[i], 1.0f, 1e-6f) << i;
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
}

// Misuse and the defaults.
TEST(DoublePositions, DefaultsAndMisuse) {
  nbmc_params p;
  nbmc_params_init(&p);
  EXPECT_EQ(p.double_positions, 0);
  EXPECT_EQ(nbmc_mesh_positions_f64(nullptr), nullptr);
  // A float mesh has no doubles; its float positions are there.
  nbmc_mesh* m = nullptr;
  const Outcome f32 = run(offset_sphere(0), params(false), 1, 1, 1, 0, NBMC_BACKEND_OPENMP, &m);
  ASSERT_EQ(f32.status, NBMC_OK);
  EXPECT_EQ(nbmc_mesh_positions_f64(m), nullptr);
  EXPECT_NE(nbmc_mesh_positions(m), nullptr);
  nbmc_mesh_destroy(m);
  // A caller built before the field was appended: float positions.
  nbmc_params old = params(true);
  old.struct_size = uint32_t(offsetof(nbmc_params, double_positions));
  const Outcome legacy = run(offset_sphere(0), old);
  ASSERT_EQ(legacy.status, NBMC_OK) << legacy.error;
  EXPECT_FALSE(legacy.mesh.f64);
  // nbmc_mesh_copy_to_host gives the rounded positions of a double mesh.
  const Outcome f64 = run(offset_sphere(kOffset), params(true), 1, 1, 1, 0, NBMC_BACKEND_OPENMP, &m);
  ASSERT_EQ(f64.status, NBMC_OK);
  std::vector<float> pos(3 * nbmc_mesh_vertex_count(m));
  ASSERT_EQ(nbmc_mesh_copy_to_host(m, pos.data(), nullptr, nullptr), NBMC_OK);
  EXPECT_TRUE(same_bits(pos, f64.mesh.positions_f32));
  EXPECT_EQ(nbmc_mesh_memory(m), NBMC_MEMORY_HOST);
  nbmc_mesh_destroy(m);
}

// The float positions of a double mesh are rounded on the first request:
// threads asking at once all get the same, complete array.
TEST(DoublePositions, ConcurrentFloatRequestsGetOneArray) {
  nbmc_mesh* m = nullptr;
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(&d, &ctx), NBMC_OK);
  const Points p = offset_sphere(kOffset);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  const nbmc_params prm = params(true);
  ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &m), NBMC_OK);
  std::vector<const float*> got(8, nullptr);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < got.size(); ++t) threads.emplace_back([&, t] { got[t] = nbmc_mesh_positions(m); });
  for (std::thread& t : threads) t.join();
  const double* d64 = nbmc_mesh_positions_f64(m);
  ASSERT_NE(got[0], nullptr);
  for (const float* g : got) EXPECT_EQ(g, got[0]);
  for (std::size_t i = 0; i < 3 * nbmc_mesh_vertex_count(m); ++i) ASSERT_EQ(got[0][i], float(d64[i])) << i;
  nbmc_mesh_destroy(m);
  nbmc_context_destroy(ctx);
}

// ----------------------------------------------------------------- writers

namespace {

struct TempDir {
  fs::path dir;
  TempDir() {
    dir = fs::temp_directory_path() / ("nbmc_f64_" + std::to_string(::getpid()));
    fs::create_directories(dir);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
  std::string operator()(const std::string& name) const { return (dir / name).string(); }
};

std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace

// Every writer that can store doubles does, and the project's readers (PLY,
// VTK, VTU, VTP; OBJ parsed here) give them back bit for bit; glTF rounds.
TEST(DoublePositions, WritersKeepTheDoubles) {
  nbmc_mesh* m = nullptr;
  const Outcome r = run(offset_sphere(kOffset), params(true), 1, 1, 1, 0, NBMC_BACKEND_OPENMP, &m);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  ASSERT_TRUE(r.mesh.f64);
  TempDir tmp;
  for (const char* ext : {"ply", "vtk", "vtu", "vtp"}) {
    SCOPED_TRACE(ext);
    const std::string path = tmp(std::string("m.") + ext);
    ASSERT_EQ(nbmc_mesh_write(m, path.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    const nbmc::io::Mesh back = nbmc::io::read_mesh(path);
    EXPECT_TRUE(same_bits(back.positions64, r.mesh.positions));
    EXPECT_EQ(back.triangles, r.mesh.triangles);
    EXPECT_EQ(back.normals, r.mesh.normals);
    const std::string text = slurp(path);
    const char* tag = std::string(ext) == "ply" ? "property double x" : std::string(ext) == "vtk" ? "POINTS " : "Float64";
    EXPECT_NE(text.find(tag), std::string::npos);
    if (std::string(ext) == "vtk") EXPECT_NE(text.find(" double\n"), std::string::npos);
  }
  {  // OBJ: shortest decimals that read back exactly
    const std::string path = tmp("m.obj");
    ASSERT_EQ(nbmc_mesh_write(m, path.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    std::ifstream f(path);
    std::string line;
    std::vector<double> v;
    while (std::getline(f, line))
      if (line.rfind("v ", 0) == 0) {
        std::istringstream s(line.substr(2));
        for (int k = 0; k < 3; ++k) {
          std::string w;
          s >> w;
          v.push_back(std::strtod(w.c_str(), nullptr));
        }
      }
    EXPECT_TRUE(same_bits(v, r.mesh.positions));
  }
  {  // glTF: float positions (the rounded ones)
    const std::string path = tmp("m.glb");
    ASSERT_EQ(nbmc_mesh_write(m, path.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    const std::string b = slurp(path);
    std::uint32_t json_len = 0;
    std::memcpy(&json_len, b.data() + 12, 4);
    const std::size_t bin = 20 + json_len + 8;
    ASSERT_GE(b.size(), bin + 12 * r.mesh.vertex_count());
    std::vector<float> f(3 * r.mesh.vertex_count());
    std::memcpy(f.data(), b.data() + bin, f.size() * sizeof(float));
    EXPECT_TRUE(same_bits(f, r.mesh.positions_f32));
  }
  nbmc_mesh_destroy(m);
}

// Without the flag the writers write what they always wrote: float
// positions, the float mesh's bytes.
TEST(DoublePositions, FloatMeshesWriteFloats) {
  nbmc_mesh* m = nullptr;
  const Outcome r = run(offset_sphere(0), params(false), 1, 1, 1, 0, NBMC_BACKEND_OPENMP, &m);
  ASSERT_EQ(r.status, NBMC_OK) << r.error;
  TempDir tmp;
  for (const char* ext : {"ply", "vtk", "vtu"}) {
    const std::string path = tmp(std::string("f.") + ext);
    ASSERT_EQ(nbmc_mesh_write(m, path.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    const std::string text = slurp(path);
    EXPECT_EQ(text.find("double"), std::string::npos) << ext;
    EXPECT_EQ(text.find("Float64\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\""), std::string::npos);
    const nbmc::io::Mesh back = nbmc::io::read_mesh(path);
    EXPECT_TRUE(same_bits(back.positions, r.mesh.positions_f32)) << ext;
  }
  nbmc_mesh_destroy(m);
}
