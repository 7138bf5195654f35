// SPDX-License-Identifier: MIT
// Readers on damaged input: every sample of tests/data truncated at many
// lengths and with random bytes changed must give an nbmc::io::Error naming
// the file, or particles that are consistent; files that lie about sizes
// must fail before anything of that size is allocated.
#include "io/particles.hpp"

#include <gtest/gtest.h>

#include <zlib.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using nbmc::io::Error;
using nbmc::io::Particles;

namespace {

const std::string kData = std::string(NBMC_SOURCE_DIR) + "/tests/data/";

std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
}

// Parses bytes as format; returns "" on success (after checking the result),
// else the message (which must name the input).
std::string parse(const std::string& bytes, const std::string& format, const std::string& name) {
  try {
    const Particles p = nbmc::io::parse_particles(bytes.data(), bytes.size(), format, name);
    EXPECT_EQ(p.xyz.size() % 3, 0u);
    for (const auto& a : p.attributes) EXPECT_EQ(a.values.size(), p.count() * static_cast<std::size_t>(a.components));
    return "";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(name), std::string::npos) << msg;
    return msg.empty() ? "?" : msg;
  }
}

struct Sample {
  const char* file;
  const char* format;
};
const Sample kSamples[] = {
    {"legacy_poly_ascii.vtk", "vtk"},      {"legacy_poly_binary.vtk", "vtk"},    {"legacy_ugrid_binary.vtk", "vtk"},
    {"legacy51_poly_ascii.vtk", "vtk"},    {"legacy51_ugrid_binary.vtk", "vtk"}, {"appended_raw.vtu", "vtu"},
    {"appended_raw_zlib.vtu", "vtu"},      {"appended_raw_zlib64.vtu", "vtu"},   {"appended_base64.vtu", "vtu"},
    {"appended_base64_zlib.vtu", "vtu"},   {"inline_binary.vtu", "vtu"},         {"inline_binary_zlib64.vtu", "vtu"},
    {"ascii.vtu", "vtu"},                  {"appended_raw_zlib.vtp", "vtp"},     {"small_points.bgeo", "bgeo"},
    {"small_points.bgeo.gz", "bgeo"},
};

} // namespace

TEST(IoRobustness, TruncatedFilesFailCleanly) {
  for (const Sample& s : kSamples) {
    SCOPED_TRACE(s.file);
    const std::string all = slurp(kData + s.file);
    ASSERT_FALSE(all.empty());
    EXPECT_EQ(parse(all, s.format, s.file), "");
    std::size_t failures = 0;
    for (std::size_t n = 0; n < all.size(); ++n) failures += !parse(all.substr(0, n), s.format, s.file).empty();
    // Text formats may stop at a value boundary and still parse; binary ones
    // must fail at every cut that loses data.
    EXPECT_GT(failures, all.size() / 2);
  }
}

TEST(IoRobustness, CorruptedBytesFailCleanly) {
  std::mt19937 rng(12345);
  for (const Sample& s : kSamples) {
    SCOPED_TRACE(s.file);
    const std::string all = slurp(kData + s.file);
    for (int round = 0; round < 300; ++round) {
      std::string bad = all;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits; ++e) {
        const std::size_t at = rng() % bad.size();
        switch (rng() % 3) {
        case 0: bad[at] = static_cast<char>(rng()); break;
        case 1: bad[at] = static_cast<char>(bad[at] ^ (1 << (rng() % 8))); break;
        default: bad[at] = "0123456789 \n<>\"=_-"[rng() % 19]; break;
        }
      }
      parse(bad, s.format, s.file);
    }
  }
}

TEST(IoRobustness, Hdf5TruncatedImagesFailCleanly) {
  for (const char* f : {"h5part_steps.h5part", "pysph_output.hdf5", "gadget_snapshot.hdf5", "sphexa_dump.h5"}) {
    SCOPED_TRACE(f);
    const std::string all = slurp(kData + f);
    EXPECT_EQ(parse(all, "hdf5", f), "");
    for (std::size_t n = 0; n < all.size(); n += 1 + n / 8) EXPECT_NE(parse(all.substr(0, n), "hdf5", f), "") << n;
  }
}

TEST(IoRobustness, Hdf5DatasetsThatStoreNothing) {
  try {
    nbmc::io::read_particles(kData + "hdf5_unwritten.h5part");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("declares 2147483648 values but stores only 0 bytes"), std::string::npos)
        << e.what();
  }
}

TEST(IoRobustness, Hdf5WronglyTypedDatasets) {
  const std::string f = kData + "hdf5_wrong.h5part";
  const char* expected[] = {"dataset /Step#0/x is not numeric", "dataset /Step#1/y is not one-dimensional",
                            "dataset /Step#2/z has 3 values but /Step#2/x has 4",
                            "group /Step#3 has no dataset 'z'"};
  for (int s = 0; s < 4; ++s) {
    nbmc::io::ReadOptions o;
    o.frame = s;
    try {
      nbmc::io::read_particles(f, o);
      ADD_FAILURE() << s;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("hdf5_wrong.h5part"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(expected[s]), std::string::npos) << e.what();
      EXPECT_EQ(e.kind(), Error::Kind::format);
    }
  }
}

TEST(IoRobustness, LyingSizesAreCaughtBeforeAllocating) {
  const auto fails_with = [](const std::string& bytes, const char* format, const std::string& needle) {
    const std::string msg = parse(bytes, format, std::string("lie.") + format);
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  };
  // Legacy VTK: a billion points in a few bytes.
  fails_with("# vtk DataFile Version 3.0\nx\nBINARY\nDATASET POLYDATA\nPOINTS 1000000000 float\nabcdefgh", "vtk",
             "bytes are left");
  fails_with("# vtk DataFile Version 3.0\nx\nASCII\nDATASET POLYDATA\nPOINTS 1000000000 float\n1 2 3", "vtk",
             "bytes are left");
  // VTU: many points, a block header that lies, a compression header with
  // 2^31 blocks.
  const std::string head = "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" header_type=\"UInt32\"%C>"
                           "<UnstructuredGrid><Piece NumberOfPoints=\"%N\" NumberOfCells=\"0\"><Points>"
                           "<DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"0\"/>"
                           "</Points></Piece></UnstructuredGrid><AppendedData encoding=\"raw\">_";
  const auto vtu = [&](const std::string& n, bool zlib, const std::string& data) {
    std::string h = head;
    h.replace(h.find("%C"), 2, zlib ? " compressor=\"vtkZLibDataCompressor\"" : "");
    h.replace(h.find("%N"), 2, n);
    return h + data + "</AppendedData></VTKFile>";
  };
  const auto u32 = [](std::uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  fails_with(vtu("1000000000", false, u32(12000000000u % 4294967296u) + "abcd"), "vtu", "block header declares");
  fails_with(vtu("1000000", false, u32(12000000) + "abcd"), "vtu", "fewer are left");
  fails_with(vtu("1000000", true, u32(0x80000000u) + u32(65536) + u32(0) + "xx"), "vtu", "more than the file holds");
  // A deflate block cannot expand more than 1032 times.
  fails_with(vtu("1000000", true, u32(1) + u32(12000000) + u32(0) + u32(100) + std::string(100, 'x')), "vtu",
             "cannot hold");
  // A block that inflates to more than its header says.
  {
    std::vector<unsigned char> zeros(1200, 0), z(2000);
    uLongf zl = z.size();
    ASSERT_EQ(compress(z.data(), &zl, zeros.data(), zeros.size()), Z_OK);
    fails_with(vtu("10", true, u32(1) + u32(120) + u32(0) + u32(static_cast<std::uint32_t>(zl)) +
                                   std::string(reinterpret_cast<const char*>(z.data()), zl)),
               "vtu", "more than the 120 bytes");
  }
  // BGEO: 2^31 - 1 points.
  std::string bgeo = "BgeoV";
  const auto be32 = [](std::int32_t v) {
    std::string s(4, '\0');
    for (int i = 0; i < 4; ++i) s[static_cast<std::size_t>(i)] = static_cast<char>((static_cast<std::uint32_t>(v) >> (24 - 8 * i)) & 0xff);
    return s;
  };
  bgeo += be32(5) + be32(0x7fffffff);
  for (int i = 0; i < 7; ++i) bgeo += be32(0);
  fails_with(bgeo + "0123456789abcdef", "bgeo", "header says 2147483647 points");
  bgeo = "BgeoV" + be32(5) + be32(1) + be32(0) + be32(0) + be32(0) + be32(0x7fffffff);
  for (int i = 0; i < 3; ++i) bgeo += be32(0);
  fails_with(bgeo, "bgeo", "point attributes");
  // gzip that ends early.
  const std::string gz = slurp(kData + "small_points.bgeo.gz");
  fails_with(gz.substr(0, gz.size() / 2), "bgeo", "truncated");
}

TEST(IoRobustness, GzipBombIsBounded) {
  // 64 MiB of zeros compress to ~64 KiB; the bound (1032 x input) allows
  // that, so it inflates and then fails as a BGEO, without a crash.
  std::vector<unsigned char> zeros(std::size_t(64) << 20, 0);
  std::vector<unsigned char> out(compressBound(static_cast<uLong>(zeros.size())));
  z_stream z{};
  ASSERT_EQ(deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 9, Z_DEFAULT_STRATEGY), Z_OK);
  z.next_in = zeros.data();
  z.avail_in = static_cast<uInt>(zeros.size());
  z.next_out = out.data();
  z.avail_out = static_cast<uInt>(out.size());
  ASSERT_EQ(deflate(&z, Z_FINISH), Z_STREAM_END);
  const std::string gz(reinterpret_cast<const char*>(out.data()), z.total_out);
  deflateEnd(&z);
  const std::string msg = parse(gz, "bgeo", "bomb.bgeo");
  EXPECT_NE(msg.find("not a BGEO file"), std::string::npos) << msg;
}
