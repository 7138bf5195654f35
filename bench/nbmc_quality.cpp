// SPDX-License-Identifier: MIT
// nbmc surface-quality benchmark (issue #11): for one frame, every method,
// cell size and post-processing variant asked for, the topology and quality
// figures of the mesh, through the public C API only.
//
//   nbmc_quality FRAME.xyz --spacing R [--methods ssp07,zb05,sph,yt10]
//                [--cells 1,0.5] [--variants raw,clean,smooth] [--smooth N]
//                [--threads N] [--label NAME] [--markdown FILE]
//   nbmc_quality --single-particle --spacing R ...   (one particle at the origin)
//
// Variants: raw = the marching-cubes mesh (cleanup 0, smoothing 0); clean =
// the defaults (cleanup on, no smoothing); smooth = cleanup on and
// smooth_iterations N (default 10, Taubin lambda|mu, docs/api.md).
//
// The frame is loaded with nbmc_context_load_particles (nbmc's own reader);
// the vertex-to-particle distances need the positions themselves, which the
// tool reads from the .xyz file (raw little-endian float32 triples) and
// checks against the count nbmc loaded. Other formats: those columns are "-".
//
// Per configuration one line "QUALITY key=value ..." on stdout:
//  closed/manifold/oriented, degenerate, slivers, components, min_angle, volume
//    from nbmc_mesh_check;
//  below1deg: triangles with an angle below 1 degree, degenerate ones included
//    (a zero-length side or a zero area counts);
//  dihedral_mean / dihedral_p99: angle in degrees between the normals of the
//    two triangles of every edge that has exactly two non-degenerate ones
//    (0 = flat);
//  dist_p50 / dist_p99 / dist_max: distance from each mesh vertex to its
//    nearest particle, in units of r; beyond2r: share of vertices farther
//    than 2 r (a uniform grid of cell r over the particles, searched ring by
//    ring until no closer particle can exist);
//  volume_ratio: enclosed volume / (N r^3);
//  seconds: nbmc_stats.total_seconds (the reconstruction, clean-up and
//    smoothing; not the file read, not this tool's analysis);
//  raw_triangles: nbmc_stats.raw_triangle_count (before the clean-up).
// A method this build of nbmc does not have gives "status=not-available".
// With --markdown FILE the rows are appended to FILE as a Markdown table (the
// header is written when FILE is empty or new).
#include "nbmc.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace {

struct Options {
  std::string file;
  bool single_particle = false;
  double spacing = 0;
  std::vector<std::string> methods{"ssp07", "zb05", "sph", "yt10"};
  std::vector<double> cells{1.0, 0.5};
  std::vector<std::string> variants{"raw", "clean", "smooth"};
  int smooth = 10;
  int threads = 2;
  std::string label;
  std::string markdown;
};

[[noreturn]] void usage(const char* msg) {
  std::fprintf(stderr,
               "nbmc_quality: %s\nusage: nbmc_quality FRAME.xyz|--single-particle --spacing R "
               "[--methods ssp07,zb05,sph,yt10] [--cells 1,0.5] [--variants raw,clean,smooth] [--smooth N] "
               "[--threads N] [--label NAME] [--markdown FILE]\n",
               msg);
  std::exit(2);
}

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

double to_double(const std::string& s, const char* what) {
  char* end = nullptr;
  double v = std::strtod(s.c_str(), &end);
  if (s.empty() || *end != '\0' || !std::isfinite(v)) usage(what);
  return v;
}

Options parse(int argc, char** argv) {
  Options o;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto next = [&](const char* what) -> std::string {
      if (i + 1 >= argc) usage(what);
      return argv[++i];
    };
    if (a == "--spacing") o.spacing = to_double(next("--spacing needs a value"), "bad --spacing");
    else if (a == "--single-particle") o.single_particle = true;
    else if (a == "--methods") o.methods = split(next("--methods needs a list"));
    else if (a == "--cells") {
      o.cells.clear();
      for (const auto& c : split(next("--cells needs a list"))) o.cells.push_back(to_double(c, "bad --cells"));
    } else if (a == "--variants") o.variants = split(next("--variants needs a list"));
    else if (a == "--smooth") o.smooth = static_cast<int>(to_double(next("--smooth needs a value"), "bad --smooth"));
    else if (a == "--threads") o.threads = static_cast<int>(to_double(next("--threads needs a value"), "bad --threads"));
    else if (a == "--label") o.label = next("--label needs a name");
    else if (a == "--markdown") o.markdown = next("--markdown needs a file");
    else if (!a.empty() && a[0] == '-') usage(("unknown option " + a).c_str());
    else if (o.file.empty()) o.file = a;
    else usage("more than one frame");
  }
  if (o.file.empty() == !o.single_particle) usage("give one frame or --single-particle");
  if (!(o.spacing > 0)) usage("--spacing must be > 0");
  if (o.threads < 1) o.threads = 1;
  if (o.smooth < 0) usage("--smooth must be >= 0");
  for (double c : o.cells)
    if (!(c > 0)) usage("cells must be > 0");
  for (const auto& v : o.variants)
    if (v != "raw" && v != "clean" && v != "smooth") usage("variants are raw, clean, smooth");
  if (o.label.empty()) {
    if (o.single_particle) o.label = "single-particle";
    else {
      std::string base = o.file.substr(o.file.find_last_of('/') + 1);
      o.label = base.substr(0, base.find_last_of('.'));
    }
  }
  return o;
}

// Method name -> NBMC_METHOD_*, or -1 when this build of nbmc lacks it.
int method_id(const std::string& m) {
  if (m == "ssp07") return NBMC_METHOD_SSP07;
  if (m == "zb05") return NBMC_METHOD_ZB05;
#ifdef NBMC_METHOD_SPH
  if (m == "sph") return NBMC_METHOD_SPH;
#endif
#ifdef NBMC_METHOD_YT10
  if (m == "yt10") return NBMC_METHOD_YT10;
#endif
  return -1;  // sph and yt10 only where the header has them
}

bool ends_with(const std::string& s, const std::string& tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

// Raw float32 triples; empty on failure.
std::vector<float> read_xyz(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  in.seekg(0, std::ios::end);
  std::streamoff bytes = in.tellg();
  in.seekg(0);
  if (bytes <= 0 || bytes % 12 != 0) return {};
  std::vector<float> xyz(static_cast<size_t>(bytes) / 4);
  in.read(reinterpret_cast<char*>(xyz.data()), bytes);
  if (!in) return {};
  return xyz;
}

// ----------------------------------------------------------- nearest particle
// A uniform grid of cell h over the particles' bounding box (counting sort of
// the particle indices by cell). Query: the rings of cells around the query's
// cell (clamped into the grid), k = 0, 1, ...; after ring k every particle not
// yet seen lies at least k * h away, so the search stops once the best
// distance found is at most that.
class NearestGrid {
 public:
  NearestGrid(const std::vector<float>& xyz, double h) : xyz_(xyz) {
    const size_t n = xyz.size() / 3;
    for (int a = 0; a < 3; ++a) {
      lo_[a] = std::numeric_limits<double>::max();
      double hi = -lo_[a];
      for (size_t i = 0; i < n; ++i) {
        lo_[a] = std::min(lo_[a], double(xyz[3 * i + a]));
        hi = std::max(hi, double(xyz[3 * i + a]));
      }
      hi_[a] = hi;
    }
    // Keep the grid at most ~64 M cells: a frame with far outliers gets larger cells.
    h_ = h;
    for (;;) {
      uint64_t total = 1;
      for (int a = 0; a < 3; ++a) {
        dims_[a] = static_cast<int64_t>(std::floor((hi_[a] - lo_[a]) / h_)) + 1;
        total *= static_cast<uint64_t>(dims_[a]);
      }
      if (total <= (uint64_t(1) << 26)) break;
      h_ *= 1.5;
    }
    const size_t cells = static_cast<size_t>(dims_[0] * dims_[1] * dims_[2]);
    start_.assign(cells + 1, 0);
    std::vector<uint32_t> cell_of(n);
    for (size_t i = 0; i < n; ++i) {
      int64_t c[3];
      for (int a = 0; a < 3; ++a) c[a] = clamp_cell(a, xyz[3 * i + a]);
      cell_of[i] = static_cast<uint32_t>((c[2] * dims_[1] + c[1]) * dims_[0] + c[0]);
      ++start_[cell_of[i] + 1];
    }
    for (size_t c = 0; c < cells; ++c) start_[c + 1] += start_[c];
    index_.resize(n);
    std::vector<uint32_t> fill(start_.begin(), start_.end() - 1);
    for (size_t i = 0; i < n; ++i) index_[fill[cell_of[i]]++] = static_cast<uint32_t>(i);
  }

  double nearest(const float* p) const {
    int64_t c[3];
    for (int a = 0; a < 3; ++a) c[a] = clamp_cell(a, p[a]);
    double best2 = std::numeric_limits<double>::max();
    const int64_t kmax = std::max(dims_[0], std::max(dims_[1], dims_[2]));
    for (int64_t k = 0; k <= kmax; ++k) {
      for (int64_t z = c[2] - k; z <= c[2] + k; ++z) {
        if (z < 0 || z >= dims_[2]) continue;
        for (int64_t y = c[1] - k; y <= c[1] + k; ++y) {
          if (y < 0 || y >= dims_[1]) continue;
          const bool face = (z == c[2] - k || z == c[2] + k || y == c[1] - k || y == c[1] + k);
          const int64_t step = face ? 1 : 2 * k;  // inner rows: only the two end cells
          for (int64_t x = c[0] - k; x <= c[0] + k; x += (step == 0 ? 1 : step)) {
            if (x < 0 || x >= dims_[0]) continue;
            const size_t cell = static_cast<size_t>((z * dims_[1] + y) * dims_[0] + x);
            for (uint32_t j = start_[cell]; j < start_[cell + 1]; ++j) {
              const float* q = &xyz_[3 * size_t(index_[j])];
              const double dx = double(p[0]) - q[0], dy = double(p[1]) - q[1], dz = double(p[2]) - q[2];
              best2 = std::min(best2, dx * dx + dy * dy + dz * dz);
            }
          }
        }
      }
      const double bound = double(k) * h_;
      if (best2 <= bound * bound) break;
    }
    return std::sqrt(best2);
  }

 private:
  int64_t clamp_cell(int a, float v) const {
    int64_t c = static_cast<int64_t>(std::floor((double(v) - lo_[a]) / h_));
    return std::min<int64_t>(std::max<int64_t>(c, 0), dims_[a] - 1);
  }
  const std::vector<float>& xyz_;
  double lo_[3], hi_[3], h_;
  int64_t dims_[3];
  std::vector<uint32_t> start_, index_;
};

double percentile(std::vector<double>& v, double q) {  // nearest-rank, v reordered
  if (v.empty()) return 0;
  size_t k = static_cast<size_t>(std::ceil(q * double(v.size())));
  k = std::min(v.size() - 1, k == 0 ? 0 : k - 1);
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

struct Metrics {
  uint64_t below1deg = 0;
  double dihedral_mean = 0, dihedral_p99 = 0;
  uint64_t dihedral_edges = 0;
  bool have_dist = false;
  double dist_p50 = 0, dist_p99 = 0, dist_max = 0, beyond2r = 0;
};

void face_normal(const float* P, const uint32_t* t, double n[3], double* len) {
  const float *a = P + 3 * size_t(t[0]), *b = P + 3 * size_t(t[1]), *c = P + 3 * size_t(t[2]);
  const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
  const double w[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
  n[0] = u[1] * w[2] - u[2] * w[1];
  n[1] = u[2] * w[0] - u[0] * w[2];
  n[2] = u[0] * w[1] - u[1] * w[0];
  *len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
}

// Smallest angle of triangle t in degrees (0 for a zero-length side).
double min_angle(const float* P, const uint32_t* t) {
  double best = 180;
  for (int k = 0; k < 3; ++k) {
    const float *a = P + 3 * size_t(t[k]), *b = P + 3 * size_t(t[(k + 1) % 3]), *c = P + 3 * size_t(t[(k + 2) % 3]);
    const double u[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
    const double w[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
    const double lu = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    const double lw = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (lu == 0 || lw == 0) return 0;
    const double cr[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]};
    const double s = std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
    const double d = u[0] * w[0] + u[1] * w[1] + u[2] * w[2];
    best = std::min(best, std::atan2(s, d) * 180.0 / M_PI);
  }
  return best;
}

Metrics analyse(const float* P, uint64_t nv, const uint32_t* T, uint64_t nt, const std::vector<float>* particles,
                double spacing, int threads) {
  Metrics m;
  // Triangles with an angle below 1 degree.
  for (uint64_t t = 0; t < nt; ++t)
    if (min_angle(P, T + 3 * t) < 1.0) ++m.below1deg;

  // Dihedral angles: edges as (min, max, triangle), sorted; pairs of equal keys.
  struct E {
    uint64_t key;
    uint32_t tri;
  };
  std::vector<E> edges;
  edges.reserve(3 * nt);
  for (uint64_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      uint64_t a = T[3 * t + k], b = T[3 * t + (k + 1) % 3];
      if (a > b) std::swap(a, b);
      edges.push_back({(a << 32) | b, static_cast<uint32_t>(t)});
    }
  std::sort(edges.begin(), edges.end(), [](const E& x, const E& y) {
    return x.key != y.key ? x.key < y.key : x.tri < y.tri;
  });
  std::vector<double> dihedral;
  dihedral.reserve(edges.size() / 2);
  double sum = 0;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    if (j - i == 2) {
      double n0[3], n1[3], l0, l1;
      face_normal(P, T + 3 * size_t(edges[i].tri), n0, &l0);
      face_normal(P, T + 3 * size_t(edges[i + 1].tri), n1, &l1);
      if (l0 > 0 && l1 > 0) {
        double c = (n0[0] * n1[0] + n0[1] * n1[1] + n0[2] * n1[2]) / (l0 * l1);
        c = std::min(1.0, std::max(-1.0, c));
        const double ang = std::acos(c) * 180.0 / M_PI;
        dihedral.push_back(ang);
        sum += ang;
      }
    }
    i = j;
  }
  m.dihedral_edges = dihedral.size();
  if (!dihedral.empty()) {
    m.dihedral_mean = sum / double(dihedral.size());
    m.dihedral_p99 = percentile(dihedral, 0.99);
  }

  // Vertex-to-nearest-particle distances, in r.
  if (particles && !particles->empty() && nv > 0) {
    NearestGrid grid(*particles, spacing);
    std::vector<double> dist(nv);
    const int nth = std::max(1, std::min<int>(threads, 64));
    std::vector<std::thread> pool;
    for (int w = 0; w < nth; ++w)
      pool.emplace_back([&, w] {
        for (uint64_t v = uint64_t(w); v < nv; v += uint64_t(nth)) dist[v] = grid.nearest(P + 3 * v) / spacing;
      });
    for (auto& th : pool) th.join();
    uint64_t beyond = 0;
    double mx = 0;
    for (double d : dist) {
      if (d > 2.0) ++beyond;
      mx = std::max(mx, d);
    }
    m.have_dist = true;
    m.dist_max = mx;
    m.beyond2r = double(beyond) / double(nv);
    m.dist_p99 = percentile(dist, 0.99);
    m.dist_p50 = percentile(dist, 0.50);
  }
  return m;
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

const char* kMarkdownHeader =
    "| frame | method | cell [r] | variant | triangles | raw triangles | closed/manifold/oriented | degenerate | "
    "< 1° | min angle [°] | dihedral mean [°] | dihedral p99 [°] | dist p50 [r] | dist p99 [r] | dist max [r] | "
    "beyond 2r | V/(N r³) | components | time [s] |\n"
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";

}  // namespace

int main(int argc, char** argv) {
  Options o = parse(argc, argv);

  nbmc_context_desc desc;
  nbmc_context_desc_init(&desc);
  desc.num_threads = o.threads;
  nbmc_context* ctx = nullptr;
  if (nbmc_context_create(&desc, &ctx) != NBMC_OK) {
    std::fprintf(stderr, "nbmc_quality: %s\n", nbmc_context_last_error(nullptr));
    return 1;
  }

  std::vector<float> particles;
  uint64_t count = 0;
  if (o.single_particle) {
    particles = {0.f, 0.f, 0.f};
    count = 1;
    if (nbmc_context_set_particles_f32(ctx, particles.data(), 1, 0) != NBMC_OK) {
      std::fprintf(stderr, "nbmc_quality: %s\n", nbmc_context_last_error(ctx));
      return 1;
    }
  } else {
    if (nbmc_context_load_particles(ctx, o.file.c_str(), nullptr, &count) != NBMC_OK) {
      std::fprintf(stderr, "nbmc_quality: %s\n", nbmc_context_last_error(ctx));
      return 1;
    }
    if (ends_with(o.file, ".xyz")) {
      particles = read_xyz(o.file);
      if (particles.size() != 3 * count) {
        std::fprintf(stderr, "nbmc_quality: %s: nbmc loaded %llu particles, the raw read %zu\n", o.file.c_str(),
                     (unsigned long long)count, particles.size() / 3);
        return 1;
      }
    }
  }

  std::string rows;
  int failures = 0;
  for (const auto& mname : o.methods) {
    const int method = method_id(mname);
    for (double cell : o.cells)
      for (const auto& variant : o.variants) {
        const std::string vname = variant == "smooth" ? "smooth" + std::to_string(o.smooth) : variant;
        char head[256];
        std::snprintf(head, sizeof head, "frame=%s method=%s cell=%g variant=%s", o.label.c_str(), mname.c_str(), cell,
                      vname.c_str());
        if (method < 0) {
          std::printf("QUALITY %s status=not-available\n", head);
          rows += "| " + o.label + " | " + mname + " | " + fmt("%g", cell) + " | " + vname +
                  " | not available in nbmc |||||||||||||||\n";
          continue;
        }
        nbmc_params p;
        nbmc_params_init(&p);
        p.spacing = o.spacing;
        p.cell_size = cell;
        p.method = method;
        p.cleanup = variant == "raw" ? 0 : 1;
        p.smooth_iterations = variant == "smooth" ? o.smooth : 0;
        nbmc_mesh* mesh = nullptr;
        const int32_t st = nbmc_context_reconstruct(ctx, &p, &mesh);
        if (st != NBMC_OK) {
          std::printf("QUALITY %s status=error message=\"%s\"\n", head, nbmc_context_last_error(ctx));
          ++failures;
          continue;
        }
        nbmc_stats s;
        nbmc_stats_init(&s);
        nbmc_context_stats(ctx, &s);
        nbmc_mesh_check_result c;
        nbmc_mesh_check_result_init(&c);
        if (nbmc_mesh_check(mesh, &c) != NBMC_OK) {
          std::printf("QUALITY %s status=error message=\"mesh check failed\"\n", head);
          ++failures;
          nbmc_mesh_destroy(mesh);
          continue;
        }
        const uint64_t nv = nbmc_mesh_vertex_count(mesh), nt = nbmc_mesh_triangle_count(mesh);
        Metrics m = analyse(nbmc_mesh_positions(mesh), nv, nbmc_mesh_triangles(mesh), nt,
                            particles.empty() ? nullptr : &particles, o.spacing, o.threads);
        const double r3 = o.spacing * o.spacing * o.spacing;
        const double vratio = c.volume / (double(count) * r3);
        std::string dist = m.have_dist ? fmt("dist_p50=%.4f", m.dist_p50) + fmt(" dist_p99=%.4f", m.dist_p99) +
                                             fmt(" dist_max=%.4f", m.dist_max) + fmt(" beyond2r=%.6f", m.beyond2r)
                                       : "dist_p50=- dist_p99=- dist_max=- beyond2r=-";
        std::printf(
            "QUALITY %s status=ok particles=%llu vertices=%llu triangles=%llu raw_triangles=%llu closed=%d "
            "manifold=%d oriented=%d degenerate=%llu slivers=%llu below1deg=%llu min_angle=%.4f "
            "dihedral_mean=%.4f dihedral_p99=%.4f %s volume_ratio=%.5f components=%llu seconds=%.3f "
            "post_seconds=%.3f\n",
            head, (unsigned long long)count, (unsigned long long)nv, (unsigned long long)nt,
            (unsigned long long)s.raw_triangle_count, c.closed, c.manifold, c.oriented,
            (unsigned long long)c.degenerate_triangle_count, (unsigned long long)c.sliver_triangle_count,
            (unsigned long long)m.below1deg, c.min_angle_degrees, m.dihedral_mean, m.dihedral_p99, dist.c_str(),
            vratio, (unsigned long long)c.component_count, s.total_seconds,
            s.stage_seconds[NBMC_STAGE_POSTPROCESS]);
        std::fflush(stdout);
        auto yn = [](int v) { return v ? "y" : "**n**"; };
        rows += "| " + o.label + " | " + mname + " | " + fmt("%g", cell) + " | " + vname + " | " + std::to_string(nt) +
                " | " + std::to_string(s.raw_triangle_count) + " | " + yn(c.closed) + "/" + yn(c.manifold) + "/" +
                yn(c.oriented) + " | " + std::to_string(c.degenerate_triangle_count) + " | " +
                std::to_string(m.below1deg) + " | " + fmt("%.2f", c.min_angle_degrees) + " | " +
                fmt("%.2f", m.dihedral_mean) + " | " + fmt("%.1f", m.dihedral_p99) + " | " +
                (m.have_dist ? fmt("%.3f", m.dist_p50) + " | " + fmt("%.3f", m.dist_p99) + " | " +
                                   fmt("%.2f", m.dist_max) + " | " + fmt("%.4f%%", 100.0 * m.beyond2r)
                             : std::string("- | - | - | -")) +
                " | " + fmt("%.3f", vratio) + " | " + std::to_string(c.component_count) + " | " +
                fmt("%.2f", s.total_seconds) + " |\n";
        nbmc_mesh_destroy(mesh);
      }
  }
  nbmc_context_destroy(ctx);

  if (!o.markdown.empty()) {
    bool empty = true;
    {
      std::ifstream probe(o.markdown, std::ios::binary | std::ios::ate);
      if (probe && probe.tellg() > 0) empty = false;
    }
    std::ofstream md(o.markdown, std::ios::app);
    if (!md) {
      std::fprintf(stderr, "nbmc_quality: cannot write %s\n", o.markdown.c_str());
      return 1;
    }
    if (empty) md << kMarkdownHeader;
    md << rows;
  } else {
    std::printf("\n%s%s", kMarkdownHeader, rows.c_str());
  }
  return failures ? 1 : 0;
}
