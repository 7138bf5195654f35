// SPDX-License-Identifier: MIT
// The command line's mesh post-processing options: --check (text and JSON
// reports), --no-cleanup, --smooth, --smooth-weights, --decimate, and
// --isolated sphere's point set.
#include "cli_fixture.hpp"
#include "io/mesh.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>

namespace {

namespace fs = std::filesystem;
using nbmc_test::contains;
using nbmc_test::quote;
using nbmc_test::slurp;

const std::string kFrame = std::string(NBMC_DATA_DIR) + "/xyz/splashsurf_dambreak_f23_24389.xyz";

// The number after "key": in a JSON text, as a string ("" if absent); the
// first occurrence after `after` (an object's key) when given.
std::string json_value(const std::string& json, const std::string& key, const std::string& after = "") {
  std::size_t pos = after.empty() ? 0 : json.find("\"" + after + "\"");
  if (pos == std::string::npos) return "";
  pos = json.find("\"" + key + "\"", pos);
  if (pos == std::string::npos) return "";
  pos = json.find(':', pos) + 1;
  while (pos < json.size() && json[pos] == ' ') ++pos;
  std::size_t end = pos;
  while (end < json.size() && json[end] != ',' && json[end] != '}' && json[end] != '\n') ++end;
  return json.substr(pos, end - pos);
}

class MeshCliTest : public nbmc_test::CliFixture {
 protected:
  MeshCliTest() : CliFixture("nbmc_mesh_cli_") {}
};

TEST_F(MeshCliTest, CheckCleanupSmooth) {
  if (!fs::exists(kFrame)) GTEST_SKIP() << kFrame << " not found";
  const std::string base = "reconstruct " + quote(kFrame) + " -o " + quote(path("m.ply")) +
                           " --spacing 0.05 --progress never --check";
  // Text report: the check's section, the post-processing line and stage.
  nbmc_test::CliResult r = run(base);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* s : {"mesh check: closed yes, manifold yes, oriented yes", "cleaned up (92,960 triangles before, ",
                        "postprocess", "euler_characteristic", "min_angle_degrees", "volume"})
    EXPECT_TRUE(contains(r.out, s)) << s << "\n" << r.out;

  // JSON: raw mesh (--no-cleanup) against the default.
  r = run(base + " --no-cleanup --json " + quote(path("raw.json")) + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string raw = slurp(path("raw.json"));
  r = run(base + " --json " + quote(path("clean.json")) + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string clean = slurp(path("clean.json"));
  EXPECT_EQ(json_value(raw, "cleanup"), "false") << raw;
  EXPECT_EQ(json_value(clean, "cleanup"), "true") << clean;
  for (const std::string* j : {&raw, &clean}) {
    EXPECT_EQ(json_value(*j, "closed", "mesh_check"), "true") << *j;
    EXPECT_EQ(json_value(*j, "manifold", "mesh_check"), "true");
    EXPECT_EQ(json_value(*j, "oriented", "mesh_check"), "true");
    EXPECT_EQ(json_value(*j, "euler_characteristic", "mesh_check"), "84");
    EXPECT_EQ(json_value(*j, "raw_triangle_count"), "92960");
  }
  EXPECT_NE(json_value(raw, "sliver_triangle_count", "mesh_check"), "0");
  EXPECT_EQ(json_value(clean, "sliver_triangle_count", "mesh_check"), "0");
  EXPECT_EQ(json_value(clean, "degenerate_triangle_count", "mesh_check"), "0");
  EXPECT_EQ(json_value(clean, "triangle_count", "mesh_check"), json_value(clean, "triangle_count", "counts"));
  EXPECT_EQ(json_value(raw, "triangle_count", "counts"), "92960");
  EXPECT_FALSE(contains(clean, "\"smoothing\"")) << clean;
  // The clean-up's counts: what it found is what the check finds on the raw
  // mesh; every removed triangle is accounted for; none without it.
  auto count = [](const std::string& j, const char* key, const char* in = "counts") {
    return std::stoll(json_value(j, key, in));
  };
  EXPECT_EQ(count(clean, "cleanup_bad_triangles_before"),
            count(raw, "sliver_triangle_count", "mesh_check") + count(raw, "degenerate_triangle_count", "mesh_check"));
  EXPECT_GT(count(clean, "cleanup_bad_triangles_before"), 0);
  EXPECT_EQ(count(clean, "cleanup_bad_triangles_after"), 0);
  EXPECT_GT(count(clean, "cleanup_moves") + count(clean, "cleanup_flips") + count(clean, "cleanup_collapses"), 0);
  EXPECT_EQ(count(clean, "raw_triangle_count") - count(clean, "triangle_count"),
            2 * count(clean, "cleanup_collapses") + 6 * count(clean, "cleanup_cuts") +
                count(clean, "cleanup_removed_component_triangles"))
      << clean;
  for (const char* k : {"cleanup_bad_triangles_before", "cleanup_moves", "cleanup_flips", "cleanup_collapses"})
    EXPECT_EQ(count(raw, k), 0) << k;

  // Smoothing: reported volume change, still a clean closed mesh.
  r = run(base + " --smooth 5 --json " + quote(path("smooth.json")) + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string smooth = slurp(path("smooth.json"));
  EXPECT_EQ(json_value(smooth, "iterations", "smoothing"), "5") << smooth;
  const double dv = std::stod(json_value(smooth, "volume_change", "smoothing"));
  EXPECT_LT(std::abs(dv), 0.01);
  EXPECT_NE(dv, 0.0);
  EXPECT_EQ(json_value(smooth, "closed", "mesh_check"), "true");
  EXPECT_EQ(json_value(smooth, "sliver_triangle_count", "mesh_check"), "0");

  // Bad values are usage errors.
  r = run(base + " --smooth -1");
  EXPECT_EQ(r.exit_code, 2) << r.out << r.err;
}

// --double-positions: PLY with double x y z and VTU with Float64 points,
// "double_positions" in the JSON, the text report says so; without it, float.
TEST_F(MeshCliTest, DoublePositions) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) + " --particle-radius 0.025 --progress never";
  nbmc_test::CliResult r = run(base + " -o " + quote(path("d.ply")) + " --double-positions --json " +
                               quote(path("d.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "double-precision positions")) << r.out;
  EXPECT_EQ(json_value(slurp(path("d.json")), "double_positions"), "true");
  r = run(base + " -o " + quote(path("f.ply")) + " --json " + quote(path("f.json")) + " -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(json_value(slurp(path("f.json")), "double_positions"), "false");
  const std::string d = slurp(path("d.ply")), f = slurp(path("f.ply"));
  EXPECT_TRUE(contains(d, "property double x\nproperty double y\nproperty double z\n"));
  EXPECT_TRUE(contains(f, "property float x\nproperty float y\nproperty float z\n"));
  EXPECT_FALSE(contains(f, "double"));
  r = run(base + " -o " + quote(path("d.vtu")) + " --double-positions -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(slurp(path("d.vtu")), "<DataArray type=\"Float64\" Name=\"Points\""));
}

// --decimate: the mesh written has at most that fraction of the triangles,
// still closed, manifold and oriented; the text and JSON reports give the
// counts before and after; --smooth-weights feature is reported; bad
// fractions are usage errors.
TEST_F(MeshCliTest, DecimateAndFeatureSmoothing) {
  if (!fs::exists(kFrame)) GTEST_SKIP() << kFrame << " not found";
  const std::string base = "reconstruct " + quote(kFrame) + " --spacing 0.05 --progress never --check";
  nbmc_test::CliResult r = run(base + " -o " + quote(path("d.ply")) + " --smooth 3 --smooth-weights feature" +
                               " --decimate 0.25 --json " + quote(path("d.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string j = slurp(path("d.json"));
  const long long before = std::stoll(json_value(j, "triangles_before", "decimation"));
  const long long after = std::stoll(json_value(j, "triangles_after", "decimation"));
  EXPECT_GT(before, 80000) << j;
  EXPECT_LE(after, (before + 3) / 4) << j;
  EXPECT_GE(after, before / 5) << j;
  EXPECT_EQ(json_value(j, "pre_decimation_triangle_count", "counts"), std::to_string(before));
  EXPECT_EQ(json_value(j, "triangle_count", "counts"), std::to_string(after));
  EXPECT_EQ(json_value(j, "decimate"), "0.25");
  EXPECT_EQ(json_value(j, "smooth_weights"), "\"feature\"");
  EXPECT_EQ(json_value(j, "closed", "mesh_check"), "true");
  EXPECT_EQ(json_value(j, "manifold", "mesh_check"), "true");
  EXPECT_EQ(json_value(j, "oriented", "mesh_check"), "true");
  EXPECT_EQ(json_value(j, "euler_characteristic", "mesh_check"), "84");  // the same topology as undecimated
  EXPECT_EQ(nbmc::io::read_mesh_ply(path("d.ply")).triangle_count(), std::uint64_t(after));
  r = run(base + " -o " + quote(path("t.ply")) + " --smooth 3 --smooth-weights feature --decimate 0.25");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "3 feature-weighted smoothing iterations")) << r.out;
  EXPECT_TRUE(contains(r.out, "decimated to 0.25 (")) << r.out;
  for (const char* bad : {"0", "1.5", "-1", "x"})
    EXPECT_EQ(run(base + " -o " + quote(path("x.ply")) + " --decimate " + bad).exit_code, 2) << bad;
  EXPECT_EQ(run(base + " -o " + quote(path("x.ply")) + " --smooth-weights sometimes").exit_code, 2);
}

// --isolated sphere: the mesh is --isolated drop's, and the dropped particles
// go to <output>_spheres.ply (x y z radius, no faces); the report names it.
TEST_F(MeshCliTest, IsolatedSpheres) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) + " --particle-radius 0.025 --progress never";
  nbmc_test::CliResult r = run(base + " -o " + quote(path("s.obj")) + " --isolated sphere --min-cluster 20 --json " +
                               quote(path("s.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run(base + " -o " + quote(path("drop.obj")) + " --isolated drop --min-cluster 20 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(slurp(path("s.obj")), slurp(path("drop.obj")));
  EXPECT_FALSE(fs::exists(path("drop_spheres.ply")));
  const std::string j = slurp(path("s.json"));
  const long long n = std::stoll(json_value(j, "count", "spheres"));
  EXPECT_GT(n, 0) << j;
  EXPECT_EQ(json_value(j, "dropped_particle_count", "counts"), std::to_string(n));
  EXPECT_TRUE(contains(j, "s_spheres.ply")) << j;
  const std::string ply = slurp(path("s_spheres.ply"));
  EXPECT_TRUE(contains(ply, "element vertex " + std::to_string(n) + "\n")) << ply.substr(0, 300);
  EXPECT_TRUE(contains(ply, "property float radius\n")) << ply.substr(0, 300);
  EXPECT_TRUE(contains(ply, "element face 0\n")) << ply.substr(0, 300);
  const nbmc::io::Mesh m = nbmc::io::read_mesh_ply(path("s_spheres.ply"));
  EXPECT_EQ(m.vertex_count(), std::uint64_t(n));
  EXPECT_EQ(m.triangle_count(), 0u);
  r = run(base + " -o " + quote(path("t.ply")) + " --isolated sphere --min-cluster 20");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "written as spheres to " + path("t_spheres.ply"))) << r.out;
}

}  // namespace
