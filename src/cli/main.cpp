// SPDX-License-Identifier: MIT
// nbmc — command-line surface reconstruction of particle files.
//
//   nbmc reconstruct IN -o OUT (--spacing R | --particle-radius P) [options]
//
// Exit codes: 0 success, 1 error (input, library, output), 2 usage error,
// 130 cancelled with Ctrl-C.
#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/particles.hpp"
#include "progress.hpp"
#include "report.hpp"

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
  bool quiet = false;
  std::string progress = "auto";
  bool json = false;
  std::string json_path;
};

// --------------------------------------------------------------- helpers
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
    particles = io::read_particles(o.input, o.input_format);
    report.read_seconds = seconds_since(t0);
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
  std::int32_t backend = o.desc.backend;
  if (nbmc_context_backend(ctx.get(), &backend) == NBMC_OK) report.backend = name_of(kBackends, backend);
  nbmc_context_set_progress(ctx.get(), &cli::Progress::callback, &progress);

  st = nbmc_context_set_particles_f64(ctx.get(), particles.xyz.data(), particles.count(), 0);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  particles = io::Particles(); // the context has its copy

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
  if (cli::interrupted()) return cancelled(progress);

  // Write the mesh.
  io::MeshView view;
  view.positions = nbmc_mesh_positions(mesh.get());
  view.normals = nbmc_mesh_normals(mesh.get());
  view.triangles = nbmc_mesh_triangles(mesh.get());
  view.vertex_count = nbmc_mesh_vertex_count(mesh.get());
  view.triangle_count = nbmc_mesh_triangle_count(mesh.get());
  report.normals = view.normals != nullptr;
  try {
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
  if (!o.quiet && !json_to_stdout) std::fputs(cli::format_report(report).c_str(), stdout);
  if (o.json) {
    const std::string text = cli::format_json(report);
    if (json_to_stdout)
      std::fputs(text.c_str(), stdout);
    else if (!write_text(o.json_path, text))
      return 1;
  }
  std::fflush(stdout);
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
      "PLY, .obj: Wavefront OBJ). Exit codes: 0 ok, 1 error, 2 usage, 130 cancelled (Ctrl-C).");
  rec->add_option("input", o.input, "Particle file (.xyz: raw float32 triples, .ply: point set)")
      ->required()
      ->option_text("IN");
  rec->add_option("-o,--output", o.output, "Mesh to write (.ply or .obj)")->required()->option_text("OUT");
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
  rec->add_option("--bbox", o.bbox, "Only reconstruct inside this box (absolute)")
      ->expected(6)
      ->option_text("XMIN YMIN ZMIN XMAX YMAX ZMAX");
  rec->add_option("--threads", o.desc.num_threads, "Host threads (0 = all cores)")->capture_default_str();
  rec->add_option("--backend", o.backend, "Compute backend")
      ->check(CLI::IsMember(names(kBackends), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--format", o.input_format, "Input format, overriding the extension")
      ->check(CLI::IsMember({"xyz", "ply"}, CLI::ignore_case))
      ->option_text("xyz|ply");
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
    return reconstruct(o);
  } catch (const std::bad_alloc&) {
    std::fputs("nbmc: error: out of memory\n", stderr);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nbmc: error: %s\n", e.what());
  }
  return 1;
}
