// SPDX-License-Identifier: MIT
#include "io/particles.hpp"
#include "core/huge_pages.hpp"

#include "io/detail.hpp"
#include "io/readers.hpp"

#include <algorithm>
#include <cstdint>
#include <cctype>
#include <cstring>

namespace nbmc::io {

using detail::ByteReader;
using detail::EndOfData;
using detail::fail;
using detail::fail_arg;
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
  resize_for_filling(p.xyz, static_cast<std::size_t>(3 * n));
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

double load_int(PlyType t, const unsigned char* src, bool swap) {
  unsigned char b[8];
  const std::size_t n = detail::ply_type_size(t);
  std::memcpy(b, src, n);
  if (swap) std::reverse(b, b + n);
  switch (t) {
  case PlyType::int8: return static_cast<double>(static_cast<std::int8_t>(b[0]));
  case PlyType::uint8: return static_cast<double>(b[0]);
  case PlyType::int16: { std::int16_t v; std::memcpy(&v, b, 2); return v; }
  case PlyType::uint16: { std::uint16_t v; std::memcpy(&v, b, 2); return v; }
  case PlyType::int32: { std::int32_t v; std::memcpy(&v, b, 4); return v; }
  case PlyType::uint32: { std::uint32_t v; std::memcpy(&v, b, 4); return v; }
  default: return 0;
  }
}

Particles read_ply(ByteReader& in, const ReadOptions& opt) {
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
  // role[k]: 0..2 = axis, 3 + j = attribute j, -1 = skipped.
  std::vector<int> role(v.properties.size(), -1);
  for (int a = 0; a < 3; ++a) role[static_cast<std::size_t>(axis[a])] = a;
  Particles out;
  for (std::size_t k = 0; k < v.properties.size(); ++k) {
    if (role[k] >= 0 || !detail::want_attribute(opt, v.properties[k].name)) continue;
    role[k] = 3 + static_cast<int>(out.attributes.size());
    Attribute at;
    at.name = v.properties[k].name;
    out.attributes.push_back(std::move(at));
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

  if (h.format == PlyFormat::ascii) {
    // Each vertex takes at least 2 bytes per value (digit and separator), so
    // the file size bounds what can really be there.
    const std::uint64_t per_vertex = 2 * v.properties.size();
    const std::size_t bound = static_cast<std::size_t>(std::min(count, (in.remaining() + 1) / per_vertex));
    out.xyz.reserve(3 * bound);
    for (Attribute& at : out.attributes) at.values.reserve(bound);
    std::uint64_t i = 0;
    try {
      for (; i < count; ++i) {
        double xyz[3] = {0, 0, 0};
        for (std::size_t k = 0; k < v.properties.size(); ++k) {
          const int r = role[k];
          if (r < 0)
            body.skip(v.properties[k].type);
          else if (r < 3)
            xyz[r] = body.read_real(v.properties[k].type);
          else
            out.attributes[static_cast<std::size_t>(r - 3)].values.push_back(body.read_real(v.properties[k].type));
        }
        out.xyz.insert(out.xyz.end(), xyz, xyz + 3);
      }
    } catch (const EndOfData&) {
      ends_after(i);
    }
    detail::merge_vector_attributes(out.attributes);
    return out;
  }

  // Binary: fixed-size records.
  std::size_t record = 0;
  std::vector<std::size_t> offset(v.properties.size());
  for (std::size_t k = 0; k < v.properties.size(); ++k) {
    offset[k] = record;
    record += detail::ply_type_size(v.properties[k].type);
  }
  const std::uint64_t available = in.remaining() / record;
  if (count > available) ends_after(available);
  resize_for_filling(out.xyz, static_cast<std::size_t>(3 * count));
  for (Attribute& at : out.attributes) at.values.resize(static_cast<std::size_t>(count));
  const bool swap = (h.format == PlyFormat::binary_big_endian) == host_is_little_endian();
  std::vector<std::size_t> used; // properties read
  for (std::size_t k = 0; k < v.properties.size(); ++k)
    if (role[k] >= 0) used.push_back(k);

  const std::size_t chunk = std::max<std::size_t>(1, (std::size_t(1) << 20) / record);
  std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(count, chunk)) * record);
  for (std::uint64_t done = 0; done < count;) {
    const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(count - done, chunk));
    const std::size_t got = in.read(buf.data(), k * record);
    if (got != k * record) ends_after(done + got / record); // the file shrank while being read
    for (std::size_t i = 0; i < k; ++i) {
      const unsigned char* r = buf.data() + i * record;
      const std::size_t item = static_cast<std::size_t>(done + i);
      for (std::size_t p : used) {
        const PlyType t = v.properties[p].type;
        const double value = detail::ply_type_is_float(t) ? load(t, r + offset[p], swap) : load_int(t, r + offset[p], swap);
        const int ro = role[p];
        if (ro < 3)
          out.xyz[3 * item + static_cast<std::size_t>(ro)] = value;
        else
          out.attributes[static_cast<std::size_t>(ro - 3)].values[item] = value;
      }
    }
    done += k;
  }
  detail::merge_vector_attributes(out.attributes);
  return out;
}

Particles parse(ByteReader& in, const std::string& format, const ReadOptions& opt) {
  if (format == "xyz") return read_xyz(in);
  if (format == "ply") return read_ply(in, opt);
  if (format == "vtk") return detail::read_vtk_legacy(in, opt);
  if (format == "bgeo") return detail::read_bgeo(in, opt);
  if (format == "vtu" || format == "vtp") {
    if (const unsigned char* mem = in.memory()) return detail::read_vtk_xml(mem, in.size(), in.name(), opt);
    const std::vector<unsigned char> all = in.read_rest();
    return detail::read_vtk_xml(all.data(), all.size(), in.name(), opt);
  }
  fail(in.name(), "internal: no reader for format '" + format + "'");
}

bool is_hdf5_format(const std::string& f) { return f == "h5part" || f == "pysph" || f == "gadget" || f == "hdf5"; }

struct FormatName {
  const char* name;
  const char* canonical;
};
const FormatName kFormatNames[] = {{"xyz", "xyz"},   {"ply", "ply"},       {"vtk", "vtk"},       {"vtu", "vtu"},
                                   {"vtp", "vtp"},   {"bgeo", "bgeo"},     {"h5part", "h5part"}, {"pysph", "pysph"},
                                   {"gadget", "gadget"}, {"swift", "gadget"}, {"hdf5", "hdf5"},   {"h5", "hdf5"}};

} // namespace

const std::vector<std::string>& particle_format_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const FormatName& f : kFormatNames) v.emplace_back(f.name);
    return v;
  }();
  return names;
}

std::string particle_format(const std::string& path, const std::string& format) {
  if (!format.empty()) {
    std::string f = detail::to_lower(format);
    if (!f.empty() && f[0] == '.') f.erase(0, 1);
    for (const FormatName& n : kFormatNames)
      if (f == n.name) return n.canonical;
    fail_arg(path, "unknown format '" + format +
                       "' (supported: xyz, ply, vtk, vtu, vtp, bgeo, h5part, pysph, gadget, swift, hdf5)");
  }
  std::string file = path, object;
  if (detail::split_hdf5_path(path, false, file, object)) return "hdf5";
  const std::string lower = detail::to_lower(file);
  const auto ends_with = [&](const char* suffix) {
    const std::size_t n = std::strlen(suffix);
    return lower.size() > n && lower.compare(lower.size() - n, n, suffix) == 0;
  };
  if (ends_with(".bgeo.gz")) return "bgeo";
  const std::string ext = detail::lower_extension(file);
  if (ext == ".xyz") return "xyz";
  if (ext == ".ply") return "ply";
  if (ext == ".vtk") return "vtk";
  if (ext == ".vtu") return "vtu";
  if (ext == ".vtp") return "vtp";
  if (ext == ".bgeo" || ext == ".bhclassic") return "bgeo";
  if (ext == ".h5part") return "h5part";
  if (ext == ".h5" || ext == ".hdf5" || ext == ".hdf" || ext == ".he5") return "hdf5";
  static const char* kSupported =
      "supported: .xyz, .ply, .vtk, .vtu, .vtp, .bgeo, .bgeo.gz, .h5part, .h5, .hdf5; use --format";
  if (ext.empty()) fail(path, std::string("no file extension to tell the format (") + kSupported + ")");
  fail(path, "unknown extension '" + ext + "' (" + kSupported + ")");
}

Particles read_particles(const std::string& path, const std::string& format) {
  ReadOptions o;
  o.format = format;
  return read_particles(path, o);
}

Particles read_particles(const std::string& path, const ReadOptions& options) {
  const std::string f = particle_format(path, options.format);
  if (is_hdf5_format(f)) {
    std::string file = path, object;
    detail::split_hdf5_path(path, true, file, object);
    return detail::read_hdf5_file(file, object, f, options);
  }
  ByteReader in(path);
  return parse(in, f, options);
}

Particles parse_particles(const void* data, std::size_t size, const std::string& format, const std::string& name) {
  ReadOptions o;
  o.format = format;
  return parse_particles(data, size, o, name);
}

Particles parse_particles(const void* data, std::size_t size, const ReadOptions& options, const std::string& name) {
  const std::string f = particle_format(name, options.format);
  if (is_hdf5_format(f)) {
    std::string file = name, object;
    detail::split_hdf5_path(name, false, file, object);
    return detail::read_hdf5_memory(data, size, name, object, f, options);
  }
  ByteReader in(data, size, name);
  return parse(in, f, options);
}

std::vector<std::int64_t> list_frames(const std::string& path, const std::string& format) {
  const std::string f = particle_format(path, format);
  if (f != "h5part" && f != "hdf5") return {};
  std::string file = path, object;
  detail::split_hdf5_path(path, true, file, object);
  return detail::hdf5_steps(file, object, f);
}

// ------------------------------------------------------------ shared helpers
namespace detail {

bool want_attribute(const ReadOptions& o, const std::string& name) {
  if (!o.attributes || name.empty()) return false; // nameless arrays cannot be asked for
  if (o.only.empty()) return true;
  for (const std::string& n : o.only) {
    if (n == name || to_lower(n) == to_lower(name)) return true;
    // A vector attribute merged from <n>x, <n>y, <n>z (or <n>_x ...) is
    // wanted when <n> is.
    if (name.size() == n.size() + 1 || name.size() == n.size() + 2) {
      const char last = static_cast<char>(std::tolower(static_cast<unsigned char>(name.back())));
      const std::string stem = name.substr(0, name.size() - 1);
      const std::string base = !stem.empty() && stem.back() == '_' ? stem.substr(0, stem.size() - 1) : stem;
      if ((last == 'x' || last == 'y' || last == 'z') && to_lower(base) == to_lower(n)) return true;
    }
  }
  return false;
}

void merge_vector_attributes(std::vector<Attribute>& list) {
  const auto find = [&](const std::string& name) -> int {
    for (std::size_t i = 0; i < list.size(); ++i)
      if (list[i].name == name && list[i].components == 1) return static_cast<int>(i);
    return -1;
  };
  for (std::size_t i = 0; i < list.size(); ++i) {
    const Attribute& a = list[i];
    if (a.components != 1 || a.name.size() < 2) continue;
    const char last = a.name.back();
    if (last != 'x' && last != 'X') continue;
    const bool upper = last == 'X';
    const std::string stem = a.name.substr(0, a.name.size() - 1);
    const int iy = find(stem + (upper ? "Y" : "y"));
    const int iz = find(stem + (upper ? "Z" : "z"));
    if (iy < 0 || iz < 0) continue;
    std::string base = stem;
    if (!base.empty() && base.back() == '_') base.pop_back();
    if (base.empty()) continue;
    bool taken = false;
    for (const Attribute& other : list) taken = taken || other.name == base;
    if (taken) continue;
    const std::size_t n = a.values.size();
    if (list[static_cast<std::size_t>(iy)].values.size() != n || list[static_cast<std::size_t>(iz)].values.size() != n)
      continue;
    Attribute v;
    v.name = base;
    v.components = 3;
    v.values.resize(3 * n);
    for (std::size_t k = 0; k < n; ++k) {
      v.values[3 * k] = a.values[k];
      v.values[3 * k + 1] = list[static_cast<std::size_t>(iy)].values[k];
      v.values[3 * k + 2] = list[static_cast<std::size_t>(iz)].values[k];
    }
    list[i] = std::move(v);
    const int hi = std::max(iy, iz), lo = std::min(iy, iz);
    list.erase(list.begin() + hi);
    list.erase(list.begin() + lo);
    // Keep i on the merged entry.
    i -= static_cast<std::size_t>(static_cast<std::size_t>(lo) < i) + static_cast<std::size_t>(static_cast<std::size_t>(hi) < i);
  }
}

} // namespace detail

} // namespace nbmc::io
