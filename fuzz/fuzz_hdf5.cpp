// SPDX-License-Identifier: MIT
// libFuzzer target: the HDF5 layouts (H5Part, PySPH, GADGET/SWIFT, generic
// objects). HDF5's own binary parser is not ours to fuzz, so the input
// drives a builder: it picks a layout, group and dataset names (right and
// wrong ones), element types (float, double, integers, strings), shapes
// (lengths that disagree, wrong ranks), chunking and deflate, attributes of
// odd types; the file is made in memory with the HDF5 library and handed to
// the reader as an image with a format and object path also drawn from the
// input. With NBMC_FUZZ_HDF5_FLIPS=1 in the environment, inputs starting
// with 255 also flip bytes of the image, which fuzzes HDF5's own parser
// (see fuzz/README.md for what that finds in libhdf5 1.10).
#include "check.hpp"

#include <hdf5.h>

#include <vector>

namespace {

class Input {
public:
  Input(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  unsigned byte() { return i_ < n_ ? d_[i_++] : 0; }
  unsigned pick(unsigned k) { return k ? byte() % k : 0; }
  bool flag() { return byte() & 1; }
  double real() {
    const unsigned b = byte();
    return (static_cast<int>(b) - 128) / 16.0;
  }
  std::size_t left() const { return n_ - i_; }

private:
  const std::uint8_t* d_;
  std::size_t n_, i_ = 0;
};

const char* const kNames[] = {"x",        "y",       "z",         "vx",       "vy",       "vz",     "rho",
                              "Coordinates", "Velocities", "Density", "arrays",  "fluid",    "Step#0", "Step#1",
                              "Step#x",   "particles", "PartType0", "Header", "h",        "velocity", "Step#2"};
constexpr unsigned kNameCount = sizeof kNames / sizeof kNames[0];

hid_t file_type(unsigned t) {
  switch (t % 6) {
  case 0: return H5T_NATIVE_FLOAT;
  case 1: return H5T_NATIVE_DOUBLE;
  case 2: return H5T_NATIVE_INT;
  case 3: return H5T_NATIVE_UCHAR;
  case 4: return H5T_STD_I64BE;
  default: return H5T_C_S1; // a string: not numeric
  }
}

void make_dataset(hid_t loc, const char* name, Input& in) {
  const unsigned rank = 1 + in.pick(3);
  hsize_t dims[3];
  hsize_t total = 1;
  for (unsigned r = 0; r < rank; ++r) {
    dims[r] = r == 1 && in.flag() ? 3 : in.pick(9);
    total *= dims[r];
  }
  const hid_t space = H5Screate_simple(static_cast<int>(rank), dims, nullptr);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  const unsigned layout = in.pick(3);
  if (layout > 0 && total > 0) {
    hsize_t chunk[3];
    for (unsigned r = 0; r < rank; ++r) chunk[r] = dims[r] ? 1 + in.pick(static_cast<unsigned>(dims[r])) : 1;
    H5Pset_chunk(dcpl, static_cast<int>(rank), chunk);
    if (layout == 2) H5Pset_deflate(dcpl, 1 + in.pick(9));
  }
  const unsigned t = in.pick(6);
  hid_t type = H5Tcopy(file_type(t));
  if (t == 5) H5Tset_size(type, 4);
  const hid_t d = H5Dcreate2(loc, name, type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
  if (d >= 0 && total > 0 && t != 5 && in.flag()) {
    std::vector<double> v(total);
    for (double& x : v) x = in.real();
    H5Dwrite(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
  }
  if (d >= 0) H5Dclose(d);
  H5Tclose(type);
  H5Pclose(dcpl);
  H5Sclose(space);
}

void make_attribute(hid_t loc, Input& in) {
  static const char* const names[] = {"TimeValue", "time", "Time", "t"};
  const char* name = names[in.pick(4)];
  const hsize_t n = in.pick(3);
  const hid_t space = n == 0 ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, &n, nullptr);
  const unsigned t = in.pick(6);
  hid_t type = H5Tcopy(file_type(t));
  if (t == 5) H5Tset_size(type, 8);
  const hid_t a = H5Acreate2(loc, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  if (a >= 0 && t != 5) {
    double v[2] = {in.real(), in.real()};
    H5Awrite(a, H5T_NATIVE_DOUBLE, v);
  }
  if (a >= 0) H5Aclose(a);
  H5Tclose(type);
  H5Sclose(space);
}

// A group with members drawn from the input, recursively (depth-limited).
void fill_group(hid_t g, Input& in, int depth) {
  const unsigned members = in.pick(7);
  for (unsigned m = 0; m < members && in.left() > 0; ++m) {
    const char* name = kNames[in.pick(kNameCount)];
    if (H5Lexists(g, name, H5P_DEFAULT) > 0) continue;
    const unsigned what = in.pick(4);
    if (what == 0 && depth < 3) {
      const hid_t sub = H5Gcreate2(g, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      if (sub >= 0) {
        if (in.flag()) make_attribute(sub, in);
        fill_group(sub, in, depth + 1);
        H5Gclose(sub);
      }
    } else if (what == 3) {
      make_attribute(g, in);
    } else {
      make_dataset(g, name, in);
    }
  }
}

// A plausible skeleton for the chosen layout, then random members.
void build(hid_t f, unsigned layout, Input& in) {
  const auto xyz = [&](hid_t g) {
    for (const char* a : {"x", "y", "z"})
      if (in.pick(8) != 0) make_dataset(g, a, in);
  };
  if (layout == 0) { // H5Part
    const unsigned steps = 1 + in.pick(3);
    for (unsigned s = 0; s < steps; ++s) {
      const std::string name = "Step#" + std::to_string(in.pick(4));
      if (H5Lexists(f, name.c_str(), H5P_DEFAULT) > 0) continue;
      const hid_t g = H5Gcreate2(f, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      make_attribute(g, in);
      xyz(g);
      fill_group(g, in, 1);
      H5Gclose(g);
    }
  } else if (layout == 1) { // PySPH
    const hid_t p = H5Gcreate2(f, "particles", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    const hid_t fl = H5Gcreate2(p, in.flag() ? "fluid" : "solid", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (in.pick(4) != 0) {
      const hid_t a = H5Gcreate2(fl, "arrays", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
      xyz(a);
      fill_group(a, in, 2);
      H5Gclose(a);
    }
    H5Gclose(fl);
    H5Gclose(p);
  } else if (layout == 2) { // GADGET
    const hid_t h = H5Gcreate2(f, "Header", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    make_attribute(h, in);
    H5Gclose(h);
    const hid_t p = H5Gcreate2(f, "PartType0", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    make_dataset(p, "Coordinates", in);
    fill_group(p, in, 1);
    H5Gclose(p);
  }
  fill_group(f, in, 0);
}

std::vector<unsigned char> image(unsigned layout, Input& in) {
  const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  H5Pset_fapl_core(fapl, 1 << 16, 0);
  const hid_t f = H5Fcreate("fuzz-build.h5", H5F_ACC_TRUNC, H5P_DEFAULT, fapl);
  H5Pclose(fapl);
  std::vector<unsigned char> out;
  if (f < 0) return out;
  build(f, layout, in);
  H5Fflush(f, H5F_SCOPE_GLOBAL);
  const ssize_t n = H5Fget_file_image(f, nullptr, 0);
  if (n > 0) {
    out.resize(static_cast<std::size_t>(n));
    H5Fget_file_image(f, out.data(), out.size());
  }
  H5Fclose(f);
  return out;
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  Input in(data, size);
  const unsigned mode = in.byte();
  const unsigned layout = mode % 4;
  std::vector<unsigned char> img = image(layout, in);
  if (img.empty()) return 0;
  static const bool flips = [] {
    const char* e = std::getenv("NBMC_FUZZ_HDF5_FLIPS");
    return e && *e == '1';
  }();
  if (mode == 255 && flips) {
    // Byte flips in the image: exercises HDF5's own parser.
    while (in.left() >= 3) {
      const std::size_t at = (in.byte() << 8 | in.byte()) % img.size();
      img[at] ^= static_cast<unsigned char>(in.byte());
    }
  }
  static const char* const formats[] = {"h5part", "pysph", "gadget", "hdf5"};
  static const char* const objects[] = {"",         ":/PartType0", ":/particles/fluid", ":/Step#0",
                                        ":/Step#0/x", ":/x",         ":/Coordinates",     ":/nothing/here"};
  nbmc::io::ReadOptions o;
  o.format = formats[in.pick(4)];
  const std::string object = objects[in.pick(8)];
  if (!object.empty()) o.format = "hdf5";
  o.frame = static_cast<int>(in.pick(4)) - 1;
  o.attributes = in.pick(4) != 0;
  if (in.flag()) o.only = {"v"};
  nbmc_fuzz::parse_twice(img.data(), img.size(), o, "fuzz.h5" + object);
  return 0;
}
