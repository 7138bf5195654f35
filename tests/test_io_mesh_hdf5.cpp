// SPDX-License-Identifier: MIT
// The VTK PolyData (.vtp) and HDF5 + XDMF (.h5 / .xdmf) mesh writers: the
// .vtp read back with nbmc's VTK XML reader, the .h5 read back with libhdf5
// itself, both compared bit for bit; the XDMF descriptors checked for what
// they reference; sequences through the nbmc command. (ParaView's readers
// check the XDMF in tests/xdmf/check_xdmf.py.)
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "nbmc.h"
#include "cli_fixture.hpp"
#include "nbmc_test.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nbmc::io::Attribute;
using nbmc::io::Error;
using nbmc_test::contains;
using nbmc_test::slurp;

namespace {

// A strip of 2 * n triangles over n + 1 columns of two vertices, with
// normals, a scalar "T" (values that float cannot hold exactly) and a
// vector "v" per vertex.
struct Strip {
  std::vector<float> positions, normals;
  std::vector<std::uint32_t> triangles;
  std::vector<Attribute> attributes;
  explicit Strip(int n, float shift = 0) {
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j < 2; ++j) {
        positions.insert(positions.end(), {0.1f * static_cast<float>(i) + shift, static_cast<float>(j), 0.3f});
        normals.insert(normals.end(), {0, 0, 1});
      }
    for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(n); ++i)
      triangles.insert(triangles.end(), {2 * i, 2 * i + 2, 2 * i + 1, 2 * i + 1, 2 * i + 2, 2 * i + 3});
    Attribute t{"T", 1, {}}, v{"v", 3, {}};
    for (std::size_t k = 0; k < positions.size() / 3; ++k) {
      t.values.push_back(273.15 + 0.1 * static_cast<double>(k));
      v.values.insert(v.values.end(), {1.0 / 3, -2.5 * static_cast<double>(k), 1e-7});
    }
    attributes = {t, v};
  }
  nbmc::io::MeshView view(bool with_normals = true) const {
    nbmc::io::MeshView m;
    m.positions = positions.data();
    m.normals = with_normals ? normals.data() : nullptr;
    m.triangles = triangles.data();
    m.vertex_count = positions.size() / 3;
    m.triangle_count = triangles.size() / 3;
    m.attributes = attributes.data();
    m.attribute_count = attributes.size();
    return m;
  }
};

// A dataset of the HDF5 file read with libhdf5 as type T (memory type mt);
// dims receives its shape.
template <class T>
std::vector<T> h5read(const std::string& file, const std::string& path, hid_t mt, std::vector<hsize_t>& dims) {
  std::vector<T> out;
  dims.clear();
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return out;
  const hid_t d = H5Dopen2(f, path.c_str(), H5P_DEFAULT);
  if (d >= 0) {
    const hid_t s = H5Dget_space(d);
    dims.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(s)));
    H5Sget_simple_extent_dims(s, dims.data(), nullptr);
    out.resize(static_cast<std::size_t>(H5Sget_simple_extent_npoints(s)));
    if (!out.empty()) H5Dread(d, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data());
    H5Sclose(s);
    H5Dclose(d);
  }
  H5Fclose(f);
  return out;
}

// Checks that `group` of the HDF5 file holds exactly the mesh s.
void expect_h5_mesh(const std::string& file, const std::string& group, const Strip& s, bool normals = true) {
  SCOPED_TRACE(file + ":" + group);
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  const std::uint64_t nv = s.positions.size() / 3, nt = s.triangles.size() / 3;
  std::vector<hsize_t> dims;
  EXPECT_EQ(h5read<float>(file, group + "/positions", H5T_NATIVE_FLOAT, dims), s.positions);
  EXPECT_EQ(dims, (std::vector<hsize_t>{nv, 3}));
  EXPECT_EQ(h5read<std::uint32_t>(file, group + "/triangles", H5T_NATIVE_UINT32, dims), s.triangles);
  EXPECT_EQ(dims, (std::vector<hsize_t>{nt, 3}));
  const std::vector<float> n = h5read<float>(file, group + "/normals", H5T_NATIVE_FLOAT, dims);
  EXPECT_EQ(n, normals ? s.normals : std::vector<float>());
  for (const Attribute& a : s.attributes) {
    EXPECT_EQ(h5read<double>(file, group + "/attributes/" + a.name, H5T_NATIVE_DOUBLE, dims), a.values) << a.name;
    const std::vector<hsize_t> want = a.components == 1 ? std::vector<hsize_t>{nv} : std::vector<hsize_t>{nv, 3};
    EXPECT_EQ(dims, want) << a.name;
  }
}

class MeshOut : public nbmc_test::CliFixture {
protected:
  MeshOut() : CliFixture("nbmc_test_mesh_hdf5_") {}
  void SetUp() override { nbmc_test::CliFixture::SetUp(); }
};

std::size_t count(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = s.find(what); at != std::string::npos; at = s.find(what, at + 1)) ++n;
  return n;
}

} // namespace

TEST_F(MeshOut, VtpReadsBackExactly) {
  const Strip s(5);
  for (bool normals : {true, false}) {
    const std::string p = path(normals ? "n.vtp" : "p.vtp");
    nbmc::io::write_mesh(p, s.view(normals));
    const std::string text = slurp(p);
    EXPECT_TRUE(contains(text, "<VTKFile type=\"PolyData\"")) << text.substr(0, 400);
    EXPECT_TRUE(contains(text, "NumberOfPolys=\"10\""));
    EXPECT_TRUE(contains(text, "<Polys>"));
    EXPECT_FALSE(contains(text, "\"types\""));
    const nbmc::io::Mesh m = nbmc::io::read_mesh(p);
    EXPECT_EQ(m.positions, s.positions);
    EXPECT_EQ(m.triangles, s.triangles);
    EXPECT_EQ(m.normals, normals ? s.normals : std::vector<float>());
    ASSERT_EQ(m.attributes.size(), 2u);
    for (std::size_t a = 0; a < 2; ++a) {
      EXPECT_EQ(m.attributes[a].name, s.attributes[a].name);
      EXPECT_EQ(m.attributes[a].components, s.attributes[a].components);
      ASSERT_EQ(m.attributes[a].values.size(), s.attributes[a].values.size());
      for (std::size_t i = 0; i < s.attributes[a].values.size(); ++i) // Float32 in the file
        EXPECT_EQ(m.attributes[a].values[i], static_cast<double>(static_cast<float>(s.attributes[a].values[i])));
    }
    EXPECT_EQ(nbmc::io::read_particles(p).count(), 12u);
  }
  // Empty meshes give valid files.
  nbmc::io::write_mesh(path("empty.vtp"), nbmc::io::MeshView{});
  EXPECT_EQ(nbmc::io::read_mesh(path("empty.vtp")).vertex_count(), 0u);
}

TEST_F(MeshOut, Hdf5FileWithXdmf) {
  const Strip s(4);
  for (bool normals : {true, false}) {
    const std::string p = path(normals ? "m.h5" : "sub/p.hdf5");
    fs::create_directories(path("sub"));
    nbmc::io::write_mesh(p, s.view(normals));
    expect_h5_mesh(p, "", s, normals);
    const std::string x = slurp(normals ? path("m.xdmf") : path("sub/p.xdmf"));
    const std::string ref = normals ? "m.h5" : "p.hdf5"; // relative to the descriptor
    EXPECT_TRUE(contains(x, "<Xdmf Version=\"3.0\">")) << x;
    EXPECT_TRUE(contains(x, "<Topology TopologyType=\"Triangle\" NumberOfElements=\"8\">")) << x;
    EXPECT_TRUE(contains(x, "<DataItem Dimensions=\"8 3\" NumberType=\"UInt\" Precision=\"4\" Format=\"HDF\">" + ref +
                                ":/triangles</DataItem>"))
        << x;
    EXPECT_TRUE(contains(x, "<Geometry GeometryType=\"XYZ\">")) << x;
    EXPECT_TRUE(contains(x, "<DataItem Dimensions=\"10 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" +
                                ref + ":/positions</DataItem>"))
        << x;
    EXPECT_EQ(contains(x, "<Attribute Name=\"Normals\" AttributeType=\"Vector\" Center=\"Node\">"), normals) << x;
    EXPECT_TRUE(contains(x, "<Attribute Name=\"T\" AttributeType=\"Scalar\" Center=\"Node\">")) << x;
    EXPECT_TRUE(contains(x, "<DataItem Dimensions=\"10\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">" + ref +
                                ":/attributes/T</DataItem>"))
        << x;
    EXPECT_TRUE(contains(x, "<Attribute Name=\"v\" AttributeType=\"Vector\" Center=\"Node\">")) << x;
    EXPECT_FALSE(contains(x, "Temporal"));
  }
  EXPECT_EQ(nbmc::io::mesh_format("a.HDF5"), "h5");
  EXPECT_EQ(nbmc::io::mesh_format("x", "hdf5"), "h5");
  EXPECT_EQ(nbmc::io::mesh_format("a.h5:/frame_1"), "h5");
  EXPECT_EQ(nbmc::io::mesh_format("a.vtp"), "vtp");
  // No temporary files are left behind.
  for (const auto& e : fs::directory_iterator(dir_)) EXPECT_FALSE(contains(e.path().string(), "nbmc-tmp"));
}

// Double positions (nbmc_params.double_positions): a float64 dataset that
// reads back bit for bit, and the XDMF descriptor says Precision="8"; also
// into a group of an existing file.
TEST_F(MeshOut, Hdf5DoublePositions) {
  const Strip s(4);
  std::vector<double> p64;
  for (std::size_t i = 0; i < s.positions.size(); ++i) p64.push_back(5e6 + 1e-3 / 3 * double(i));  // UTM-like
  nbmc::io::MeshView v = s.view();
  v.positions = nullptr;
  v.positions64 = p64.data();
  for (const std::string group : {"", "/frame_1"}) {
    SCOPED_TRACE(group);
    const std::string f = path("d.h5");
    nbmc::io::write_mesh(group.empty() ? f : f + ":" + group, v);
    std::vector<hsize_t> dims;
    const std::vector<double> back = h5read<double>(f, group + "/positions", H5T_NATIVE_DOUBLE, dims);
    ASSERT_EQ(back.size(), p64.size());
    EXPECT_EQ(std::memcmp(back.data(), p64.data(), p64.size() * sizeof(double)), 0);
    EXPECT_EQ(dims, (std::vector<hsize_t>{10, 3}));
    // Stored as float64, not widened floats: the file's type says so.
    const hid_t fh = H5Fopen(f.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t d = H5Dopen2(fh, (group + "/positions").c_str(), H5P_DEFAULT);
    const hid_t t = H5Dget_type(d);
    EXPECT_EQ(H5Tget_size(t), 8u);
    EXPECT_EQ(H5Tget_class(t), H5T_FLOAT);
    H5Tclose(t);
    H5Dclose(d);
    H5Fclose(fh);
    EXPECT_EQ(h5read<float>(f, group + "/normals", H5T_NATIVE_FLOAT, dims), s.normals);
    const std::string x = slurp(path("d.xdmf"));
    EXPECT_TRUE(contains(x, "<DataItem Dimensions=\"10 3\" NumberType=\"Float\" Precision=\"8\" Format=\"HDF\">d.h5:" +
                                group + "/positions</DataItem>"))
        << x;
    fs::remove(f);
    fs::remove(path("d.xdmf"));
    if (!group.empty()) continue;
    // The group case writes into an existing file (of float meshes).
    nbmc::io::write_mesh(f + ":/frame_0", s.view());
  }
}

TEST_F(MeshOut, Hdf5GroupsMakeATemporalCollection) {
  const std::string f = path("seq.h5");
  const Strip a(2), b(3, 0.5f), c(4, 1.0f);
  EXPECT_FALSE(nbmc::io::mesh_output_exists(f + ":/frame_2"));
  nbmc::io::write_mesh(f + ":/frame_2", a.view());
  nbmc::io::write_mesh(f + ":/frame_10", b.view());
  nbmc::io::write_mesh(f + ":/frame_1", a.view(false));
  nbmc::io::write_mesh(f + ":/frame_2", c.view()); // replaces the group
  expect_h5_mesh(f, "/frame_1", a, false);
  expect_h5_mesh(f, "/frame_2", c);
  expect_h5_mesh(f, "/frame_10", b);
  EXPECT_TRUE(nbmc::io::mesh_output_exists(f + ":/frame_10"));
  EXPECT_FALSE(nbmc::io::mesh_output_exists(f + ":/frame_3"));
  EXPECT_EQ(nbmc::io::mesh_output_file(f + ":/frame_3"), f);
  const std::string x = slurp(path("seq.xdmf"));
  EXPECT_TRUE(contains(x, "<Grid Name=\"frames\" GridType=\"Collection\" CollectionType=\"Temporal\">")) << x;
  EXPECT_EQ(count(x, "GridType=\"Uniform\""), 3u) << x;
  // In numeric order, the number being the time.
  const std::size_t t1 = x.find("<Time Value=\"1\"/>"), t2 = x.find("<Time Value=\"2\"/>"),
                    t10 = x.find("<Time Value=\"10\"/>");
  ASSERT_NE(t1, std::string::npos) << x;
  ASSERT_NE(t2, std::string::npos) << x;
  ASSERT_NE(t10, std::string::npos) << x;
  EXPECT_LT(t1, t2);
  EXPECT_LT(t2, t10);
  EXPECT_TRUE(contains(x, "seq.h5:/frame_2/positions")) << x;
  EXPECT_TRUE(contains(x, "<DataItem Dimensions=\"10 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">"
                          "seq.h5:/frame_2/positions</DataItem>"))
      << x;
  // A whole-file write replaces the frames.
  nbmc::io::write_mesh(f, a.view());
  EXPECT_FALSE(nbmc::io::mesh_output_exists(f + ":/frame_2"));
  EXPECT_FALSE(contains(slurp(path("seq.xdmf")), "Temporal"));
}

TEST_F(MeshOut, Hdf5Errors) {
  const Strip s(2);
  std::ofstream(path("text.h5")) << "not HDF5";
  try {
    nbmc::io::write_mesh(path("text.h5") + ":/frame_1", s.view());
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_TRUE(contains(e.what(), "text.h5")) << e.what();
    EXPECT_TRUE(contains(e.what(), "not an HDF5 file")) << e.what();
  }
  EXPECT_EQ(slurp(path("text.h5")), "not HDF5");
  try {
    nbmc::io::write_mesh(path("no/such/folder/m.h5"), s.view());
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), Error::Kind::io);
  }
  // A cancelled group write leaves no group behind.
  nbmc::io::write_mesh(path("c.h5:/frame_1"), s.view());
  EXPECT_THROW(nbmc::io::write_mesh(path("c.h5:/frame_2"), s.view(), "", [] { return true; }), nbmc::io::Cancelled);
  EXPECT_TRUE(nbmc::io::mesh_output_exists(path("c.h5:/frame_1")));
  EXPECT_FALSE(nbmc::io::mesh_output_exists(path("c.h5:/frame_2")));
  EXPECT_THROW(nbmc::io::write_mesh(path("d.h5"), s.view(), "", [] { return true; }), nbmc::io::Cancelled);
  EXPECT_FALSE(fs::exists(path("d.h5")));
  // Empty meshes.
  nbmc::io::write_mesh(path("e.h5"), nbmc::io::MeshView{});
  Strip none(0);
  none.positions.clear();
  none.attributes.clear();
  expect_h5_mesh(path("e.h5"), "", none, false);
  EXPECT_TRUE(contains(slurp(path("e.xdmf")), "NumberOfElements=\"0\""));
}

TEST_F(MeshOut, CliSequenceIntoOneHdf5File) {
  fs::create_directories(path("frames"));
  for (int i : {1, 2, 10}) {
    const auto p = nbmc_test::sphere(0, 0, 0, 0.3 + 0.02 * i, 0.1);
    std::ofstream out(path("frames/f_" + std::to_string(i) + ".xyz"), std::ios::binary);
    for (double v : p) {
      const float x = static_cast<float>(v);
      out.write(reinterpret_cast<const char*>(&x), 4);
    }
  }
  nbmc_test::CliResult r = run("reconstruct 'frames/f_{}.xyz' -o 'out/s_{}.h5' --spacing 0.1 --frames 1:2 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(path("out/s_.h5")));
  ASSERT_TRUE(fs::exists(path("out/s.h5")));
  EXPECT_TRUE(nbmc::io::mesh_output_exists(path("out/s.h5:/frame_1")));
  EXPECT_TRUE(nbmc::io::mesh_output_exists(path("out/s.h5:/frame_2")));
  r = run("reconstruct 'frames/f_{}.xyz' -o 'out/s_{}.h5' --spacing 0.1 --resume --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "\"skipped\": 2")) << r.out;
  EXPECT_TRUE(contains(r.out, "\"written\": 1")) << r.out;
  EXPECT_TRUE(contains(r.out, "out/s.h5:/frame_10")) << r.out;
  const std::string x = slurp(path("out/s.xdmf"));
  EXPECT_EQ(count(x, "<Time Value="), 3u) << x;
  EXPECT_TRUE(contains(x, "s.h5:/frame_10/triangles")) << x;
  // The same frame as a single .vtp: the same mesh.
  r = run("reconstruct frames/f_10.xyz -o one.vtp --spacing 0.1 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nbmc::io::Mesh m = nbmc::io::read_mesh(path("one.vtp"));
  Strip want(0);
  want.positions = m.positions;
  want.normals = m.normals;
  want.triangles = m.triangles;
  want.attributes.clear();
  expect_h5_mesh(path("out/s.h5"), "/frame_10", want);
  // The group can be named in the pattern, too.
  r = run("reconstruct 'frames/f_{}.xyz' -o 'all.h5:/step_{}' --spacing 0.1 --frames 2:2 -q");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(nbmc::io::mesh_output_exists(path("all.h5:/step_2")));
  EXPECT_TRUE(contains(slurp(path("all.xdmf")), "all.h5:/step_2/positions"));
}

TEST_F(MeshOut, CApiWritesVtpAndHdf5) {
  nbmc_context* ctx = nullptr;
  ASSERT_EQ(nbmc_context_create(nullptr, &ctx), NBMC_OK);
  const auto p = nbmc_test::sphere(0, 0, 0, 0.4, 0.1);
  ASSERT_EQ(nbmc_context_set_particles_f64(ctx, p.data(), p.size() / 3, 0), NBMC_OK);
  nbmc_params prm = nbmc_test::params(0.1);
  nbmc_mesh* mesh = nullptr;
  ASSERT_EQ(nbmc_context_reconstruct(ctx, &prm, &mesh), NBMC_OK) << nbmc_context_last_error(ctx);
  Strip want(0);
  want.attributes.clear();
  const std::uint64_t nv = nbmc_mesh_vertex_count(mesh), nt = nbmc_mesh_triangle_count(mesh);
  want.positions.assign(nbmc_mesh_positions(mesh), nbmc_mesh_positions(mesh) + 3 * nv);
  want.normals.assign(nbmc_mesh_normals(mesh), nbmc_mesh_normals(mesh) + 3 * nv);
  want.triangles.assign(nbmc_mesh_triangles(mesh), nbmc_mesh_triangles(mesh) + 3 * nt);
  ASSERT_EQ(nbmc_mesh_write(mesh, path("c.vtp").c_str(), nullptr), NBMC_OK) << nbmc_last_error();
  ASSERT_EQ(nbmc_mesh_write(mesh, path("c.h5").c_str(), nullptr), NBMC_OK) << nbmc_last_error();
  ASSERT_EQ(nbmc_mesh_write(mesh, (path("s.h5") + ":/frame_7").c_str(), nullptr), NBMC_OK) << nbmc_last_error();
  ASSERT_EQ(nbmc_mesh_write(mesh, path("x.bin").c_str(), "HDF5"), NBMC_OK) << nbmc_last_error();
  const nbmc::io::Mesh back = nbmc::io::read_mesh(path("c.vtp"));
  EXPECT_EQ(back.positions, want.positions);
  EXPECT_EQ(back.triangles, want.triangles);
  expect_h5_mesh(path("c.h5"), "", want);
  expect_h5_mesh(path("s.h5"), "/frame_7", want);
  expect_h5_mesh(path("x.bin"), "", want);
  EXPECT_TRUE(fs::exists(path("x.xdmf")));
  EXPECT_TRUE(contains(slurp(path("s.xdmf")), "<Time Value=\"7\"/>"));
  EXPECT_EQ(nbmc_mesh_write(mesh, path("c.stl").c_str(), nullptr), NBMC_ERROR_FORMAT);
  nbmc_mesh_destroy(mesh);
  nbmc_context_destroy(ctx);
}
