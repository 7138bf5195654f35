// SPDX-License-Identifier: MIT
// nbmc — command-line surface reconstruction of particle files.
//
//   nbmc reconstruct IN -o OUT (--spacing R | --particle-radius P) [options]
//   nbmc reconstruct 'frames/fluid_{}.bgeo' -o 'out/surface_{}.ply' ...   (a sequence)
//   nbmc reconstruct dump.h5part -o 'out/surface_{}.glb' ...              (every step)
//
// Exit codes: 0 success, 1 error (input, library, output; in a sequence: any
// frame failed), 2 usage error, 130 cancelled with Ctrl-C.
#include "io/attributes.hpp"
#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "progress.hpp"
#include "report.hpp"
#include "sequence.hpp"

#include <nbmc.h>

#include <CLI/CLI.hpp>

#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// ------------------------------------------------------------ name tables
struct Named {
  const char* name;
  std::int32_t value;
};
const Named kMethods[] = {{"ssp07", NBMC_METHOD_SSP07}, {"zb05", NBMC_METHOD_ZB05}};
const Named kFields[] = {
    {"narrow-band", NBMC_FIELD_NARROW_BAND}, {"dense", NBMC_FIELD_DENSE}, {"scatter", NBMC_FIELD_SCATTER}};
const Named kBackends[] = {{"auto", NBMC_BACKEND_AUTO},
                           {"serial", NBMC_BACKEND_SERIAL},
                           {"openmp", NBMC_BACKEND_OPENMP},
                           {"cuda", NBMC_BACKEND_CUDA}};

template <std::size_t N> std::string name_of(const Named (&table)[N], std::int32_t v) {
  for (const Named& e : table)
    if (e.value == v) return e.name;
  return std::to_string(v);
}
std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}
template <std::size_t N> std::int32_t value_of(const Named (&table)[N], const std::string& name) {
  for (const Named& e : table)
    if (lower(name) == e.name) return e.value;
  return table[0].value; // not reached: CLI::IsMember checked the name
}
template <std::size_t N> std::vector<std::string> names(const Named (&table)[N]) {
  std::vector<std::string> out;
  for (const Named& e : table) out.emplace_back(e.name);
  return out;
}

// ------------------------------------------------------------- options
struct Options {
  std::string input;
  std::string output;
  std::string input_format;
  double spacing = 0;
  double particle_radius = 0;
  nbmc_params params{};
  nbmc_context_desc desc{};
  std::string method, field, backend;
  std::vector<double> bbox;
  bool no_normals = false;
  bool no_cleanup = false;  // --no-cleanup
  bool check = false;       // --check
  bool quiet = false;
  std::string progress = "auto";
  bool json = false;
  std::string json_path;
  std::vector<std::string> attributes; // --attributes
  std::string frames;                   // --frames a:b[:step]
  bool resume = false;
  std::int64_t step = -1; // H5Part step of a single-frame run (-1: the first)
  std::string memory_budget;  // --memory-budget, "" = no cap
  std::string subdomains;     // --subdomains auto|N|NxMxK, "" = whole frame
};

// --------------------------------------------------------------- helpers
// "4G", "512M", "64k", "1000000" -> bytes; false if malformed.
bool parse_size(const std::string& text, std::uint64_t& bytes) {
  if (text.empty()) return false;
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(text, &used);
  } catch (...) {
    return false;
  }
  const std::string unit = lower(text.substr(used));
  double scale = 1;
  if (unit == "k" || unit == "kb" || unit == "kib") scale = 1024.0;
  else if (unit == "m" || unit == "mb" || unit == "mib") scale = 1024.0 * 1024.0;
  else if (unit == "g" || unit == "gb" || unit == "gib") scale = 1024.0 * 1024.0 * 1024.0;
  else if (unit == "t" || unit == "tb" || unit == "tib") scale = 1024.0 * 1024.0 * 1024.0 * 1024.0;
  else if (!unit.empty() && unit != "b") return false;
  if (!(v >= 0) || v * scale > 1.8e19) return false;
  bytes = std::uint64_t(v * scale);
  return true;
}

// --subdomains: "auto" -> {NBMC_SUBDOMAINS_AUTO, 0, 0}; "3" -> {3, 3, 3};
// "4x2x1" -> {4, 2, 1}. False if malformed.
bool parse_subdomains(const std::string& text, int parts[3]) {
  if (lower(text) == "auto") {
    parts[0] = NBMC_SUBDOMAINS_AUTO;
    parts[1] = parts[2] = 0;
    return true;
  }
  std::vector<std::string> f;
  std::size_t start = 0;
  for (;;) {
    const std::size_t x = lower(text).find('x', start);
    f.push_back(text.substr(start, x == std::string::npos ? std::string::npos : x - start));
    if (x == std::string::npos) break;
    start = x + 1;
  }
  if (f.size() != 1 && f.size() != 3) return false;
  for (std::size_t a = 0; a < 3; ++a) {
    const std::string& t = f[f.size() == 1 ? 0 : a];
    if (t.empty() || t.size() > 4 || t.find_first_not_of("0123456789") != std::string::npos) return false;
    parts[a] = std::stoi(t);
    if (parts[a] < 1) return false;
  }
  return true;
}

void apply_memory_budget(nbmc_context* ctx, const Options& o) {
  std::uint64_t bytes = 0;
  if (!o.memory_budget.empty() && parse_size(o.memory_budget, bytes)) nbmc_context_set_memory_budget(ctx, bytes);
  int parts[3];
  if (!o.subdomains.empty() && parse_subdomains(o.subdomains, parts))
    nbmc_context_set_subdomains(ctx, parts[0], parts[1], parts[2]);
}

struct ContextDeleter {
  void operator()(nbmc_context* c) const { nbmc_context_destroy(c); }
};
struct MeshDeleter {
  void operator()(nbmc_mesh* m) const { nbmc_mesh_destroy(m); }
};
using ContextPtr = std::unique_ptr<nbmc_context, ContextDeleter>;
using MeshPtr = std::unique_ptr<nbmc_mesh, MeshDeleter>;

int library_error(std::int32_t status, const char* detail) {
  std::fprintf(stderr, "nbmc: error: %s", nbmc_status_string(status));
  if (detail && *detail) std::fprintf(stderr, ": %s", detail);
  std::fputc('\n', stderr);
  return 1;
}

int cancelled(nbmc::cli::Progress& progress) {
  progress.finish();
  std::fputs("nbmc: cancelled\n", stderr);
  return 130;
}

bool write_text(const std::string& path, const std::string& text) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) {
    std::fprintf(stderr, "nbmc: error: %s: cannot open for writing: %s\n", path.c_str(), std::strerror(errno));
    return false;
  }
  const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
  if (std::fclose(f) != 0 || !ok) {
    std::fprintf(stderr, "nbmc: error: %s: write error\n", path.c_str());
    return false;
  }
  return true;
}

// Prints the text report (unless --quiet or JSON goes to stdout) and writes
// the JSON report where --json asked; false if the JSON file failed.
template <class Text, class Json>
bool emit_report(const Options& o, bool json_to_stdout, Text text, Json json) {
  if (!o.quiet && !json_to_stdout) std::fputs(text().c_str(), stdout);
  bool ok = true;
  if (o.json) {
    const std::string j = json();
    if (json_to_stdout)
      std::fputs(j.c_str(), stdout);
    else
      ok = write_text(o.json_path, j);
  }
  std::fflush(stdout);
  return ok;
}

// R of the field in absolute units (what attributes are interpolated with).
// The writers' view of a (host) mesh from the C API.
nbmc::io::MeshView mesh_view(const nbmc_mesh* mesh) {
  nbmc::io::MeshView view;
  view.positions = nbmc_mesh_positions(mesh);
  view.normals = nbmc_mesh_normals(mesh);
  view.triangles = nbmc_mesh_triangles(mesh);
  view.vertex_count = nbmc_mesh_vertex_count(mesh);
  view.triangle_count = nbmc_mesh_triangle_count(mesh);
  return view;
}

double absolute_radius(const nbmc_params& p) {
  return p.length_unit == NBMC_UNIT_ABSOLUTE ? p.influence_radius : p.influence_radius * p.spacing;
}

// Every name asked for with --attributes must be in the file. The message
// lists what the file has (read again with all attributes: only on error).
void check_attributes(const std::string& path, const nbmc::io::Particles& p, const std::vector<std::string>& names,
                      const nbmc::io::ReadOptions& read) {
  for (const std::string& n : names) {
    if (p.attribute(n)) continue;
    std::string have = "?";
    try {
      nbmc::io::ReadOptions all = read;
      all.only.clear();
      all.attributes = true;
      have = nbmc::io::attribute_names(nbmc::io::read_particles(path, all).attributes);
    } catch (const nbmc::io::Error&) {
    }
    throw nbmc::io::Error(path + ": no particle attribute '" + n + "' (the file has: " + have + ")");
  }
}

// ------------------------------------------------------------ a sequence
int reconstruct_sequence(Options& o, const std::vector<nbmc::cli::Frame>& frames) {
  using namespace nbmc;
  const auto t_start = Clock::now();
  const bool json_to_stdout = o.json && (o.json_path.empty() || o.json_path == "-");
  const bool show = !o.quiet && o.progress != "never";
  const bool stderr_tty = ::isatty(STDERR_FILENO) == 1;
  // The per-stage bar is replaced by one line per frame.
  cli::Progress bar(false, stderr_tty);

  nbmc_context* raw = nullptr;
  std::int32_t st = nbmc_context_create(&o.desc, &raw);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(nullptr));
  ContextPtr ctx(raw);
  apply_memory_budget(ctx.get(), o);
  nbmc_context_set_progress(ctx.get(), &cli::Progress::callback, &bar);
  std::int32_t backend = o.desc.backend;
  nbmc_context_backend(ctx.get(), &backend);

  std::vector<cli::FrameResult> results;
  cli::RateMeter meter(frames.size());
  bool cancelled_run = false;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const cli::Frame& f = frames[i];
    cli::FrameResult r;
    r.label = f.label;
    r.input = f.input;
    r.output = f.output;
    const auto t0 = Clock::now();
    if (cli::interrupted()) {
      cancelled_run = true;
      break;
    }
    if (!f.missing.empty()) {
      r.status = "failed";
      r.error = f.missing;
    } else if (o.resume && cli::output_exists(f.output)) {
      r.status = "skipped";
    } else {
      try {
        io::ReadOptions ro;
        ro.format = o.input_format;
        ro.attributes = !o.attributes.empty();
        ro.only = o.attributes;
        ro.frame = f.step;
        io::Particles particles = io::read_particles(f.input, ro);
        check_attributes(f.input, particles, o.attributes, ro);
        r.particles = particles.count();
        st = nbmc_context_set_particles_f64(ctx.get(), particles.xyz.data(), particles.count(), 0);
        if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(ctx.get()));
        nbmc_mesh* raw_mesh = nullptr;
        st = nbmc_context_reconstruct(ctx.get(), &o.params, &raw_mesh);
        MeshPtr mesh(raw_mesh);
        if (st == NBMC_ERROR_CANCELLED) {
          cancelled_run = true;
          break;
        }
        if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(ctx.get()));
        io::MeshView view = mesh_view(mesh.get());
        std::vector<io::Attribute> attrs;
        if (!o.attributes.empty()) {
          attrs = io::interpolate_attributes(particles.xyz, particles.attributes, o.attributes, view.positions,
                                             view.vertex_count, absolute_radius(o.params));
          view.attributes = attrs.data();
          view.attribute_count = attrs.size();
        }
        particles = io::Particles();
        cli::make_parent_folders(f.output);
        io::write_mesh(f.output, view, "", [] { return cli::interrupted(); });
        r.vertices = view.vertex_count;
        r.triangles = view.triangle_count;
        r.status = "written";
      } catch (const io::Cancelled&) {
        cancelled_run = true;
        break;
      } catch (const std::bad_alloc&) {
        r.status = "failed";
        r.error = "out of memory";
      } catch (const std::exception& e) {
        r.status = "failed";
        r.error = e.what();
      }
    }
    r.seconds = seconds_since(t0);
    meter.done(r.status == "written", r.seconds);
    if (r.status == "failed") {
      if (r.error.rfind(r.input, 0) == 0) // the message names the file already
        std::fprintf(stderr, "nbmc: error: frame %s: %s\n", r.label.c_str(), r.error.c_str());
      else
        std::fprintf(stderr, "nbmc: error: frame %s (%s): %s\n", r.label.c_str(), r.input.c_str(), r.error.c_str());
    }
    if (show) std::fputs(cli::progress_line(i + 1, frames.size(), r, meter).c_str(), stderr);
    results.push_back(std::move(r));
  }
  ctx.reset();
  nbmc_kokkos_finalize();
  if (cancelled_run) {
    std::fputs("nbmc: cancelled\n", stderr);
    return 130;
  }
  cli::SequenceReport rep;
  rep.version = nbmc_version_string();
  rep.backend = name_of(kBackends, backend);
  rep.params = o.params;
  rep.frames = std::move(results);
  rep.total_seconds = seconds_since(t_start);
  if (!emit_report(o, json_to_stdout, [&] { return cli::format_sequence(rep); },
                   [&] { return cli::format_sequence_json(rep); }))
    return 1;
  return rep.failed() > 0 ? 1 : 0;
}

// -------------------------------------------------------------- the run
int reconstruct(Options& o) {
  using namespace nbmc;
  const auto t_start = Clock::now();
  cli::install_interrupt_handler();

  const bool json_to_stdout = o.json && (o.json_path.empty() || o.json_path == "-");
  const bool stderr_tty = ::isatty(STDERR_FILENO) == 1;
  const bool show_progress =
      o.progress == "always" || (o.progress == "auto" && stderr_tty && !o.quiet);
  cli::Progress progress(show_progress, stderr_tty);

  cli::Report report;
  report.version = nbmc_version_string();
  report.input_path = o.input;
  report.output_path = o.output;

  // Read the particles (and check the output name first, to fail early).
  io::Particles particles;
  try {
    report.output_format = io::mesh_format(o.output);
    report.input_format = io::particle_format(o.input, o.input_format);
    const auto t0 = Clock::now();
    io::ReadOptions ro;
    ro.format = o.input_format;
    ro.attributes = !o.attributes.empty();
    ro.only = o.attributes;
    ro.frame = o.step;
    particles = io::read_particles(o.input, ro);
    report.read_seconds = seconds_since(t0);
    check_attributes(o.input, particles, o.attributes, ro);
  } catch (const io::Error& e) {
    std::fprintf(stderr, "nbmc: error: %s\n", e.what());
    return 1;
  }
  report.particle_count = particles.count();
  if (cli::interrupted()) return cancelled(progress);

  // Context, upload, reconstruction.
  nbmc_context* raw = nullptr;
  std::int32_t st = nbmc_context_create(&o.desc, &raw);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(nullptr));
  ContextPtr ctx(raw);
  apply_memory_budget(ctx.get(), o);
  std::int32_t backend = o.desc.backend;
  if (nbmc_context_backend(ctx.get(), &backend) == NBMC_OK) report.backend = name_of(kBackends, backend);
  nbmc_context_set_progress(ctx.get(), &cli::Progress::callback, &progress);

  st = nbmc_context_set_particles_f64(ctx.get(), particles.xyz.data(), particles.count(), 0);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  if (o.attributes.empty()) particles = io::Particles(); // the context has its copy

  nbmc_mesh* raw_mesh = nullptr;
  st = nbmc_context_reconstruct(ctx.get(), &o.params, &raw_mesh);
  MeshPtr mesh(raw_mesh);
  progress.finish();
  if (st == NBMC_ERROR_CANCELLED) return cancelled(progress);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  nbmc_stats_init(&report.stats);
  st = nbmc_context_stats(ctx.get(), &report.stats);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  report.params = o.params;
  nbmc_subdomain_stats_init(&report.subdomains);
  if (nbmc_context_subdomain_stats(ctx.get(), &report.subdomains) == NBMC_OK)
    for (std::uint64_t i = 0; i < report.subdomains.count; ++i) {
      nbmc_subdomain_entry e;
      nbmc_subdomain_entry_init(&e);
      if (nbmc_context_subdomain_entry(ctx.get(), i, &e) == NBMC_OK) report.subdomain_entries.push_back(e);
    }
  if (o.check) {
    nbmc_mesh_check_result_init(&report.check);
    st = nbmc_mesh_check(mesh.get(), &report.check);
    if (st != NBMC_OK) return library_error(st, "nbmc_mesh_check failed");
    report.has_check = true;
  }
  if (cli::interrupted()) return cancelled(progress);

  // Write the mesh.
  io::MeshView view = mesh_view(mesh.get());
  report.normals = view.normals != nullptr;
  std::vector<io::Attribute> vertex_attributes;
  try {
    if (!o.attributes.empty()) {
      const auto t0 = Clock::now();
      vertex_attributes = io::interpolate_attributes(particles.xyz, particles.attributes, o.attributes,
                                                     view.positions, view.vertex_count, absolute_radius(o.params));
      report.interpolate_seconds = seconds_since(t0);
      particles = io::Particles();
      view.attributes = vertex_attributes.data();
      view.attribute_count = vertex_attributes.size();
      for (const io::Attribute& a : vertex_attributes) report.attributes.push_back(a.name);
    }
    const auto t0 = Clock::now();
    io::write_mesh(o.output, view, report.output_format, [] { return cli::interrupted(); });
    report.write_seconds = seconds_since(t0);
  } catch (const io::Cancelled&) {
    return cancelled(progress);
  } catch (const io::Error& e) {
    std::fprintf(stderr, "nbmc: error: %s\n", e.what());
    return 1;
  }
  mesh.reset();
  ctx.reset();
  nbmc_kokkos_finalize();

  report.total_seconds = seconds_since(t_start);
  report.peak_rss_bytes = cli::peak_rss_bytes();
  if (!emit_report(o, json_to_stdout, [&] { return cli::format_report(report); },
                   [&] { return cli::format_json(report); }))
    return 1;
  return 0;
}

} // namespace

int main(int argc, char** argv) {
  Options o;
  nbmc_params_init(&o.params);
  nbmc_context_desc_init(&o.desc);
  nbmc_params& p = o.params;
  o.method = name_of(kMethods, p.method);
  o.field = name_of(kFields, p.field);
  o.backend = name_of(kBackends, o.desc.backend);

  CLI::App app{"nbmc: narrow-band marching cubes surface reconstruction of particle-based fluids"};
  app.set_version_flag("--version", std::string("nbmc ") + nbmc_version_string());
  app.require_subcommand(1);
  app.footer("Run 'nbmc reconstruct --help' for the reconstruction options (--spacing, --cell-size, ...).");

  CLI::App* rec = app.add_subcommand(
      "reconstruct", "Reconstruct the surface of a particle file and write a triangle mesh.");
  rec->footer(
      "Lengths are multiples of the spacing unless stated. The mesh format follows OUT's extension (.ply: binary "
      "PLY, .obj: Wavefront OBJ, .vtk: legacy VTK, .vtu/.vtp: VTK XML, .glb: glTF binary, .h5: HDF5 with an "
      ".xdmf descriptor). Sequences: "
      "'frames/f_{}.bgeo' -o 'out/s_{}.ply' reconstructs every matching file in numeric order; a multi-step "
      "H5Part file with -o 'out/s_{}.glb' every step; -o 'out/s_{}.h5' writes all frames into out/s.h5 (one "
      "group each) with a temporal out/s.xdmf. Exit codes: 0 ok, 1 error (or a failed frame), 2 usage, "
      "130 cancelled (Ctrl-C).");
  rec->add_option("input", o.input,
                  "Particle file (.xyz .ply .vtk .vtu .vtp .bgeo[.gz] .h5part .h5 .hdf5; FILE.h5:/object); "
                  "{} in the name: a numbered sequence")
      ->required()
      ->option_text("IN");
  rec->add_option("-o,--output", o.output,
                  "Mesh to write (.ply .obj .vtk .vtu .vtp .glb .h5); {} in the name: per frame")
      ->required()
      ->option_text("OUT");
  auto* sp = rec->add_option("--spacing", o.spacing, "Particle spacing r (absolute); this or --particle-radius")
                 ->option_text("R");
  auto* pr = rec->add_option("--particle-radius", o.particle_radius,
                             "Particle radius as in SPlisHSPlasH/splashsurf (absolute); spacing = 2 * radius")
                 ->option_text("P");
  sp->excludes(pr);
  rec->add_option("--cell-size", p.cell_size, "Marching-cubes cell edge")->capture_default_str();
  rec->add_option("--influence-radius", p.influence_radius, "Kernel support of the scalar field")
      ->capture_default_str();
  rec->add_option("--band-width", p.band_width, "Half width of the narrow band around surface particles")
      ->capture_default_str();
  rec->add_option("--surface-radius", p.surface_radius, "Neighbourhood radius of the surface-particle test")
      ->capture_default_str();
  rec->add_option("--iso-radius", p.iso_radius, "Iso radius (SSP07) or particle radius (ZB05) of the field")
      ->capture_default_str();
  rec->add_option("--method", o.method, "Scalar field")
      ->check(CLI::IsMember(names(kMethods), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--field", o.field, "Field evaluation: on the band only, or baselines")
      ->check(CLI::IsMember(names(kFields), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--t-low", p.t_low, "SSP07 lower eigenvalue threshold")->capture_default_str();
  rec->add_option("--t-high", p.t_high, "SSP07 upper eigenvalue threshold")->capture_default_str();
  rec->add_option("--color-threshold", p.color_threshold,
                  "Colour-field gradient threshold of the surface-particle test")
      ->capture_default_str();
  rec->add_option("--neighbour-threshold", p.neighbour_threshold,
                  "Fewer neighbours than this within the surface radius: surface particle")
      ->capture_default_str();
  rec->add_flag("--no-normals", o.no_normals, "Do not compute vertex normals");
  rec->add_flag("--no-cleanup", o.no_cleanup,
                "Keep the raw marching-cubes mesh (no removal of degenerate and sliver triangles)");
  rec->add_option("--smooth", p.smooth_iterations,
                  "Taubin smoothing iterations after the clean-up (lambda 0.5, mu -0.53)")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  rec->add_flag("--check", o.check,
                "Check the mesh (closed, manifold, oriented, bad triangles, components, volume) and report it");
  rec->add_option("--bbox", o.bbox, "Only reconstruct inside this box (absolute)")
      ->expected(6)
      ->option_text("XMIN YMIN ZMIN XMAX YMAX ZMAX");
  rec->add_option("--threads", o.desc.num_threads, "Host threads (0 = all cores)")->capture_default_str();
  rec->add_option("--memory-budget", o.memory_budget,
                  "Cap on the memory nbmc may allocate (host and GPU), e.g. 4G, 512M; over it the run stops "
                  "with 'memory budget exceeded' and the estimate")
      ->check([](const std::string& v) {
        std::uint64_t b = 0;
        return parse_size(v, b) ? std::string() : std::string("expected a size such as 4G, 512M or 1000000");
      });
  rec->add_option("--subdomains", o.subdomains,
                  "Reconstruct the frame in subdomains and stitch them (the same mesh, bit for bit): NxMxK, N "
                  "(= NxNxN), or auto (split only when the frame's estimate exceeds --memory-budget or, on a GPU, "
                  "its free memory)")
      ->option_text("auto|NxMxK")
      ->check([](const std::string& v) {
        int parts[3];
        return parse_subdomains(v, parts) ? std::string()
                                          : std::string("expected auto, N or NxMxK with positive integers, e.g. 2x2x1");
      });
  rec->add_option("--backend", o.backend, "Compute backend")
      ->check(CLI::IsMember(names(kBackends), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--format", o.input_format,
                  "Input format, overriding the extension (HDF5 objects: FILE.h5:/path; see docs/formats.md)")
      ->check(CLI::IsMember(nbmc::io::particle_format_names(), CLI::ignore_case))
      ->option_text("xyz|ply|vtk|vtu|vtp|bgeo|h5part|pysph|gadget|swift|hdf5");
  rec->add_option("--attributes", o.attributes,
                  "Particle attributes to interpolate onto the mesh vertices (comma-separated, e.g. vel,rho); "
                  "written by the PLY, VTK, VTU and glTF writers")
      ->delimiter(',')
      ->option_text("NAME[,NAME...]");
  rec->add_option("--frames", o.frames,
                  "Sequences: only frames a to b (inclusive), every step-th; IN with {} or a multi-step H5Part file")
      ->option_text("A:B[:STEP]");
  rec->add_flag("--resume", o.resume, "Sequences: skip frames whose output exists already");
  auto* json = rec->add_option("--json", o.json_path,
                               "Write a machine-readable report to FILE ('-' or no value: stdout, instead of the "
                               "table); use --json=FILE before other arguments")
                   ->expected(0, 1)
                   ->option_text("[FILE]");
  rec->add_flag("-q,--quiet", o.quiet, "Print no report");
  rec->add_option("--progress", o.progress, "Progress bar on stderr (auto: when stderr is a terminal)")
      ->check(CLI::IsMember({"auto", "always", "never"}))
      ->capture_default_str();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  if (sp->count() == 0 && pr->count() == 0) {
    std::fputs("nbmc: error: one of --spacing or --particle-radius is required\n"
               "Run with --help for more information.\n",
               stderr);
    return 2;
  }
  p.spacing = sp->count() > 0 ? o.spacing : 2.0 * o.particle_radius;
  p.method = value_of(kMethods, o.method);
  p.field = value_of(kFields, o.field);
  o.desc.backend = value_of(kBackends, o.backend);
  if (o.no_normals) p.compute_normals = 0;
  if (o.no_cleanup) p.cleanup = 0;
  if (!o.bbox.empty()) {
    p.use_bbox = 1;
    for (int i = 0; i < 3; ++i) {
      p.bbox_min[i] = o.bbox[static_cast<std::size_t>(i)];
      p.bbox_max[i] = o.bbox[static_cast<std::size_t>(i + 3)];
    }
  }
  o.json = json->count() > 0;
  o.progress = lower(o.progress);

  try {
    if (!o.attributes.empty()) {
      for (const std::string& a : o.attributes)
        if (a.empty()) {
          std::fputs("nbmc: error: --attributes has an empty name\n", stderr);
          return 2;
        }
      std::string fmt;
      try {
        fmt = nbmc::io::mesh_format(nbmc::cli::without_braces(o.output));
      } catch (const nbmc::io::Error&) {
      }
      if (fmt == "obj") {
        std::fputs("nbmc: error: OBJ has no place for vertex attributes; write .ply, .vtk, .vtu, .vtp, .glb or .h5 with "
                   "--attributes\n",
                   stderr);
        return 2;
      }
    }
    nbmc::cli::SequencePlan plan;
    std::string usage;
    if (!nbmc::cli::plan_sequence(o.input, o.output, o.input_format, o.frames, plan, usage)) {
      std::fprintf(stderr, "nbmc: error: %s\n", usage.c_str());
      return plan.usage_error ? 2 : 1;
    }
    if (plan.is_sequence) {
      nbmc::cli::install_interrupt_handler();
      return reconstruct_sequence(o, plan.frames);
    }
    o.step = plan.step;
    return reconstruct(o);
  } catch (const std::bad_alloc&) {
    std::fputs("nbmc: error: out of memory\n", stderr);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nbmc: error: %s\n", e.what());
  }
  return 1;
}
