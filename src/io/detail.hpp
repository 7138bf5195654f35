// SPDX-License-Identifier: MIT
// nbmc::io internals shared by the particle and mesh modules: a bounded byte
// reader over a file or a memory block, and a PLY header parser. Not part of
// any public interface.
#ifndef NBMC_IO_DETAIL_HPP
#define NBMC_IO_DETAIL_HPP

#include "io/error.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace nbmc::io::detail {

// Throws Error("<name>: <what>") of kind format (malformed or unsupported
// data), io (cannot open, read or write) or argument (bad request).
[[noreturn]] void fail(const std::string& name, const std::string& what);
[[noreturn]] void fail_io(const std::string& name, const std::string& what);
[[noreturn]] void fail_arg(const std::string& name, const std::string& what);

// At most 40 characters of s with non-printable bytes replaced by '?', for
// quoting file content in messages.
std::string printable(std::string_view s);

bool host_is_little_endian();

// Loads a value of type T stored in n = sizeof(T) bytes of the given byte
// order.
template <class T> T load_as(const unsigned char* src, bool big_endian) {
  unsigned char b[sizeof(T)];
  for (std::size_t i = 0; i < sizeof(T); ++i) b[i] = src[i];
  if (big_endian == host_is_little_endian())
    for (std::size_t i = 0; i < sizeof(T) / 2; ++i) {
      const unsigned char t = b[i];
      b[i] = b[sizeof(T) - 1 - i];
      b[sizeof(T) - 1 - i] = t;
    }
  T v;
  std::memcpy(&v, b, sizeof v);
  return v;
}

// Numeric element types shared by the VTK readers.
enum class Scalar { int8, uint8, int16, uint16, int32, uint32, int64, uint64, float32, float64 };
std::size_t scalar_size(Scalar t);
// Value i of an array of type t stored with the given byte order, as double.
double load_scalar(Scalar t, const unsigned char* base, std::size_t i, bool big_endian);

// Lower-case extension of path including the dot (".ply"), "" if none.
std::string lower_extension(const std::string& path);
std::string to_lower(std::string s);

// Sequential reader over a regular file (buffered) or a memory block. size()
// is known up front, so parsers can check counts from headers against the
// bytes that are really there before they allocate.
class ByteReader {
public:
  // Opens a regular file; throws Error naming the file on failure.
  explicit ByteReader(const std::string& path);
  // Reads from memory (not copied; must outlive the reader). name is used in
  // error messages.
  ByteReader(const void* data, std::size_t size, std::string name);
  ~ByteReader();
  ByteReader(const ByteReader&) = delete;
  ByteReader& operator=(const ByteReader&) = delete;

  const std::string& name() const { return name_; }
  std::uint64_t size() const { return size_; }
  std::uint64_t tell() const { return base_ + static_cast<std::uint64_t>(cur_ - begin_); }
  std::uint64_t remaining() const { return size_ > tell() ? size_ - tell() : 0; }

  // Next byte, or -1 at the end.
  int get() {
    if (cur_ == end_ && !refill()) return -1;
    return *cur_++;
  }
  int peek() {
    if (cur_ == end_ && !refill()) return -1;
    return *cur_;
  }
  // Copies up to n bytes; returns how many were copied (< n only at the end).
  std::size_t read(void* dst, std::size_t n);
  // Skips up to n bytes; returns how many were skipped.
  std::uint64_t skip(std::uint64_t n);
  // Reads everything left (remaining() bytes at most); for formats that are
  // parsed in memory.
  std::vector<unsigned char> read_rest();
  // The memory block of a memory reader (null for a file reader).
  const unsigned char* memory() const { return fd_ < 0 ? begin_ : nullptr; }

private:
  bool refill();

  std::string name_;
  int fd_ = -1;
  std::vector<unsigned char> buffer_;
  const unsigned char* begin_ = nullptr;
  const unsigned char* cur_ = nullptr;
  const unsigned char* end_ = nullptr;
  std::uint64_t base_ = 0; // offset of begin_ in the source
  std::uint64_t size_ = 0;
};

// ------------------------------------------------------------------ PLY
enum class PlyFormat { ascii, binary_little_endian, binary_big_endian };
enum class PlyType { int8, uint8, int16, uint16, int32, uint32, float32, float64 };

std::size_t ply_type_size(PlyType t);
const char* ply_type_name(PlyType t);
bool ply_type_is_float(PlyType t);

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::float32; // value type (item type of a list)
  bool is_list = false;
  PlyType count_type = PlyType::uint8; // lists only
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  // Index of the property called name, or -1.
  int find(std::string_view property) const;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
  // Index of the element called name, or -1.
  int find(std::string_view element) const;
};

// Parses the header and leaves the reader at the first byte of the body.
PlyHeader read_ply_header(ByteReader& in);

// Thrown by PlyBody when the data ends in the middle of a value; callers
// catch it and report which element ran short.
struct EndOfData {};

// Reads the values of a PLY body one at a time, in any of the three formats.
class PlyBody {
public:
  PlyBody(ByteReader& in, PlyFormat format) : in_(in), format_(format) {}
  // A scalar of type t as double (ASCII: any number).
  double read_real(PlyType t);
  // A non-negative integer (list counts, indices) of integer type t.
  std::uint64_t read_index(PlyType t, const char* what);
  // Skips one scalar of type t.
  void skip(PlyType t);
  // Skips one property value (scalar or whole list).
  void skip(const PlyProperty& p);
  // Skips count records of element e.
  void skip_element(const PlyElement& e);

private:
  void read_raw(void* dst, std::size_t n);
  std::string_view token();

  ByteReader& in_;
  PlyFormat format_;
  char token_[128];
};

} // namespace nbmc::io::detail

#endif
