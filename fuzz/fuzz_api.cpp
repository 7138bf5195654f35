// SPDX-License-Identifier: MIT
// libFuzzer target: the C API (include/nbmc.h), serial backend.
//
// The input is read by a small byte consumer (no FuzzedDataProvider, so that
// the replay program builds with any compiler): a particle set (lattice blobs,
// random points in a small box, points placed by the input, duplicates, thin
// sheets; now and then NaN/Inf/huge coordinates or a far-away particle), the
// parameters (sometimes invalid, sometimes with a bounding box, a memory
// budget or a cancelling progress callback), float or double upload with a
// padded or unaligned stride, and a permutation of the particles.
//
// Invariants (a failure prints the reason and calls abort()):
//  - every status is one of the documented codes, with a non-empty
//    nbmc_context_last_error on failure and an empty one on success; a failed
//    reconstruction leaves *mesh NULL and NBMC_ERROR_INTERNAL never happens;
//  - inputs whose outcome the documentation fixes get exactly that status
//    (NaN/Inf/|x| > 1e15 -> INVALID_PARTICLES naming the first bad particle,
//    then NO_PARTICLES; bad stride -> INVALID_ARGUMENT; invalid parameters ->
//    INVALID_PARAMETER; an empty bounding box -> NO_PARTICLES; valid input on
//    an indexable grid without budget or callback -> OK);
//  - on success: consistent counts and stats, indices in range, finite
//    positions, unit normals (or none when not asked for); without a bounding
//    box the mesh is closed, edge- and vertex-manifold, consistently oriented
//    (positive volume), with no degenerate triangle or unused vertex; with one,
//    vertices lie within the box plus the margin nbmc.h documents for use_bbox
//    (plus one cell: the grid's last vertex);
//  - a second run gives the same status and the bitwise identical mesh, and so
//    does the same set uploaded in a shuffled order;
//  - every successful free run again with post-processing drawn from the
//    permutation seed (0-5 smoothing steps, uniform or feature weights,
//    decimation to 0.1-1, isolated particles kept or as spheres): closed,
//    manifold, oriented without a bounding box, no more triangles than
//    before decimation, one sphere per dropped particle, deterministic.
//
// One serial context is created on the first input and reused. Each input is
// capped (<= 400 particles; an estimate of the band vertices and the field work
// bounds the cell size from below): with ASan/UBSan an execution (three
// reconstructions and the checks) takes about 10 ms in the median and under
// 75 ms for 90% of the corpus; the slowest are band growth (fuzz/README_api.md,
// finding 4). NBMC_FUZZ_API_VERBOSE=1 prints one line per input.
#include "nbmc.h"
#include "nbmc_test.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace {

// ------------------------------------------------------------ input reading
// Reads past the end give zeros, and zeros always choose the ordinary path.
class Input {
 public:
  Input(const std::uint8_t* d, std::size_t n) : d_(d), n_(n) {}
  std::uint8_t u8() { return pos_ < n_ ? d_[pos_++] : 0; }
  // (every read is a statement of its own: the order of evaluation of
  // operands and arguments differs between compilers, the decoding must not)
  std::uint16_t u16() {
    const unsigned lo = u8();
    const unsigned hi = u8();
    return std::uint16_t(lo | (hi << 8));
  }
  std::uint32_t u32() {
    const std::uint32_t lo = u16();
    const std::uint32_t hi = u16();
    return lo | (hi << 16);
  }
  // true with probability about 1/k (never once the input is used up)
  bool one_in(unsigned k) { return u8() % k == k - 1; }
  std::uint32_t below(std::uint32_t n) { return n ? u32() % n : 0; }
  std::uint32_t small_below(std::uint32_t n) { return n ? u8() % n : 0; }  // n <= 256
  double unit() { return u16() / 65535.0; }
  double range(double lo, double hi) { return lo + (hi - lo) * unit(); }

 private:
  const std::uint8_t* d_;
  std::size_t n_, pos_ = 0;
};

// Bulk randomness (random clouds, permutations) seeded from the input.
struct SplitMix {
  std::uint64_t s;
  std::uint64_t next() {
    std::uint64_t z = (s += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  double unit() { return double(next() >> 11) * (1.0 / 9007199254740992.0); }
  double range(double lo, double hi) { return lo + (hi - lo) * unit(); }
};

// ------------------------------------------------------------------ failure
std::string g_case;  // short description of the current input, for reports

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "fuzz_api invariant violated: %s\n  input: %s\n", what.c_str(), g_case.c_str());
  std::fflush(stderr);
  std::abort();
}

const char* name_of(int32_t s) { return nbmc_status_string(s); }

std::string status_text(int32_t s) { return std::to_string(s) + " (" + name_of(s) + ")"; }

nbmc_context* context() {
  static nbmc_context* ctx = [] {
    nbmc_context_desc d;
    nbmc_context_desc_init(&d);
    d.backend = NBMC_BACKEND_SERIAL;
    nbmc_context* c = nullptr;
    const int32_t s = nbmc_context_create(&d, &c);
    if (s != NBMC_OK || !c) {
      std::fprintf(stderr, "fuzz_api: nbmc_context_create failed: %s\n", nbmc_context_last_error(nullptr));
      std::abort();
    }
    return c;
  }();
  return ctx;
}

// ------------------------------------------------------------ particle sets
constexpr std::size_t kMaxParticles = 400;
constexpr std::size_t kMaxThinBandParticles = 100;
// Bounds of the estimated work of one reconstruction (see below): field
// evaluations, and band (or dense grid) vertices.
constexpr double kMaxWork = 3e6;
constexpr double kMaxVertices = 12000;

using Local = std::vector<double>;  // x, y, z per particle, in units of the spacing

// Particles beyond the input's cap are dropped.
std::size_t g_cap = kMaxParticles;

void add(Local& p, double x, double y, double z) {
  if (p.size() / 3 >= g_cap) return;
  p.push_back(x);
  p.push_back(y);
  p.push_back(z);
}

void add_piece(Input& in, Local& p) {
  const unsigned kind = in.small_below(6);
  const double cx = in.range(-6, 6), cy = in.range(-6, 6), cz = in.range(-6, 6);
  switch (kind) {
    case 0: {  // lattice ball, optionally jittered
      const double radius = in.range(0.2, 4.5);
      const bool jittered = in.one_in(3);
      const double amount = in.range(0, 0.3);
      const double jitter = jittered ? amount : 0.0;
      SplitMix rng{in.u32()};
      const int m = int(std::ceil(radius));
      for (int k = -m; k <= m; ++k)
        for (int j = -m; j <= m; ++j)
          for (int i = -m; i <= m; ++i)
            if (i * i + j * j + k * k <= radius * radius) {
              const double dx = rng.range(-jitter, jitter);
              const double dy = rng.range(-jitter, jitter);
              const double dz = rng.range(-jitter, jitter);
              add(p, cx + i + dx, cy + j + dy, cz + k + dz);
            }
      break;
    }
    case 1: {  // lattice box
      const int nx = 1 + int(in.small_below(8)), ny = 1 + int(in.small_below(8)), nz = 1 + int(in.small_below(8));
      for (int k = 0; k < nz; ++k)
        for (int j = 0; j < ny; ++j)
          for (int i = 0; i < nx; ++i) add(p, cx + i, cy + j, cz + k);
      break;
    }
    case 2: {  // random points in a small box
      const std::uint32_t n = 1 + in.small_below(200);
      const double s = in.range(0.2, 8);
      SplitMix rng{in.u32()};
      for (std::uint32_t i = 0; i < n; ++i) {
        const double x = rng.range(0, s);
        const double y = rng.range(0, s);
        const double z = rng.range(0, s);
        add(p, cx + x, cy + y, cz + z);
      }
      break;
    }
    case 3: {  // points placed by the input
      const std::uint32_t n = 1 + in.small_below(16);
      for (std::uint32_t i = 0; i < n; ++i) {
        const double x = (int(in.u16()) - 32768) / 4096.0, y = (int(in.u16()) - 32768) / 4096.0,
                     z = (int(in.u16()) - 32768) / 4096.0;
        add(p, x, y, z);
      }
      break;
    }
    case 4: {  // duplicates of existing particles (or many at one point)
      const std::uint32_t n = 1 + in.small_below(64);
      const std::size_t have = p.size() / 3;
      const std::uint32_t pick = in.u32();
      const std::size_t src = have ? pick % have : 0;
      const bool same = in.one_in(2);
      for (std::uint32_t i = 0; i < n; ++i) {
        const std::size_t s = have ? (same ? src : (src + i) % have) : 0;
        if (have) add(p, p[3 * s], p[3 * s + 1], p[3 * s + 2]);
        else add(p, cx, cy, cz);
      }
      break;
    }
    default: {  // a sheet of one or two layers
      const int nx = 1 + int(in.small_below(12)), ny = 1 + int(in.small_below(12)), nz = 1 + int(in.small_below(2));
      for (int k = 0; k < nz; ++k)
        for (int j = 0; j < ny; ++j)
          for (int i = 0; i < nx; ++i) add(p, cx + i, cy + j, cz + k);
      break;
    }
  }
}

// ------------------------------------------------------------------ uploads
struct Upload {
  bool f64 = true;
  std::uint64_t stride = 0;  // as passed to the API
  std::uint64_t count = 0;
  bool null_pointer = false;
  std::vector<unsigned char> bytes;
};

// double -> float as a float array of the caller would hold it (out of range
// becomes +-inf rather than undefined behaviour).
float narrow(double x) {
  if (std::fabs(x) > double(std::numeric_limits<float>::max()))
    return std::copysign(std::numeric_limits<float>::infinity(), float(x > 0 ? 1 : -1));
  return float(x);
}

// Packs the (typed) values with the given stride; padding bytes are 0xff, a
// NaN pattern for float and double, so reading them would be noticed.
Upload pack(const std::vector<double>& v, bool f64, std::uint64_t stride, std::size_t count) {
  Upload u;
  u.f64 = f64;
  u.stride = stride;
  u.count = count;
  const std::size_t elem = f64 ? sizeof(double) : sizeof(float);
  const std::size_t step = stride ? std::size_t(stride) : 3 * elem;
  if (step < 3 * elem) {  // invalid stride: the API must not read anything
    u.bytes.assign(std::max<std::size_t>(count * 3 * elem, 1), 0xff);
    return u;
  }
  u.bytes.assign(std::max<std::size_t>(count * step, 1), 0xff);
  for (std::size_t i = 0; i < count; ++i)
    for (int a = 0; a < 3; ++a) {
      unsigned char* dst = u.bytes.data() + i * step + a * elem;
      if (f64) {
        const double x = v[3 * i + a];
        std::memcpy(dst, &x, sizeof x);
      } else {
        const float x = narrow(v[3 * i + a]);
        std::memcpy(dst, &x, sizeof x);
      }
    }
  return u;
}

int32_t upload(nbmc_context* ctx, const Upload& u) {
  // The buffer is a std::vector<unsigned char> (suitably aligned by new) and
  // the API reads it with memcpy, so an odd stride is legal.
  const void* base = u.null_pointer ? nullptr : static_cast<const void*>(u.bytes.data());
  return u.f64 ? nbmc_context_set_particles_f64(ctx, static_cast<const double*>(base), u.count, u.stride)
               : nbmc_context_set_particles_f32(ctx, static_cast<const float*>(base), u.count, u.stride);
}

// --------------------------------------------------------------- reconstruct
struct Cancel {
  int calls = 0;
  int cancel_at = -1;  // cancel on this call (0 = the first), -1 = never
  bool bad_fraction = false;
  static int32_t fn(void* user, int32_t stage, double fraction) {
    auto* c = static_cast<Cancel*>(user);
    if (stage < 0 || stage >= NBMC_STAGE_COUNT || !(fraction >= 0.0 && fraction <= 1.0)) c->bad_fraction = true;
    return c->calls++ == c->cancel_at ? 1 : 0;
  }
};

struct Run {
  int32_t status = -1;
  std::string message;
  nbmc_test::Mesh mesh;
  nbmc_stats stats{};
  bool has_normals = false;
  std::vector<double> positions64;  // nbmc_mesh_positions_f64 (double_positions)
  std::uint64_t spheres = 0;        // nbmc_mesh_sphere_count (NBMC_ISOLATED_SPHERE)
};

Run reconstruct(nbmc_context* ctx, const nbmc_params& prm, int cancel_at) {
  Run r;
  Cancel cancel;
  cancel.cancel_at = cancel_at;
  if (cancel_at >= 0 && nbmc_context_set_progress(ctx, &Cancel::fn, &cancel) != NBMC_OK)
    die("nbmc_context_set_progress failed");
  nbmc_mesh* m = reinterpret_cast<nbmc_mesh*>(std::uintptr_t(0x10));  // must be overwritten
  r.status = nbmc_context_reconstruct(ctx, &prm, &m);
  r.message = nbmc_context_last_error(ctx);
  if (cancel_at >= 0) {
    if (nbmc_context_set_progress(ctx, nullptr, nullptr) != NBMC_OK) die("nbmc_context_set_progress(NULL) failed");
    if (cancel.bad_fraction) die("progress callback got a stage or fraction out of range");
    if (r.status == NBMC_ERROR_CANCELLED && cancel.calls != cancel_at + 1)
      die("CANCELLED although the callback did not ask for it");
    if (r.status != NBMC_ERROR_CANCELLED && cancel.calls > cancel_at + 1)
      die("the callback asked to cancel but the reconstruction went on");
  }
  if (r.status != NBMC_OK) {
    if (m != nullptr) die("failed reconstruction left *mesh non-NULL");
    return r;
  }
  if (!m) die("NBMC_OK with a NULL mesh");
  const std::uint64_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  const float* pos = nbmc_mesh_positions(m);
  const float* nrm = nbmc_mesh_normals(m);
  const std::uint32_t* tri = nbmc_mesh_triangles(m);
  if ((nv == 0) != (pos == nullptr)) die("positions pointer does not match the vertex count");
  if ((nt == 0) != (tri == nullptr)) die("triangles pointer does not match the triangle count");
  r.has_normals = nrm != nullptr;
  if (nrm && nv == 0) die("normals without vertices");
  if (pos) r.mesh.positions.assign(pos, pos + 3 * nv);
  if (nrm) r.mesh.normals.assign(nrm, nrm + 3 * nv);
  if (tri) r.mesh.triangles.assign(tri, tri + 3 * nt);
  const double* pos64 = nbmc_mesh_positions_f64(m);
  if (bool(pos64) != (prm.double_positions && nv > 0)) die("double positions present/absent against double_positions");
  if (pos64) r.positions64.assign(pos64, pos64 + 3 * nv);
  r.spheres = nbmc_mesh_sphere_count(m);
  if ((r.spheres > 0) != (nbmc_mesh_spheres(m) != nullptr)) die("sphere pointer does not match the sphere count");
  for (std::uint64_t i = 0; i < r.spheres; ++i)
    for (int k = 0; k < 4; ++k)
      if (!std::isfinite(nbmc_mesh_spheres(m)[4 * i + std::uint64_t(k)])) die("non-finite sphere");
  nbmc_mesh_destroy(m);
  nbmc_stats_init(&r.stats);
  if (nbmc_context_stats(ctx, &r.stats) != NBMC_OK) die("nbmc_context_stats failed after a success");
  return r;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void expect_same(const Run& a, const Run& b, const char* what, bool compare_messages) {
  if (a.status != b.status)
    die(std::string(what) + ": status " + status_text(a.status) + " then " + status_text(b.status) + " (\"" +
        a.message + "\" / \"" + b.message + "\")");
  if (a.status != NBMC_OK) {
    if (compare_messages && a.message != b.message)
      die(std::string(what) + ": different messages \"" + a.message + "\" / \"" + b.message + "\"");
    return;
  }
  if (a.mesh.triangles != b.mesh.triangles)
    die(std::string(what) + ": triangles differ (" + std::to_string(a.mesh.triangle_count()) + " vs " +
        std::to_string(b.mesh.triangle_count()) + ")");
  if (!same_bits(a.mesh.positions, b.mesh.positions))
    die(std::string(what) + ": positions differ (" + std::to_string(a.mesh.vertex_count()) + " vs " +
        std::to_string(b.mesh.vertex_count()) + " vertices)");
  if (!same_bits(a.mesh.normals, b.mesh.normals)) die(std::string(what) + ": normals differ");
  const nbmc_stats &s = a.stats, &t = b.stats;
  if (s.surface_particle_count != t.surface_particle_count || s.band_vertex_count != t.band_vertex_count ||
      s.neighbour_evaluations != t.neighbour_evaluations || s.triangulated_cell_count != t.triangulated_cell_count)
    die(std::string(what) + ": statistics differ");
}

// ------------------------------------------------------- parameter validity
struct Expect {
  bool struct_ok = true, params_ok = true, domain_small = true, grid_ok = true, bbox_has_particles = true;
};

void check_mesh_invariants(const Run& r, const nbmc_params& prm, double cell_abs, double bw_abs, double iso_abs,
                           std::size_t particles) {
  const nbmc_test::Mesh& m = r.mesh;
  const std::size_t nv = m.vertex_count(), nt = m.triangle_count();
  const nbmc_stats& st = r.stats;
  if (st.vertex_count != nv || st.triangle_count != nt) die("stats vertex/triangle counts differ from the mesh");
  if (prm.use_bbox ? st.particle_count > particles : st.particle_count != particles)
    die("stats particle_count " + std::to_string(st.particle_count) + " for " + std::to_string(particles) +
        " particles");
  if (st.surface_particle_count > st.particle_count) die("more surface particles than particles");
  if (st.grid_vertex_count != st.grid_dims[0] * st.grid_dims[1] * st.grid_dims[2])
    die("grid_vertex_count is not the product of grid_dims");
  if (st.band_vertex_count > st.grid_vertex_count) die("more band vertices than grid vertices");
  if (std::fabs(st.cell_size - cell_abs) > 1e-12 * cell_abs) die("stats cell_size is not the absolute cell size");
  if (prm.compute_normals ? (nv > 0 && !r.has_normals) : r.has_normals)
    die("normals present/absent against compute_normals");

  for (std::uint32_t t : m.triangles)
    if (t >= nv) die("triangle index " + std::to_string(t) + " out of range (" + std::to_string(nv) + " vertices)");
  for (float x : m.positions)
    if (!std::isfinite(x)) die("non-finite vertex position");
  for (std::size_t v = 0; v < m.normals.size() / 3; ++v) {
    const double x = m.normals[3 * v], y = m.normals[3 * v + 1], z = m.normals[3 * v + 2];
    const double len = std::sqrt(x * x + y * y + z * z);
    if (!(std::fabs(len - 1.0) < 1e-3)) die("normal " + std::to_string(v) + " has length " + std::to_string(len));
  }

  if (prm.use_bbox) {
    // nbmc.h (use_bbox): the grid covers the box plus a margin of
    // max(band_width, iso_radius + cell_size) + 2 cells and the mesh may
    // reach into it; the grid's last vertex may lie up to one cell beyond.
    const double margin = std::max(bw_abs, iso_abs + cell_abs) + 2 * cell_abs;
    for (std::size_t v = 0; v < nv; ++v)
      for (int a = 0; a < 3; ++a) {
        const double x = m.positions[3 * v + a];
        const double tol = margin + cell_abs + 1e-6 * std::fabs(x);
        if (x < prm.bbox_min[a] - tol || x > prm.bbox_max[a] + tol)
          die("vertex " + std::to_string(v) + " at " + std::to_string(x) + " on axis " + std::to_string(a) +
              " lies outside the bounding box [" + std::to_string(prm.bbox_min[a]) + ", " +
              std::to_string(prm.bbox_max[a]) + "] plus the margin " + std::to_string(margin) +
              " and one cell (" + std::to_string(cell_abs) + ")");
      }
    return;
  }
  const nbmc_test::MeshReport rep = nbmc_test::check_mesh(m);
  if (!rep.closed || !rep.edge_manifold || !rep.vertex_manifold || !rep.oriented || rep.degenerate_triangles ||
      rep.unreferenced_vertices)
    die("mesh without a bounding box is not closed/manifold/oriented: " + rep.summary() + " (" +
        std::to_string(nv) + " vertices, " + std::to_string(nt) + " triangles)");
  // Outward orientation: positive volume (about the first vertex, for
  // precision), where float positions resolve the cell well enough.
  float max_abs = 0;
  for (float x : m.positions) max_abs = std::max(max_abs, std::fabs(x));
  if (nt && double(max_abs) * 1.2e-7 < 0.02 * cell_abs) {
    double vol = 0;
    const float* o = &m.positions[0];
    for (std::size_t t = 0; t < nt; ++t) {
      double p[3][3];
      for (int c = 0; c < 3; ++c)
        for (int a = 0; a < 3; ++a) p[c][a] = double(m.positions[3 * std::size_t(m.triangles[3 * t + c]) + a]) - o[a];
      vol += (p[0][0] * (p[1][1] * p[2][2] - p[1][2] * p[2][1]) - p[0][1] * (p[1][0] * p[2][2] - p[1][2] * p[2][0]) +
              p[0][2] * (p[1][0] * p[2][1] - p[1][1] * p[2][0])) / 6.0;
    }
    if (!(vol > 0)) die("closed mesh has non-positive volume " + std::to_string(vol) + " (inward orientation?)");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  nbmc_context* ctx = context();
  Input in(data, size);

  // Layout: a header of fixed size (scale, upload, parameters, rare events),
  // then the particle pieces, which take whatever the input has left.

  // -------------------------------------------------- header: scale
  static const double kSpacings[] = {1.0, 0.1, 0.025, 3.0, 0.001, 1000.0, 0.5, 7.25};
  const bool odd_spacing = in.one_in(8);
  const double odd_r = std::exp(in.range(std::log(1e-4), std::log(1e4)));
  const unsigned spacing_pick = in.small_below(8);
  const double r = odd_spacing ? odd_r : kSpacings[spacing_pick];
  static const double kOffsets[] = {0.0, 10.0, -123.4, 0.0, 1e4, -3e5, 0.0, 1e7};
  const double offset = kOffsets[in.small_below(8)];

  // ------------------------------------------------- header: upload
  const bool f64 = !in.one_in(3);
  const std::size_t elem = f64 ? sizeof(double) : sizeof(float);
  std::uint64_t stride = 0;
  const unsigned stride_kind = in.small_below(8);
  const unsigned stride_extra = in.small_below(9);
  const unsigned stride_small = 1 + in.small_below(unsigned(3 * elem - 1));
  if (stride_kind == 5) stride = 3 * elem + stride_extra;                     // padded, maybe unaligned
  else if (stride_kind == 6) stride = 3 * elem + elem * (stride_extra % 4);   // Fortran-like pos(4+, n)
  else if (stride_kind == 7 && stride_extra == 8) stride = stride_small;       // too small: invalid
  const bool zero_count = in.one_in(64);
  const bool null_pointer = in.one_in(64);

  // --------------------------------------------- header: parameters
  nbmc_params prm;
  nbmc_params_init(&prm);
  prm.spacing = r;
  const bool absolute = in.one_in(4);
  prm.length_unit = absolute ? NBMC_UNIT_ABSOLUTE : NBMC_UNIT_SPACING;
  const double L = absolute ? r : 1.0;  // lengths are given in units of r, or absolute
  double cell = in.range(0.3, 2.0);
  prm.influence_radius = in.range(1.5, 6.0) * L;
  // Thin bands (< r) make nbmc grow the band over many rounds, each a scan of
  // the whole band (finding 4): they get fewer particles.
  const bool thin_band = in.one_in(6);
  const double band_u = in.unit();
  prm.band_width = (thin_band ? 0.5 + 0.5 * band_u : 1.0 + 2.0 * band_u) * L;
  const std::size_t max_particles = thin_band ? kMaxThinBandParticles : kMaxParticles;
  prm.surface_radius = in.range(1.0, 4.0) * L;
  prm.iso_radius = in.range(0.3, 1.6) * L;
  prm.method = in.one_in(2) ? NBMC_METHOD_ZB05 : NBMC_METHOD_SSP07;
  prm.field = in.one_in(4) ? NBMC_FIELD_DENSE : NBMC_FIELD_NARROW_BAND;
  prm.t_low = in.range(0.05, 1.5);
  prm.t_high = prm.t_low + in.range(0.01, 5.0);
  prm.color_threshold = in.range(0.0, 2.0);
  prm.neighbour_threshold = int32_t(in.small_below(61));
  prm.compute_normals = in.one_in(4) ? 0 : 1;
  if (in.u8() < 40) {  // ~1/6: defaults for the thresholds (the ordinary surface test)
    prm.t_low = 0.4;
    prm.t_high = 3.5;
    prm.color_threshold = 0.75;
    prm.neighbour_threshold = 25;
  }
  const bool use_bbox = in.one_in(6);
  const bool bbox_away = in.one_in(6);
  double bbox_u[3][2];
  for (auto& u : bbox_u) {
    u[0] = in.range(-0.3, 1.0);
    u[1] = in.range(0.05, 1.3);
  }
  const bool corrupt = in.one_in(8);
  const unsigned corrupt_kind = in.small_below(16);
  const std::uint8_t corrupt_a = in.u8(), corrupt_b = in.u8();
  const double corrupt_u = in.unit();

  // ---------------------------------------------- header: rare events
  const bool with_budget = in.one_in(16);
  const unsigned budget_log2 = 10 + in.small_below(14);  // 1 KiB .. 8 MiB
  const bool with_cancel = in.one_in(16);
  const unsigned cancel_call = in.small_below(12);
  const int cancel_at = with_cancel ? int(cancel_call) : -1;  // which progress call cancels
  const std::uint64_t budget = with_budget ? std::uint64_t(1) << budget_log2 : 0;
  const bool far = in.one_in(12);
  const unsigned far_kind = in.small_below(6);
  const bool plant_bad = in.one_in(14);
  const std::uint32_t bad_pick = in.u32();
  const unsigned bad_axis = in.small_below(3), bad_kind = in.small_below(6);
  const std::uint32_t perm_seed = in.u32();

  // ------------------------------------------------------ particles
  Local local;
  g_cap = max_particles;
  const unsigned pieces = 1 + in.small_below(3);
  for (unsigned i = 0; i < pieces; ++i) add_piece(in, local);
  if (local.empty()) add(local, 0, 0, 0);
  if (far) {  // one particle a long way off (the grid may not be indexable)
    static const double kFar[] = {40.0, 1e3, 1e5, 3e6, 1e8, -2e4};
    local.back() = kFar[far_kind];  // the last particle's z
  }
  const std::size_t n = local.size() / 3;
  std::vector<double> values(local.size());
  for (std::size_t i = 0; i < local.size(); ++i) values[i] = offset + r * local[i];
  long bad_index = -1;  // a planted invalid coordinate
  if (plant_bad) {
    static const double kBad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                                  -std::numeric_limits<double>::infinity(), 1e16, -2e15, 1e300};
    bad_index = long(bad_pick % n);
    values[3 * std::size_t(bad_index) + bad_axis] = kBad[bad_kind];
  }

  const std::size_t count = zero_count ? 0 : n;
  Upload up = pack(values, f64, stride, n);
  up.count = count;
  up.null_pointer = count > 0 && null_pointer;

  // What the library sees: the values after conversion to the upload type.
  std::vector<double> seen(values.size());
  for (std::size_t i = 0; i < values.size(); ++i) seen[i] = f64 ? values[i] : double(narrow(values[i]));
  long first_bad = -1;
  for (std::size_t i = 0; i < n && first_bad < 0; ++i)
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(seen[3 * i + a]) || std::fabs(seen[3 * i + a]) > 1e15) first_bad = long(i);

  int32_t want_upload = NBMC_OK;
  if (count == 0) want_upload = NBMC_ERROR_NO_PARTICLES;
  else if (up.null_pointer) want_upload = NBMC_ERROR_INVALID_ARGUMENT;
  else if (stride != 0 && stride < 3 * elem) want_upload = NBMC_ERROR_INVALID_ARGUMENT;
  else if (first_bad >= 0) want_upload = NBMC_ERROR_INVALID_PARTICLES;

  // ----------------------------------------------- bounding box
  if (use_bbox) {  // a part of the particles' extent, now and then off them all
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a)
        if (std::isfinite(seen[3 * i + a]) && std::fabs(seen[3 * i + a]) < 1e14) {
          lo[a] = std::min(lo[a], seen[3 * i + a]);
          hi[a] = std::max(hi[a], seen[3 * i + a]);
        }
    prm.use_bbox = 1;
    for (int a = 0; a < 3; ++a) {
      if (lo[a] > hi[a]) lo[a] = hi[a] = offset;
      const double ext = std::max(hi[a] - lo[a], r);
      prm.bbox_min[a] = lo[a] + bbox_u[a][0] * ext;
      prm.bbox_max[a] = prm.bbox_min[a] + bbox_u[a][1] * ext;
      if (bbox_away && a == 0) {
        prm.bbox_min[a] = hi[a] + 50 * ext + 20 * r;
        prm.bbox_max[a] = prm.bbox_min[a] + ext;
      }
    }
  }

  // Appended draws (NBMC_METHOD_SPH), after all the others so that inputs
  // made before them keep their meaning (a used-up input reads zeros: no SPH).
  const bool sph = in.one_in(5);
  const double sph_threshold = in.range(0.05, 0.95);
  const unsigned sph_corrupt = in.small_below(4);
  if (sph) {
    prm.method = NBMC_METHOD_SPH;
    prm.iso_threshold = sph_threshold;
  }
  // Appended draws (NBMC_METHOD_YT10), after the SPH ones: Yu & Turk's
  // anisotropic kernels with their parameters over (and, with yt10_corrupt,
  // just beyond) their ranges. Zeros (a used-up input): no YT10.
  const bool yt10 = in.one_in(5);
  const double yt10_threshold = in.range(0.05, 0.95);
  const double aniso_kr = in.range(1.0, 8.0), aniso_ks = in.range(0.3, 3.0), aniso_kn = in.range(0.05, 1.5),
               aniso_lambda = in.unit();
  const int32_t aniso_neighbours = int32_t(in.small_below(61));
  const unsigned yt10_corrupt = in.small_below(8);
  const bool yt10_defaults = in.one_in(3);
  const bool sph_or_yt10 = sph || yt10;
  if (yt10) {
    prm.method = NBMC_METHOD_YT10;
    prm.iso_threshold = yt10_threshold;
    if (!yt10_defaults) {
      prm.aniso_kr = aniso_kr;
      prm.aniso_ks = aniso_ks;
      prm.aniso_kn = aniso_kn;
      prm.aniso_lambda = aniso_lambda;
      prm.aniso_neighbours = aniso_neighbours;
    }
  }
  // Appended draws (the distance guard), after the YT10 ones: max_distance
  // from 0 (off) to beyond R, or (guard_corrupt) NaN, infinite or negative.
  // Zeros (a used-up input): the default.
  const bool guard_set = in.one_in(2);
  const double guard_distance = in.range(0.0, 6.0);
  const unsigned guard_corrupt = in.small_below(24);
  if (guard_set) prm.max_distance = guard_distance * L;
  if (guard_set && guard_corrupt < 3) {
    const double bad[] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
                          -0.5 * L};
    prm.max_distance = bad[guard_corrupt];
  }

  // Keep the work small: an estimate of the field evaluations (band or dense
  // vertices times the most neighbours any particle has within R) bounds the
  // cell size from below; a dense grid that stays too large becomes a band.
  {
    // (iso: how far the surface lies beyond the particles; R for the SPH
    // density and YT10)
    const double R = prm.influence_radius / L, bw = prm.band_width / L,
                 iso = (sph_or_yt10 ? prm.influence_radius : prm.iso_radius) / L;  // units of r
    std::size_t max_nb = 1;
    for (std::size_t i = 0; i < n; ++i) {
      std::size_t c = 0;
      for (std::size_t j = 0; j < n; ++j) {
        const double dx = local[3 * i] - local[3 * j], dy = local[3 * i + 1] - local[3 * j + 1],
                     dz = local[3 * i + 2] - local[3 * j + 2];
        c += dx * dx + dy * dy + dz * dz <= R * R;
      }
      max_nb = std::max(max_nb, c);
    }
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], local[3 * i + a]);
        hi[a] = std::max(hi[a], local[3 * i + a]);
      }
    auto vertices = [&](double c, bool dense) {
      const double pad = std::max(bw, iso + c) + 2 * c;
      double grid = 1;
      for (int a = 0; a < 3; ++a) grid *= (hi[a] - lo[a] + 2 * pad) / c + 2;
      const double per_particle = std::pow(2 * bw / c + 2, 3);
      return dense ? grid : std::min(grid, double(n) * per_particle);
    };
    // The band may grow over dozens of rounds, each a scan of all of it
    // (finding 4), most when the surface lies beyond the band (iso radius +
    // cell > band width): the vertex count is bounded on its own, besides
    // the field work, and tighter then.
    const bool grows = iso + cell > bw;
    auto too_much = [&](double c, bool dense) {
      const double v = vertices(c, dense);
      return v > (grows ? kMaxVertices / 4 : kMaxVertices) ||
             v * double(max_nb) * (prm.method == NBMC_METHOD_SSP07 || prm.method == NBMC_METHOD_YT10 ? 2.0 : 1.0) >
                 kMaxWork;
    };
    if (prm.field == NBMC_FIELD_DENSE && too_much(cell, true)) prm.field = NBMC_FIELD_NARROW_BAND;
    for (int i = 0; i < 60 && too_much(cell, false); ++i) cell *= 1.15;
  }
  prm.cell_size = cell * L;

  // Sometimes one invalid value (documented: INVALID_PARAMETER, or
  // INVALID_ARGUMENT for struct_size; DOMAIN_TOO_LARGE for an absurd cell).
  bool absurd_cell = false;
  if (corrupt) {
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    const bool alt = corrupt_a & 1;
    switch (corrupt_kind) {
      case 0: prm.spacing = alt ? 0.0 : -r; break;
      case 1: prm.spacing = alt ? nan : inf; break;
      case 2: prm.cell_size = alt ? 0.0 : -prm.cell_size; break;
      case 3: prm.influence_radius = alt ? nan : -1.0; break;
      case 4: prm.band_width = alt ? 0.0 : inf; break;
      case 5: prm.surface_radius = alt ? -prm.surface_radius : prm.influence_radius * (2.01 + corrupt_u); break;
      case 6:
        if (yt10 && yt10_corrupt < 5) {  // YT10 ignores iso_radius: an anisotropy parameter out of range
          switch (yt10_corrupt) {
            case 0: prm.aniso_kr = alt ? std::numeric_limits<double>::quiet_NaN() : 1.0 - 0.5 * corrupt_u - 1e-9; break;
            case 1: prm.aniso_ks = alt ? -corrupt_u : 0.0; break;
            case 2: prm.aniso_kn = alt ? 0.0 : 1.5 + corrupt_u + 1e-9; break;
            case 3: prm.aniso_lambda = alt ? -1e-9 - corrupt_u : 1.0 + corrupt_u + 1e-9; break;
            default: prm.aniso_neighbours = -1 - int32_t(corrupt_b % 100); break;
          }
        } else if (yt10) {
          prm.iso_threshold = alt ? std::numeric_limits<double>::quiet_NaN() : (corrupt_b & 1 ? 0.0 : 1.0 + corrupt_u);
        } else if (sph && sph_corrupt == 0) {  // the SPH method ignores iso_radius: a bad threshold instead
          prm.iso_threshold = alt ? std::numeric_limits<double>::quiet_NaN() : (corrupt_b & 1 ? 0.0 : 1.0 + corrupt_u);
        } else {
          prm.iso_radius = prm.influence_radius * (1.0 + corrupt_u);
        }
        break;
      case 7: std::swap(prm.t_low, prm.t_high); break;
      case 8: prm.t_high = nan; break;
      case 9: prm.method = alt ? 4 : -1; break;
      case 10: prm.field = alt ? 3 : -1; break;  // not 2: the scatter baseline is valid but slow
      case 11: prm.length_unit = alt ? 2 : -7; break;
      case 12: prm.color_threshold = alt ? -0.5 : nan; break;
      case 13: prm.neighbour_threshold = -1 - int32_t(corrupt_b % 100); break;
      case 14:
        prm.use_bbox = 1;
        prm.bbox_min[corrupt_b % 3] = alt ? nan : 1.0;
        prm.bbox_max[0] = prm.bbox_min[0];
        break;
      default:
        if (alt) {
          prm.struct_size = std::uint32_t(corrupt_b % sizeof(nbmc_params));
        } else {  // valid, but far too fine a grid for the band
          prm.cell_size = prm.band_width / 2000.0;
          absurd_cell = true;
        }
        break;
    }
  }

  // The documented validity rules (nbmc.h, docs/api.md "Parameters"),
  // evaluated the way they are specified: lengths positive and finite,
  // iso < R and surface radius <= 2 R in absolute units, t_low < t_high,
  // bounding box finite with min < max.
  Expect ex;
  // A shorter struct (a caller built against an older header) is accepted
  // down to `cleanup`; the fields it lacks keep their defaults.
  ex.struct_ok = prm.struct_size >= offsetof(nbmc_params, cleanup);
  nbmc_params eff;
  nbmc_params_init(&eff);
  std::memcpy(&eff, &prm, std::min<std::size_t>(prm.struct_size, sizeof eff));
  {
    auto pos = [](double v) { return std::isfinite(v) && v > 0; };
    bool ok = pos(prm.spacing) &&
              (prm.length_unit == NBMC_UNIT_SPACING || prm.length_unit == NBMC_UNIT_ABSOLUTE) &&
              (prm.method == NBMC_METHOD_SSP07 || prm.method == NBMC_METHOD_ZB05 ||
               prm.method == NBMC_METHOD_SPH || prm.method == NBMC_METHOD_YT10) &&
              std::isfinite(eff.iso_threshold) && eff.iso_threshold > 0 && eff.iso_threshold < 1 &&
              std::isfinite(eff.aniso_kr) && eff.aniso_kr >= 1 && std::isfinite(eff.aniso_ks) && eff.aniso_ks > 0 &&
              std::isfinite(eff.aniso_kn) && eff.aniso_kn > 0 && eff.aniso_kn <= 1.5 &&
              std::isfinite(eff.aniso_lambda) && eff.aniso_lambda >= 0 && eff.aniso_lambda <= 1 &&
              eff.aniso_neighbours >= 0 && std::isfinite(eff.max_distance) && eff.max_distance >= 0 &&
              (eff.isolated == NBMC_ISOLATED_KEEP || eff.isolated == NBMC_ISOLATED_DROP ||
               eff.isolated == NBMC_ISOLATED_SPHERE) &&
              eff.min_cluster >= 1 && eff.decimate_fraction > 0 && eff.decimate_fraction <= 1 &&
              (eff.smooth_weighting == NBMC_SMOOTH_UNIFORM || eff.smooth_weighting == NBMC_SMOOTH_FEATURE) &&
              (prm.field >= NBMC_FIELD_NARROW_BAND && prm.field <= NBMC_FIELD_SCATTER) && pos(prm.cell_size) &&
              pos(prm.influence_radius) && pos(prm.band_width) && pos(prm.surface_radius) && pos(prm.iso_radius) &&
              std::isfinite(prm.t_low) && std::isfinite(prm.t_high) && prm.t_low < prm.t_high &&
              std::isfinite(prm.color_threshold) && prm.color_threshold >= 0 && prm.neighbour_threshold >= 0;
    if (ok) {
      const double f = prm.length_unit == NBMC_UNIT_SPACING ? prm.spacing : 1.0;
      ok = (prm.method == NBMC_METHOD_SPH || prm.method == NBMC_METHOD_YT10 ||
            prm.iso_radius * f < prm.influence_radius * f) &&
           prm.surface_radius * f <= 2 * (prm.influence_radius * f);
    }
    if (ok && prm.use_bbox)
      for (int a = 0; a < 3; ++a)
        ok = ok && std::isfinite(prm.bbox_min[a]) && std::isfinite(prm.bbox_max[a]) && prm.bbox_min[a] < prm.bbox_max[a];
    ex.params_ok = ok;
  }
  const double f = prm.length_unit == NBMC_UNIT_SPACING ? prm.spacing : 1.0;
  // iso_abs: how far beyond the particles the surface can lie (R for the SPH
  // density and YT10); reach_abs: how far beyond the box particles are kept
  // (nbmc.h: R, 2R for the SPH density and YT10).
  const bool is_sph = prm.method == NBMC_METHOD_SPH || prm.method == NBMC_METHOD_YT10;
  const double cell_abs = prm.cell_size * f, R_abs = prm.influence_radius * f, bw_abs = prm.band_width * f,
               iso_abs = (is_sph ? prm.influence_radius : prm.iso_radius) * f, reach_abs = is_sph ? 2 * R_abs : R_abs,
               sr_abs = prm.surface_radius * f;
  if (ex.params_ok) {
    ex.domain_small = !absurd_cell;
    // Particles the reconstruction keeps, and the extent of its grid.
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n; ++i) {
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        const double x = seen[3 * i + a];
        inside = inside && (!prm.use_bbox || (x >= prm.bbox_min[a] - reach_abs && x <= prm.bbox_max[a] + reach_abs));
      }
      if (!inside) continue;
      ++kept;
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], seen[3 * i + a]);
        hi[a] = std::max(hi[a], seen[3 * i + a]);
      }
    }
    ex.bbox_has_particles = kept > 0;
    if (prm.use_bbox)
      for (int a = 0; a < 3; ++a) {
        lo[a] = prm.bbox_min[a];
        hi[a] = prm.bbox_max[a];
      }
    // The grid must be indexable: fewer than 2^21 - 2 vertices per axis for
    // the marching-cubes cells and the neighbour cells (max(R/2, surface radius)); a generous
    // margin either side leaves the boundary itself to the library.
    const double pad = std::max(bw_abs, iso_abs + cell_abs) + 2 * cell_abs;
    const double limit = double((1u << 21) - 2);
    for (int a = 0; a < 3 && ex.bbox_has_particles; ++a) {
      const double ext = hi[a] - lo[a] + 2 * pad;
      const double cells = std::max(ext / cell_abs, ext / std::max(0.5 * R_abs, sr_abs)) + 2;
      if (cells > 0.999 * limit) ex.grid_ok = false;
      if (cells > 0.999 * limit && cells < 1.001 * limit) ex.grid_ok = ex.domain_small = false;  // either way
    }
    if (!ex.grid_ok && prm.field == NBMC_FIELD_DENSE) prm.field = NBMC_FIELD_NARROW_BAND;  // never allocate it
  }

  char desc[512];
  std::snprintf(desc, sizeof desc,
                "n=%zu r=%g offset=%g %s stride=%llu count=%llu bad=%ld unit=%s cell=%g R=%g band=%g surf=%g iso=%g "
                "method=%d field=%d t=[%g,%g] iso_t=%g aniso=[%g,%g,%g,%g,%d] guard=%g color=%g nbr=%d normals=%d bbox=%d "
                "budget=%llu cancel=%d",
                n, r, offset, f64 ? "f64" : "f32", (unsigned long long)stride, (unsigned long long)count, bad_index,
                absolute ? "abs" : "rel", prm.cell_size, prm.influence_radius, prm.band_width, prm.surface_radius,
                prm.iso_radius, prm.method, prm.field, prm.t_low, prm.t_high, prm.iso_threshold, prm.aniso_kr,
                prm.aniso_ks, prm.aniso_kn, prm.aniso_lambda, int(prm.aniso_neighbours), prm.max_distance,
                prm.color_threshold,
                prm.neighbour_threshold, prm.compute_normals, prm.use_bbox, (unsigned long long)budget, cancel_at);
  g_case = desc;

  // ---------------------------------------------------------------- run
  const auto t0 = std::chrono::steady_clock::now();
  if (nbmc_context_set_memory_budget(ctx, budget) != NBMC_OK) die("nbmc_context_set_memory_budget failed");
  const int32_t us = upload(ctx, up);
  const std::string umsg = nbmc_context_last_error(ctx);
  if (us != want_upload)
    die("upload gave " + status_text(us) + ", expected " + status_text(want_upload) + ": \"" + umsg + "\"");
  if (us != NBMC_OK && umsg.empty()) die("failed upload without a message");
  if (us == NBMC_OK && !umsg.empty()) die("successful upload with a message: " + umsg);
  if (us == NBMC_ERROR_INVALID_PARTICLES &&
      umsg.find("particle " + std::to_string(first_bad) + ")") == std::string::npos)
    die("INVALID_PARTICLES message does not name particle " + std::to_string(first_bad) + ": " + umsg);

  const Run a = reconstruct(ctx, prm, cancel_at);
  switch (a.status) {
    case NBMC_OK: case NBMC_ERROR_INVALID_ARGUMENT: case NBMC_ERROR_NO_PARTICLES: case NBMC_ERROR_INVALID_PARAMETER:
    case NBMC_ERROR_DOMAIN_TOO_LARGE: case NBMC_ERROR_MEMORY_BUDGET: case NBMC_ERROR_CANCELLED: break;
    default: die("reconstruct gave " + status_text(a.status) + ": \"" + a.message + "\"");
  }
  if (a.status != NBMC_OK && a.message.empty()) die("failed reconstruction without a message");
  if (a.status == NBMC_OK && !a.message.empty()) die("successful reconstruction with a message: " + a.message);

  // The status the documentation fixes, where it does.
  auto expect = [&](bool cond, int32_t want) {
    if (cond && a.status != want)
      die("reconstruct gave " + status_text(a.status) + ", expected " + status_text(want) + ": \"" + a.message + "\"");
  };
  const bool free_run = budget == 0 && cancel_at < 0;
  if (!ex.struct_ok) expect(true, NBMC_ERROR_INVALID_ARGUMENT);
  else if (us != NBMC_OK) {
    if (a.status != NBMC_ERROR_NO_PARTICLES && !(a.status == NBMC_ERROR_INVALID_PARAMETER && !ex.params_ok))
      die("reconstruct after a failed upload gave " + status_text(a.status));
  } else if (!ex.params_ok) expect(true, NBMC_ERROR_INVALID_PARAMETER);
  else if (ex.domain_small) {
    if (cancel_at == 0) expect(true, NBMC_ERROR_CANCELLED);
    else if (!ex.bbox_has_particles) expect(budget == 0, NBMC_ERROR_NO_PARTICLES);
    else if (!ex.grid_ok) expect(budget == 0 && cancel_at < 0, NBMC_ERROR_DOMAIN_TOO_LARGE);
    else expect(free_run, NBMC_OK);
  } else if (absurd_cell) expect(true, NBMC_ERROR_DOMAIN_TOO_LARGE);
  if (a.status == NBMC_ERROR_MEMORY_BUDGET && budget == 0) die("MEMORY_BUDGET without a budget");
  if (a.status == NBMC_ERROR_CANCELLED && cancel_at < 0) die("CANCELLED without a callback");

  if (a.status == NBMC_OK) check_mesh_invariants(a, prm, cell_abs, bw_abs, iso_abs, n);

  // Same input again: same status and message, bitwise identical mesh.
  const Run b = reconstruct(ctx, prm, cancel_at);
  expect_same(a, b, "second run", true);

  // The same particles in another order (upload has to succeed again).
  if (us == NBMC_OK && n > 1) {
    SplitMix rng{perm_seed};
    std::vector<std::size_t> perm(n);
    for (std::size_t i = 0; i < n; ++i) perm[i] = i;
    for (std::size_t i = n - 1; i > 0; --i) std::swap(perm[i], perm[std::size_t(rng.next() % (i + 1))]);
    std::vector<double> shuffled(values.size());
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) shuffled[3 * i + k] = values[3 * perm[i] + k];
    Upload su = pack(shuffled, f64, stride, n);
    const int32_t s2 = upload(ctx, su);
    if (s2 != NBMC_OK) die("upload of the shuffled particles gave " + status_text(s2));
    const Run c = reconstruct(ctx, prm, cancel_at);
    expect_same(a, c, "shuffled particle order", false);
  }

  // double_positions (every successful free run; 12 of the 21 corpus inputs):
  // the raw mesh in double, rounded, is the raw float mesh bit for bit
  // (marching cubes computes in double either way; only the store rounds).
  if (a.status == NBMC_OK && free_run && ex.struct_ok && us == NBMC_OK &&
      prm.struct_size >= offsetof(nbmc_params, double_positions) + sizeof(int32_t)) {
    nbmc_params raw = prm;
    raw.cleanup = 0;
    raw.smooth_iterations = 0;
    nbmc_params raw64 = raw;
    raw64.double_positions = 1;
    const Run f = reconstruct(ctx, raw, -1), d = reconstruct(ctx, raw64, -1);
    if (f.status != NBMC_OK || d.status != NBMC_OK)
      die("double_positions: raw runs gave " + status_text(f.status) + " / " + status_text(d.status));
    expect_same(f, d, "double_positions (rounded to float)", false);
    for (std::size_t i = 0; i < d.positions64.size(); ++i)
      if (float(d.positions64[i]) != d.mesh.positions[i]) die("double_positions: float positions are not the doubles rounded");
  }

  // Post-processing (issue #11: smoothing with either weighting, decimation,
  // isolated particles as spheres) on every successful free run, with values
  // drawn from the permutation seed (no new input bytes, so the corpus keeps
  // its meaning): the mesh stays closed, manifold and oriented without a
  // bounding box, decimation never adds triangles, the spheres are the
  // dropped particles, and a second run gives the same mesh.
  if (a.status == NBMC_OK && free_run && ex.struct_ok && us == NBMC_OK && prm.struct_size == sizeof(nbmc_params)) {
    SplitMix g{perm_seed ^ 0x5bd1e995u};
    nbmc_params pp = prm;
    pp.smooth_iterations = int32_t(g.next() % 6);
    pp.smooth_weighting = g.next() % 2 ? NBMC_SMOOTH_FEATURE : NBMC_SMOOTH_UNIFORM;
    pp.decimate_fraction = 0.1 + 0.9 * double(g.next() % 1000 + 1) / 1000.0;
    pp.isolated = g.next() % 2 ? NBMC_ISOLATED_SPHERE : NBMC_ISOLATED_KEEP;
    pp.min_cluster = int32_t(1 + g.next() % 20);
    const Run p1 = reconstruct(ctx, pp, -1);
    // Every particle may fall in a small cluster (nothing left to mesh), and
    // the cluster filter indexes at most 2^21 - 2 cells of the surface radius
    // per axis (a sparse cloud spread wider: DOMAIN_TOO_LARGE, said so).
    const bool filter_limit = p1.status == NBMC_ERROR_DOMAIN_TOO_LARGE &&
                              p1.message.find("isolated-particle filter") != std::string::npos;
    if (p1.status != NBMC_OK &&
        !(pp.isolated == NBMC_ISOLATED_SPHERE && (p1.status == NBMC_ERROR_NO_PARTICLES || filter_limit)))
      die("post-processing run gave " + status_text(p1.status) + ": \"" + p1.message + "\"");
    if (p1.status == NBMC_OK) {
      const std::size_t nt = p1.mesh.triangle_count();
      if (nt > p1.stats.pre_decimation_triangle_count) die("decimation added triangles");
      if (pp.decimate_fraction >= 1 && nt != p1.stats.pre_decimation_triangle_count)
        die("decimate_fraction 1 removed triangles");
      // The clean-up's counts account for every triangle it removed.
      const nbmc_stats& s1 = p1.stats;
      if (s1.raw_triangle_count - s1.pre_decimation_triangle_count !=
          2 * s1.cleanup_collapses + 6 * s1.cleanup_cuts + s1.cleanup_removed_component_triangles)
        die("clean-up counts: " + std::to_string(s1.raw_triangle_count) + " -> " +
            std::to_string(s1.pre_decimation_triangle_count) + " triangles with " +
            std::to_string(s1.cleanup_collapses) + " collapses, " + std::to_string(s1.cleanup_cuts) + " cuts, " +
            std::to_string(s1.cleanup_removed_component_triangles) + " removed in components");
      if (pp.isolated == NBMC_ISOLATED_SPHERE ? p1.spheres != p1.stats.dropped_particle_count : p1.spheres != 0)
        die("spheres: " + std::to_string(p1.spheres) + " for " + std::to_string(p1.stats.dropped_particle_count) +
            " dropped particles");
      if (!prm.use_bbox) {
        const nbmc_test::MeshReport rep = nbmc_test::check_mesh(p1.mesh);
        if (!rep.closed || !rep.edge_manifold || !rep.vertex_manifold || !rep.oriented || rep.unreferenced_vertices)
          die("post-processed mesh is not closed/manifold/oriented: " + rep.summary() + " (smooth " +
              std::to_string(pp.smooth_iterations) + ", weighting " + std::to_string(pp.smooth_weighting) +
              ", decimate " + std::to_string(pp.decimate_fraction) + ", isolated " + std::to_string(pp.isolated) +
              ")");
      }
    }
    const Run p2 = reconstruct(ctx, pp, -1);
    expect_same(p1, p2, "post-processing, second run", true);
  }

  // Per-particle radii (every successful free run, no input bytes of their
  // own): radii all equal to the spacing give the mesh without radii, bit for
  // bit; radii drawn between half the spacing and the spacing (the first
  // particle's the spacing, so every global length stays) give a successful
  // run whose mesh keeps the invariants above, the same on a second run and
  // with the particles shuffled together with their radii.
  if (a.status == NBMC_OK && free_run && ex.struct_ok && us == NBMC_OK) {
    if (upload(ctx, up) != NBMC_OK) die("radii: the upload failed again");
    std::vector<double> radii(n, prm.spacing);  // spacing is absolute in either unit
    auto set_radii = [&](const std::vector<double>& v) {
      if (nbmc_context_set_radii_f64(ctx, v.data(), v.size(), 0) != NBMC_OK)
        die(std::string("nbmc_context_set_radii_f64 refused valid radii: ") + nbmc_context_last_error(ctx));
    };
    set_radii(radii);
    expect_same(a, reconstruct(ctx, prm, -1), "radii equal to the spacing", false);
    SplitMix rng{perm_seed ^ 0x9e3779b97f4a7c15ull};
    for (std::size_t i = 1; i < n; ++i) radii[i] = prm.spacing * (0.5 + double(rng.next() % 1025) / 2048.0);
    set_radii(radii);
    const Run v = reconstruct(ctx, prm, -1);
    // YT10 has no per-particle radii: differing ones are refused.
    const bool refused = prm.method == NBMC_METHOD_YT10 &&
                         std::any_of(radii.begin(), radii.end(), [&](double r) { return r != radii[0]; });
    if (refused) {
      if (v.status != NBMC_ERROR_INVALID_PARAMETER)
        die("yt10 with differing radii: " + status_text(v.status) + " (expected invalid parameter): \"" + v.message +
            "\"");
    } else {
      if (v.status != NBMC_OK) die("per-particle radii: " + status_text(v.status) + ": \"" + v.message + "\"");
      check_mesh_invariants(v, prm, cell_abs, bw_abs, iso_abs, n);
      expect_same(v, reconstruct(ctx, prm, -1), "radii, second run", true);
      if (n > 1) {
        std::vector<std::size_t> perm(n);
        for (std::size_t i = 0; i < n; ++i) perm[i] = i;
        for (std::size_t i = n - 1; i > 0; --i) std::swap(perm[i], perm[std::size_t(rng.next() % (i + 1))]);
        std::vector<double> shuffled(values.size()), shuffled_radii(n);
        for (std::size_t i = 0; i < n; ++i) {
          for (int k = 0; k < 3; ++k) shuffled[3 * i + k] = values[3 * perm[i] + k];
          shuffled_radii[i] = radii[perm[i]];
        }
        if (upload(ctx, pack(shuffled, f64, stride, n)) != NBMC_OK) die("radii: the shuffled upload failed");
        set_radii(shuffled_radii);
        expect_same(v, reconstruct(ctx, prm, -1), "radii, shuffled particle order", false);
      }
    }
    if (nbmc_context_set_radii_f64(ctx, nullptr, 0, 0) != NBMC_OK) die("removing the radii failed");
  }

  // The context stays usable after whatever happened: leave it clean.
  if (nbmc_context_set_memory_budget(ctx, 0) != NBMC_OK) die("nbmc_context_set_memory_budget(0) failed");

  // NBMC_FUZZ_API_VERBOSE=1: one line per input (what it was, what came out).
  static const bool verbose = std::getenv("NBMC_FUZZ_API_VERBOSE") != nullptr;
  if (verbose) {
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    std::fprintf(stderr, "[fuzz_api] %s -> upload %d, reconstruct %d, %zu vertices, %zu triangles, %llu band vertices, "
                 "%llu evaluations, %.1f ms\n", g_case.c_str(), us, a.status, a.mesh.vertex_count(),
                 a.mesh.triangle_count(), (unsigned long long)a.stats.band_vertex_count,
                 (unsigned long long)a.stats.neighbour_evaluations, ms);
  }
  return 0;
}
