// SPDX-License-Identifier: MIT
// The nbmc command: exit codes, messages, and a small real reconstruction.
// Needs the nbmc_cli target built (NBMC_BINARY_DIR/src/cli/nbmc).
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "nbmc.h"
#include "cli_fixture.hpp"
#include "nbmc_test.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <chrono>
#include <csignal>
#include <thread>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

using nbmc_test::contains;
using nbmc_test::quote;
using nbmc_test::slurp;
using Result = nbmc_test::CliResult;
const std::string kBinary = nbmc_test::cli_binary();
const std::string kFrame = std::string(NBMC_DATA_DIR) + "/xyz/splashsurf_doubledambreak_f26_4732.xyz";

class CliTest : public nbmc_test::CliFixture {
protected:
  CliTest() : CliFixture("nbmc_test_cli_") {}
};

// The unsigned integer after "\"key\":" in a JSON text, or -1.
long long json_uint(const std::string& json, const std::string& key) {
  const std::string k = "\"" + key + "\"";
  std::size_t pos = json.find(k);
  if (pos == std::string::npos) return -1;
  pos = json.find(':', pos + k.size());
  if (pos == std::string::npos) return -1;
  ++pos;
  while (pos < json.size() && json[pos] == ' ') ++pos;
  std::size_t end = pos;
  while (end < json.size() && json[end] >= '0' && json[end] <= '9') ++end;
  if (end == pos) return -1;
  return std::stoll(json.substr(pos, end - pos));
}

} // namespace

TEST_F(CliTest, Help) {
  Result r = run("--help");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "reconstruct")) << r.out;
  EXPECT_TRUE(contains(r.out, "--spacing")) << r.out;

  r = run("reconstruct --help");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  for (const char* opt : {"--spacing", "--particle-radius", "--cell-size", "--influence-radius", "--band-width",
                          "--surface-radius", "--iso-radius", "--method", "--field", "--t-low", "--t-high",
                          "--color-threshold", "--neighbour-threshold", "--no-normals", "--bbox", "--threads",
                          "--backend", "--format", "--json", "--quiet", "--progress"})
    EXPECT_TRUE(contains(r.out, opt)) << opt;
  // Defaults shown are those of nbmc_params_init.
  nbmc_params p;
  nbmc_params_init(&p);
  std::ostringstream want;
  want << "--cell-size FLOAT=" << p.cell_size;
  EXPECT_TRUE(contains(r.out, want.str())) << r.out;
}

TEST_F(CliTest, Version) {
  const Result r = run("--version");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_TRUE(contains(r.out, nbmc_version_string())) << r.out;
}

TEST_F(CliTest, MissingInputFile) {
  const Result r = run("reconstruct " + quote(path("missing_particles.xyz")) + " -o " + quote(path("out.ply")) +
                       " --spacing 0.1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "missing_particles.xyz")) << r.err;
  EXPECT_TRUE(contains(r.err, "nbmc: error:")) << r.err;
  EXPECT_FALSE(fs::exists(path("out.ply")));
}

TEST_F(CliTest, UsageErrorsExitWith2) {
  const std::string io = quote(kFrame) + " -o " + quote(path("out.ply"));
  Result r = run("reconstruct " + io);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_TRUE(contains(r.err, "--spacing")) << r.err;
  EXPECT_EQ(run("reconstruct " + io + " --spacing 0.05 --particle-radius 0.025").exit_code, 2);
  EXPECT_EQ(run("reconstruct " + io + " --spacing 0.05 --method nope").exit_code, 2);
  EXPECT_EQ(run("reconstruct " + io + " --spacing 0.05 --no-such-option").exit_code, 2);
  EXPECT_EQ(run("reconstruct " + io + " --spacing 0.05 --bbox 0 0 0 1 1").exit_code, 2);
  EXPECT_EQ(run("reconstruct --spacing 0.05").exit_code, 2);
  EXPECT_EQ(run("").exit_code, 2);
  EXPECT_FALSE(fs::exists(path("out.ply")));
}

TEST_F(CliTest, BadInputAndOutputExitWith1) {
  std::ofstream(path("odd.xyz")) << "12345";
  Result r = run("reconstruct " + quote(path("odd.xyz")) + " -o " + quote(path("out.ply")) + " --spacing 0.05");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "odd.xyz")) << r.err;
  r = run("reconstruct " + quote(path("odd.xyz")) + " -o " + quote(path("out.stl")) + " --spacing 0.05");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "out.stl")) << r.err;
  r = run("reconstruct " + quote(path("odd.foo")) + " -o " + quote(path("out.ply")) + " --spacing 0.05");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, "unknown extension '.foo'")) << r.err;
}

TEST_F(CliTest, LibraryErrorsExitWith1) {
  if (!fs::exists(kFrame)) GTEST_SKIP() << kFrame << " not found";
  const Result r = run("reconstruct " + quote(kFrame) + " -o " + quote(path("out.ply")) + " --spacing -1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_TRUE(contains(r.err, std::string("nbmc: error: ") + nbmc_status_string(NBMC_ERROR_INVALID_PARAMETER)))
      << r.err;
  EXPECT_FALSE(fs::exists(path("out.ply")));
}

TEST_F(CliTest, ReconstructsARealFrame) {
  if (!fs::exists(kFrame)) GTEST_SKIP() << kFrame << " not found";
  const std::string ply = path("dd.ply");
  Result r = run("reconstruct " + quote(kFrame) + " -o " + quote(ply) +
                 " --particle-radius 0.025 --cell-size 1 --progress never");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto mesh = nbmc::io::read_mesh_ply(ply);
  EXPECT_GT(mesh.triangle_count(), 0u);
  EXPECT_EQ(mesh.normals.size(), mesh.positions.size());
  // The report: input, stages, counts, memory.
  EXPECT_TRUE(contains(r.out, "4,732 particles")) << r.out;
  for (int s = 0; s < NBMC_STAGE_COUNT; ++s) EXPECT_TRUE(contains(r.out, nbmc_stage_name(s))) << s;
  for (const char* word : {"read", "write", "total", "triangles", "peak memory"})
    EXPECT_TRUE(contains(r.out, word)) << word;
  EXPECT_TRUE(r.err.empty()) << r.err;

  // Same mesh size as the C API gives for the same input and parameters.
  const auto particles = nbmc::io::read_particles(kFrame);
  nbmc_params p = nbmc_test::params(0.05);
  p.cell_size = 1;
  const nbmc_test::Result direct = nbmc_test::reconstruct(particles.xyz, p, NBMC_BACKEND_AUTO);
  ASSERT_EQ(direct.status, NBMC_OK) << direct.message;
  EXPECT_EQ(mesh.triangle_count(), direct.mesh.triangle_count());
  EXPECT_EQ(mesh.vertex_count(), direct.mesh.vertex_count());

  // JSON on stdout (no table), and OBJ output without normals.
  const std::string obj = path("dd.obj");
  r = run("reconstruct " + quote(kFrame) + " -o " + quote(obj) +
          " --particle-radius 0.025 --cell-size 1 --no-normals --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.front(), '{') << r.out;
  EXPECT_EQ(json_uint(r.out, "triangle_count"), static_cast<long long>(mesh.triangle_count())) << r.out;
  EXPECT_EQ(json_uint(r.out, "particle_count"), 4732) << r.out;
  EXPECT_GT(json_uint(r.out, "peak_rss_bytes"), 0) << r.out;
  EXPECT_FALSE(contains(slurp(obj), "vn ")) << "normals written despite --no-normals";

  // JSON to a file, quiet: nothing on stdout.
  const std::string json = path("report.json");
  r = run("reconstruct " + quote(kFrame) + " -o " + quote(ply) + " --spacing 0.05 --cell-size 1 --quiet --json=" +
          quote(json));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
  const std::string text = slurp(json);
  EXPECT_EQ(json_uint(text, "triangle_count"), static_cast<long long>(mesh.triangle_count())) << text;
  EXPECT_TRUE(contains(text, "\"timings_seconds\"")) << text;
  // No temporary files left next to the outputs.
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_FALSE(contains(e.path().filename().string(), "nbmc-tmp")) << e.path();
}

// Ctrl-C during the reconstruction: exit 130, "cancelled", no mesh written.
TEST_F(CliTest, InterruptCancels) {
  const std::string frame = std::string(NBMC_DATA_DIR) + "/xyz/cbd1654k_t040_1654104.xyz";
  if (!fs::exists(frame)) GTEST_SKIP() << frame << " not found";
  const std::string out = path("big.ply"), err = path("stderr.txt");
  std::vector<std::string> args = {kBinary, "reconstruct", frame, "-o", out, "--spacing", "0.00484",
                                   "--cell-size", "0.25", "--progress", "always", "--quiet"};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = 0;
  ASSERT_EQ(posix_spawn(&pid, kBinary.c_str(), &actions, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&actions);
  // Wait for the first progress report, then interrupt.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!contains(slurp(err), "stage") && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ::kill(pid, SIGINT);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  if (WEXITSTATUS(status) == 0) GTEST_SKIP() << "the reconstruction finished before the interrupt arrived";
  EXPECT_EQ(WEXITSTATUS(status), 130) << slurp(err);
  EXPECT_TRUE(contains(slurp(err), "cancelled")) << slurp(err);
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(CliTest, MemoryBudget) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) + " -o " + quote(path("budget.ply")) +
                           " --particle-radius 0.025 --cell-size 1 --quiet";
  Result r = run(base + " --memory-budget 64k");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("memory budget exceeded"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("MiB"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(path("budget.ply")));
  EXPECT_EQ(run(base + " --memory-budget 12parsecs").exit_code, 2);
  r = run(base + " --memory-budget 2G");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(path("budget.ply")));
}

// --subdomains: the same file as the whole frame, the split in the report and
// the JSON; malformed values are usage errors.
TEST_F(CliTest, SubdomainsGiveTheSameFile) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) + " --particle-radius 0.025 --progress never";
  Result whole = run(base + " -o " + quote(path("whole.ply")));
  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  Result split = run(base + " -o " + quote(path("split.ply")) + " --subdomains 3x2x2 --json " +
                     quote(path("split.json")));
  ASSERT_EQ(split.exit_code, 0) << split.err;
  EXPECT_EQ(slurp(path("whole.ply")), slurp(path("split.ply")));
  EXPECT_TRUE(contains(split.out, "subdomains: 3 x 2 x 2")) << split.out;
  const std::string json = slurp(path("split.json"));
  EXPECT_TRUE(contains(json, "\"subdomains\": {\"grid\": [3, 2, 2]")) << json;
  EXPECT_EQ(json_uint(json, "count"), 12);
  // auto with a budget the frame fits: not split.
  Result fits = run(base + " -o " + quote(path("auto.ply")) + " --subdomains auto --memory-budget 2G --json " +
                    quote(path("auto.json")));
  ASSERT_EQ(fits.exit_code, 0) << fits.err;
  EXPECT_FALSE(contains(slurp(path("auto.json")), "\"subdomains\""));
  EXPECT_EQ(slurp(path("whole.ply")), slurp(path("auto.ply")));
  for (const char* bad : {"0", "2x2", "x", "-1x1x1", "autox", "2x2x2x2", "99999"}) {
    Result r = run(base + " -o " + quote(path("bad.ply")) + " --subdomains " + bad);
    EXPECT_EQ(r.exit_code, 2) << bad;
    EXPECT_TRUE(contains(r.err, "--subdomains")) << r.err;
  }
  EXPECT_FALSE(fs::exists(path("bad.ply")));
}

// --method sph with splashsurf's parameters: the same mesh as the C API,
// the method and threshold in the report and the JSON, a split gives the
// same file, and a threshold out of (0, 1) is the library's error (exit 1).
TEST_F(CliTest, SphMethodLikeSplashsurf) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) +
                           " --particle-radius 0.025 --method sph --influence-radius 2 --cell-size 0.75"
                           " --iso-threshold 0.55 --progress never";
  Result r = run(base + " -o " + quote(path("sph.ply")) + " --json " + quote(path("sph.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "sph (iso threshold 0.55)")) << r.out;
  const std::string json = slurp(path("sph.json"));
  EXPECT_TRUE(contains(json, "\"method\": \"sph\"")) << json;
  EXPECT_TRUE(contains(json, "\"iso_threshold\": 0.55")) << json;
  const auto mesh = nbmc::io::read_mesh_ply(path("sph.ply"));
  const auto particles = nbmc::io::read_particles(frame);
  nbmc_params p = nbmc_test::params(0.05);
  p.method = NBMC_METHOD_SPH;
  p.influence_radius = 2;
  p.cell_size = 0.75;
  p.iso_threshold = 0.55;
  const nbmc_test::Result direct = nbmc_test::reconstruct(particles.xyz, p, NBMC_BACKEND_AUTO);
  ASSERT_EQ(direct.status, NBMC_OK) << direct.message;
  EXPECT_GT(mesh.triangle_count(), 0u);
  EXPECT_EQ(mesh.triangle_count(), direct.mesh.triangle_count());
  EXPECT_EQ(mesh.vertex_count(), direct.mesh.vertex_count());
  Result split = run(base + " -o " + quote(path("split.ply")) + " --subdomains 2x2x1");
  ASSERT_EQ(split.exit_code, 0) << split.err;
  EXPECT_EQ(slurp(path("sph.ply")), slurp(path("split.ply")));
  for (const char* bad : {"0", "1", "-0.2", "nan"}) {
    Result b = run("reconstruct " + quote(frame) + " -o " + quote(path("bad.ply")) +
                   " --particle-radius 0.025 --method sph --iso-threshold " + bad);
    EXPECT_NE(b.exit_code, 0) << bad;
    EXPECT_TRUE(contains(b.err, "iso_threshold") || contains(b.err, "--iso-threshold")) << bad << ": " << b.err;
  }
  EXPECT_FALSE(fs::exists(path("bad.ply")));
}

// --method yt10 with its options: the same mesh as the C API, the method and
// settings in the report and the JSON, a split gives the same file, and
// values out of range are the library's errors (exit 1).
TEST_F(CliTest, Yt10MethodAndOptions) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) +
                           " --particle-radius 0.025 --method yt10 --cell-size 0.75 --aniso-kr 3"
                           " --aniso-ks 0.9 --aniso-kn 0.6 --aniso-neighbours 20 --aniso-lambda 0.5"
                           " --iso-threshold 0.5 --progress never";
  Result r = run(base + " -o " + quote(path("yt10.ply")) + " --json " + quote(path("yt10.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "yt10 (iso threshold 0.5, k_r 3, k_s 0.9, k_n 0.6, N_eps 20, lambda 0.5)")) << r.out;
  const std::string json = slurp(path("yt10.json"));
  EXPECT_TRUE(contains(json, "\"method\": \"yt10\"")) << json;
  EXPECT_TRUE(contains(json, "\"aniso_kr\": 3")) << json;
  EXPECT_TRUE(contains(json, "\"aniso_ks\": 0.9")) << json;
  EXPECT_TRUE(contains(json, "\"aniso_kn\": 0.6")) << json;
  EXPECT_TRUE(contains(json, "\"aniso_lambda\": 0.5")) << json;
  EXPECT_TRUE(contains(json, "\"aniso_neighbours\": 20")) << json;
  const auto mesh = nbmc::io::read_mesh_ply(path("yt10.ply"));
  const auto particles = nbmc::io::read_particles(frame);
  nbmc_params p = nbmc_test::params(0.05);
  p.method = NBMC_METHOD_YT10;
  p.cell_size = 0.75;
  p.aniso_kr = 3;
  p.aniso_ks = 0.9;
  p.aniso_kn = 0.6;
  p.aniso_neighbours = 20;
  p.aniso_lambda = 0.5;
  p.iso_threshold = 0.5;
  const nbmc_test::Result direct = nbmc_test::reconstruct(particles.xyz, p, NBMC_BACKEND_AUTO);
  ASSERT_EQ(direct.status, NBMC_OK) << direct.message;
  EXPECT_GT(mesh.triangle_count(), 0u);
  EXPECT_EQ(mesh.triangle_count(), direct.mesh.triangle_count());
  EXPECT_EQ(mesh.vertex_count(), direct.mesh.vertex_count());
  Result split = run(base + " -o " + quote(path("split.ply")) + " --subdomains 2x1x2");
  ASSERT_EQ(split.exit_code, 0) << split.err;
  EXPECT_EQ(slurp(path("yt10.ply")), slurp(path("split.ply")));
  const std::pair<const char*, const char*> bad[] = {{"--aniso-kr", "0.5"},      {"--aniso-ks", "0"},
                                                     {"--aniso-kn", "2"},        {"--aniso-lambda", "1.5"},
                                                     {"--aniso-neighbours", "-3"}};
  for (const auto& [option, value] : bad) {
    Result b = run("reconstruct " + quote(frame) + " -o " + quote(path("bad.ply")) +
                   " --particle-radius 0.025 --method yt10 " + option + " " + value);
    EXPECT_EQ(b.exit_code, 1) << option << " " << value << ": " << b.err;
    EXPECT_TRUE(contains(b.err, std::string(option + 2).replace(5, 1, "_"))) << option << ": " << b.err;
  }
  EXPECT_FALSE(fs::exists(path("bad.ply")));
}

// --isolated drop: the report says what was dropped, the JSON counts it, and
// the counts are the C API's; bad values are usage errors (exit 2) or the
// library's (exit 1).
TEST_F(CliTest, IsolatedDrop) {
  const std::string frame = std::string(NBMC_SOURCE_DIR) + "/examples/data/double_dam_break_4732.xyz";
  const std::string base = "reconstruct " + quote(frame) + " --particle-radius 0.025 --progress never";
  Result r = run(base + " -o " + quote(path("drop.ply")) + " --isolated drop --min-cluster 20 --json " +
                 quote(path("drop.json")));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto particles = nbmc::io::read_particles(frame);
  nbmc_params p = nbmc_test::params(0.05);
  p.isolated = NBMC_ISOLATED_DROP;
  p.min_cluster = 20;
  const nbmc_test::Result direct = nbmc_test::reconstruct(particles.xyz, p, NBMC_BACKEND_AUTO);
  ASSERT_EQ(direct.status, NBMC_OK) << direct.message;
  EXPECT_GT(direct.stats.dropped_particle_count, 0u) << "the frame has splashes of fewer than 20 particles";
  EXPECT_TRUE(contains(r.out, "dropped " + std::to_string(direct.stats.dropped_particle_count) + " particles in " +
                                  std::to_string(direct.stats.dropped_cluster_count) + " clusters"))
      << r.out;
  const std::string json = slurp(path("drop.json"));
  EXPECT_EQ(json_uint(json, "dropped_particle_count"), static_cast<long long>(direct.stats.dropped_particle_count));
  EXPECT_EQ(json_uint(json, "dropped_cluster_count"), static_cast<long long>(direct.stats.dropped_cluster_count));
  EXPECT_TRUE(contains(json, "\"isolated\": \"drop\"")) << json;
  EXPECT_EQ(nbmc::io::read_mesh_ply(path("drop.ply")).triangle_count(), direct.mesh.triangle_count());
  EXPECT_EQ(run(base + " -o " + quote(path("bad.ply")) + " --isolated sometimes").exit_code, 2);
  Result bad = run(base + " -o " + quote(path("bad.ply")) + " --isolated drop --min-cluster 0");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_TRUE(contains(bad.err, "min_cluster")) << bad.err;
}
