// SPDX-License-Identifier: MIT
// nbmc benchmark: per-stage times, peak memory and counts for one frame, and
// the comparison table of the paper's Tables 3/4 (scatter, dense gather,
// narrow band; 1 thread and all threads; two cell sizes).
//
//   nbmc_bench FRAME.xyz --spacing R [--cell-size C] [--threads N]
//              [--field narrow-band|dense|scatter] [--method ssp07|zb05|sph|yt10] [--backend B]
//              [--repeat K] [--device-resident] [--tile N] [--subdomains auto|NxMxK]
//              [--memory-budget MIB] [--influence-radius K] [--surface-radius K]
//              [--no-cleanup] [--max-distance D]
//
// --influence-radius / --surface-radius: in units of the spacing (defaults 4
// and 2, nbmc_params_init's).
// --no-cleanup: the raw marching-cubes mesh (nbmc_params.cleanup = 0).
// --max-distance D: the distance guard in units of the spacing (0: off).
// --tile N: the frame repeated N x N x N times with gaps of 10% of its extent
// (N = 2: the 1.65 M frame becomes 13.2 M particles, N = 4: 106 M), built in
// memory. --subdomains / --memory-budget: nbmc_context_set_subdomains and the
// context's budget (in MiB), for the out-of-core runs.
//
// --device-resident (CUDA builds): the particles are uploaded from a
// cudaMalloc'd array (nbmc_context_set_particles_device_f32) and the mesh is
// left in device memory (NBMC_MEMORY_DEVICE), as a GPU solver would use it.
// set_particles= is the wall time of the upload call itself (host: validation
// and copy; device: the same on the GPU), which the stage times do not include;
// set_particles_again= the same upload once more after the runs (a
// sequence's next frame: the context's buffer is reused).
//   nbmc_bench FRAME.xyz --spacing R --table [--cell-sizes 1,0.5] [--skip-scatter]
//              [--max-threads N]
//
// In --table mode every configuration runs in a child process of its own
// (this program with --one), so that the reported peak RSS is that run's.
#include "nbmc.h"

#if defined(NBMC_BENCH_CUDA)
#include <cuda_runtime.h>
#endif

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

struct Options {
  std::string file;
  double spacing = 0, cell = 0.5, influence = 0, surface = 0;
  int threads = 0, method = NBMC_METHOD_SSP07, field = NBMC_FIELD_NARROW_BAND, backend = NBMC_BACKEND_AUTO;
  bool table = false, one = false, skip_scatter = false;
  std::vector<double> cells{1.0, 0.5};
  int max_threads = 0;
  int repeat = 1;
  bool device_resident = false;
  int tile = 1;
  int sub[3] = {1, 1, 1};
  double budget_mib = 0;
  bool no_cleanup = false;
  double max_distance = -1;  // < 0: nbmc_params_init's
};

[[noreturn]] void usage(const char* msg) {
  std::fprintf(stderr, "nbmc_bench: %s\nusage: nbmc_bench FRAME.xyz --spacing R [--cell-size C] [--threads N] "
                       "[--field narrow-band|dense|scatter] [--method ssp07|zb05|sph|yt10] [--backend auto|serial|openmp|cuda] "
                       "[--repeat K] [--device-resident] [--no-cleanup] [--max-distance D] | --table [--cell-sizes 1,0.5] [--skip-scatter] [--max-threads N]\n", msg);
  std::exit(2);
}

int field_of(const std::string& s) {
  if (s == "narrow-band") return NBMC_FIELD_NARROW_BAND;
  if (s == "dense") return NBMC_FIELD_DENSE;
  if (s == "scatter") return NBMC_FIELD_SCATTER;
  usage("unknown --field");
}
const char* method_name(int m) {
  return m == NBMC_METHOD_ZB05 ? "zb05" : m == NBMC_METHOD_SPH ? "sph" : m == NBMC_METHOD_YT10 ? "yt10" : "ssp07";
}

const char* field_name(int f) {
  return f == NBMC_FIELD_NARROW_BAND ? "narrow-band" : f == NBMC_FIELD_DENSE ? "dense" : "scatter";
}

std::vector<float> read_xyz(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) usage(("cannot open " + path).c_str());
  f.seekg(0, std::ios::end);
  const std::size_t bytes = std::size_t(f.tellg());
  if (bytes % 12) usage((path + ": size is not a multiple of 12 bytes").c_str());
  f.seekg(0);
  std::vector<float> v(bytes / 4);
  f.read(reinterpret_cast<char*>(v.data()), std::streamsize(bytes));
  return v;
}

double peak_rss_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;
}

// The frame repeated n x n x n times, 10% of its extent apart.
std::vector<float> tiled(const std::vector<float>& p, int n) {
  if (n <= 1) return p;
  float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
  for (std::size_t i = 0; i + 2 < p.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], p[i + std::size_t(a)]);
      hi[a] = std::max(hi[a], p[i + std::size_t(a)]);
    }
  std::vector<float> out;
  out.reserve(p.size() * std::size_t(n) * std::size_t(n) * std::size_t(n));
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const float off[3] = {1.1f * float(x) * (hi[0] - lo[0]), 1.1f * float(y) * (hi[1] - lo[1]),
                              1.1f * float(z) * (hi[2] - lo[2])};
        for (std::size_t i = 0; i + 2 < p.size(); i += 3)
          for (int a = 0; a < 3; ++a) out.push_back(p[i + std::size_t(a)] + off[a]);
      }
  return out;
}

// One reconstruction; prints a single "RESULT key=value ..." line.
int run_one(const Options& o) {
  const std::vector<float> p = tiled(read_xyz(o.file), o.tile);
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = o.backend;
  d.num_threads = o.threads;
  nbmc_context* ctx = nullptr;
  if (nbmc_context_create(&d, &ctx) != NBMC_OK) {
    std::fprintf(stderr, "nbmc_bench: %s\n", nbmc_context_last_error(nullptr));
    return 1;
  }
  if (o.sub[0] != 1 || o.sub[1] != 1 || o.sub[2] != 1) nbmc_context_set_subdomains(ctx, o.sub[0], o.sub[1], o.sub[2]);
  if (o.budget_mib > 0) nbmc_context_set_memory_budget(ctx, std::uint64_t(o.budget_mib * 1048576.0));
  nbmc_params prm;
  nbmc_params_init(&prm);
  prm.spacing = o.spacing;
  prm.cell_size = o.cell;
  if (o.influence > 0) prm.influence_radius = o.influence;
  if (o.surface > 0) prm.surface_radius = o.surface;
  if (o.no_cleanup) prm.cleanup = 0;
  if (o.max_distance >= 0) prm.max_distance = o.max_distance;
  prm.method = o.method;
  prm.field = o.field;
  auto t_up = std::chrono::steady_clock::now();
  int32_t st = NBMC_OK;
  void* device_copy = nullptr;
  if (o.device_resident) {
#if defined(NBMC_BENCH_CUDA)
    if (cudaMalloc(&device_copy, p.size() * sizeof(float)) != cudaSuccess ||
        cudaMemcpy(device_copy, p.data(), p.size() * sizeof(float), cudaMemcpyHostToDevice) != cudaSuccess)
      usage("cudaMalloc/cudaMemcpy failed");
    t_up = std::chrono::steady_clock::now();  // the solver's own copy is not nbmc's time
    st = nbmc_context_set_particles_device_f32(ctx, static_cast<const float*>(device_copy), p.size() / 3, 0);
    if (st == NBMC_OK) st = nbmc_context_set_mesh_memory(ctx, NBMC_MEMORY_DEVICE);
#else
    usage("--device-resident needs a CUDA build");
#endif
  } else {
    st = nbmc_context_set_particles_f32(ctx, p.data(), p.size() / 3, 0);
  }
  double upload_call = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_up).count();
  nbmc_stats s;
  nbmc_stats_init(&s);
  double best = 1e300;
  for (int k = 0; k < o.repeat && st == NBMC_OK; ++k) {
    nbmc_mesh* mesh = nullptr;
    st = nbmc_context_reconstruct(ctx, &prm, &mesh);
    nbmc_mesh_destroy(mesh);
    if (st == NBMC_OK) {
      nbmc_stats cur;
      nbmc_stats_init(&cur);
      nbmc_context_stats(ctx, &cur);
      if (cur.total_seconds < best) {
        best = cur.total_seconds;
        s = cur;
      }
    }
  }
#if defined(NBMC_BENCH_CUDA)
  if (device_copy) cudaFree(device_copy);
#endif
  // The same upload again, as a sequence's next frame makes it: the
  // context's host buffer (pinned on CUDA contexts) is reused.
  double upload_again = 0;
  if (st == NBMC_OK && !o.device_resident) {
    const auto t_again = std::chrono::steady_clock::now();
    st = nbmc_context_set_particles_f32(ctx, p.data(), p.size() / 3, 0);
    upload_again = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_again).count();
  }
  if (st != NBMC_OK) {
    std::fprintf(stderr, "nbmc_bench: %s: %s\n", nbmc_status_string(st), nbmc_context_last_error(ctx));
    nbmc_context_destroy(ctx);
    return 1;
  }
  int32_t backend = 0;
  nbmc_context_backend(ctx, &backend);
  std::printf("RESULT field=%s threads=%d backend=%d cell=%g particles=%llu surface=%llu band=%llu blocks=%llu "
              "grid=%llux%llux%llu cells=%llu vertices=%llu triangles=%llu evals=%llu peak_nbmc_mib=%.1f "
              "peak_rss_mib=%.1f total=%.4f",
              field_name(o.field), o.threads, backend, o.cell, (unsigned long long)s.particle_count,
              (unsigned long long)s.surface_particle_count, (unsigned long long)s.band_vertex_count,
              (unsigned long long)s.band_block_count, (unsigned long long)s.grid_dims[0],
              (unsigned long long)s.grid_dims[1], (unsigned long long)s.grid_dims[2],
              (unsigned long long)s.triangulated_cell_count, (unsigned long long)s.vertex_count,
              (unsigned long long)s.triangle_count, (unsigned long long)s.neighbour_evaluations,
              double(s.peak_memory_bytes) / 1048576.0, peak_rss_mib(), s.total_seconds);
  for (int i = 0; i < NBMC_STAGE_COUNT; ++i) std::printf(" t%d=%.4f", i, s.stage_seconds[i]);
  std::printf(" postprocess=%.4f", s.stage_seconds[NBMC_STAGE_POSTPROCESS]);
  nbmc_subdomain_stats sub;
  nbmc_subdomain_stats_init(&sub);
  if (nbmc_context_subdomain_stats(ctx, &sub) == NBMC_OK && sub.count)
    std::printf(" subdomains=%dx%dx%d ghosts=%llu reruns=%llu stitch=%.4f", sub.parts[0], sub.parts[1], sub.parts[2],
                (unsigned long long)sub.ghost_particles, (unsigned long long)sub.reruns, sub.stitch_seconds);
  std::printf(" set_particles=%.4f", upload_call);
  if (o.device_resident)
    std::printf(" device_resident=1\n");
  else
    std::printf(" set_particles_again=%.4f\n", upload_again);
  nbmc_context_destroy(ctx);
  return 0;
}

double value(const std::string& line, const std::string& key) {
  const std::size_t at = line.find(" " + key + "=");
  if (at == std::string::npos) return -1;
  return std::atof(line.c_str() + at + key.size() + 2);
}

std::string self_path() {
  char self[4096];
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  if (n <= 0) usage("cannot find this program's path in /proc/self/exe");
  self[n] = 0;
  return self;
}

// Runs one configuration in a child process; returns its RESULT line.
std::string child(const Options& o, int field, int threads, double cell) {
  std::ostringstream cmd;
  cmd << "'" << self_path() << "' '" << o.file << "' --one --spacing " << o.spacing << " --cell-size " << cell
      << " --threads " << threads << " --field " << field_name(field) << " --method "
      << method_name(o.method) << " --backend "
      << (o.backend == NBMC_BACKEND_SERIAL   ? "serial"
          : o.backend == NBMC_BACKEND_CUDA   ? "cuda"
          : o.backend == NBMC_BACKEND_OPENMP ? "openmp"
                                             : "auto");
  FILE* f = popen(cmd.str().c_str(), "r");
  std::string out;
  char buf[4096];
  while (f && std::fgets(buf, sizeof buf, f))
    if (std::strncmp(buf, "RESULT", 6) == 0) out = buf;
  if (f) pclose(f);
  return out;
}

int run_table(const Options& o) {
  const int all = o.max_threads > 0 ? o.max_threads : int(std::max(1u, std::thread::hardware_concurrency()));
  std::printf("frame: %s, spacing %g, influence radius 4r, method %s, %d hardware threads\n\n", o.file.c_str(),
              o.spacing, method_name(o.method), all);
  for (double cell : o.cells) {
    std::printf("### cell size %g r\n\n", cell);
    std::printf("| method | threads | t_sf [s] | t_tri [s] | total [s] | nbmc peak [MiB] | process peak RSS [MiB] | "
                "field vertices | triangles |\n|---|---|---|---|---|---|---|---|---|\n");
    struct Cfg {
      int field, threads;
    };
    std::vector<Cfg> cfgs;
    if (!o.skip_scatter) cfgs.push_back({NBMC_FIELD_SCATTER, 1});
    cfgs.push_back({NBMC_FIELD_DENSE, 1});
    if (all > 1) cfgs.push_back({NBMC_FIELD_DENSE, all});
    cfgs.push_back({NBMC_FIELD_NARROW_BAND, 1});
    if (all > 1) cfgs.push_back({NBMC_FIELD_NARROW_BAND, all});
    for (const Cfg& c : cfgs) {
      const std::string r = child(o, c.field, c.threads, cell);
      if (r.empty()) {
        std::printf("| %s | %d | failed | | | | | | |\n", field_name(c.field), c.threads);
        continue;
      }
      const double t_sf = value(r, "t4"), t_tri = value(r, "t5");
      std::printf("| %s | %d | %.3f | %.3f | %.3f | %.0f | %.0f | %.0f | %.0f |\n", field_name(c.field), c.threads,
                  t_sf, t_tri, value(r, "total"), value(r, "peak_nbmc_mib"), value(r, "peak_rss_mib"),
                  value(r, "band"), value(r, "triangles"));
      std::fflush(stdout);
      std::fprintf(stderr, "%s", r.c_str());
    }
    std::printf("\n");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) usage(("missing value after " + a).c_str());
      return argv[++i];
    };
    if (a == "--spacing") o.spacing = std::atof(next().c_str());
    else if (a == "--cell-size") o.cell = std::atof(next().c_str());
    else if (a == "--influence-radius") o.influence = std::atof(next().c_str());
    else if (a == "--surface-radius") o.surface = std::atof(next().c_str());
    else if (a == "--threads") o.threads = std::atoi(next().c_str());
    else if (a == "--max-threads") o.max_threads = std::atoi(next().c_str());
    else if (a == "--repeat") o.repeat = std::max(1, std::atoi(next().c_str()));
    else if (a == "--device-resident") o.device_resident = true;
    else if (a == "--no-cleanup") o.no_cleanup = true;
    else if (a == "--max-distance") o.max_distance = std::atof(next().c_str());
    else if (a == "--tile") o.tile = std::max(1, std::atoi(next().c_str()));
    else if (a == "--memory-budget") o.budget_mib = std::atof(next().c_str());
    else if (a == "--subdomains") {
      const std::string v = next();
      if (v == "auto") o.sub[0] = NBMC_SUBDOMAINS_AUTO, o.sub[1] = o.sub[2] = 0;
      else if (std::sscanf(v.c_str(), "%dx%dx%d", &o.sub[0], &o.sub[1], &o.sub[2]) != 3) usage("--subdomains NxMxK|auto");
    }
    else if (a == "--field") o.field = field_of(next());
    else if (a == "--method") {
      const std::string m = next();
      o.method = m == "zb05"   ? NBMC_METHOD_ZB05
                 : m == "sph"  ? NBMC_METHOD_SPH
                 : m == "yt10" ? NBMC_METHOD_YT10
                               : NBMC_METHOD_SSP07;
    }
    else if (a == "--backend") {
      const std::string b = next();
      o.backend = b == "serial" ? NBMC_BACKEND_SERIAL : b == "openmp" ? NBMC_BACKEND_OPENMP : b == "cuda" ? NBMC_BACKEND_CUDA : NBMC_BACKEND_AUTO;
    } else if (a == "--table") o.table = true;
    else if (a == "--one") o.one = true;
    else if (a == "--skip-scatter") o.skip_scatter = true;
    else if (a == "--cell-sizes") {
      o.cells.clear();
      std::stringstream ss(next());
      std::string t;
      while (std::getline(ss, t, ',')) o.cells.push_back(std::atof(t.c_str()));
    } else if (a[0] == '-') usage(("unknown option " + a).c_str());
    else o.file = a;
  }
  if (o.file.empty() || !(o.spacing > 0)) usage("a frame and --spacing are required");
  if (o.table) return run_table(o);
  return run_one(o);
}
