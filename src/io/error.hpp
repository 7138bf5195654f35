// SPDX-License-Identifier: MIT
// nbmc::io — the exception type of the file-format readers and writers.
#ifndef NBMC_IO_ERROR_HPP
#define NBMC_IO_ERROR_HPP

#include <stdexcept>
#include <string>

namespace nbmc::io {

// Thrown by every reader and writer of nbmc::io. what() names the file and
// what is wrong with it ("frame.ply: header says 1000 vertices but the file
// ends after 10").
class Error : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

// Thrown by a writer whose cancellation check returned true; the destination
// is left untouched.
class Cancelled : public Error {
public:
  using Error::Error;
};

} // namespace nbmc::io

#endif
