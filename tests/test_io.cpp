// SPDX-License-Identifier: MIT
// nbmc::io: particle readers (raw xyz, PLY points) and mesh writers/readers.
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "io_expect.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using nbmc::io::Error;

namespace {

// A fresh folder per test, removed afterwards.
class IoTest : public ::testing::Test {
protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("nbmc_test_io_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  std::string write(const std::string& name, const std::string& bytes) const {
    const std::string p = path(name);
    std::ofstream f(p, std::ios::binary);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return p;
  }
  std::vector<std::string> files() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(dir_)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }
  fs::path dir_;
};

using nbmc_test::expect_error;

// Binary encoders.
template <class T> void put(std::string& out, T v, bool big_endian = false) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof v);
  if (big_endian) std::reverse(b, b + sizeof v);
  out.append(b, sizeof v);
}

std::string xyz_bytes(const std::vector<float>& v) {
  std::string out;
  for (float f : v) put(out, f);
  return out;
}

const std::vector<double> kPoints = {0.5, -1.25, 3.0, 1e-3, 2.0, -0.0, 100.125, 7.5, -8.0};

} // namespace

// ------------------------------------------------------------------ raw xyz
TEST_F(IoTest, XyzReadsFloatTriples) {
  const std::vector<float> v = {0.5f, -1.25f, 3.0f, 1e-3f, 2.0f, 0.0f, 1.0e6f, -7.5f, 0.1f};
  const auto p = nbmc::io::read_particles(write("a.xyz", xyz_bytes(v)));
  ASSERT_EQ(p.count(), 3u);
  for (std::size_t i = 0; i < v.size(); ++i) EXPECT_EQ(p.xyz[i], static_cast<double>(v[i]));
}

TEST_F(IoTest, XyzNaNIsNotRejected) {
  const auto p = nbmc::io::read_particles(
      write("nan.xyz", xyz_bytes({std::numeric_limits<float>::quiet_NaN(), 1.0f, 2.0f})));
  ASSERT_EQ(p.count(), 1u);
  EXPECT_TRUE(std::isnan(p.xyz[0]));
}

TEST_F(IoTest, XyzEmptyFileHasNoParticles) {
  EXPECT_EQ(nbmc::io::read_particles(write("empty.xyz", "")).count(), 0u);
}

TEST_F(IoTest, XyzSizeNotMultipleOf12) {
  const std::string p = write("odd_size.xyz", xyz_bytes({1, 2, 3}) + "x");
  expect_error([&] { nbmc::io::read_particles(p); }, {"odd_size.xyz", "13", "multiple of 12"});
}

TEST_F(IoTest, FormatOverrideAndCaseInsensitiveExtension) {
  const std::string bytes = xyz_bytes({1, 2, 3, 4, 5, 6});
  EXPECT_EQ(nbmc::io::read_particles(write("frame.bin", bytes), "xyz").count(), 2u);
  EXPECT_EQ(nbmc::io::read_particles(write("frame.XYZ", bytes)).count(), 2u);
  EXPECT_EQ(nbmc::io::read_particles(write("frame.dat", bytes), "XYZ").count(), 2u);
}

TEST_F(IoTest, UnknownExtension) {
  const std::string p = write("particles.foo", xyz_bytes({1, 2, 3}));
  expect_error([&] { nbmc::io::read_particles(p); }, {"particles.foo", "unknown extension '.foo'", "use --format"});
  expect_error([&] { nbmc::io::read_particles(write("noext", "")); }, {"noext", "extension"});
  expect_error([&] { nbmc::io::read_particles(p, "stl"); }, {"particles.foo", "unknown format 'stl'"});
}

TEST_F(IoTest, NonexistentFile) {
  const std::string p = path("does_not_exist.xyz");
  expect_error([&] { nbmc::io::read_particles(p); }, {"does_not_exist.xyz", "No such file"});
  const std::string d = path("folder.ply");
  fs::create_directories(d);
  expect_error([&] { nbmc::io::read_particles(d); }, {"folder.ply", "directory"});
}

// ---------------------------------------------------------------- PLY points
TEST_F(IoTest, PlyAsciiWithExtraPropertiesAndOtherElements) {
  std::string s = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info nothing\r\n"
                  "element vertex 3\r\n"
                  "property uchar red\r\nproperty double x\r\nproperty int id\r\nproperty float y\r\n"
                  "property float32 z\r\nproperty short s\r\n"
                  "element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n";
  s += "255 0.5 -7 -1.25 3 12\n";
  s += "0 +1e-3 2 2.0 -0.0 -5\r\n";
  s += "  1   100.125\t3 7.5 -8   0\n";
  s += "3 0 1 2\n";
  const auto p = nbmc::io::read_particles(write("ascii.ply", s));
  ASSERT_EQ(p.count(), 3u);
  for (std::size_t i = 0; i < kPoints.size(); ++i) EXPECT_EQ(p.xyz[i], kPoints[i]) << i;
}

TEST_F(IoTest, PlyAsciiNanAndInf) {
  const std::string s = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                        "property float z\nend_header\nnan inf -inf\n";
  const auto p = nbmc::io::read_particles(write("nan.ply", s));
  ASSERT_EQ(p.count(), 1u);
  EXPECT_TRUE(std::isnan(p.xyz[0]));
  EXPECT_TRUE(std::isinf(p.xyz[1]));
  EXPECT_TRUE(std::isinf(p.xyz[2]) && p.xyz[2] < 0);
}

namespace {
// Binary PLY points with x, y, z of type T between properties of every other
// scalar type; optionally an element with a list before the vertices and a
// face element after them.
template <class T>
std::string binary_ply(bool big_endian, const char* type_name, bool element_before, std::uint64_t header_count = 3) {
  std::string s = "ply\nformat ";
  s += big_endian ? "binary_big_endian" : "binary_little_endian";
  s += " 1.0\n";
  if (element_before) s += "element camera 2\nproperty list uchar float params\nproperty int id\n";
  s += "element vertex " + std::to_string(header_count) + "\n";
  s += "property char a\nproperty uchar b\n";
  s += std::string("property ") + type_name + " x\n";
  s += "property short c\nproperty ushort d\n";
  s += std::string("property ") + type_name + " y\n";
  s += "property int e\nproperty uint f\nproperty float g\nproperty double h\n";
  s += std::string("property ") + type_name + " z\n";
  s += "element face 1\nproperty list uchar uint vertex_indices\nend_header\n";
  const bool be = big_endian;
  if (element_before) {
    put<std::uint8_t>(s, 2);
    put<float>(s, 1.f, be);
    put<float>(s, 2.f, be);
    put<std::int32_t>(s, 7, be);
    put<std::uint8_t>(s, 0);
    put<std::int32_t>(s, 8, be);
  }
  for (int i = 0; i < 3; ++i) {
    put<std::int8_t>(s, -1);
    put<std::uint8_t>(s, 200);
    put<T>(s, static_cast<T>(kPoints[3 * i + 0]), be);
    put<std::int16_t>(s, -300, be);
    put<std::uint16_t>(s, 60000, be);
    put<T>(s, static_cast<T>(kPoints[3 * i + 1]), be);
    put<std::int32_t>(s, -70000, be);
    put<std::uint32_t>(s, 4000000000u, be);
    put<float>(s, 1.5f, be);
    put<double>(s, 2.5, be);
    put<T>(s, static_cast<T>(kPoints[3 * i + 2]), be);
  }
  put<std::uint8_t>(s, 3);
  for (std::uint32_t k = 0; k < 3; ++k) put<std::uint32_t>(s, k, be);
  return s;
}
} // namespace

TEST_F(IoTest, PlyBinaryAllEncodingsAndTypes) {
  struct Case {
    const char* name;
    std::string bytes;
    bool is_float;
  };
  const Case cases[] = {
      {"le_float.ply", binary_ply<float>(false, "float", false), true},
      {"le_float32.ply", binary_ply<float>(false, "float32", true), true},
      {"le_double.ply", binary_ply<double>(false, "double", false), false},
      {"be_float.ply", binary_ply<float>(true, "float", true), true},
      {"be_double.ply", binary_ply<double>(true, "float64", false), false},
      {"be_double_before.ply", binary_ply<double>(true, "double", true), false},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const auto p = nbmc::io::read_particles(write(c.name, c.bytes));
    ASSERT_EQ(p.count(), 3u);
    for (std::size_t i = 0; i < kPoints.size(); ++i) {
      const double want = c.is_float ? static_cast<double>(static_cast<float>(kPoints[i])) : kPoints[i];
      EXPECT_EQ(p.xyz[i], want) << i;
    }
  }
}

TEST_F(IoTest, PlyAsciiElementBeforeVertices) {
  const std::string s = "ply\nformat ascii 1.0\nelement camera 2\nproperty list uchar float params\n"
                        "property int id\nelement vertex 2\nproperty float x\nproperty float y\n"
                        "property float z\nend_header\n3 1 2 3 7\n0 8\n1 2 3\n4 5 6\n";
  const auto p = nbmc::io::read_particles(write("before.ply", s));
  ASSERT_EQ(p.count(), 2u);
  EXPECT_EQ(p.xyz, (std::vector<double>{1, 2, 3, 4, 5, 6}));
}

TEST_F(IoTest, PlyZeroVertices) {
  const std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\n"
                        "property float y\nproperty float z\nend_header\n";
  EXPECT_EQ(nbmc::io::read_particles(write("zero.ply", s)).count(), 0u);
}

TEST_F(IoTest, PlyTruncatedBinaryBody) {
  std::string s = binary_ply<float>(false, "float", false, 10); // says 10, holds 3 (+ the face bytes)
  expect_error([&] { nbmc::io::read_particles(write("trunc.ply", s)); },
               {"trunc.ply", "header says 10 vertices but the file ends after 3"});
  // Cut inside the third record.
  s = binary_ply<double>(false, "double", false);
  s.resize(s.size() - 13 - 20);
  expect_error([&] { nbmc::io::read_particles(write("cut.ply", s)); },
               {"cut.ply", "header says 3 vertices but the file ends after 2"});
}

TEST_F(IoTest, PlyHeaderCountLargerThanFile) {
  std::string s = "ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
                  "property float y\nproperty float z\nend_header\n";
  for (int i = 0; i < 30; ++i) put<float>(s, 1.0f);
  expect_error([&] { nbmc::io::read_particles(write("particles.ply", s)); },
               {"particles.ply", "header says 1000 vertices but the file ends after 10"});

  // Counts that would overflow or exhaust memory if trusted.
  for (const char* count : {"18446744073709551615", "6148914691236517206", "4611686018427387904"}) {
    std::string h = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::string(count) +
                    "\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
    expect_error([&] { nbmc::io::read_particles(write("huge.ply", h + std::string(48, '\0'))); },
                 {"huge.ply", "header says " + std::string(count) + " vertices but the file ends after 2"});
    std::string a = "ply\nformat ascii 1.0\nelement vertex " + std::string(count) +
                    "\nproperty double x\nproperty double y\nproperty double z\nend_header\n1 2 3\n";
    expect_error([&] { nbmc::io::read_particles(write("huge_ascii.ply", a)); },
                 {"huge_ascii.ply", "ends after 1"});
    std::string before = "ply\nformat binary_little_endian 1.0\nelement junk " + std::string(count) +
                         "\nproperty list uint double v\nelement vertex 1\nproperty float x\nproperty float y\n"
                         "property float z\nend_header\n";
    put<std::uint32_t>(before, 0xffffffffu);
    expect_error([&] { nbmc::io::read_particles(write("huge_before.ply", before)); },
                 {"huge_before.ply", "junk"});
  }
  // Too large for uint64.
  expect_error(
      [&] {
        nbmc::io::read_particles(write("toolarge.ply", "ply\nformat ascii 1.0\nelement vertex 99999999999999999999\n"
                                                       "property float x\nend_header\n"));
      },
      {"toolarge.ply", "element"});
}

TEST_F(IoTest, PlyAsciiTruncatedAndBadNumbers) {
  const std::string h = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                        "property float z\nend_header\n";
  expect_error([&] { nbmc::io::read_particles(write("short.ply", h + "1 2 3\n4 5")); },
               {"short.ply", "header says 3 vertices but the file ends after 1"});
  expect_error([&] { nbmc::io::read_particles(write("word.ply", h + "1 2 3\n4 five 6\n7 8 9\n")); },
               {"word.ply", "'five' is not a number"});
  expect_error([&] { nbmc::io::read_particles(write("long.ply", h + std::string(1000, '1'))); },
               {"long.ply", "too long"});
}

TEST_F(IoTest, PlyMissingProperty) {
  const std::string s = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\n"
                        "end_header\n1 2\n";
  expect_error([&] { nbmc::io::read_particles(write("nox.ply", s)); }, {"nox.ply", "no 'x' property"});
  const std::string nov = "ply\nformat ascii 1.0\nelement point 1\nproperty float x\nend_header\n1\n";
  expect_error([&] { nbmc::io::read_particles(write("novertex.ply", nov)); }, {"novertex.ply", "'vertex'"});
}

TEST_F(IoTest, PlyListPropertyInVertex) {
  const std::string s = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                        "property float z\nproperty list uchar int tags\nend_header\n1 2 3 2 5 6\n";
  expect_error([&] { nbmc::io::read_particles(write("list.ply", s)); }, {"list.ply", "'tags' is a list"});
}

TEST_F(IoTest, PlyIntegerCoordinate) {
  const std::string s = "ply\nformat ascii 1.0\nelement vertex 1\nproperty int x\nproperty float y\n"
                        "property float z\nend_header\n1 2 3\n";
  expect_error([&] { nbmc::io::read_particles(write("intx.ply", s)); }, {"intx.ply", "'x' has type int"});
}

TEST_F(IoTest, PlyGarbageHeaders) {
  struct Case {
    std::string bytes;
    const char* needle;
  };
  std::string random(300, '\0');
  std::mt19937 rng(42);
  for (char& c : random) c = static_cast<char>(rng());
  const std::string ok_tail = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  const Case cases[] = {
      {random, "not a PLY file"},
      {"", "not a PLY file"},
      {"plyx\n", "not a PLY file"},
      {"PLY\n", "not a PLY file"},
      {"ply\nformat ascii 1.0\n" + ok_tail, "end_header"},
      {"ply\nformat ascii 1.0\n" + ok_tail + std::string(2 << 20, 'c'), "1 MiB"},
      {"ply\nformat ascii 2.0\n" + ok_tail + "end_header\n", "version"},
      {"ply\nformat binary_middle_endian 1.0\n" + ok_tail + "end_header\n", "unknown PLY format"},
      {"ply\n" + ok_tail + "end_header\n", "no 'format'"},
      {"ply\nformat ascii 1.0\nformat ascii 1.0\n" + ok_tail + "end_header\n", "two 'format'"},
      {"ply\nformat ascii 1.0\nproperty float x\n" + ok_tail + "end_header\n", "before any element"},
      {"ply\nformat ascii 1.0\n" + ok_tail + "property quad w\nend_header\n", "unknown PLY property type 'quad'"},
      {"ply\nformat ascii 1.0\n" + ok_tail + "property float x\nend_header\n", "two properties called 'x'"},
      {"ply\nformat ascii 1.0\nelement vertex\n" + ok_tail + "end_header\n", "malformed PLY element"},
      {"ply\nformat ascii 1.0\nelement vertex -1\n" + ok_tail + "end_header\n", "malformed PLY element"},
      {"ply\nformat ascii 1.0\n" + ok_tail + "property list float int n\nend_header\n", "floating-point count"},
      {"ply\nformat ascii 1.0\n" + ok_tail + "hello world\nend_header\n", "unexpected PLY header line 'hello world'"},
      {"ply\nformat ascii 1.0\n" + ok_tail + "\x01\x02\xff\nend_header\n", "unexpected PLY header line '?\?\?'"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string name = "garbage" + std::to_string(i++) + ".ply";
    SCOPED_TRACE(name);
    expect_error([&] { nbmc::io::read_particles(write(name, c.bytes)); }, {name, c.needle});
  }
}

// Every prefix and many corruptions of valid files either parse or throw
// io::Error: never crash, hang or over-allocate (run under ASan for the full
// effect).
TEST_F(IoTest, PlyReaderSurvivesTruncationAndCorruption) {
  const std::string samples[] = {
      binary_ply<float>(false, "float", true),
      binary_ply<double>(true, "double", true),
      "ply\nformat ascii 1.0\nelement camera 1\nproperty list uchar float p\nelement vertex 2\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n2 1 2\n1 2 3\n4 5 6\n",
  };
  std::mt19937 rng(7);
  for (const std::string& sample : samples) {
    for (std::size_t n = 0; n <= sample.size(); ++n) {
      try {
        nbmc::io::parse_particles(sample.data(), n, "ply", "mem.ply");
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("mem.ply"), std::string::npos);
      }
    }
    for (int trial = 0; trial < 2000; ++trial) {
      std::string s = sample;
      const int flips = 1 + static_cast<int>(rng() % 4);
      for (int k = 0; k < flips; ++k) s[rng() % s.size()] = static_cast<char>(rng());
      try {
        const auto p = nbmc::io::parse_particles(s.data(), s.size(), "ply", "mem.ply");
        EXPECT_LE(p.count() * 12, s.size());
      } catch (const Error&) {
      }
    }
  }
  // Memory reader with the other format and a null block.
  EXPECT_EQ(nbmc::io::parse_particles(nullptr, 0, "xyz").count(), 0u);
  const std::string x = xyz_bytes({1, 2, 3});
  EXPECT_EQ(nbmc::io::parse_particles(x.data(), x.size(), "", "mem.xyz").count(), 1u);
}

// ------------------------------------------------------------------- meshes
namespace {
// A tetrahedron with normals.
nbmc::io::Mesh tetrahedron(bool normals) {
  nbmc::io::Mesh m;
  m.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1.0f / 3.0f};
  if (normals) m.normals = {-0.57735f, -0.57735f, -0.57735f, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  m.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  return m;
}

std::vector<std::string> lines_of(const std::string& path) {
  std::ifstream f(path);
  std::vector<std::string> out;
  for (std::string line; std::getline(f, line);) out.push_back(line);
  return out;
}
} // namespace

TEST_F(IoTest, MeshPlyRoundTrip) {
  for (bool normals : {true, false}) {
    SCOPED_TRACE(normals ? "with normals" : "without normals");
    const auto m = tetrahedron(normals);
    const std::string p = path(normals ? "n.ply" : "plain.PLY");
    nbmc::io::write_mesh(p, m.view());
    const auto r = nbmc::io::read_mesh_ply(p);
    EXPECT_EQ(r.positions, m.positions);
    EXPECT_EQ(r.normals, m.normals);
    EXPECT_EQ(r.triangles, m.triangles);
    // The header is what the brief promises.
    const auto lines = lines_of(p);
    ASSERT_GT(lines.size(), 3u);
    EXPECT_EQ(lines[0], "ply");
    EXPECT_EQ(lines[1], "format binary_little_endian 1.0");
    std::ifstream f(p, std::ios::binary);
    const std::string all((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    EXPECT_NE(all.find("property list uchar uint vertex_indices\nend_header\n"), std::string::npos);
    EXPECT_EQ(all.find("property float nx") != std::string::npos, normals);
    const std::size_t body = all.find("end_header\n") + 11;
    EXPECT_EQ(all.size() - body, 4 * (normals ? 24 : 12) + 4 * 13u);
  }
}

TEST_F(IoTest, MeshObj) {
  const auto m = tetrahedron(true);
  const std::string p = path("mesh.obj");
  nbmc::io::write_mesh(p, m.view());
  std::vector<float> v, vn;
  std::vector<std::uint32_t> f;
  for (const std::string& line : lines_of(p)) {
    std::istringstream s(line);
    std::string tag;
    s >> tag;
    if (tag == "v" || tag == "vn") {
      float a, b, c;
      ASSERT_TRUE(static_cast<bool>(s >> a >> b >> c)) << line;
      for (float x : {a, b, c}) (tag == "v" ? v : vn).push_back(x);
    } else if (tag == "f") {
      for (int k = 0; k < 3; ++k) {
        std::string t;
        ASSERT_TRUE(static_cast<bool>(s >> t)) << line;
        const std::size_t slash = t.find("//");
        ASSERT_NE(slash, std::string::npos) << line;
        EXPECT_EQ(t.substr(0, slash), t.substr(slash + 2)) << line;
        f.push_back(static_cast<std::uint32_t>(std::stoul(t.substr(0, slash)) - 1));
      }
    } else {
      EXPECT_EQ(tag, "#") << line;
    }
  }
  EXPECT_EQ(v, m.positions); // shortest round-trip formatting is exact
  EXPECT_EQ(vn, m.normals);
  EXPECT_EQ(f, m.triangles);

  // Without normals: "f a b c".
  const std::string q = path("plain.obj");
  nbmc::io::write_mesh(q, tetrahedron(false).view());
  int faces = 0;
  for (const std::string& line : lines_of(q)) {
    EXPECT_NE(line.rfind("vn", 0), 0u);
    if (line.rfind("f ", 0) == 0) {
      EXPECT_EQ(line.find('/'), std::string::npos);
      ++faces;
    }
  }
  EXPECT_EQ(faces, 4);
  EXPECT_EQ(lines_of(q)[5], "f 1 3 2");
}

TEST_F(IoTest, MeshEmpty) {
  nbmc::io::MeshView empty;
  nbmc::io::write_mesh(path("empty.ply"), empty);
  nbmc::io::write_mesh(path("empty.obj"), empty);
  const auto r = nbmc::io::read_mesh_ply(path("empty.ply"));
  EXPECT_EQ(r.vertex_count(), 0u);
  EXPECT_EQ(r.triangle_count(), 0u);
}

TEST_F(IoTest, MeshWriteErrorsLeaveNothingBehind) {
  auto m = tetrahedron(false);
  const std::string p = write("keep.ply", "old content");
  m.triangles[5] = 9;
  expect_error([&] { nbmc::io::write_mesh(p, m.view()); }, {"keep.ply", "refers to vertex 9"});
  m = tetrahedron(false);
  expect_error([&] { nbmc::io::write_mesh(path("mesh.stl"), m.view()); }, {"mesh.stl", "'.stl'"});
  expect_error([&] { nbmc::io::write_mesh(path("no/such/dir/mesh.ply"), m.view()); },
               {"mesh.ply", "No such file"});
  // Cancelled: the old file stays as it was, no temporary file remains.
  bool asked = false;
  EXPECT_THROW(nbmc::io::write_mesh(p, m.view(), "", [&] { return asked = true; }), nbmc::io::Cancelled);
  EXPECT_TRUE(asked);
  EXPECT_EQ(lines_of(p), std::vector<std::string>{"old content"});
  EXPECT_EQ(files(), std::vector<std::string>{"keep.ply"});
  // A successful write replaces it and also leaves no temporary file.
  nbmc::io::write_mesh(p, m.view(), "", [] { return false; });
  EXPECT_EQ(nbmc::io::read_mesh_ply(p).triangle_count(), 4u);
  EXPECT_EQ(files(), std::vector<std::string>{"keep.ply"});
  // Format override.
  nbmc::io::write_mesh(path("mesh.txt"), m.view(), "obj");
  EXPECT_EQ(lines_of(path("mesh.txt")).size(), 1u + 4 + 4);
}

TEST_F(IoTest, MeshPlyReaderAsciiAndErrors) {
  const std::string head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\nproperty uchar red\nelement face 1\n"
                           "property list uchar int vertex_index\nend_header\n"
                           "0 0 0 1\n1 0 0 2\n0 1 0 3\n";
  const auto r = nbmc::io::read_mesh_ply(write("ascii_mesh.ply", head + "3 0 1 2\n"));
  EXPECT_EQ(r.vertex_count(), 3u);
  EXPECT_EQ(r.triangles, (std::vector<std::uint32_t>{0, 1, 2}));
  EXPECT_TRUE(r.normals.empty());
  expect_error([&] { nbmc::io::read_mesh_ply(write("quad.ply", head + "4 0 1 2 2\n")); },
               {"quad.ply", "only triangles"});
  expect_error([&] { nbmc::io::read_mesh_ply(write("badidx.ply", head + "3 0 1 5\n")); },
               {"badidx.ply", "refers to vertex 5"});
  expect_error([&] { nbmc::io::read_mesh_ply(write("negidx.ply", head + "3 0 -1 2\n")); },
               {"negidx.ply", "vertex index"});
  expect_error([&] { nbmc::io::read_mesh_ply(write("noface.ply", head)); },
               {"noface.ply", "header says 1 face elements but the file ends after 0"});
  // Binary mesh truncated anywhere: an error naming the file, never a crash.
  const std::string p = path("whole.ply");
  nbmc::io::write_mesh(p, tetrahedron(true).view());
  std::ifstream f(p, std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  for (std::size_t n = 0; n < all.size(); ++n)
    expect_error([&] { nbmc::io::parse_mesh_ply(all.data(), n, "cut_mesh.ply"); }, {"cut_mesh.ply"});
}

// ------------------------------------------------------------ real frames
TEST(IoRealFrames, XyzFramesHaveTheDocumentedCounts) {
  const fs::path dir = fs::path(NBMC_DATA_DIR) / "xyz";
  if (!fs::is_directory(dir)) GTEST_SKIP() << dir << " not found";
  struct Frame {
    const char* file;
    std::size_t count;
    double lo[3], hi[3]; // bounding box from data/README.md (2 decimals)
  };
  const Frame frames[] = {
      {"splashsurf_doubledambreak_f26_4732.xyz", 4732, {-1.52, -0.02, -1.52}, {1.52, 1.02, 1.52}},
      {"splashsurf_bunny_f14_7706.xyz", 7706, {-0.61, 0.67, -0.98}, {0.72, 2.03, 0.68}},
      {"splashsurf_dambreak_f23_24389.xyz", 24389, {-1.51, 0.03, -0.76}, {1.52, 3.97, 0.77}},
      {"cbd46k_t050_46250.xyz", 46250, {-0.79, 0.01, -0.39}, {0.79, 1.08, 0.39}},
      {"cbd292k_t040_292008.xyz", 292008, {-0.79, 0.01, -0.39}, {0.63, 0.75, 0.39}},
      {"cbd950k_t040_950232.xyz", 950232, {-0.80, 0.00, -0.40}, {0.79, 0.75, 0.40}},
      {"cbd1654k_t040_1654104.xyz", 1654104, {-0.80, 0.00, -0.40}, {0.79, 1.17, 0.40}},
  };
  for (const Frame& fr : frames) {
    SCOPED_TRACE(fr.file);
    const fs::path p = dir / fr.file;
    if (!fs::exists(p)) continue;
    const auto parts = nbmc::io::read_particles(p.string());
    ASSERT_EQ(parts.count(), fr.count);
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < parts.count(); ++i)
      for (int a = 0; a < 3; ++a) {
        const double v = parts.xyz[3 * i + a];
        ASSERT_TRUE(std::isfinite(v));
        lo[a] = std::min(lo[a], v);
        hi[a] = std::max(hi[a], v);
      }
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(lo[a], fr.lo[a], 0.011) << "axis " << a;
      EXPECT_NEAR(hi[a], fr.hi[a], 0.011) << "axis " << a;
    }
  }
}
