// SPDX-License-Identifier: MIT
// The figures the nbmc command reports, as a table and as JSON.
#ifndef NBMC_CLI_REPORT_HPP
#define NBMC_CLI_REPORT_HPP

#include <nbmc.h>

#include <cstdint>
#include <string>
#include <vector>

namespace nbmc::cli {

struct Report {
  std::string version;
  std::string input_path;
  std::string input_format;
  std::string output_path;
  std::string output_format;
  std::string backend;
  std::uint64_t particle_count = 0;
  nbmc_params params{};  // as passed (spacing absolute)
  nbmc_stats stats{};    // of the reconstruction
  nbmc_subdomain_stats subdomains{};  // count 0: the frame was not split
  std::vector<nbmc_subdomain_entry> subdomain_entries;
  int ranks = 0;  // MPI ranks that shared the frame (0: none)
  bool normals = false;  // the mesh has normals
  std::vector<std::string> attributes; // interpolated onto the vertices
  std::string spheres_path;            // --isolated sphere: the file the spheres went to
  // --radius-attribute: the attribute, the factor, the smallest and largest radius
  std::string radius_attribute;
  double radius_scale = 1, radius_min = 0, radius_max = 0;
  double interpolate_seconds = 0;
  bool has_check = false;             // --check
  nbmc_mesh_check_result check{};     // of the written mesh
  double read_seconds = 0;
  // The context's creation, measured where it ran while the file was read
  // (single-frame runs without MPI; has_setup).
  bool has_setup = false;
  double setup_seconds = 0;
  double write_seconds = 0;
  double total_seconds = 0; // wall clock of the whole command
  std::uint64_t peak_rss_bytes = 0;
};

// Peak resident set size of this process so far (getrusage), in bytes.
std::uint64_t peak_rss_bytes();

// Human-readable report.
std::string format_report(const Report& r);
// The same figures as one JSON object (ends with a newline).
std::string format_json(const Report& r);

// JSON string literal of s (quoted, escaped; invalid UTF-8 becomes U+FFFD).
std::string json_string(const std::string& s);

} // namespace nbmc::cli

#endif
