// SPDX-License-Identifier: MIT
// Houdini classic binary geometry (.bgeo, version 5), as partio writes it
// for SPlisHSPlasH: big-endian header, point attribute definitions, then per
// point x, y, z, w and the attribute values. gzip-compressed files (what
// partio writes by default) are detected by their magic bytes.
#include "io/codec.hpp"
#include "io/readers.hpp"
#include "core/huge_pages.hpp"

#include <algorithm>
#include <cstring>

namespace nbmc::io::detail {

namespace {

// Largest decompressed BGEO accepted (besides the deflate ratio bound).
constexpr std::uint64_t kMaxInflated = std::uint64_t(16) << 30;

struct AttrDef {
  std::string name;
  std::uint32_t size = 0; // components
  std::int32_t type = 0;  // 0 float, 1 int, 4 index (string table), 5 vector
  bool keep = false;
};

class Bgeo {
public:
  Bgeo(ByteReader& in, const ReadOptions& o) : in_(in), opt_(o) {}
  Particles run();

private:
  const std::string& name() const { return in_.name(); }
  void bytes(void* dst, std::size_t n, const char* what) {
    if (in_.read(dst, n) != n) fail(name(), std::string("the file ends inside ") + what);
  }
  std::int32_t i32(const char* what) {
    unsigned char b[4];
    bytes(b, 4, what);
    return load_as<std::int32_t>(b, true);
  }
  std::uint16_t u16(const char* what) {
    unsigned char b[2];
    bytes(b, 2, what);
    return load_as<std::uint16_t>(b, true);
  }
  std::string str(const char* what) {
    const std::uint16_t n = u16(what);
    if (n > in_.remaining()) fail(name(), std::string("the file ends inside ") + what);
    std::string s(n, '\0');
    bytes(s.data(), n, what);
    return s;
  }
  ByteReader& in_;
  const ReadOptions& opt_;
};

Particles Bgeo::run() {
  unsigned char magic[5];
  if (in_.read(magic, 5) != 5) fail(name(), "too short for a BGEO file");
  if (std::memcmp(magic, "Bgeo", 4) != 0) {
    if (magic[0] == 0x7f && std::memcmp(magic + 1, "NSJ", 3) == 0)
      fail(name(), "JSON-based BGEO (Houdini 12+ default) is not supported; save as classic .bgeo (partio)");
    fail(name(), "not a BGEO file (no 'Bgeo' magic)");
  }
  if (magic[4] != 'V') fail(name(), "not a classic BGEO file ('V' expected after the magic)");
  const std::int32_t version = i32("the header");
  if (version != 5) fail(name(), "BGEO version " + std::to_string(version) + " is not supported (only 5)");
  std::int32_t h[8];
  for (std::int32_t& v : h) v = i32("the header");
  const std::int32_t n_points = h[0], n_prims = h[1], n_point_groups = h[2], n_prim_groups = h[3];
  const std::int32_t n_point_attr = h[4], n_vertex_attr = h[5], n_prim_attr = h[6], n_detail_attr = h[7];
  for (std::int32_t v : h)
    if (v < 0) fail(name(), "negative count " + std::to_string(v) + " in the BGEO header");
  (void)n_prims;
  (void)n_point_groups;
  (void)n_prim_groups;
  (void)n_vertex_attr;
  (void)n_prim_attr;
  (void)n_detail_attr;

  // Every attribute definition takes at least 8 bytes.
  if (static_cast<std::uint64_t>(n_point_attr) > in_.remaining() / 8)
    fail(name(), "header declares " + std::to_string(n_point_attr) + " point attributes, more than the file holds");
  std::vector<AttrDef> defs;
  std::uint64_t record = 16; // x, y, z, w
  for (std::int32_t a = 0; a < n_point_attr; ++a) {
    AttrDef d;
    d.name = str("an attribute name");
    d.size = u16("an attribute definition");
    d.type = i32("an attribute definition");
    const std::string what = "point attribute '" + printable(d.name) + "'";
    if (d.size == 0) fail(name(), what + " has 0 components");
    if (d.type == 0 || d.type == 1 || d.type == 5) {
      if (d.type == 5 && d.size != 3) fail(name(), what + " is a vector of " + std::to_string(d.size) + " components");
      if (in_.skip(4u * d.size) != 4u * d.size) fail(name(), "the file ends inside " + what); // defaults
      d.keep = (d.size == 1 || d.size == 3) && want_attribute(opt_, d.name);
    } else if (d.type == 4) {
      const std::int32_t n = i32("an index attribute");
      if (n < 0 || static_cast<std::uint64_t>(n) > in_.remaining() / 2)
        fail(name(), what + " declares " + std::to_string(n) + " strings, more than the file holds");
      for (std::int32_t k = 0; k < n; ++k) str("an index attribute string");
    } else if (d.type == 2) {
      fail(name(), what + " is a string attribute (not supported)");
    } else {
      fail(name(), what + " has unknown type " + std::to_string(d.type));
    }
    record += 4ull * d.size;
    defs.push_back(std::move(d));
  }

  const std::uint64_t n = static_cast<std::uint64_t>(n_points);
  if (n > in_.remaining() / record)
    fail(name(), "header says " + std::to_string(n) + " points of " + std::to_string(record) +
                     " bytes but only " + std::to_string(in_.remaining()) + " bytes follow");
  Particles out;
  resize_for_filling(out.xyz, static_cast<std::size_t>(3 * n));
  std::vector<std::size_t> slot(defs.size(), SIZE_MAX);
  for (std::size_t a = 0; a < defs.size(); ++a) {
    if (!defs[a].keep) continue;
    slot[a] = out.attributes.size();
    Attribute at;
    at.name = defs[a].name;
    at.components = static_cast<int>(defs[a].size);
    at.values.resize(static_cast<std::size_t>(n * defs[a].size));
    out.attributes.push_back(std::move(at));
  }
  const std::size_t rec = static_cast<std::size_t>(record);
  const std::size_t chunk = std::max<std::size_t>(1, (std::size_t(1) << 20) / rec);
  std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(n, chunk)) * rec);
  for (std::uint64_t done = 0; done < n;) {
    const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(n - done, chunk));
    bytes(buf.data(), k * rec, "the point data");
    for (std::size_t i = 0; i < k; ++i) {
      const unsigned char* r = buf.data() + i * rec;
      const std::size_t p = static_cast<std::size_t>(done + i);
      for (int c = 0; c < 3; ++c) out.xyz[3 * p + static_cast<std::size_t>(c)] = load_as<float>(r + 4 * c, true);
      std::size_t off = 16;
      for (std::size_t a = 0; a < defs.size(); ++a) {
        const AttrDef& d = defs[a];
        if (slot[a] != SIZE_MAX) {
          double* dst = out.attributes[slot[a]].values.data() + p * d.size;
          for (std::uint32_t c = 0; c < d.size; ++c)
            dst[c] = d.type == 1 ? static_cast<double>(load_as<std::int32_t>(r + off + 4 * c, true))
                                 : static_cast<double>(load_as<float>(r + off + 4 * c, true));
        }
        off += 4u * d.size;
      }
    }
    done += k;
  }
  // Primitives, groups and detail attributes follow; they are not needed.
  return out;
}

} // namespace

Particles read_bgeo(ByteReader& in, const ReadOptions& o) {
  unsigned char head[2] = {0, 0};
  std::vector<unsigned char> all;
  const unsigned char* mem = in.memory();
  if (mem) {
    if (in.size() >= 2) std::memcpy(head, mem, 2);
  } else {
    // A file: peek at the magic through a memory copy of the whole file
    // only when it is compressed.
    const int c0 = in.peek();
    if (c0 == 0x1f) {
      all = in.read_rest();
      mem = all.data();
      if (all.size() >= 2) std::memcpy(head, mem, 2);
    }
  }
  if (head[0] == 0x1f && head[1] == 0x8b) {
    const std::uint64_t bound = std::min<std::uint64_t>(kMaxInflated, in.size() * kMaxDeflateRatio + 4096);
    std::vector<unsigned char> raw = inflate_all(mem, static_cast<std::size_t>(in.size()), bound, in.name(), "the gzip stream");
    all.clear();
    all.shrink_to_fit();
    ByteReader inner(raw.data(), raw.size(), in.name());
    Bgeo b(inner, o);
    return b.run();
  }
  if (!all.empty()) {
    ByteReader inner(all.data(), all.size(), in.name());
    Bgeo b(inner, o);
    return b.run();
  }
  Bgeo b(in, o);
  return b.run();
}

} // namespace nbmc::io::detail
