// SPDX-License-Identifier: MIT
#include "io/detail.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <limits>
#include <system_error>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace nbmc::io::detail {

void fail(const std::string& name, const std::string& what) { throw Error(name + ": " + what); }
void fail_io(const std::string& name, const std::string& what) { throw Error(name + ": " + what, Error::Kind::io); }
void fail_arg(const std::string& name, const std::string& what) {
  throw Error(name + ": " + what, Error::Kind::argument);
}

bool host_is_little_endian() {
  const std::uint16_t one = 1;
  unsigned char first = 0;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

std::size_t scalar_size(Scalar t) {
  switch (t) {
  case Scalar::int8:
  case Scalar::uint8: return 1;
  case Scalar::int16:
  case Scalar::uint16: return 2;
  case Scalar::int32:
  case Scalar::uint32:
  case Scalar::float32: return 4;
  case Scalar::int64:
  case Scalar::uint64:
  case Scalar::float64: return 8;
  }
  return 1;
}

double load_scalar(Scalar t, const unsigned char* base, std::size_t i, bool be) {
  const unsigned char* p = base + i * scalar_size(t);
  switch (t) {
  case Scalar::int8: return static_cast<double>(static_cast<std::int8_t>(p[0]));
  case Scalar::uint8: return static_cast<double>(p[0]);
  case Scalar::int16: return static_cast<double>(load_as<std::int16_t>(p, be));
  case Scalar::uint16: return static_cast<double>(load_as<std::uint16_t>(p, be));
  case Scalar::int32: return static_cast<double>(load_as<std::int32_t>(p, be));
  case Scalar::uint32: return static_cast<double>(load_as<std::uint32_t>(p, be));
  case Scalar::int64: return static_cast<double>(load_as<std::int64_t>(p, be));
  case Scalar::uint64: return static_cast<double>(load_as<std::uint64_t>(p, be));
  case Scalar::float32: return static_cast<double>(load_as<float>(p, be));
  case Scalar::float64: return load_as<double>(p, be);
  }
  return 0;
}

std::string to_lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string lower_extension(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t start = slash == std::string::npos ? 0 : slash + 1;
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || dot <= start) return {}; // none, or a hidden file's leading dot
  return to_lower(path.substr(dot));
}

// --------------------------------------------------------------- ByteReader
namespace {
constexpr std::size_t kFileBuffer = std::size_t(1) << 20;
}

ByteReader::ByteReader(const std::string& path) : name_(path) {
  do {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  } while (fd_ < 0 && errno == EINTR);
  if (fd_ < 0) fail_io(path, std::string("cannot open: ") + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int err = errno;
    ::close(fd_);
    fail_io(path, std::string("cannot stat: ") + std::strerror(err));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd_);
    fail_io(path, S_ISDIR(st.st_mode) ? "is a directory" : "is not a regular file");
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  buffer_.resize(static_cast<std::size_t>(std::min<std::uint64_t>(size_ + 1, kFileBuffer)));
  begin_ = cur_ = end_ = buffer_.data();
}

ByteReader::ByteReader(const void* data, std::size_t size, std::string name)
    : name_(std::move(name)), size_(size) {
  begin_ = cur_ = static_cast<const unsigned char*>(data);
  end_ = begin_ + (data ? size : 0);
  if (!data) size_ = 0;
}

ByteReader::~ByteReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool ByteReader::refill() {
  if (fd_ < 0) return false;
  base_ += static_cast<std::uint64_t>(end_ - begin_);
  begin_ = cur_ = end_ = buffer_.data();
  for (;;) {
    const ssize_t n = ::read(fd_, buffer_.data(), buffer_.size());
    if (n > 0) {
      end_ = begin_ + n;
      return true;
    }
    if (n == 0) return false;
    if (errno != EINTR) fail_io(name_, std::string("read error: ") + std::strerror(errno));
  }
}

std::size_t ByteReader::read(void* dst, std::size_t n) {
  auto* out = static_cast<unsigned char*>(dst);
  std::size_t done = 0;
  while (done < n) {
    if (cur_ == end_ && !refill()) break;
    const std::size_t k = std::min<std::size_t>(n - done, static_cast<std::size_t>(end_ - cur_));
    std::memcpy(out + done, cur_, k);
    cur_ += k;
    done += k;
  }
  return done;
}

std::uint64_t ByteReader::skip(std::uint64_t n) {
  std::uint64_t done = 0;
  while (done < n) {
    if (cur_ == end_ && !refill()) break;
    const std::uint64_t k = std::min<std::uint64_t>(n - done, static_cast<std::uint64_t>(end_ - cur_));
    cur_ += k;
    done += k;
  }
  return done;
}

std::vector<unsigned char> ByteReader::read_rest() {
  std::vector<unsigned char> out(static_cast<std::size_t>(remaining()));
  const std::size_t got = read(out.data(), out.size());
  if (got != out.size())
    fail_io(name_, "file ends after " + std::to_string(tell()) + " of " + std::to_string(size_) +
                       " bytes (did it change while being read?)");
  return out;
}

// --------------------------------------------------------------------- PLY
std::size_t ply_type_size(PlyType t) {
  switch (t) {
  case PlyType::int8:
  case PlyType::uint8: return 1;
  case PlyType::int16:
  case PlyType::uint16: return 2;
  case PlyType::int32:
  case PlyType::uint32:
  case PlyType::float32: return 4;
  case PlyType::float64: return 8;
  }
  return 1;
}

const char* ply_type_name(PlyType t) {
  switch (t) {
  case PlyType::int8: return "char";
  case PlyType::uint8: return "uchar";
  case PlyType::int16: return "short";
  case PlyType::uint16: return "ushort";
  case PlyType::int32: return "int";
  case PlyType::uint32: return "uint";
  case PlyType::float32: return "float";
  case PlyType::float64: return "double";
  }
  return "?";
}

bool ply_type_is_float(PlyType t) { return t == PlyType::float32 || t == PlyType::float64; }

int PlyElement::find(std::string_view property) const {
  for (std::size_t i = 0; i < properties.size(); ++i)
    if (properties[i].name == property) return static_cast<int>(i);
  return -1;
}

int PlyHeader::find(std::string_view element) const {
  for (std::size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == element) return static_cast<int>(i);
  return -1;
}

namespace {

constexpr std::uint64_t kMaxHeaderBytes = std::uint64_t(1) << 20;

bool parse_type(std::string_view s, PlyType& t) {
  struct Entry {
    const char* name;
    PlyType type;
  };
  static const Entry table[] = {
      {"char", PlyType::int8},     {"int8", PlyType::int8},       {"uchar", PlyType::uint8},
      {"uint8", PlyType::uint8},   {"short", PlyType::int16},     {"int16", PlyType::int16},
      {"ushort", PlyType::uint16}, {"uint16", PlyType::uint16},   {"int", PlyType::int32},
      {"int32", PlyType::int32},   {"uint", PlyType::uint32},     {"uint32", PlyType::uint32},
      {"float", PlyType::float32}, {"float32", PlyType::float32}, {"double", PlyType::float64},
      {"float64", PlyType::float64}};
  for (const Entry& e : table)
    if (s == e.name) {
      t = e.type;
      return true;
    }
  return false;
}

std::vector<std::string_view> split(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

bool parse_u64(std::string_view s, std::uint64_t& v) {
  if (s.empty()) return false;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

// Reads one header line (without "\n" and a trailing "\r") into line.
// Returns false at the end of the data.
bool read_line(ByteReader& in, std::string& line, std::uint64_t limit) {
  line.clear();
  for (;;) {
    const int c = in.get();
    if (c < 0) return false;
    if (c == '\n') break;
    line.push_back(static_cast<char>(c));
    if (in.tell() > limit) return false;
  }
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return true;
}

} // namespace

// A header line shown in a message: at most 40 characters, non-printable
// bytes replaced, so that a binary file does not garble the terminal.
std::string printable(std::string_view s) {
  std::string out;
  for (std::size_t i = 0; i < s.size() && i < 40; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (s.size() > 40) out += "...";
  return out;
}

PlyHeader read_ply_header(ByteReader& in) {
  const std::string& name = in.name();
  std::string line;
  if (!read_line(in, line, 8) || line != "ply") fail(name, "not a PLY file (the first line is not 'ply')");

  PlyHeader h;
  bool have_format = false;
  for (;;) {
    if (!read_line(in, line, kMaxHeaderBytes)) {
      if (in.tell() > kMaxHeaderBytes) fail(name, "PLY header longer than 1 MiB (no end_header)");
      fail(name, "PLY header ends without 'end_header'");
    }
    const std::vector<std::string_view> tok = split(line);
    if (tok.empty()) continue;
    const std::string_view key = tok[0];
    if (key == "end_header") break;
    if (key == "comment" || key == "obj_info") continue;
    if (key == "format") {
      if (have_format) fail(name, "PLY header has two 'format' lines");
      if (tok.size() != 3) fail(name, "malformed PLY format line '" + printable(line) + "'");
      if (tok[1] == "ascii")
        h.format = PlyFormat::ascii;
      else if (tok[1] == "binary_little_endian")
        h.format = PlyFormat::binary_little_endian;
      else if (tok[1] == "binary_big_endian")
        h.format = PlyFormat::binary_big_endian;
      else
        fail(name, "unknown PLY format '" + printable(tok[1]) + "'");
      if (tok[2] != "1.0" && tok[2] != "1")
        fail(name, "unsupported PLY version '" + printable(tok[2]) + "' (expected 1.0)");
      have_format = true;
    } else if (key == "element") {
      PlyElement e;
      if (tok.size() != 3 || !parse_u64(tok[2], e.count))
        fail(name, "malformed PLY element line '" + printable(line) + "'");
      e.name = std::string(tok[1]);
      h.elements.push_back(std::move(e));
    } else if (key == "property") {
      if (h.elements.empty()) fail(name, "PLY property line before any element");
      PlyElement& e = h.elements.back();
      PlyProperty p;
      if (tok.size() == 5 && tok[1] == "list") {
        p.is_list = true;
        if (!parse_type(tok[2], p.count_type) || !parse_type(tok[3], p.type))
          fail(name, "unknown type in PLY property line '" + printable(line) + "'");
        if (ply_type_is_float(p.count_type))
          fail(name, "PLY list property '" + printable(tok[4]) + "' has a floating-point count type");
        p.name = std::string(tok[4]);
      } else if (tok.size() == 3 && tok[1] != "list") {
        if (!parse_type(tok[1], p.type))
          fail(name, "unknown PLY property type '" + printable(tok[1]) + "'");
        p.name = std::string(tok[2]);
      } else {
        fail(name, "malformed PLY property line '" + printable(line) + "'");
      }
      if (e.find(p.name) >= 0)
        fail(name, "PLY element '" + printable(e.name) + "' has two properties called '" + printable(p.name) + "'");
      e.properties.push_back(std::move(p));
    } else {
      fail(name, "unexpected PLY header line '" + printable(line) + "'");
    }
  }
  if (!have_format) fail(name, "PLY header has no 'format' line");
  return h;
}

// ------------------------------------------------------------------ PlyBody
void PlyBody::read_raw(void* dst, std::size_t n) {
  if (in_.read(dst, n) != n) throw EndOfData{};
  const bool swap = (format_ == PlyFormat::binary_big_endian) == host_is_little_endian();
  if (swap) std::reverse(static_cast<unsigned char*>(dst), static_cast<unsigned char*>(dst) + n);
}

std::string_view PlyBody::token() {
  int c = in_.get();
  while (c == ' ' || c == '\t' || c == '\r' || c == '\n') c = in_.get();
  if (c < 0) throw EndOfData{};
  std::size_t n = 0;
  while (c >= 0 && c != ' ' && c != '\t' && c != '\r' && c != '\n') {
    if (n + 1 >= sizeof token_)
      fail(in_.name(), "value too long in the PLY body near byte " + std::to_string(in_.tell()));
    token_[n++] = static_cast<char>(c);
    c = in_.get();
  }
  return std::string_view(token_, n);
}

namespace {
template <class T> double load_as_double(const unsigned char* b) {
  T v;
  std::memcpy(&v, b, sizeof v);
  return static_cast<double>(v);
}
} // namespace

double PlyBody::read_real(PlyType t) {
  if (format_ == PlyFormat::ascii) {
    std::string_view s = token();
    if (s.size() > 1 && s[0] == '+' && s[1] != '-') s.remove_prefix(1);
    double v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (r.ec != std::errc() || r.ptr != s.data() + s.size())
      fail(in_.name(), "'" + printable(s) + "' is not a number (near byte " + std::to_string(in_.tell()) + ")");
    return v;
  }
  unsigned char b[8];
  read_raw(b, ply_type_size(t));
  switch (t) {
  case PlyType::int8: return load_as_double<std::int8_t>(b);
  case PlyType::uint8: return load_as_double<std::uint8_t>(b);
  case PlyType::int16: return load_as_double<std::int16_t>(b);
  case PlyType::uint16: return load_as_double<std::uint16_t>(b);
  case PlyType::int32: return load_as_double<std::int32_t>(b);
  case PlyType::uint32: return load_as_double<std::uint32_t>(b);
  case PlyType::float32: return load_as_double<float>(b);
  case PlyType::float64: return load_as_double<double>(b);
  }
  return 0;
}

std::uint64_t PlyBody::read_index(PlyType t, const char* what) {
  if (format_ == PlyFormat::ascii) {
    std::string_view s = token();
    if (s.size() > 1 && s[0] == '+') s.remove_prefix(1);
    std::uint64_t v = 0;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
    if (r.ec != std::errc() || r.ptr != s.data() + s.size())
      fail(in_.name(), std::string(what) + " '" + printable(s) + "' is not a non-negative integer");
    return v;
  }
  unsigned char b[8];
  read_raw(b, ply_type_size(t));
  std::int64_t v = 0;
  switch (t) {
  case PlyType::int8: v = static_cast<std::int64_t>(load_as_double<std::int8_t>(b)); break;
  case PlyType::uint8: v = b[0]; break;
  case PlyType::int16: v = static_cast<std::int64_t>(load_as_double<std::int16_t>(b)); break;
  case PlyType::uint16: v = static_cast<std::int64_t>(load_as_double<std::uint16_t>(b)); break;
  case PlyType::int32: v = static_cast<std::int64_t>(load_as_double<std::int32_t>(b)); break;
  case PlyType::uint32: v = static_cast<std::int64_t>(load_as_double<std::uint32_t>(b)); break;
  default: fail(in_.name(), std::string(what) + " has a floating-point type");
  }
  if (v < 0) fail(in_.name(), std::string("negative ") + what + " " + std::to_string(v));
  return static_cast<std::uint64_t>(v);
}

void PlyBody::skip(PlyType t) {
  if (format_ == PlyFormat::ascii) {
    token();
    return;
  }
  const std::size_t n = ply_type_size(t);
  if (in_.skip(n) != n) throw EndOfData{};
}

void PlyBody::skip(const PlyProperty& p) {
  if (!p.is_list) {
    skip(p.type);
    return;
  }
  const std::uint64_t n = read_index(p.count_type, "list length");
  if (format_ == PlyFormat::ascii) {
    if (n > in_.remaining()) throw EndOfData{}; // every value takes at least one byte
    for (std::uint64_t i = 0; i < n; ++i) token();
    return;
  }
  const std::size_t size = ply_type_size(p.type);
  if (n > in_.remaining() / size) throw EndOfData{};
  if (in_.skip(n * size) != n * size) throw EndOfData{};
}

void PlyBody::skip_element(const PlyElement& e) {
  if (e.properties.empty()) return;
  bool fixed = format_ != PlyFormat::ascii;
  std::uint64_t record = 0;
  for (const PlyProperty& p : e.properties) {
    fixed = fixed && !p.is_list;
    record += ply_type_size(p.type);
  }
  if (fixed) {
    if (e.count > in_.remaining() / record) throw EndOfData{};
    if (in_.skip(e.count * record) != e.count * record) throw EndOfData{};
    return;
  }
  // Every record takes at least one byte, so this loop ends with the data.
  for (std::uint64_t i = 0; i < e.count; ++i)
    for (const PlyProperty& p : e.properties) skip(p);
}

} // namespace nbmc::io::detail
