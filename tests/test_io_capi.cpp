// SPDX-License-Identifier: MIT
// The File I/O section of nbmc.h: nbmc_context_load_particles,
// nbmc_mesh_write, nbmc_last_error; exact status codes for misuse.
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "nbmc.h"
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <unistd.h>

namespace fs = std::filesystem;

namespace {

const std::string kData = std::string(NBMC_SOURCE_DIR) + "/tests/data/";

class CapiIo : public ::testing::Test {
protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("nbmc_test_capi_io_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = NBMC_BACKEND_SERIAL;
    ASSERT_EQ(nbmc_context_create(&d, &ctx_), NBMC_OK);
  }
  void TearDown() override {
    nbmc_context_destroy(ctx_);
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& n) const { return (dir_ / n).string(); }
  std::string write(const std::string& n, const std::string& bytes) const {
    std::ofstream(path(n), std::ios::binary) << bytes;
    return path(n);
  }
  bool has(const char* msg, const std::string& needle) const { return std::string(msg).find(needle) != std::string::npos; }
  nbmc_context* ctx_ = nullptr;
  fs::path dir_;
};

std::string floats(std::initializer_list<float> v) {
  std::string s;
  for (float f : v) s.append(reinterpret_cast<const char*>(&f), 4);
  return s;
}

} // namespace

TEST_F(CapiIo, LoadsEveryFormatAndReconstructs) {
  for (const char* f : {"appended_raw_zlib.vtu", "legacy_poly_binary.vtk", "small_points.bgeo.gz",
                        "h5part_steps.h5part", "gadget_snapshot.hdf5", "pysph_output.hdf5"}) {
    SCOPED_TRACE(f);
    uint64_t n = 0;
    ASSERT_EQ(nbmc_context_load_particles(ctx_, (kData + f).c_str(), nullptr, &n), NBMC_OK)
        << nbmc_context_last_error(ctx_);
    EXPECT_EQ(n, 20u);
    EXPECT_STREQ(nbmc_context_last_error(ctx_), "");
  }
  uint64_t n = 0;
  ASSERT_EQ(nbmc_context_load_particles(ctx_, (kData + "generic.h5:/cloud").c_str(), "hdf5", &n), NBMC_OK);
  EXPECT_EQ(n, 20u);
  ASSERT_EQ(nbmc_context_load_particles(ctx_, (kData + "small_points.bgeo").c_str(), "BGEO", nullptr), NBMC_OK);
  // A real reconstruction from a loaded file, written through the C API.
  const auto lattice = nbmc_test::sphere(0, 0, 0, 0.5, 0.1);
  nbmc::io::Particles p;
  p.xyz = lattice;
  std::string bytes;
  for (double v : lattice) {
    const float f = static_cast<float>(v);
    bytes.append(reinterpret_cast<const char*>(&f), 4);
  }
  const std::string xyz = write("sphere.xyz", bytes);
  ASSERT_EQ(nbmc_context_load_particles(ctx_, xyz.c_str(), nullptr, &n), NBMC_OK);
  EXPECT_EQ(n, lattice.size() / 3);
  nbmc_params prm = nbmc_test::params(0.1);
  nbmc_mesh* mesh = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx_, &prm, &mesh), NBMC_OK) << nbmc_context_last_error(ctx_);
  for (const char* ext : {"ply", "obj", "vtk", "vtu", "glb"}) {
    const std::string out = path(std::string("sphere.") + ext);
    ASSERT_EQ(nbmc_mesh_write(mesh, out.c_str(), nullptr), NBMC_OK) << nbmc_last_error();
    EXPECT_STREQ(nbmc_last_error(), "");
    EXPECT_GT(fs::file_size(out), 0u);
  }
  const nbmc::io::Mesh back = nbmc::io::read_mesh(path("sphere.vtu"));
  EXPECT_EQ(back.vertex_count(), nbmc_mesh_vertex_count(mesh));
  EXPECT_EQ(back.triangle_count(), nbmc_mesh_triangle_count(mesh));
  EXPECT_EQ(0, std::memcmp(back.positions.data(), nbmc_mesh_positions(mesh), back.positions.size() * 4));
  // Explicit format over the extension.
  ASSERT_EQ(nbmc_mesh_write(mesh, path("sphere.bin").c_str(), "vtk"), NBMC_OK);
  EXPECT_EQ(nbmc::io::read_mesh(path("sphere.bin"), "vtk").triangle_count(), nbmc_mesh_triangle_count(mesh));
  nbmc_mesh_destroy(mesh);
}

TEST_F(CapiIo, LoadErrorsHaveExactCodesAndNameTheFile) {
  uint64_t n = 99;
  EXPECT_EQ(nbmc_context_load_particles(ctx_, path("missing.vtu").c_str(), nullptr, &n), NBMC_ERROR_IO);
  EXPECT_EQ(n, 0u);
  EXPECT_TRUE(has(nbmc_context_last_error(ctx_), "missing.vtu")) << nbmc_context_last_error(ctx_);

  const std::string bad = write("bad.vtk", "# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 5 float\n1 2 3\n");
  EXPECT_EQ(nbmc_context_load_particles(ctx_, bad.c_str(), nullptr, &n), NBMC_ERROR_FORMAT);
  EXPECT_TRUE(has(nbmc_context_last_error(ctx_), "bad.vtk")) << nbmc_context_last_error(ctx_);

  EXPECT_EQ(nbmc_context_load_particles(ctx_, write("p.foo", "").c_str(), nullptr, &n), NBMC_ERROR_FORMAT);
  EXPECT_EQ(nbmc_context_load_particles(ctx_, bad.c_str(), "nope", &n), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_TRUE(has(nbmc_context_last_error(ctx_), "nope"));

  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::string nanfile = write("nan.xyz", floats({0, 0, 0, nan, 1, 2}));
  EXPECT_EQ(nbmc_context_load_particles(ctx_, nanfile.c_str(), nullptr, &n), NBMC_ERROR_INVALID_PARTICLES);
  EXPECT_TRUE(has(nbmc_context_last_error(ctx_), "nan.xyz")) << nbmc_context_last_error(ctx_);
  EXPECT_EQ(nbmc_context_load_particles(ctx_, write("empty.xyz", "").c_str(), nullptr, &n), NBMC_ERROR_NO_PARTICLES);
  EXPECT_TRUE(has(nbmc_context_last_error(ctx_), "empty.xyz")) << nbmc_context_last_error(ctx_);

  // A failed load leaves no particles behind.
  ASSERT_EQ(nbmc_context_load_particles(ctx_, (kData + "small_points.bgeo").c_str(), nullptr, &n), NBMC_OK);
  EXPECT_NE(nbmc_context_load_particles(ctx_, bad.c_str(), nullptr, &n), NBMC_OK);
  nbmc_params prm = nbmc_test::params(0.1);
  nbmc_mesh* mesh = nullptr;
  EXPECT_EQ(nbmc_context_reconstruct(ctx_, &prm, &mesh), NBMC_ERROR_NO_PARTICLES);

  EXPECT_EQ(nbmc_context_load_particles(nullptr, bad.c_str(), nullptr, &n), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_TRUE(has(nbmc_last_error(), "ctx is NULL"));
  EXPECT_EQ(nbmc_context_load_particles(ctx_, nullptr, nullptr, &n), NBMC_ERROR_INVALID_ARGUMENT);
}

TEST_F(CapiIo, MeshWriteErrors) {
  nbmc_params prm = nbmc_test::params(0.1);
  const auto s = nbmc_test::sphere(0, 0, 0, 0.3, 0.1);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx_, s.data(), s.size() / 3, 0), NBMC_OK);
  nbmc_mesh* mesh = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx_, &prm, &mesh), NBMC_OK);
  EXPECT_EQ(nbmc_mesh_write(nullptr, path("a.ply").c_str(), nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_TRUE(has(nbmc_last_error(), "mesh is NULL"));
  EXPECT_EQ(nbmc_mesh_write(mesh, nullptr, nullptr), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_mesh_write(mesh, path("a.stl").c_str(), nullptr), NBMC_ERROR_FORMAT);
  EXPECT_TRUE(has(nbmc_last_error(), "a.stl")) << nbmc_last_error();
  EXPECT_EQ(nbmc_mesh_write(mesh, path("a.ply").c_str(), "stl"), NBMC_ERROR_INVALID_ARGUMENT);
  EXPECT_EQ(nbmc_mesh_write(mesh, path("no/dir/a.ply").c_str(), nullptr), NBMC_ERROR_IO);
  EXPECT_TRUE(has(nbmc_last_error(), "no/dir/a.ply")) << nbmc_last_error();
  EXPECT_EQ(nbmc_mesh_write(mesh, path("ok.ply").c_str(), nullptr), NBMC_OK);
  EXPECT_STREQ(nbmc_last_error(), "");
  nbmc_mesh_destroy(mesh);
}
