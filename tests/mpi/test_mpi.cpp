// SPDX-License-Identifier: MIT
// nbmc over MPI (run by ctest with mpirun -n 2, 3 and 4): every rank builds
// the same particles, passes its share (slabs, a random assignment, all on
// one rank) to a collective reconstruction, and the result must equal one
// process's mesh of all the particles, bit for bit (gathered), or make it up
// exactly (pieces: every triangle once, shared vertices with one global id
// and the same position on every rank). Errors on one rank must end the call
// on every rank with the same status and the failing rank named.
#include "nbmc_mpi.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace {

int g_rank = 0, g_size = 1, g_failures = 0;

#define CHECK(cond, ...)                                                            \
  do {                                                                              \
    if (!(cond)) {                                                                  \
      std::fprintf(stderr, "[rank %d] %s:%d: CHECK(%s) failed: ", g_rank, __FILE__, \
                   __LINE__, #cond);                                                \
      std::fprintf(stderr, __VA_ARGS__);                                            \
      std::fprintf(stderr, "\n");                                                   \
      ++g_failures;                                                                 \
    }                                                                               \
  } while (0)

struct Mesh {
  std::vector<float> pos, nrm;
  std::vector<double> pos64;  // double_positions
  std::vector<std::uint32_t> tri;
  std::vector<std::uint64_t> gid;
  std::uint64_t global_count = 0;
};

Mesh take(nbmc_mesh* m) {
  Mesh out;
  const std::size_t nv = nbmc_mesh_vertex_count(m), nt = nbmc_mesh_triangle_count(m);
  if (nv) out.pos.assign(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nv);
  if (nv && nbmc_mesh_positions_f64(m)) out.pos64.assign(nbmc_mesh_positions_f64(m), nbmc_mesh_positions_f64(m) + 3 * nv);
  if (nv && nbmc_mesh_normals(m)) out.nrm.assign(nbmc_mesh_normals(m), nbmc_mesh_normals(m) + 3 * nv);
  if (nt) out.tri.assign(nbmc_mesh_triangles(m), nbmc_mesh_triangles(m) + 3 * nt);
  if (const std::uint64_t* g = nbmc_mesh_global_vertex_ids(m)) out.gid.assign(g, g + nv);
  out.global_count = nbmc_mesh_global_vertex_count(m);
  nbmc_mesh_destroy(m);
  return out;
}

nbmc_context* context(bool bound) {
  nbmc_context_desc d;
  nbmc_context_desc_init(&d);
  d.backend = NBMC_BACKEND_OPENMP;
  d.num_threads = 1;
  nbmc_context* ctx = nullptr;
  if (nbmc_context_create(&d, &ctx) != NBMC_OK) {
    std::fprintf(stderr, "context: %s\n", nbmc_context_last_error(nullptr));
    std::exit(2);
  }
  if (bound) CHECK(nbmc_mpi_context_set_comm(ctx, MPI_COMM_WORLD) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
  return ctx;
}

// A lumpy blob (sphere + box), jittered: the same on every rank.
std::vector<double> blob(double r) {
  std::vector<double> p;
  std::mt19937 g(42);
  std::uniform_real_distribution<double> u(-0.2 * r, 0.2 * r);
  for (double z = -0.35; z <= 0.3; z += r)
    for (double y = -0.3; y <= 0.25; y += r)
      for (double x = -0.4; x <= 0.3; x += r) p.insert(p.end(), {x + u(g), y + u(g), z + u(g)});
  for (double z = -0.35; z <= 0.35; z += r)
    for (double y = -0.25; y <= 0.45; y += r)
      for (double x = 0.0; x <= 0.7; x += r)
        if ((x - 0.35) * (x - 0.35) + (y - 0.1) * (y - 0.1) + z * z <= 0.35 * 0.35)
          p.insert(p.end(), {x + u(g), y + u(g), z + u(g)});
  return p;
}

std::vector<double> read_xyz(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::vector<float> v;
  float x;
  while (f.read(reinterpret_cast<char*>(&x), sizeof x)) v.push_back(x);
  return std::vector<double>(v.begin(), v.end());
}

Mesh whole(const std::vector<double>& all, const nbmc_params& prm, nbmc_stats* stats = nullptr) {
  nbmc_context* ctx = context(false);
  CHECK(nbmc_context_set_particles_f64(ctx, all.data(), all.size() / 3, 0) == NBMC_OK, "upload");
  nbmc_mesh* m = nullptr;
  CHECK(nbmc_context_reconstruct(ctx, &prm, &m) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
  if (stats) {
    nbmc_stats_init(stats);
    CHECK(nbmc_context_stats(ctx, stats) == NBMC_OK, "whole: stats");
  }
  Mesh out = take(m);
  nbmc_context_destroy(ctx);
  return out;
}

// This rank's share of the particles under a split rule.
std::vector<double> share(const std::vector<double>& all, const std::string& rule) {
  std::vector<double> mine;
  const std::size_t n = all.size() / 3;
  double lo = 1e300, hi = -1e300;
  for (std::size_t i = 0; i < n; ++i) {
    lo = std::min(lo, all[3 * i]);
    hi = std::max(hi, all[3 * i]);
  }
  std::mt19937_64 g(7);
  for (std::size_t i = 0; i < n; ++i) {
    int owner = 0;
    if (rule == "slabs") owner = std::min(g_size - 1, int((all[3 * i] - lo) / (hi - lo + 1e-12) * g_size));
    else if (rule == "random") owner = int(g() % std::uint64_t(g_size));
    else if (rule == "rank0") owner = 0;
    else if (rule == "last") owner = g_size - 1;
    if (owner == g_rank) mine.insert(mine.end(), all.begin() + 3 * std::ptrdiff_t(i), all.begin() + 3 * std::ptrdiff_t(i) + 3);
  }
  return mine;
}

// Gathers variable-length arrays of T to rank 0.
template <class T>
std::vector<std::vector<T>> gather(const std::vector<T>& v) {
  int n = int(v.size() * sizeof(T));
  std::vector<int> counts(static_cast<std::size_t>(g_size)), displs(static_cast<std::size_t>(g_size));
  MPI_Gather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, MPI_COMM_WORLD);
  int total = 0;
  for (int r = 0; r < g_size; ++r) {
    displs[std::size_t(r)] = total;
    total += counts[std::size_t(r)];
  }
  std::vector<char> buf(std::size_t(g_rank == 0 ? total : 0) + 1);
  MPI_Gatherv(v.data(), n, MPI_BYTE, buf.data(), counts.data(), displs.data(), MPI_BYTE, 0, MPI_COMM_WORLD);
  std::vector<std::vector<T>> out;
  if (g_rank != 0) return out;
  for (int r = 0; r < g_size; ++r) {
    std::vector<T> part(std::size_t(counts[std::size_t(r)]) / sizeof(T));
    if (!part.empty()) std::memcpy(part.data(), buf.data() + displs[std::size_t(r)], std::size_t(counts[std::size_t(r)]));
    out.push_back(part);
  }
  return out;
}

using Tri = std::array<float, 9>;
std::vector<Tri> triangles_by_position(const Mesh& m) {
  std::vector<Tri> t;
  for (std::size_t i = 0; i + 2 < m.tri.size(); i += 3) {
    Tri x;
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) x[std::size_t(3 * c + a)] = m.pos[3 * std::size_t(m.tri[i + std::size_t(c)]) + std::size_t(a)];
    t.push_back(x);
  }
  std::sort(t.begin(), t.end());
  return t;
}

void check_case(const char* name, const std::vector<double>& all, const nbmc_params& prm, const std::string& rule,
                int nx, int ny, int nz) {
  nbmc_stats ref_stats;
  const Mesh ref = whole(all, prm, &ref_stats);
  const std::vector<double> mine = share(all, rule);
  // Gathered on the last rank (a root other than 0).
  {
    nbmc_context* ctx = context(true);
    if (nx > 0) nbmc_context_set_subdomains(ctx, nx, ny, nz);
    CHECK(nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0) == NBMC_OK,
          "%s", nbmc_context_last_error(ctx));
    nbmc_mesh* m = nullptr;
    const int root = g_size - 1;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, root, &m);
    CHECK(st == NBMC_OK, "%s %s: %s", name, rule.c_str(), nbmc_context_last_error(ctx));
    if (st == NBMC_OK) {
      const Mesh got = take(m);
      if (g_rank == root) {
        CHECK(got.pos == ref.pos && got.tri == ref.tri && got.nrm == ref.nrm,
              "%s %s gather: mesh differs (%zu/%zu vertices, %zu/%zu triangles)", name, rule.c_str(),
              got.pos.size() / 3, ref.pos.size() / 3, got.tri.size() / 3, ref.tri.size() / 3);
        nbmc_stats s;
        nbmc_stats_init(&s);
        CHECK(nbmc_context_stats(ctx, &s) == NBMC_OK && s.particle_count == all.size() / 3, "stats");
        // The clean-up ran on the stitched mesh, which is the whole frame's:
        // the same counts.
        CHECK(s.raw_triangle_count == ref_stats.raw_triangle_count &&
                  s.cleanup_bad_triangles_before == ref_stats.cleanup_bad_triangles_before &&
                  s.cleanup_bad_triangles_after == ref_stats.cleanup_bad_triangles_after &&
                  s.cleanup_moves == ref_stats.cleanup_moves && s.cleanup_flips == ref_stats.cleanup_flips &&
                  s.cleanup_collapses == ref_stats.cleanup_collapses && s.cleanup_cuts == ref_stats.cleanup_cuts &&
                  s.cleanup_removed_component_triangles == ref_stats.cleanup_removed_component_triangles,
              "%s %s gather: clean-up counts differ (%llu/%llu bad, %llu/%llu moves, %llu/%llu collapses)", name,
              rule.c_str(), (unsigned long long)s.cleanup_bad_triangles_before,
              (unsigned long long)ref_stats.cleanup_bad_triangles_before, (unsigned long long)s.cleanup_moves,
              (unsigned long long)ref_stats.cleanup_moves, (unsigned long long)s.cleanup_collapses,
              (unsigned long long)ref_stats.cleanup_collapses);
        nbmc_subdomain_stats d;
        nbmc_subdomain_stats_init(&d);
        CHECK(nbmc_context_subdomain_stats(ctx, &d) == NBMC_OK && d.count >= std::uint64_t(g_size) - 0 &&
                  d.count >= 1,
              "subdomain stats");
      } else {
        CHECK(got.pos.empty() && got.tri.empty(), "non-root got a mesh");
      }
    }
    nbmc_context_destroy(ctx);
  }
  // Pieces with global ids.
  {
    nbmc_context* ctx = context(true);
    if (nx > 0) nbmc_context_set_subdomains(ctx, nx, ny, nz);
    nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_PIECES, 0, &m);
    CHECK(st == NBMC_OK, "%s %s pieces: %s", name, rule.c_str(), nbmc_context_last_error(ctx));
    Mesh piece;
    if (st == NBMC_OK) piece = take(m);
    CHECK(piece.gid.size() == piece.pos.size() / 3, "global ids missing");
    const auto pos = gather(piece.pos);
    const auto tri = gather(piece.tri);
    const auto gid = gather(piece.gid);
    if (g_rank == 0 && st == NBMC_OK) {
      // The raw marching-cubes reference (pieces are not cleaned up).
      nbmc_params raw = prm;
      raw.cleanup = 0;
      raw.smooth_iterations = 0;
      const Mesh ref_raw = whole(all, raw);
      CHECK(piece.global_count == ref_raw.pos.size() / 3, "%s %s: %llu global vertices, the whole mesh has %zu", name,
            rule.c_str(), (unsigned long long)piece.global_count, ref_raw.pos.size() / 3);
      std::map<std::uint64_t, std::array<float, 3>> by_id;
      Mesh joined;
      for (int r = 0; r < g_size; ++r) {
        Mesh p;
        p.pos = pos[std::size_t(r)];
        p.tri = tri[std::size_t(r)];
        for (std::size_t v = 0; v < gid[std::size_t(r)].size(); ++v) {
          const std::array<float, 3> x = {p.pos[3 * v], p.pos[3 * v + 1], p.pos[3 * v + 2]};
          const auto it = by_id.find(gid[std::size_t(r)][v]);
          if (it == by_id.end()) by_id[gid[std::size_t(r)][v]] = x;
          else CHECK(it->second == x, "global id %llu has two positions", (unsigned long long)gid[std::size_t(r)][v]);
        }
        const std::vector<Tri> t = triangles_by_position(p);
        for (const Tri& x : t) {
          joined.tri.push_back(std::uint32_t(joined.pos.size() / 3));
          joined.tri.push_back(std::uint32_t(joined.pos.size() / 3 + 1));
          joined.tri.push_back(std::uint32_t(joined.pos.size() / 3 + 2));
          joined.pos.insert(joined.pos.end(), x.begin(), x.end());
        }
      }
      CHECK(by_id.size() == ref_raw.pos.size() / 3, "%s %s: %zu distinct ids, %zu vertices", name, rule.c_str(),
            by_id.size(), ref_raw.pos.size() / 3);
      CHECK(triangles_by_position(joined) == triangles_by_position(ref_raw),
            "%s %s pieces: the triangles differ from the whole mesh's", name, rule.c_str());
    }
    nbmc_context_destroy(ctx);
  }
  if (g_rank == 0) std::printf("ok  %-10s %-7s (%zu particles)\n", name, rule.c_str(), all.size() / 3);
}

// double_positions far from the origin (1e7 added to every coordinate): the
// gathered mesh has the whole frame's doubles bit for bit; the pieces carry
// doubles, one position per global id, the raw whole mesh's.
void check_f64(const std::vector<double>& near, nbmc_params prm, const std::string& rule) {
  std::vector<double> all = near;
  for (double& x : all) x += 1e7;
  prm.double_positions = 1;
  const Mesh ref = whole(all, prm);
  CHECK(!ref.pos64.empty() && ref.pos64.size() == ref.pos.size(), "f64: the whole mesh has no doubles");
  const std::vector<double> mine = share(all, rule);
  {
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m);
    CHECK(st == NBMC_OK, "f64 %s gather: %s", rule.c_str(), nbmc_context_last_error(ctx));
    if (st == NBMC_OK) {
      const Mesh got = take(m);
      if (g_rank == 0)
        CHECK(got.pos64 == ref.pos64 && got.tri == ref.tri && got.nrm == ref.nrm && got.pos == ref.pos,
              "f64 %s gather: mesh differs (%zu/%zu vertices)", rule.c_str(), got.pos64.size() / 3,
              ref.pos64.size() / 3);
    }
    nbmc_context_destroy(ctx);
  }
  {
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_PIECES, 0, &m);
    CHECK(st == NBMC_OK, "f64 %s pieces: %s", rule.c_str(), nbmc_context_last_error(ctx));
    Mesh piece;
    if (st == NBMC_OK) piece = take(m);
    CHECK(piece.pos64.size() == piece.pos.size(), "f64 pieces: no doubles");
    const auto pos = gather(piece.pos64);
    const auto gid = gather(piece.gid);
    if (g_rank == 0 && st == NBMC_OK) {
      nbmc_params raw = prm;
      raw.cleanup = 0;
      const Mesh ref_raw = whole(all, raw);
      std::map<std::uint64_t, std::array<double, 3>> by_id;
      for (int r = 0; r < g_size; ++r)
        for (std::size_t v = 0; v < gid[std::size_t(r)].size(); ++v) {
          const std::vector<double>& p = pos[std::size_t(r)];
          const std::array<double, 3> x = {p[3 * v], p[3 * v + 1], p[3 * v + 2]};
          const auto it = by_id.find(gid[std::size_t(r)][v]);
          if (it == by_id.end()) by_id[gid[std::size_t(r)][v]] = x;
          else CHECK(it->second == x, "f64: global id %llu has two positions", (unsigned long long)gid[std::size_t(r)][v]);
        }
      std::vector<std::array<double, 3>> got, want;
      for (const auto& kv : by_id) got.push_back(kv.second);
      for (std::size_t v = 0; v < ref_raw.pos64.size() / 3; ++v)
        want.push_back({ref_raw.pos64[3 * v], ref_raw.pos64[3 * v + 1], ref_raw.pos64[3 * v + 2]});
      std::sort(got.begin(), got.end());
      std::sort(want.begin(), want.end());
      CHECK(got == want, "f64 %s pieces: the vertices differ from the whole raw mesh's (%zu/%zu)", rule.c_str(),
            got.size(), want.size());
    }
    nbmc_context_destroy(ctx);
  }
  if (g_rank == 0) std::printf("ok  %-10s %-7s (%zu particles)\n", "f64", rule.c_str(), all.size() / 3);
}

// Particle attributes over MPI: values that are a function of the position
// (so each rank computes its own share's), interpolated on the root's
// gathered mesh and on the pieces, equal a single process's bit for bit
// (the pieces: at the same positions of the raw whole mesh). Then the
// errors: ranks that set different attributes fail together.
std::vector<double> attr_vel(const std::vector<double>& p) {
  std::vector<double> v(p.size());
  for (std::size_t i = 0; i < p.size(); i += 3) {
    v[i] = std::sin(7 * p[i + 1]);
    v[i + 1] = p[i] * p[i + 2];
    v[i + 2] = 1 + p[i + 2];
  }
  return v;
}
std::vector<double> attr_h(const std::vector<double>& p) {
  std::vector<double> h(p.size() / 3);
  for (std::size_t i = 0; i < h.size(); ++i) h[i] = 2.5 + p[3 * i] - p[3 * i + 1];
  return h;
}
std::vector<float> attribute_of(const nbmc_mesh* m, const char* name, uint32_t comps) {
  uint32_t c = 0;
  const float* a = nbmc_mesh_attribute(m, name, &c);
  if (!a || c != comps) return {};
  return std::vector<float>(a, a + comps * nbmc_mesh_vertex_count(m));
}
struct Attributed {
  std::vector<float> pos, vel, h;
};
Attributed attributed(nbmc_context* ctx, const std::vector<double>& mine, const nbmc_params& prm, int output,
                      int root, int32_t& st) {
  Attributed out;
  nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
  if (!mine.empty()) {
    const std::vector<double> vel = attr_vel(mine), h = attr_h(mine);
    CHECK(nbmc_context_set_attribute_f64(ctx, "vel", vel.data(), 3, 0) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
    CHECK(nbmc_context_set_attribute_f64(ctx, "h", h.data(), 1, 0) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
  }
  nbmc_mesh* m = nullptr;
  st = output < 0 ? nbmc_context_reconstruct(ctx, &prm, &m) : nbmc_mpi_reconstruct(ctx, &prm, output, root, &m);
  if (st != NBMC_OK) return out;
  const std::size_t nv = nbmc_mesh_vertex_count(m);
  if (nv) out.pos.assign(nbmc_mesh_positions(m), nbmc_mesh_positions(m) + 3 * nv);
  out.vel = attribute_of(m, "vel", 3);
  out.h = attribute_of(m, "h", 1);
  nbmc_mesh_destroy(m);
  return out;
}

void check_attributes(const char* name, const std::vector<double>& all, const nbmc_params& prm,
                      const std::string& rule, int nx, int ny, int nz) {
  const std::vector<double> mine = share(all, rule);
  int32_t st = 0;
  nbmc_context* one = context(false);
  const Attributed ref = attributed(one, all, prm, -1, 0, st);
  CHECK(st == NBMC_OK && !ref.vel.empty() && ref.h.size() == ref.pos.size() / 3, "whole frame with attributes");
  nbmc_params raw = prm;
  raw.cleanup = 0;
  raw.smooth_iterations = 0;
  const Attributed ref_raw = attributed(one, all, raw, -1, 0, st);
  nbmc_context_destroy(one);
  // Gathered on the last rank.
  {
    nbmc_context* ctx = context(true);
    if (nx > 0) nbmc_context_set_subdomains(ctx, nx, ny, nz);
    const int root = g_size - 1;
    const Attributed got = attributed(ctx, mine, prm, NBMC_MPI_GATHER, root, st);
    CHECK(st == NBMC_OK, "%s %s attributes gather: %s", name, rule.c_str(), nbmc_context_last_error(ctx));
    if (st == NBMC_OK && g_rank == root) {
      CHECK(got.pos == ref.pos, "%s %s attributes gather: mesh differs", name, rule.c_str());
      std::size_t diff = 0;
      for (std::size_t i = 0; i < got.h.size() && i < ref.h.size(); ++i) diff += got.h[i] != ref.h[i];
      CHECK(got.vel == ref.vel && got.h == ref.h, "%s %s gather: attributes differ (%zu of %zu scalar values)", name,
            rule.c_str(), diff, ref.h.size());
    } else if (st == NBMC_OK) {
      CHECK(got.pos.empty() && got.h.empty(), "non-root got attributes");
    }
    nbmc_context_destroy(ctx);
  }
  // Pieces: every piece vertex has the raw whole mesh's values at its position.
  {
    std::map<std::array<float, 3>, std::array<float, 4>> at;
    for (std::size_t v = 0; v < ref_raw.h.size(); ++v)
      at[{ref_raw.pos[3 * v], ref_raw.pos[3 * v + 1], ref_raw.pos[3 * v + 2]}] = {
          ref_raw.vel[3 * v], ref_raw.vel[3 * v + 1], ref_raw.vel[3 * v + 2], ref_raw.h[v]};
    nbmc_context* ctx = context(true);
    if (nx > 0) nbmc_context_set_subdomains(ctx, nx, ny, nz);
    const Attributed got = attributed(ctx, mine, prm, NBMC_MPI_PIECES, 0, st);
    CHECK(st == NBMC_OK, "%s %s attributes pieces: %s", name, rule.c_str(), nbmc_context_last_error(ctx));
    std::size_t bad = 0, missing = 0;
    CHECK(got.h.size() == got.pos.size() / 3, "%s %s pieces: %zu values for %zu vertices", name, rule.c_str(),
          got.h.size(), got.pos.size() / 3);
    for (std::size_t v = 0; v < got.h.size(); ++v) {
      const auto it = at.find({got.pos[3 * v], got.pos[3 * v + 1], got.pos[3 * v + 2]});
      if (it == at.end()) {
        ++missing;
        continue;
      }
      const std::array<float, 4> want = it->second;
      if (want[0] != got.vel[3 * v] || want[1] != got.vel[3 * v + 1] || want[2] != got.vel[3 * v + 2] ||
          want[3] != got.h[v])
        ++bad;
    }
    CHECK(bad == 0 && missing == 0, "%s %s pieces: %zu vertices with other values, %zu not in the whole mesh", name,
          rule.c_str(), bad, missing);
    nbmc_context_destroy(ctx);
  }
  // Different attributes on two ranks: all fail, with both lists named.
  if (g_size > 1) {
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, all.data(), all.size() / 3, 0);
    const std::vector<double> h = attr_h(all);
    nbmc_context_set_attribute_f64(ctx, g_rank == 1 ? "rho" : "h", h.data(), 1, 0);
    nbmc_mesh* m = nullptr;
    st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m);
    const std::string msg = nbmc_context_last_error(ctx);
    CHECK(st == NBMC_ERROR_INVALID_ARGUMENT && m == nullptr && msg.find("'rho'") != std::string::npos &&
              msg.find("'h'") != std::string::npos,
          "different attributes: status %d (%s)", st, msg.c_str());
    nbmc_mesh_destroy(m);
    // And the context stays usable.
    nbmc_context_set_attribute_f64(ctx, g_rank == 1 ? "rho" : "h", nullptr, 1, 0);
    CHECK(nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m) == NBMC_OK, "after: %s", nbmc_context_last_error(ctx));
    nbmc_mesh_destroy(m);
    nbmc_context_destroy(ctx);
  }
  if (g_rank == 0) std::printf("ok  attributes %-10s %-7s\n", name, rule.c_str());
}

void check_errors(const std::vector<double>& all, const nbmc_params& prm) {
  std::vector<double> mine = share(all, "slabs");
  // Bad particles on the last rank: every rank fails with its status.
  {
    nbmc_context* ctx = context(true);
    if (g_rank == g_size - 1 && !mine.empty()) mine[0] = std::nan("");
    const int32_t up = nbmc_context_set_particles_f64(ctx, mine.data(), mine.size() / 3, 0);
    if (g_rank == g_size - 1) CHECK(up == NBMC_ERROR_INVALID_PARTICLES, "upload of a NaN: %d", up);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m);
    const std::string msg = nbmc_context_last_error(ctx);
    CHECK(st == NBMC_ERROR_INVALID_PARTICLES && m == nullptr, "NaN on one rank: status %d (%s)", st, msg.c_str());
    CHECK(msg.find("rank " + std::to_string(g_size - 1)) != std::string::npos, "message names no rank: %s", msg.c_str());
    // The context stays usable: a good upload works again.
    mine = share(all, "slabs");
    nbmc_context_set_particles_f64(ctx, mine.data(), mine.size() / 3, 0);
    CHECK(nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m) == NBMC_OK, "after the error: %s",
          nbmc_context_last_error(ctx));
    nbmc_mesh_destroy(m);
    nbmc_context_destroy(ctx);
  }
  // Isolated-particle dropping is not available over MPI: every rank says so.
  {
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, mine.data(), mine.size() / 3, 0);
    nbmc_params drop = prm;
    drop.isolated = NBMC_ISOLATED_DROP;
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &drop, NBMC_MPI_GATHER, 0, &m);
    CHECK(st == NBMC_ERROR_INVALID_PARAMETER && m == nullptr, "isolated drop over MPI: status %d (%s)", st,
          nbmc_context_last_error(ctx));
    CHECK(std::string(nbmc_context_last_error(ctx)).find("isolated") != std::string::npos, "%s",
          nbmc_context_last_error(ctx));
    nbmc_context_destroy(ctx);
  }
  // A memory budget on rank 0 only.
  {
    nbmc_context* ctx = context(true);
    if (g_rank == 0) nbmc_context_set_memory_budget(ctx, 1024);
    nbmc_context_set_particles_f64(ctx, mine.data(), mine.size() / 3, 0);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_PIECES, 0, &m);
    CHECK(st == NBMC_ERROR_MEMORY_BUDGET, "budget on rank 0: status %d (%s)", st, nbmc_context_last_error(ctx));
    CHECK(std::string(nbmc_context_last_error(ctx)).find("rank 0") != std::string::npos, "%s",
          nbmc_context_last_error(ctx));
    nbmc_context_destroy(ctx);
  }
  // A bad parameter (the same on every rank) and an unbound context.
  {
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, mine.data(), mine.size() / 3, 0);
    nbmc_params bad = prm;
    bad.cell_size = -1;
    nbmc_mesh* m = nullptr;
    CHECK(nbmc_mpi_reconstruct(ctx, &bad, NBMC_MPI_GATHER, 0, &m) == NBMC_ERROR_INVALID_PARAMETER, "bad parameter");
    CHECK(nbmc_mpi_reconstruct(ctx, &prm, 5, 0, &m) == NBMC_ERROR_INVALID_ARGUMENT, "bad output");
    CHECK(nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, g_size, &m) == NBMC_ERROR_INVALID_ARGUMENT, "bad root");
    nbmc_context_destroy(ctx);
    nbmc_context* plain = context(false);
    CHECK(nbmc_mpi_reconstruct(plain, &prm, NBMC_MPI_GATHER, 0, &m) == NBMC_ERROR_INVALID_ARGUMENT, "unbound");
    CHECK(nbmc_mpi_context_rank(plain) == -1, "unbound rank");
    nbmc_context_destroy(plain);
  }
  // No particles anywhere.
  {
    nbmc_context* ctx = context(true);
    CHECK(nbmc_context_set_particles_f64(ctx, nullptr, 0, 0) == NBMC_OK, "zero particles on a bound context");
    nbmc_mesh* m = nullptr;
    CHECK(nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m) == NBMC_ERROR_NO_PARTICLES, "no particles");
    nbmc_context_destroy(ctx);
  }
  if (g_rank == 0) std::printf("ok  errors agreed on every rank\n");
}

// Per-particle radii (nbmc_context_set_radii_f64): every rank sets its own
// particles' radii; the gathered mesh is one process's mesh of all the
// particles with their radii, bit for bit, for every share. Ranks without
// particles set none. Some ranks with particles and no radii: every rank
// fails with NBMC_ERROR_INVALID_ARGUMENT.
void check_radii(const std::vector<double>& all, nbmc_params prm) {
  const std::size_t n = all.size() / 3;
  std::vector<double> radii(n);
  for (std::size_t i = 0; i < n; ++i) radii[i] = all[3 * i] < 0 ? prm.spacing : 0.5 * prm.spacing;
  prm.cell_size = 0.25;
  Mesh ref;
  {
    nbmc_context* ctx = context(false);
    CHECK(nbmc_context_set_particles_f64(ctx, all.data(), n, 0) == NBMC_OK, "upload");
    CHECK(nbmc_context_set_radii_f64(ctx, radii.data(), n, 0) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
    nbmc_mesh* m = nullptr;
    CHECK(nbmc_context_reconstruct(ctx, &prm, &m) == NBMC_OK, "%s", nbmc_context_last_error(ctx));
    ref = take(m);
    nbmc_context_destroy(ctx);
  }
  // The radii of this rank's share (interleaved with the positions: 4 doubles each).
  auto share_radii = [&](const std::string& rule, std::vector<double>& mine, std::vector<double>& mine_radii) {
    std::vector<double> tagged(4 * n);
    for (std::size_t i = 0; i < n; ++i) {
      tagged[4 * i] = all[3 * i];
      tagged[4 * i + 1] = all[3 * i + 1];
      tagged[4 * i + 2] = all[3 * i + 2];
      tagged[4 * i + 3] = radii[i];
    }
    // share() works on triples: share the indices as x, then pick.
    std::vector<double> idx(3 * n);
    for (std::size_t i = 0; i < n; ++i) {
      idx[3 * i] = all[3 * i];
      idx[3 * i + 1] = double(i);
      idx[3 * i + 2] = 0;
    }
    const std::vector<double> got = share(idx, rule);
    mine.clear();
    mine_radii.clear();
    for (std::size_t k = 0; k + 2 < got.size(); k += 3) {
      const std::size_t i = std::size_t(got[k + 1]);
      mine.insert(mine.end(), {tagged[4 * i], tagged[4 * i + 1], tagged[4 * i + 2]});
      mine_radii.push_back(tagged[4 * i + 3]);
    }
  };
  for (const char* rule : {"slabs", "random", "rank0"}) {
    std::vector<double> mine, mine_radii;
    share_radii(rule, mine, mine_radii);
    nbmc_context* ctx = context(true);
    CHECK(nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0) == NBMC_OK,
          "%s", nbmc_context_last_error(ctx));
    if (!mine.empty())
      CHECK(nbmc_context_set_radii_f64(ctx, mine_radii.data(), mine_radii.size(), 0) == NBMC_OK, "%s",
            nbmc_context_last_error(ctx));
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m);
    CHECK(st == NBMC_OK, "radii %s: %s", rule, nbmc_context_last_error(ctx));
    if (st == NBMC_OK) {
      const Mesh got = take(m);
      if (g_rank == 0)
        CHECK(got.pos == ref.pos && got.tri == ref.tri && got.nrm == ref.nrm,
              "radii %s gather: mesh differs (%zu/%zu vertices)", rule, got.pos.size() / 3, ref.pos.size() / 3);
    }
    nbmc_context_destroy(ctx);
  }
  if (g_size > 1) {  // radii on rank 0 only, particles everywhere
    std::vector<double> mine, mine_radii;
    share_radii("slabs", mine, mine_radii);
    nbmc_context* ctx = context(true);
    nbmc_context_set_particles_f64(ctx, mine.empty() ? nullptr : mine.data(), mine.size() / 3, 0);
    if (g_rank == 0 && !mine.empty()) nbmc_context_set_radii_f64(ctx, mine_radii.data(), mine_radii.size(), 0);
    nbmc_mesh* m = nullptr;
    const int32_t st = nbmc_mpi_reconstruct(ctx, &prm, NBMC_MPI_GATHER, 0, &m);
    CHECK(st == NBMC_ERROR_INVALID_ARGUMENT && m == nullptr, "radii on one rank only: status %d (%s)", st,
          nbmc_context_last_error(ctx));
    nbmc_context_destroy(ctx);
  }
  if (g_rank == 0) std::printf("ok  radii     (%zu particles, two radii)\n", n);
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  const double r = 0.05;
  const std::vector<double> b = blob(r);
  nbmc_params prm;
  nbmc_params_init(&prm);
  prm.spacing = r;
  for (const char* rule : {"slabs", "random", "rank0", "last"}) check_case("blob", b, prm, rule, 0, 0, 0);
  nbmc_params thin = prm;  // band growth that crosses subdomain faces
  thin.band_width = 0.6;
  thin.cleanup = 0;
  check_case("thin-band", b, thin, "random", 3, 2, 2);
  nbmc_params coarse = prm;
  coarse.cell_size = 1;
  coarse.method = NBMC_METHOD_ZB05;
  check_case("zb05", b, coarse, "slabs", 4, 1, 1);
  nbmc_params sph = prm;  // per-particle densities: ghosts 2R wide
  sph.method = NBMC_METHOD_SPH;
  sph.influence_radius = 2;
  check_case("sph", b, sph, "random", 0, 0, 0);
  nbmc_params yt10 = prm;  // per-particle anisotropic kernels: ghosts 2R wide
  yt10.method = NBMC_METHOD_YT10;
  check_case("yt10", b, yt10, "random", 0, 0, 0);
  const char* dir = std::getenv("NBMC_DATA_DIR");
  if (dir) {
    const std::vector<double> f = read_xyz(std::string(dir) + "/xyz/splashsurf_dambreak_f23_24389.xyz");
    if (!f.empty()) check_case("dambreak", f, prm, "slabs", 0, 0, 0);
  }
  check_f64(b, prm, "random");
  check_attributes("blob", b, prm, "random", 0, 0, 0);
  check_attributes("blob-3x2x1", b, prm, "slabs", 3, 2, 1);
  check_radii(b, prm);
  check_errors(b, prm);
  int failures = g_failures;
  MPI_Allreduce(MPI_IN_PLACE, &failures, 1, MPI_INT, MPI_SUM, MPI_COMM_WORLD);
  if (g_rank == 0) std::printf("%s (%d ranks, %d failed checks)\n", failures ? "FAILED" : "PASSED", g_size, failures);
  MPI_Finalize();
  return failures ? 1 : 0;
}
