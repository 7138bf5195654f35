// SPDX-License-Identifier: MIT
// Frame sequences for the nbmc command: numbered files ('f_{}.bgeo') or the
// steps of an H5Part file, the --frames filter, per-frame progress lines and
// the summary.
#ifndef NBMC_CLI_SEQUENCE_HPP
#define NBMC_CLI_SEQUENCE_HPP

#include <nbmc.h>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace nbmc::cli {

struct Frame {
  std::string label;   // the number as it appears in the input name (or the step)
  std::string input;   // file to read
  std::int64_t step = -1; // H5Part step, -1 for a file per frame
  std::string output;  // mesh to write
  std::string missing; // non-empty: --frames asked for it but no file exists (the message)
};

struct SequencePlan {
  bool is_sequence = false;
  std::vector<Frame> frames; // when is_sequence
  std::int64_t step = -1;    // single H5Part step chosen by --frames
  bool usage_error = false;  // when planning fails: exit 2 (else 1)
};

// Works out what IN and OUT mean: a single frame, numbered files, or H5Part
// steps. Returns false with a message in error on a usage problem or an
// input that cannot be listed.
bool plan_sequence(const std::string& input, const std::string& output, const std::string& format,
                   const std::string& frames_spec, SequencePlan& plan, std::string& error);

// OUT with every "{}" removed (for telling the format from the extension).
std::string without_braces(const std::string& path);
bool output_exists(const std::string& path);
void make_parent_folders(const std::string& path);

class FrameError : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

struct FrameResult {
  std::string label, input, output;
  std::string status = "failed"; // written, skipped, failed
  std::string error;
  std::uint64_t particles = 0, vertices = 0, triangles = 0;
  double seconds = 0;
  // Its three phases (with overlapped I/O they run beside other frames'):
  // reading the file, the library (upload, reconstruction, post-processing;
  // waiting for the GPU included), writing the mesh.
  double read_seconds = 0, reconstruct_seconds = 0, write_seconds = 0;
};

// Frames per second over the frames processed so far and the time left.
class RateMeter {
public:
  explicit RateMeter(std::size_t total) : total_(total) {}
  void done(bool processed, double seconds) {
    ++seen_;
    if (processed) {
      ++processed_;
      busy_ += seconds;
    }
  }
  double rate() const { return busy_ > 0 ? static_cast<double>(processed_) / busy_ : 0; }
  double remaining_seconds() const {
    return processed_ ? busy_ / static_cast<double>(processed_) * static_cast<double>(total_ - seen_) : 0;
  }

private:
  std::size_t total_, seen_ = 0, processed_ = 0;
  double busy_ = 0;
};

// "[ 3/120] frame 0003: 24,389 particles -> out/s_0003.ply (52,114 triangles, 1.23 s) | 0.81 frames/s, 2:24 left"
std::string progress_line(std::size_t index, std::size_t total, const FrameResult& r, const RateMeter& m);

struct SequenceReport {
  std::string version, backend;
  nbmc_params params{};
  std::vector<FrameResult> frames;
  double total_seconds = 0;
  std::size_t count(const char* status) const {
    std::size_t n = 0;
    for (const FrameResult& f : frames) n += f.status == status;
    return n;
  }
  std::size_t failed() const { return count("failed"); }
};

std::string format_sequence(const SequenceReport& r);
std::string format_sequence_json(const SequenceReport& r);

} // namespace nbmc::cli

#endif
