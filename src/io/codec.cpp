// SPDX-License-Identifier: MIT
#include "io/codec.hpp"

#include "io/detail.hpp"

#include <zlib.h>

#include <algorithm>
#include <climits>
#include <cstring>

namespace nbmc::io::detail {

namespace {
std::string zmsg(const z_stream& z, int rc) {
  if (z.msg) return z.msg;
  switch (rc) {
  case Z_DATA_ERROR: return "corrupt data";
  case Z_MEM_ERROR: return "out of memory";
  case Z_BUF_ERROR: return "truncated data";
  case Z_STREAM_ERROR: return "stream error";
  default: return "zlib error " + std::to_string(rc);
  }
}
} // namespace

std::vector<unsigned char> inflate_all(const unsigned char* src, std::size_t n, std::uint64_t max_out,
                                       const std::string& name, const std::string& what) {
  std::vector<unsigned char> out;
  z_stream z{};
  if (inflateInit2(&z, 15 + 32) != Z_OK) throw std::bad_alloc(); // auto-detect gzip or zlib
  struct Guard {
    z_stream* z;
    ~Guard() { inflateEnd(z); }
  } guard{&z};
  std::size_t in_pos = 0;
  std::size_t used = 0;
  for (;;) {
    if (used == out.size()) {
      if (out.size() >= max_out)
        fail(name, what + " inflates to more than " + std::to_string(max_out) + " bytes");
      const std::uint64_t grow = std::max<std::uint64_t>(out.size(), 1 << 16);
      out.resize(static_cast<std::size_t>(std::min<std::uint64_t>(out.size() + grow, max_out)));
    }
    const std::size_t in_chunk = std::min<std::size_t>(n - in_pos, UINT_MAX);
    const std::size_t out_chunk = std::min<std::size_t>(out.size() - used, UINT_MAX);
    z.next_in = const_cast<unsigned char*>(src + in_pos);
    z.avail_in = static_cast<uInt>(in_chunk);
    z.next_out = out.data() + used;
    z.avail_out = static_cast<uInt>(out_chunk);
    const int rc = inflate(&z, Z_NO_FLUSH);
    const std::size_t produced = out_chunk - z.avail_out;
    in_pos += in_chunk - z.avail_in;
    used += produced;
    if (rc == Z_STREAM_END) {
      // Another gzip member may follow (gzip allows concatenation); anything
      // else after the end is ignored.
      if (n - in_pos >= 2 && src[in_pos] == 0x1f && src[in_pos + 1] == 0x8b) {
        if (inflateReset(&z) != Z_OK) fail(name, what + ": " + zmsg(z, rc));
        continue;
      }
      break;
    }
    if (rc == Z_OK) continue;
    if (rc == Z_BUF_ERROR) {
      if (in_pos == n && produced == 0 && z.avail_out > 0)
        fail(name, what + " is truncated (the compressed stream ends early)");
      continue;
    }
    fail(name, what + ": " + zmsg(z, rc));
  }
  out.resize(used);
  return out;
}

void inflate_block(const unsigned char* src, std::size_t n, unsigned char* dst, std::size_t expected,
                   const std::string& name, const std::string& what) {
  if (n > UINT_MAX || expected > UINT_MAX) fail(name, what + ": block larger than 4 GiB");
  z_stream z{};
  if (inflateInit(&z) != Z_OK) throw std::bad_alloc();
  z.next_in = const_cast<unsigned char*>(src);
  z.avail_in = static_cast<uInt>(n);
  z.next_out = dst;
  z.avail_out = static_cast<uInt>(expected);
  const int rc = inflate(&z, Z_FINISH);
  const uLong got = z.total_out;
  const std::string msg = rc == Z_STREAM_END ? std::string() : zmsg(z, rc);
  inflateEnd(&z);
  if (rc == Z_STREAM_END && got == expected) return;
  if (rc == Z_STREAM_END)
    fail(name, what + " inflates to " + std::to_string(got) + " bytes, the header says " + std::to_string(expected));
  if (rc == Z_BUF_ERROR && z.avail_out == 0)
    fail(name, what + " inflates to more than the " + std::to_string(expected) + " bytes the header says");
  fail(name, what + ": " + msg);
}

std::vector<unsigned char> deflate_block(const unsigned char* src, std::size_t n, int level) {
  uLongf size = compressBound(static_cast<uLong>(n));
  std::vector<unsigned char> out(size);
  if (compress2(out.data(), &size, src, static_cast<uLong>(n), level) != Z_OK) throw std::bad_alloc();
  out.resize(size);
  return out;
}

// ------------------------------------------------------------------ base64
namespace {
int b64_value(unsigned char c) {
  if (c >= 'A' && c <= 'Z') return c - 'A';
  if (c >= 'a' && c <= 'z') return c - 'a' + 26;
  if (c >= '0' && c <= '9') return c - '0' + 52;
  if (c == '+') return 62;
  if (c == '/') return 63;
  return -1;
}
bool is_space(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }
} // namespace

bool Base64::fill(const std::string& name) {
  std::uint32_t acc = 0;
  int k = 0;
  while (cur_ != end_ && k < 4) {
    const char c = *cur_;
    if (is_space(c)) {
      ++cur_;
      continue;
    }
    if (c == '=') {
      ++cur_;
      if (k < 2) fail(name, "malformed base64 data (misplaced '=')");
      // Consume the rest of the padding of this group.
      int pad = 4 - k - 1;
      while (pad > 0 && cur_ != end_) {
        if (*cur_ == '=') --pad;
        else if (!is_space(*cur_)) break;
        ++cur_;
      }
      break;
    }
    const int v = b64_value(static_cast<unsigned char>(c));
    if (v < 0) fail(name, "malformed base64 data (character '" + printable(std::string(1, c)) + "')");
    acc = (acc << 6) | static_cast<std::uint32_t>(v);
    ++k;
    ++cur_;
  }
  if (k == 0) return false;
  if (k == 1) fail(name, "malformed base64 data (a lone trailing character)");
  acc <<= 6 * (4 - k);
  out_[0] = static_cast<unsigned char>(acc >> 16);
  out_[1] = static_cast<unsigned char>(acc >> 8);
  out_[2] = static_cast<unsigned char>(acc);
  have_ = k - 1;
  pos_ = 0;
  return true;
}

std::size_t Base64::read(unsigned char* dst, std::size_t n, const std::string& name) {
  std::size_t done = 0;
  while (done < n) {
    if (pos_ == have_ && !fill(name)) break;
    dst[done++] = out_[pos_++];
  }
  return done;
}

std::string base64_encode(const unsigned char* src, std::size_t n) {
  static const char* kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((n + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= n; i += 3) {
    const std::uint32_t v = (std::uint32_t(src[i]) << 16) | (std::uint32_t(src[i + 1]) << 8) | src[i + 2];
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  if (i < n) {
    std::uint32_t v = std::uint32_t(src[i]) << 16;
    if (i + 1 < n) v |= std::uint32_t(src[i + 1]) << 8;
    out += kAlphabet[v >> 18];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < n ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

} // namespace nbmc::io::detail
