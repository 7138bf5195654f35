// SPDX-License-Identifier: MIT
#include "io/mesh.hpp"

#include "io/detail.hpp"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
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
    if (base.empty()) fail(path, "the output path names a folder, not a file");
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
    fail(path, std::string("cannot create a temporary file in ") + (dir.empty() ? "." : dir) + ": " +
                   std::strerror(errno));
  }
  ~AtomicFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!committed_) ::unlink(tmp_.c_str());
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(const char* data, std::size_t n) {
    while (n > 0) {
      const ssize_t k = ::write(fd_, data, n);
      if (k < 0) {
        if (errno == EINTR) continue;
        fail(path_, std::string("write error: ") + std::strerror(errno));
      }
      data += k;
      n -= static_cast<std::size_t>(k);
    }
  }

  void commit() {
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) fail(path_, std::string("write error: ") + std::strerror(errno));
    if (::rename(tmp_.c_str(), path_.c_str()) != 0)
      fail(path_, std::string("cannot replace the file: ") + std::strerror(errno));
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
  if (m.vertex_count > 0 && !m.positions) fail(path, "mesh has vertices but no positions");
  if (m.triangle_count > 0 && !m.triangles) fail(path, "mesh has triangles but no index array");
  const std::uint64_t n = 3 * m.triangle_count;
  for (std::uint64_t i = 0; i < n; ++i)
    if (m.triangles[i] >= m.vertex_count)
      fail(path, "triangle " + std::to_string(i / 3) + " refers to vertex " + std::to_string(m.triangles[i]) +
                     " but the mesh has " + std::to_string(m.vertex_count) + " vertices");
}

void put_floats(char* dst, const float* src, std::size_t n, bool swap) {
  std::memcpy(dst, src, 4 * n);
  if (swap)
    for (std::size_t i = 0; i < n; ++i) std::reverse(dst + 4 * i, dst + 4 * i + 4);
}

void write_ply(Output& out, const MeshView& m) {
  const bool normals = m.normals != nullptr;
  std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by nbmc\n";
  h += "element vertex " + std::to_string(m.vertex_count) + "\n";
  h += "property float x\nproperty float y\nproperty float z\n";
  if (normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  h += "element face " + std::to_string(m.triangle_count) + "\n";
  h += "property list uchar uint vertex_indices\nend_header\n";
  out.put(h);
  const bool swap = !host_is_little_endian();
  for (std::uint64_t i = 0; i < m.vertex_count; ++i) {
    char* p = out.room(24);
    put_floats(p, m.positions + 3 * i, 3, swap);
    if (normals) put_floats(p + 12, m.normals + 3 * i, 3, swap);
    out.advance(normals ? 24 : 12);
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

// Appends " v" for a float in the shortest form that reads back exactly.
inline char* put_float(char* p, char* end, float v) {
  *p++ = ' ';
  return std::to_chars(p, end, v).ptr;
}

inline char* put_index(char* p, char* end, std::uint64_t v) { return std::to_chars(p, end, v).ptr; }

void write_obj(Output& out, const MeshView& m) {
  const bool normals = m.normals != nullptr;
  out.put("# written by nbmc: " + std::to_string(m.vertex_count) + " vertices, " +
          std::to_string(m.triangle_count) + " triangles\n");
  const auto put_vectors = [&](const char* tag, const float* v) {
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
  put_vectors("v", m.positions);
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
        if (have_normals) mesh.normals.reserve(3 * reserve);
        for (; i < el.count; ++i) {
          float v[6] = {0, 0, 0, 0, 0, 0};
          for (std::size_t k = 0; k < el.properties.size(); ++k) {
            if (role[k] >= 0)
              v[role[k]] = static_cast<float>(body.read_real(el.properties[k].type));
            else
              body.skip(el.properties[k]);
          }
          mesh.positions.insert(mesh.positions.end(), v, v + 3);
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

} // namespace

std::string mesh_format(const std::string& path, const std::string& format) {
  if (!format.empty()) {
    std::string f = detail::to_lower(format);
    if (!f.empty() && f[0] == '.') f.erase(0, 1);
    if (f == "ply" || f == "obj") return f;
    fail(path, "unknown mesh format '" + format + "' (supported: ply, obj)");
  }
  const std::string ext = detail::lower_extension(path);
  if (ext == ".ply") return "ply";
  if (ext == ".obj") return "obj";
  if (ext.empty()) fail(path, "no file extension to tell the mesh format (supported: .ply, .obj)");
  fail(path, "unknown mesh extension '" + ext + "' (supported: .ply, .obj)");
}

void write_mesh(const std::string& path, const MeshView& m, const std::string& format,
                const std::function<bool()>& cancelled) {
  const std::string f = mesh_format(path, format);
  check(path, m);
  AtomicFile file(path);
  Output out(file, path, cancelled);
  if (f == "ply")
    write_ply(out, m);
  else
    write_obj(out, m);
  out.flush();
  file.commit();
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
