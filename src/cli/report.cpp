// SPDX-License-Identifier: MIT
#include "report.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <utility>
#include <vector>

#include <sys/resource.h>

namespace nbmc::cli {

std::uint64_t peak_rss_bytes() {
  struct rusage ru {};
  if (getrusage(RUSAGE_SELF, &ru) != 0) return 0;
  return static_cast<std::uint64_t>(ru.ru_maxrss) * 1024; // Linux: KiB
}

namespace {

// "1,234,567"
std::string grouped(std::uint64_t v) {
  std::string digits = std::to_string(v);
  std::string out;
  const std::size_t n = digits.size();
  for (std::size_t i = 0; i < n; ++i) {
    out += digits[i];
    if (i + 1 < n && (n - 1 - i) % 3 == 0) out += ',';
  }
  return out;
}

std::string printf_string(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

std::string mib(std::uint64_t bytes) { return printf_string("%.1f MiB", static_cast<double>(bytes) / 1048576.0); }

// Shortest representation that reads back exactly; "null" when not finite.
std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

const char* stage_label(int i) {
  const char* name = nbmc_stage_name(i);
  return name ? name : "?";
}

std::vector<std::pair<std::string, double>> timings(const Report& r) {
  std::vector<std::pair<std::string, double>> rows;
  rows.emplace_back("read", r.read_seconds);
  if (r.has_setup) rows.emplace_back("setup", r.setup_seconds);
  for (int i = 0; i < NBMC_STAGE_COUNT; ++i) rows.emplace_back(stage_label(i), r.stats.stage_seconds[i]);
  rows.emplace_back(stage_label(NBMC_STAGE_POSTPROCESS), r.stats.stage_seconds[NBMC_STAGE_POSTPROCESS]);
  rows.emplace_back("write", r.write_seconds);
  return rows;
}

std::vector<std::pair<const char*, std::uint64_t>> counts(const nbmc_stats& s) {
  return {{"particle_count", s.particle_count},
          {"surface_particle_count", s.surface_particle_count},
          {"occupied_cell_count", s.occupied_cell_count},
          {"band_vertex_count", s.band_vertex_count},
          {"band_block_count", s.band_block_count},
          {"grid_vertex_count", s.grid_vertex_count},
          {"triangulated_cell_count", s.triangulated_cell_count},
          {"vertex_count", s.vertex_count},
          {"triangle_count", s.triangle_count},
          {"raw_triangle_count", s.raw_triangle_count},
          {"pre_decimation_triangle_count", s.pre_decimation_triangle_count},
          {"cleanup_bad_triangles_before", s.cleanup_bad_triangles_before},
          {"cleanup_bad_triangles_after", s.cleanup_bad_triangles_after},
          {"cleanup_moves", s.cleanup_moves},
          {"cleanup_flips", s.cleanup_flips},
          {"cleanup_collapses", s.cleanup_collapses},
          {"cleanup_cuts", s.cleanup_cuts},
          {"cleanup_removed_component_triangles", s.cleanup_removed_component_triangles},
          {"dropped_particle_count", s.dropped_particle_count},
          {"dropped_cluster_count", s.dropped_cluster_count},
          {"neighbour_evaluations", s.neighbour_evaluations}};
}

// The mesh check's counts, by their JSON names.
std::vector<std::pair<const char*, std::uint64_t>> check_counts(const nbmc_mesh_check_result& c) {
  return {{"vertex_count", c.vertex_count},
          {"triangle_count", c.triangle_count},
          {"edge_count", c.edge_count},
          {"boundary_edge_count", c.boundary_edge_count},
          {"nonmanifold_edge_count", c.nonmanifold_edge_count},
          {"misoriented_edge_count", c.misoriented_edge_count},
          {"nonmanifold_vertex_count", c.nonmanifold_vertex_count},
          {"unreferenced_vertex_count", c.unreferenced_vertex_count},
          {"degenerate_triangle_count", c.degenerate_triangle_count},
          {"sliver_triangle_count", c.sliver_triangle_count},
          {"component_count", c.component_count}};
}

// " (iso threshold t, k_r ..., lambda ...)" of --method yt10.
std::string yt10_settings(const nbmc_params& q) {
  char b[192];
  std::snprintf(b, sizeof b, " (iso threshold %g, k_r %g, k_s %g, k_n %g, N_eps %d, lambda %g)", q.iso_threshold,
                q.aniso_kr, q.aniso_ks, q.aniso_kn, int(q.aniso_neighbours), q.aniso_lambda);
  return b;
}

const char* yes_no(std::int32_t v) { return v ? "yes" : "no"; }

const char* method_name(std::int32_t m) {
  return m == NBMC_METHOD_ZB05 ? "zb05" : m == NBMC_METHOD_SPH ? "sph" : m == NBMC_METHOD_YT10 ? "yt10" : "ssp07";
}
const char* field_name(std::int32_t f) {
  return f == NBMC_FIELD_DENSE ? "dense" : f == NBMC_FIELD_SCATTER ? "scatter" : "narrow-band";
}

} // namespace

std::string json_string(const std::string& s) {
  std::string out = "\"";
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  const std::size_t n = s.size();
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    if (c == '"' || c == '\\') {
      out += '\\';
      out += static_cast<char>(c);
      ++i;
    } else if (c < 0x20) {
      char buf[8];
      switch (c) {
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default: std::snprintf(buf, sizeof buf, "\\u%04x", c); out += buf;
      }
      ++i;
    } else if (c < 0x80) {
      out += static_cast<char>(c);
      ++i;
    } else {
      // Copy a well-formed UTF-8 sequence, replace anything else by U+FFFD.
      std::size_t len = c >= 0xf0 && c <= 0xf4 ? 4 : c >= 0xe0 ? 3 : c >= 0xc2 && c <= 0xdf ? 2 : 0;
      if (c > 0xf4) len = 0;
      bool ok = len > 0 && i + len <= n;
      for (std::size_t k = 1; ok && k < len; ++k) ok = (p[i + k] & 0xc0) == 0x80;
      if (ok && len == 3) { // no overlongs, no surrogates
        ok = !(c == 0xe0 && p[i + 1] < 0xa0) && !(c == 0xed && p[i + 1] >= 0xa0);
      }
      if (ok && len == 4) ok = !(c == 0xf0 && p[i + 1] < 0x90) && !(c == 0xf4 && p[i + 1] >= 0x90);
      if (ok) {
        out.append(s, i, len);
        i += len;
      } else {
        out += "\\ufffd";
        ++i;
      }
    }
  }
  out += '"';
  return out;
}

namespace {
struct RankSums {
  std::uint64_t subdomains = 0, particles = 0, ghosts = 0, triangles = 0;
  double seconds = 0;
};
std::vector<RankSums> per_rank(const Report& r) {
  std::vector<RankSums> v(static_cast<std::size_t>(r.ranks > 0 ? r.ranks : 0));
  for (const nbmc_subdomain_entry& e : r.subdomain_entries) {
    if (e.rank < 0 || e.rank >= r.ranks) continue;
    RankSums& s = v[static_cast<std::size_t>(e.rank)];
    ++s.subdomains;
    s.particles += e.particles;
    s.ghosts += e.ghost_particles;
    s.triangles += e.triangle_count;
    s.seconds += e.seconds;
  }
  return v;
}
}  // namespace

std::string format_report(const Report& r) {
  const nbmc_stats& s = r.stats;
  std::string o;
  const auto line = [&](const std::string& key, const std::string& value) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%-10s ", key.c_str());
    o += buf + value + "\n";
  };
  line("nbmc", r.version);
  line("input", r.input_path + " (" + r.input_format + ", " + grouped(r.particle_count) + " particles)");
  line("output", r.output_path + " (" + r.output_format + ", " + grouped(s.vertex_count) + " vertices, " +
                     grouped(s.triangle_count) + " triangles" + (r.normals ? ", normals" : "") + ")");
  if (!r.attributes.empty()) {
    std::string names;
    for (const std::string& a : r.attributes) names += (names.empty() ? "" : ", ") + a;
    line("attributes", names + " (interpolated, " + printf_string("%.4f", r.interpolate_seconds) + " s)");
  }
  line("backend", r.backend);
  const nbmc_params& q = r.params;
  line("method", std::string(method_name(q.method)) +
                    (q.method == NBMC_METHOD_SPH ? printf_string(" (iso threshold %g)", q.iso_threshold)
                     : q.method == NBMC_METHOD_YT10 ? yt10_settings(q)
                                                    : std::string()) +
                    (q.method != NBMC_METHOD_YT10 && q.max_distance > 0 && q.max_distance < q.influence_radius
                         ? printf_string(", max distance %g", q.max_distance)
                         : std::string()) +
                    ", " + field_name(q.field) + " field");
  line("mesh", (r.params.cleanup ? "cleaned up (" + grouped(s.raw_triangle_count) + " triangles before, " +
                                       grouped(s.cleanup_bad_triangles_before) + " bad: " +
                                       grouped(s.cleanup_moves) + " moves, " + grouped(s.cleanup_flips) +
                                       " flips, " + grouped(s.cleanup_collapses) + " collapses, " +
                                       grouped(s.cleanup_cuts) + " cuts, " +
                                       grouped(s.cleanup_removed_component_triangles) +
                                       " triangles in removed components; " +
                                       grouped(s.cleanup_bad_triangles_after) + " bad left)"
                                  : std::string("raw (no clean-up)")) +
                   (r.params.smooth_iterations > 0
                        ? ", " + std::to_string(r.params.smooth_iterations) +
                              (r.params.smooth_weighting == NBMC_SMOOTH_FEATURE ? " feature-weighted" : "") +
                              " smoothing iterations (volume " +
                              printf_string("%+.3f%%", 100.0 * s.smoothing_volume_change) + ")"
                        : std::string()) +
                   (r.params.decimate_fraction < 1
                        ? ", decimated to " + printf_string("%g", r.params.decimate_fraction) + " (" +
                              grouped(s.pre_decimation_triangle_count) + " -> " + grouped(s.triangle_count) +
                              " triangles)"
                        : std::string()) +
                   (r.params.double_positions ? ", double-precision positions" : ""));
  if (r.params.isolated == NBMC_ISOLATED_DROP || r.params.isolated == NBMC_ISOLATED_SPHERE)
    line("isolated", "dropped " + grouped(s.dropped_particle_count) + " particles in " +
                         grouped(s.dropped_cluster_count) + " clusters of fewer than " +
                         std::to_string(r.params.min_cluster) + " particles" +
                         (r.params.isolated == NBMC_ISOLATED_SPHERE ? ", written as spheres to " + r.spheres_path
                                                                    : std::string()));
  line("spacing", printf_string("%g", r.params.spacing) + " (cell size " + printf_string("%g", s.cell_size) + ")");
  if (!r.radius_attribute.empty())
    line("radii", "'" + r.radius_attribute + "' x " + printf_string("%g", r.radius_scale) + ": " +
                      printf_string("%g", r.radius_min) + " to " + printf_string("%g", r.radius_max));
  line("grid", grouped(s.grid_dims[0]) + " x " + grouped(s.grid_dims[1]) + " x " + grouped(s.grid_dims[2]) +
                   " vertices, origin (" + printf_string("%g", s.grid_origin[0]) + ", " +
                   printf_string("%g", s.grid_origin[1]) + ", " + printf_string("%g", s.grid_origin[2]) + ")");

  o += "\nstage                  seconds      %\n";
  const double total = r.total_seconds > 0 ? r.total_seconds : 1;
  char buf[128];
  for (const auto& [name, sec] : timings(r)) {
    std::snprintf(buf, sizeof buf, "  %-18s %9.4f %6.1f\n", name.c_str(), sec, 100.0 * sec / total);
    o += buf;
  }
  std::snprintf(buf, sizeof buf, "  %-18s %9.4f %6.1f\n", "total", r.total_seconds, 100.0);
  o += buf;
  if (r.has_setup)
    std::snprintf(buf, sizeof buf, "  (read and setup ran at the same time; library total %.4f s)\n", s.total_seconds);
  else
    std::snprintf(buf, sizeof buf, "  (library total %.4f s; the rest is start-up and context creation)\n",
                  s.total_seconds);
  o += buf;

  o += "\n";
  const std::pair<const char*, std::uint64_t> rows[] = {
      {"surface particles", s.surface_particle_count},
      {"occupied cells", s.occupied_cell_count},
      {"band vertices", s.band_vertex_count},
      {"band blocks", s.band_block_count},
      {"grid vertices", s.grid_vertex_count},
      {"triangulated cells", s.triangulated_cell_count},
      {"vertices", s.vertex_count},
      {"triangles", s.triangle_count},
      {"neighbour evals", s.neighbour_evaluations}};
  for (const auto& [name, v] : rows) {
    std::snprintf(buf, sizeof buf, "  %-20s %16s\n", name, grouped(v).c_str());
    o += buf;
  }
  if (r.has_check) {
    const nbmc_mesh_check_result& c = r.check;
    o += "\nmesh check: closed " + std::string(yes_no(c.closed)) + ", manifold " + yes_no(c.manifold) +
         ", oriented " + yes_no(c.oriented) + "\n";
    for (const auto& [name, v] : check_counts(c)) {
      std::snprintf(buf, sizeof buf, "  %-26s %16s\n", name, grouped(v).c_str());
      o += buf;
    }
    std::snprintf(buf, sizeof buf, "  %-26s %16lld\n", "euler_characteristic",
                  static_cast<long long>(c.euler_characteristic));
    o += buf;
    std::snprintf(buf, sizeof buf, "  %-26s %16.6g\n", "volume", c.volume);
    o += buf;
    std::snprintf(buf, sizeof buf, "  %-26s %16.6g\n", "area", c.area);
    o += buf;
    std::snprintf(buf, sizeof buf, "  %-26s %16.4f\n", "min_angle_degrees", c.min_angle_degrees);
    o += buf;
  }
  if (r.subdomains.count > 0) {
    const nbmc_subdomain_stats& d = r.subdomains;
    o += "\nsubdomains: " + std::to_string(d.parts[0]) + " x " + std::to_string(d.parts[1]) + " x " +
         std::to_string(d.parts[2]) + (d.automatic ? " (auto, budget " + mib(d.budget_bytes) + ")" : std::string()) +
         ", ghost layer " + printf_string("%g", d.ghost_width) + ", " + grouped(d.ghost_particles) +
         " ghost particles, " + grouped(d.shared_vertices) + " shared vertices merged, " + grouped(d.reruns) +
         " reruns (" + grouped(d.exchanged_cells) + " band cells exchanged), stitched in " +
         printf_string("%.4f", d.stitch_seconds) + " s\n";
    o += "  subdomain       cells             particles      ghosts   triangles  runs   seconds\n";
    for (const nbmc_subdomain_entry& e : r.subdomain_entries) {
      std::snprintf(buf, sizeof buf, "  %-3d %-3d %-3d  %5lld-%-5lld %11s %11s %11s %4u %9.4f\n", e.coord[0],
                    e.coord[1], e.coord[2], static_cast<long long>(e.cell_lo[0]),
                    static_cast<long long>(e.cell_hi[0]), grouped(e.particles).c_str(),
                    grouped(e.ghost_particles).c_str(), grouped(e.triangle_count).c_str(), e.runs, e.seconds);
      o += buf;
    }
  }
  if (r.ranks > 0) {
    o += "\nmpi: " + std::to_string(r.ranks) + " ranks (peak memory below: rank 0's)\n";
    o += "  rank  subdomains    particles      ghosts   triangles   seconds\n";
    int k = 0;
    for (const RankSums& x : per_rank(r)) {
      std::snprintf(buf, sizeof buf, "  %4d %11llu %12s %11s %11s %9.4f\n", k++,
                    static_cast<unsigned long long>(x.subdomains), grouped(x.particles).c_str(),
                    grouped(x.ghosts).c_str(), grouped(x.triangles).c_str(), x.seconds);
      o += buf;
    }
  }
  o += "\npeak memory: nbmc " + mib(s.peak_memory_bytes) + ", process RSS " + mib(r.peak_rss_bytes) + "\n";
  return o;
}

std::string format_json(const Report& r) {
  const nbmc_stats& s = r.stats;
  const nbmc_params& p = r.params;
  std::string o = "{\n";
  o += "  \"nbmc_version\": " + json_string(r.version) + ",\n";
  o += "  \"input\": {\"path\": " + json_string(r.input_path) + ", \"format\": " + json_string(r.input_format) +
       ", \"particle_count\": " + std::to_string(r.particle_count) + "},\n";
  o += "  \"output\": {\"path\": " + json_string(r.output_path) + ", \"format\": " + json_string(r.output_format) +
       ", \"normals\": " + (r.normals ? "true" : "false") + "},\n";
  o += "  \"backend\": " + json_string(r.backend) + ",\n";
  o += "  \"attributes\": [";
  for (std::size_t i = 0; i < r.attributes.size(); ++i) o += (i ? ", " : "") + json_string(r.attributes[i]);
  o += "],\n";
  if (r.radius_attribute.empty())
    o += "  \"radii\": null,\n";
  else
    o += "  \"radii\": {\"attribute\": " + json_string(r.radius_attribute) + ", \"scale\": " +
         json_number(r.radius_scale) + ", \"min\": " + json_number(r.radius_min) + ", \"max\": " +
         json_number(r.radius_max) + "},\n";

  o += "  \"params\": {";
  o += "\"length_unit\": " + json_string(p.length_unit == NBMC_UNIT_ABSOLUTE ? "absolute" : "spacing");
  const std::pair<const char*, double> reals[] = {
      {"spacing", p.spacing},           {"cell_size", p.cell_size},   {"influence_radius", p.influence_radius},
      {"band_width", p.band_width},     {"surface_radius", p.surface_radius},
      {"iso_radius", p.iso_radius},     {"t_low", p.t_low},           {"t_high", p.t_high},
      {"color_threshold", p.color_threshold}, {"iso_threshold", p.iso_threshold},
      {"aniso_kr", p.aniso_kr},         {"aniso_ks", p.aniso_ks},     {"aniso_kn", p.aniso_kn},
      {"aniso_lambda", p.aniso_lambda}, {"max_distance", p.max_distance}};
  for (const auto& [k, v] : reals) o += std::string(", \"") + k + "\": " + json_number(v);
  o += ", \"method\": " + json_string(method_name(p.method));
  o += ", \"field\": " + json_string(field_name(p.field));
  o += ", \"neighbour_threshold\": " + std::to_string(p.neighbour_threshold);
  o += ", \"aniso_neighbours\": " + std::to_string(p.aniso_neighbours);
  o += ", \"isolated\": " + json_string(p.isolated == NBMC_ISOLATED_SPHERE ? "sphere"
                                         : p.isolated == NBMC_ISOLATED_DROP ? "drop"
                                                                            : "keep");
  o += ", \"min_cluster\": " + std::to_string(p.min_cluster);
  o += std::string(", \"compute_normals\": ") + (p.compute_normals ? "true" : "false");
  o += std::string(", \"double_positions\": ") + (p.double_positions ? "true" : "false");
  o += std::string(", \"cleanup\": ") + (p.cleanup ? "true" : "false");
  o += ", \"smooth_iterations\": " + std::to_string(p.smooth_iterations);
  o += ", \"smooth_weights\": " + json_string(p.smooth_weighting == NBMC_SMOOTH_FEATURE ? "feature" : "uniform");
  o += ", \"decimate\": " + json_number(p.decimate_fraction);
  if (p.use_bbox) {
    o += ", \"bbox\": [";
    for (int i = 0; i < 6; ++i) o += (i ? ", " : "") + json_number(i < 3 ? p.bbox_min[i] : p.bbox_max[i - 3]);
    o += "]";
  } else {
    o += ", \"bbox\": null";
  }
  o += "},\n";

  o += "  \"grid\": {\"dims\": [" + std::to_string(s.grid_dims[0]) + ", " + std::to_string(s.grid_dims[1]) + ", " +
       std::to_string(s.grid_dims[2]) + "], \"origin\": [" + json_number(s.grid_origin[0]) + ", " +
       json_number(s.grid_origin[1]) + ", " + json_number(s.grid_origin[2]) +
       "], \"cell_size\": " + json_number(s.cell_size) + "},\n";

  o += "  \"timings_seconds\": {";
  bool first = true;
  for (const auto& [name, sec] : timings(r)) {
    o += (first ? "" : ", ") + json_string(name) + ": " + json_number(sec);
    first = false;
  }
  o += ", \"total\": " + json_number(r.total_seconds) + ", \"library_total\": " + json_number(s.total_seconds) +
       "},\n";

  o += "  \"counts\": {";
  first = true;
  for (const auto& [name, v] : counts(s)) {
    o += std::string(first ? "" : ", ") + "\"" + name + "\": " + std::to_string(v);
    first = false;
  }
  o += "},\n";
  if (p.smooth_iterations > 0)
    o += "  \"smoothing\": {\"iterations\": " + std::to_string(p.smooth_iterations) +
         ", \"volume_change\": " + json_number(s.smoothing_volume_change) + "},\n";
  if (p.decimate_fraction < 1)
    o += "  \"decimation\": {\"fraction\": " + json_number(p.decimate_fraction) +
         ", \"triangles_before\": " + std::to_string(s.pre_decimation_triangle_count) +
         ", \"triangles_after\": " + std::to_string(s.triangle_count) + "},\n";
  if (p.isolated == NBMC_ISOLATED_SPHERE)
    o += "  \"spheres\": {\"path\": " + json_string(r.spheres_path) +
         ", \"count\": " + std::to_string(s.dropped_particle_count) + "},\n";
  if (r.has_check) {
    const nbmc_mesh_check_result& c = r.check;
    o += std::string("  \"mesh_check\": {\"closed\": ") + (c.closed ? "true" : "false") +
         ", \"manifold\": " + (c.manifold ? "true" : "false") + ", \"oriented\": " + (c.oriented ? "true" : "false");
    for (const auto& [name, v] : check_counts(c)) o += std::string(", \"") + name + "\": " + std::to_string(v);
    o += ", \"euler_characteristic\": " + std::to_string(c.euler_characteristic) +
         ", \"volume\": " + json_number(c.volume) + ", \"area\": " + json_number(c.area) +
         ", \"min_angle_degrees\": " + json_number(c.min_angle_degrees) + "},\n";
  }
  if (r.subdomains.count > 0) {
    const nbmc_subdomain_stats& d = r.subdomains;
    o += "  \"subdomains\": {\"grid\": [" + std::to_string(d.parts[0]) + ", " + std::to_string(d.parts[1]) + ", " +
         std::to_string(d.parts[2]) + "], \"count\": " + std::to_string(d.count) +
         ", \"automatic\": " + (d.automatic ? "true" : "false") + ", \"budget_bytes\": " +
         std::to_string(d.budget_bytes) + ", \"ghost_width\": " + json_number(d.ghost_width) +
         ", \"ghost_particles\": " + std::to_string(d.ghost_particles) + ", \"reruns\": " + std::to_string(d.reruns) +
         ", \"exchanged_cells\": " + std::to_string(d.exchanged_cells) + ", \"shared_vertices\": " +
         std::to_string(d.shared_vertices) + ", \"stitch_seconds\": " + json_number(d.stitch_seconds) +
         ", \"per_subdomain\": [";
    bool first_entry = true;
    for (const nbmc_subdomain_entry& e : r.subdomain_entries) {
      o += std::string(first_entry ? "" : ", ") + "{\"coord\": [" + std::to_string(e.coord[0]) + ", " +
           std::to_string(e.coord[1]) + ", " + std::to_string(e.coord[2]) + "], \"cells\": [[" +
           std::to_string(e.cell_lo[0]) + ", " + std::to_string(e.cell_lo[1]) + ", " + std::to_string(e.cell_lo[2]) +
           "], [" + std::to_string(e.cell_hi[0]) + ", " + std::to_string(e.cell_hi[1]) + ", " +
           std::to_string(e.cell_hi[2]) + "]], \"particles\": " + std::to_string(e.particles) +
           ", \"ghost_particles\": " + std::to_string(e.ghost_particles) + ", \"vertices\": " +
           std::to_string(e.vertex_count) + ", \"triangles\": " + std::to_string(e.triangle_count) +
           ", \"runs\": " + std::to_string(e.runs) + ", \"rank\": " + std::to_string(e.rank) +
           ", \"seconds\": " + json_number(e.seconds) + "}";
      first_entry = false;
    }
    o += "]},\n";
  }
  if (r.ranks > 0) {
    o += "  \"mpi\": {\"ranks\": " + std::to_string(r.ranks) + ", \"per_rank\": [";
    int k = 0;
    for (const RankSums& x : per_rank(r)) {
      o += std::string(k ? ", " : "") + "{\"rank\": " + std::to_string(k) + ", \"subdomains\": " +
           std::to_string(x.subdomains) + ", \"particles\": " + std::to_string(x.particles) +
           ", \"ghost_particles\": " + std::to_string(x.ghosts) + ", \"triangles\": " +
           std::to_string(x.triangles) + ", \"seconds\": " + json_number(x.seconds) + "}";
      ++k;
    }
    o += "]},\n";
  }
  o += "  \"memory\": {\"peak_memory_bytes\": " + std::to_string(s.peak_memory_bytes) +
       ", \"peak_rss_bytes\": " + std::to_string(r.peak_rss_bytes) + "}\n";
  o += "}\n";
  return o;
}

} // namespace nbmc::cli
