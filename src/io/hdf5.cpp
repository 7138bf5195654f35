// SPDX-License-Identifier: MIT
// HDF5 particle layouts through the HDF5 C library: H5Part (Step#<n> groups,
// also SPH-EXA), PySPH (/particles/<array>/arrays), GADGET / SWIFT
// (/PartType0/Coordinates) and generic objects ("file.h5:/path"). HDF5's
// automatic error printing is switched off; failures become Error messages
// that name the file and the object.
#include "io/codec.hpp"
#include "io/readers.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <mutex>
#include <sys/stat.h>

namespace nbmc::io::detail {

namespace {

// HDF5 keeps global state; calls are serialised even where the library is
// built without its own lock.
std::mutex& h5_mutex() {
  static std::mutex m;
  return m;
}

constexpr std::uint64_t kMaxParticles = 4294967294ull; // what nbmc can upload

// Innermost message of HDF5's error stack (then cleared), for messages.
herr_t walk_cb(unsigned n, const H5E_error2_t* err, void* data) {
  auto* out = static_cast<std::string*>(data);
  if (err && err->desc && *err->desc) {
    if (n == 0 || out->empty()) *out = err->desc;
    else *out = err->desc; // keep the deepest one
  }
  return 0;
}
std::string h5_message() {
  std::string msg;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk_cb, &msg);
  H5Eclear2(H5E_DEFAULT);
  return msg.empty() ? std::string() : " (HDF5: " + msg + ")";
}

class Id {
public:
  Id() = default;
  Id(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Id(const Id&) = delete;
  Id& operator=(const Id&) = delete;
  Id(Id&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = -1; }
  Id& operator=(Id&& o) noexcept {
    reset();
    id_ = o.id_;
    close_ = o.close_;
    o.id_ = -1;
    return *this;
  }
  ~Id() { reset(); }
  void reset() {
    if (id_ >= 0 && close_) close_(id_);
    id_ = -1;
  }
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

private:
  hid_t id_ = -1;
  herr_t (*close_)(hid_t) = nullptr;
};

class H5File {
public:
  H5File(const std::string& path, const std::string& name) : name_(name) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0) fail_io(name, "cannot open: No such file or directory");
    if (S_ISDIR(st.st_mode)) fail_io(name, "is a directory");
    const htri_t is = H5Fis_hdf5(path.c_str());
    if (is == 0) fail(name, "not an HDF5 file");
    if (is < 0) fail_io(name, "cannot open" + h5_message());
    Id fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG);
    file_ = Id(H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
    if (!file_.ok()) fail_io(name, "cannot open the HDF5 file" + h5_message());
  }
  H5File(const void* data, std::size_t size, const std::string& name) : name_(name) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    static const unsigned char kSig[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
    if (size < 8 || std::memcmp(data, kSig, 8) != 0) fail(name, "not an HDF5 file (no signature at offset 0)");
    Id fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
    H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG);
    if (H5Pset_fapl_core(fapl.get(), 1 << 16, 0) < 0 || H5Pset_file_image(fapl.get(), const_cast<void*>(data), size) < 0)
      fail(name, "cannot set up an in-memory HDF5 file" + h5_message());
    file_ = Id(H5Fopen("nbmc-memory.h5", H5F_ACC_RDONLY, fapl.get()), H5Fclose);
    if (!file_.ok()) fail(name, "cannot open the HDF5 image" + h5_message());
  }
  hid_t get() const { return file_.get(); }
  const std::string& name() const { return name_; }

private:
  std::string name_;
  Id file_;
};

std::vector<std::string> split_path(const std::string& p) {
  std::vector<std::string> out;
  std::size_t i = 0;
  while (i < p.size()) {
    while (i < p.size() && p[i] == '/') ++i;
    const std::size_t b = i;
    while (i < p.size() && p[i] != '/') ++i;
    if (i > b) out.push_back(p.substr(b, i - b));
  }
  return out;
}

// Whether path (absolute or relative to loc) names an existing object,
// checking every link on the way so that HDF5 never fails inside.
bool exists(hid_t loc, const std::string& path) {
  std::string sofar = path.size() && path[0] == '/' ? "/" : "";
  const std::vector<std::string> parts = split_path(path);
  if (parts.empty()) return true;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    sofar += (sofar.empty() || sofar.back() == '/' ? "" : "/") + parts[i];
    const htri_t e = H5Lexists(loc, sofar.c_str(), H5P_DEFAULT);
    if (e <= 0) {
      H5Eclear2(H5E_DEFAULT);
      return false;
    }
    if (i + 1 < parts.size()) {
      // Intermediate parts must be groups.
      Id o(H5Oopen(loc, sofar.c_str(), H5P_DEFAULT), H5Oclose);
      if (!o.ok() || H5Iget_type(o.get()) != H5I_GROUP) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
    }
  }
  return true;
}

H5I_type_t kind_of(hid_t loc, const std::string& path) {
  Id o(H5Oopen(loc, path.c_str(), H5P_DEFAULT), H5Oclose);
  if (!o.ok()) {
    H5Eclear2(H5E_DEFAULT);
    return H5I_BADID;
  }
  return H5Iget_type(o.get());
}

herr_t collect_cb(hid_t, const char* name, const H5L_info_t*, void* data) {
  auto* v = static_cast<std::vector<std::string>*>(data);
  if (v->size() >= 1000000) return 1; // enough
  v->emplace_back(name);
  return 0;
}

std::vector<std::string> members(hid_t group) {
  std::vector<std::string> names;
  hsize_t idx = 0;
  if (H5Literate(group, H5_INDEX_NAME, H5_ITER_INC, &idx, collect_cb, &names) < 0) H5Eclear2(H5E_DEFAULT);
  return names;
}

std::string join(const std::string& group, const std::string& name) {
  if (group.empty() || group == "/") return "/" + name;
  return group + "/" + name;
}

// Shape of a dataset, or false when it is not a simple numeric dataset.
struct Shape {
  int rank = 0;
  hsize_t dims[2] = {0, 0};
  std::size_t type_size = 0;
};

bool numeric_shape(hid_t dset, Shape& s) {
  Id type(H5Dget_type(dset), H5Tclose);
  if (!type.ok()) return false;
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls != H5T_FLOAT && cls != H5T_INTEGER) return false;
  s.type_size = H5Tget_size(type.get());
  Id space(H5Dget_space(dset), H5Sclose);
  if (!space.ok() || H5Sget_simple_extent_type(space.get()) != H5S_SIMPLE) return false;
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2) return false;
  s.rank = rank;
  H5Sget_simple_extent_dims(space.get(), s.dims, nullptr);
  return true;
}

class Reader {
public:
  Reader(const H5File& f, const ReadOptions& o) : f_(f), opt_(o) {}

  Particles by_layout(const std::string& layout, const std::string& object);
  std::vector<std::int64_t> steps();

private:
  const std::string& name() const { return f_.name(); }
  // cols > 0: positions, rows of cols values; with opt_.parts > 1 only this
  // reader's share of the rows is read (a hyperslab).
  std::vector<double> read_dataset(hid_t loc, const std::string& path, std::uint64_t values, const std::string& what,
                                   std::uint64_t cols = 0);
  bool sharing() const { return opt_.parts > 1; }
  Particles from_group(const std::string& group, bool positions_as_xyz);
  Particles from_gadget_group(const std::string& group);
  void attributes_of_group(const std::string& group, std::uint64_t n, const std::vector<std::string>& skip,
                           Particles& out);
  bool scalar_attribute(const std::string& object, const char* attr, double& v);
  std::vector<std::pair<std::int64_t, std::string>> step_groups();

  const H5File& f_;
  const ReadOptions& opt_;
};

std::vector<double> Reader::read_dataset(hid_t loc, const std::string& path, std::uint64_t values,
                                         const std::string& what, std::uint64_t cols) {
  Id d(H5Dopen2(loc, path.c_str(), H5P_DEFAULT), H5Dclose);
  if (!d.ok()) fail(name(), "cannot open dataset " + path + h5_message());
  Shape s;
  if (!numeric_shape(d.get(), s)) fail(name(), what + " " + path + " is not a numeric dataset of rank 1 or 2");
  const std::uint64_t elements = s.rank == 1 ? s.dims[0] : s.dims[0] * s.dims[1];
  if (elements != values)
    fail(name(), what + " " + path + " has " + std::to_string(elements) + " values, expected " + std::to_string(values));
  const std::uint64_t bytes_needed = values * s.type_size;
  const std::uint64_t storage = H5Dget_storage_size(d.get());
  // A dataset can be declared huge with nothing written (reads as fill
  // values); refuse what the stored bytes cannot hold even compressed.
  if (values > kMaxParticles * 3 || bytes_needed / kMaxDeflateRatio > storage + (1 << 20) / kMaxDeflateRatio)
    fail(name(), what + " " + path + " declares " + std::to_string(values) + " values but stores only " +
                     std::to_string(storage) + " bytes");
  if (cols > 0 && sharing()) {
    const std::uint64_t rows = values / cols;
    const std::uint64_t lo = rows * opt_.part / opt_.parts, hi = rows * (opt_.part + 1) / opt_.parts;
    std::vector<double> v(static_cast<std::size_t>((hi - lo) * cols));
    if (hi > lo) {
      hsize_t start[2] = {lo, 0}, count[2] = {hi - lo, s.rank == 2 ? s.dims[1] : 1};
      Id file_space(H5Dget_space(d.get()), H5Sclose);
      hsize_t mem_dims[1] = {(hi - lo) * cols};
      Id mem_space(H5Screate_simple(1, mem_dims, nullptr), H5Sclose);
      if (!file_space.ok() || !mem_space.ok() ||
          H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr) < 0 ||
          H5Dread(d.get(), H5T_NATIVE_DOUBLE, mem_space.get(), file_space.get(), H5P_DEFAULT, v.data()) < 0)
        fail(name(), "cannot read rows " + std::to_string(lo) + " to " + std::to_string(hi) + " of " + what + " " +
                         path + h5_message());
    }
    return v;
  }
  std::vector<double> v(static_cast<std::size_t>(values));
  if (values > 0 && H5Dread(d.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()) < 0)
    fail(name(), "cannot read " + what + " " + path + h5_message());
  return v;
}

bool Reader::scalar_attribute(const std::string& object, const char* attr, double& v) {
  const htri_t e = H5Aexists_by_name(f_.get(), object.c_str(), attr, H5P_DEFAULT);
  if (e <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  Id a(H5Aopen_by_name(f_.get(), object.c_str(), attr, H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!a.ok()) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  Id type(H5Aget_type(a.get()), H5Tclose);
  const H5T_class_t cls = H5Tget_class(type.get());
  if (cls != H5T_FLOAT && cls != H5T_INTEGER) return false;
  Id space(H5Aget_space(a.get()), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) return false;
  double x = 0;
  if (H5Aread(a.get(), H5T_NATIVE_DOUBLE, &x) < 0) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  v = x;
  return true;
}

void Reader::attributes_of_group(const std::string& group, std::uint64_t n, const std::vector<std::string>& skip,
                                 Particles& out) {
  if (!opt_.attributes) return;
  Id g(H5Gopen2(f_.get(), group.c_str(), H5P_DEFAULT), H5Gclose);
  if (!g.ok()) fail(name(), "cannot open group " + group + h5_message());
  for (const std::string& m : members(g.get())) {
    if (std::find(skip.begin(), skip.end(), m) != skip.end()) continue;
    if (!want_attribute(opt_, m)) continue;
    const std::string path = join(group, m);
    if (kind_of(f_.get(), path) != H5I_DATASET) continue;
    Id d(H5Dopen2(f_.get(), path.c_str(), H5P_DEFAULT), H5Dclose);
    Shape s;
    if (!d.ok() || !numeric_shape(d.get(), s)) {
      H5Eclear2(H5E_DEFAULT);
      continue;
    }
    d.reset();
    int comps = 0;
    if (s.rank == 1 && s.dims[0] == n) comps = 1;
    else if (s.rank == 2 && s.dims[0] == n && s.dims[1] == 1) comps = 1;
    else if (s.rank == 2 && s.dims[0] == n && s.dims[1] == 3) comps = 3;
    if (comps == 0) continue; // other lengths: not per particle
    Attribute a;
    a.name = m;
    a.components = comps;
    a.values = read_dataset(f_.get(), path, n * static_cast<std::uint64_t>(comps), "dataset");
    out.attributes.push_back(std::move(a));
  }
  merge_vector_attributes(out.attributes);
}

// A group with 1-D datasets x, y, z (H5Part step, PySPH arrays, generic).
Particles Reader::from_group(const std::string& group, bool) {
  Id g(H5Gopen2(f_.get(), group.c_str(), H5P_DEFAULT), H5Gclose);
  if (!g.ok()) fail(name(), "cannot open group " + group + h5_message());
  Particles out;
  std::uint64_t n = 0;
  std::vector<double> axis[3];
  const char* names[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    const std::string path = join(group, names[a]);
    if (!exists(f_.get(), path) || kind_of(f_.get(), path) != H5I_DATASET)
      fail(name(), "group " + group + " has no dataset '" + names[a] + "'");
    Id d(H5Dopen2(f_.get(), path.c_str(), H5P_DEFAULT), H5Dclose);
    Shape s;
    if (!d.ok() || !numeric_shape(d.get(), s))
      fail(name(), "dataset " + path + " is not numeric" + h5_message());
    const bool one_d = s.rank == 1 || (s.rank == 2 && s.dims[1] == 1);
    if (!one_d) fail(name(), "dataset " + path + " is not one-dimensional");
    if (a == 0) n = s.dims[0];
    else if (s.dims[0] != n)
      fail(name(), "dataset " + path + " has " + std::to_string(s.dims[0]) + " values but " + join(group, "x") +
                       " has " + std::to_string(n));
    d.reset();
    axis[a] = read_dataset(f_.get(), path, n, "dataset", 1);
  }
  const std::size_t m = axis[0].size();  // n, or this reader's share
  out.xyz.resize(3 * m);
  for (std::size_t i = 0; i < m; ++i)
    for (int a = 0; a < 3; ++a) out.xyz[3 * i + static_cast<std::size_t>(a)] = axis[a][i];
  if (!sharing()) attributes_of_group(group, n, {"x", "y", "z"}, out);
  return out;
}

// A group with an N x 3 Coordinates dataset (GADGET / SWIFT PartTypeN).
Particles Reader::from_gadget_group(const std::string& group) {
  const std::string path = join(group, "Coordinates");
  if (!exists(f_.get(), path) || kind_of(f_.get(), path) != H5I_DATASET)
    fail(name(), "group " + group + " has no dataset 'Coordinates'");
  Id d(H5Dopen2(f_.get(), path.c_str(), H5P_DEFAULT), H5Dclose);
  Shape s;
  if (!d.ok() || !numeric_shape(d.get(), s)) fail(name(), "dataset " + path + " is not numeric" + h5_message());
  if (s.rank != 2 || s.dims[1] != 3)
    fail(name(), "dataset " + path + " is not N x 3");
  d.reset();
  Particles out;
  out.xyz = read_dataset(f_.get(), path, 3 * s.dims[0], "dataset", 3);
  if (!sharing()) attributes_of_group(group, s.dims[0], {"Coordinates"}, out);
  return out;
}

std::vector<std::pair<std::int64_t, std::string>> Reader::step_groups() {
  std::vector<std::pair<std::int64_t, std::string>> out;
  Id root(H5Gopen2(f_.get(), "/", H5P_DEFAULT), H5Gclose);
  if (!root.ok()) fail(name(), "cannot open the root group" + h5_message());
  for (const std::string& m : members(root.get())) {
    if (m.rfind("Step#", 0) != 0) continue;
    std::int64_t v = 0;
    const auto r = std::from_chars(m.data() + 5, m.data() + m.size(), v);
    if (r.ec != std::errc() || r.ptr != m.data() + m.size() || m.size() == 5) continue;
    out.emplace_back(v, "/" + m);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<std::int64_t> Reader::steps() {
  std::vector<std::int64_t> out;
  for (const auto& s : step_groups()) out.push_back(s.first);
  return out;
}

Particles Reader::by_layout(const std::string& layout_in, const std::string& object) {
  std::string layout = layout_in;
  const hid_t f = f_.get();
  if (!object.empty() && object != "/") {
    if (!exists(f, object)) fail(name(), "no object " + object + " in the file");
    const H5I_type_t k = kind_of(f, object);
    if (k == H5I_DATASET) {
      Id d(H5Dopen2(f, object.c_str(), H5P_DEFAULT), H5Dclose);
      Shape s;
      if (!d.ok() || !numeric_shape(d.get(), s)) fail(name(), "dataset " + object + " is not numeric" + h5_message());
      if (s.rank != 2 || s.dims[1] != 3) fail(name(), "dataset " + object + " is not N x 3 (positions)");
      d.reset();
      Particles out;
      out.xyz = read_dataset(f, object, 3 * s.dims[0], "dataset", 3);
      return out;
    }
    if (k != H5I_GROUP) fail(name(), object + " is neither a group nor a dataset");
    if (exists(f, join(object, "x"))) return from_group(object, true);
    if (exists(f, join(object, "arrays")) && exists(f, join(join(object, "arrays"), "x")))
      return from_group(join(object, "arrays"), true);
    if (exists(f, join(object, "Coordinates"))) return from_gadget_group(object);
    fail(name(), "group " + object + " has no datasets x, y, z (nor arrays/x or Coordinates)");
  }
  if (layout == "hdf5") {
    if (!step_groups().empty()) layout = "h5part";
    else if (exists(f, "/particles")) layout = "pysph";
    else if (exists(f, "/PartType0")) layout = "gadget";
    else
      fail(name(), "cannot tell the layout of this HDF5 file (no Step#<n> groups, /particles or /PartType0); "
                   "name the object as FILE:/path/to/dataset-or-group");
  }
  if (layout == "h5part") {
    const auto steps = step_groups();
    if (steps.empty()) fail(name(), "no Step#<n> groups (not an H5Part file)");
    std::string group;
    if (opt_.frame < 0) {
      group = steps.front().second;
    } else {
      for (const auto& s : steps)
        if (s.first == opt_.frame) group = s.second;
      if (group.empty())
        fail(name(), "no group Step#" + std::to_string(opt_.frame) + " (the file has steps " +
                         std::to_string(steps.front().first) + " to " + std::to_string(steps.back().first) + ")");
    }
    Particles out = from_group(group, true);
    double t = 0;
    if (scalar_attribute(group, "TimeValue", t) || scalar_attribute(group, "time", t) ||
        scalar_attribute(group, "Time", t))
      out.time = t;
    return out;
  }
  if (layout == "pysph") {
    if (!exists(f, "/particles") || kind_of(f, "/particles") != H5I_GROUP)
      fail(name(), "no group /particles (not a PySPH file)");
    Id g(H5Gopen2(f, "/particles", H5P_DEFAULT), H5Gclose);
    const std::vector<std::string> arrays = members(g.get());
    if (arrays.empty()) fail(name(), "group /particles is empty");
    std::string pick = arrays.front();
    for (const std::string& a : arrays)
      if (a == "fluid") pick = a;
    const std::string group = "/particles/" + pick + "/arrays";
    if (!exists(f, group)) fail(name(), "no group " + group);
    Particles out = from_group(group, true);
    double t = 0;
    if (scalar_attribute("/solver_data", "t", t)) out.time = t;
    return out;
  }
  if (layout == "gadget") {
    if (!exists(f, "/PartType0")) fail(name(), "no group /PartType0 (not a GADGET / SWIFT file)");
    Particles out = from_gadget_group("/PartType0");
    double t = 0;
    if (exists(f, "/Header") && scalar_attribute("/Header", "Time", t)) out.time = t;
    return out;
  }
  fail(name(), "internal: unknown HDF5 layout '" + layout + "'");
}

} // namespace

bool split_hdf5_path(const std::string& path, bool check_exists, std::string& file, std::string& object) {
  for (std::size_t pos = path.find(":/"); pos != std::string::npos; pos = path.find(":/", pos + 1)) {
    const std::string f = path.substr(0, pos);
    const std::string ext = lower_extension(f);
    bool ok = ext == ".h5" || ext == ".hdf5" || ext == ".hdf" || ext == ".h5part" || ext == ".he5";
    if (!ok && check_exists) {
      struct stat st {};
      ok = ::stat(f.c_str(), &st) == 0 && S_ISREG(st.st_mode);
    }
    if (ok) {
      file = f;
      object = path.substr(pos + 1);
      return true;
    }
  }
  return false;
}

Particles read_hdf5_file(const std::string& file, const std::string& object, const std::string& layout,
                         const ReadOptions& o) {
  std::lock_guard<std::mutex> lock(h5_mutex());
  const std::string shown = object.empty() ? file : file + ":" + object;
  H5File f(file, shown);
  Reader r(f, o);
  return r.by_layout(layout, object);
}

Particles read_hdf5_memory(const void* data, std::size_t size, const std::string& name, const std::string& object,
                           const std::string& layout, const ReadOptions& o) {
  std::lock_guard<std::mutex> lock(h5_mutex());
  H5File f(data, size, name);
  Reader r(f, o);
  return r.by_layout(layout, object);
}

std::vector<std::int64_t> hdf5_steps(const std::string& file, const std::string& object, const std::string& layout) {
  if (!object.empty() && object != "/") return {};
  std::lock_guard<std::mutex> lock(h5_mutex());
  H5File f(file, file);
  ReadOptions o;
  Reader r(f, o);
  if (layout != "h5part" && layout != "hdf5") return {};
  return r.steps();
}

} // namespace nbmc::io::detail
