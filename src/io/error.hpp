// SPDX-License-Identifier: MIT
// nbmc::io — the exception type of the file-format readers and writers.
#ifndef NBMC_IO_ERROR_HPP
#define NBMC_IO_ERROR_HPP

#include <stdexcept>
#include <string>

namespace nbmc::io {

// Thrown by every reader and writer of nbmc::io. what() names the file and
// what is wrong with it ("frame.ply: header says 1000 vertices but the file
// ends after 10"). kind() tells a malformed or unsupported file (format) from
// a file that cannot be opened, read or written (io) and from a bad request
// such as an unknown format name (argument); the C API maps them to
// NBMC_ERROR_FORMAT, NBMC_ERROR_IO and NBMC_ERROR_INVALID_ARGUMENT.
class Error : public std::runtime_error {
public:
  enum class Kind { format, io, argument };
  explicit Error(const std::string& what, Kind kind = Kind::format) : std::runtime_error(what), kind_(kind) {}
  Kind kind() const noexcept { return kind_; }

private:
  Kind kind_;
};

// Thrown by a writer whose cancellation check returned true; the destination
// is left untouched.
class Cancelled : public Error {
public:
  explicit Cancelled(const std::string& what) : Error(what, Kind::io) {}
};

} // namespace nbmc::io

#endif
