// SPDX-License-Identifier: MIT
// Every mesh writer against a reader: PLY, legacy VTK and VTU against nbmc's
// own readers (positions, normals, triangles, attributes), glTF .glb and OBJ
// against small parsers here that check the layout the specifications ask for.
#include "io/mesh.hpp"
#include "io/particles.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace fs = std::filesystem;
using nbmc::io::Attribute;
using nbmc::io::Error;

namespace {

class RoundTrip : public ::testing::Test {
protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("nbmc_test_io_rt_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // An octahedron with outward normals and two attributes.
    const float v[] = {1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1};
    pos_.assign(v, v + 18);
    for (int i = 0; i < 18; ++i) pos_[i] = pos_[i] * 0.5f + 0.25f * static_cast<float>(i % 3);
    nrm_.assign(v, v + 18);
    const std::uint32_t t[] = {0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5};
    tri_.assign(t, t + 24);
    Attribute rho;
    rho.name = "rho";
    rho.components = 1;
    Attribute vel;
    vel.name = "vel";
    vel.components = 3;
    for (int i = 0; i < 6; ++i) {
      rho.values.push_back(1000.5 + i);
      vel.values.insert(vel.values.end(), {0.25 * i, -1.5 * i, 3.0});
    }
    attrs_ = {rho, vel};
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  nbmc::io::MeshView view(bool normals = true, bool attributes = true) const {
    nbmc::io::MeshView m;
    m.positions = pos_.data();
    m.normals = normals ? nrm_.data() : nullptr;
    m.triangles = tri_.data();
    m.vertex_count = 6;
    m.triangle_count = 8;
    if (attributes) {
      m.attributes = attrs_.data();
      m.attribute_count = attrs_.size();
    }
    return m;
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string slurp(const std::string& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  }
  void expect_mesh(const nbmc::io::Mesh& m, bool normals, bool attributes) const {
    ASSERT_EQ(m.positions, pos_);
    ASSERT_EQ(m.triangles, tri_);
    if (normals)
      EXPECT_EQ(m.normals, nrm_);
    else
      EXPECT_TRUE(m.normals.empty());
    if (!attributes) return;
    for (const Attribute& want : attrs_) {
      const Attribute* got = nbmc::io::find_attribute(m.attributes, want.name);
      ASSERT_NE(got, nullptr) << want.name << "; have " << nbmc::io::attribute_names(m.attributes);
      EXPECT_EQ(got->components, want.components);
      ASSERT_EQ(got->values.size(), want.values.size());
      for (std::size_t i = 0; i < want.values.size(); ++i)
        EXPECT_EQ(got->values[i], static_cast<double>(static_cast<float>(want.values[i]))) << want.name << i;
    }
  }

  fs::path dir_;
  std::vector<float> pos_, nrm_;
  std::vector<std::uint32_t> tri_;
  std::vector<Attribute> attrs_;
};

std::uint32_t u32(const std::string& s, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}

// Numbers after "key": in the order they appear.
std::vector<double> numbers_after(const std::string& json, const std::string& key) {
  std::vector<double> out;
  const std::regex re("\"" + key + "\":(-?[0-9.eE+-]+)");
  for (auto it = std::sregex_iterator(json.begin(), json.end(), re); it != std::sregex_iterator(); ++it)
    out.push_back(std::stod((*it)[1].str()));
  return out;
}

} // namespace

TEST_F(RoundTrip, Ply) {
  for (bool normals : {true, false}) {
    const std::string p = path(normals ? "n.ply" : "p.ply");
    nbmc::io::write_mesh(p, view(normals));
    expect_mesh(nbmc::io::read_mesh_ply(p), normals, false);
    expect_mesh(nbmc::io::read_mesh(p), normals, false);
    // Attributes are extra vertex properties: the particle reader sees them
    // (vel_x, vel_y, vel_z merged into vel).
    const nbmc::io::Particles pts = nbmc::io::read_particles(p);
    ASSERT_EQ(pts.count(), 6u);
    nbmc::io::Mesh as_mesh;
    as_mesh.positions = pos_;
    as_mesh.triangles = tri_;
    as_mesh.attributes = pts.attributes;
    if (normals) as_mesh.normals = nrm_;
    expect_mesh(as_mesh, normals, true);
    if (normals) ASSERT_NE(pts.attribute("n"), nullptr);
  }
}

TEST_F(RoundTrip, LegacyVtk) {
  for (bool normals : {true, false}) {
    const std::string p = path(normals ? "n.vtk" : "p.vtk");
    nbmc::io::write_mesh(p, view(normals));
    const std::string bytes = slurp(p);
    EXPECT_EQ(bytes.rfind("# vtk DataFile Version 4.2\n", 0), 0u);
    EXPECT_NE(bytes.find("\nBINARY\n"), std::string::npos);
    expect_mesh(nbmc::io::read_mesh(p), normals, true);
    const nbmc::io::Particles pts = nbmc::io::read_particles(p);
    EXPECT_EQ(pts.count(), 6u);
    // Big-endian per the format: the first coordinate as written.
    const std::size_t at = bytes.find("float\n") + 6;
    unsigned char b[4];
    std::memcpy(b, bytes.data() + at, 4);
    std::swap(b[0], b[3]);
    std::swap(b[1], b[2]);
    float first;
    std::memcpy(&first, b, 4);
    EXPECT_EQ(first, pos_[0]);
  }
  // No point data at all.
  const std::string bare = path("bare.vtk");
  nbmc::io::write_mesh(bare, view(false, false));
  expect_mesh(nbmc::io::read_mesh(bare), false, false);
}

TEST_F(RoundTrip, Vtu) {
  for (bool normals : {true, false}) {
    const std::string p = path(normals ? "n.vtu" : "p.vtu");
    nbmc::io::write_mesh(p, view(normals));
    EXPECT_NE(slurp(p).find("<AppendedData encoding=\"raw\">"), std::string::npos);
    expect_mesh(nbmc::io::read_mesh(p), normals, true);
    EXPECT_EQ(nbmc::io::read_particles(p).count(), 6u);
  }
}

TEST_F(RoundTrip, GlbFollowsTheSpecification) {
  const std::string p = path("m.glb");
  nbmc::io::write_mesh(p, view(true));
  const std::string b = slurp(p);
  ASSERT_GE(b.size(), 28u);
  EXPECT_EQ(b.substr(0, 4), "glTF");
  EXPECT_EQ(u32(b, 4), 2u);
  EXPECT_EQ(u32(b, 8), b.size());
  const std::uint32_t json_len = u32(b, 12);
  EXPECT_EQ(b.substr(16, 4), "JSON");
  EXPECT_EQ(json_len % 4, 0u);
  const std::string json = b.substr(20, json_len);
  const std::size_t bin_at = 20 + json_len;
  EXPECT_EQ(bin_at % 4, 0u);
  const std::uint32_t bin_len = u32(b, bin_at);
  EXPECT_EQ(b.substr(bin_at + 4, 4), std::string("BIN\0", 4));
  EXPECT_EQ(bin_len % 4, 0u);
  EXPECT_EQ(bin_at + 8 + bin_len, b.size());
  const std::string bin = b.substr(bin_at + 8);
  EXPECT_NE(json.find("\"version\":\"2.0\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"POSITION\":0"), std::string::npos) << json;
  EXPECT_NE(json.find("\"NORMAL\":1"), std::string::npos) << json;
  EXPECT_NE(json.find("\"_RHO\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"_VEL\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"mode\":4"), std::string::npos) << json;
  EXPECT_EQ(numbers_after(json, "byteLength").front(), bin_len) << json; // the buffer
  // POSITION min / max are those of the data.
  const std::regex mm("\"min\":\\[([^\\]]*)\\],\"max\":\\[([^\\]]*)\\]");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(json, m, mm)) << json;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = hi[a] = pos_[a];
    for (int i = 0; i < 6; ++i) {
      lo[a] = std::min(lo[a], pos_[3 * i + a]);
      hi[a] = std::max(hi[a], pos_[3 * i + a]);
    }
  }
  std::stringstream smin(m[1].str()), smax(m[2].str());
  for (int a = 0; a < 3; ++a) {
    std::string x, y;
    std::getline(smin, x, ',');
    std::getline(smax, y, ',');
    EXPECT_EQ(std::stof(x), lo[a]);
    EXPECT_EQ(std::stof(y), hi[a]);
  }
  // Buffer views: positions, normals, rho, vel, indices.
  const std::vector<double> offsets = numbers_after(json, "byteOffset");
  ASSERT_EQ(offsets.size(), 5u) << json;
  for (double o : offsets) EXPECT_EQ(static_cast<long>(o) % 4, 0);
  std::vector<float> got(18);
  std::memcpy(got.data(), bin.data() + static_cast<std::size_t>(offsets[0]), 72);
  EXPECT_EQ(got, pos_);
  std::memcpy(got.data(), bin.data() + static_cast<std::size_t>(offsets[1]), 72);
  EXPECT_EQ(got, nrm_); // already unit length
  float rho[6];
  std::memcpy(rho, bin.data() + static_cast<std::size_t>(offsets[2]), 24);
  EXPECT_EQ(rho[5], 1005.5f);
  std::vector<std::uint32_t> idx(24);
  std::memcpy(idx.data(), bin.data() + static_cast<std::size_t>(offsets[4]), 96);
  EXPECT_EQ(idx, tri_);
  EXPECT_NE(json.find("\"componentType\":5125"), std::string::npos); // UNSIGNED_INT indices
}

TEST_F(RoundTrip, GlbNormalisesNormals) {
  std::vector<float> scaled = nrm_;
  for (float& v : scaled) v *= 3;
  scaled[0] = scaled[1] = scaled[2] = 0; // degenerate: becomes +z
  nbmc::io::MeshView m = view(true, false);
  m.normals = scaled.data();
  const std::string p = path("n.glb");
  nbmc::io::write_mesh(p, m);
  const std::string b = slurp(p);
  const std::string json = b.substr(20, u32(b, 12));
  const std::string bin = b.substr(20 + json.size() + 8);
  const std::vector<double> offsets = numbers_after(json, "byteOffset");
  std::vector<float> got(18);
  std::memcpy(got.data(), bin.data() + static_cast<std::size_t>(offsets[1]), 72);
  EXPECT_EQ(got[0], 0.f);
  EXPECT_EQ(got[2], 1.f);
  for (int i = 1; i < 6; ++i) EXPECT_NEAR(std::hypot(got[3 * i], got[3 * i + 1], got[3 * i + 2]), 1.0, 1e-6);
}

TEST_F(RoundTrip, ObjHasNoAttributes) {
  const std::string p = path("m.obj");
  nbmc::io::write_mesh(p, view(true));
  std::istringstream in(slurp(p));
  std::vector<float> v, vn;
  std::vector<std::uint32_t> f;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string tag;
    ls >> tag;
    if (tag == "v" || tag == "vn") {
      float x, y, z;
      ls >> x >> y >> z;
      auto& dst = tag == "v" ? v : vn;
      dst.insert(dst.end(), {x, y, z});
    } else if (tag == "f") {
      std::string a;
      while (ls >> a) f.push_back(static_cast<std::uint32_t>(std::stoul(a.substr(0, a.find('/')))) - 1);
    }
  }
  EXPECT_EQ(v, pos_);
  EXPECT_EQ(vn, nrm_);
  EXPECT_EQ(f, tri_);
}

TEST_F(RoundTrip, EmptyMeshesInEveryFormat) {
  nbmc::io::MeshView empty;
  for (const char* ext : {"ply", "obj", "vtk", "vtu", "glb"}) {
    SCOPED_TRACE(ext);
    const std::string p = path(std::string("empty.") + ext);
    nbmc::io::write_mesh(p, empty);
    ASSERT_TRUE(fs::exists(p));
    if (std::string(ext) == "vtk" || std::string(ext) == "vtu" || std::string(ext) == "ply") {
      const nbmc::io::Mesh m = nbmc::io::read_mesh(p);
      EXPECT_EQ(m.vertex_count(), 0u);
      EXPECT_EQ(m.triangle_count(), 0u);
    }
    if (std::string(ext) == "glb") {
      const std::string b = slurp(p);
      EXPECT_EQ(u32(b, 8), b.size());
      EXPECT_EQ(20 + u32(b, 12), b.size()); // no BIN chunk
    }
  }
}

TEST_F(RoundTrip, WriterErrors) {
  nbmc::io::MeshView m = view();
  try {
    nbmc::io::write_mesh(path("no/such/folder/m.vtu"), m);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), Error::Kind::io);
    EXPECT_NE(std::string(e.what()).find("m.vtu"), std::string::npos);
  }
  try {
    nbmc::io::write_mesh(path("m.stl"), m);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown mesh extension '.stl'"), std::string::npos) << e.what();
  }
  std::vector<Attribute> bad = attrs_;
  bad[0].values.pop_back();
  m.attributes = bad.data();
  try {
    nbmc::io::write_mesh(path("bad.vtu"), m);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("'rho'"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(path("bad.vtu")));
}
