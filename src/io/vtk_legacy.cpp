// SPDX-License-Identifier: MIT
// Legacy VTK reader ("# vtk DataFile Version 2.0 ... 5.1"): ASCII and BINARY
// (big-endian), POLYDATA, UNSTRUCTURED_GRID and STRUCTURED_GRID; POINTS
// plus the arrays of POINT_DATA (SCALARS, VECTORS, NORMALS, FIELD). Cell
// sections are skipped, or read as triangles when asked.
#include "io/readers.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>

namespace nbmc::io::detail {

namespace {

constexpr std::size_t kMaxToken = 1024;

struct VtkType {
  Scalar scalar = Scalar::float32;
  bool bit = false;
};

bool parse_vtk_type(std::string t, VtkType& out) {
  t = to_lower(t);
  struct E {
    const char* name;
    Scalar s;
  };
  static const E table[] = {{"char", Scalar::int8},
                            {"signed_char", Scalar::int8},
                            {"unsigned_char", Scalar::uint8},
                            {"short", Scalar::int16},
                            {"unsigned_short", Scalar::uint16},
                            {"int", Scalar::int32},
                            {"unsigned_int", Scalar::uint32},
                            {"long", Scalar::int64},
                            {"unsigned_long", Scalar::uint64},
                            {"long_long", Scalar::int64},
                            {"unsigned_long_long", Scalar::uint64},
                            {"vtkidtype", Scalar::int32}, // written as int
                            {"vtktypeint8", Scalar::int8},
                            {"vtktypeuint8", Scalar::uint8},
                            {"vtktypeint16", Scalar::int16},
                            {"vtktypeuint16", Scalar::uint16},
                            {"vtktypeint32", Scalar::int32},
                            {"vtktypeuint32", Scalar::uint32},
                            {"vtktypeint64", Scalar::int64},
                            {"vtktypeuint64", Scalar::uint64},
                            {"float", Scalar::float32},
                            {"vtktypefloat32", Scalar::float32},
                            {"double", Scalar::float64},
                            {"vtktypefloat64", Scalar::float64}};
  for (const E& e : table)
    if (t == e.name) {
      out.scalar = e.s;
      out.bit = false;
      return true;
    }
  if (t == "bit") {
    out.bit = true;
    out.scalar = Scalar::uint8;
    return true;
  }
  return false;
}

// "%20" and friends in VTK 5 names.
std::string decode_name(const std::string& s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

class Legacy {
public:
  Legacy(ByteReader& in, const ReadOptions& o, std::vector<std::uint32_t>* tris) : in_(in), opt_(o), tris_(tris) {}
  Particles run();

private:
  const std::string& name() const { return in_.name(); }
  bool next(std::string& tok);
  std::string need(const char* what);
  std::uint64_t need_count(const char* what);
  void end_line();
  std::string line(std::size_t limit);
  void read_values(const VtkType& t, std::uint64_t n, std::vector<double>* dst, const std::string& what);
  void skip_values(const VtkType& t, std::uint64_t n, const std::string& what) { read_values(t, n, nullptr, what); }
  void read_cells_v4(std::uint64_t ncells, std::uint64_t size, bool as_triangles, const std::string& what);
  void read_cells_v5(std::uint64_t noffsets, std::uint64_t nconn, bool as_triangles, const std::string& what);
  void maybe_lookup_table();
  void skip_metadata();
  void add_attribute(const std::string& aname, int components, std::vector<double>&& values);
  VtkType need_type(const std::string& t, const std::string& what) {
    VtkType v;
    if (!parse_vtk_type(t, v)) fail(name(), "unsupported data type '" + printable(t) + "' in " + what);
    return v;
  }

  ByteReader& in_;
  const ReadOptions& opt_;
  std::vector<std::uint32_t>* tris_;
  bool binary_ = false;
  int major_ = 0;
  Particles out_;
  bool have_points_ = false;
  std::string pending_; // a token read ahead
};

bool Legacy::next(std::string& tok) {
  if (!pending_.empty()) {
    tok.swap(pending_);
    pending_.clear();
    return true;
  }
  tok.clear();
  int c = in_.peek();
  while (c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v') {
    in_.get();
    c = in_.peek();
  }
  if (c < 0) return false;
  while (c >= 0 && c != ' ' && c != '\t' && c != '\r' && c != '\n' && c != '\f' && c != '\v') {
    if (tok.size() >= kMaxToken) fail(name(), "a word longer than 1024 characters near byte " + std::to_string(in_.tell()));
    tok.push_back(static_cast<char>(in_.get()));
    c = in_.peek();
  }
  return true;
}

std::string Legacy::need(const char* what) {
  std::string t;
  if (!next(t)) fail(name(), std::string("the file ends where ") + what + " was expected");
  return t;
}

std::uint64_t Legacy::need_count(const char* what) {
  const std::string t = need(what);
  std::uint64_t v = 0;
  const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
  if (r.ec != std::errc() || r.ptr != t.data() + t.size())
    fail(name(), std::string(what) + " '" + printable(t) + "' is not a non-negative integer");
  return v;
}

void Legacy::end_line() {
  for (;;) {
    const int c = in_.get();
    if (c < 0 || c == '\n') return;
    if (c != ' ' && c != '\t' && c != '\r')
      fail(name(), "unexpected '" + printable(std::string(1, static_cast<char>(c))) + "' at the end of a line near byte " +
                       std::to_string(in_.tell()));
  }
}

std::string Legacy::line(std::size_t limit) {
  std::string s;
  for (;;) {
    const int c = in_.get();
    if (c < 0) fail(name(), "the file ends inside the header");
    if (c == '\n') break;
    if (s.size() >= limit) fail(name(), "header line longer than " + std::to_string(limit) + " characters");
    s.push_back(static_cast<char>(c));
  }
  if (!s.empty() && s.back() == '\r') s.pop_back();
  return s;
}

void Legacy::read_values(const VtkType& t, std::uint64_t n, std::vector<double>* dst, const std::string& what) {
  if (binary_) {
    end_line();
    std::uint64_t bytes;
    if (t.bit) {
      bytes = n / 8 + (n % 8 != 0);
    } else {
      const std::uint64_t size = scalar_size(t.scalar);
      if (n > in_.remaining() / size)
        fail(name(), what + " needs " + std::to_string(n) + " values of " + std::to_string(size) +
                         " bytes but only " + std::to_string(in_.remaining()) + " bytes are left");
      bytes = n * size;
    }
    if (bytes > in_.remaining())
      fail(name(), what + " needs " + std::to_string(bytes) + " bytes but only " + std::to_string(in_.remaining()) +
                       " are left");
    if (!dst) {
      if (in_.skip(bytes) != bytes) fail(name(), "the file ends inside " + what);
      return;
    }
    dst->resize(static_cast<std::size_t>(n));
    constexpr std::size_t kChunk = std::size_t(1) << 20;
    std::vector<unsigned char> buf(static_cast<std::size_t>(std::min<std::uint64_t>(bytes, kChunk)));
    if (t.bit) {
      std::uint64_t done = 0;
      for (std::uint64_t off = 0; off < bytes;) {
        const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(bytes - off, buf.size()));
        if (in_.read(buf.data(), k) != k) fail(name(), "the file ends inside " + what);
        for (std::size_t b = 0; b < k; ++b)
          for (int bit = 7; bit >= 0 && done < n; --bit) (*dst)[static_cast<std::size_t>(done++)] = (buf[b] >> bit) & 1;
        off += k;
      }
      return;
    }
    const std::size_t size = scalar_size(t.scalar);
    const std::size_t per = buf.size() / size;
    for (std::uint64_t done = 0; done < n;) {
      const std::size_t k = static_cast<std::size_t>(std::min<std::uint64_t>(n - done, per));
      if (in_.read(buf.data(), k * size) != k * size) fail(name(), "the file ends inside " + what);
      for (std::size_t i = 0; i < k; ++i)
        (*dst)[static_cast<std::size_t>(done + i)] = load_scalar(t.scalar, buf.data(), i, true);
      done += k;
    }
    return;
  }
  // ASCII: every value takes at least two bytes (a digit and a separator).
  if (n > in_.remaining() / 2 + 1)
    fail(name(), what + " needs " + std::to_string(n) + " values but only " + std::to_string(in_.remaining()) +
                     " bytes are left");
  if (dst) dst->resize(static_cast<std::size_t>(n));
  std::string tok;
  for (std::uint64_t i = 0; i < n; ++i) {
    if (!next(tok))
      fail(name(), "the file ends inside " + what + " after " + std::to_string(i) + " of " + std::to_string(n) +
                       " values");
    if (!dst) continue;
    double v = 0;
    std::string_view s(tok);
    if (s.size() > 1 && s[0] == '+') s.remove_prefix(1);
    auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (r.ec == std::errc::result_out_of_range) {
      v = std::strtod(tok.c_str(), nullptr); // denormals, huge values: as strtod gives them
      r.ec = std::errc();
    }
    if (r.ec != std::errc() || r.ptr != s.data() + s.size())
      fail(name(), "'" + printable(tok) + "' in " + what + " is not a number");
    (*dst)[static_cast<std::size_t>(i)] = v;
  }
}

void Legacy::read_cells_v4(std::uint64_t ncells, std::uint64_t size, bool as_triangles, const std::string& what) {
  if (!as_triangles) {
    skip_values(VtkType{Scalar::int32, false}, size, what);
    return;
  }
  std::vector<double> v;
  read_values(VtkType{Scalar::int32, false}, size, &v, what);
  std::size_t pos = 0;
  for (std::uint64_t c = 0; c < ncells; ++c) {
    if (pos >= v.size()) fail(name(), what + " ends after " + std::to_string(c) + " of " + std::to_string(ncells) + " cells");
    if (v[pos] != 3) fail(name(), what + ": cell " + std::to_string(c) + " is not a triangle (only triangles are supported)");
    if (pos + 4 > v.size()) fail(name(), what + " ends inside cell " + std::to_string(c));
    for (int k = 1; k <= 3; ++k) {
      const double idx = v[pos + static_cast<std::size_t>(k)];
      if (!(idx >= 0) || idx >= static_cast<double>(out_.count()))
        fail(name(), what + ": cell " + std::to_string(c) + " refers to point " + std::to_string(static_cast<long long>(idx)) +
                         " but there are " + std::to_string(out_.count()) + " points");
      tris_->push_back(static_cast<std::uint32_t>(idx));
    }
    pos += 4;
  }
  if (pos != v.size()) fail(name(), what + ": the size does not match the cells");
}

void Legacy::read_cells_v5(std::uint64_t noffsets, std::uint64_t nconn, bool as_triangles, const std::string& what) {
  std::string t;
  std::vector<double> offsets, conn;
  if (!next(t) || to_lower(t) != "offsets") fail(name(), what + ": OFFSETS expected");
  VtkType ot = need_type(need("the OFFSETS type"), what);
  read_values(ot, noffsets, as_triangles ? &offsets : nullptr, what + " offsets");
  if (!next(t) || to_lower(t) != "connectivity") fail(name(), what + ": CONNECTIVITY expected");
  VtkType ct = need_type(need("the CONNECTIVITY type"), what);
  read_values(ct, nconn, as_triangles ? &conn : nullptr, what + " connectivity");
  if (!as_triangles) return;
  for (std::size_t c = 0; c + 1 < offsets.size(); ++c) {
    const double a = offsets[c], b = offsets[c + 1];
    if (!(a >= 0) || b - a != 3 || !(b <= static_cast<double>(conn.size())))
      fail(name(), what + ": cell " + std::to_string(c) + " is not a triangle or its offsets are wrong");
    for (std::size_t k = static_cast<std::size_t>(a); k < static_cast<std::size_t>(b); ++k) {
      const double idx = conn[k];
      if (!(idx >= 0) || idx >= static_cast<double>(out_.count()))
        fail(name(), what + ": cell " + std::to_string(c) + " refers to a point that does not exist");
      tris_->push_back(static_cast<std::uint32_t>(idx));
    }
  }
}

void Legacy::maybe_lookup_table() {
  std::string t;
  if (!next(t)) return;
  if (to_lower(t) != "lookup_table") {
    pending_ = t;
    return;
  }
  need("the lookup table name");
}

void Legacy::skip_metadata() {
  // METADATA, then lines up to an empty one.
  for (;;) {
    const int c = in_.get();
    if (c < 0) return;
    if (c == '\n') break;
  }
  std::size_t total = 0;
  for (;;) {
    std::string s;
    for (;;) {
      const int c = in_.get();
      if (c < 0) return;
      if (c == '\n') break;
      if (++total > (std::size_t(1) << 20)) fail(name(), "METADATA block longer than 1 MiB");
      s.push_back(static_cast<char>(c));
    }
    bool blank = true;
    for (char ch : s) blank = blank && (ch == ' ' || ch == '\t' || ch == '\r');
    if (blank) return;
  }
}

void Legacy::add_attribute(const std::string& aname, int components, std::vector<double>&& values) {
  for (const Attribute& a : out_.attributes)
    if (a.name == aname) return; // the first of two equal names wins
  Attribute a;
  a.name = aname;
  a.components = components;
  a.values = std::move(values);
  out_.attributes.push_back(std::move(a));
}

Particles Legacy::run() {
  const std::string first = line(256);
  if (first.rfind("# vtk DataFile Version", 0) != 0)
    fail(name(), "not a legacy VTK file (the first line is not '# vtk DataFile Version x.x')");
  {
    const std::size_t p = std::strlen("# vtk DataFile Version");
    std::size_t i = p;
    while (i < first.size() && first[i] == ' ') ++i;
    int major = 0;
    const auto r = std::from_chars(first.data() + i, first.data() + first.size(), major);
    if (r.ec != std::errc() || major < 1 || major > 5)
      fail(name(), "unsupported legacy VTK version '" + printable(first.substr(p)) + "'");
    major_ = major;
  }
  line(1024); // title
  {
    std::string mode = line(64);
    while (!mode.empty() && (mode.back() == ' ' || mode.back() == '\t')) mode.pop_back();
    mode = to_lower(mode);
    if (mode == "binary")
      binary_ = true;
    else if (mode != "ascii")
      fail(name(), "third line is '" + printable(mode) + "', expected ASCII or BINARY");
  }

  std::string t = need("DATASET");
  if (to_lower(t) == "field") {
    // Dataset-level field data before DATASET is not standard; refuse.
    fail(name(), "FIELD before DATASET is not supported");
  }
  if (to_lower(t) != "dataset") fail(name(), "expected DATASET, found '" + printable(t) + "'");
  const std::string kind = to_lower(need("the dataset type"));
  if (kind != "polydata" && kind != "unstructured_grid" && kind != "structured_grid")
    fail(name(), "dataset type '" + printable(kind) +
                     "' has no point list (supported: POLYDATA, UNSTRUCTURED_GRID, STRUCTURED_GRID)");

  enum class Section { none, point, cell };
  Section section = Section::none;
  std::uint64_t section_count = 0;
  std::uint64_t cell_count = 0;
  bool have_cells = false;

  while (next(t)) {
    const std::string key = to_lower(t);
    if (key == "points") {
      if (have_points_) fail(name(), "two POINTS sections");
      const std::uint64_t n = need_count("the number of points");
      const VtkType type = need_type(need("the POINTS type"), "POINTS");
      if (n > std::uint64_t(1) << 40) fail(name(), "POINTS count " + std::to_string(n) + " is too large");
      read_values(type, 3 * n, &out_.xyz, "POINTS (" + std::to_string(n) + " points)");
      have_points_ = true;
    } else if (key == "field") {
      need("the field name");
      const std::uint64_t arrays = need_count("the number of field arrays");
      for (std::uint64_t a = 0; a < arrays; ++a) {
        std::string aname = need("a field array name");
        if (to_lower(aname) == "metadata") {
          skip_metadata();
          aname = need("a field array name");
        }
        aname = decode_name(aname);
        const std::uint64_t comps = need_count("the number of components");
        const std::uint64_t tuples = need_count("the number of tuples");
        const std::string tname = need("the array type");
        const VtkType type = need_type(tname, "field array '" + printable(aname) + "'");
        if (comps == 0 || comps > 1024) fail(name(), "field array '" + printable(aname) + "' has " + std::to_string(comps) + " components");
        if (tuples > (std::uint64_t(1) << 40)) fail(name(), "field array '" + printable(aname) + "' is too large");
        const std::string what = "field array '" + printable(aname) + "'";
        const bool keep = section == Section::point && (comps == 1 || comps == 3) && tuples == section_count &&
                          want_attribute(opt_, aname);
        if (section == Section::point && tuples != section_count && (comps == 1 || comps == 3))
          fail(name(), what + " has " + std::to_string(tuples) + " tuples but POINT_DATA has " +
                           std::to_string(section_count));
        if (keep) {
          std::vector<double> v;
          read_values(type, comps * tuples, &v, what);
          add_attribute(aname, static_cast<int>(comps), std::move(v));
        } else if (section == Section::none && to_lower(aname) == "time" && comps * tuples == 1) {
          std::vector<double> v;
          read_values(type, 1, &v, what);
          out_.time = v[0];
        } else {
          skip_values(type, comps * tuples, what);
        }
      }
    } else if (key == "vertices" || key == "lines" || key == "polygons" || key == "triangle_strips" ||
               key == "cells") {
      const std::uint64_t n = need_count("the number of cells");
      const std::uint64_t size = need_count("the cell list size");
      const bool tri = tris_ && (key == "polygons" || key == "cells");
      if (tris_ && (key == "lines" || key == "triangle_strips") && n > 0)
        fail(name(), key + " are not supported in a mesh (only triangles)");
      if (tris_ && key == "vertices") {
        // Point clouds written as meshes have vertex cells: ignore them.
      }
      if (major_ >= 5)
        read_cells_v5(n, size, tri, key);
      else
        read_cells_v4(n, size, tri, key);
      if (key == "cells") {
        cell_count = major_ >= 5 ? (n > 0 ? n - 1 : 0) : n;
        have_cells = true;
      }
    } else if (key == "cell_types") {
      const std::uint64_t n = need_count("the number of cell types");
      std::vector<double> types;
      read_values(VtkType{Scalar::int32, false}, n, tris_ ? &types : nullptr, "CELL_TYPES");
      if (tris_)
        for (double ct : types)
          if (ct != 5 && ct != 1) fail(name(), "CELL_TYPES: only triangles (type 5) are supported in a mesh");
      (void)have_cells;
      (void)cell_count;
    } else if (key == "dimensions") {
      need_count("a dimension");
      need_count("a dimension");
      need_count("a dimension");
    } else if (key == "point_data" || key == "cell_data") {
      section_count = need_count("the number of data items");
      section = key == "point_data" ? Section::point : Section::cell;
      if (section == Section::point && section_count != out_.count())
        fail(name(), "POINT_DATA " + std::to_string(section_count) + " but there are " +
                         std::to_string(out_.count()) + " points");
    } else if (key == "scalars" || key == "vectors" || key == "normals" || key == "texture_coordinates" ||
               key == "tensors" || key == "tensors6" || key == "global_ids" || key == "pedigree_ids") {
      if (section == Section::none) fail(name(), t + " outside POINT_DATA / CELL_DATA");
      const std::string aname = decode_name(need("the array name"));
      std::uint64_t comps = 3;
      std::string tname;
      if (key == "texture_coordinates") comps = need_count("the texture dimension");
      tname = need("the array type");
      const VtkType type = need_type(tname, t + " '" + printable(aname) + "'");
      if (key == "scalars") {
        comps = 1;
        // Optional number of components, then LOOKUP_TABLE.
        std::string look;
        if (next(look)) {
          std::uint64_t c = 0;
          const auto r = std::from_chars(look.data(), look.data() + look.size(), c);
          if (r.ec == std::errc() && r.ptr == look.data() + look.size()) {
            if (c == 0 || c > 4) fail(name(), "SCALARS '" + printable(aname) + "' has " + std::to_string(c) + " components");
            comps = c;
          } else {
            pending_ = look;
          }
        }
        maybe_lookup_table();
      } else if (key == "tensors") {
        comps = 9;
      } else if (key == "tensors6") {
        comps = 6;
      } else if (key == "global_ids" || key == "pedigree_ids") {
        comps = 1;
      }
      if (comps == 0 || comps > 1024) fail(name(), t + " '" + printable(aname) + "' has a bad component count");
      const std::string what = t + " '" + printable(aname) + "'";
      const bool keep = section == Section::point && (comps == 1 || comps == 3) && key != "texture_coordinates" &&
                        want_attribute(opt_, aname);
      if (keep) {
        std::vector<double> v;
        read_values(type, comps * section_count, &v, what);
        add_attribute(aname, static_cast<int>(comps), std::move(v));
      } else {
        skip_values(type, comps * section_count, what);
      }
    } else if (key == "color_scalars") {
      need("the array name");
      const std::uint64_t comps = need_count("the number of values");
      if (comps == 0 || comps > 4) fail(name(), "COLOR_SCALARS has a bad component count");
      skip_values(binary_ ? VtkType{Scalar::uint8, false} : VtkType{Scalar::float32, false}, comps * section_count,
                  "COLOR_SCALARS");
    } else if (key == "lookup_table") {
      need("the lookup table name");
      const std::uint64_t n = need_count("the lookup table size");
      skip_values(binary_ ? VtkType{Scalar::uint8, false} : VtkType{Scalar::float32, false}, 4 * n, "LOOKUP_TABLE");
    } else if (key == "metadata") {
      skip_metadata();
    } else {
      fail(name(), "unexpected keyword '" + printable(t) + "' near byte " + std::to_string(in_.tell()));
    }
  }
  if (!have_points_) fail(name(), "no POINTS section");
  merge_vector_attributes(out_.attributes);
  return std::move(out_);
}

} // namespace

Particles read_vtk_legacy(ByteReader& in, const ReadOptions& o, std::vector<std::uint32_t>* triangles) {
  Legacy reader(in, o, triangles);
  return reader.run();
}

} // namespace nbmc::io::detail
