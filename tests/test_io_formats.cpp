// SPDX-License-Identifier: MIT
// nbmc::io readers on files written by other programs: tests/data/ (h5py and
// VTK's Python writers, see tests/data/generate.py) and the real solver
// frames of NBMC_DATA_DIR (partio BGEO, SPlisHSPlasH and DualSPHysics VTK).
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "io_expect.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nbmc::io::Error;
using nbmc::io::Particles;

namespace {

const std::string kData = std::string(NBMC_SOURCE_DIR) + "/tests/data/";
const std::string kRaw = std::string(NBMC_DATA_DIR) + "/raw/";
constexpr int N = 20;

double ex(int i) { return 0.1 * i; }
double ey(int i) { return 0.5 + 0.01 * i * i; }
double ez(int i) { return -1.0 + 0.05 * i; }

// Positions, velocity and density as generate.py wrote them; tol covers
// float32 storage.
void expect_sample(const Particles& p, double tol, bool velocity = true, bool density = true,
                   const char* vel_name = "velocity", const char* rho_name = "density", double x_shift = 0) {
  ASSERT_EQ(p.count(), static_cast<std::size_t>(N));
  for (int i = 0; i < N; ++i) {
    EXPECT_NEAR(p.xyz[3 * i], ex(i) + x_shift, tol) << i;
    EXPECT_NEAR(p.xyz[3 * i + 1], ey(i), tol) << i;
    EXPECT_NEAR(p.xyz[3 * i + 2], ez(i), tol) << i;
  }
  if (velocity) {
    const nbmc::io::Attribute* v = p.attribute(vel_name);
    ASSERT_NE(v, nullptr) << vel_name << " missing; have " << nbmc::io::attribute_names(p.attributes);
    ASSERT_EQ(v->components, 3);
    for (int i = 0; i < N; ++i) {
      EXPECT_NEAR(v->values[3 * i], i, tol);
      EXPECT_NEAR(v->values[3 * i + 1], -i, tol);
      EXPECT_NEAR(v->values[3 * i + 2], 0.5 * i, tol);
    }
  }
  if (density) {
    const nbmc::io::Attribute* r = p.attribute(rho_name);
    ASSERT_NE(r, nullptr) << rho_name << " missing; have " << nbmc::io::attribute_names(p.attributes);
    ASSERT_EQ(r->components, 1);
    for (int i = 0; i < N; ++i) EXPECT_NEAR(r->values[i], 1000 + i, 1e-3);
  }
}

using nbmc_test::expect_error;

} // namespace

// ----------------------------------------------------------- legacy VTK
TEST(IoFormats, LegacyVtkFromVtkWriters) {
  for (const char* f : {"legacy_poly_ascii.vtk", "legacy_poly_binary.vtk", "legacy_ugrid_binary.vtk",
                        "legacy51_poly_ascii.vtk", "legacy51_ugrid_binary.vtk"}) {
    SCOPED_TRACE(f);
    EXPECT_EQ(nbmc::io::particle_format(kData + f), "vtk");
    expect_sample(nbmc::io::read_particles(kData + f), 1e-6);
  }
}

TEST(IoFormats, AttributesCanBeSkippedOrChosen) {
  nbmc::io::ReadOptions o;
  o.attributes = false;
  EXPECT_TRUE(nbmc::io::read_particles(kData + "legacy_poly_binary.vtk", o).attributes.empty());
  o.attributes = true;
  o.only = {"density"};
  const Particles p = nbmc::io::read_particles(kData + "appended_raw_zlib.vtu", o);
  ASSERT_EQ(p.attributes.size(), 1u);
  EXPECT_EQ(p.attributes[0].name, "density");
}

// -------------------------------------------------------------- VTK XML
TEST(IoFormats, VtuAllEncodingsFromVtkWriters) {
  for (const char* f : {"appended_raw.vtu", "appended_raw_zlib.vtu", "appended_raw_zlib64.vtu",
                        "appended_base64.vtu", "appended_base64_zlib.vtu", "inline_binary.vtu",
                        "inline_binary_zlib64.vtu", "ascii.vtu", "appended_raw_zlib.vtp"}) {
    SCOPED_TRACE(f);
    expect_sample(nbmc::io::read_particles(kData + f), 1e-6);
  }
}

// ------------------------------------------------------------------ BGEO
TEST(IoFormats, BgeoRawAndGzip) {
  for (const char* f : {"small_points.bgeo", "small_points.bgeo.gz"}) {
    SCOPED_TRACE(f);
    EXPECT_EQ(nbmc::io::particle_format(kData + f), "bgeo");
    const Particles p = nbmc::io::read_particles(kData + f);
    expect_sample(p, 1e-5);
    const nbmc::io::Attribute* id = p.attribute("id");
    ASSERT_NE(id, nullptr);
    EXPECT_EQ(id->values[7], 7);
  }
}

// ------------------------------------------------------------------ HDF5
TEST(IoFormats, H5PartStepsTimesAndCompression) {
  const std::string f = kData + "h5part_steps.h5part";
  EXPECT_EQ(nbmc::io::particle_format(f), "h5part");
  EXPECT_EQ(nbmc::io::list_frames(f), (std::vector<std::int64_t>{0, 1, 2}));
  nbmc::io::ReadOptions o;
  const Particles first = nbmc::io::read_particles(f, o);
  expect_sample(first, 1e-12, true, true, "v", "rho");
  EXPECT_EQ(first.time, 0.0);
  o.frame = 1; // float32, chunked, deflate
  const Particles s1 = nbmc::io::read_particles(f, o);
  expect_sample(s1, 1e-5, true, true, "v", "rho", 1.0);
  EXPECT_EQ(s1.time, 0.25);
  o.frame = 2;
  const Particles s2 = nbmc::io::read_particles(f, o);
  expect_sample(s2, 1e-12, false, true, "v", "rho", 2.0);
  EXPECT_EQ(s2.attribute("v"), nullptr);
  EXPECT_EQ(s2.time, 0.5);
  o.frame = 7;
  expect_error([&] { nbmc::io::read_particles(f, o); }, {"h5part_steps.h5part", "Step#7", "0 to 2"});
}

TEST(IoFormats, SphExaDumpIsDetectedAsH5Part) {
  const std::string f = kData + "sphexa_dump.h5";
  EXPECT_EQ(nbmc::io::particle_format(f), "hdf5");
  const Particles p = nbmc::io::read_particles(f);
  expect_sample(p, 1e-12, true, true, "v", "rho");
  EXPECT_EQ(p.time, 1.5);
  ASSERT_NE(p.attribute("h"), nullptr);
  EXPECT_EQ(nbmc::io::read_particles(f, "h5part").count(), static_cast<std::size_t>(N));
}

TEST(IoFormats, PySphPicksTheFluidArray) {
  const std::string f = kData + "pysph_output.hdf5";
  Particles p = nbmc::io::read_particles(f);
  expect_sample(p, 1e-12, false, true, "velocity", "rho");
  EXPECT_EQ(p.time, 0.125);
  ASSERT_NE(p.attribute("u"), nullptr);
  p = nbmc::io::read_particles(f, "pysph");
  EXPECT_NEAR(p.xyz[0], 0.0, 1e-12);
  // Another array by name.
  p = nbmc::io::read_particles(f + ":/particles/boundary");
  expect_sample(p, 1e-12, false, true, "velocity", "rho", 10.0);
}

TEST(IoFormats, GadgetSnapshot) {
  const std::string f = kData + "gadget_snapshot.hdf5";
  Particles p = nbmc::io::read_particles(f, "gadget");
  expect_sample(p, 1e-5, true, true, "Velocities", "Density");
  EXPECT_EQ(p.time, 0.75);
  EXPECT_EQ(nbmc::io::read_particles(f, "swift").count(), static_cast<std::size_t>(N));
  EXPECT_EQ(nbmc::io::read_particles(f).count(), static_cast<std::size_t>(N)); // detected
  EXPECT_EQ(nbmc::io::read_particles(f + ":/PartType1").count(), 5u);
  EXPECT_TRUE(nbmc::io::list_frames(f).empty());
}

TEST(IoFormats, GenericHdf5Objects) {
  const std::string f = kData + "generic.h5";
  expect_sample(nbmc::io::read_particles(f + ":/data/positions"), 1e-12, false, false);
  const Particles g = nbmc::io::read_particles(f + ":/cloud");
  expect_sample(g, 1e-6, false, true);
  expect_error([&] { nbmc::io::read_particles(f); }, {"generic.h5", "layout", ":/path"});
  expect_error([&] { nbmc::io::read_particles(f + ":/nothing"); }, {"generic.h5:/nothing", "no object /nothing"});
  expect_error([&] { nbmc::io::read_particles(f + ":/not_positions"); }, {"not_positions", "N x 3"});
  expect_error([&] { nbmc::io::read_particles(f + ":/data"); }, {"group /data has no datasets x, y, z"});
  expect_error([&] { nbmc::io::read_particles(f, "h5part"); }, {"generic.h5", "no Step#<n> groups"});
  expect_error([&] { nbmc::io::read_particles(f, "pysph"); }, {"generic.h5", "no group /particles"});
  expect_error([&] { nbmc::io::read_particles(f, "gadget"); }, {"generic.h5", "/PartType0"});
}

TEST(IoFormats, Hdf5Errors) {
  expect_error([&] { nbmc::io::read_particles(kData + "missing.h5part"); }, {"missing.h5part", "cannot open"});
  expect_error([&] { nbmc::io::read_particles(kData + "appended_raw.vtu", "hdf5"); },
               {"appended_raw.vtu", "not an HDF5 file"});
  // From memory as well (what the fuzzer uses).
  expect_error([&] { nbmc::io::parse_particles("abc", 3, "hdf5", "mem.h5"); }, {"mem.h5", "not an HDF5 file"});
}

TEST(IoFormats, FormatNamesAndExtensions) {
  EXPECT_EQ(nbmc::io::particle_format("a.VTU"), "vtu");
  EXPECT_EQ(nbmc::io::particle_format("a.vtp"), "vtp");
  EXPECT_EQ(nbmc::io::particle_format("a.bgeo.gz"), "bgeo");
  EXPECT_EQ(nbmc::io::particle_format("a.h5part"), "h5part");
  EXPECT_EQ(nbmc::io::particle_format("a.hdf5:/x/y"), "hdf5");
  EXPECT_EQ(nbmc::io::particle_format("a.bin", "SWIFT"), "gadget");
  try {
    nbmc::io::particle_format("a.bin", "nope");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), Error::Kind::argument);
  }
}

// ------------------------------------------------------- real solver data
TEST(IoFormats, RealPartioBgeoFrames) {
  const std::string dam = kRaw + "dam_break_frame_23_24389_particles.bgeo";
  const std::string cbd = kRaw + "cbd46k_ParticleData_Fluid_11.bgeo";
  if (!fs::exists(dam) || !fs::exists(cbd)) GTEST_SKIP() << kRaw << " not found";
  const Particles a = nbmc::io::read_particles(dam);
  EXPECT_EQ(a.count(), 24389u);
  EXPECT_TRUE(a.attributes.empty());
  // The same particles as the raw xyz frame.
  const std::string xyz = std::string(NBMC_DATA_DIR) + "/xyz/splashsurf_dambreak_f23_24389.xyz";
  if (fs::exists(xyz)) {
    const Particles b = nbmc::io::read_particles(xyz);
    ASSERT_EQ(b.count(), a.count());
    EXPECT_EQ(a.xyz, b.xyz);
  }
  const Particles c = nbmc::io::read_particles(cbd);
  EXPECT_EQ(c.count(), 46250u);
  const nbmc::io::Attribute* vel = c.attribute("velocity");
  const nbmc::io::Attribute* rho = c.attribute("density");
  ASSERT_NE(vel, nullptr);
  ASSERT_NE(rho, nullptr);
  EXPECT_EQ(vel->components, 3);
  EXPECT_EQ(rho->components, 1);
  double mean = 0;
  for (double r : rho->values) mean += r / static_cast<double>(rho->values.size());
  EXPECT_GT(mean, 900);
  EXPECT_LT(mean, 1100);
  const std::string xyz46 = std::string(NBMC_DATA_DIR) + "/xyz/cbd46k_t050_46250.xyz";
  if (fs::exists(xyz46)) EXPECT_EQ(nbmc::io::read_particles(xyz46).xyz, c.xyz);
}

TEST(IoFormats, RealLegacyVtkFrames) {
  struct Case {
    const char* file;
    std::size_t count;
    const char* vec;
    const char* scalar;
  };
  const Case cases[] = {{"bunny_frame_14_7705_particles.vtk", 7706, "velocity", "id"},
                        {"double_dam_break_frame_26_4732_particles.vtk", 4732, "velocity", "id"},
                        {"dualsphysics_cbd_PartFluid_0007.vtk", 48692, "Vel", "Rhop"}};
  bool any = false;
  for (const Case& c : cases) {
    const std::string f = kRaw + c.file;
    if (!fs::exists(f)) continue;
    any = true;
    SCOPED_TRACE(c.file);
    const Particles p = nbmc::io::read_particles(f);
    EXPECT_EQ(p.count(), c.count);
    const nbmc::io::Attribute* v = p.attribute(c.vec);
    const nbmc::io::Attribute* s = p.attribute(c.scalar);
    ASSERT_NE(v, nullptr) << nbmc::io::attribute_names(p.attributes);
    ASSERT_NE(s, nullptr) << nbmc::io::attribute_names(p.attributes);
    EXPECT_EQ(v->components, 3);
    EXPECT_EQ(s->components, 1);
    for (double x : p.xyz) ASSERT_TRUE(std::isfinite(x));
  }
  if (!any) GTEST_SKIP() << kRaw << " not found";
  const std::string dd = kRaw + "double_dam_break_frame_26_4732_particles.vtk";
  const std::string xyz = std::string(NBMC_DATA_DIR) + "/xyz/splashsurf_doubledambreak_f26_4732.xyz";
  if (fs::exists(dd) && fs::exists(xyz)) EXPECT_EQ(nbmc::io::read_particles(dd).xyz, nbmc::io::read_particles(xyz).xyz);
  const std::string ds = kRaw + "dualsphysics_cbd_PartFluid_0007.vtk";
  if (fs::exists(ds)) {
    const Particles p = nbmc::io::read_particles(ds);
    double mean = 0;
    for (double r : p.attribute("Rhop")->values) mean += r / static_cast<double>(p.count());
    EXPECT_NEAR(mean, 1000, 100);
  }
}
