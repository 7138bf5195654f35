// SPDX-License-Identifier: MIT
#include "io/particles.hpp"

#include "io/detail.hpp"

#include <algorithm>
#include <cstdint>
#include <cstring>

namespace nbmc::io {

using detail::ByteReader;
using detail::EndOfData;
using detail::fail;
using detail::PlyBody;
using detail::PlyElement;
using detail::PlyFormat;
using detail::PlyHeader;
using detail::PlyProperty;
using detail::PlyType;

namespace {

bool host_is_little_endian() {
  const std::uint16_t one = 1;
  unsigned char first = 0;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

// ------------------------------------------------------------------ raw xyz
Particles read_xyz(ByteReader& in) {
  const std::uint64_t size = in.size();
  if (size % 12 != 0)
    fail(in.name(), "size " + std::to_string(size) +
                        " bytes is not a multiple of 12 (a raw .xyz file holds float32 x, y, z triples)");
  const std::uint64_t n = size / 12;
  Particles p;
  p.xyz.resize(static_cast<std::size_t>(3 * n));
  const bool swap = !host_is_little_endian();
  constexpr std::size_t kChunk = 1 << 16; // particles per read
  std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(n, kChunk)) * 12);
  double* out = p.xyz.data();
  for (std::uint64_t done = 0; done < n;) {
    const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(n - done, kChunk));
    if (in.read(buf.data(), k * 12) != k * 12)
      fail(in.name(), "file ends after " + std::to_string(in.tell()) + " of " + std::to_string(size) +
                          " bytes (did it change while being read?)");
    for (std::size_t i = 0; i < 3 * k; ++i) {
      unsigned char* b = buf.data() + 4 * i;
      if (swap) std::reverse(b, b + 4);
      float v;
      std::memcpy(&v, b, 4);
      out[i] = v;
    }
    out += 3 * k;
    done += k;
  }
  return p;
}

// ---------------------------------------------------------------------- PLY
double load(PlyType t, const unsigned char* src, bool swap) {
  unsigned char b[8];
  const std::size_t n = detail::ply_type_size(t);
  std::memcpy(b, src, n);
  if (swap) std::reverse(b, b + n);
  if (t == PlyType::float64) {
    double v;
    std::memcpy(&v, b, 8);
    return v;
  }
  float v;
  std::memcpy(&v, b, 4);
  return v;
}

Particles read_ply(ByteReader& in) {
  const std::string& name = in.name();
  const PlyHeader h = detail::read_ply_header(in);
  const int vi = h.find("vertex");
  if (vi < 0) fail(name, "PLY file has no 'vertex' element");
  const PlyElement& v = h.elements[static_cast<std::size_t>(vi)];

  int axis[3];
  const char* axis_name[3] = {"x", "y", "z"};
  for (const PlyProperty& p : v.properties)
    if (p.is_list)
      fail(name, "vertex property '" + p.name + "' is a list (not supported in a particle file)");
  for (int a = 0; a < 3; ++a) {
    axis[a] = v.find(axis_name[a]);
    if (axis[a] < 0) fail(name, std::string("the vertex element has no '") + axis_name[a] + "' property");
    const PlyType t = v.properties[static_cast<std::size_t>(axis[a])].type;
    if (!detail::ply_type_is_float(t))
      fail(name, std::string("vertex property '") + axis_name[a] + "' has type " + detail::ply_type_name(t) +
                     " (expected float or double)");
  }

  PlyBody body(in, h.format);
  for (int i = 0; i < vi; ++i) {
    try {
      body.skip_element(h.elements[static_cast<std::size_t>(i)]);
    } catch (const EndOfData&) {
      fail(name, "the file ends inside element '" + h.elements[static_cast<std::size_t>(i)].name +
                     "' (before the vertices)");
    }
  }

  const std::uint64_t count = v.count;
  const auto ends_after = [&](std::uint64_t k) {
    fail(name, "header says " + std::to_string(count) + " vertices but the file ends after " + std::to_string(k));
  };
  Particles out;

  if (h.format == PlyFormat::ascii) {
    // Each vertex takes at least 2 bytes per value (digit and separator), so
    // the file size bounds what can really be there.
    const std::uint64_t per_vertex = 2 * v.properties.size();
    const std::uint64_t bound = (in.remaining() + 1) / per_vertex;
    out.xyz.reserve(static_cast<std::size_t>(3 * std::min(count, bound)));
    std::uint64_t i = 0;
    try {
      for (; i < count; ++i) {
        double xyz[3] = {0, 0, 0};
        for (std::size_t k = 0; k < v.properties.size(); ++k) {
          const int a = k == static_cast<std::size_t>(axis[0])   ? 0
                        : k == static_cast<std::size_t>(axis[1]) ? 1
                        : k == static_cast<std::size_t>(axis[2]) ? 2
                                                                 : -1;
          if (a >= 0)
            xyz[a] = body.read_real(v.properties[k].type);
          else
            body.skip(v.properties[k].type);
        }
        out.xyz.insert(out.xyz.end(), xyz, xyz + 3);
      }
    } catch (const EndOfData&) {
      ends_after(i);
    }
    return out;
  }

  // Binary: fixed-size records.
  std::size_t record = 0;
  std::size_t offset[3] = {0, 0, 0};
  for (std::size_t k = 0; k < v.properties.size(); ++k) {
    for (int a = 0; a < 3; ++a)
      if (k == static_cast<std::size_t>(axis[a])) offset[a] = record;
    record += detail::ply_type_size(v.properties[k].type);
  }
  const std::uint64_t available = in.remaining() / record;
  if (count > available) ends_after(available);
  out.xyz.resize(static_cast<std::size_t>(3 * count));
  const bool swap = (h.format == PlyFormat::binary_big_endian) == host_is_little_endian();
  PlyType type[3];
  for (int a = 0; a < 3; ++a) type[a] = v.properties[static_cast<std::size_t>(axis[a])].type;

  const std::size_t chunk = std::max<std::size_t>(1, (std::size_t(1) << 20) / record);
  std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(count, chunk)) * record);
  double* dst = out.xyz.data();
  for (std::uint64_t done = 0; done < count;) {
    const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(count - done, chunk));
    const std::size_t got = in.read(buf.data(), k * record);
    if (got != k * record) ends_after(done + got / record); // the file shrank while being read
    for (std::size_t i = 0; i < k; ++i) {
      const unsigned char* r = buf.data() + i * record;
      for (int a = 0; a < 3; ++a) *dst++ = load(type[a], r + offset[a], swap);
    }
    done += k;
  }
  return out;
}

Particles parse(ByteReader& in, const std::string& format) {
  if (format == "xyz") return read_xyz(in);
  return read_ply(in);
}

} // namespace

std::string particle_format(const std::string& path, const std::string& format) {
  if (!format.empty()) {
    std::string f = detail::to_lower(format);
    if (!f.empty() && f[0] == '.') f.erase(0, 1);
    if (f == "xyz" || f == "ply") return f;
    fail(path, "unknown format '" + format + "' (supported: xyz, ply)");
  }
  const std::string ext = detail::lower_extension(path);
  if (ext == ".xyz") return "xyz";
  if (ext == ".ply") return "ply";
  if (ext.empty()) fail(path, "no file extension to tell the format (supported: .xyz, .ply; use --format)");
  fail(path, "unknown extension '" + ext + "' (supported: .xyz, .ply; use --format)");
}

Particles read_particles(const std::string& path, const std::string& format) {
  const std::string f = particle_format(path, format);
  ByteReader in(path);
  return parse(in, f);
}

Particles parse_particles(const void* data, std::size_t size, const std::string& format,
                          const std::string& name) {
  const std::string f = particle_format(name, format);
  ByteReader in(data, size, name);
  return parse(in, f);
}

} // namespace nbmc::io
