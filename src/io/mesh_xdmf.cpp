// SPDX-License-Identifier: MIT
// Triangle meshes as HDF5 datasets plus an XDMF descriptor (see
// mesh_xdmf.hpp for the layout). HDF5 is driven through its C library with
// automatic error printing off; calls are serialised by a lock of this file.
#include "io/mesh_xdmf.hpp"

#include "io/detail.hpp"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <mutex>
#include <sys/stat.h>

namespace nbmc::io::detail {

std::string xml_escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
    case '<': out += "&lt;"; break;
    case '>': out += "&gt;"; break;
    case '&': out += "&amp;"; break;
    case '"': out += "&quot;"; break;
    default: {
      const unsigned char u = static_cast<unsigned char>(c);
      out += (u < 0x20) ? '_' : c;
    }
    }
  }
  return out;
}

namespace {

std::mutex& write_lock() {
  static std::mutex m;
  return m;
}

// An HDF5 identifier closed by its own close function.
class Handle {
public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  operator hid_t() const { return id_; }
  bool ok() const { return id_ >= 0; }

private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

bool is_file(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

// Whether every link of the absolute path exists (HDF5 fails on a missing
// intermediate link, so they are checked one by one).
bool has_link(hid_t loc, const std::string& path) {
  for (std::size_t at = path.find('/', 1);; at = path.find('/', at + 1)) {
    const std::string part = path.substr(0, at);
    if (part.size() > 1 && H5Lexists(loc, part.c_str(), H5P_DEFAULT) <= 0) {
      H5Eclear2(H5E_DEFAULT);
      return false;
    }
    if (at == std::string::npos) return true;
  }
}

hid_t open_read(const std::string& file, const std::string& name) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  if (!is_file(file)) fail_io(name, "cannot open: no such file");
  if (H5Fis_hdf5(file.c_str()) <= 0) fail(name, "not an HDF5 file");
  const hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) fail_io(name, "cannot open the HDF5 file");
  return f;
}

// 2-D [rows][cols] (1-D when cols is 1) dataset `path` of `type` under loc.
void put_dataset(hid_t loc, const std::string& path, const std::string& name, hid_t type, const void* data,
                 std::uint64_t rows, int cols) {
  const hsize_t dims[2] = {static_cast<hsize_t>(rows), static_cast<hsize_t>(cols)};
  Handle space(H5Screate_simple(cols == 1 ? 1 : 2, dims, nullptr), H5Sclose);
  Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
  H5Pset_create_intermediate_group(lcpl, 1);
  Handle set(H5Dcreate2(loc, path.c_str(), type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT), H5Dclose);
  if (!space.ok() || !set.ok()) fail_io(name, "cannot create the dataset " + path);
  if (rows > 0 && H5Dwrite(set, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
    fail_io(name, "cannot write the dataset " + path);
}

// An HDF5 link name for an attribute: no '/', not "." or empty, unique.
std::string link_name(const std::string& s, std::vector<std::string>& taken) {
  std::string out = s;
  std::replace(out.begin(), out.end(), '/', '_');
  if (out.empty() || out == ".") out = "attribute";
  while (std::find(taken.begin(), taken.end(), out) != taken.end()) out += "_";
  taken.push_back(out);
  return out;
}

void write_group(hid_t g, const std::string& name, const MeshView& m, const std::function<bool()>& cancelled) {
  const auto poll = [&] {
    if (cancelled && cancelled()) throw Cancelled(name + ": cancelled while writing (nothing written)");
  };
  // Double positions (nbmc_params.double_positions) as float64: the XDMF
  // descriptor takes the precision from the dataset (Precision="8").
  if (m.positions64) put_dataset(g, "positions", name, H5T_NATIVE_DOUBLE, m.positions64, m.vertex_count, 3);
  else put_dataset(g, "positions", name, H5T_NATIVE_FLOAT, m.positions, m.vertex_count, 3);
  poll();
  put_dataset(g, "triangles", name, H5T_NATIVE_UINT32, m.triangles, m.triangle_count, 3);
  poll();
  if (m.normals) {
    put_dataset(g, "normals", name, H5T_NATIVE_FLOAT, m.normals, m.vertex_count, 3);
    poll();
  }
  if (!m.attribute_count) return;
  // Attributes are listed in the order they were written (creation order).
  Handle gcpl(H5Pcreate(H5P_GROUP_CREATE), H5Pclose);
  H5Pset_link_creation_order(gcpl, H5P_CRT_ORDER_TRACKED | H5P_CRT_ORDER_INDEXED);
  Handle ag(H5Gcreate2(g, "attributes", H5P_DEFAULT, gcpl, H5P_DEFAULT), H5Gclose);
  if (!ag.ok()) fail_io(name, "cannot create the group 'attributes'");
  std::vector<std::string> taken;
  for (std::size_t a = 0; a < m.attribute_count; ++a) {
    const Attribute& at = m.attributes[a];
    put_dataset(ag, link_name(at.name, taken), name, H5T_NATIVE_DOUBLE, at.values.data(), m.vertex_count,
                at.components);
    poll();
  }
}

// ------------------------------------------------------------------ XDMF
struct Item {
  std::string path; // absolute, in the HDF5 file
  hsize_t dims[2] = {0, 1};
  int rank = 0;
  std::string number_type; // Float, Int, UInt
  std::size_t precision = 0;
};

bool item(hid_t file, const std::string& path, Item& out) {
  if (!has_link(file, path)) return false;
  Handle set(H5Dopen2(file, path.c_str(), H5P_DEFAULT), H5Dclose);
  if (!set.ok()) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  Handle space(H5Dget_space(set), H5Sclose);
  Handle type(H5Dget_type(set), H5Tclose);
  const int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 1 || rank > 2) return false;
  out.path = path;
  out.rank = rank;
  H5Sget_simple_extent_dims(space, out.dims, nullptr);
  const H5T_class_t cls = H5Tget_class(type);
  if (cls == H5T_FLOAT)
    out.number_type = "Float";
  else if (cls == H5T_INTEGER)
    out.number_type = H5Tget_sign(type) == H5T_SGN_NONE ? "UInt" : "Int";
  else
    return false;
  out.precision = H5Tget_size(type);
  return true;
}

struct Grid {
  std::string group; // "" for the root
  double time = 0;
  Item positions, triangles, normals;
  bool has_normals = false;
  std::vector<std::pair<std::string, Item>> attributes;
};

// The names of the links of a group, by name or by creation order.
std::vector<std::string> links(hid_t file, const std::string& group, H5_index_t order) {
  std::vector<std::string> out;
  H5G_info_t info{};
  if (H5Gget_info_by_name(file, group.c_str(), &info, H5P_DEFAULT) < 0) {
    H5Eclear2(H5E_DEFAULT);
    return out;
  }
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    const ssize_t n = H5Lget_name_by_idx(file, group.c_str(), order, H5_ITER_INC, i, nullptr, 0, H5P_DEFAULT);
    if (n < 0) break;
    std::string s(static_cast<std::size_t>(n) + 1, '\0');
    H5Lget_name_by_idx(file, group.c_str(), order, H5_ITER_INC, i, s.data(), s.size(), H5P_DEFAULT);
    s.resize(static_cast<std::size_t>(n));
    out.push_back(s);
  }
  H5Eclear2(H5E_DEFAULT);
  return out;
}

bool read_grid(hid_t file, const std::string& group, Grid& g) {
  const std::string base = group + "/";
  if (!item(file, base + "positions", g.positions) || !item(file, base + "triangles", g.triangles)) return false;
  g.group = group;
  g.has_normals = item(file, base + "normals", g.normals);
  if (!has_link(file, base + "attributes")) return true;
  for (const std::string& a : links(file, base + "attributes", H5_INDEX_CRT_ORDER)) {
    Item it;
    if (item(file, base + "attributes/" + a, it) && it.dims[0] == g.positions.dims[0] &&
        (it.rank == 1 || it.dims[1] == 1 || it.dims[1] == 3))
      g.attributes.emplace_back(a, it);
  }
  return true;
}

// The number at the end of a group name ("frame_0042" -> 42), or -1.
double trailing_number(const std::string& s) {
  std::size_t b = s.size();
  while (b > 0 && s[b - 1] >= '0' && s[b - 1] <= '9') --b;
  double v = -1;
  if (b < s.size()) std::from_chars(s.data() + b, s.data() + s.size(), v);
  return v;
}

std::string data_item(const Item& it, const std::string& ref, const std::string& indent) {
  std::string dims = std::to_string(it.dims[0]);
  if (it.rank == 2) dims += " " + std::to_string(it.dims[1]);
  return indent + "<DataItem Dimensions=\"" + dims + "\" NumberType=\"" + it.number_type + "\" Precision=\"" +
         std::to_string(it.precision) + "\" Format=\"HDF\">" + xml_escape(ref + ":" + it.path) + "</DataItem>\n";
}

std::string attribute(const std::string& nm, const Item& it, const std::string& ref, const std::string& indent) {
  const bool vector = it.rank == 2 && it.dims[1] == 3;
  return indent + "<Attribute Name=\"" + xml_escape(nm) + "\" AttributeType=\"" + (vector ? "Vector" : "Scalar") +
         "\" Center=\"Node\">\n" + data_item(it, ref, indent + "  ") + indent + "</Attribute>\n";
}

std::string grid_xml(const Grid& g, const std::string& ref, const std::string& indent, bool timed) {
  const std::string in = indent + "  ";
  std::string x = indent + "<Grid Name=\"" + xml_escape(g.group.empty() ? "mesh" : g.group.substr(1)) +
                  "\" GridType=\"Uniform\">\n";
  if (timed) {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, g.time);
    x += in + "<Time Value=\"" + std::string(buf, r.ptr) + "\"/>\n";
  }
  x += in + "<Topology TopologyType=\"Triangle\" NumberOfElements=\"" + std::to_string(g.triangles.dims[0]) + "\">\n";
  x += data_item(g.triangles, ref, in + "  ") + in + "</Topology>\n";
  x += in + "<Geometry GeometryType=\"XYZ\">\n" + data_item(g.positions, ref, in + "  ") + in + "</Geometry>\n";
  if (g.has_normals) x += attribute("Normals", g.normals, ref, in);
  for (const auto& a : g.attributes) x += attribute(a.first, a.second, ref, in);
  return x + indent + "</Grid>\n";
}

} // namespace

void write_hdf5_mesh(const std::string& file, const std::string& name, const std::string& group, bool create,
                     const MeshView& m, const std::function<bool()>& cancelled) {
  std::lock_guard<std::mutex> lock(write_lock());
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  const bool root = group.empty() || group == "/";
  if (root && !create) fail_arg(name, "a mesh at the root of an HDF5 file replaces the whole file");
  const bool exists = is_file(file);
  if (!create && exists && H5Fis_hdf5(file.c_str()) <= 0) fail(name, "exists and is not an HDF5 file");
  Handle f(create || !exists ? H5Fcreate(file.c_str(), create ? H5F_ACC_TRUNC : H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT)
                             : H5Fopen(file.c_str(), H5F_ACC_RDWR, H5P_DEFAULT),
           H5Fclose);
  if (!f.ok()) fail_io(name, "cannot open the HDF5 file for writing");
  if (root) {
    write_group(f, name, m, cancelled);
  } else {
    if (has_link(f, group) && H5Ldelete(f, group.c_str(), H5P_DEFAULT) < 0)
      fail_io(name, "cannot replace the group " + group);
    Handle lcpl(H5Pcreate(H5P_LINK_CREATE), H5Pclose);
    H5Pset_create_intermediate_group(lcpl, 1);
    Handle g(H5Gcreate2(f, group.c_str(), lcpl, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    if (!g.ok()) fail_io(name, "cannot create the group " + group);
    try {
      write_group(g, name, m, cancelled);
    } catch (...) {
      H5Ldelete(f, group.c_str(), H5P_DEFAULT); // no partial frame stays behind
      H5Eclear2(H5E_DEFAULT);
      throw;
    }
  }
  if (H5Fflush(f, H5F_SCOPE_GLOBAL) < 0) fail_io(name, "write error (HDF5 flush)");
}

std::string xdmf_for_hdf5(const std::string& file, const std::string& name, const std::string& h5_ref) {
  std::lock_guard<std::mutex> lock(write_lock());
  Handle f(open_read(file, name), H5Fclose);
  std::vector<Grid> grids;
  Grid g;
  const bool single = read_grid(f, "", g);
  if (single) {
    grids.push_back(std::move(g));
  } else {
    for (const std::string& l : links(f, "/", H5_INDEX_NAME)) {
      Grid one;
      if (!read_grid(f, "/" + l, one)) continue;
      one.time = trailing_number(l);
      if (one.time < 0) one.time = static_cast<double>(grids.size());
      grids.push_back(std::move(one));
    }
    std::stable_sort(grids.begin(), grids.end(), [](const Grid& a, const Grid& b) { return a.time < b.time; });
  }
  if (grids.empty()) fail(name, "the HDF5 file holds no mesh");
  std::string x = "<?xml version=\"1.0\" ?>\n<!-- written by nbmc: the meshes of " + xml_escape(h5_ref) +
                  " -->\n<Xdmf Version=\"3.0\">\n  <Domain>\n";
  if (single) {
    x += grid_xml(grids.front(), h5_ref, "    ", false);
  } else {
    x += "    <Grid Name=\"frames\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
    for (const Grid& one : grids) x += grid_xml(one, h5_ref, "      ", true);
    x += "    </Grid>\n";
  }
  return x + "  </Domain>\n</Xdmf>\n";
}

bool hdf5_mesh_exists(const std::string& file, const std::string& group) {
  std::lock_guard<std::mutex> lock(write_lock());
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  if (!is_file(file) || H5Fis_hdf5(file.c_str()) <= 0) return false;
  Handle f(H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  Item it;
  return f.ok() && item(f, (group == "/" ? "" : group) + "/positions", it);
}

} // namespace nbmc::io::detail
