// SPDX-License-Identifier: MIT
// VTK XML reader (.vtu UnstructuredGrid, .vtp PolyData): a small XML
// tokenizer of its own, DataArrays in ascii, inline base64 ("binary") or
// appended (raw or base64) form, uncompressed or vtkZLibDataCompressor, with
// UInt32 or UInt64 block headers, little- or big-endian.
#include "io/codec.hpp"
#include "io/readers.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>

namespace nbmc::io::detail {

namespace {

constexpr int kMaxDepth = 64;
constexpr std::size_t kMaxNodes = 1 << 20;
constexpr std::size_t kMaxAttributes = 256;

struct Node {
  std::string name;
  std::vector<std::pair<std::string, std::string>> attrs;
  std::size_t text_begin = 0, text_end = 0; // first text run inside the element
  bool has_text = false;
  std::vector<std::size_t> children;
  const std::string* attr(const char* key) const {
    for (const auto& a : attrs)
      if (a.first == key) return &a.second;
    return nullptr;
  }
};

bool is_space(unsigned char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }
bool is_name_char(unsigned char c) {
  return std::isalnum(c) || c == '_' || c == '-' || c == '.' || c == ':' || c >= 0x80;
}

class Xml {
public:
  Xml(const unsigned char* data, std::size_t size, const std::string& name) : d_(data), n_(size), name_(name) {}
  void parse();
  const Node& node(std::size_t i) const { return nodes_[i]; }
  std::size_t root() const { return 0; }
  bool has_appended() const { return appended_begin_ != 0; }
  std::size_t appended_begin() const { return appended_begin_; }
  std::size_t appended_end() const { return appended_end_; }
  const std::string* appended_encoding() const { return appended_encoding_.empty() ? nullptr : &appended_encoding_; }
  const unsigned char* data() const { return d_; }

private:
  [[noreturn]] void bad(const std::string& what) const {
    fail(name_, "malformed XML near byte " + std::to_string(p_) + ": " + what);
  }
  void skip_until(const char* s) {
    const std::size_t len = std::strlen(s);
    while (p_ + len <= n_ && std::memcmp(d_ + p_, s, len) != 0) ++p_;
    if (p_ + len > n_) bad(std::string("no closing '") + s + "'");
    p_ += len;
  }
  bool starts(const char* s) const {
    const std::size_t len = std::strlen(s);
    return p_ + len <= n_ && std::memcmp(d_ + p_, s, len) == 0;
  }
  std::string name() {
    const std::size_t b = p_;
    while (p_ < n_ && is_name_char(d_[p_])) ++p_;
    if (p_ == b) bad("a name was expected");
    if (p_ - b > 256) bad("a name longer than 256 characters");
    return std::string(reinterpret_cast<const char*>(d_ + b), p_ - b);
  }
  void spaces() {
    while (p_ < n_ && is_space(d_[p_])) ++p_;
  }
  std::string value(char quote);

  const unsigned char* d_;
  std::size_t n_;
  const std::string& name_;
  std::size_t p_ = 0;
  std::vector<Node> nodes_;
  std::size_t appended_begin_ = 0, appended_end_ = 0;
  std::string appended_encoding_;
};

std::string Xml::value(char quote) {
  std::string out;
  while (p_ < n_ && d_[p_] != static_cast<unsigned char>(quote)) {
    if (d_[p_] == '<') bad("'<' in an attribute value");
    if (d_[p_] == '&') {
      const std::size_t semi_limit = std::min(n_, p_ + 12);
      std::size_t e = p_ + 1;
      while (e < semi_limit && d_[e] != ';') ++e;
      if (e >= semi_limit) bad("unterminated entity");
      const std::string ent(reinterpret_cast<const char*>(d_ + p_ + 1), e - p_ - 1);
      if (ent == "lt") out += '<';
      else if (ent == "gt") out += '>';
      else if (ent == "amp") out += '&';
      else if (ent == "quot") out += '"';
      else if (ent == "apos") out += '\'';
      else if (!ent.empty() && ent[0] == '#') {
        unsigned long v = 0;
        const bool hex = ent.size() > 1 && (ent[1] == 'x' || ent[1] == 'X');
        const char* b = ent.data() + (hex ? 2 : 1);
        const auto r = std::from_chars(b, ent.data() + ent.size(), v, hex ? 16 : 10);
        if (r.ec != std::errc() || r.ptr != ent.data() + ent.size() || v == 0 || v > 0x10ffff) bad("bad character reference");
        if (v < 0x80) out += static_cast<char>(v);
        else out += '?';
      } else {
        bad("unknown entity '&" + printable(ent) + ";'");
      }
      p_ = e + 1;
      continue;
    }
    out += static_cast<char>(d_[p_++]);
    if (out.size() > (1u << 16)) bad("attribute value longer than 64 KiB");
  }
  if (p_ >= n_) bad("unterminated attribute value");
  ++p_;
  return out;
}

void Xml::parse() {
  if (n_ >= 3 && d_[0] == 0xef && d_[1] == 0xbb && d_[2] == 0xbf) p_ = 3;
  std::vector<std::size_t> stack;
  bool done = false;
  while (p_ < n_ && !done) {
    if (d_[p_] != '<') {
      const std::size_t b = p_;
      while (p_ < n_ && d_[p_] != '<') ++p_;
      if (!stack.empty()) {
        Node& top = nodes_[stack.back()];
        if (!top.has_text) {
          top.has_text = true;
          top.text_begin = b;
          top.text_end = p_;
        }
      } else {
        for (std::size_t i = b; i < p_; ++i)
          if (!is_space(d_[i])) bad("text outside the root element");
      }
      continue;
    }
    if (starts("<?")) {
      skip_until("?>");
      continue;
    }
    if (starts("<!--")) {
      skip_until("-->");
      continue;
    }
    if (starts("<![CDATA[")) {
      const std::size_t b = p_ + 9;
      skip_until("]]>");
      if (!stack.empty()) {
        Node& top = nodes_[stack.back()];
        if (!top.has_text) {
          top.has_text = true;
          top.text_begin = b;
          top.text_end = p_ - 3;
        }
      }
      continue;
    }
    if (starts("<!")) {
      skip_until(">");
      continue;
    }
    if (starts("</")) {
      p_ += 2;
      const std::string nm = name();
      spaces();
      if (p_ >= n_ || d_[p_] != '>') bad("'>' expected");
      ++p_;
      if (stack.empty() || nodes_[stack.back()].name != nm) bad("closing tag '" + printable(nm) + "' does not match");
      stack.pop_back();
      if (stack.empty()) done = true;
      continue;
    }
    ++p_;
    if (stack.empty() && !nodes_.empty()) bad("a second root element");
    if (nodes_.size() >= kMaxNodes) bad("more than 2^20 elements");
    if (stack.size() >= static_cast<std::size_t>(kMaxDepth)) bad("elements nested deeper than 64");
    Node nd;
    nd.name = name();
    for (;;) {
      spaces();
      if (p_ >= n_) bad("unterminated tag");
      if (d_[p_] == '>' || d_[p_] == '/') break;
      std::string key = name();
      spaces();
      if (p_ >= n_ || d_[p_] != '=') bad("'=' expected after attribute '" + printable(key) + "'");
      ++p_;
      spaces();
      if (p_ >= n_ || (d_[p_] != '"' && d_[p_] != '\'')) bad("quoted attribute value expected");
      const char q = static_cast<char>(d_[p_++]);
      std::string v = value(q);
      if (nd.attrs.size() >= kMaxAttributes) bad("too many attributes");
      nd.attrs.emplace_back(std::move(key), std::move(v));
    }
    bool empty = false;
    if (d_[p_] == '/') {
      ++p_;
      if (p_ >= n_ || d_[p_] != '>') bad("'>' expected");
      empty = true;
    }
    ++p_;
    const std::size_t idx = nodes_.size();
    const bool appended = nd.name == "AppendedData";
    if (appended) {
      if (const std::string* e = nd.attr("encoding")) appended_encoding_ = *e;
    }
    nodes_.push_back(std::move(nd));
    if (!stack.empty()) nodes_[stack.back()].children.push_back(idx);
    if (appended && !empty) {
      // Binary data follow an underscore; the rest is not XML.
      while (p_ < n_ && d_[p_] != '_') {
        if (!is_space(d_[p_])) bad("appended data must start with '_'");
        ++p_;
      }
      if (p_ >= n_) bad("appended data without '_'");
      appended_begin_ = ++p_;
      appended_end_ = n_;
      static const char kClose[] = "</AppendedData>";
      const std::size_t len = sizeof kClose - 1;
      if (n_ >= appended_begin_ + len)
        for (std::size_t i = n_ - len + 1; i-- > appended_begin_;)
          if (std::memcmp(d_ + i, kClose, len) == 0) {
            appended_end_ = i;
            break;
          }
      return;
    }
    if (!empty) stack.push_back(idx);
    else if (stack.empty()) done = true;
  }
  if (nodes_.empty()) bad("no XML element");
  if (!done) bad("the document ends inside element '" + printable(nodes_[stack.empty() ? 0 : stack.back()].name) + "'");
}

// ------------------------------------------------------------ byte sources
class Source {
public:
  virtual ~Source() = default;
  virtual std::size_t read(unsigned char* dst, std::size_t n) = 0;
  virtual std::uint64_t remaining_bound() const = 0;
};

class RawSource : public Source {
public:
  RawSource(const unsigned char* b, const unsigned char* e) : cur_(b), end_(e) {}
  std::size_t read(unsigned char* dst, std::size_t n) override {
    const std::size_t k = std::min<std::size_t>(n, static_cast<std::size_t>(end_ - cur_));
    if (k) std::memcpy(dst, cur_, k); // dst may be null when k == 0
    cur_ += k;
    return k;
  }
  std::uint64_t remaining_bound() const override { return static_cast<std::uint64_t>(end_ - cur_); }

private:
  const unsigned char* cur_;
  const unsigned char* end_;
};

class Base64Source : public Source {
public:
  Base64Source(const char* b, const char* e, const std::string& name) : dec_(b, e), name_(name) {}
  std::size_t read(unsigned char* dst, std::size_t n) override { return dec_.read(dst, n, name_); }
  std::uint64_t remaining_bound() const override { return dec_.remaining_bound(); }

private:
  Base64 dec_;
  const std::string& name_;
};

bool parse_type(const std::string& t, Scalar& s) {
  struct E {
    const char* name;
    Scalar s;
  };
  static const E table[] = {{"Int8", Scalar::int8},       {"UInt8", Scalar::uint8},    {"Int16", Scalar::int16},
                            {"UInt16", Scalar::uint16},   {"Int32", Scalar::int32},    {"UInt32", Scalar::uint32},
                            {"Int64", Scalar::int64},     {"UInt64", Scalar::uint64},  {"Float32", Scalar::float32},
                            {"Float64", Scalar::float64}, {"Char", Scalar::int8},      {"UChar", Scalar::uint8}};
  for (const E& e : table)
    if (t == e.name) {
      s = e.s;
      return true;
    }
  return false;
}

class VtkXml {
public:
  VtkXml(const unsigned char* data, std::size_t size, const std::string& name, const ReadOptions& o,
         std::vector<std::uint32_t>* tris)
      : xml_(data, size, name), name_(name), opt_(o), tris_(tris) {}
  Particles run();

private:
  std::uint64_t uint_attr(const Node& n, const char* key, std::uint64_t def, bool required);
  void read_array(const Node& da, std::uint64_t values, std::vector<double>& out, const std::string& what);
  std::vector<unsigned char> read_block(Source& src, std::uint64_t expected, const std::string& what);
  std::uint64_t read_header_uint(Source& src, const std::string& what);
  const Node* child(const Node& n, const char* nm) const {
    for (std::size_t c : n.children)
      if (xml_.node(c).name == nm) return &xml_.node(c);
    return nullptr;
  }
  void read_cells(const Node& piece, const char* section, const char* count_key, std::uint64_t point_base,
                  std::uint64_t npoints);

  Xml xml_;
  const std::string& name_;
  const ReadOptions& opt_;
  std::vector<std::uint32_t>* tris_;
  bool big_endian_ = false;
  bool header64_ = false;
  bool zlib_ = false;
  std::string compressor_;
  Particles out_;
};

std::uint64_t VtkXml::uint_attr(const Node& n, const char* key, std::uint64_t def, bool required) {
  const std::string* v = n.attr(key);
  if (!v) {
    if (required) fail(name_, "<" + n.name + "> has no " + key + " attribute");
    return def;
  }
  std::uint64_t x = 0;
  const char* b = v->data();
  const char* e = b + v->size();
  while (b < e && is_space(static_cast<unsigned char>(*b))) ++b;
  while (e > b && is_space(static_cast<unsigned char>(e[-1]))) --e;
  const auto r = std::from_chars(b, e, x);
  if (r.ec != std::errc() || r.ptr != e || b == e)
    fail(name_, "<" + n.name + "> " + key + "=\"" + printable(*v) + "\" is not a non-negative integer");
  return x;
}

std::uint64_t VtkXml::read_header_uint(Source& src, const std::string& what) {
  unsigned char b[8];
  const std::size_t k = header64_ ? 8 : 4;
  if (src.read(b, k) != k) fail(name_, what + ": the data end inside the block header");
  return header64_ ? load_as<std::uint64_t>(b, big_endian_) : load_as<std::uint32_t>(b, big_endian_);
}

std::vector<unsigned char> VtkXml::read_block(Source& src, std::uint64_t expected, const std::string& what) {
  std::vector<unsigned char> out;
  if (!zlib_) {
    const std::uint64_t n = read_header_uint(src, what);
    if (n != expected)
      fail(name_, what + ": the block header declares " + std::to_string(n) + " bytes but the array needs " +
                      std::to_string(expected));
    if (n > src.remaining_bound())
      fail(name_, what + " needs " + std::to_string(n) + " bytes but fewer are left in the file");
    out.resize(static_cast<std::size_t>(n));
    if (src.read(out.data(), out.size()) != out.size()) fail(name_, what + ": the data end early");
    return out;
  }
  const std::uint64_t nblocks = read_header_uint(src, what);
  const std::uint64_t block = read_header_uint(src, what);
  const std::uint64_t last = read_header_uint(src, what);
  const std::uint64_t hsize = header64_ ? 8 : 4;
  if (nblocks > src.remaining_bound() / hsize)
    fail(name_, what + ": the compression header declares " + std::to_string(nblocks) + " blocks, more than the file holds");
  std::uint64_t total = 0;
  if (nblocks > 0) {
    if (block == 0 || last > block) fail(name_, what + ": bad compression header (block size " + std::to_string(block) + ", last " + std::to_string(last) + ")");
    const std::uint64_t last_size = last == 0 ? block : last;
    if (nblocks - 1 > (UINT64_MAX - last_size) / block) fail(name_, what + ": the compression header overflows");
    total = (nblocks - 1) * block + last_size;
  }
  if (total != expected)
    fail(name_, what + ": the compression header declares " + std::to_string(total) + " bytes but the array needs " +
                    std::to_string(expected));
  std::vector<std::uint64_t> csize(static_cast<std::size_t>(nblocks));
  std::uint64_t csum = 0;
  for (std::uint64_t& c : csize) {
    c = read_header_uint(src, what);
    if (c > src.remaining_bound()) fail(name_, what + ": a compressed block is larger than the rest of the file");
    csum += c;
  }
  if (csum > src.remaining_bound()) fail(name_, what + ": the compressed blocks are larger than the rest of the file");
  if (expected / kMaxDeflateRatio > csum + nblocks)
    fail(name_, what + ": " + std::to_string(csum) + " compressed bytes cannot hold " + std::to_string(expected) + " bytes");
  out.resize(static_cast<std::size_t>(expected));
  std::vector<unsigned char> cbuf;
  std::uint64_t pos = 0;
  for (std::uint64_t i = 0; i < nblocks; ++i) {
    const std::uint64_t usize = (i + 1 == nblocks && last != 0) ? last : block;
    const std::size_t cs = static_cast<std::size_t>(csize[static_cast<std::size_t>(i)]);
    if (usize / kMaxDeflateRatio > cs) fail(name_, what + ": compressed block " + std::to_string(i) + " is too small for its size");
    cbuf.resize(cs);
    if (src.read(cbuf.data(), cs) != cs) fail(name_, what + ": the data end inside compressed block " + std::to_string(i));
    inflate_block(cbuf.data(), cs, out.data() + pos, static_cast<std::size_t>(usize), name_,
                  what + " block " + std::to_string(i));
    pos += usize;
  }
  return out;
}

void VtkXml::read_array(const Node& da, std::uint64_t values, std::vector<double>& out, const std::string& what) {
  const std::string* type = da.attr("type");
  if (!type) fail(name_, what + " has no type attribute");
  Scalar s;
  if (!parse_type(*type, s)) fail(name_, what + " has unsupported type '" + printable(*type) + "'");
  const std::string* fmt_attr = da.attr("format");
  const std::string fmt = fmt_attr ? *fmt_attr : "ascii";
  const std::size_t size = scalar_size(s);
  if (fmt == "ascii") {
    const unsigned char* p = xml_.data() + da.text_begin;
    const unsigned char* e = xml_.data() + da.text_end;
    if (!da.has_text) p = e = xml_.data();
    if (values > static_cast<std::uint64_t>(e - p) / 2 + 1)
      fail(name_, what + " needs " + std::to_string(values) + " values but its text is " +
                      std::to_string(e - p) + " bytes long");
    out.resize(static_cast<std::size_t>(values));
    for (std::uint64_t i = 0; i < values; ++i) {
      while (p < e && is_space(*p)) ++p;
      const unsigned char* b = p;
      while (p < e && !is_space(*p)) ++p;
      if (b == p) fail(name_, what + " has " + std::to_string(i) + " values, expected " + std::to_string(values));
      const char* cb = reinterpret_cast<const char*>(b);
      const char* ce = reinterpret_cast<const char*>(p);
      if (ce - cb > 1 && *cb == '+') ++cb;
      double v = 0;
      auto r = std::from_chars(cb, ce, v);
      if (r.ec == std::errc::result_out_of_range && r.ptr == ce) {
        v = std::strtod(std::string(cb, ce).c_str(), nullptr);
        r.ec = std::errc();
      }
      if (r.ec != std::errc() || r.ptr != ce)
        fail(name_, "'" + printable(std::string(cb, ce)) + "' in " + what + " is not a number");
      out[static_cast<std::size_t>(i)] = v;
    }
    while (p < e && is_space(*p)) ++p;
    if (p != e) fail(name_, what + " has more than the " + std::to_string(values) + " values expected");
    return;
  }
  if (values > UINT64_MAX / size) fail(name_, what + " is too large");
  const std::uint64_t bytes = values * size;
  std::vector<unsigned char> raw;
  if (fmt == "binary") {
    const char* b = reinterpret_cast<const char*>(xml_.data() + da.text_begin);
    const char* e = reinterpret_cast<const char*>(xml_.data() + da.text_end);
    if (!da.has_text) b = e;
    Base64Source src(b, e, name_);
    raw = read_block(src, bytes, what);
  } else if (fmt == "appended") {
    if (!xml_.has_appended()) fail(name_, what + " is appended but the file has no <AppendedData>");
    const std::uint64_t offset = uint_attr(da, "offset", 0, true);
    const std::size_t ab = xml_.appended_begin(), ae = xml_.appended_end();
    if (offset > ae - ab) fail(name_, what + ": offset " + std::to_string(offset) + " is beyond the appended data");
    const std::string* enc = xml_.appended_encoding();
    const std::string encoding = enc ? *enc : "raw";
    if (encoding == "raw") {
      RawSource src(xml_.data() + ab + offset, xml_.data() + ae);
      raw = read_block(src, bytes, what);
    } else if (encoding == "base64") {
      Base64Source src(reinterpret_cast<const char*>(xml_.data() + ab + offset),
                       reinterpret_cast<const char*>(xml_.data() + ae), name_);
      raw = read_block(src, bytes, what);
    } else {
      fail(name_, "unsupported AppendedData encoding '" + printable(encoding) + "'");
    }
  } else {
    fail(name_, what + " has unsupported format '" + printable(fmt) + "'");
  }
  out.resize(static_cast<std::size_t>(values));
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = load_scalar(s, raw.data(), i, big_endian_);
}

void VtkXml::read_cells(const Node& piece, const char* section, const char* count_key, std::uint64_t point_base,
                        std::uint64_t npoints) {
  const std::uint64_t ncells = uint_attr(piece, count_key, 0, false);
  if (ncells == 0) return;
  const Node* cells = child(piece, section);
  if (!cells) fail(name_, std::string("a piece has ") + count_key + " but no <" + section + ">");
  const Node *conn = nullptr, *offs = nullptr, *types = nullptr;
  for (std::size_t c : cells->children) {
    const Node& n = xml_.node(c);
    const std::string* nm = n.attr("Name");
    if (n.name != "DataArray" || !nm) continue;
    if (*nm == "connectivity") conn = &n;
    if (*nm == "offsets") offs = &n;
    if (*nm == "types") types = &n;
  }
  if (!conn || !offs) fail(name_, std::string("<") + section + "> lacks the connectivity or offsets array");
  std::vector<double> off;
  read_array(*offs, ncells, off, std::string(section) + " offsets");
  const double nconn = off.empty() ? 0 : off.back();
  if (!(nconn >= 0) || nconn != 3.0 * static_cast<double>(ncells))
    fail(name_, std::string("<") + section + ">: only triangles are supported in a mesh");
  std::vector<double> cv;
  read_array(*conn, static_cast<std::uint64_t>(nconn), cv, std::string(section) + " connectivity");
  for (std::uint64_t i = 0; i < ncells; ++i)
    if (off[static_cast<std::size_t>(i)] != 3.0 * static_cast<double>(i + 1))
      fail(name_, std::string("<") + section + ">: cell " + std::to_string(i) + " is not a triangle");
  if (types) {
    std::vector<double> tv;
    read_array(*types, ncells, tv, std::string(section) + " types");
    for (double t : tv)
      if (t != 5) fail(name_, std::string("<") + section + ">: only triangles (type 5) are supported in a mesh");
  }
  for (double v : cv) {
    if (!(v >= 0) || v >= static_cast<double>(npoints))
      fail(name_, std::string("<") + section + "> refers to a point that does not exist");
    tris_->push_back(static_cast<std::uint32_t>(point_base + static_cast<std::uint64_t>(v)));
  }
}

Particles VtkXml::run() {
  xml_.parse();
  const Node& root = xml_.node(xml_.root());
  if (root.name != "VTKFile") fail(name_, "not a VTK XML file (the root element is <" + printable(root.name) + ">)");
  const std::string* type = root.attr("type");
  if (!type) fail(name_, "<VTKFile> has no type attribute");
  if (*type != "UnstructuredGrid" && *type != "PolyData")
    fail(name_, "VTK XML type '" + printable(*type) + "' is not supported (UnstructuredGrid, PolyData)");
  if (const std::string* bo = root.attr("byte_order")) {
    if (*bo == "BigEndian") big_endian_ = true;
    else if (*bo != "LittleEndian") fail(name_, "unknown byte_order '" + printable(*bo) + "'");
  }
  if (const std::string* ht = root.attr("header_type")) {
    if (*ht == "UInt64") header64_ = true;
    else if (*ht != "UInt32") fail(name_, "unsupported header_type '" + printable(*ht) + "' (UInt32, UInt64)");
  }
  if (const std::string* c = root.attr("compressor")) {
    if (*c == "vtkZLibDataCompressor") zlib_ = true;
    else if (!c->empty()) fail(name_, "unsupported compressor '" + printable(*c) + "' (only vtkZLibDataCompressor)");
  }
  const Node* grid = child(root, type->c_str());
  if (!grid) fail(name_, "no <" + *type + "> element");
  bool any_piece = false;
  std::vector<std::vector<Attribute>> piece_attrs;
  for (std::size_t pc : grid->children) {
    const Node& piece = xml_.node(pc);
    if (piece.name != "Piece") continue;
    any_piece = true;
    const std::uint64_t np = uint_attr(piece, "NumberOfPoints", 0, true);
    if (np > (std::uint64_t(1) << 40)) fail(name_, "NumberOfPoints " + std::to_string(np) + " is too large");
    const std::uint64_t base = out_.count();
    if (np > 0) {
      const Node* pts = child(piece, "Points");
      if (!pts) fail(name_, "a piece with " + std::to_string(np) + " points has no <Points>");
      const Node* da = child(*pts, "DataArray");
      if (!da) fail(name_, "<Points> has no <DataArray>");
      if (uint_attr(*da, "NumberOfComponents", 1, false) != 3) fail(name_, "<Points> DataArray does not have 3 components");
      std::vector<double> v;
      read_array(*da, 3 * np, v, "Points");
      out_.xyz.insert(out_.xyz.end(), v.begin(), v.end());
    }
    std::vector<Attribute> attrs;
    if (const Node* pd = child(piece, "PointData")) {
      for (std::size_t c : pd->children) {
        const Node& da = xml_.node(c);
        if (da.name != "DataArray") continue;
        const std::string* nm = da.attr("Name");
        const std::string aname = nm ? *nm : std::string("unnamed");
        const std::uint64_t comps = uint_attr(da, "NumberOfComponents", 1, false);
        if ((comps != 1 && comps != 3) || !want_attribute(opt_, aname)) continue;
        const std::string* t = da.attr("type");
        Scalar s;
        if (!t || !parse_type(*t, s)) continue; // strings and bits are no attributes
        bool dup = false;
        for (const Attribute& a : attrs) dup = dup || a.name == aname;
        if (dup) continue;
        Attribute a;
        a.name = aname;
        a.components = static_cast<int>(comps);
        read_array(da, comps * np, a.values, "point data array '" + printable(aname) + "'");
        attrs.push_back(std::move(a));
      }
    }
    piece_attrs.push_back(std::move(attrs));
    if (tris_) {
      if (*type == "UnstructuredGrid") read_cells(piece, "Cells", "NumberOfCells", base, np);
      else read_cells(piece, "Polys", "NumberOfPolys", base, np);
    }
  }
  if (!any_piece) fail(name_, "no <Piece> element");
  // Attributes that every piece has, in the order of the first piece.
  if (!piece_attrs.empty()) {
    for (Attribute& a : piece_attrs[0]) {
      bool everywhere = true;
      for (std::size_t p = 1; p < piece_attrs.size() && everywhere; ++p) {
        bool found = false;
        for (const Attribute& b : piece_attrs[p]) found = found || (b.name == a.name && b.components == a.components);
        everywhere = found;
      }
      if (!everywhere) continue;
      Attribute merged;
      merged.name = a.name;
      merged.components = a.components;
      merged.values = std::move(a.values);
      for (std::size_t p = 1; p < piece_attrs.size(); ++p)
        for (Attribute& b : piece_attrs[p])
          if (b.name == merged.name) merged.values.insert(merged.values.end(), b.values.begin(), b.values.end());
      out_.attributes.push_back(std::move(merged));
    }
  }
  merge_vector_attributes(out_.attributes);
  return std::move(out_);
}

} // namespace

Particles read_vtk_xml(const unsigned char* data, std::size_t size, const std::string& name, const ReadOptions& o,
                       std::vector<std::uint32_t>* triangles) {
  VtkXml reader(data, size, name, o, triangles);
  return reader.run();
}

} // namespace nbmc::io::detail
