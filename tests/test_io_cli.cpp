// SPDX-License-Identifier: MIT
// The nbmc command with the formats of issue 4: numbered sequences, H5Part
// steps, --frames, --resume, --attributes, --format, failed frames.
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "nbmc.h"
#include "cli_fixture.hpp"
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using nbmc_test::contains;
using nbmc_test::quote;
using nbmc_test::slurp;
using Result = nbmc_test::CliResult;
const std::string kBinary = nbmc_test::cli_binary();
const std::string kData = std::string(NBMC_SOURCE_DIR) + "/tests/data/";

class CliIo : public nbmc_test::CliFixture {
protected:
  CliIo() : CliFixture("nbmc_test_cli_io_") {}
  void SetUp() override {
    CliFixture::SetUp();
    fs::create_directories(dir_ / "frames");
  }
  // A small sphere of particles as a raw .xyz frame.
  void frame(const std::string& name, double radius) const {
    const auto p = nbmc_test::sphere(0, 0, 0, radius, 0.1);
    std::string bytes;
    for (double v : p) {
      const float f = static_cast<float>(v);
      bytes.append(reinterpret_cast<const char*>(&f), 4);
    }
    std::ofstream(path(name), std::ios::binary) << bytes;
  }
};

} // namespace

TEST_F(CliIo, NumberedFilesInNaturalOrder) {
  frame("frames/fluid_1.xyz", 0.3);
  frame("frames/fluid_2.xyz", 0.35);
  frame("frames/fluid_10.xyz", 0.4);
  std::ofstream(path("frames/fluid_x.xyz")) << "not a frame number";
  const Result r = run("reconstruct 'frames/fluid_{}.xyz' -o 'out/s_{}.ply' --spacing 0.1 --progress always");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"out/s_1.ply", "out/s_2.ply", "out/s_10.ply"}) {
    ASSERT_TRUE(fs::exists(path(f))) << f;
    EXPECT_GT(nbmc::io::read_mesh_ply(path(f)).triangle_count(), 0u) << f;
  }
  const std::size_t a = r.err.find("[1/3] frame 1:"), b = r.err.find("[2/3] frame 2:"), c = r.err.find("[3/3] frame 10:");
  ASSERT_NE(a, std::string::npos) << r.err;
  ASSERT_NE(b, std::string::npos) << r.err;
  ASSERT_NE(c, std::string::npos) << r.err;
  EXPECT_LT(a, b);
  EXPECT_LT(b, c);
  EXPECT_TRUE(contains(r.err, "frames/s")) << r.err;
  EXPECT_TRUE(contains(r.err, "left")) << r.err;
  EXPECT_TRUE(contains(r.out, "3 (3 written, 0 skipped, 0 failed)")) << r.out;
}

TEST_F(CliIo, AFailedFrameIsReportedAndTheRestGoOn) {
  frame("frames/f_1.xyz", 0.3);
  std::ofstream(path("frames/f_2.xyz")) << "1234567890123"; // 13 bytes
  frame("frames/f_3.xyz", 0.3);
  const Result r = run("reconstruct 'frames/f_{}.xyz' -o 'out/s_{}.vtk' --spacing 0.1 --json");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "frame 2")) << r.err;
  EXPECT_TRUE(contains(r.err, "f_2.xyz")) << r.err;
  EXPECT_TRUE(fs::exists(path("out/s_1.vtk")));
  EXPECT_FALSE(fs::exists(path("out/s_2.vtk")));
  EXPECT_TRUE(fs::exists(path("out/s_3.vtk")));
  EXPECT_TRUE(contains(r.out, "\"failed\": 1")) << r.out;
  EXPECT_TRUE(contains(r.out, "\"written\": 2")) << r.out;
}

// A sequence reads the next frame and writes the previous one while it
// reconstructs a frame; --sequential-io does one thing at a time. Same files
// byte for byte, same report (a failed frame, a skipped one, spheres too).
TEST_F(CliIo, OverlappedAndSequentialIoGiveTheSameFiles) {
  for (int i = 0; i < 5; ++i) frame("frames/f_" + std::to_string(i) + ".xyz", 0.25 + 0.05 * i);
  std::ofstream(path("frames/f_2.xyz")) << "1234567890123";  // 13 bytes: fails
  const std::string common = " --spacing 0.1 --isolated sphere --min-cluster 1 --json";
  fs::create_directories(path("a"));
  fs::copy_file(path("frames/f_0.xyz"), path("a/s_4.ply"));  // "exists": --resume skips frame 4
  fs::create_directories(path("b"));
  fs::copy_file(path("frames/f_0.xyz"), path("b/s_4.ply"));
  const Result a = run("reconstruct 'frames/f_{}.xyz' -o 'a/s_{}.ply' --resume" + common);
  const Result b = run("reconstruct 'frames/f_{}.xyz' -o 'b/s_{}.ply' --resume --sequential-io" + common);
  // Two contexts taking turns (the default with CUDA): the same again.
  fs::create_directories(path("c"));
  fs::copy_file(path("frames/f_0.xyz"), path("c/s_4.ply"));
  const Result c = run("reconstruct 'frames/f_{}.xyz' -o 'c/s_{}.ply' --resume --contexts 2" + common);
  EXPECT_EQ(a.exit_code, 1) << a.err;
  EXPECT_EQ(b.exit_code, 1) << b.err;
  EXPECT_EQ(c.exit_code, 1) << c.err;
  for (const char* f : {"s_0.ply", "s_1.ply", "s_3.ply", "s_0_spheres.ply", "s_3_spheres.ply"}) {
    const std::string da = slurp(path(std::string("a/") + f)), db = slurp(path(std::string("b/") + f));
    EXPECT_FALSE(da.empty()) << f;
    EXPECT_EQ(da, db) << f;
    EXPECT_EQ(da, slurp(path(std::string("c/") + f))) << f;
  }
  EXPECT_FALSE(fs::exists(path("a/s_2.ply")));
  EXPECT_FALSE(fs::exists(path("c/s_2.ply")));
  for (const char* key : {"\"written\": 3", "\"failed\": 1", "\"skipped\": 1"}) {
    EXPECT_TRUE(contains(a.out, key)) << a.out;
    EXPECT_TRUE(contains(b.out, key)) << b.out;
    EXPECT_TRUE(contains(c.out, key)) << c.out;
  }
  for (const Result* r : {&a, &c}) {
    const std::size_t e1 = r->err.find("frame 2"), l3 = r->err.find("[4/5] frame 3");
    ASSERT_NE(e1, std::string::npos) << r->err;
    EXPECT_TRUE(l3 == std::string::npos || e1 < l3) << r->err;  // reported in frame order
  }
  // In frame order in the JSON as well.
  std::size_t at = 0;
  for (int i = 0; i < 5; ++i) {
    const std::size_t k = c.out.find("\"label\": \"" + std::to_string(i) + "\"", at);
    ASSERT_NE(k, std::string::npos) << i << c.out;
    at = k;
  }
  EXPECT_EQ(run("reconstruct 'frames/f_{}.xyz' -o 'c/s_{}.ply' --contexts 3" + common).exit_code, 2);
}

// An overlapped sequence runs itself again with OMP_WAIT_POLICY=passive
// (libgomp's spinning threads otherwise take the cores from the I/O
// threads), once; not when the user set the variable, nor with
// --sequential-io; the same files every way.
TEST_F(CliIo, OverlappedSequencesRunAgainWithPassiveOpenMp) {
  if (!nbmc_backend_available(NBMC_BACKEND_OPENMP)) GTEST_SKIP() << "no OpenMP in this build";
  for (int i = 0; i < 3; ++i) frame("frames/f_" + std::to_string(i) + ".xyz", 0.25 + 0.05 * i);
  const char* had = std::getenv("OMP_WAIT_POLICY");
  const std::string saved = had ? had : "";
  ::unsetenv("OMP_WAIT_POLICY");
  ::setenv("NBMC_TRACE", "1", 1);
  const std::string line = "running again with OMP_WAIT_POLICY=passive";
  const auto count = [&](const std::string& err) {
    std::size_t n = 0;
    for (std::size_t at = err.find(line); at != std::string::npos; at = err.find(line, at + 1)) ++n;
    return n;
  };
  const Result a = run("reconstruct 'frames/f_{}.xyz' -o 'a/s_{}.ply' --spacing 0.1 -q");
  const Result b = run("reconstruct 'frames/f_{}.xyz' -o 'b/s_{}.ply' --spacing 0.1 -q --sequential-io");
  ::setenv("OMP_WAIT_POLICY", "active", 1);
  const Result c = run("reconstruct 'frames/f_{}.xyz' -o 'c/s_{}.ply' --spacing 0.1 -q");
  ::unsetenv("NBMC_TRACE");
  if (had) ::setenv("OMP_WAIT_POLICY", saved.c_str(), 1);
  else ::unsetenv("OMP_WAIT_POLICY");
  ASSERT_EQ(a.exit_code, 0) << a.err;
  ASSERT_EQ(b.exit_code, 0) << b.err;
  ASSERT_EQ(c.exit_code, 0) << c.err;
  EXPECT_EQ(count(a.err), 1u) << a.err.substr(0, 2000);
  EXPECT_EQ(count(b.err), 0u);
  EXPECT_EQ(count(c.err), 0u);
  for (int i = 0; i < 3; ++i) {
    const std::string f = "/s_" + std::to_string(i) + ".ply";
    const std::string da = slurp(path("a" + f));
    EXPECT_FALSE(da.empty()) << f;
    EXPECT_EQ(da, slurp(path("b" + f))) << f;
    EXPECT_EQ(da, slurp(path("c" + f))) << f;
  }
}

TEST_F(CliIo, ResumeAndFrames) {
  for (int i = 0; i < 4; ++i) frame("frames/f_000" + std::to_string(i) + ".xyz", 0.3);
  Result r = run("reconstruct 'frames/f_{}.xyz' -o 'out/s_{}.glb' --spacing 0.1 --frames 1:3:2 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(path("out/s_0000.glb")));
  EXPECT_TRUE(fs::exists(path("out/s_0001.glb"))); // zero padding kept
  EXPECT_FALSE(fs::exists(path("out/s_0002.glb")));
  EXPECT_TRUE(fs::exists(path("out/s_0003.glb")));
  r = run("reconstruct 'frames/f_{}.xyz' -o 'out/s_{}.glb' --spacing 0.1 --resume --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "\"skipped\": 2")) << r.out;
  EXPECT_TRUE(contains(r.out, "\"written\": 2")) << r.out;
  EXPECT_TRUE(fs::exists(path("out/s_0000.glb")));
  // A frame asked for that does not exist fails on its own.
  r = run("reconstruct 'frames/f_{}.xyz' -o 'out/t_{}.ply' --spacing 0.1 --frames 3:4 -q");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "frame 4")) << r.err;
  EXPECT_TRUE(fs::exists(path("out/t_0003.ply")));
  EXPECT_EQ(run("reconstruct 'frames/f_{}.xyz' -o 'out/t_{}.ply' --spacing 0.1 --frames 3").exit_code, 2);
  EXPECT_EQ(run("reconstruct 'frames/none_{}.xyz' -o 'out/t_{}.ply' --spacing 0.1").exit_code, 1);
}

TEST_F(CliIo, H5PartStepsWithAttributes) {
  const std::string h5 = kData + "h5part_steps.h5part";
  Result r = run("reconstruct " + quote(h5) + " -o 'out/h_{}.vtu' --spacing 0.1 --attributes rho,v --frames 0:1 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(path("out/h_2.vtu")));
  for (int s = 0; s < 2; ++s) {
    const std::string f = path("out/h_" + std::to_string(s) + ".vtu");
    ASSERT_TRUE(fs::exists(f)) << f;
    const nbmc::io::Mesh m = nbmc::io::read_mesh(f);
    ASSERT_GT(m.vertex_count(), 0u);
    const nbmc::io::Attribute* rho = nbmc::io::find_attribute(m.attributes, "rho");
    const nbmc::io::Attribute* v = nbmc::io::find_attribute(m.attributes, "v");
    ASSERT_NE(rho, nullptr);
    ASSERT_NE(v, nullptr);
    EXPECT_EQ(v->components, 3);
    for (double x : rho->values) {
      EXPECT_GE(x, 1000 - 1e-3);
      EXPECT_LE(x, 1019 + 1e-3);
    }
  }
  // Step 2 has no velocity: that frame fails, the others are written.
  r = run("reconstruct " + quote(h5) + " -o 'out/g_{}.ply' --spacing 0.1 --attributes v -q");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "no particle attribute 'v'")) << r.err;
  EXPECT_TRUE(contains(r.err, "id (scalar), rho (scalar)")) << r.err;
  EXPECT_TRUE(fs::exists(path("out/g_1.ply")));
  EXPECT_FALSE(fs::exists(path("out/g_2.ply")));
  // One output name: the first step, or the one --frames picks.
  r = run("reconstruct " + quote(h5) + " -o single.ply --spacing 0.1 --frames 2:2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "\"format\": \"h5part\"")) << r.out;
  EXPECT_EQ(run("reconstruct " + quote(h5) + " -o single.ply --spacing 0.1 --frames 0:2").exit_code, 2);
}

TEST_F(CliIo, FormatsAndUsageErrors) {
  frame("one.xyz", 0.3);
  // --format for a file without a telling extension.
  fs::copy_file(kData + "legacy_poly_binary.vtk", path("cloud.dat"));
  Result r = run("reconstruct cloud.dat --format vtk -o c.vtu --spacing 0.1 -q");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = run("reconstruct cloud.dat --format VTK -o c.obj --spacing 0.1 --attributes density");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(contains(r.err, "OBJ")) << r.err;
  r = run("reconstruct cloud.dat --format vtk -o c.ply --spacing 0.1 --attributes pressure");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "no particle attribute 'pressure'")) << r.err;
  EXPECT_TRUE(contains(r.err, "velocity")) << r.err;
  EXPECT_EQ(run("reconstruct 'f_{}.xyz' -o out.ply --spacing 0.1").exit_code, 2);
  EXPECT_EQ(run("reconstruct one.xyz -o 'out_{}.ply' --spacing 0.1").exit_code, 2);
  EXPECT_EQ(run("reconstruct one.xyz -o out.ply --spacing 0.1 --frames 1:2").exit_code, 2);
  EXPECT_EQ(run("reconstruct one.xyz -o out.ply --spacing 0.1 --format stl").exit_code, 2);
  r = run("reconstruct one.xyz -o out.vtk --spacing 0.1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "\"attributes\": []")) << r.out;
  EXPECT_EQ(nbmc::io::read_mesh(path("out.vtk")).normals.size(), nbmc::io::read_mesh(path("out.vtk")).positions.size());
}
