// SPDX-License-Identifier: MIT
// nbmc — command-line surface reconstruction of particle files.
//
//   nbmc reconstruct IN -o OUT (--spacing R | --particle-radius P | --radius-attribute NAME) [options]
//   nbmc reconstruct 'frames/fluid_{}.bgeo' -o 'out/surface_{}.ply' ...   (a sequence)
//   nbmc reconstruct dump.h5part -o 'out/surface_{}.glb' ...              (every step)
//
// Exit codes: 0 success, 1 error (input, library, output; in a sequence: any
// frame failed), 2 usage error, 130 cancelled with Ctrl-C.
#include "io/attributes.hpp"
#include "io/error.hpp"
#include "io/mesh.hpp"
#include "io/mesh_xdmf.hpp"
#include "io/particles.hpp"
#include "progress.hpp"
#include "report.hpp"
#include "sequence.hpp"

#include <nbmc.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <future>
#include <limits>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <unistd.h>

#if defined(NBMC_CLI_MPI)
#include <nbmc_mpi.h>

#include <cstdlib>
#include <fstream>
#endif

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Stores the seconds of its life into `to` (on every way out of a scope).
struct SecondsInto {
  double& to;
  Clock::time_point t0 = Clock::now();
  ~SecondsInto() { to = seconds_since(t0); }
};

// ------------------------------------------------------------ name tables
struct Named {
  const char* name;
  std::int32_t value;
};
const Named kMethods[] = {
    {"ssp07", NBMC_METHOD_SSP07}, {"zb05", NBMC_METHOD_ZB05}, {"sph", NBMC_METHOD_SPH}, {"yt10", NBMC_METHOD_YT10}};
const Named kIsolated[] = {
    {"keep", NBMC_ISOLATED_KEEP}, {"drop", NBMC_ISOLATED_DROP}, {"sphere", NBMC_ISOLATED_SPHERE}};
const Named kSmoothWeights[] = {{"uniform", NBMC_SMOOTH_UNIFORM}, {"feature", NBMC_SMOOTH_FEATURE}};
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
  std::string method, field, backend, isolated, smooth_weights;
  std::vector<double> bbox;
  bool no_normals = false;
  bool double_positions = false;
  bool no_cleanup = false;  // --no-cleanup
  bool check = false;       // --check
  bool quiet = false;
  std::string progress = "auto";
  bool json = false;
  std::string json_path;
  std::vector<std::string> attributes; // --attributes
  std::string radius_attribute;         // --radius-attribute: per-particle radii from this attribute
  double radius_scale = 1;              // --radius-scale: times this
  bool spacing_from_radii = false;      // no --spacing/--particle-radius: each frame's largest radius
  std::string frames;                   // --frames a:b[:step]
  bool resume = false;
  bool sequential_io = false;  // --sequential-io: a sequence reads and writes between reconstructions
  int contexts = 0;            // --contexts: frames of a sequence reconstructed at once (0: 2 on CUDA, else 1)
  std::int64_t step = -1; // H5Part step of a single-frame run (-1: the first)
  std::string memory_budget;  // --memory-budget, "" = no cap
  std::string subdomains;     // --subdomains auto|N|NxMxK, "" = whole frame
  bool pieces = false;        // --pieces: under MPI, one piece per rank and a .pvtp/.pvtu index
  bool read_on_root = false;  // --read-on-root: under MPI, rank 0 reads HDF5 too and scatters
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
  // --double-positions: the doubles (the writers round them where they must).
  view.positions64 = nbmc_mesh_positions_f64(mesh);
  if (!view.positions64) view.positions = nbmc_mesh_positions(mesh);
  view.normals = nbmc_mesh_normals(mesh);
  view.triangles = nbmc_mesh_triangles(mesh);
  view.vertex_count = nbmc_mesh_vertex_count(mesh);
  view.triangle_count = nbmc_mesh_triangle_count(mesh);
  return view;
}

// Hands the particle attributes asked for with --attributes (under the
// file's names) to the context, which interpolates them onto the mesh
// (nbmc_context_set_attribute_f64). Returns the status; the message is the
// context's.
std::int32_t set_attributes(nbmc_context* ctx, const nbmc::io::Particles& p, const std::vector<std::string>& names) {
  for (const std::string& n : names) {
    const nbmc::io::Attribute* a = p.attribute(n);
    if (!a) continue;  // check_attributes reported it
    const std::int32_t st = nbmc_context_set_attribute_f64(ctx, a->name.c_str(), a->values.data(),
                                                           static_cast<std::uint32_t>(a->components), 0);
    if (st != NBMC_OK) return st;
  }
  return NBMC_OK;
}

// --isolated sphere: where the spheres of the mesh written to output go,
// <output without its extension>_spheres.ply ("file.h5:/group": beside the file).
std::string spheres_path(const std::string& output) {
  const std::string file = nbmc::io::mesh_output_file(output);
  const std::size_t slash = file.find_last_of('/');
  const std::size_t dot = file.rfind('.');
  const std::string stem = dot != std::string::npos && (slash == std::string::npos || dot > slash) ? file.substr(0, dot)
                                                                                                   : file;
  return stem + "_spheres.ply";
}

// Writes the mesh's spheres (NBMC_ISOLATED_SPHERE) as a PLY point set: vertex
// x y z and a float property radius, no faces. Throws io::Error.
void write_spheres(const std::string& path, const nbmc_mesh* mesh) {
  const std::uint64_t n = nbmc_mesh_sphere_count(mesh);
  const float* s = nbmc_mesh_spheres(mesh);
  std::vector<float> xyz(3 * n);
  nbmc::io::Attribute radius;
  radius.name = "radius";
  radius.components = 1;
  radius.values.resize(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) xyz[3 * i + a] = s[4 * i + a];
    radius.values[i] = s[4 * i + 3];
  }
  nbmc::io::MeshView view;
  view.positions = xyz.empty() ? nullptr : xyz.data();
  view.vertex_count = n;
  view.attributes = &radius;
  view.attribute_count = 1;
  nbmc::io::write_mesh(path, view, "ply", [] { return nbmc::cli::interrupted(); });
}

// The attributes the library interpolated onto mesh, for the writers.
std::vector<nbmc::io::Attribute> mesh_attributes(const nbmc_mesh* mesh) {
  std::vector<nbmc::io::Attribute> out(nbmc_mesh_attribute_count(mesh));
  const std::uint64_t nv = nbmc_mesh_vertex_count(mesh);
  for (std::uint32_t i = 0; i < out.size(); ++i) {
    out[i].name = nbmc_mesh_attribute_name(mesh, i);
    std::uint32_t comps = 0;
    const float* v = nbmc_mesh_attribute(mesh, out[i].name.c_str(), &comps);
    out[i].components = static_cast<int>(comps);
    if (v) out[i].values.assign(v, v + nv * comps);
  }
  return out;
}

// What to read from a particle file: the --attributes and the
// --radius-attribute.
nbmc::io::ReadOptions read_options(const Options& o) {
  nbmc::io::ReadOptions ro;
  ro.format = o.input_format;
  ro.only = o.attributes;
  if (!o.radius_attribute.empty()) ro.only.push_back(o.radius_attribute);
  ro.attributes = !ro.only.empty();
  return ro;
}

// --radius-attribute: the attribute's values times --radius-scale as the
// particles' radii (nbmc_context_set_radii_f64), and the parameters of the
// frame (without --spacing/--particle-radius, spacing is its largest radius).
// Returns the status (the message is the context's, or in error); the report
// (may be null) gets the smallest and largest radius.
std::int32_t set_radii(nbmc_context* ctx, const Options& o, const nbmc::io::Particles& p, nbmc_params& params,
                       std::string& error, nbmc::cli::Report* report = nullptr) {
  params = o.params;
  if (o.radius_attribute.empty()) return NBMC_OK;
  const nbmc::io::Attribute* a = p.attribute(o.radius_attribute);
  if (!a) return NBMC_OK;  // check_attributes reported it
  if (a->components != 1) {
    error = "--radius-attribute: '" + a->name + "' is a vector; radii need a scalar attribute";
    return NBMC_ERROR_INVALID_PARAMETER;
  }
  std::vector<double> radii(a->values.size());
  double largest = 0, smallest = radii.empty() ? 0 : a->values[0] * o.radius_scale;
  for (std::size_t i = 0; i < radii.size(); ++i) {
    radii[i] = a->values[i] * o.radius_scale;
    largest = std::max(largest, radii[i]);
    smallest = std::min(smallest, radii[i]);
  }
  const std::int32_t st = nbmc_context_set_radii_f64(ctx, radii.data(), radii.size(), 0);
  if (st != NBMC_OK) {
    error = std::string("--radius-attribute '") + a->name + "': " + nbmc_context_last_error(ctx);
    return st;
  }
  if (o.spacing_from_radii) params.spacing = largest;
  if (report) {
    report->radius_attribute = a->name;
    report->radius_scale = o.radius_scale;
    report->radius_min = smallest;
    report->radius_max = largest;
  }
  return NBMC_OK;
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

// A frame of a sequence in three stages: read (any thread), reconstruct (the
// caller's thread, on the context), write (any thread). A failure is
// reported in the frame's result, not thrown; a cancel sets a flag.
struct FrameInput {
  nbmc::io::Particles particles;
  bool skipped = false, cancelled = false;
  std::string error;  // not empty: the frame failed
  double seconds = 0;
};

// Reads one file's particles (H5Part: step) and checks the --attributes;
// errors go into the result, not thrown.
FrameInput read_input(const Options& o, const std::string& path, std::int64_t step) {
  using namespace nbmc;
  FrameInput in;
  const auto t0 = Clock::now();
  try {
    io::ReadOptions ro = read_options(o);
    ro.frame = step;
    in.particles = io::read_particles(path, ro);
    check_attributes(path, in.particles, ro.only, ro);
  } catch (const io::Cancelled&) {
    in.cancelled = true;
  } catch (const std::bad_alloc&) {
    in.error = "out of memory";
  } catch (const std::exception& e) {
    in.error = e.what();
  }
  if (!in.error.empty()) in.particles = io::Particles();
  in.seconds = seconds_since(t0);
  return in;
}

FrameInput read_frame(const Options& o, const nbmc::cli::Frame& f) {
  FrameInput in;
  if (!f.missing.empty()) in.error = f.missing;
  else if (o.resume && nbmc::cli::output_exists(f.output)) in.skipped = true;
  else in = read_input(o, f.input, f.step);
  return in;
}

// The frame's mesh (NULL when it failed: r.error says why, or was cancelled).
MeshPtr reconstruct_frame(const Options& o, nbmc_context* ctx, FrameInput& in, nbmc::cli::FrameResult& r,
                          bool& cancelled_run) {
  using namespace nbmc;
  const SecondsInto lap{r.reconstruct_seconds};
  try {
    const io::Particles& particles = in.particles;
    r.particles = particles.count();
    std::int32_t st = nbmc_context_set_particles_f64(ctx, particles.xyz.data(), particles.count(), 0);
    if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(ctx));
    st = set_attributes(ctx, particles, o.attributes);
    if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(ctx));
    nbmc_params params;
    std::string radii_error;
    st = set_radii(ctx, o, particles, params, radii_error);
    if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + radii_error);
    in.particles = io::Particles();  // the context has its copies
    nbmc_mesh* raw_mesh = nullptr;
    st = nbmc_context_reconstruct(ctx, &params, &raw_mesh);
    MeshPtr mesh(raw_mesh);
    if (st == NBMC_ERROR_CANCELLED) {
      cancelled_run = true;
      return nullptr;
    }
    if (st != NBMC_OK) throw cli::FrameError(std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(ctx));
    return mesh;
  } catch (const std::bad_alloc&) {
    r.error = "out of memory";
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  in.particles = io::Particles();
  return nullptr;
}

// Writes the frame's mesh (and its spheres); r.status "written" on success.
void write_frame(const Options& o, const nbmc::cli::Frame& f, const nbmc_mesh* mesh, nbmc::cli::FrameResult& r,
                 bool& cancelled_run) {
  using namespace nbmc;
  const SecondsInto lap{r.write_seconds};
  try {
    io::MeshView view = mesh_view(mesh);
    const std::vector<io::Attribute> attrs = mesh_attributes(mesh);
    view.attributes = attrs.empty() ? nullptr : attrs.data();
    view.attribute_count = attrs.size();
    cli::make_parent_folders(f.output);
    io::write_mesh(f.output, view, "", [] { return cli::interrupted(); });
    if (o.params.isolated == NBMC_ISOLATED_SPHERE) write_spheres(spheres_path(f.output), mesh);
    r.vertices = view.vertex_count;
    r.triangles = view.triangle_count;
    r.status = "written";
  } catch (const io::Cancelled&) {
    cancelled_run = true;
  } catch (const std::bad_alloc&) {
    r.error = "out of memory";
  } catch (const std::exception& e) {
    r.error = e.what();
  }
}

nbmc::cli::FrameResult frame_result(const nbmc::cli::Frame& f) {
  nbmc::cli::FrameResult r;
  r.label = f.label;
  r.input = f.input;
  r.output = f.output;
  return r;
}

// One frame of a sequence, the three stages one after the other.
nbmc::cli::FrameResult run_frame(const Options& o, nbmc_context* ctx, const nbmc::cli::Frame& f, bool& cancelled_run) {
  using namespace nbmc;
  cli::FrameResult r = frame_result(f);
  const auto t0 = Clock::now();
  FrameInput in = read_frame(o, f);
  r.read_seconds = in.seconds;
  if (in.cancelled) {
    cancelled_run = true;
    return r;
  }
  if (in.skipped) r.status = "skipped";
  else if (!in.error.empty()) r.error = in.error;
  else if (MeshPtr mesh = reconstruct_frame(o, ctx, in, r, cancelled_run)) write_frame(o, f, mesh.get(), r, cancelled_run);
  r.seconds = seconds_since(t0);
  return r;
}

// Whether a sequence reads or writes HDF5 (the HDF5 library is not
// thread-safe here: its frames are read and written on one thread).
bool sequence_uses_hdf5(const Options& o, const std::vector<nbmc::cli::Frame>& frames) {
  for (const nbmc::cli::Frame& f : frames) {
    try {
      const std::string in = nbmc::io::particle_format(f.input, o.input_format);
      if (in == "h5part" || in == "hdf5" || in == "pysph" || in == "gadget") return true;
      if (lower(nbmc::io::mesh_format(f.output)) == "h5") return true;
    } catch (const std::exception&) {
      // (read_frame reports it)
    }
  }
  return false;
}

// Whether a sequence reads the next frame and writes the previous one on
// two more threads while a frame is reconstructed.
bool overlapped_io(const Options& o, const std::vector<nbmc::cli::Frame>& frames) {
  return !o.sequential_io && frames.size() > 1 && !sequence_uses_hdf5(o, frames);
}

// An overlapped sequence runs its reading and writing threads beside the
// library's OpenMP threads. By default libgomp's idle threads spin for a
// while after every parallel region, and they then take the cores from the
// I/O threads and from the thread that waits for the GPU: on an H100
// machine's 16 cores, 8 copies of the 1.65 M frame at r/2 took 0.93-1.08 s,
// slower than one frame after the other (0.94-1.03 s), and 0.62-0.64 s with
// OMP_WAIT_POLICY=passive; single frames and the benchmarks ran as fast
// either way (bench/RESULTS.md, "Session 28"). OpenMP reads the variable
// once, when its library is loaded, before main: so the command runs itself
// again with it set. Not when the user has set it (to anything), nor where
// the library has no OpenMP; if the exec fails, the run goes on as it is.
void run_again_with_passive_openmp(char** argv) {
#if defined(__linux__)
  if (std::getenv("OMP_WAIT_POLICY") != nullptr || !nbmc_backend_available(NBMC_BACKEND_OPENMP)) return;
  if (::setenv("OMP_WAIT_POLICY", "passive", 1) != 0) return;
  if (std::getenv("NBMC_TRACE") != nullptr) std::fputs("[nbmc trace] running again with OMP_WAIT_POLICY=passive\n", stderr);
  ::execv("/proc/self/exe", argv);
  ::unsetenv("OMP_WAIT_POLICY");
#else
  (void)argv;
#endif
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

  std::vector<ContextPtr> ctxs;
  auto add_context = [&]() -> std::int32_t {
    nbmc_context* raw = nullptr;
    const std::int32_t st = nbmc_context_create(&o.desc, &raw);
    if (st != NBMC_OK) return st;
    ctxs.emplace_back(raw);
    apply_memory_budget(raw, o);
    nbmc_context_set_progress(raw, &cli::Progress::callback, &bar);  // (Ctrl-C only: no bar is drawn)
    return NBMC_OK;
  };
  // While a frame is reconstructed, the next one is read and the previous
  // one written on two other threads (not with HDF5 files, nor with
  // --sequential-io); the meshes are the same either way. The first frame
  // is read while the contexts are set up.
  const bool overlap = overlapped_io(o, frames);
  auto read_ahead = [&](std::size_t i) {
    return std::async(std::launch::async, [&o, &f = frames[i]] { return read_frame(o, f); });
  };
  std::future<FrameInput> next;
  if (overlap) next = read_ahead(0);
  std::int32_t st = add_context();
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(nullptr));
  std::int32_t backend = o.desc.backend;
  nbmc_context_backend(ctxs[0].get(), &backend);

  std::vector<cli::FrameResult> results;
  cli::RateMeter meter(frames.size());
  bool cancelled_run = false;
  // A frame's result, reported in frame order once it is final. The meter
  // counts each frame's share of the wall time (with the overlap below, the
  // stages of neighbouring frames run at once).
  auto last_done = Clock::now();
  auto report = [&](cli::FrameResult r) {
    const double wall = std::chrono::duration<double>(Clock::now() - last_done).count();
    last_done = Clock::now();
    meter.done(r.status == "written", wall);
    if (r.status == "failed") {
      if (r.error.rfind(r.input, 0) == 0) // the message names the file already
        std::fprintf(stderr, "nbmc: error: frame %s: %s\n", r.label.c_str(), r.error.c_str());
      else
        std::fprintf(stderr, "nbmc: error: frame %s (%s): %s\n", r.label.c_str(), r.input.c_str(), r.error.c_str());
    }
    if (show) std::fputs(cli::progress_line(results.size() + 1, frames.size(), r, meter).c_str(), stderr);
    results.push_back(std::move(r));
  };
  // With CUDA, two contexts take turns: one frame's upload and what the
  // library does outside its Kokkos thread run while the other's frame is
  // reconstructed. The reconstructions and their clean-ups run one at a
  // time on nbmc's Kokkos thread, so the gain is small (8 frames of 1.65 M
  // particles on an H100 machine: 0.59-0.67 s, one context 0.63-0.71 s;
  // bench/RESULTS.md, "Session 28"). Each context holds its own buffers, so
  // not under a memory budget unless asked for.
  int n_contexts = o.contexts > 0 ? o.contexts
                   : backend == NBMC_BACKEND_CUDA && o.memory_budget.empty() ? 2 : 1;
  if (!overlap) n_contexts = 1;
  while (int(ctxs.size()) < n_contexts) {
    st = add_context();
    if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(nullptr));
  }
  struct Writing {
    std::future<void> done;
    cli::FrameResult r;
    MeshPtr mesh;
    bool cancelled = false;
    double seconds = 0;  // the frame's read and reconstruction
  };
  std::unique_ptr<Writing> writing;  // the previous frame's write
  auto finish_writing = [&] {
    if (!writing) return;
    writing->done.get();
    writing->mesh.reset();
    if (writing->cancelled) cancelled_run = true;
    else report(std::move(writing->r));
    writing.reset();
  };
  // A frame's reconstruction (on a thread of its own with two contexts).
  struct Reconstruction {
    std::size_t index = 0;  // in frames
    std::future<void> done;
    FrameInput in;
    cli::FrameResult r;
    MeshPtr mesh;
    bool cancelled = false;
  };
  // Takes a reconstruction, in frame order, to its report (and write).
  auto complete = [&](std::unique_ptr<Reconstruction> c) {
    if (c->done.valid()) c->done.get();
    if (c->cancelled) cancelled_run = true;
    if (cancelled_run) return;
    finish_writing();
    if (cancelled_run) return;
    if (!c->mesh) {
      report(std::move(c->r));
    } else if (!overlap) {
      const auto t1 = Clock::now();
      write_frame(o, frames[c->index], c->mesh.get(), c->r, cancelled_run);
      c->r.seconds += seconds_since(t1);
      if (!cancelled_run) report(std::move(c->r));
    } else {
      writing.reset(new Writing);
      writing->r = std::move(c->r);
      writing->mesh = std::move(c->mesh);
      Writing* w = writing.get();
      w->done = std::async(std::launch::async, [&o, &f = frames[c->index], w] {
        const auto t1 = Clock::now();
        write_frame(o, f, w->mesh.get(), w->r, w->cancelled);
        w->r.seconds += seconds_since(t1);
      });
    }
  };
  std::unique_ptr<Reconstruction> pending;  // the previous frame's, still running (two contexts)
  for (std::size_t i = 0; i < frames.size() && !cancelled_run; ++i) {
    const cli::Frame& f = frames[i];
    if (cli::interrupted()) {
      cancelled_run = true;
      break;
    }
    FrameInput in = overlap ? next.get() : read_frame(o, f);
    if (overlap && i + 1 < frames.size()) next = read_ahead(i + 1);
    if (in.cancelled) {
      cancelled_run = true;
      break;
    }
    auto c = std::make_unique<Reconstruction>();
    c->index = i;
    c->r = frame_result(f);
    c->in = std::move(in);
    c->r.seconds = c->in.seconds;
    c->r.read_seconds = c->in.seconds;
    if (c->in.skipped) {
      c->r.status = "skipped";
    } else if (!c->in.error.empty()) {
      c->r.error = c->in.error;
    } else {
      Reconstruction* p = c.get();
      nbmc_context* ctx = ctxs[i % ctxs.size()].get();  // not the previous frame's
      auto work = [&o, ctx, p] {
        const auto t0 = Clock::now();
        p->mesh = reconstruct_frame(o, ctx, p->in, p->r, p->cancelled);
        p->r.seconds += seconds_since(t0);
      };
      if (ctxs.size() > 1) p->done = std::async(std::launch::async, work);
      else work();
    }
    if (pending) complete(std::move(pending));
    if (ctxs.size() > 1 && !cancelled_run) pending = std::move(c);
    else if (!cancelled_run) complete(std::move(c));
    else if (c->done.valid()) c->done.wait();
  }
  if (pending && !cancelled_run) complete(std::move(pending));
  if (pending && pending->done.valid()) pending->done.wait();  // (cancelled)
  finish_writing();
  if (next.valid()) next.wait();  // (a frame read ahead of a cancel)
  ctxs.clear();
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

  // Check the file names first, to fail early.
  try {
    report.output_format = io::mesh_format(o.output);
    report.input_format = io::particle_format(o.input, o.input_format);
  } catch (const io::Error& e) {
    std::fprintf(stderr, "nbmc: error: %s\n", e.what());
    return 1;
  }
  // The particles are read on a thread of their own while this one sets up
  // the context (with CUDA: the driver, the device and its memory pools, a
  // large part of a single run's time). Errors are reported in the order of
  // a sequential run: the file's first.
  std::future<FrameInput> reading =
      std::async(std::launch::async, [&o] { return read_input(o, o.input, o.step); });
  const auto t_setup = Clock::now();
  nbmc_context* raw = nullptr;
  std::int32_t st = nbmc_context_create(&o.desc, &raw);
  const std::string setup_error = st == NBMC_OK ? std::string() : nbmc_context_last_error(nullptr);
  ContextPtr ctx(raw);
  report.setup_seconds = seconds_since(t_setup);
  report.has_setup = true;

  io::Particles particles;
  {
    FrameInput in = reading.get();
    report.read_seconds = in.seconds;
    if (in.cancelled) return cancelled(progress);
    if (!in.error.empty()) {
      std::fprintf(stderr, "nbmc: error: %s\n", in.error.c_str());
      return 1;
    }
    particles = std::move(in.particles);
  }
  report.particle_count = particles.count();
  if (st != NBMC_OK) return library_error(st, setup_error.c_str());
  if (cli::interrupted()) return cancelled(progress);

  // Upload, reconstruction.
  apply_memory_budget(ctx.get(), o);
  std::int32_t backend = o.desc.backend;
  if (nbmc_context_backend(ctx.get(), &backend) == NBMC_OK) report.backend = name_of(kBackends, backend);
  nbmc_context_set_progress(ctx.get(), &cli::Progress::callback, &progress);

  st = nbmc_context_set_particles_f64(ctx.get(), particles.xyz.data(), particles.count(), 0);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  st = set_attributes(ctx.get(), particles, o.attributes);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  nbmc_params params;
  std::string radii_error;
  st = set_radii(ctx.get(), o, particles, params, radii_error, &report);
  if (st != NBMC_OK) return library_error(st, radii_error.c_str());
  particles = io::Particles(); // the context has its copies

  nbmc_mesh* raw_mesh = nullptr;
  st = nbmc_context_reconstruct(ctx.get(), &params, &raw_mesh);
  MeshPtr mesh(raw_mesh);
  progress.finish();
  if (st == NBMC_ERROR_CANCELLED) return cancelled(progress);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  nbmc_stats_init(&report.stats);
  st = nbmc_context_stats(ctx.get(), &report.stats);
  if (st != NBMC_OK) return library_error(st, nbmc_context_last_error(ctx.get()));
  report.params = params;
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
    vertex_attributes = mesh_attributes(mesh.get());
    if (!vertex_attributes.empty()) {
      report.interpolate_seconds = report.stats.stage_seconds[NBMC_STAGE_ATTRIBUTES];
      view.attributes = vertex_attributes.data();
      view.attribute_count = vertex_attributes.size();
      for (const io::Attribute& a : vertex_attributes) report.attributes.push_back(a.name);
    }
    const auto t0 = Clock::now();
    io::write_mesh(o.output, view, report.output_format, [] { return cli::interrupted(); });
    if (o.params.isolated == NBMC_ISOLATED_SPHERE) {
      report.spheres_path = spheres_path(o.output);
      write_spheres(report.spheres_path, mesh.get());
    }
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


#if defined(NBMC_CLI_MPI)
// ------------------------------------------------------------ under MPI
// `mpirun -n P nbmc reconstruct ...`: one frame split over the ranks (rank
// 0 reads and scatters; the mesh gathered on rank 0, or --pieces), or a
// sequence whose frames the ranks take one at a time from a shared counter.

// Started by mpirun/mpiexec/srun (an MPI launcher sets one of these).
bool launched_by_mpi() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"})
    if (std::getenv(v)) return true;
  return false;
}

int local_rank() {
  for (const char* v : {"OMPI_COMM_WORLD_LOCAL_RANK", "MPI_LOCALRANKID", "SLURM_LOCALID"})
    if (const char* s = std::getenv(v)) return std::atoi(s);
  return 0;
}

// A context on this rank's GPU (local rank -> device) or CPU.
nbmc_context* mpi_context(Options& o, std::string& error) {
  nbmc_context_desc d = o.desc;
  if (d.backend == NBMC_BACKEND_CUDA || (d.backend == NBMC_BACKEND_AUTO && nbmc_backend_available(NBMC_BACKEND_CUDA)))
    d.device_id = local_rank();
  nbmc_context* ctx = nullptr;
  std::int32_t st = nbmc_context_create(&d, &ctx);
  if (st != NBMC_OK && d.device_id != 0) {  // fewer GPUs than ranks on this node: share device 0
    d.device_id = 0;
    st = nbmc_context_create(&d, &ctx);
  }
  if (st != NBMC_OK) {
    error = std::string(nbmc_status_string(st)) + ": " + nbmc_context_last_error(nullptr);
    return nullptr;
  }
  apply_memory_budget(ctx, o);
  return ctx;
}

// The same string on every rank (from root).
std::string bcast_string(const std::string& s, int rank, int root = 0) {
  std::uint64_t n = s.size();
  MPI_Bcast(&n, 1, MPI_UINT64_T, root, MPI_COMM_WORLD);
  std::string out = rank == root ? s : std::string(n, '\0');
  if (n) MPI_Bcast(&out[0], int(n), MPI_CHAR, root, MPI_COMM_WORLD);
  return out;
}

// Every rank's error (or ""), agreed: the lowest failing rank's, named.
std::string agree_error(const std::string& mine, int rank, int size) {
  int first = mine.empty() ? size : rank;
  MPI_Allreduce(MPI_IN_PLACE, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  if (first == size) return "";
  const std::string msg = bcast_string(mine, rank, first);
  return "rank " + std::to_string(first) + ": " + msg;
}

std::string piece_path(const std::string& index, int rank, const std::string& ext) {
  const std::size_t dot = index.rfind('.');
  return index.substr(0, dot) + "_" + std::to_string(rank) + "." + ext;
}

int reconstruct_mpi(Options& o, int rank, int size, bool pieces) {
  using namespace nbmc;
  const auto t_start = Clock::now();
  cli::install_interrupt_handler();
  const bool root = rank == 0;
  const bool json_to_stdout = o.json && (o.json_path.empty() || o.json_path == "-");
  const bool stderr_tty = ::isatty(STDERR_FILENO) == 1;
  const bool show_progress = root && (o.progress == "always" || (o.progress == "auto" && stderr_tty && !o.quiet));
  cli::Progress progress(show_progress, stderr_tty);
  auto fail = [&](const std::string& msg, int code) {
    if (root) std::fprintf(stderr, "nbmc: error: %s\n", msg.c_str());
    return code;
  };
  std::string piece_ext;
  if (pieces) {
    const std::string lower_out = lower(o.output);
    const bool pvtp = lower_out.size() > 5 && lower_out.substr(lower_out.size() - 5) == ".pvtp";
    const bool pvtu = lower_out.size() > 5 && lower_out.substr(lower_out.size() - 5) == ".pvtu";
    if (!pvtp && !pvtu) return fail("--pieces writes a ParaView index: give -o NAME.pvtp (or .pvtu)", 2);
    piece_ext = pvtp ? "vtp" : "vtu";
  }

  cli::Report report;
  report.version = nbmc_version_string();
  report.input_path = o.input;
  report.output_path = o.output;
  // HDF5 layouts: every rank reads its own rows (hyperslabs); otherwise (or
  // with --read-on-root) rank 0 reads the frame and scatters even shares.
  io::Particles particles;
  std::string error;
  std::string format;
  try {
    format = io::particle_format(o.input, o.input_format);
  } catch (const std::exception& e) {
    error = e.what();
  }
  // (--attributes: rank 0 reads them with the positions and scatters both;
  // the per-rank hyperslab reads take positions only.)
  const bool parallel_read = !o.read_on_root && o.attributes.empty() && o.radius_attribute.empty() &&
                             (format == "h5part" || format == "hdf5" || format == "pysph" || format == "gadget");
  std::vector<double> mine;
  io::Particles mine_attributes;  // this rank's share of the --attributes (names as in the file)
  if (parallel_read && error.empty()) {
    const auto t0 = Clock::now();
    try {
      report.output_format = pieces ? piece_ext : io::mesh_format(o.output);
      report.input_format = format;
      io::ReadOptions ro;
      ro.format = o.input_format;
      ro.frame = o.step;
      ro.attributes = false;
      ro.part = std::uint32_t(rank);
      ro.parts = std::uint32_t(size);
      particles = io::read_particles(o.input, ro);
    } catch (const std::exception& e) {
      error = e.what();
    }
    error = agree_error(error, rank, size);
    if (!error.empty()) return fail(error, 1);
    double t = seconds_since(t0);
    MPI_Allreduce(MPI_IN_PLACE, &t, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
    report.read_seconds = t;
    std::uint64_t n = particles.count();
    MPI_Allreduce(MPI_IN_PLACE, &n, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
    report.particle_count = n;
    mine.swap(particles.xyz);
    particles = io::Particles();
  }
  if (!parallel_read && root && error.empty()) {
    try {
      report.output_format = pieces ? piece_ext : io::mesh_format(o.output);
      report.input_format = io::particle_format(o.input, o.input_format);
      const auto t0 = Clock::now();
      io::ReadOptions ro = read_options(o);
      ro.frame = o.step;
      particles = io::read_particles(o.input, ro);
      check_attributes(o.input, particles, ro.only, ro);
      report.read_seconds = seconds_since(t0);
    } catch (const std::exception& e) {
      error = e.what();
    }
  }
  if (!parallel_read) {
  error = bcast_string(error, rank);
  if (!error.empty()) return fail(error, 1);
  // Even shares, in file order (nbmc moves them to the ranks that need them).
  std::uint64_t n = particles.count();
  MPI_Bcast(&n, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
  report.particle_count = n;
  std::vector<int> counts(static_cast<std::size_t>(size)), displs(static_cast<std::size_t>(size));
  for (int r = 0; r < size; ++r) {
    const std::uint64_t a = n * std::uint64_t(r) / std::uint64_t(size), b = n * std::uint64_t(r + 1) / std::uint64_t(size);
    if (3 * (b - a) > std::uint64_t(INT32_MAX) || 3 * a > std::uint64_t(INT32_MAX))
      return fail("the frame is too large to scatter from rank 0 (" + std::to_string(n) +
                      " particles); use more ranks", 1);
    counts[std::size_t(r)] = int(3 * (b - a));
    displs[std::size_t(r)] = int(3 * a);
  }
  mine.resize(static_cast<std::size_t>(counts[static_cast<std::size_t>(rank)]));
  MPI_Scatterv(root ? particles.xyz.data() : nullptr, counts.data(), displs.data(), MPI_DOUBLE, mine.data(),
               counts[std::size_t(rank)], MPI_DOUBLE, 0, MPI_COMM_WORLD);
  // The attributes asked for, the same shares (each name is in the file:
  // check_attributes on rank 0 agreed above).
  std::vector<std::string> scattered = o.attributes;
  if (!o.radius_attribute.empty()) scattered.push_back(o.radius_attribute);
  for (const std::string& name : scattered) {
    const io::Attribute* a = root ? particles.attribute(name) : nullptr;
    int comps = a ? a->components : 0;
    MPI_Bcast(&comps, 1, MPI_INT, 0, MPI_COMM_WORLD);
    std::vector<int> c(counts), d(displs);
    for (int r = 0; r < size; ++r) {
      if (std::int64_t(c[std::size_t(r)] / 3) * comps > std::int64_t(INT32_MAX) ||
          std::int64_t(d[std::size_t(r)] / 3) * comps > std::int64_t(INT32_MAX))
        return fail("the attribute '" + name + "' is too large to scatter from rank 0; use more ranks", 1);
      c[std::size_t(r)] = c[std::size_t(r)] / 3 * comps;
      d[std::size_t(r)] = d[std::size_t(r)] / 3 * comps;
    }
    io::Attribute part;
    part.name = a ? a->name : name;
    part.components = comps;
    part.values.resize(std::size_t(c[std::size_t(rank)]));
    MPI_Scatterv(a ? a->values.data() : nullptr, c.data(), d.data(), MPI_DOUBLE, part.values.data(),
                 c[std::size_t(rank)], MPI_DOUBLE, 0, MPI_COMM_WORLD);
    mine_attributes.attributes.push_back(std::move(part));
  }
  particles = io::Particles();
  }

  std::string ctx_error;
  ContextPtr ctx(mpi_context(o, ctx_error));
  ctx_error = agree_error(ctx_error, rank, size);
  if (!ctx_error.empty()) return fail(ctx_error, 1);
  std::int32_t backend = o.desc.backend;
  if (nbmc_context_backend(ctx.get(), &backend) == NBMC_OK) report.backend = name_of(kBackends, backend);
  if (root) nbmc_context_set_progress(ctx.get(), &cli::Progress::callback, &progress);
  std::int32_t st = nbmc_mpi_context_set_comm(ctx.get(), MPI_COMM_WORLD);
  if (st != NBMC_OK) return fail(nbmc_context_last_error(ctx.get()), 1);
  nbmc_context_set_particles_f64(ctx.get(), mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
  // This rank's attributes and radii (--radius-attribute: the spacing
  // without --spacing is the largest radius over all ranks).
  nbmc_params params = o.params;
  {
    std::string attr_error;
    double extent[2] = {0, -std::numeric_limits<double>::infinity()};  // -smallest, largest
    if (!mine.empty()) {
      if (set_attributes(ctx.get(), mine_attributes, o.attributes) != NBMC_OK)
        attr_error = nbmc_context_last_error(ctx.get());
      else if (set_radii(ctx.get(), o, mine_attributes, params, attr_error, &report) != NBMC_OK && attr_error.empty())
        attr_error = nbmc_context_last_error(ctx.get());
      if (!o.radius_attribute.empty()) extent[0] = -report.radius_min, extent[1] = report.radius_max;
    }
    attr_error = agree_error(attr_error, rank, size);
    if (!attr_error.empty()) return fail(attr_error, 1);
    if (!o.radius_attribute.empty()) {
      if (mine.empty()) extent[0] = -std::numeric_limits<double>::infinity();
      MPI_Allreduce(MPI_IN_PLACE, extent, 2, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
      report.radius_attribute = o.radius_attribute;
      report.radius_scale = o.radius_scale;
      report.radius_min = -extent[0];
      report.radius_max = extent[1];
      params = o.params;
      if (o.spacing_from_radii) params.spacing = extent[1];
    }
  }
  std::vector<double>().swap(mine);
  mine_attributes = io::Particles();

  nbmc_mesh* raw_mesh = nullptr;
  st = nbmc_mpi_reconstruct(ctx.get(), &params, pieces ? NBMC_MPI_PIECES : NBMC_MPI_GATHER, 0, &raw_mesh);
  MeshPtr mesh(raw_mesh);
  progress.finish();
  if (st != NBMC_OK) {
    if (root) library_error(st, nbmc_context_last_error(ctx.get()));
    return st == NBMC_ERROR_CANCELLED ? 130 : 1;
  }
  nbmc_stats_init(&report.stats);
  nbmc_context_stats(ctx.get(), &report.stats);
  report.params = params;
  report.ranks = size;
  nbmc_subdomain_stats_init(&report.subdomains);
  if (nbmc_context_subdomain_stats(ctx.get(), &report.subdomains) == NBMC_OK && root)
    for (std::uint64_t i = 0; i < report.subdomains.count; ++i) {
      nbmc_subdomain_entry e;
      nbmc_subdomain_entry_init(&e);
      if (nbmc_context_subdomain_entry(ctx.get(), i, &e) == NBMC_OK) report.subdomain_entries.push_back(e);
    }

  // Write: the whole mesh on rank 0, or every rank its piece and rank 0 the index.
  std::string write_error;
  const auto t0 = Clock::now();
  if (!pieces) {
    if (root) {
      try {
        if (o.check) {
          nbmc_mesh_check_result_init(&report.check);
          report.has_check = nbmc_mesh_check(mesh.get(), &report.check) == NBMC_OK;
        }
        io::MeshView view = mesh_view(mesh.get());
        const std::vector<io::Attribute> attrs = mesh_attributes(mesh.get());
        view.attributes = attrs.empty() ? nullptr : attrs.data();
        view.attribute_count = attrs.size();
        for (const io::Attribute& a : attrs) report.attributes.push_back(a.name);
        report.interpolate_seconds = report.stats.stage_seconds[NBMC_STAGE_ATTRIBUTES];
        io::write_mesh(o.output, view, report.output_format, [] { return cli::interrupted(); });
      } catch (const std::exception& e) {
        write_error = e.what();
      }
    }
  } else {
    const std::string mine_path = piece_path(o.output, rank, piece_ext);
    const std::vector<io::Attribute> attrs = mesh_attributes(mesh.get());
    if (root) {
      for (const io::Attribute& a : attrs) report.attributes.push_back(a.name);
      report.interpolate_seconds = report.stats.stage_seconds[NBMC_STAGE_ATTRIBUTES];
    }
    try {
      io::MeshView view = mesh_view(mesh.get());
      view.attributes = attrs.empty() ? nullptr : attrs.data();
      view.attribute_count = attrs.size();
      io::write_mesh(mine_path, view, piece_ext, [] { return cli::interrupted(); });
    } catch (const std::exception& e) {
      write_error = e.what();
    }
    write_error = agree_error(write_error, rank, size);
    if (!write_error.empty()) {
      std::remove(mine_path.c_str());  // no partial output
    } else if (root) {
      // The ParaView index of the pieces (file names relative to it).
      const bool vtp = piece_ext == "vtp";
      const std::string type = vtp ? "PPolyData" : "PUnstructuredGrid";
      std::string x = "<?xml version=\"1.0\"?>\n<VTKFile type=\"" + type +
                      "\" version=\"0.1\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n  <" + type +
                      " GhostLevel=\"0\">\n";
      if (o.params.compute_normals || !attrs.empty()) {
        x += o.params.compute_normals ? "    <PPointData Normals=\"Normals\">\n" : "    <PPointData>\n";
        if (o.params.compute_normals)
          x += "      <PDataArray type=\"Float32\" Name=\"Normals\" NumberOfComponents=\"3\"/>\n";
        for (const io::Attribute& a : attrs)
          x += "      <PDataArray type=\"Float32\" Name=\"" + io::detail::xml_escape(a.name) + "\"" +
               (a.components != 1 ? " NumberOfComponents=\"" + std::to_string(a.components) + "\"" : std::string()) +
               "/>\n";
        x += "    </PPointData>\n";
      }
      x += std::string("    <PPoints>\n      <PDataArray type=\"") +
           (o.params.double_positions ? "Float64" : "Float32") + "\" NumberOfComponents=\"3\"/>\n    </PPoints>\n";
      if (!vtp)
        x += "    <PCells>\n      <PDataArray type=\"Int64\" Name=\"connectivity\"/>\n      <PDataArray "
             "type=\"Int64\" Name=\"offsets\"/>\n      <PDataArray type=\"UInt8\" Name=\"types\"/>\n    </PCells>\n";
      for (int r = 0; r < size; ++r) {
        std::string src = piece_path(o.output, r, piece_ext);
        const std::size_t slash = src.rfind('/');
        if (slash != std::string::npos) src = src.substr(slash + 1);
        x += "    <Piece Source=\"" + src + "\"/>\n";
      }
      x += "  </" + type + ">\n</VTKFile>\n";
      const std::string tmp = o.output + ".tmp";
      std::ofstream f(tmp, std::ios::binary);
      f << x;
      f.close();
      if (!f || std::rename(tmp.c_str(), o.output.c_str()) != 0) {
        std::remove(tmp.c_str());
        write_error = "could not write " + o.output;
      }
    }
  }
  write_error = bcast_string(write_error, rank);
  if (!write_error.empty()) {
    if (pieces) std::remove(piece_path(o.output, rank, piece_ext).c_str());
    return fail(write_error, 1);
  }
  report.write_seconds = seconds_since(t0);
  mesh.reset();
  ctx.reset();
  if (!root) return 0;
  report.total_seconds = seconds_since(t_start);
  report.peak_rss_bytes = cli::peak_rss_bytes();
  if (!emit_report(o, json_to_stdout, [&] { return cli::format_report(report); },
                   [&] { return cli::format_json(report); }))
    return 1;
  return 0;
}

// A sequence: every rank takes the next frame from a counter on rank 0
// (frames differ in cost), with its own context and GPU; rank 0 reports.
int reconstruct_sequence_mpi(Options& o, const std::vector<nbmc::cli::Frame>& frames, int rank, int size) {
  using namespace nbmc;
  const auto t_start = Clock::now();
  const bool root = rank == 0;
  const bool json_to_stdout = o.json && (o.json_path.empty() || o.json_path == "-");
  const bool show = root && !o.quiet && o.progress != "never";
  for (const cli::Frame& f : frames)
    if (lower(io::mesh_format(f.output)) == "h5") {
      if (root)
        std::fputs("nbmc: error: under MPI a sequence needs one output file per frame (not one .h5 for all)\n", stderr);
      return 2;
    }
  std::string error;
  ContextPtr ctx(mpi_context(o, error));
  error = agree_error(error, rank, size);
  if (!error.empty()) {
    if (root) std::fprintf(stderr, "nbmc: error: %s\n", error.c_str());
    return 1;
  }
  std::int32_t backend = o.desc.backend;
  nbmc_context_backend(ctx.get(), &backend);
  // Two counters on rank 0: frames handed out, frames done.
  std::int64_t* base = nullptr;
  MPI_Win win;
  MPI_Win_allocate(root ? 2 * sizeof(std::int64_t) : 0, sizeof(std::int64_t), MPI_INFO_NULL, MPI_COMM_WORLD, &base,
                   &win);
  if (root) base[0] = base[1] = 0;
  MPI_Barrier(MPI_COMM_WORLD);
  auto fetch_add = [&](int which) {
    const std::int64_t one = 1;
    std::int64_t got = 0;
    MPI_Win_lock(MPI_LOCK_SHARED, 0, 0, win);
    MPI_Fetch_and_op(&one, &got, MPI_INT64_T, 0, which, MPI_SUM, win);
    MPI_Win_unlock(0, win);
    return got;
  };
  std::vector<std::pair<std::int64_t, cli::FrameResult>> mine;
  cli::RateMeter meter(frames.size());
  bool cancelled_run = false;
  for (;;) {
    if (cli::interrupted()) {
      cancelled_run = true;
      break;
    }
    const std::int64_t i = fetch_add(0);
    if (i >= std::int64_t(frames.size())) break;
    cli::FrameResult r = run_frame(o, ctx.get(), frames[std::size_t(i)], cancelled_run);
    if (cancelled_run) break;
    const std::int64_t done = fetch_add(1) + 1;
    if (r.status == "failed")
      std::fprintf(stderr, "nbmc: error: frame %s (%s, rank %d): %s\n", r.label.c_str(), r.input.c_str(), rank,
                   r.error.c_str());
    meter.done(r.status == "written", r.seconds);
    if (show) std::fputs(cli::progress_line(std::size_t(done), frames.size(), r, meter).c_str(), stderr);
    mine.emplace_back(i, std::move(r));
  }
  MPI_Barrier(MPI_COMM_WORLD);
  MPI_Win_free(&win);
  int any_cancel = cancelled_run ? 1 : 0;
  MPI_Allreduce(MPI_IN_PLACE, &any_cancel, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  ctx.reset();
  // The results to rank 0, in frame order.
  std::string packed;
  auto put_str = [&](const std::string& s) {
    const std::uint64_t n = s.size();
    packed.append(reinterpret_cast<const char*>(&n), sizeof n);
    packed += s;
  };
  for (const auto& [i, r] : mine) {
    packed.append(reinterpret_cast<const char*>(&i), sizeof i);
    for (const std::string* s : {&r.label, &r.input, &r.output, &r.status, &r.error}) put_str(*s);
    const std::uint64_t nums[3] = {r.particles, r.vertices, r.triangles};
    packed.append(reinterpret_cast<const char*>(nums), sizeof nums);
    packed.append(reinterpret_cast<const char*>(&r.seconds), sizeof r.seconds);
  }
  int len = int(packed.size());
  std::vector<int> lens(static_cast<std::size_t>(size)), offs(static_cast<std::size_t>(size));
  MPI_Gather(&len, 1, MPI_INT, lens.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  int total = 0;
  for (int r = 0; r < size; ++r) {
    offs[std::size_t(r)] = total;
    total += lens[std::size_t(r)];
  }
  std::string all(root ? std::size_t(total) : 0, '\0');
  MPI_Gatherv(packed.data(), len, MPI_CHAR, root ? &all[0] : nullptr, lens.data(), offs.data(), MPI_CHAR, 0,
              MPI_COMM_WORLD);
  if (!root) return 0;
  std::vector<std::pair<std::int64_t, cli::FrameResult>> results;
  std::size_t at = 0;
  auto get = [&](void* p, std::size_t n) {
    std::memcpy(p, all.data() + at, n);
    at += n;
  };
  auto get_str = [&]() {
    std::uint64_t n = 0;
    get(&n, sizeof n);
    std::string s = all.substr(at, std::size_t(n));
    at += std::size_t(n);
    return s;
  };
  while (at < all.size()) {
    std::int64_t i = 0;
    get(&i, sizeof i);
    cli::FrameResult r;
    r.label = get_str();
    r.input = get_str();
    r.output = get_str();
    r.status = get_str();
    r.error = get_str();
    std::uint64_t nums[3];
    get(nums, sizeof nums);
    r.particles = nums[0];
    r.vertices = nums[1];
    r.triangles = nums[2];
    get(&r.seconds, sizeof r.seconds);
    results.emplace_back(i, std::move(r));
  }
  std::sort(results.begin(), results.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  if (any_cancel) {
    std::fputs("nbmc: cancelled\n", stderr);
    return 130;
  }
  cli::SequenceReport rep;
  rep.version = nbmc_version_string();
  rep.backend = name_of(kBackends, backend) + " x " + std::to_string(size) + " MPI ranks";
  rep.params = o.params;
  for (auto& [i, r] : results) rep.frames.push_back(std::move(r));
  rep.total_seconds = seconds_since(t_start);
  if (!emit_report(o, json_to_stdout, [&] { return cli::format_sequence(rep); },
                   [&] { return cli::format_sequence_json(rep); }))
    return 1;
  return rep.failed() > 0 ? 1 : 0;
}
#endif  // NBMC_CLI_MPI

} // namespace

int main(int argc, char** argv) {
  Options o;
  nbmc_params_init(&o.params);
  nbmc_context_desc_init(&o.desc);
  nbmc_params& p = o.params;
  o.method = name_of(kMethods, p.method);
  o.field = name_of(kFields, p.field);
  o.isolated = name_of(kIsolated, p.isolated);
  o.smooth_weights = name_of(kSmoothWeights, p.smooth_weighting);
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
  rec->add_option("--method", o.method,
                  "Scalar field: ssp07, zb05, sph (splashsurf's normalised SPH density, cubic spline of "
                  "support --influence-radius, surface at --iso-threshold), or yt10 (Yu & Turk 2010: the same "
                  "density with one anisotropic kernel per particle, --aniso-*; isotropic support "
                  "--influence-radius / 2)")
      ->check(CLI::IsMember(names(kMethods), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--field", o.field, "Field evaluation: on the band only, or baselines")
      ->check(CLI::IsMember(names(kFields), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--iso-threshold", p.iso_threshold,
                  "SPH, YT10: iso level of the normalised density, a fraction of the rest density in (0, 1) "
                  "(splashsurf's --surface-threshold)")
      ->capture_default_str();
  rec->add_option("--max-distance", p.max_distance,
                  "ssp07, zb05, sph: keep the surface within about this distance of the particles (the field "
                  "is raised where no particle lies within it: bridges between splashes and fillets in concave "
                  "corners are cut back); 0: off")
      ->capture_default_str();
  rec->add_option("--aniso-kr", p.aniso_kr,
                  "YT10: k_r, largest ratio of a kernel's longest to its shortest axis (>= 1; Yu & Turk: 4)")
      ->capture_default_str();
  rec->add_option("--aniso-ks", p.aniso_ks,
                  "YT10: k_s, scale of the kernel axes, normalised so that 1 gives a particle inside a uniform "
                  "fluid the isotropic kernel (> 0)")
      ->capture_default_str();
  rec->add_option("--aniso-kn", p.aniso_kn,
                  "YT10: k_n, kernel scale of a particle with few neighbours, in (0, 1.5] (Yu & Turk: 0.5)")
      ->capture_default_str();
  rec->add_option("--aniso-neighbours", p.aniso_neighbours,
                  "YT10: N_eps, more neighbours than this within --influence-radius give an anisotropic "
                  "kernel (Yu & Turk: 25)")
      ->capture_default_str();
  rec->add_option("--aniso-lambda", p.aniso_lambda,
                  "YT10: lambda, smoothing of the kernel centres towards their neighbours' weighted mean, "
                  "in [0, 1]")
      ->capture_default_str();
  rec->add_option("--isolated", o.isolated,
                  "keep: every particle makes surface; drop: clusters (particles linked closer than "
                  "--surface-radius) of fewer than --min-cluster particles make none; sphere: as drop, and "
                  "their particles are written to <output>_spheres.ply (x y z radius, no faces)")
      ->check(CLI::IsMember(names(kIsolated), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--min-cluster", p.min_cluster, "--isolated drop: smallest cluster kept (particles)")
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
  rec->add_flag("--double-positions", o.double_positions,
                "Keep the mesh's vertex positions in double precision (for coordinates far from the origin); "
                "PLY, OBJ, VTK, VTU, VTP and HDF5 store doubles, glTF rounds to float");
  rec->add_flag("--no-cleanup", o.no_cleanup,
                "Keep the raw marching-cubes mesh (no removal of degenerate and sliver triangles)");
  rec->add_option("--smooth", p.smooth_iterations,
                  "Taubin smoothing iterations after the clean-up (lambda 0.5, mu -0.53)")
      ->check(CLI::Range(0, 100000))
      ->capture_default_str();
  rec->add_option("--smooth-weights", o.smooth_weights,
                  "uniform: every vertex smoothed alike; feature: each vertex's step scaled by the particles "
                  "near it (thin sheets, filaments and droplets are not eroded; Loeschner et al. 2023)")
      ->check(CLI::IsMember(names(kSmoothWeights), CLI::ignore_case))
      ->capture_default_str();
  rec->add_option("--decimate", p.decimate_fraction,
                  "Keep this fraction of the triangles (0 < f <= 1; 1 = off): quadric-error edge collapses "
                  "that keep the mesh closed and manifold, after the clean-up and smoothing")
      ->check(CLI::Validator(
          [](std::string& s) {
            double v = 0;
            try {
              v = std::stod(s);
            } catch (...) {
            }
            return v > 0 && v <= 1 ? std::string() : std::string("must be in (0, 1]");
          },
          "FRACTION in (0, 1]"))
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
  rec->add_flag("--pieces", o.pieces,
               "Under mpirun: every rank writes its piece of the mesh (NAME_<rank>.vtp) and rank 0 a ParaView "
               "index; -o NAME.pvtp (or .pvtu)");
  rec->add_flag("--read-on-root", o.read_on_root,
               "Under mpirun: rank 0 reads the whole file and scatters it (HDF5 inputs are otherwise read by "
               "every rank, its own rows)");
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
  rec->add_option("--radius-attribute", o.radius_attribute,
                  "Per-particle radii from this scalar particle attribute (e.g. SmoothingLengths, h, radius) times "
                  "--radius-scale. A radius is a particle's r, the spacing it would have in a uniform frame: "
                  "--spacing then describes a particle of that radius (default: each frame's largest radius) and "
                  "every particle gets the other lengths scaled by its own radius; the cell size stays global "
                  "(docs/api.md, per-particle radii)")
      ->option_text("NAME");
  rec->add_option("--radius-scale", o.radius_scale,
                  "Factor from the --radius-attribute values to radii (e.g. SWIFT smoothing lengths to spacings)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  rec->add_option("--frames", o.frames,
                  "Sequences: only frames a to b (inclusive), every step-th; IN with {} or a multi-step H5Part file")
      ->option_text("A:B[:STEP]");
  rec->add_flag("--resume", o.resume, "Sequences: skip frames whose output exists already");
  rec->add_flag("--sequential-io", o.sequential_io,
                "Sequences: read and write each frame between reconstructions (default: the next frame is read "
                "and the previous one written while a frame is reconstructed; always so with HDF5 files)");
  rec->add_option("--contexts", o.contexts,
                  "Sequences: frames reconstructed at once, each in its own context, so that one frame's GPU "
                  "stages run while the previous frame is post-processed on the host (default: 2 with CUDA, "
                  "1 otherwise or with --memory-budget; 1 with --sequential-io or HDF5 files)")
      ->check(CLI::Range(0, 2));
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

  if (sp->count() == 0 && pr->count() == 0 && o.radius_attribute.empty()) {
    std::fputs("nbmc: error: one of --spacing, --particle-radius or --radius-attribute is required\n"
               "Run with --help for more information.\n",
               stderr);
    return 2;
  }
  o.spacing_from_radii = sp->count() == 0 && pr->count() == 0;
  p.spacing = sp->count() > 0 ? o.spacing : 2.0 * o.particle_radius;
  p.method = value_of(kMethods, o.method);
  p.field = value_of(kFields, o.field);
  p.isolated = value_of(kIsolated, o.isolated);
  p.smooth_weighting = value_of(kSmoothWeights, o.smooth_weights);
  o.desc.backend = value_of(kBackends, o.backend);
  if (o.no_normals) p.compute_normals = 0;
  if (o.double_positions) p.double_positions = 1;
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
#if defined(NBMC_CLI_MPI)
    if (launched_by_mpi()) {
      int rank = 0, size = 1, code = 0;
      MPI_Init(&argc, &argv);
      MPI_Comm_rank(MPI_COMM_WORLD, &rank);
      MPI_Comm_size(MPI_COMM_WORLD, &size);
      if (rank != 0) o.quiet = true;
      nbmc::cli::install_interrupt_handler();
      try {
        if (size == 1 && !o.pieces)
          code = plan.is_sequence ? reconstruct_sequence(o, plan.frames) : (o.step = plan.step, reconstruct(o));
        else if (plan.is_sequence)
          code = reconstruct_sequence_mpi(o, plan.frames, rank, size);
        else
          code = (o.step = plan.step, reconstruct_mpi(o, rank, size, o.pieces));
      } catch (const std::exception& e) {
        std::fprintf(stderr, "nbmc: error (rank %d): %s\n", rank, e.what());
        MPI_Abort(MPI_COMM_WORLD, 1);  // a rank that cannot go on must not leave the others waiting
      }
      nbmc_kokkos_finalize();
      MPI_Finalize();
      return code;
    }
#endif
    if (o.pieces) {
      std::fputs("nbmc: error: --pieces needs several MPI ranks (mpirun -n P nbmc reconstruct ...)\n", stderr);
      return 2;
    }
    if (plan.is_sequence) {
      if (overlapped_io(o, plan.frames)) run_again_with_passive_openmp(argv);
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
