// SPDX-License-Identifier: MIT
#include "io/mesh.hpp"

#include "io/detail.hpp"
#include "io/mesh_xdmf.hpp"
#include "io/readers.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cctype>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace nbmc::io {

using detail::ByteReader;
using detail::EndOfData;
using detail::fail;
using detail::PlyBody;
using detail::PlyElement;
using detail::PlyHeader;
using detail::PlyProperty;
using detail::PlyType;
using detail::xml_escape;

MeshView Mesh::view() const {
  MeshView v;
  v.positions = positions.empty() ? nullptr : positions.data();
  v.normals = normals.empty() ? nullptr : normals.data();
  v.triangles = triangles.empty() ? nullptr : triangles.data();
  v.vertex_count = vertex_count();
  v.triangle_count = triangle_count();
  return v;
}

namespace {

bool host_is_little_endian() {
  const std::uint16_t one = 1;
  unsigned char first = 0;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

// A file written under a temporary name in the destination's folder and
// renamed over the destination by commit(); removed if never committed.
class AtomicFile {
public:
  explicit AtomicFile(const std::string& path) : path_(path) {
    const std::size_t slash = path.find_last_of('/');
    const std::string dir = slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
    std::string base = slash == std::string::npos ? path : path.substr(slash + 1);
    if (base.empty()) detail::fail_io(path, "the output path names a folder, not a file");
    if (base.size() > 180) base.resize(180); // keep the temporary name under NAME_MAX
    static std::atomic<unsigned> serial{0};
    for (int attempt = 0; attempt < 100; ++attempt) {
      tmp_ = dir + "." + base + ".nbmc-tmp." + std::to_string(::getpid()) + "." + std::to_string(serial++);
      do {
        fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
      } while (fd_ < 0 && errno == EINTR);
      if (fd_ >= 0) return;
      if (errno != EEXIST) break;
    }
    detail::fail_io(path, std::string("cannot create a temporary file in ") + (dir.empty() ? "." : dir) + ": " +
                   std::strerror(errno));
  }
  ~AtomicFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!committed_) ::unlink(tmp_.c_str());
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  // The temporary name, for writers that open the file themselves (HDF5).
  const std::string& temp_path() const { return tmp_; }

  void write(const char* data, std::size_t n) {
    while (n > 0) {
      const ssize_t k = ::write(fd_, data, n);
      if (k < 0) {
        if (errno == EINTR) continue;
        detail::fail_io(path_, std::string("write error: ") + std::strerror(errno));
      }
      data += k;
      n -= static_cast<std::size_t>(k);
    }
  }

  void commit() {
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) detail::fail_io(path_, std::string("write error: ") + std::strerror(errno));
    if (::rename(tmp_.c_str(), path_.c_str()) != 0)
      detail::fail_io(path_, std::string("cannot replace the file: ") + std::strerror(errno));
    committed_ = true;
  }

private:
  std::string path_;
  std::string tmp_;
  int fd_ = -1;
  bool committed_ = false;
};

// A large output buffer in front of an AtomicFile.
class Output {
public:
  Output(AtomicFile& file, const std::string& path, const std::function<bool()>& cancelled)
      : file_(file), path_(path), cancelled_(cancelled), buf_(kSize) {}

  // Pointer to at least n (<= kReserve) free bytes.
  char* room(std::size_t n) {
    if (kSize - used_ < n) flush();
    return buf_.data() + used_;
  }
  void advance(std::size_t n) { used_ += n; }
  void put(const char* s, std::size_t n) {
    while (n > 0) {
      if (used_ == kSize) flush();
      const std::size_t k = std::min(n, kSize - used_);
      std::memcpy(buf_.data() + used_, s, k);
      used_ += k;
      s += k;
      n -= k;
    }
  }
  void put(const std::string& s) { put(s.data(), s.size()); }
  void flush() {
    if (cancelled_ && cancelled_()) throw Cancelled(path_ + ": cancelled while writing (nothing written)");
    file_.write(buf_.data(), used_);
    used_ = 0;
  }

  static constexpr std::size_t kSize = std::size_t(8) << 20;
  static constexpr std::size_t kReserve = 256;

private:
  AtomicFile& file_;
  const std::string& path_;
  const std::function<bool()>& cancelled_;
  std::vector<char> buf_;
  std::size_t used_ = 0;
};

void check(const std::string& path, const MeshView& m) {
  if (m.vertex_count > 0 && !m.positions && !m.positions64) fail(path, "mesh has vertices but no positions");
  if (m.attribute_count > 0 && !m.attributes) fail(path, "mesh has attributes but no attribute array");
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    const Attribute& at = m.attributes[a];
    if (at.components != 1 && at.components != 3)
      fail(path, "attribute '" + at.name + "' has " + std::to_string(at.components) + " components (1 or 3)");
    if (at.values.size() != static_cast<std::size_t>(m.vertex_count) * static_cast<std::size_t>(at.components))
      fail(path, "attribute '" + at.name + "' has " + std::to_string(at.values.size()) + " values for " +
                     std::to_string(m.vertex_count) + " vertices");
    if (at.name.empty()) fail(path, "an attribute has no name");
  }
  if (m.triangle_count > 0 && !m.triangles) fail(path, "mesh has triangles but no index array");
  const std::uint64_t n = 3 * m.triangle_count;
  for (std::uint64_t i = 0; i < n; ++i)
    if (m.triangles[i] >= m.vertex_count)
      fail(path, "triangle " + std::to_string(i / 3) + " refers to vertex " + std::to_string(m.triangles[i]) +
                     " but the mesh has " + std::to_string(m.vertex_count) + " vertices");
}

// An attribute name usable as a PLY property or a legacy VTK array name.
std::string safe_name(const std::string& s) {
  std::string out;
  for (char c : s) {
    const unsigned char u = static_cast<unsigned char>(c);
    out += (u > 0x20 && u < 0x7f) ? c : '_';
  }
  return out.empty() ? std::string("attribute") : out;
}

// n floats or doubles (T) to dst, byte-swapped if swap.
template <class T>
void put_floats(char* dst, const T* src, std::size_t n, bool swap) {
  constexpr std::size_t s = sizeof(T);
  std::memcpy(dst, src, s * n);
  if (swap)
    for (std::size_t i = 0; i < n; ++i) std::reverse(dst + s * i, dst + s * i + s);
}

// Appends n floats or doubles to out, byte-swapped if swap, in bounded chunks.
template <class T>
void put_float_array(Output& out, const T* src, std::size_t n, bool swap) {
  for (std::size_t off = 0; off < n; off += 64) {
    const std::size_t k = std::min<std::size_t>(64, n - off);
    put_floats(out.room(sizeof(T) * k), src + off, k, swap);
    out.advance(sizeof(T) * k);
  }
}

void write_ply(Output& out, const MeshView& m) {
  const bool normals = m.normals != nullptr;
  std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by nbmc\n";
  h += "element vertex " + std::to_string(m.vertex_count) + "\n";
  const bool f64 = m.positions64 != nullptr;  // double positions (nbmc_params.double_positions)
  h += f64 ? "property double x\nproperty double y\nproperty double z\n"
           : "property float x\nproperty float y\nproperty float z\n";
  if (normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  std::size_t extra = 0;
  std::vector<std::string> taken = {"x", "y", "z", "nx", "ny", "nz"};
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    const Attribute& at = m.attributes[a];
    std::string nm = safe_name(at.name);
    // Property names must be unique within the element.
    const auto clash = [&](const std::string& n) {
      for (const char* suffix : {"", "_x", "_y", "_z"})
        if (std::find(taken.begin(), taken.end(), n + suffix) != taken.end()) return true;
      return false;
    };
    while (clash(nm)) nm += "_";
    if (at.components == 1) {
      taken.push_back(nm);
    } else {
      for (const char* suffix : {"_x", "_y", "_z"}) taken.push_back(nm + suffix);
    }
    if (at.components == 1)
      h += "property float " + nm + "\n";
    else
      h += "property float " + nm + "_x\nproperty float " + nm + "_y\nproperty float " + nm + "_z\n";
    extra += static_cast<std::size_t>(at.components);
  }
  h += "element face " + std::to_string(m.triangle_count) + "\n";
  h += "property list uchar uint vertex_indices\nend_header\n";
  out.put(h);
  const bool swap = !host_is_little_endian();
  std::vector<float> values(extra);
  for (std::uint64_t i = 0; i < m.vertex_count; ++i) {
    const std::size_t ps = f64 ? 24 : 12;  // bytes of a position
    char* p = out.room(36);
    if (f64) put_floats(p, m.positions64 + 3 * i, 3, swap);
    else put_floats(p, m.positions + 3 * i, 3, swap);
    if (normals) put_floats(p + ps, m.normals + 3 * i, 3, swap);
    out.advance(normals ? ps + 12 : ps);
    if (extra) {
      std::size_t k = 0;
      for (std::size_t a = 0; a < m.attribute_count; ++a) {
        const Attribute& at = m.attributes[a];
        const std::size_t c = static_cast<std::size_t>(at.components);
        for (std::size_t j = 0; j < c; ++j) values[k++] = static_cast<float>(at.values[i * c + j]);
      }
      put_float_array(out, values.data(), extra, swap);
    }
  }
  for (std::uint64_t i = 0; i < m.triangle_count; ++i) {
    char* p = out.room(13);
    p[0] = 3;
    std::memcpy(p + 1, m.triangles + 3 * i, 12);
    if (swap)
      for (int k = 0; k < 3; ++k) std::reverse(p + 1 + 4 * k, p + 5 + 4 * k);
    out.advance(13);
  }
}

// Appends " v" for a float or double in the shortest form that reads back
// exactly.
template <class T>
inline char* put_float(char* p, char* end, T v) {
  *p++ = ' ';
  return std::to_chars(p, end, v).ptr;
}

inline char* put_index(char* p, char* end, std::uint64_t v) { return std::to_chars(p, end, v).ptr; }

void write_obj(Output& out, const MeshView& m) {
  const bool normals = m.normals != nullptr;
  out.put("# written by nbmc: " + std::to_string(m.vertex_count) + " vertices, " +
          std::to_string(m.triangle_count) + " triangles\n");
  const auto put_vectors = [&](const char* tag, const auto* v) {
    for (std::uint64_t i = 0; i < m.vertex_count; ++i) {
      char* const start = out.room(Output::kReserve);
      char* const end = start + Output::kReserve;
      char* p = start;
      *p++ = tag[0];
      if (tag[1]) *p++ = tag[1];
      for (int k = 0; k < 3; ++k) p = put_float(p, end, v[3 * i + k]);
      *p++ = '\n';
      out.advance(static_cast<std::size_t>(p - start));
    }
  };
  if (m.positions64) put_vectors("v", m.positions64);
  else put_vectors("v", m.positions);
  if (normals) put_vectors("vn", m.normals);
  for (std::uint64_t i = 0; i < m.triangle_count; ++i) {
    char* const start = out.room(Output::kReserve);
    char* const end = start + Output::kReserve;
    char* p = start;
    *p++ = 'f';
    for (int k = 0; k < 3; ++k) {
      const std::uint64_t idx = std::uint64_t(m.triangles[3 * i + k]) + 1;
      *p++ = ' ';
      p = put_index(p, end, idx);
      if (normals) {
        *p++ = '/';
        *p++ = '/';
        p = put_index(p, end, idx);
      }
    }
    *p++ = '\n';
    out.advance(static_cast<std::size_t>(p - start));
  }
}

// --------------------------------------------------------------- PLY reader
Mesh parse_ply(ByteReader& in) {
  const std::string& name = in.name();
  const PlyHeader h = detail::read_ply_header(in);
  const int vi = h.find("vertex");
  const int fi = h.find("face");
  if (vi < 0) fail(name, "PLY file has no 'vertex' element");

  const PlyElement& ve = h.elements[static_cast<std::size_t>(vi)];
  const char* names[6] = {"x", "y", "z", "nx", "ny", "nz"};
  int slot_of[6];
  for (int a = 0; a < 6; ++a) slot_of[a] = ve.find(names[a]);
  for (int a = 0; a < 3; ++a)
    if (slot_of[a] < 0) fail(name, std::string("the vertex element has no '") + names[a] + "' property");
  const bool have_normals = slot_of[3] >= 0 && slot_of[4] >= 0 && slot_of[5] >= 0;
  std::vector<int> role(ve.properties.size(), -1); // property -> 0..5 or -1
  for (int a = 0; a < (have_normals ? 6 : 3); ++a) {
    const PlyProperty& p = ve.properties[static_cast<std::size_t>(slot_of[a])];
    if (p.is_list) fail(name, std::string("vertex property '") + names[a] + "' is a list");
    role[static_cast<std::size_t>(slot_of[a])] = a;
  }

  int index_prop = -1;
  if (fi >= 0) {
    const PlyElement& fe = h.elements[static_cast<std::size_t>(fi)];
    index_prop = fe.find("vertex_indices");
    if (index_prop < 0) index_prop = fe.find("vertex_index");
    if (index_prop < 0) fail(name, "the face element has no 'vertex_indices' property");
    const PlyProperty& p = fe.properties[static_cast<std::size_t>(index_prop)];
    if (!p.is_list || detail::ply_type_is_float(p.type))
      fail(name, "face property '" + p.name + "' is not a list of integers");
  }

  Mesh mesh;
  PlyBody body(in, h.format);
  const bool ascii = h.format == detail::PlyFormat::ascii;
  bool done_v = false;
  bool done_f = fi < 0;
  for (std::size_t e = 0; e < h.elements.size() && !(done_v && done_f); ++e) {
    const PlyElement& el = h.elements[e];
    std::uint64_t i = 0;
    try {
      if (static_cast<int>(e) == vi) {
        // Minimum bytes per vertex: binary, the fixed scalars; ascii, two per value.
        std::uint64_t min_bytes = 0;
        for (const PlyProperty& p : el.properties)
          min_bytes += ascii ? 2 : (p.is_list ? detail::ply_type_size(p.count_type) : detail::ply_type_size(p.type));
        const std::uint64_t bound = min_bytes ? (in.remaining() + 1) / min_bytes : el.count;
        const std::size_t reserve = static_cast<std::size_t>(std::min(el.count, bound));
        mesh.positions.reserve(3 * reserve);
        mesh.positions64.reserve(3 * reserve);
        if (have_normals) mesh.normals.reserve(3 * reserve);
        for (; i < el.count; ++i) {
          double x[3] = {0, 0, 0};
          float v[6] = {0, 0, 0, 0, 0, 0};
          for (std::size_t k = 0; k < el.properties.size(); ++k) {
            if (role[k] >= 0) {
              const double r = body.read_real(el.properties[k].type);
              v[role[k]] = static_cast<float>(r);
              if (role[k] < 3) x[role[k]] = r;
            } else {
              body.skip(el.properties[k]);
            }
          }
          mesh.positions.insert(mesh.positions.end(), v, v + 3);
          mesh.positions64.insert(mesh.positions64.end(), x, x + 3);
          if (have_normals) mesh.normals.insert(mesh.normals.end(), v + 3, v + 6);
        }
        done_v = true;
      } else if (static_cast<int>(e) == fi) {
        const PlyProperty& ip = el.properties[static_cast<std::size_t>(index_prop)];
        const std::uint64_t min_bytes =
            ascii ? 8 : detail::ply_type_size(ip.count_type) + 3 * detail::ply_type_size(ip.type);
        const std::size_t reserve =
            static_cast<std::size_t>(std::min(el.count, (in.remaining() + 1) / min_bytes));
        mesh.triangles.reserve(3 * reserve);
        const std::uint64_t nv = done_v ? mesh.vertex_count() : ve.count;
        for (; i < el.count; ++i) {
          for (std::size_t k = 0; k < el.properties.size(); ++k) {
            if (static_cast<int>(k) != index_prop) {
              body.skip(el.properties[k]);
              continue;
            }
            const std::uint64_t n = body.read_index(ip.count_type, "face size");
            if (n != 3)
              fail(name, "face " + std::to_string(i) + " has " + std::to_string(n) +
                             " vertices (only triangles are supported)");
            for (int c = 0; c < 3; ++c) {
              const std::uint64_t idx = body.read_index(ip.type, "vertex index");
              if (idx >= nv)
                fail(name, "face " + std::to_string(i) + " refers to vertex " + std::to_string(idx) +
                               " but there are " + std::to_string(nv) + " vertices");
              mesh.triangles.push_back(static_cast<std::uint32_t>(idx));
            }
          }
        }
        done_f = true;
      } else {
        body.skip_element(el);
      }
    } catch (const EndOfData&) {
      if (static_cast<int>(e) == vi || static_cast<int>(e) == fi)
        fail(name, "header says " + std::to_string(el.count) + " " + el.name + " elements but the file ends after " +
                       std::to_string(i));
      fail(name, "the file ends inside element '" + el.name + "'");
    }
  }
  return mesh;
}

// ------------------------------------------------------------ legacy VTK
// Appends n floats or doubles in big-endian order (legacy VTK binary data).
template <class T>
void put_floats_be(Output& out, const T* src, std::size_t n) {
  put_float_array(out, src, n, host_is_little_endian());
}

void put_i32_be(char* p, std::int32_t v) {
  std::uint32_t u = static_cast<std::uint32_t>(v);
  for (int i = 3; i >= 0; --i) {
    p[i] = static_cast<char>(u & 0xff);
    u >>= 8;
  }
}

void write_vtk(Output& out, const std::string& path, const MeshView& m) {
  if (m.triangle_count > (std::uint64_t(INT32_MAX) / 4) || m.vertex_count > std::uint64_t(INT32_MAX))
    fail(path, "mesh too large for legacy VTK (32-bit cell lists); write .vtu instead");
  std::string h = "# vtk DataFile Version 4.2\nwritten by nbmc\nBINARY\nDATASET POLYDATA\n";
  h += "POINTS " + std::to_string(m.vertex_count) + (m.positions64 ? " double\n" : " float\n");
  out.put(h);
  if (m.positions64) put_floats_be(out, m.positions64, static_cast<std::size_t>(3 * m.vertex_count));
  else put_floats_be(out, m.positions, static_cast<std::size_t>(3 * m.vertex_count));
  out.put("\nPOLYGONS " + std::to_string(m.triangle_count) + " " + std::to_string(4 * m.triangle_count) + "\n");
  for (std::uint64_t i = 0; i < m.triangle_count; ++i) {
    char* p = out.room(16);
    put_i32_be(p, 3);
    for (int k = 0; k < 3; ++k) put_i32_be(p + 4 + 4 * k, static_cast<std::int32_t>(m.triangles[3 * i + k]));
    out.advance(16);
  }
  out.put("\n");
  if (!m.normals && m.attribute_count == 0) return;
  out.put("POINT_DATA " + std::to_string(m.vertex_count) + "\n");
  if (m.normals) {
    out.put("NORMALS Normals float\n");
    put_floats_be(out, m.normals, static_cast<std::size_t>(3 * m.vertex_count));
    out.put("\n");
  }
  std::vector<float> tmp;
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    const Attribute& at = m.attributes[a];
    const std::string nm = safe_name(at.name);
    if (at.components == 1)
      out.put("SCALARS " + nm + " float 1\nLOOKUP_TABLE default\n");
    else
      out.put("VECTORS " + nm + " float\n");
    tmp.assign(at.values.begin(), at.values.end());
    put_floats_be(out, tmp.data(), tmp.size());
    out.put("\n");
  }
}

// ---------------------------------------------------------------- VTU, VTP
void put_u64_le(Output& out, std::uint64_t v) {
  char b[8];
  for (int i = 0; i < 8; ++i) b[i] = static_cast<char>((v >> (8 * i)) & 0xff);
  out.put(b, 8);
}

// VTK XML with raw appended data (UInt64 headers, uncompressed): an
// UnstructuredGrid of triangles (.vtu) or PolyData with the triangles as
// Polys (.vtp). Both share points, point data, connectivity and offsets;
// only the .vtu has cell types.
void write_vtk_xml(Output& out, const MeshView& m, bool polydata) {
  const std::uint64_t nv = m.vertex_count, nt = m.triangle_count;
  // Appended blocks in order: points, normals, attributes, connectivity,
  // offsets, types; each is a UInt64 byte count and the little-endian data.
  std::uint64_t offset = 0;
  const auto array = [&](const std::string& name, const char* type, int comps, std::uint64_t bytes) {
    std::string a = "        <DataArray type=\"" + std::string(type) + "\"";
    if (!name.empty()) a += " Name=\"" + xml_escape(name) + "\"";
    if (comps != 1) a += " NumberOfComponents=\"" + std::to_string(comps) + "\"";
    a += " format=\"appended\" offset=\"" + std::to_string(offset) + "\"/>\n";
    offset += 8 + bytes;
    return a;
  };
  // Points come after the point data in the XML, but their block is first
  // in the appended section: the offsets follow the block order.
  std::string points = "      <Points>\n";
  const std::uint64_t point_bytes = (m.positions64 ? 24 : 12) * nv;
  points += array("Points", m.positions64 ? "Float64" : "Float32", 3, point_bytes);
  points += "      </Points>\n";
  std::string pdata;
  if (m.normals || m.attribute_count) {
    pdata = "      <PointData";
    if (m.normals) pdata += " Normals=\"Normals\"";
    pdata += ">\n";
    if (m.normals) pdata += array("Normals", "Float32", 3, 12 * nv);
    for (std::size_t a = 0; a < m.attribute_count; ++a)
      pdata += array(m.attributes[a].name, "Float32", m.attributes[a].components,
                     4 * nv * static_cast<std::uint64_t>(m.attributes[a].components));
    pdata += "      </PointData>\n";
  }
  // (One statement each: the offsets depend on the order of the calls.)
  const std::string section = polydata ? "Polys" : "Cells";
  std::string cells = "      <" + section + ">\n";
  cells += array("connectivity", "Int64", 1, 24 * nt);
  cells += array("offsets", "Int64", 1, 8 * nt);
  if (!polydata) cells += array("types", "UInt8", 1, nt);
  cells += "      </" + section + ">\n";
  const std::string type = polydata ? "PolyData" : "UnstructuredGrid";
  std::string head = "<?xml version=\"1.0\"?>\n<VTKFile type=\"" + type + "\" version=\"1.0\" "
                     "byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <" + type + ">\n";
  head += "    <Piece NumberOfPoints=\"" + std::to_string(nv) + "\" ";
  head += polydata ? "NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\""
                    : "NumberOfCells=\"";
  head += std::to_string(nt) + "\">\n";
  head += pdata + points + cells;
  head += "    </Piece>\n  </" + type + ">\n  <AppendedData encoding=\"raw\">\n   _";
  out.put(head);

  const bool swap = !host_is_little_endian();
  const auto floats = [&](const float* src, std::size_t n) { put_float_array(out, src, n, swap); };
  put_u64_le(out, point_bytes);
  if (m.positions64) put_float_array(out, m.positions64, static_cast<std::size_t>(3 * nv), swap);
  else floats(m.positions, static_cast<std::size_t>(3 * nv));
  if (m.normals) {
    put_u64_le(out, 12 * nv);
    floats(m.normals, static_cast<std::size_t>(3 * nv));
  }
  std::vector<float> tmp;
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    const Attribute& at = m.attributes[a];
    put_u64_le(out, 4 * nv * static_cast<std::uint64_t>(at.components));
    tmp.assign(at.values.begin(), at.values.end());
    floats(tmp.data(), tmp.size());
  }
  put_u64_le(out, 24 * nt);
  for (std::uint64_t i = 0; i < 3 * nt; ++i) put_u64_le(out, m.triangles[i]);
  put_u64_le(out, 8 * nt);
  for (std::uint64_t i = 0; i < nt; ++i) put_u64_le(out, 3 * (i + 1));
  if (!polydata) {
    put_u64_le(out, nt);
    for (std::uint64_t i = 0; i < nt; ++i) {
      *out.room(1) = 5; // VTK_TRIANGLE
      out.advance(1);
    }
  }
  out.put("\n  </AppendedData>\n</VTKFile>\n");
}

// ---------------------------------------------------------------- glTF
std::string json_float(float v) {
  if (!std::isfinite(v)) return "0";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

void put_u32_le(char* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<char>((v >> (8 * i)) & 0xff);
}

void write_glb(Output& out, const std::string& path, const MeshView& m) {
  const std::uint64_t nv = m.vertex_count, nt = m.triangle_count;
  // Buffer layout: positions, normals, attributes, indices (all 4-byte aligned).
  struct View {
    std::uint64_t offset, length;
    int target; // 34962 ARRAY_BUFFER, 34963 ELEMENT_ARRAY_BUFFER
  };
  std::vector<View> views;
  std::uint64_t bin = 0;
  const auto add_view = [&](std::uint64_t len, int target) {
    views.push_back({bin, len, target});
    bin += len;
    return views.size() - 1;
  };
  std::string attrs, accessors;
  std::size_t accessor_count = 0;
  const auto add_accessor = [&](std::size_t view, int comp_type, std::uint64_t count, const char* type,
                                const std::string& extra) {
    if (accessor_count) accessors += ",";
    accessors += "{\"bufferView\":" + std::to_string(view) + ",\"componentType\":" + std::to_string(comp_type) +
                 ",\"count\":" + std::to_string(count) + ",\"type\":\"" + type + "\"" + extra + "}";
    return accessor_count++;
  };
  std::string json = "{\"asset\":{\"version\":\"2.0\",\"generator\":\"nbmc\"},\"scene\":0,";
  if (nv == 0) {
    json += "\"scenes\":[{\"nodes\":[]}]}";
  } else {
    if (nv > UINT32_MAX) fail(path, "too many vertices for glTF");
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = m.positions[a];
    for (std::uint64_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) {
        const float v = m.positions[3 * i + static_cast<std::uint64_t>(a)];
        if (!std::isfinite(v)) fail(path, "vertex " + std::to_string(i) + " is not finite (glTF needs finite positions)");
        lo[a] = std::min(lo[a], v);
        hi[a] = std::max(hi[a], v);
      }
    const std::string mm = ",\"min\":[" + json_float(lo[0]) + "," + json_float(lo[1]) + "," + json_float(lo[2]) +
                           "],\"max\":[" + json_float(hi[0]) + "," + json_float(hi[1]) + "," + json_float(hi[2]) + "]";
    attrs += "\"POSITION\":" + std::to_string(add_accessor(add_view(12 * nv, 34962), 5126, nv, "VEC3", mm));
    if (m.normals)
      attrs += ",\"NORMAL\":" + std::to_string(add_accessor(add_view(12 * nv, 34962), 5126, nv, "VEC3", ""));
    std::vector<std::string> used;
    for (std::size_t a = 0; a < m.attribute_count; ++a) {
      const Attribute& at = m.attributes[a];
      std::string sem = "_";
      for (char c : at.name) {
        const unsigned char u = static_cast<unsigned char>(c);
        sem += std::isalnum(u) ? static_cast<char>(std::toupper(u)) : '_';
      }
      while (std::find(used.begin(), used.end(), sem) != used.end()) sem += "_";
      used.push_back(sem);
      const std::size_t view = add_view(4 * nv * static_cast<std::uint64_t>(at.components), 34962);
      attrs += ",\"" + sem + "\":" +
               std::to_string(add_accessor(view, 5126, nv, at.components == 1 ? "SCALAR" : "VEC3", ""));
    }
    std::string prim = "{\"attributes\":{" + attrs + "}";
    if (nt > 0) {
      if (3 * nt > UINT32_MAX) fail(path, "too many triangles for glTF");
      prim += ",\"indices\":" + std::to_string(add_accessor(add_view(12 * nt, 34963), 5125, 3 * nt, "SCALAR", "")) +
              ",\"mode\":4}";
    } else {
      prim += ",\"mode\":0}";
    }
    json += "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],\"meshes\":[{\"primitives\":[" + prim + "]}],";
    json += "\"buffers\":[{\"byteLength\":" + std::to_string(bin) + "}],\"bufferViews\":[";
    for (std::size_t i = 0; i < views.size(); ++i) {
      if (i) json += ",";
      json += "{\"buffer\":0,\"byteOffset\":" + std::to_string(views[i].offset) +
              ",\"byteLength\":" + std::to_string(views[i].length) + ",\"target\":" + std::to_string(views[i].target) +
              "}";
    }
    json += "],\"accessors\":[" + accessors + "]}";
  }
  while (json.size() % 4) json += ' ';
  const std::uint64_t total = 12 + 8 + json.size() + (bin ? 8 + bin : 0);
  if (total > UINT32_MAX) fail(path, "mesh too large for one .glb file (4 GiB)");
  char head[20];
  std::memcpy(head, "glTF", 4);
  put_u32_le(head + 4, 2);
  put_u32_le(head + 8, static_cast<std::uint32_t>(total));
  put_u32_le(head + 12, static_cast<std::uint32_t>(json.size()));
  std::memcpy(head + 16, "JSON", 4);
  out.put(head, 20);
  out.put(json);
  if (!bin) return;
  char chunk[8];
  put_u32_le(chunk, static_cast<std::uint32_t>(bin));
  std::memcpy(chunk + 4, "BIN\0", 4);
  out.put(chunk, 8);
  const bool swap = !host_is_little_endian();
  const auto floats = [&](const float* src, std::size_t n) { put_float_array(out, src, n, swap); };
  floats(m.positions, static_cast<std::size_t>(3 * nv));
  if (m.normals) {
    // glTF requires unit normals: normalise, and give degenerate ones +z.
    for (std::uint64_t i = 0; i < nv; ++i) {
      float n[3] = {m.normals[3 * i], m.normals[3 * i + 1], m.normals[3 * i + 2]};
      const double len = std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]);
      if (std::isfinite(len) && len > 1e-30) {
        for (float& c : n) c = static_cast<float>(c / len);
      } else {
        n[0] = n[1] = 0;
        n[2] = 1;
      }
      put_floats(out.room(12), n, 3, swap);
      out.advance(12);
    }
  }
  std::vector<float> tmp;
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    tmp.assign(m.attributes[a].values.begin(), m.attributes[a].values.end());
    floats(tmp.data(), tmp.size());
  }
  for (std::uint64_t i = 0; i < 3 * nt; ++i) {
    put_u32_le(out.room(4), m.triangles[i]);
    out.advance(4);
  }
}

} // namespace

namespace {
// "out/s.h5:/frame_3" -> "out/s.h5", "/frame_3"; other paths stay whole.
void split_output(const std::string& path, std::string& file, std::string& group) {
  file = path;
  group.clear();
  detail::split_hdf5_path(path, false, file, group);
}

// The mesh into an HDF5 file (a new file, or a group of an existing one),
// then the XDMF descriptor of everything the file holds.
void write_h5(const std::string& path, const MeshView& m, const std::function<bool()>& cancelled) {
  std::string file, group;
  split_output(path, file, group);
  if (group.empty() || group == "/") {
    AtomicFile tmp(file);
    detail::write_hdf5_mesh(tmp.temp_path(), file, "/", true, m, cancelled);
    tmp.commit();
  } else {
    detail::write_hdf5_mesh(file, file, group, false, m, cancelled);
  }
  std::string xdmf = file.substr(0, file.size() - detail::lower_extension(file).size()) + ".xdmf";
  if (xdmf == file) xdmf += ".xdmf"; // never over the HDF5 file itself
  const std::size_t slash = file.find_last_of('/');
  const std::string ref = slash == std::string::npos ? file : file.substr(slash + 1); // next to the .xdmf
  const std::string text = detail::xdmf_for_hdf5(file, file, ref);
  AtomicFile x(xdmf);
  x.write(text.data(), text.size());
  x.commit();
}
} // namespace

std::string mesh_format(const std::string& path, const std::string& format) {
  static const char* kSupported = "supported: .ply, .obj, .vtk, .vtu, .vtp, .glb, .h5";
  static const char* kNames[] = {"ply", "obj", "vtk", "vtu", "vtp", "glb", "h5"};
  if (!format.empty()) {
    std::string f = detail::to_lower(format);
    if (!f.empty() && f[0] == '.') f.erase(0, 1);
    if (f == "hdf5") f = "h5";
    for (const char* n : kNames)
      if (f == n) return f;
    detail::fail_arg(path, "unknown mesh format '" + format + "' (supported: ply, obj, vtk, vtu, vtp, glb, h5)");
  }
  std::string file, group;
  split_output(path, file, group);
  if (!group.empty()) return "h5";
  const std::string ext = detail::lower_extension(path);
  if (ext == ".hdf5") return "h5";
  for (const char* n : kNames)
    if (ext.size() > 1 && ext.compare(1, std::string::npos, n) == 0) return n;
  if (ext.empty()) fail(path, std::string("no file extension to tell the mesh format (") + kSupported + ")");
  fail(path, "unknown mesh extension '" + ext + "' (" + kSupported + ")");
}

std::string mesh_output_file(const std::string& path) {
  std::string file, group;
  split_output(path, file, group);
  return file;
}

bool mesh_output_exists(const std::string& path) {
  std::string file, group;
  split_output(path, file, group);
  if (!group.empty()) return detail::hdf5_mesh_exists(file, group);
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

void write_mesh(const std::string& path, const MeshView& m, const std::string& format,
                const std::function<bool()>& cancelled) {
  const std::string f = mesh_format(path, format);
  check(path, m);
  if (f == "h5") return write_h5(path, m, cancelled);
  // glTF has float positions only: double positions are rounded.
  MeshView rounded_view = m;
  std::vector<float> rounded;
  if (f == "glb" && !m.positions && m.positions64) {
    rounded.assign(m.positions64, m.positions64 + 3 * m.vertex_count);
    rounded_view.positions = rounded.data();
  }
  AtomicFile file(path);
  Output out(file, path, cancelled);
  if (f == "ply")
    write_ply(out, m);
  else if (f == "obj")
    write_obj(out, m);
  else if (f == "vtk")
    write_vtk(out, path, m);
  else if (f == "vtu" || f == "vtp")
    write_vtk_xml(out, m, f == "vtp");
  else
    write_glb(out, path, rounded_view);
  out.flush();
  file.commit();
}

namespace {
Mesh mesh_from(Particles&& p, std::vector<std::uint32_t>&& tris) {
  Mesh m;
  m.positions.assign(p.xyz.begin(), p.xyz.end());
  m.positions64 = p.xyz;
  m.triangles = std::move(tris);
  for (Attribute& a : p.attributes) {
    if (a.name == "Normals" && a.components == 3 && m.normals.empty())
      m.normals.assign(a.values.begin(), a.values.end());
    else
      m.attributes.push_back(std::move(a));
  }
  return m;
}

Mesh parse_mesh_any(ByteReader& in, const std::string& f) {
  std::vector<std::uint32_t> tris;
  ReadOptions o;
  if (f == "ply") return parse_ply(in);
  if (f == "vtk") {
    Particles p = detail::read_vtk_legacy(in, o, &tris);
    return mesh_from(std::move(p), std::move(tris));
  }
  if (f == "vtu" || f == "vtp") {
    std::vector<unsigned char> all;
    const unsigned char* mem = in.memory();
    if (!mem) {
      all = in.read_rest();
      mem = all.data();
    }
    Particles p = detail::read_vtk_xml(mem, static_cast<std::size_t>(in.size()), in.name(), o, &tris);
    return mesh_from(std::move(p), std::move(tris));
  }
  detail::fail_arg(in.name(), "cannot read meshes in format '" + f + "' (ply, vtk, vtu, vtp)");
}

std::string mesh_read_format(const std::string& path, const std::string& format) {
  std::string f = format.empty() ? detail::lower_extension(path) : detail::to_lower(format);
  if (!f.empty() && f[0] == '.') f.erase(0, 1);
  if (f == "ply" || f == "vtk" || f == "vtu" || f == "vtp") return f;
  detail::fail_arg(path, "cannot read meshes in format '" + f + "' (ply, vtk, vtu, vtp)");
}
} // namespace

Mesh read_mesh(const std::string& path, const std::string& format) {
  const std::string f = mesh_read_format(path, format);
  ByteReader in(path);
  return parse_mesh_any(in, f);
}

Mesh parse_mesh(const void* data, std::size_t size, const std::string& format, const std::string& name) {
  const std::string f = mesh_read_format(name, format);
  ByteReader in(data, size, name);
  return parse_mesh_any(in, f);
}

Mesh read_mesh_ply(const std::string& path) {
  ByteReader in(path);
  return parse_ply(in);
}

Mesh parse_mesh_ply(const void* data, std::size_t size, const std::string& name) {
  ByteReader in(data, size, name);
  return parse_ply(in);
}

} // namespace nbmc::io
