// SPDX-License-Identifier: MIT
// nbmc::io internals: bounded zlib/gzip inflation and base64 decoding.
#ifndef NBMC_IO_CODEC_HPP
#define NBMC_IO_CODEC_HPP

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace nbmc::io::detail {

// Deflate cannot expand data by more than this factor (RFC 1951: a 258-byte
// match costs at least 2 bits), so a compressed block of n bytes never holds
// more than n * kMaxDeflateRatio bytes.
constexpr std::uint64_t kMaxDeflateRatio = 1032;

// Inflates a whole gzip (RFC 1952; concatenated members allowed) or zlib
// (RFC 1950) stream. The output grows with the data actually decoded and
// may not exceed max_out bytes. Throws Error naming name on corrupt data,
// a truncated stream or too much output.
std::vector<unsigned char> inflate_all(const unsigned char* src, std::size_t n, std::uint64_t max_out,
                                       const std::string& name, const std::string& what);

// Inflates one zlib block of n bytes into exactly expected bytes at dst.
void inflate_block(const unsigned char* src, std::size_t n, unsigned char* dst, std::size_t expected,
                   const std::string& name, const std::string& what);

// Compresses a buffer into one zlib block (level 6 by default).
std::vector<unsigned char> deflate_block(const unsigned char* src, std::size_t n, int level = 6);

// Streaming base64 decoder over [begin, end). Whitespace is skipped; '='
// padding ends a group, after which decoding starts afresh, so blocks that
// were encoded one after the other (VTK's compression header and data) decode
// as one byte stream.
class Base64 {
public:
  Base64(const char* begin, const char* end) : cur_(begin), end_(end) {}
  // Decodes up to n bytes into dst; returns how many (< n at the end of the
  // text). Throws Error(name: ...) on a character outside the alphabet.
  std::size_t read(unsigned char* dst, std::size_t n, const std::string& name);
  // Upper bound of the bytes left.
  std::uint64_t remaining_bound() const { return static_cast<std::uint64_t>(end_ - cur_) / 4 * 3 + 3; }

private:
  bool fill(const std::string& name);
  const char* cur_;
  const char* end_;
  unsigned char out_[3] = {0, 0, 0};
  int have_ = 0, pos_ = 0;
};

std::string base64_encode(const unsigned char* src, std::size_t n);

} // namespace nbmc::io::detail

#endif
